"""Many grasps at once: [`evaluate_batch`][jaxgrasp.evaluate_batch] and `evaluate_dataset`.

::

    import jaxgrasp
    grasps = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(), jaxgrasp.load("examples/four_finger.json")]
    res = jaxgrasp.evaluate_batch(grasps)   # any contact counts: padded (jaxgrasp.stack)
    res.value, res.status_names              # (B,) J, names
    res.rank()[:10]                          # indices of the best grasps

Both are adapters over the engine's one batch runner
(`run_batch`, a `Stacked`
source): the grasps are cut into segments by contact count, each run at its own width
where that pays for its compilation (`plan_segments`), and
each segment into chunks (`plan_chunks`), each evaluated by
the compiled pipeline (`chunk_evaluator`, the settling
stage inline), split over every device, each device running its own work queue on its
slice (`run_chunks`); the last chunk is padded to the same
size, so a set compiles once per chunk size, number of contacts and options. Memory is
bounded by the chunk size. Each result equals [`jaxgrasp.evaluate`][jaxgrasp.evaluate]'s within the
solver's precision (``tests/engine/test_single_vs_batch.py``).
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from jaxgrasp.engine._batch_result import BatchResult, assemble
from jaxgrasp.engine._plan import check_chunk_size, grasps_by_count, plan_widths
from jaxgrasp.engine._runner import Run, Stacked, plan_source, platform, run_batch
from jaxgrasp.engine._settling import INLINE
from jaxgrasp.io import GraspSet
from jaxgrasp.model import Grasp, GraspValueError, check_batch_inputs, stack
from jaxgrasp.tolerance import EvaluateOptions

__all__ = ["evaluate_batch", "evaluate_dataset", "evaluate_in_chunks"]


def _batched_fields(grasps) -> tuple[dict[str, np.ndarray], tuple]:
    """The fields of ``grasps`` (a sequence of [`Grasp`][jaxgrasp.Grasp], one batched grasp, or a
    [`GraspSet`][jaxgrasp.GraspSet]), each with a leading ``B`` axis (padded to the largest
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
    """The columns of a set ([`columns`][jaxgrasp.GraspSet.columns], not copied) with
    ``active`` where the grasps of ``rows`` (default all) differ in contact count."""
    columns = gset.columns()
    if not columns.valid.any():
        raise GraspValueError(f"{gset.source}: no valid grasp to evaluate (first: {gset.errors[0]})")
    counts = columns.counts if rows is None else columns.counts[rows]
    fields = dict(columns.fields)
    if np.any(counts != fields["positions"].shape[1]):
        fields["active"] = columns.active
    return fields


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
    [`jaxgrasp.evaluate`][jaxgrasp.evaluate] of that grasp to the solver's precision (the same status and
    limiting boundary; energies within ``1e-12`` of ``|U0|``: another program, whose
    solver takes other steps to the same minima).

    Grasps of different contact counts are padded to the widest (inactive contacts), in
    one compiled program; where a count has enough grasps to pay for a compilation of
    its own (tens of thousands on a CPU), its grasps run in a narrower program
    (`plan_widths`), which costs a 2-contact grasp half of
    what it costs padded to 7. The widths depend on the batch's contact counts only; the
    results are laid out at the widest count either way.

    Args:
        grasps: a sequence of [`Grasp`][jaxgrasp.Grasp] (any contact counts: they are
            padded with inactive contacts, [`jaxgrasp.stack`][jaxgrasp.stack]), one batched grasp
            (leading axis ``B``; fields without it are shared by every grasp), or a
            [`GraspSet`][jaxgrasp.GraspSet] from [`jaxgrasp.load_dataset`][jaxgrasp.load_dataset], whose invalid
            grasps are not evaluated: their status is ``invalid`` and their error kept.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] of every evaluation.
        chunk_size: grasps per compiled call, at most (bounds memory; default 64 per CPU
            device, 1024 per accelerator); the chunk is the smallest bucket (1, 4, 16, 64,
            ... per device) that holds them, so batches of different sizes share
            compilations (`plan_chunks`).
        progress: ``progress(done, total)`` after each chunk (an object with a
            ``start(plan)`` method is also told the plan before the first: a
            `SegmentPlan`).
        on_chunk: ``on_chunk(rows, results)`` after each chunk (before ``progress``):
            ``rows`` the input indices of its grasps (segments by contact count finish
            out of input order), ``results`` each [`Evaluation`][jaxgrasp.Evaluation] field for
            them (leading axis ``len(rows)``, contacts laid out as in the result).
        devices: the devices each chunk is sharded over (default ``jax.devices()``,
            which after ``jax.distributed.initialize()`` spans every host).

    Returns:
        A [`BatchResult`][jaxgrasp.BatchResult]: every [`Evaluation`][jaxgrasp.Evaluation] field with
        a leading ``B`` axis, in input order.

    Raises:
        GraspValueError: before anything is compiled: the first invalid grasp of a
            sequence or batched grasp (a set keeps them as rows), or a set without a valid one.
    """
    check_chunk_size(chunk_size)  # before the grasps: nothing is validated for a bad call
    fields, errors = _batched_fields(grasps)
    return _evaluate_fields(fields, errors, chunk_size, devices, options, progress, on_chunk)


def evaluate_in_chunks(grasps, chunk: int, /, *, options: EvaluateOptions = EvaluateOptions(), devices=None,
                       progress: Callable[[int, int], Any] | None = None) -> BatchResult:
    """[`evaluate_batch`][jaxgrasp.evaluate_batch] of ``grasps`` in chunks of exactly ``chunk`` grasps however
    few there are (`plan_source`'s ``exact_chunk``): a few
    grasps run in the program compiled for a larger run of the same width (a robust
    evaluation's nominal grasps in its samples', a plan's candidates in one program
    whatever their number); each grasp's result is the one it has in that program.
    ``options``, ``devices``, ``progress``: as [`evaluate_batch`][jaxgrasp.evaluate_batch]."""
    check_chunk_size(chunk)
    fields, errors = _batched_fields(grasps)
    return _evaluate_fields(fields, errors, chunk, devices, options, progress, None, exact_chunk=True)


def _evaluate_fields(fields: dict[str, np.ndarray], errors, chunk_size, devices, options: EvaluateOptions,
                     progress, on_chunk, exact_chunk: bool = False) -> BatchResult:
    """[`evaluate_batch`][jaxgrasp.evaluate_batch] of validated fields (`_batched_fields`): the rows whose
    error is ``None`` through the runner (`_run`). The result has a row for every
    row of ``fields``."""
    total, n_contacts = fields["positions"].shape[:2]
    rows = np.flatnonzero([e is None for e in errors])
    active = fields.get("active")
    run = _run(Stacked(fields, rows), None, chunk_size, devices, options, progress, on_chunk, exact_chunk)
    outs = run.results
    if rows.size != total:  # rows not evaluated (invalid): marked by assemble
        outs = {f: _scattered(a, rows, total) for f, a in outs.items()}
    invalid = np.setdiff1d(np.arange(total), rows)
    full = np.ones((total, n_contacts), dtype=bool) if active is None else active
    return assemble([(np.arange(total), outs)], total, invalid, full, errors, **_timings(run))


def _run(source: Stacked, widths, chunk_size, devices, options: EvaluateOptions, progress, on_chunk,
         exact_chunk: bool = False) -> Run:
    """The grasps of ``source`` through `run_batch`, at
    ``widths`` (``None``: `plan_source`'s default, `plan_widths` of their counts), the
    settling stage inline (a set of varied grasps, `_settling`);
    ``on_chunk(rows, results)`` with the rows of ``source.fields``."""
    plan = plan_source(source, chunk_size, devices, widths, exact_chunk=exact_chunk)
    rows_of = None if on_chunk is None else (lambda at, results: on_chunk(source.rows[at], results))
    return run_batch(source, plan, options, settle=INLINE, progress=progress, on_chunk=rows_of)


def _timings(run: Run | BatchResult) -> dict:
    return dict(compile_seconds=run.compile_seconds, run_seconds=run.run_seconds, devices=run.devices)


def _scattered(a: np.ndarray, rows: np.ndarray, total: int) -> np.ndarray:
    out = np.empty((total, *a.shape[1:]), dtype=a.dtype)
    out[rows] = a
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
        dataset: a [`GraspSet`][jaxgrasp.GraspSet] ([`jaxgrasp.load_dataset`][jaxgrasp.load_dataset]).
        done: ``(rows, results)``: input rows an earlier run finished and their
            [`Evaluation`][jaxgrasp.Evaluation] fields (a checkpoint's,
            `open`).
        on_chunk_rows: ``on_chunk_rows(rows, results)`` after each chunk, with its input
            rows and their results (to keep them in a checkpoint,
            `keeper`).
        options, chunk_size, progress, devices: as [`evaluate_batch`][jaxgrasp.evaluate_batch]. Each chunk's
            grasps are gathered from the dataset's columns
            (`GraspColumns`) when it runs: beyond the
            columns, memory grows with the chunk and the results, not with a copy of
            the set.
        widths: the width each contact count runs at (default
            `plan_widths` of the dataset's valid grasps'
            counts, all of them, done or not: so a resumed run evaluates every grasp at
            the width an uninterrupted one does, and compiles what it did).

    Returns:
        ``(every row, this run)``: the [`BatchResult`][jaxgrasp.BatchResult] of every row of the
        dataset (the earlier run's, this run's and the invalid ones, in input order), and
        that of the grasps evaluated now (``None`` when none was left).
    """
    rows, results = done if done is not None else (np.zeros(0, dtype=np.int64), {})
    columns = dataset.columns()
    todo = np.flatnonzero(columns.valid & ~np.isin(np.arange(len(dataset)), rows))
    parts = [(rows, results)] if rows.size else []
    run = None
    if todo.size:
        if widths is None:  # of every valid grasp, done or not: a resumed run runs at the same widths
            widths = plan_widths(grasps_by_count(columns.counts), platform(devices))
        ran = _run(Stacked(dict(columns.fields, active=columns.active), todo), widths, chunk_size, devices, options,
                   progress, on_chunk_rows)
        run = assemble([(np.arange(todo.size), ran.results)], todo.size, [], columns.active[todo],
                       (None,) * todo.size, **_timings(ran))
        parts.append((todo, ran.results))
    timings = {} if run is None else _timings(run)
    return assemble(parts, len(dataset), ~columns.valid, columns.active, dataset.errors, **timings), run
