"""Many grasps at once: :func:`evaluate_batch` and :func:`evaluate_dataset`.

::

    import jaxgrasp
    grasps = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(), jaxgrasp.load("examples/four_finger.json")]
    res = jaxgrasp.evaluate_batch(grasps)   # any contact counts: padded (jaxgrasp.stack)
    res.value, res.status_names              # (B,) J, names
    res.rank()[:10]                          # indices of the best grasps

The grasps are cut into chunks (:func:`~jaxgrasp.engine._plan.plan_chunks`), each
evaluated by the compiled pipeline (:func:`~jaxgrasp.engine._evaluator.chunk_evaluator`:
equal to ``jax.vmap(jaxgrasp.evaluate)`` grasp by grasp), split over every device, each
device running its own work queue on its slice (:func:`~jaxgrasp.engine._run.run_chunks`);
the last chunk is padded to the same size, so a set compiles once per chunk size, number
of contacts and options. Memory is bounded by the chunk size.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from jaxgrasp.engine._batch_result import BatchResult, assemble, mark_invalid
from jaxgrasp.engine._evaluator import chunk_evaluator, grasp_fields
from jaxgrasp.engine._plan import ChunkPlan, check_chunk_size, plan_chunks
from jaxgrasp.engine._run import run_chunks
from jaxgrasp.io._dataset import GraspSet
from jaxgrasp.model._grasp import Grasp, stack
from jaxgrasp.model._validation import GraspValueError, check_batch_inputs
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._result import FIELDS

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


def start_progress(progress, plan: ChunkPlan) -> None:
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
    on_chunk: Callable[[int, int, Mapping[str, np.ndarray]], Any] | None = None,
    devices=None,
) -> BatchResult:
    """Evaluate many grasps in chunks of one compiled evaluator; every result equals
    :func:`jaxgrasp.evaluate` of that grasp.

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
            ``start(plan)`` method is also told the chunk plan before the first).
        on_chunk: ``on_chunk(start, stop, results)`` after each chunk (before
            ``progress``): grasps ``start .. stop - 1`` and all before are done;
            ``results`` maps each :class:`~jaxgrasp.Evaluation` field to a ``(B, ...)``
            array whose first ``stop`` rows are final (the engine's own buffers: read,
            never write).
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
    return _evaluate_fields(fields, errors, plan_chunks(len(errors), chunk_size, devices), options, progress, on_chunk)


def _evaluate_fields(fields: dict[str, np.ndarray], errors, plan: ChunkPlan, options: EvaluateOptions,
                     progress, on_chunk, rows: np.ndarray | None = None) -> BatchResult:
    """:func:`evaluate_batch` of validated fields (:func:`_batched_fields`) by ``plan``;
    ``rows``: the rows of ``fields`` to evaluate, in order (default all), gathered a chunk
    at a time."""
    masked = "active" in fields
    start_progress(progress, plan)  # before the compilation, which the first chunk's time includes
    fn, compile_seconds, settling = chunk_evaluator("batch", options, fields["positions"].shape[1], plan, masked)
    invalid = np.flatnonzero([e is not None for e in errors])

    def finished(start: int, stop: int, outs: dict[str, np.ndarray]) -> None:
        mark_invalid(outs, invalid[(invalid >= start) & (invalid < stop)])
        if on_chunk is not None:
            on_chunk(start, stop, outs)

    outs, run_seconds = run_chunks(
        fn, lambda start: _chunk_of(fields, start, plan.chunk, rows), grasp_fields(masked), plan, progress, finished,
        settling=settling,
    )
    shape = (plan.total, fields["positions"].shape[1])
    active = np.ones(shape, dtype=bool) if "active" not in fields else (
        fields["active"] if rows is None else fields["active"][rows])
    return assemble([(np.arange(plan.total), outs)], plan.total, invalid, active, errors,
                    compile_seconds=compile_seconds, run_seconds=run_seconds, devices=plan.n_devices)


def _chunk_of(fields: Mapping[str, np.ndarray], start: int, chunk: int, rows: np.ndarray | None = None
              ) -> dict[str, np.ndarray]:
    """The fields of grasps ``start .. start + chunk - 1`` (of ``rows`` of ``fields``,
    default all), padded with the last grasp, its contacts inactive where there is a
    mask, so that the padding solves nothing. Only the chunk is copied."""
    total = fields["positions"].shape[0] if rows is None else len(rows)
    idx = np.arange(start, start + chunk)
    pick = np.minimum(idx, total - 1)
    pick = pick if rows is None else rows[pick]
    out = {k: v[pick] for k, v in fields.items()}
    if "active" in out:
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
        options, chunk_size, progress, devices: as :func:`evaluate_batch`. Grasps are
            padded to the dataset's largest contact count, so a resumed run compiles what
            the first one did. Each chunk's grasps are gathered from the dataset's
            columns (:class:`~jaxgrasp.io._dataset.GraspColumns`) when it runs: beyond
            the columns, memory grows with the chunk and the results, not with a copy
            of the set.

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
        check_chunk_size(chunk_size)
        fields = _set_fields(dataset, todo)
        keep = None if on_chunk_rows is None else (
            lambda start, stop, res: on_chunk_rows(todo[start:stop], {f: a[start:stop] for f, a in res.items()})
        )
        run = _evaluate_fields(fields, (None,) * todo.size, plan_chunks(todo.size, chunk_size, devices), options,
                               progress, keep, rows=todo)
        parts.append((todo, {f: getattr(run, f) for f in FIELDS}))
    timings = {} if run is None else dict(
        compile_seconds=run.compile_seconds, run_seconds=run.run_seconds, devices=run.devices
    )
    return assemble(parts, len(dataset), ~columns.valid, columns.active, dataset.errors, **timings), run
