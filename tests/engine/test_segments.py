"""Segments by contact count (issue 41, item 1): a mixed batch's counts each run at a
width of their own where that pays for a compilation (``plan_widths``), results laid out
at the batch's widest count as the padded program lays them out.

The plan is checked against every choice of own or widest width per count (it must be
the cheapest by its own cost model) and for its platform rule. The evaluation runs the five
grasps of ``tests/engine/test_batch.py`` and a 2-contact grasp padded to 4 with its
contacts in slots 1 and 3, with the widths ``{2: 2, 3: 4, 4: 4}`` forced: the 3- and
4-contact grasps in that module's program (4 contacts, masked, chunks of 2), the
2-contact ones in a program of 2 contacts (one compilation here). Every field must equal
the padded batch's: codes exactly, numbers to rounding, the padding contacts exactly.
"""

from __future__ import annotations

import itertools
import json

import jax
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import Grasp, evaluate_batch
from jaxgrasp.engine import _runner as runner_module
from jaxgrasp.engine import _compile, _store
from jaxgrasp.engine._batch import evaluate_dataset
from jaxgrasp.engine._plan import (
    COMPILE_CPU_SECONDS,
    WIDTH_PLATFORMS,
    grasp_cpu_seconds,
    plan_segments,
    plan_widths,
)
from jaxgrasp.model._fields import FIELDS as GRASP_FIELDS
from jaxgrasp.solver._status import LaneStatus
from jaxgrasp.tolerance._result import FIELDS
from test_batch import _grasps as batch_grasps

FORCED = {2: 2, 3: 4, 4: 4}
CODES = ("status", "limiting_kind", "limiting_contact", "boundary_status", "equilibrium_status", "steps")


# ------------------------------------------------------------------------------ the plan


def _cost(histogram: dict[int, int], widths: dict[int, int]) -> float:
    """The plan's own cost model: a compilation per width, each grasp at its width."""
    return len(set(widths.values())) * COMPILE_CPU_SECONDS + sum(
        n * grasp_cpu_seconds(c, widths[c]) for c, n in histogram.items())


def _every_plan(counts: list[int]):
    """Every way to run sorted ``counts`` each at its own width or at the largest count."""
    for own in itertools.product([False, True], repeat=len(counts) - 1):
        yield {c: c if mine else counts[-1] for c, mine in zip(counts, own)} | {counts[-1]: counts[-1]}


@pytest.mark.parametrize("seed", range(6))
def test_widths_are_the_cheapest_plan(seed):
    rng = np.random.default_rng(seed)
    counts = sorted(rng.choice(np.arange(2, 12), size=rng.integers(2, 7), replace=False).tolist())
    histogram = {c: int(10 ** rng.uniform(2, 5)) for c in counts}
    got = plan_widths(histogram)
    assert all(got[c] in (c, counts[-1]) for c in counts) and got[counts[-1]] == counts[-1]
    best = min(_cost(histogram, w) for w in _every_plan(counts))
    assert _cost(histogram, got) == pytest.approx(best, rel=1e-12)


def test_few_grasps_share_the_widest_program_and_many_get_their_own():
    assert plan_widths({2: 167, 3: 167, 4: 167, 5: 167, 6: 166, 7: 166}) == {c: 7 for c in range(2, 8)}
    assert plan_widths({c: 16_700 for c in range(2, 8)}) == {c: c for c in range(2, 8)}
    assert plan_widths({c: 5000 for c in range(2, 8)}) == {2: 2, 3: 3, 4: 7, 5: 7, 6: 7, 7: 7}
    # a 2-contact grasp saves 7 ms of CPU run at its own width against padded to 7: a
    # compilation pays from about 4300 of them
    assert plan_widths({2: 4200, 7: 100}) == {2: 7, 7: 7}
    assert plan_widths({2: 4400, 7: 100}) == {2: 2, 7: 7}
    assert plan_widths({}) == {} and plan_widths({5: 0, 3: 4}) == {3: 3}


def test_widths_on_an_accelerator_are_the_widest():
    assert "gpu" not in WIDTH_PLATFORMS
    assert plan_widths({c: 10**6 for c in (2, 3, 7)}, "gpu") == {2: 7, 3: 7, 7: 7}


def test_segments_hold_every_grasp_once_widest_first():
    counts = np.array([2, 4, 3, 2, 4, 2])
    plan = plan_segments(counts, FORCED, chunk_size=2, devices=jax.devices()[:1])
    assert [(s.width, s.counts, s.masked) for s in plan.segments] == [(4, (3, 4), True), (2, (2,), False)]
    assert sorted(np.concatenate([s.at for s in plan.segments]).tolist()) == list(range(6))
    assert plan.total == 6 and plan.n_chunks == 2 + 2
    assert plan.describe() == "3-4 contacts at width 4: 3 grasps; 2 contacts at width 2: 3 grasps"
    with pytest.raises(ValueError, match=r"no width planned for contact counts \[5\]"):
        plan_segments(np.array([5]), FORCED)


