"""The batched engine ``jaxgrasp.evaluate_batch`` (issue 12, part 2): grasps with
different contact counts in one compiled program, chunked, equal to ``evaluate`` grasp by
grasp in every Evaluation field; invalid rows of a dataset; buckets; ranking; files;
one-line errors before anything is compiled.

Every evaluation here goes through ONE compilation (4 contacts, masked, batch 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import BatchResult, GraspSet, GraspValueError, evaluate_batch
from jaxgrasp.engine._plan import bucket_size
from jaxgrasp.tolerance._result import FIELDS, Evaluation
from jaxgrasp.tolerance._status import GraspStatus
from jaxgrasp.solver._status import LaneStatus

ROOT = Path(__file__).resolve().parents[2]


def _grasps():
    return [
        jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002),  # stable, slip
        jaxgrasp.presets.prism(mass=0.1),  # 3 contacts
        jaxgrasp.load(ROOT / "examples" / "four_finger.json"),  # 4 contacts
        jaxgrasp.presets.cube(young_modulus=1e6, initial_deformation=4.5e-3),  # infeasible: squeezed past f_max
        jaxgrasp.presets.cube(young_modulus=1e6, initial_deformation=0.002),  # stable, max_force
    ]


@pytest.fixture(scope="module")
def batch_and_refs(evaluate_many):
    grasps = _grasps()
    calls = []
    res = evaluate_batch(grasps, chunk_size=2, progress=lambda d, t: calls.append((d, t)))
    return grasps, res, evaluate_many(grasps), calls


def test_mixed_contact_counts_equal_evaluate(batch_and_refs):
    grasps, res, refs, calls = batch_and_refs
    assert len(res) == 5
    assert res.num_contacts.tolist() == [2, 3, 4, 2, 2]
    assert calls == [(2, 5), (4, 5), (5, 5)]  # 3 chunks of 2, the last padded
    for i, ref in enumerate(refs):
        assert int(res.status[i]) == int(ref.status), i
        assert int(res.limiting_kind[i]) == int(ref.limiting_kind), i
        assert int(res.limiting_contact[i]) == int(ref.limiting_contact), i
        scale = abs(float(ref.equilibrium_energy))
        np.testing.assert_allclose(res.value[i], ref.value, rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(res.equilibrium_energy[i], ref.equilibrium_energy, rtol=1e-12, atol=1e-12 * scale)
    assert res.status_names[3] == "infeasible"
    assert res.counts()["stable"] == int(np.sum(res.status == GraspStatus.STABLE))


def test_rank_puts_stable_grasps_first_by_value(batch_and_refs):
    _, res, refs, _ = batch_and_refs
    order = res.rank()
    stable = [i for i in order if res.status[i] == GraspStatus.STABLE]
    assert list(order[: len(stable)]) == stable
    assert np.all(np.diff(res.value[stable]) <= 0)
    assert int(order[-1]) == 3  # the infeasible grasp (value 0) is last here


def _fake(value, status) -> BatchResult:
    b = len(value)
    ev = {f: np.zeros(b) for f in FIELDS} | {"value": np.asarray(value), "status": np.asarray(status)}
    return BatchResult(
        evaluation=Evaluation(**ev), num_contacts=np.full(b, 2), active=np.ones((b, 2), bool), errors=(None,) * b
    )


def test_rank_orders_groups_and_ties():
    r = _fake([0.0, 2.0, 5.0, 2.0, 9.0, 0.0, np.nan], [1, 0, 3, 0, 0, 2, 4])
    # stable by value (ties in input order), then unstable/infeasible, then not_converged, then invalid
    assert r.rank().tolist() == [4, 1, 3, 0, 5, 2, 6]


def test_every_evaluation_field_equals_evaluate(batch_and_refs):
    """Padded to 4 contacts, grasp i's own contacts are the first n_i: every array of
    res[i] equals evaluate's on them; the padding contacts are no_start, +inf, never limiting."""
    _, res, refs, _ = batch_and_refs
    for i, ref in enumerate(refs):
        n, N = int(res.num_contacts[i]), res.active.shape[1]
        got = res[i]
        assert isinstance(got, Evaluation)
        assert res.active[i].tolist() == [True] * n + [False] * (N - n)
        rows = np.r_[0, 1 + np.arange(n), 1 + N + np.arange(n)]  # kkt/steps rows of the real lanes
        pairs = {
            "boundary_energy": (got.boundary_energy[:, :n], ref.boundary_energy),
            "boundary_translation": (got.boundary_translation[:, :n], ref.boundary_translation),
            "boundary_rotation": (got.boundary_rotation[:, :n], ref.boundary_rotation),
            "equilibrium_margins": (got.equilibrium_margins[:, :n], ref.equilibrium_margins),
            "equilibrium_translation": (got.equilibrium_translation, ref.equilibrium_translation),
            "equilibrium_rotation": (got.equilibrium_rotation, ref.equilibrium_rotation),
        }
        for name, (a, b) in pairs.items():
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-13, err_msg=f"grasp {i} {name}")
        # KKT residuals of converged lanes are round-off (~1e-11, scaled units): equal to far below the tolerance
        np.testing.assert_allclose(got.kkt[rows], ref.kkt, rtol=0, atol=1e-9, err_msg=f"grasp {i} kkt")
        np.testing.assert_array_equal(got.boundary_status[:, :n], ref.boundary_status, err_msg=f"grasp {i}")
        np.testing.assert_array_equal(got.steps[rows], ref.steps, err_msg=f"grasp {i}")
        assert int(got.equilibrium_status) == int(ref.equilibrium_status)
        assert np.all(got.boundary_status[:, n:] == LaneStatus.NO_START)
        assert np.all(np.isposinf(got.boundary_energy[:, n:]))


