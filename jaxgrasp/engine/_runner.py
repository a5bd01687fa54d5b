"""The one batch runner: a source of grasp fields in, every grasp's evaluation out.

Every batch of jaxgrasp runs here: [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] and
`jaxgrasp.evaluate_dataset` (stacked grasps, a dataset's rows not done yet),
[`jaxgrasp.sweep`][jaxgrasp.sweep] (a grid), [`jaxgrasp.robust_batch`][jaxgrasp.robust_batch] (perturbed copies) and
[`jaxgrasp.plan`][jaxgrasp.plan] (candidates) are adapters that make a source and read the results.

A source (`GraspSource`) says how many grasps it has, their contact counts and the
fields of any of them. `plan_source` cuts them into segments by contact count, each
at its width (`plan_widths`), each into chunks
(`plan_segments`); `run_batch` gathers each chunk from
the source when it runs (narrowed to its segment's width,
`_widths`), evaluates it over the devices by the settling policy it
is given (`_settling`, `run_chunks`)
and lays the results out at the source's width, in the source's order.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, Protocol

import jax
import numpy as np

from jaxgrasp.engine._evaluator import chunk_evaluator, grasp_fields, release_chunk_evaluator
from jaxgrasp.engine._plan import (
    ChunkPlan,
    Segment,
    SegmentPlan,
    bucket_size,
    grasps_by_count,
    plan_segments,
    plan_widths,
)
from jaxgrasp.engine._progress import chunk_progress
from jaxgrasp.engine._run import run_chunks
from jaxgrasp.engine._widths import contact_slots, narrow, widen
from jaxgrasp.tolerance import FIELDS as RESULT_FIELDS
from jaxgrasp.tolerance import EvaluateOptions

__all__ = ["GraspSource", "Stacked", "Run", "plan_source", "run_batch", "start_progress"]


class GraspSource(Protocol):
    """What `run_batch` evaluates: ``size`` grasps of at most ``width`` contacts.

    Attributes:
        size: the grasps, numbered ``0 .. size - 1`` (the results' order).
        width: contacts of the layout ``N`` (of its fields and of the results).
    """

    size: int
    width: int

    def counts(self) -> np.ndarray:
        """``(size,)`` int, each grasp's contacts (``1 .. width``)."""

    def gather(self, at: np.ndarray) -> dict[str, np.ndarray]:
        """The [`Grasp`][jaxgrasp.Grasp] fields of grasps ``at`` ``(K,)`` (each in
        ``0 .. size - 1``, repeats allowed), each with a leading axis ``K`` (SI units;
        ``active`` ``(K, N)`` where the grasps have a contact mask)."""


@dataclasses.dataclass(frozen=True)
class Stacked:
    """The rows ``rows`` ``(size,)`` of stacked grasp ``fields`` (each ``(B, ...)``, SI
    units, ``active`` ``(B, N)`` where there is a mask) as a `GraspSource`: grasp
    ``k`` is row ``rows[k]``. Only a chunk's rows are copied, when it runs."""

    fields: Mapping[str, np.ndarray]
    rows: np.ndarray

    @property
    def size(self) -> int:
        return int(self.rows.size)

    @property
    def width(self) -> int:
        return int(self.fields["positions"].shape[1])

    def counts(self) -> np.ndarray:
        active = self.fields.get("active")
        return np.full(self.size, self.width) if active is None else active[self.rows].sum(axis=1)

    def gather(self, at: np.ndarray) -> dict[str, np.ndarray]:
        pick = self.rows[at]
        return {k: v[pick] for k, v in self.fields.items()}


@dataclasses.dataclass(frozen=True)
class Run:
    """What `run_batch` gives.

    Attributes:
        results: [`Evaluation`][jaxgrasp.Evaluation] fields by name (those asked for), each
            ``(size, ...)`` in the source's order, contacts laid out at its ``width``.
        compile_seconds: time spent compiling (or loading) the programs, s.
        run_seconds: time spent evaluating the chunks, s.
        devices: the devices each chunk was split over.
    """

    results: dict[str, np.ndarray]
    compile_seconds: float
    run_seconds: float
    devices: int


def start_progress(progress, plan: ChunkPlan | SegmentPlan, verb: str = "evaluating", noun: str = "grasp"):
    """The progress report of a run: ``progress``, or where it is ``None`` the engine's
    chunk records on the ``"jaxgrasp"`` logger (`ChunkProgress`
    of ``verb`` and ``noun``); told the plan before the first chunk, where it asks (an
    object with a ``start(plan)`` method, such as `ChunkProgress`)."""
    progress = chunk_progress(progress, verb, noun)
    start = getattr(progress, "start", None)
    if callable(start):
        start(plan)
    return progress


def platform(devices) -> str:
    """The platform of ``devices`` (default ``jax.devices()``): ``"cpu"``, ``"gpu"`` ..."""
    return (jax.devices() if devices is None else list(devices))[0].platform


def plan_source(source: GraspSource, chunk_size: int | None = None, devices=None,
                widths: Mapping[int, int] | None = None, *, exact_chunk: bool = False) -> SegmentPlan:
    """The segments and chunks of ``source``'s grasps
    (`plan_segments`) at ``widths`` (default
    `plan_widths` of the source's counts, on the devices'
    platform; a resumed run gives those of the whole set it belongs to).

    With ``exact_chunk`` every segment's chunk is ``chunk_size`` (rounded up to a multiple
    of the devices) however few grasps it has, not the smallest bucket that holds them: a
    few grasps run in the program compiled for a larger run (a robust evaluation's
    nominal grasps in its samples', a plan's candidates in one program whatever their
    number), the last chunk padded as always."""
    counts = source.counts()
    if widths is None:
        widths = plan_widths(grasps_by_count(counts), platform(devices))
    plan = plan_segments(counts, widths, chunk_size, devices)
    if not exact_chunk or chunk_size is None:
        return plan
    chunk = bucket_size(chunk_size, chunk_size, plan.n_devices)
    segments = tuple(dataclasses.replace(s, plan=ChunkPlan(s.plan.total, chunk, plan.devices)) for s in plan.segments)
    return SegmentPlan(segments, plan.devices)


def run_batch(source: GraspSource, plan: SegmentPlan, options: EvaluateOptions = EvaluateOptions(), *,
              settle: str, keep: tuple[str, ...] = RESULT_FIELDS, progress: Callable[[int, int], Any] | None = None,
              on_chunk: Callable[[np.ndarray, Mapping[str, np.ndarray]], Any] | None = None,
              results: dict[str, np.ndarray] | None = None, verb: str = "evaluating", noun: str = "grasp") -> Run:
    """Evaluate every grasp of ``source`` by ``plan`` (`plan_source`), segment after
    segment, chunk after chunk; a grasp's result does not depend on the other grasps of
    its chunk (each lane is its own), and is [`jaxgrasp.evaluate`][jaxgrasp.evaluate]'s within the bound
    that ``tests/engine/test_single_vs_batch.py`` states (two programs, one method).

    Args:
        source: a `GraspSource`.
        plan: its `SegmentPlan`.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] of every evaluation.
        settle: the settling policy (`INLINE` or
            `RETRY`).
        keep: the [`Evaluation`][jaxgrasp.Evaluation] fields to keep (of `RESULT_FIELDS`).
        progress: ``progress(done, total)`` after each chunk (``start(plan)`` first, where
            it has one); ``None``: chunk records on the ``"jaxgrasp"`` logger, saying
            ``verb`` and ``noun`` (`start_progress`).
        on_chunk: ``on_chunk(at, results)`` after each chunk (before ``progress``): ``at``
            ``(K,)`` the source's numbers of its grasps (segments finish out of order),
            ``results`` the ``keep`` fields for them (leading axis ``K``, width ``N``).
        results: a dict the result arrays are put in, as each is first written (for a
            caller that reads them while the run goes on); default a new one.

    Returns:
        A `Run`.
    """
    progress = start_progress(progress, plan, verb, noun)  # before the compilation, which the first chunk's time includes
    outs = {} if results is None else results
    compile_seconds = run_seconds = 0.0
    done = 0
    for seg in plan.segments:
        fn, seconds, settling = chunk_evaluator(settle, options, seg.width, seg.plan, seg.masked)
        compile_seconds += seconds
        chunk_fields, finished = _segment_io(source, seg, keep, outs, on_chunk)

        def reported(stop: int, _total: int, before=done) -> None:
            if progress is not None:
                progress(before + stop, plan.total)

        run_seconds += run_chunks(fn, chunk_fields, grasp_fields(seg.masked), seg.plan, reported, finished,
                                  keep=keep, settling=settling)
        done += seg.plan.total
        if seg is not plan.segments[-1]:  # one program held at a time (the store keeps them all)
            del fn, settling
            release_chunk_evaluator(settle, options, seg.width, seg.plan, seg.masked)
    return Run(outs, compile_seconds, run_seconds, plan.n_devices)


def _segment_io(source: GraspSource, seg: Segment, keep, outs: dict, on_chunk):
    """``(chunk_fields, finished)`` of `run_chunks` for one
    segment: a chunk's fields gathered from ``source`` and narrowed to the segment's width,
    and its results widened back to the source's and put in ``outs`` at their grasps'
    numbers (then ``on_chunk``)."""
    slots_of: dict[int, np.ndarray] = {}  # each chunk's contact slots, from its gathering to its results

    def chunk_fields(start: int) -> dict[str, np.ndarray]:
        chunk = _chunk_of(source, seg.at, start, seg.plan.chunk, keep_padding_active=not seg.masked)
        slots_of[start] = contact_slots(chunk.get("active"), seg.width, seg.plan.chunk)
        return narrow(chunk, slots_of[start], seg.masked)

    def finished(start: int, stop: int, res: Mapping[str, np.ndarray]) -> None:
        slots = slots_of.pop(start)[: stop - start]
        wide = widen(res, slots, source.width)
        for f, a in wide.items():
            if f not in outs:
                outs[f] = np.empty((source.size, *a.shape[1:]), dtype=a.dtype)
            outs[f][seg.at[start:stop]] = a
        if on_chunk is not None:
            on_chunk(seg.at[start:stop], wide)

    return chunk_fields, finished


def _chunk_of(source: GraspSource, at: np.ndarray, start: int, chunk: int,
              keep_padding_active: bool = False) -> dict[str, np.ndarray]:
    """The fields of grasps ``at[start .. start + chunk - 1]`` of ``source``, padded with
    the last one, its contacts inactive where there is a mask (unless
    ``keep_padding_active``: a program without a mask evaluates the repeats), so that the
    padding solves nothing."""
    idx = np.arange(start, start + chunk)
    out = source.gather(at[np.minimum(idx, at.size - 1)])
    if "active" in out and not keep_padding_active:
        out["active"] = out["active"] & (idx < at.size)[:, None]
    return out