# ------------------------------------------------------------------------ the evaluation


def _grasps():
    """``tests/engine/test_batch.py``'s five grasps (2, 3, 4, 2 infeasible, 2 contacts) with
    a sagging cube as grasp 4."""
    grasps = batch_grasps()
    return grasps[:4] + [jaxgrasp.presets.cube(young_modulus=8e5, initial_deformation=0.002, mass=0.05)] + grasps[4:]


def _batch() -> Grasp:
    """The grasps of :func:`_grasps` as one batched grasp of 4 contacts, grasp 4's own
    contacts in slots 1 and 3 (copies of them, inactive, in slots 0 and 2); ``stack``
    puts a grasp's contacts first, a batched grasp may place them anywhere."""
    fields = {k: np.array(v) for k, v in jaxgrasp.stack(_grasps()).to_numpy_batch().items()}
    for field in GRASP_FIELDS:
        if field.per_contact:
            fields[field.name][4] = fields[field.name][4][[0, 0, 1, 1]]
    fields["active"][4] = [False, True, False, True]
    return Grasp(**{k: jax.numpy.asarray(v) for k, v in fields.items()})


@pytest.fixture(scope="module")
def padded_and_segmented():
    grasps = _batch()
    padded = evaluate_batch(grasps, chunk_size=2)  # test_batch.py's program
    chunks, reports = [], []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner_module, "plan_widths", lambda counts, platform: FORCED)
        segmented = evaluate_batch(grasps, chunk_size=2, on_chunk=lambda rows, res: chunks.append((rows, res)),
                                   progress=lambda done, total: reports.append((done, total)))
    held = {key[2:4] + key[6:7] for key in _compile._MEMO if key[0] == "chunk"}  # (contacts, chunk, masked)
    return padded, segmented, chunks, reports, held


def test_segmented_results_equal_the_padded_ones(padded_and_segmented):
    padded, seg, _, _, _ = padded_and_segmented
    assert seg.num_contacts.tolist() == [2, 3, 4, 2, 2, 2]
    np.testing.assert_array_equal(seg.active, padded.active)
    for f in FIELDS:
        a, b = np.asarray(getattr(padded, f)), np.asarray(getattr(seg, f))
        assert a.shape == b.shape and a.dtype == b.dtype, f
        if f in CODES:
            np.testing.assert_array_equal(b, a, err_msg=f)
            continue
        np.testing.assert_array_equal(np.isnan(b), np.isnan(a), err_msg=f)
        np.testing.assert_array_equal(np.isposinf(b), np.isposinf(a), err_msg=f)
        ok = np.isfinite(a)
        scale = 1e-8 if f == "kkt" else 1e-12 * max(np.abs(a[ok]).max(), 1e-300)  # kkt: round-off, scaled units
        np.testing.assert_allclose(b[ok], a[ok], rtol=1e-10, atol=scale, err_msg=f)
    assert seg.status_names[3] == "infeasible" and (seg.status == 0).sum() >= 4


def test_padding_contacts_read_as_inactive(padded_and_segmented):
    """Grasp 4 ran at width 2 with its contacts 1 and 3: its slots 0 and 2 hold exactly
    what the padded program writes for an inactive contact."""
    padded, seg, _, _, _ = padded_and_segmented
    for i, off in ((0, [2, 3]), (4, [0, 2]), (5, [2, 3])):
        got = seg[i]
        assert np.all(got.boundary_status[:, off] == LaneStatus.NO_START)
        assert np.all(np.isposinf(got.boundary_energy[:, off]))
        np.testing.assert_array_equal(got.boundary_translation[:, off],
                                      np.broadcast_to(got.equilibrium_translation, (2, 2, 3)))
        np.testing.assert_array_equal(got.equilibrium_margins[:, off], 1.0)
        rows = np.r_[1 + np.asarray(off), 1 + 4 + np.asarray(off)]
        assert np.isnan(got.kkt[rows]).all() and (got.steps[rows] == 0).all()
    assert abs(seg.equilibrium_translation[4, 2]) > 1e-6  # it sags: the padding's pose is not zero
    assert int(seg.limiting_contact[4]) in (1, 3)  # renumbered to the batch's slots
    assert int(seg.limiting_contact[4]) == int(padded.limiting_contact[4])


