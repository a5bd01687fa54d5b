"""The batched engine ``jaxgrasp.evaluate_batch`` (issue 12, part 2, first step): grasps
with different contact counts in one compiled program, chunked, equal to ``evaluate``
grasp by grasp; ranking; one-line errors before anything is compiled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import BatchResult, GraspValueError, evaluate_batch
from jaxgrasp.status import GraspStatus

ROOT = Path(__file__).resolve().parent.parent


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


def test_rank_orders_groups_and_ties():
    r = BatchResult(
        value=np.array([0.0, 2.0, 5.0, 2.0, 9.0, 0.0]),
        status=np.array([1, 0, 3, 0, 0, 2]),
        limiting_kind=np.zeros(6, int), limiting_contact=np.zeros(6, int),
        equilibrium_energy=np.zeros(6), num_contacts=np.full(6, 2),
    )
    # stable by value (ties in input order), then unstable/infeasible, then not_converged
    assert r.rank().tolist() == [4, 1, 3, 0, 5, 2]


def test_errors_are_one_line_before_compiling():
    cube = jaxgrasp.presets.cube()
    with pytest.raises(GraspValueError, match="non-empty sequence"):
        evaluate_batch([])
    with pytest.raises(GraspValueError, match=r"batch axis: positions \(B, N, 3\)"):
        evaluate_batch(cube)
    with pytest.raises(GraspValueError, match="chunk_size must be a positive integer"):
        evaluate_batch([cube], chunk_size=0)
    bad = cube.replace(friction=np.array([0.5, -0.5]))
    with pytest.raises(GraspValueError, match=r"^grasp 1: friction"):
        evaluate_batch([cube, bad])
