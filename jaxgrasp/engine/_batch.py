"""The batched engine: many grasps evaluated in chunks of one compiled, sharded program.

::

    import jaxgrasp
    grasps = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(), jaxgrasp.load("examples/four_finger.json")]
    res = jaxgrasp.evaluate_batch(grasps)   # any contact counts: padded (jaxgrasp.stack)
    res.value, res.status_names              # (B,) J, names
    res.rank()[:10]                          # indices of the best grasps

:func:`evaluate_batch` and :func:`jaxgrasp.sweep` share this path: the grasps of a chunk
are evaluated by one compiled evaluator, :func:`jaxgrasp.engine._evaluate.evaluate_batch_traced`
in the stages of :mod:`jaxgrasp.engine._stages` (equal to ``jax.vmap(evaluate)`` lane
by lane; from :func:`compiled_evaluator`, memoised and stored by :mod:`jaxgrasp.engine._store`),
split along the batch over all devices, each
device running its own work queue on its slice (:func:`over_devices`; on a CPU
``import jaxgrasp`` makes one device per core, :mod:`jaxgrasp.engine._devices`); the
last chunk is padded to the same size, so a set compiles once per chunk size, number of
contacts and options. Memory is bounded by the chunk size.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from jaxgrasp.engine import _compile, _pipeline
from jaxgrasp.engine import _stages as batch_stages
from jaxgrasp.engine._batch_result import BatchResult, mark_invalid
from jaxgrasp.io._dataset import GraspSet
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.model._fields import NAMES
from jaxgrasp.model._grasp import Grasp, stack
from jaxgrasp.engine._xla_options import COMPILER_OPTIONS, LATENCY_CPU_OPTIONS
from jaxgrasp.tolerance._settle import needs_settling
from jaxgrasp.tolerance._result import FIELDS, Evaluation
from jaxgrasp.model._validation import GraspValueError, check_batch_inputs

__all__ = [
    "evaluate_batch",
    "BatchResult",
    "RESULT_FIELDS",
    "BUCKET_BASE",
    "DEFAULT_CHUNK_SIZE",
    "ACCELERATOR_CHUNK_SIZE",
    "default_chunk_size",
    "bucket_size",
    "check_chunk_size",
    "grasp_fields",
    "compiled_evaluator",
    "settling_evaluator",
    "run_chunks",
    "over_devices",
    "batch_sharding",
]

RESULT_FIELDS = FIELDS
"""The per-grasp arrays a compiled batch returns: every :class:`~jaxgrasp.Evaluation`
field, in field order."""

BUCKET_BASE = 4
"""Batch sizes come from the buckets ``devices * BUCKET_BASE**k`` (1, 4, 16, 64, ... per
device; see :func:`bucket_size`), so sets and grids of different sizes share compilations."""

DEFAULT_CHUNK_SIZE = 64
"""Default grid points per compiled batch and per CPU device (see :func:`default_chunk_size`).

