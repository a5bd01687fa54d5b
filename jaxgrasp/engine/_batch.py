"""Many grasps at once: :func:`evaluate_batch` and :func:`evaluate_dataset`.

::

    import jaxgrasp
    grasps = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(), jaxgrasp.load("examples/four_finger.json")]
    res = jaxgrasp.evaluate_batch(grasps)   # any contact counts: padded (jaxgrasp.stack)
    res.value, res.status_names              # (B,) J, names
    res.rank()[:10]                          # indices of the best grasps

The grasps are cut into segments by contact count, each run at its own width where that
pays for its compilation (:func:`~jaxgrasp.engine._plan.plan_segments`), and each segment
into chunks (:func:`~jaxgrasp.engine._plan.plan_chunks`), each
evaluated by the compiled pipeline (:func:`~jaxgrasp.engine._evaluator.chunk_evaluator`:
equal to ``jax.vmap(jaxgrasp.evaluate)`` grasp by grasp), split over every device, each
device running its own work queue on its slice (:func:`~jaxgrasp.engine._run.run_chunks`);
the last chunk is padded to the same size, so a set compiles once per chunk size, number
of contacts and options. Memory is bounded by the chunk size.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

import jax
import numpy as np

from jaxgrasp.engine._batch_result import BatchResult, assemble
from jaxgrasp.engine._evaluator import chunk_evaluator, grasp_fields, release_chunk_evaluator
from jaxgrasp.engine._plan import (
    ChunkPlan,
    SegmentPlan,
    check_chunk_size,
    grasps_by_count,
    plan_segments,
    plan_widths,
)
from jaxgrasp.engine._run import run_chunks
from jaxgrasp.engine._settling import INLINE
from jaxgrasp.engine._widths import contact_slots, narrow, widen
from jaxgrasp.io._dataset import GraspSet
from jaxgrasp.model._grasp import Grasp, stack
from jaxgrasp.model._validation import GraspValueError, check_batch_inputs
from jaxgrasp.tolerance._options import EvaluateOptions

__all__ = ["evaluate_batch", "evaluate_dataset", "start_progress"]


def _batched_fields(grasps) -> tuple[dict[str, np.ndarray], tuple]:
    """The fields of ``grasps`` (a sequence of :class:`Grasp`, one batched grasp, or a
    :class:`~jaxgrasp.GraspSet`), each with a leading ``B`` axis (padded to the largest
    contact count, with ``active``, where counts differ or a grasp has a mask), and each
    grasp's error (``None``: valid). Every valid grasp is validated (a set's columns were
    when they were made); an invalid one (a set's ``None``) is stood in for by the first
    valid grasp and has no active contact."""
    if isinstance(grasps, GraspSet):
        return _set_fields(grasps), tuple(grasps.errors)
    if isinstance(grasps, Grasp):
        batch = grasps
    else:
        items = list(grasps)
        if not items or not all(isinstance(g, Grasp) for g in items):
            raise GraspValueError(
                "evaluate_batch needs a non-empty sequence of jaxgrasp.Grasp, one batched Grasp or a GraspSet"
            )
        counts = {g.num_contacts for g in items}
        masked = len(counts) > 1 or any(g.active is not None for g in items)
        batch = stack(items)  # per-contact fields given as scalars broadcast: any mix stacks
        batch = batch if masked else batch.replace(active=None)
    pos = np.shape(batch.positions)
    if len(pos) != 3:
        raise GraspValueError(f"evaluate_batch needs grasps with a batch axis: positions (B, N, 3), got {pos}")
    fields = batch.to_numpy_batch()
    check_batch_inputs(fields)
    return fields, (None,) * pos[0]


def _set_fields(gset: GraspSet, rows: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The columns of a set (:meth:`~jaxgrasp.GraspSet.columns`, not copied) with
    ``active`` where the grasps of ``rows`` (default all) differ in contact count."""
    columns = gset.columns()
    if not columns.valid.any():
        raise GraspValueError(f"{gset.source}: no valid grasp to evaluate (first: {gset.errors[0]})")
    counts = columns.counts if rows is None else columns.counts[rows]
    fields = dict(columns.fields)
    if np.any(counts != fields["positions"].shape[1]):
        fields["active"] = columns.active
    return fields


def start_progress(progress, plan: ChunkPlan | SegmentPlan) -> None:
    """Tell ``progress`` the plan before the first chunk, where it asks (an object with a
    ``start(plan)`` method, such as the command line's progress lines)."""
    start = getattr(progress, "start", None)
    if callable(start):
        start(plan)


def evaluate_batch(
    grasps,
    /,
    *,
    options: EvaluateOptions = EvaluateOptions(),
    chunk_size: int | None = None,
    progress: Callable[[int, int], Any] | None = None,
    on_chunk: Callable[[np.ndarray, Mapping[str, np.ndarray]], Any] | None = None,
    devices=None,
) -> BatchResult:
    """Evaluate many grasps in chunks of compiled evaluators; every result equals
    :func:`jaxgrasp.evaluate` of that grasp.

    Grasps of different contact counts are padded to the widest (inactive contacts), in
    one compiled program; where a count has enough grasps to pay for a compilation of
    its own (tens of thousands on a CPU), its grasps run in a narrower program
    (:func:`~jaxgrasp.engine._plan.plan_widths`), which costs a 2-contact grasp half of
    what it costs padded to 7. The widths depend on the batch's contact counts only; the
    results are laid out at the widest count either way.

    Args:
        grasps: a sequence of :class:`~jaxgrasp.Grasp` (any contact counts: they are
            padded with inactive contacts, :func:`jaxgrasp.stack`), one batched grasp
            (leading axis ``B``; fields without it are shared by every grasp), or a
            :class:`~jaxgrasp.GraspSet` from :func:`jaxgrasp.load_dataset`, whose invalid
            grasps are not evaluated: their status is ``invalid`` and their error kept.
        options: :class:`~jaxgrasp.EvaluateOptions` of every evaluation.
        chunk_size: grasps per compiled call, at most (bounds memory; default 64 per CPU
            device, 1024 per accelerator); the chunk is the smallest bucket (1, 4, 16, 64,
            ... per device) that holds them, so batches of different sizes share
            compilations (:func:`~jaxgrasp.engine._plan.plan_chunks`).
        progress: ``progress(done, total)`` after each chunk (an object with a
            ``start(plan)`` method is also told the plan before the first: a
            :class:`~jaxgrasp.engine._plan.SegmentPlan`).
        on_chunk: ``on_chunk(rows, results)`` after each chunk (before ``progress``):
            ``rows`` the input indices of its grasps (segments by contact count finish
            out of input order), ``results`` each :class:`~jaxgrasp.Evaluation` field for
            them (leading axis ``len(rows)``, contacts laid out as in the result).
        devices: the devices each chunk is sharded over (default ``jax.devices()``,
            which after ``jax.distributed.initialize()`` spans every host).

    Returns:
        A :class:`~jaxgrasp.BatchResult`: every :class:`~jaxgrasp.Evaluation` field with
        a leading ``B`` axis, in input order.

    Raises:
        GraspValueError: before anything is compiled: the first invalid grasp of a
            sequence or batched grasp (a set keeps them as rows), or a set without a valid one.
    """
    check_chunk_size(chunk_size)  # before the grasps: nothing is validated for a bad call
    fields, errors = _batched_fields(grasps)
    return _evaluate_fields(fields, errors, chunk_size, devices, options, progress, on_chunk)


def _evaluate_fields(fields: dict[str, np.ndarray], errors, chunk_size, devices, options: EvaluateOptions,
                     progress, on_chunk, rows: np.ndarray | None = None, widths=None) -> BatchResult:
    """:func:`evaluate_batch` of validated fields (:func:`_batched_fields`): the valid
    ``rows`` (default every row whose error is ``None``) in segments by contact count
    (:func:`~jaxgrasp.engine._plan.plan_segments`, by ``widths``, default
    :func:`~jaxgrasp.engine._plan.plan_widths` of these rows' counts), each gathered a
    chunk at a time. ``on_chunk(rows, results)`` after each chunk. The result has a row
    for every row of ``fields``."""
    total, n_contacts = fields["positions"].shape[:2]
    rows = np.flatnonzero([e is None for e in errors]) if rows is None else rows
    active = fields.get("active")
    counts = np.full(rows.size, n_contacts) if active is None else active[rows].sum(axis=1)
    if widths is None:
        widths = plan_widths(grasps_by_count(counts), _platform(devices))
    plan = plan_segments(counts, widths, chunk_size, devices)
    outs, compile_seconds, run_seconds = _run_segments(fields, rows, plan, options, progress, on_chunk)
    if rows.size != total:  # rows not evaluated (invalid): marked by assemble
        outs = {f: _scattered(a, rows, total) for f, a in outs.items()}
    invalid = np.setdiff1d(np.arange(total), rows)
    full = np.ones((total, n_contacts), dtype=bool) if active is None else active
    return assemble([(np.arange(total), outs)], total, invalid, full, errors,
                    compile_seconds=compile_seconds, run_seconds=run_seconds, devices=plan.n_devices)


def _platform(devices) -> str:
    return (jax.devices() if devices is None else list(devices))[0].platform


def _scattered(a: np.ndarray, rows: np.ndarray, total: int) -> np.ndarray:
    out = np.empty((total, *a.shape[1:]), dtype=a.dtype)
    out[rows] = a
    return out


def _run_segments(fields: Mapping[str, np.ndarray], rows: np.ndarray, plan: SegmentPlan, options: EvaluateOptions,
                  progress, on_chunk) -> tuple[dict[str, np.ndarray], float, float]:
    """Evaluate the grasps ``rows`` of ``fields`` by ``plan``, segment after segment:
    ``(results, compile seconds, run seconds)``, each :class:`~jaxgrasp.Evaluation` field
    ``(len(rows), ...)`` in the order of ``rows``, at the width of ``fields``."""
    n_contacts = fields["positions"].shape[1]
    start_progress(progress, plan)  # before the compilation, which the first chunk's time includes
    outs: dict[str, np.ndarray] = {}
    compile_seconds = run_seconds = 0.0
    done = 0
    for seg in plan.segments:
        fn, seconds, settling = chunk_evaluator(INLINE, options, seg.width, seg.plan, seg.masked)
        compile_seconds += seconds
        picked = rows[seg.at]

        slots_of: dict[int, np.ndarray] = {}  # each chunk's contact slots, from its gathering to its results

        def chunk_fields(start: int, seg=seg, picked=picked, slots_of=slots_of) -> dict[str, np.ndarray]:
            chunk = _chunk_of(fields, start, seg.plan.chunk, picked, keep_padding_active=not seg.masked)
            slots_of[start] = contact_slots(chunk.get("active"), seg.width, seg.plan.chunk)
            return narrow(chunk, slots_of[start], seg.masked)

        def finished(start: int, stop: int, res: Mapping[str, np.ndarray], seg=seg, picked=picked,
                     slots_of=slots_of) -> None:
            slots = slots_of.pop(start)[: stop - start]
            wide = widen({f: a[start:stop] for f, a in res.items()}, slots, n_contacts)
            for f, a in wide.items():
                if f not in outs:
                    outs[f] = np.empty((rows.size, *a.shape[1:]), dtype=a.dtype)
                outs[f][seg.at[start:stop]] = a
            if on_chunk is not None:
                on_chunk(picked[start:stop], wide)

        def reported(stop: int, _total: int, before=done) -> None:
            if progress is not None:
                progress(before + stop, plan.total)

        _, seconds = run_chunks(fn, chunk_fields, grasp_fields(seg.masked), seg.plan, reported, finished,
                                settling=settling)
        run_seconds += seconds
        done += seg.plan.total
        if seg is not plan.segments[-1]:  # one program held at a time (the store keeps them all)
            del fn, settling
            release_chunk_evaluator(INLINE, options, seg.width, seg.plan, seg.masked)
    return outs, compile_seconds, run_seconds


def _chunk_of(fields: Mapping[str, np.ndarray], start: int, chunk: int, rows: np.ndarray | None = None,
              keep_padding_active: bool = False) -> dict[str, np.ndarray]:
    """The fields of grasps ``start .. start + chunk - 1`` (of ``rows`` of ``fields``,
    default all), padded with the last grasp, its contacts inactive where there is a
    mask (unless ``keep_padding_active``: a program without a mask evaluates the
    repeats), so that the padding solves nothing. Only the chunk is copied."""
    total = fields["positions"].shape[0] if rows is None else len(rows)
    idx = np.arange(start, start + chunk)
    pick = np.minimum(idx, total - 1)
    pick = pick if rows is None else rows[pick]
    out = {k: v[pick] for k, v in fields.items()}
    if "active" in out and not keep_padding_active:
        out["active"] = out["active"] & (idx < total)[:, None]
    return out


def evaluate_dataset(
    dataset: GraspSet,
    /,
    *,
    done: tuple[np.ndarray, Mapping[str, np.ndarray]] | None = None,
    on_chunk_rows: Callable[[np.ndarray, Mapping[str, np.ndarray]], Any] | None = None,
    options: EvaluateOptions = EvaluateOptions(),
    chunk_size: int | None = None,
    progress: Callable[[int, int], Any] | None = None,
    devices=None,
    widths: Mapping[int, int] | None = None,
) -> tuple[BatchResult, BatchResult | None]:
    """Evaluate the valid grasps of ``dataset`` that are not ``done`` yet, and merge.

    Args:
        dataset: a :class:`~jaxgrasp.GraspSet` (:func:`jaxgrasp.load_dataset`).
        done: ``(rows, results)``: input rows an earlier run finished and their
            :class:`~jaxgrasp.Evaluation` fields (a checkpoint's,
            :meth:`~jaxgrasp.engine._checkpoint.BatchCheckpoint.open`).
        on_chunk_rows: ``on_chunk_rows(rows, results)`` after each chunk, with its input
            rows and their results (to keep them in a checkpoint,
            :meth:`~jaxgrasp.engine._checkpoint.BatchCheckpoint.keeper`).
        options, chunk_size, progress, devices: as :func:`evaluate_batch`. Each chunk's
            grasps are gathered from the dataset's columns
            (:class:`~jaxgrasp.io._dataset.GraspColumns`) when it runs: beyond the
            columns, memory grows with the chunk and the results, not with a copy of
            the set.
        widths: the width each contact count runs at (default
            :func:`~jaxgrasp.engine._plan.plan_widths` of the dataset's valid grasps'
            counts, all of them, done or not: so a resumed run evaluates every grasp at
            the width an uninterrupted one does, and compiles what it did).

    Returns:
        ``(every row, this run)``: the :class:`~jaxgrasp.BatchResult` of every row of the
        dataset (the earlier run's, this run's and the invalid ones, in input order), and
        that of the grasps evaluated now (``None`` when none was left).
    """
    rows, results = done if done is not None else (np.zeros(0, dtype=np.int64), {})
    columns = dataset.columns()
    todo = np.flatnonzero(columns.valid & ~np.isin(np.arange(len(dataset)), rows))
    parts = [(rows, results)] if rows.size else []
    run = None
    if todo.size:
        fields = dict(columns.fields, active=columns.active)
        if widths is None:
            widths = plan_widths(grasps_by_count(columns.counts), _platform(devices))
        plan = plan_segments(columns.counts[todo], widths, chunk_size, devices)
        outs, compile_seconds, run_seconds = _run_segments(fields, todo, plan, options, progress, on_chunk_rows)
        run = assemble([(np.arange(todo.size), outs)], todo.size, [], columns.active[todo], (None,) * todo.size,
                       compile_seconds=compile_seconds, run_seconds=run_seconds, devices=plan.n_devices)
        parts.append((todo, outs))
    timings = {} if run is None else dict(
        compile_seconds=run.compile_seconds, run_seconds=run.run_seconds, devices=run.devices
    )
    return assemble(parts, len(dataset), ~columns.valid, columns.active, dataset.errors, **timings), run
