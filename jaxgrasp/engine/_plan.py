"""The chunk plan: how many grasps one compiled call evaluates, over which devices.

Every batch of jaxgrasp (:func:`jaxgrasp.evaluate_batch`, :func:`jaxgrasp.sweep`, the
``batch`` and ``sweep`` commands) is cut into chunks by :func:`plan_chunks`. A chunk's size
is a bucket (:func:`bucket_size`), so that sets and grids of different sizes share a few
compilations, at the price of padding lanes; the last chunk is padded to the same size.
Memory is bounded by the chunk size.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from jaxgrasp.model._validation import GraspValueError

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
]

BUCKET_BASE = 4
"""Chunk sizes come from the buckets ``devices * BUCKET_BASE**k`` (1, 4, 16, 64, ... per
device; see :func:`bucket_size`), so sets and grids of different sizes share compilations."""

DEFAULT_CHUNK_SIZE = 64
"""Default grasps per chunk and per CPU device (see :func:`default_chunk_size`). A larger
chunk costs more per grasp (the lanes of a chunk iterate until its last one converges)
and needs more memory for XLA's temporaries, in proportion to the chunk and the contacts."""

ACCELERATOR_CHUNK_SIZE = 1024
"""Default grasps per chunk and per GPU/TPU device: an accelerator runs many lanes at
once, so it wants wide chunks (tune ``chunk_size`` on a given device)."""

MIN_AUTO_CHUNK = 64
"""The smallest chunk per device that ``auto`` picks in :func:`plan_chunks` (smaller
chunks cost more per grasp)."""

AUTO_CHUNKS = 10
"""About this many chunks (progress steps) on a long run with ``auto``."""


def default_chunk_size(devices=None) -> int:
    """The default chunk: :data:`DEFAULT_CHUNK_SIZE` per CPU device,
    :data:`ACCELERATOR_CHUNK_SIZE` per GPU/TPU device, times the number of ``devices``
    (default ``jax.devices()``)."""
    devices = tuple(jax.devices() if devices is None else devices)
    per = DEFAULT_CHUNK_SIZE if devices[0].platform == "cpu" else ACCELERATOR_CHUNK_SIZE
    return per * len(devices)


def check_chunk_size(chunk_size) -> None:
    """``chunk_size`` must be ``None`` (the default) or a positive integer; a one-line
    :class:`~jaxgrasp.GraspValueError` otherwise."""
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1
    ):
        raise GraspValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")


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
    :func:`default_chunk_size`), as a bucket (:func:`bucket_size`) over ``devices``
    (default ``jax.devices()``).

    With ``auto`` and no ``chunk_size``, the chunk is about a tenth of the run
    (:data:`AUTO_CHUNKS` progress steps), at least :data:`MIN_AUTO_CHUNK` per device and
    at most the default, so that a long sweep reports its progress.

    Raises:
        GraspValueError: ``chunk_size`` is not a positive integer, or there is no device.
    """
    check_chunk_size(chunk_size)
    devices = tuple(jax.devices() if devices is None else devices)
    if not devices:
        raise GraspValueError("a batch needs at least one device")
    chunk = default_chunk_size(devices) if chunk_size is None else chunk_size
    if auto and chunk_size is None:
        chunk = bucket_size(chunk, max(MIN_AUTO_CHUNK * len(devices), math.ceil(total / AUTO_CHUNKS)))
    return ChunkPlan(int(total), bucket_size(chunk, total, len(devices)), devices)