Measured on a 2-core CPU with the cube (``experiments/sweep_100k.log``): a larger batch is
slower per grasp (the lanes of a batch iterate until its slowest converges) and needs
about 1.5 MiB of XLA temporaries per grid point (385 MiB at 256; 6.0 GiB at 4096, where
the process peaked at 7.5 GiB), more contacts proportionally more."""

ACCELERATOR_CHUNK_SIZE = 1024
"""Default grid points per compiled batch and per GPU/TPU device (about 1.5 GiB of
temporaries for the cube; not measured on a GPU here: tune ``chunk_size`` there)."""


def default_chunk_size(devices=None) -> int:
    """The default batch of :func:`evaluate_batch` and :func:`jaxgrasp.sweep`: :data:`DEFAULT_CHUNK_SIZE` per CPU device,
    :data:`ACCELERATOR_CHUNK_SIZE` per GPU/TPU device, times the number of ``devices``
    (default ``jax.devices()``)."""
    devices = tuple(jax.devices() if devices is None else devices)
    per = DEFAULT_CHUNK_SIZE if devices[0].platform == "cpu" else ACCELERATOR_CHUNK_SIZE
    return per * len(devices)


# --------------------------------------------------------------------------- compiled batch

def grasp_fields(masked: bool) -> tuple[str, ...]:
    """The :class:`Grasp` fields a compiled batch takes, in order: every field of
    :data:`jaxgrasp.model._fields.NAMES`, then ``active`` for grasps with a contact mask."""
    return NAMES + (("active",) if masked else ())


def _batched_fn(options: EvaluateOptions, sharding, masked: bool = False, settle: bool = True) -> _pipeline.Pipeline:
    """The batched evaluator as a :class:`jaxgrasp.engine._pipeline.Pipeline` of the five stages of
    :mod:`jaxgrasp.engine._stages` (the solver's lanes, the starts around them, ...), each
    ``jax.jit`` over the devices of ``sharding`` (:func:`over_devices`): the
    :class:`Grasp` fields (:func:`grasp_fields`) in, every :class:`~jaxgrasp.Evaluation`
    field (:data:`RESULT_FIELDS`) out. The last stage, the evaluation, runs once per chunk
    and briefly: on a CPU it is compiled with :data:`~jaxgrasp.engine._xla_options.LATENCY_CPU_OPTIONS`."""
    functions = batch_stages.flat_stages(options, grasp_fields(masked), settle)
    cpu = sharding.mesh.devices.flat[0].platform == "cpu"
    latency = LATENCY_CPU_OPTIONS if cpu else COMPILER_OPTIONS
    return _pipeline.Pipeline(
        stages={name: over_devices(f, sharding, latency if name == "evaluation" else COMPILER_OPTIONS)
                for name, f in functions.items()},
        drive=batch_stages.run_staged,
    )


def batch_sharding(devices=None) -> NamedSharding:
    """The sharding of every batch: along its first axis (named ``"batch"``) over
    ``devices`` (default ``jax.devices()``), one slice per device."""
    devices = tuple(jax.devices() if devices is None else devices)
    return NamedSharding(Mesh(np.asarray(devices), ("batch",)), P("batch"))


def over_devices(fn: Callable, sharding: NamedSharding, compiler_options=COMPILER_OPTIONS) -> Callable:
    """``jax.jit(fn)`` of a function of a batch (leading axis on every argument and
    result), with the batch split over the devices of ``sharding``
    (:func:`batch_sharding`), compiled with ``compiler_options``.

    Each device evaluates its own slice of the batch (``jax.shard_map``), so each runs
    its own work queue (:func:`jaxgrasp.solver._lanes.solve_lanes`) on its own core: the lanes
    are independent, nothing is exchanged. (Without ``shard_map`` XLA would partition
    the one queue that the batch is folded into, and gather it on every device.)
    """
    # check_vma=False: the solver's loops carry values that are not per-device typed
    split = jax.shard_map(fn, mesh=sharding.mesh, in_specs=P("batch"), out_specs=P("batch"),
                          check_vma=False)
    return jax.jit(split, in_shardings=sharding, out_shardings=sharding, compiler_options=compiler_options)


def _batch_spec(n_contacts: int, chunk: int, sharding, masked: bool = False) -> tuple:
    """The :class:`Grasp` fields of a batch of ``chunk`` grasps, as ``ShapeDtypeStruct``."""
    per_field = dict(positions=(n_contacts, 3), normals=(n_contacts, 3), mass=(), gravity=(3,))
    return tuple(
        jax.ShapeDtypeStruct(
            (chunk, *per_field.get(f, (n_contacts,))), jnp.bool_ if f == "active" else jnp.float64, sharding=sharding
        )
        for f in grasp_fields(masked)
    )


def compiled_evaluator(options: EvaluateOptions, n_contacts: int, chunk: int, devices=None, masked: bool = False,
                       settle: bool = True):
    """The batched evaluator for ``chunk`` grasps of ``n_contacts``; ``(fn, compile seconds)``.
    With ``settle`` false, the program without the settling stage
    (:func:`~jaxgrasp.tolerance._stages.problems_of`), which :func:`run_chunks` completes.

    ``fn`` (a :class:`jaxgrasp.engine._pipeline.Staged`, the stages of :func:`_batched_fn`)
    takes the :class:`Grasp` fields (:func:`grasp_fields`: with ``masked``, the
    contact mask ``active`` last) of a batch, each sharded along
    its first axis over ``devices`` (default ``jax.devices()``; ``chunk`` must be a
    multiple of their number), and returns every :class:`~jaxgrasp.Evaluation` field
    (:data:`RESULT_FIELDS`, leading axis ``chunk``), sharded the same way. It comes from :func:`jaxgrasp.engine._compile.compiled`: memoised in the process (0
    seconds on a hit) and stored on disk where that is turned on (:mod:`jaxgrasp.engine._store`).
    """
    devices = tuple(jax.devices() if devices is None else devices)
    if chunk % len(devices):
        raise ValueError(f"chunk {chunk} is not a multiple of the {len(devices)} devices")
    x64 = jax.config.jax_enable_x64
    sharding = batch_sharding(devices)
    return _compile.compiled(
        ("sweep", options, n_contacts, chunk, x64, tuple(d.id for d in devices), masked, settle),
        lambda: _batched_fn(options, sharding, masked, settle),
        _batch_spec(n_contacts, chunk, sharding, masked),
        name="sweep_settled" if settle else "sweep",
        store_key=(options, n_contacts, chunk, x64, masked, settle),
        devices=list(sharding.mesh.devices.flat),
        n_outputs=len(RESULT_FIELDS),
    )



def settling_evaluator(options: EvaluateOptions, n_contacts: int, chunk: int, devices=None, masked: bool = False):
    """``(get, size)`` for :func:`run_chunks`'s ``settling``: the evaluator with the
    settling stage for one grasp per device (``size`` = the device count: the grasps
    that need it are few, and a larger batch would be padded with repeats that cost as
    much as they do), compiled (or loaded) when ``get()`` is first called."""
    devices = tuple(jax.devices() if devices is None else devices)
    size = len(devices)
    return (lambda: compiled_evaluator(options, n_contacts, size, devices, masked)[0]), size


def run_chunks(fn, chunk_fields: Callable[[int], Mapping[str, np.ndarray]], names, total: int, chunk: int,
               sharding, progress=None, on_chunk=None, keep=RESULT_FIELDS,
               settling: tuple[Callable[[], Callable], int] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """Evaluate ``total`` grasps ``chunk`` at a time with the compiled ``fn``; the
    ``(total, ...)`` result arrays named in ``keep`` (of :data:`RESULT_FIELDS`) and the
    run seconds.

    ``chunk_fields(start)`` gives the fields (``names``) of grasps ``start .. start +
    chunk - 1``, each with a leading axis of ``chunk`` (past ``total``: any valid grasp,
    e.g. the last one repeated). ``on_chunk(start, stop, results)`` (first: a checkpoint
    it writes is on disk before ``progress`` reports the chunk) and ``progress(stop,
    total)`` are called after each chunk. No device buffer outlives its chunk.

    ``settling = (get, size)``, where given: ``get()`` returns the evaluator with the
    settling stage for batches of ``size`` grasps (``fn`` being the one without,
    :func:`compiled_evaluator`). It is called (and compiled, the seconds counted as run
    time) only once a chunk has grasps that :func:`~jaxgrasp.tolerance._settle.needs_settling`;
    those grasps alone are evaluated again with it, ``size`` at a time (a few in a
    dataset: not the chunk, only they run again), and take its results. Every
    grasp's result is thus the same whatever chunk it is in.
    """
    outs: dict[str, np.ndarray] = {}  # host-side, filled chunk by chunk
    deal, undeal = _dealt(chunk, sharding.mesh.devices.size)
    run_seconds = 0.0
    for start in range(0, total, chunk):
        stop = min(start + chunk, total)
        fields = chunk_fields(start)
        batch = [_put(fields[k][deal], sharding) for k in names]
        t0 = time.perf_counter()
        res = dict(zip(RESULT_FIELDS, fn(*batch)))
        res = {f: _gather(res[f])[undeal] for f in dict.fromkeys((*keep, "boundary_status") if settling else keep)}
        rows = np.flatnonzero(needs_settling(res["boundary_status"])[: stop - start]) if settling else ()
        if len(rows):
            get, size = settling
            settle = get()
            res = {f: np.array(a) for f, a in res.items()}  # writable copies
            for first in range(0, rows.size, size):
                sel = rows[first : first + size]
                sub = [_put(fields[k][np.resize(sel, size)], sharding) for k in names]  # padded by repeats
                settled = dict(zip(RESULT_FIELDS, settle(*sub)))
                for f in res:
                    res[f][sel] = _gather(settled[f])[: sel.size]
        run_seconds += time.perf_counter() - t0
        del batch
        for f in keep:
            a = res[f]
            if f not in outs:
                outs[f] = np.empty((total, *a.shape[1:]), dtype=a.dtype)
            outs[f][start:stop] = a[: stop - start]
        if on_chunk is not None:
            on_chunk(start, stop, outs)
        if progress is not None:
            progress(stop, total)
    return outs, run_seconds


def _dealt(chunk: int, n_devices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(deal, undeal)``: the order in which a chunk's grasps go to the devices, dealt
    as cards (device ``d`` gets grasps ``d, d + n_devices, ...``), and its inverse.
    Neighbouring points of a grid are alike (a row of a sweep shares its Young's modulus,
    say), so contiguous slices gave one device the chunk's hard grasps while the other
    waited: the default sweep's run took 0.64 s in slices, 0.57 s dealt
    (``experiments/BENCHMARK.md``). Each grasp's result is its own, wherever it runs."""
    deal = np.arange(chunk).reshape(-1, n_devices).T.reshape(-1)
    return deal, np.argsort(deal)


def check_chunk_size(chunk_size) -> None:
    """``chunk_size`` must be ``None`` (the default) or a positive integer; a one-line
    :class:`GraspValueError` otherwise (for :func:`evaluate_batch` and :func:`jaxgrasp.sweep`)."""
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1
    ):
        raise GraspValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")