@pytest.fixture(scope="module")
def set_result(batch_and_refs):
    grasps, _, _, _ = batch_and_refs
    error = "grasp 2 (line 3): friction = -1 must be positive"
    gset = GraspSet(grasps=(grasps[0], grasps[1], None, grasps[2]), errors=(None, None, error, None), source="set.jsonl")
    return evaluate_batch(gset, chunk_size=2), error  # same bucket and N as the fixture: no compilation


def test_invalid_rows_of_a_set_are_marked_and_the_others_evaluated(batch_and_refs, set_result):
    _, res, refs, _ = batch_and_refs
    out, error = set_result
    assert out.compile_seconds == 0.0  # the fixture's compiled program
    assert out.status_names.tolist() == [res.status_names[0], res.status_names[1], "invalid", res.status_names[2]]
    assert out.errors == (None, None, error, None)
    assert out.num_contacts.tolist() == [2, 3, 0, 4]
    assert np.isnan(out.value[2]) and np.isnan(out.boundary_energy[2]).all()
    assert out.limiting_contact[2] == -1 and out.limiting_kind[2] == -1
    for j, i in ((0, 0), (1, 1), (3, 2)):
        np.testing.assert_allclose(out.value[j], refs[i].value, rtol=1e-12, atol=1e-18)
    assert out.counts()["invalid"] == 1 and int(out.rank()[-1]) == 2


def test_csv_and_npz_round_trip(set_result, tmp_path):
    import csv

    out, error = set_result
    out.to_csv(tmp_path / "r.csv")
    with open(tmp_path / "r.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["index", "num_contacts", "value_J", "status", "limiting_kind",
                             "limiting_contact", "equilibrium_energy_J", "error"]
    assert [r["index"] for r in rows] == ["0", "1", "2", "3"]
    assert float(rows[0]["value_J"]) == float(out.value[0])  # 17 digits: exact
    assert rows[2]["status"] == "invalid" and rows[2]["value_J"] == "" and rows[2]["error"] == error
    assert rows[3]["num_contacts"] == "4" and rows[3]["error"] == ""
    out.to_npz(tmp_path / "r.npz")
    back = BatchResult.from_npz(tmp_path / "r.npz")
    assert back.errors == out.errors
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(back, f), getattr(out, f), err_msg=f)
    np.testing.assert_array_equal(back.active, out.active)


def test_batch_sizes_come_from_a_few_buckets():
    # a grid or set of any size up to the chunk uses one of 1, 4, 16, 64 lanes per device
    assert [bucket_size(64, t) for t in (1, 2, 4, 5, 6, 12, 16, 17, 100, 128, 369)] == [1, 4, 4, 16, 16, 16, 16, 64, 64, 64, 64]
    assert len({bucket_size(64, t) for t in range(1, 1000)}) == 4
    assert bucket_size(6, 14) == 6 and bucket_size(4096, 369) == 1024  # an explicit chunk caps the bucket
    assert bucket_size(64, 6, n_devices=2) == 8 and bucket_size(128, 369, n_devices=2) == 128  # per device: 4, 64


def test_errors_are_one_line_before_compiling():
    cube = jaxgrasp.presets.cube()
    with pytest.raises(GraspValueError, match="no valid grasp to evaluate"):
        evaluate_batch(GraspSet(grasps=(None,), errors=("grasp 0: bad",)))
    with pytest.raises(GraspValueError, match="non-empty sequence"):
        evaluate_batch([])
    with pytest.raises(GraspValueError, match=r"batch axis: positions \(B, N, 3\)"):
        evaluate_batch(cube)
    with pytest.raises(GraspValueError, match="chunk_size must be a positive integer"):
        evaluate_batch([cube], chunk_size=0)
    bad = cube.replace(friction=np.array([0.5, -0.5]))
    with pytest.raises(GraspValueError, match=r"^grasp 1: friction"):
        evaluate_batch([cube, bad])


@pytest.mark.slow  # compiles a batch evaluator of its own
def test_smooth_minimum_is_applied_in_a_batch():
    """``EvaluateOptions(smooth_min_temperature=T)``: each batch value is
    :func:`jaxgrasp.evaluate`'s soft minimum with the same options, below the hard one."""
    grasps = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=0.002) for e in (4e5, 6e5)]
    hard = [float(jaxgrasp.evaluate(g).value) for g in grasps]
    options = jaxgrasp.EvaluateOptions(smooth_min_temperature=0.1 * min(hard))
    soft = [float(jaxgrasp.evaluate(g, options).value) for g in grasps]
    got = np.asarray(evaluate_batch(grasps, options=options).evaluation.value)
    np.testing.assert_allclose(got, soft, rtol=1e-10, atol=0)
    assert np.all(got < np.asarray(hard) * (1 - 1e-3)), (got, hard)