def test_chunks_report_their_rows_once_and_progress_adds_up(padded_and_segmented):
    _, seg, chunks, reports, _ = padded_and_segmented
    rows = np.concatenate([r for r, _ in chunks])
    assert sorted(rows.tolist()) == list(range(6))
    assert rows.tolist() != list(range(6))  # segments finish out of input order
    for r, res in chunks:
        for f in FIELDS:
            np.testing.assert_array_equal(res[f], np.asarray(getattr(seg, f))[r], err_msg=f)
    assert [t for _, t in reports] == [6] * len(chunks) and reports[-1][0] == 6
    assert all(a < b for (a, _), (b, _) in zip(reports, reports[1:]))


def test_a_segment_releases_its_program_when_the_next_begins(padded_and_segmented):
    """Programs are tens of MiB each: a run holds one at a time, the last one kept for
    the next call (the store keeps every one)."""
    *_, held = padded_and_segmented
    assert (2, 2, False) in held and (4, 2, True) not in held


def test_a_resumed_dataset_run_gives_every_grasp_its_uninterrupted_result(padded_and_segmented, tmp_path):
    """Widths come from the whole set, so rows left for a resumed run (here: grasps 1, 3
    and 4 of a set with an invalid row) run where an uninterrupted run ran them."""
    grasps = _grasps()
    path = tmp_path / "set.jsonl"
    jaxgrasp.save_dataset(path, [grasps[i] for i in (0, 1, 2, 3, 5)])
    lines = path.read_text().splitlines()
    bad = json.loads(lines[0])
    bad["fingertip"]["friction"] = -1
    path.write_text("\n".join(lines[:2] + [json.dumps(bad)] + lines[2:]) + "\n")
    gset = jaxgrasp.load_dataset(path)
    assert gset.errors[2] is not None and gset.num_contacts.tolist() == [2, 3, 0, 4, 2, 2]
    whole, _ = evaluate_dataset(gset, chunk_size=2, widths=FORCED)
    first = np.array([0, 3])
    done = (first, {f: np.asarray(getattr(whole, f))[first] for f in FIELDS})
    traced = _store.stats()["traced"]
    merged, run = evaluate_dataset(gset, done=done, chunk_size=2, widths=FORCED)
    assert len(run) == 3 and _store.stats()["traced"] == traced  # the programs of the first run, nothing compiled
    for f in FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(merged, f)), np.asarray(getattr(whole, f)), err_msg=f)
    assert merged.status_names[2] == "invalid"


# ------------------------------------------------------------------- the command's side


def test_progress_names_the_programs_and_counts_every_chunk(capsys):
    """The chunk records on the ``"jaxgrasp"`` logger, printed as the command prints them."""
    from jaxgrasp.engine import ChunkProgress
    from jaxgrasp.engine._store import log_lines_on_stderr

    plan = plan_segments(np.array([2] * 5 + [4] * 3), {2: 2, 4: 4}, chunk_size=2, devices=jax.devices()[:1])
    progress = ChunkProgress("evaluating", "grasp")
    with log_lines_on_stderr():
        progress.start(plan)
        for done in (2, 3, 5, 7, 8):  # 2 chunks of the 4-contact program, 3 of the 2-contact one
            progress(done, 8)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == ("jaxgrasp: evaluating 8 grasps in 5 chunks of up to 2, 2 programs by contact count "
                      "(4 contacts at width 4: 3 grasps; 2 contacts at width 2: 5 grasps; the first chunk of "
                      "each includes its compilation)")
    assert [line.split(" (")[0] for line in err[1:]] == [f"jaxgrasp: chunk {k}/5" for k in range(1, 6)]


def test_processes_plan_from_the_whole_sets_counts(monkeypatch):
    """Each process reads its share; the first meeting sums their counts, so every
    process plans the widths of the whole set (that a run of one process plans)."""
    from jaxgrasp.cli import _batch_processes as processes

    class Share:
        def __init__(self, counts):
            self.num_contacts = np.array(counts)
            self.valid = self.num_contacts > 0
            self.source_sha256 = "abc"

    def exchange(blob):  # process 0's facts and process 1's (a share of counts 2, 3, 7, 7)
        mine = json.loads(blob)
        theirs = dict(mine, contacts=7, valid=4, counts={"2": 1, "3": 1, "7": 2})
        return [blob, json.dumps(theirs).encode()]

    monkeypatch.setattr(processes, "exchange", exchange)
    n, counts = processes.agree_on_inputs((Share([2, 2, 0, 7]), 8), None)
    assert n == 7 and counts == {2: 3, 3: 1, 7: 3}
    assert plan_widths(counts) == plan_widths({2: 3, 3: 1, 7: 3})