def bucket_size(chunk_size: int, total: int, n_devices: int = 1) -> int:
    """The batch one compiled call evaluates for ``total`` grasps in chunks of at most
    ``chunk_size``: the smallest bucket ``n_devices * BUCKET_BASE**k`` (1, 4, 16, 64, ...
    lanes per device) that holds ``min(chunk_size, total)`` grasps, but never more than
    ``chunk_size`` rounded up to a multiple of ``n_devices``.

    So sets and grids of different sizes share a few compilations (with the CPU default
    of 64: batches of 1, 4, 16 or 64), at the price of padding lanes (a padded lane costs
    about what a grasp does, far less than a compilation).
    """
    cap = -(-max(1, int(chunk_size)) // n_devices)  # lanes per device, at most
    need = -(-max(1, min(int(chunk_size), int(total))) // n_devices)
    bucket = 1
    while bucket < need:
        bucket *= BUCKET_BASE
    return min(bucket, cap) * n_devices


def _put(a: np.ndarray, sharding) -> jax.Array:
    """Host array -> global array sharded along its first axis (each process supplies its
    own devices' slices, so this works unchanged across hosts)."""
    a = np.ascontiguousarray(a, dtype=np.bool_ if a.dtype == np.bool_ else np.float64)
    if jax.process_count() == 1:
        return jax.device_put(a, sharding)
    return jax.make_array_from_callback(a.shape, sharding, lambda i: a[i])


def _gather(x) -> np.ndarray:
    """Global (sharded) result array -> the whole array as NumPy on this host."""
    if getattr(x, "is_fully_addressable", True):
        return np.asarray(jax.device_get(x))
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


# --------------------------------------------------------------------------- evaluate_batch



def _batched_fields(grasps) -> tuple[dict[str, np.ndarray], tuple]:
    """The fields of ``grasps`` (a sequence of :class:`Grasp`, one batched grasp, or a
    :class:`~jaxgrasp.GraspSet`), each with a leading ``B`` axis (padded to the largest
    contact count, with ``active``, where counts differ or a grasp has a mask), and each
    grasp's error (``None``: valid). Every valid grasp is validated; an invalid one (a
    set's ``None``) is stood in for by the first valid grasp and has no active contact."""
    errors = None
    if isinstance(grasps, GraspSet):
        errors = tuple(grasps.errors)
        valid = [g for g in grasps.grasps if g is not None]
        if not valid:
            raise GraspValueError(f"{grasps.source}: no valid grasp to evaluate (first: {errors[0]})")
        grasps = [valid[0] if g is None else g for g in grasps.grasps]
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
    errors = (None,) * pos[0] if errors is None else errors
    check_batch_inputs(fields, skip=[i for i, e in enumerate(errors) if e is not None])
    if "active" in fields:
        fields["active"] = np.array(fields["active"])  # not a broadcast view: rows are set below
    invalid = np.asarray([e is not None for e in errors])
    if invalid.any():
        fields.setdefault("active", np.ones(pos[:2], dtype=bool))
        fields["active"][invalid] = False
    return fields, errors


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
    """Evaluate many grasps in chunks of one compiled program; every result equals
    :func:`jaxgrasp.evaluate` of that grasp.

    Args:
        grasps: a sequence of :class:`~jaxgrasp.Grasp` (any contact counts: they are
            padded with inactive contacts, :func:`jaxgrasp.stack`), one batched grasp
            (leading axis ``B``; fields without it are shared by every grasp), or a
            :class:`~jaxgrasp.GraspSet` from :func:`jaxgrasp.load_dataset`, whose invalid
            grasps are not evaluated: their status is ``invalid`` and their error kept.
        options: :class:`~jaxgrasp.EvaluateOptions` of every evaluation.
        chunk_size: grasps per compiled batch, at most (default
            :func:`default_chunk_size`); the batch is a bucket of :func:`bucket_size`, so
            batches of different sizes share compilations.
        progress: ``progress(done, total)`` after each chunk.
        on_chunk: ``on_chunk(start, stop, results)`` after each chunk (before
            ``progress``): grasps ``start .. stop - 1`` and all before are done;
            ``results`` maps :data:`RESULT_FIELDS` to ``(B, ...)`` arrays whose first
            ``stop`` rows are final (the engine's own buffers: read, never write).
        devices: the devices the batch is sharded over (default ``jax.devices()``).

    Returns:
        A :class:`~jaxgrasp.BatchResult`: every :class:`~jaxgrasp.Evaluation` field with
        a leading ``B`` axis, in input order.

    Raises:
        GraspValueError: before anything is compiled, naming the first invalid grasp of
            a sequence or batched grasp (a :class:`~jaxgrasp.GraspSet` keeps its invalid
            grasps as rows), or when a set has no valid grasp.
    """
    check_chunk_size(chunk_size)
    fields, errors = _batched_fields(grasps)
    masked = "active" in fields
    devices = tuple(jax.devices() if devices is None else devices)
    total, n_contacts = fields["positions"].shape[:2]
    chunk = bucket_size(default_chunk_size(devices) if chunk_size is None else chunk_size, total, len(devices))
    # One program, the settling stage inline for every grasp: in a dataset of random
    # grasps some 5% need it, so nearly every chunk would build and run the second
    # program on its unsettled grasps, one per device. Inline it costs less than those
    # reruns (512 random grasps of 2-7 contacts: 39.6-40.9 against 37.5 grasps/s, the
    # same results to 1e-16) and the set compiles once (experiments/BENCHMARK.md).
    # Sweeps keep the two-stage path: their grids rarely need the stage.
    fn, compile_seconds = compiled_evaluator(options, n_contacts, chunk, devices, masked, settle=True)
    sharding = batch_sharding(devices)
    invalid = np.flatnonzero([e is not None for e in errors])

    def chunk_fields(start: int) -> dict[str, np.ndarray]:
        idx = np.arange(start, start + chunk)
        out = {k: v[np.minimum(idx, total - 1)] for k, v in fields.items()}  # pad with the last grasp
        if masked:  # ... with no active contact, so that the padding solves nothing
            out["active"] = out["active"] & (idx < total)[:, None]
        return out

    def finished(start: int, stop: int, outs: dict[str, np.ndarray]) -> None:
        mark_invalid(outs, invalid[(invalid >= start) & (invalid < stop)])
        if on_chunk is not None:
            on_chunk(start, stop, outs)

    outs, run_seconds = run_chunks(
        fn, chunk_fields, grasp_fields(masked), total, chunk, sharding, progress, finished
    )
    active = fields.get("active", np.ones((total, n_contacts), dtype=bool))
    return BatchResult(
        evaluation=Evaluation(**outs),
        num_contacts=active.sum(axis=1),
        active=active,
        errors=errors,
        compile_seconds=compile_seconds,
        run_seconds=run_seconds,
        devices=len(devices),
    )
