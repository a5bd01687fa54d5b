"""The chunk plan: how many grasps one compiled call evaluates, over which devices.

Every batch of jaxgrasp ([`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch], [`jaxgrasp.sweep`][jaxgrasp.sweep], the
``batch`` and ``sweep`` commands) is cut into chunks by `plan_chunks`. A chunk's size
is a bucket (`bucket_size`), so that sets and grids of different sizes share a few
compilations, at the price of padding lanes; the last chunk is padded to the same size.
Memory is bounded by the chunk size.

A batch of mixed contact counts is cut first into segments by count
(`plan_segments`): each segment runs at its own width where that saves more than
its compilation costs (`plan_widths`), and is then cut into chunks.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from jaxgrasp.base import over_limit
from jaxgrasp.engine._limits import CHUNK_SIZE_WHAT, MAX_CHUNK_SIZE
from jaxgrasp.engine._setup import first_use
from jaxgrasp.model import GraspValueError

__all__ = [
    "ChunkPlan",
    "plan_chunks",
    "bucket_size",
    "check_chunk_size",
    "default_chunk_size",
    "batch_sharding",
    "BUCKET_BASE",
    "DEFAULT_CHUNK_SIZE",
    "ACCELERATOR_CHUNK_SIZE",
    "MIN_AUTO_CHUNK",
    "AUTO_CHUNKS",
    "Segment",
    "SegmentPlan",
    "plan_segments",
    "plan_widths",
    "grasps_by_count",
    "grasp_cpu_seconds",
    "COMPILE_CPU_SECONDS",
    "WIDTH_PLATFORMS",
]

BUCKET_BASE = 4
"""Chunk sizes come from the buckets ``devices * BUCKET_BASE**k`` (1, 4, 16, 64, ... per
device; see `bucket_size`), so sets and grids of different sizes share compilations."""

DEFAULT_CHUNK_SIZE = 64
"""Default grasps per chunk and per CPU device (see `default_chunk_size`). A larger
chunk costs more per grasp (the lanes of a chunk iterate until its last one converges)
and needs more memory for XLA's temporaries, in proportion to the chunk and the contacts."""

ACCELERATOR_CHUNK_SIZE = 1024
"""Default grasps per chunk and per GPU/TPU device: an accelerator runs many lanes at
once, so it wants wide chunks (tune ``chunk_size`` on a given device)."""

MIN_AUTO_CHUNK = 64
"""The smallest chunk per device that ``auto`` picks in `plan_chunks` (smaller
chunks cost more per grasp)."""

AUTO_CHUNKS = 10
"""About this many chunks (progress steps) on a long run with ``auto``."""


def default_chunk_size(devices=None) -> int:
    """The default chunk: `DEFAULT_CHUNK_SIZE` per CPU device,
    `ACCELERATOR_CHUNK_SIZE` per GPU/TPU device, times the number of ``devices``
    (default ``jax.devices()``)."""
    devices = tuple(jax.devices() if devices is None else devices)
    per = DEFAULT_CHUNK_SIZE if devices[0].platform == "cpu" else ACCELERATOR_CHUNK_SIZE
    return per * len(devices)


def check_chunk_size(chunk_size) -> None:
    """``chunk_size`` must be ``None`` (the default) or a positive integer of at most
    `MAX_CHUNK_SIZE`; a one-line [`GraspValueError`][jaxgrasp.GraspValueError] otherwise."""
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1
    ):
        raise GraspValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    problem = None if chunk_size is None else over_limit("chunk_size", chunk_size, MAX_CHUNK_SIZE, CHUNK_SIZE_WHAT)
    if problem:
        raise GraspValueError(problem)


def bucket_size(chunk_size: int, total: int, n_devices: int = 1) -> int:
    """The chunk one compiled call evaluates for ``total`` grasps in chunks of at most
    ``chunk_size``: the smallest bucket ``n_devices * BUCKET_BASE**k`` (1, 4, 16, 64, ...
    lanes per device) that holds ``min(chunk_size, total)`` grasps, but never more than
    ``chunk_size`` rounded up to a multiple of ``n_devices``.

    So sets and grids of different sizes share a few compilations (with the CPU default
    of 64: chunks of 1, 4, 16 or 64), at the price of padding lanes (a padded lane costs
    about what a grasp does, far less than a compilation).
    """
    cap = -(-max(1, int(chunk_size)) // n_devices)  # lanes per device, at most
    need = -(-max(1, min(int(chunk_size), int(total))) // n_devices)
    bucket = 1
    while bucket < need:
        bucket *= BUCKET_BASE
    return min(bucket, cap) * n_devices


def batch_sharding(devices=None) -> NamedSharding:
    """The sharding of every chunk: along its first axis (named ``"batch"``) over
    ``devices`` (default ``jax.devices()``), one slice per device."""
    devices = tuple(jax.devices() if devices is None else devices)
    return NamedSharding(Mesh(np.asarray(devices), ("batch",)), P("batch"))


@dataclasses.dataclass(frozen=True)
class ChunkPlan:
    """``total`` grasps in chunks of ``chunk`` (a multiple of the number of ``devices``),
    the last one padded.

    Attributes:
        total: grasps to evaluate.
        chunk: grasps per compiled call.
        devices: the devices each chunk is split over.
    """

    total: int
    chunk: int
    devices: tuple

    @property
    def n_chunks(self) -> int:
        return math.ceil(self.total / self.chunk)

    @property
    def n_devices(self) -> int:
        return len(self.devices)

    @property
    def sharding(self) -> NamedSharding:
        return batch_sharding(self.devices)


def plan_chunks(total: int, chunk_size: int | None = None, devices=None, *, auto: bool = False) -> ChunkPlan:
    """The chunks of ``total`` grasps: at most ``chunk_size`` each (default
    `default_chunk_size`), as a bucket (`bucket_size`) over ``devices``
    (default ``jax.devices()``).

    With ``auto`` and no ``chunk_size``, the chunk is about a tenth of the run
    (`AUTO_CHUNKS` progress steps), at least `MIN_AUTO_CHUNK` per device and
    at most the default, so that a long sweep reports its progress.

    Raises:
        GraspValueError: ``chunk_size`` is not a positive integer, or there is no device.
    """
    check_chunk_size(chunk_size)
    if devices is None:
        first_use(batch=True)  # JAX's CPU devices, where they can still be chosen
    devices = tuple(jax.devices() if devices is None else devices)
    if not devices:
        raise GraspValueError("a batch needs at least one device")
    chunk = default_chunk_size(devices) if chunk_size is None else chunk_size
    if auto and chunk_size is None:
        chunk = bucket_size(chunk, max(MIN_AUTO_CHUNK * len(devices), math.ceil(total / AUTO_CHUNKS)))
    return ChunkPlan(int(total), bucket_size(chunk, total, len(devices)), devices)


# ------------------------------------------------------------------ segments by contact count

COMPILE_CPU_SECONDS = 30.0
"""What one compilation of the batch evaluator costs, in CPU seconds of evaluation
forgone: its wall time, spent mostly on one core, on a two-core machine that the
evaluation keeps busy (the docs' Benchmarks page, "Datasets", has the measurements).
What a program of a count's own must save (`plan_widths`)."""

WIDTH_PLATFORMS = ("cpu",)
"""Platforms where `plan_widths` gives a contact count a narrower program than the
batch's widest. On a CPU a padded contact costs its share of every solver step; the
saving on an accelerator, where the lanes of a step run side by side, has not been
measured, so there every count runs at the widest."""


def grasp_cpu_seconds(count: int, width: int) -> float:
    """Estimated CPU seconds of evaluating one grasp of ``count`` contacts in a program of
    ``width >= count`` contacts: ``(0.012 + 0.0011 count) * (width**2 + 43) / 92``,
    fitted to a random set's grasps of 2-7 contacts at their own width and padded to 7 on
    two CPU cores (``experiments/padding_and_segments/padding_tax.py``). The first factor is the grasp's work
    at width 7 (its 1 + 2 count programs share a work queue, so it grows slowly with the
    count), the second what a solver step costs at ``width`` against width 7."""
    return (0.012 + 0.0011 * count) * (width**2 + 43) / 92


def grasps_by_count(counts) -> dict[int, int]:
    """``{count: grasps}`` of the contact counts ``counts`` ``(B,)``, what
    `plan_widths` takes (0, an invalid grasp's count, left out)."""
    values, n = np.unique(np.asarray(counts, dtype=np.int64), return_counts=True)
    return {int(c): int(k) for c, k in zip(values, n) if c > 0}


def plan_widths(counts, platform: str = "cpu") -> dict[int, int]:
    """The width (contacts of the compiled program) each contact count of a batch runs at:
    ``{count: width}``, either the count's own or the batch's largest count.

    ``counts`` maps each contact count to its number of grasps (``{2: 5000, 7: 300}``). A
    count gets a program of its own where its grasps save more CPU time there than a
    compilation costs (`COMPILE_CPU_SECONDS`; the grasps' cost
    `grasp_cpu_seconds`): by this model, from about 4300 grasps of 2 contacts in a
    set of 7, 11,400 of 6 contacts. The others are padded to the largest count, in one
    program with a contact mask. (A program for a group of counts, padded to the group's
    largest, would need a mask too: masked programs cost more per step, which the model
    does not know; ``experiments/padding_and_segments/FINDINGS.md``.) On a platform not in
    `WIDTH_PLATFORMS`, every count runs at the widest.

    The widths depend only on ``counts`` and ``platform``, so a run resumed, or split
    over processes, evaluates every grasp at the width a single run does (a grasp's
    value can differ with the width by rounding, relative to its equilibrium energy;
    ``experiments/padding_and_segments/segment_plan.py`` compares the two).
    """
    have = sorted(int(c) for c, n in dict(counts).items() if n > 0 and c > 0)
    if not have:
        return {}
    widest = have[-1]
    if platform not in WIDTH_PLATFORMS:
        return {c: widest for c in have}
    n = {int(c): int(k) for c, k in dict(counts).items()}
    return {c: c if n[c] * (grasp_cpu_seconds(c, widest) - grasp_cpu_seconds(c, c)) > COMPILE_CPU_SECONDS
            else widest for c in have}


@dataclasses.dataclass(frozen=True)
class Segment:
    """The grasps of a batch that run in one program.

    Attributes:
        width: contacts of the program (the segment's largest count).
        counts: the contact counts it holds.
        masked: whether the program takes a contact mask (``counts`` holds more than one
            count: the smaller counts' grasps are padded to ``width``).
        at: ``(n,)`` positions of its grasps among the batch's rows to evaluate, in order.
        plan: its `ChunkPlan`.
    """

    width: int
    counts: tuple[int, ...]
    masked: bool
    at: np.ndarray
    plan: ChunkPlan


@dataclasses.dataclass(frozen=True)
class SegmentPlan:
    """A batch's grasps in `Segment` s, one per width, each cut into chunks.

    ``total``, ``chunk`` (the largest), ``n_chunks`` (of every segment), ``devices`` and
    ``n_devices`` read as a `ChunkPlan` 's (a progress report's ``start(plan)``
    takes either)."""

    segments: tuple[Segment, ...]
    devices: tuple

    @property
    def total(self) -> int:
        return sum(s.plan.total for s in self.segments)

    @property
    def chunk(self) -> int:
        return max((s.plan.chunk for s in self.segments), default=1)

    @property
    def n_chunks(self) -> int:
        return sum(s.plan.n_chunks for s in self.segments)

    @property
    def n_devices(self) -> int:
        return len(self.devices)

    def describe(self) -> str:
        """The segments in words, e.g. ``7 contacts at width 7: 300 grasps; 2-3 contacts at
        width 3: 5000 grasps``."""
        return "; ".join(
            f"{s.counts[0]}{'-' + str(s.counts[-1]) if len(s.counts) > 1 else ''} contacts at width {s.width}: "
            f"{s.plan.total} grasps" for s in self.segments
        )


def plan_segments(counts: np.ndarray, widths, chunk_size: int | None = None, devices=None) -> SegmentPlan:
    """The segments of the grasps whose contact counts are ``counts`` ``(n,)`` (each > 0),
    by ``widths`` (`plan_widths`, of these counts or of a whole set they belong to),
    widest first, each cut by `plan_chunks` (``chunk_size``, ``devices``).

    Raises:
        GraspValueError: ``chunk_size`` is not a positive integer, or there is no device.
        ValueError: a count that ``widths`` has no width for.
    """
    check_chunk_size(chunk_size)
    if devices is None:
        first_use(batch=True)  # JAX's CPU devices, where they can still be chosen
    devices = tuple(jax.devices() if devices is None else devices)
    counts = np.asarray(counts, dtype=np.int64)
    missing = sorted(set(np.unique(counts).tolist()) - set(widths))
    if missing:
        raise ValueError(f"no width planned for contact counts {missing}")
    lookup = np.zeros(max(widths, default=0) + 1, dtype=np.int64)
    lookup[list(widths)] = list(widths.values())
    width_of = lookup[counts]
    segments = []
    for width in sorted(set(widths.values()), reverse=True):
        at = np.flatnonzero(width_of == width)
        if at.size:
            held = tuple(sorted(c for c, w in widths.items() if w == width))
            segments.append(Segment(int(width), held, len(held) > 1, at, plan_chunks(at.size, chunk_size, devices)))
    return SegmentPlan(tuple(segments), devices)
