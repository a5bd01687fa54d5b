"""The compiled chunk evaluator (the pipeline's stages, each ``jit`` over the devices,
memoised in the process and kept in the executable store), by settling policy
(`_settling`)."""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from jaxgrasp.engine import _compile, _pipeline
from jaxgrasp.engine import _stages as stages
from jaxgrasp.engine._plan import ChunkPlan, batch_sharding
from jaxgrasp.engine._settling import check_settle
from jaxgrasp.engine._xla_options import COMPILER_OPTIONS, latency_options
from jaxgrasp.model import NAMES
from jaxgrasp.tolerance import FIELDS as RESULT_FIELDS
from jaxgrasp.tolerance import EvaluateOptions

__all__ = ["grasp_fields", "over_devices", "compiled_evaluator", "chunk_evaluator",
           "release_chunk_evaluator"]

def grasp_fields(masked: bool) -> tuple[str, ...]:
    """The [`Grasp`][jaxgrasp.Grasp] fields a compiled chunk takes, in order: every field
    of `jaxgrasp.model._fields.NAMES`, then ``active`` for grasps with a contact mask."""
    return NAMES + (("active",) if masked else ())


def over_devices(fn: Callable, sharding: NamedSharding, compiler_options=COMPILER_OPTIONS) -> Callable:
    """``jax.jit(fn)`` of a function of a chunk (leading axis on every argument and
    result), with the chunk split over the devices of ``sharding``
    (`batch_sharding`), compiled with ``compiler_options``.

    Each device evaluates its own slice of the chunk (``jax.shard_map``), so each runs
    its own work queue (`jaxgrasp.solver.solve_lanes`) on its own core: the lanes
    are independent, nothing is exchanged. (Without ``shard_map`` XLA would partition
    the one queue that the chunk is folded into, and gather it on every device.)
    """
    # check_vma=False: the solver's loops carry values that are not per-device typed
    split = jax.shard_map(fn, mesh=sharding.mesh, in_specs=P("batch"), out_specs=P("batch"), check_vma=False)
    return jax.jit(split, in_shardings=sharding, out_shardings=sharding, compiler_options=compiler_options)


def _staged(options: EvaluateOptions, sharding, masked: bool, settle: bool) -> _pipeline.Pipeline:
    """The chunk evaluator as a `Pipeline`: the stages
    of `flat_stages`, each `over_devices`, driven by
    `run_staged`. The evaluation stage runs once per chunk
    and briefly, so on a CPU it is compiled for latency."""
    functions = stages.flat_stages(options, grasp_fields(masked), settle)
    latency = latency_options(sharding.mesh.devices.flat[0].platform)
    return _pipeline.Pipeline(
        stages={name: over_devices(f, sharding, latency if name == "evaluation" else COMPILER_OPTIONS)
                for name, f in functions.items()},
        drive=stages.run_staged,
    )


def _chunk_spec(n_contacts: int, chunk: int, sharding, masked: bool) -> tuple:
    """The [`Grasp`][jaxgrasp.Grasp] fields of a chunk of ``chunk`` grasps, as ``ShapeDtypeStruct``."""
    per_field = dict(positions=(n_contacts, 3), normals=(n_contacts, 3), mass=(), gravity=(3,))
    return tuple(
        jax.ShapeDtypeStruct(
            (chunk, *per_field.get(f, (n_contacts,))), jnp.bool_ if f == "active" else jnp.float64, sharding=sharding
        )
        for f in grasp_fields(masked)
    )


def compiled_evaluator(options: EvaluateOptions, n_contacts: int, chunk: int, devices=None, masked: bool = False,
                       settle: bool = True):
    """The chunk evaluator for ``chunk`` grasps of ``n_contacts``; ``(fn, compile seconds)``.

    ``fn`` (a `Staged`) takes the
    [`Grasp`][jaxgrasp.Grasp] fields (`grasp_fields`: with ``masked``, the contact
    mask ``active`` last) of a chunk, each sharded along its first axis over ``devices``
    (default ``jax.devices()``; ``chunk`` must be a multiple of their number), and
    returns every [`Evaluation`][jaxgrasp.Evaluation] field (leading axis ``chunk``), sharded
    the same way; ``settle`` as in `stage_functions`. It
    comes from `jaxgrasp.engine._compile.compiled`: memoised in the process (0
    seconds on a hit) and kept in the executable store where that is turned on.
    """
    devices = tuple(jax.devices() if devices is None else devices)
    if chunk % len(devices):
        raise ValueError(f"chunk {chunk} is not a multiple of the {len(devices)} devices")
    x64 = jax.config.jax_enable_x64
    sharding = batch_sharding(devices)
    return _compile.compiled(
        _memo_key(options, n_contacts, chunk, devices, masked, settle),
        lambda: _staged(options, sharding, masked, settle),
        _chunk_spec(n_contacts, chunk, sharding, masked),
        name="chunk_settled" if settle else "chunk",
        what=f"the batch evaluator for chunks of {chunk} grasps of {n_contacts} contacts",
        store_key=(options, n_contacts, chunk, x64, masked, settle),
        devices=list(sharding.mesh.devices.flat),
        n_outputs=len(RESULT_FIELDS),
    )


def _memo_key(options: EvaluateOptions, n_contacts: int, chunk: int, devices: tuple, masked: bool, settle: bool):
    return ("chunk", options, n_contacts, chunk, jax.config.jax_enable_x64, tuple(d.id for d in devices), masked,
            settle)


def chunk_evaluator(settle: str, options: EvaluateOptions, n_contacts: int, plan: ChunkPlan, masked: bool):
    """``(fn, compile seconds, settling)`` for the chunks of ``plan`` by the settling
    policy ``settle`` (`_settling`): for
    `INLINE`, ``fn`` with the settling stage and
    ``settling`` ``None``; for `RETRY`, ``fn`` without it
    and ``settling = (get, size)`` for `run_chunks`, ``get()``
    compiling (or loading) the evaluator with the stage for ``size`` grasps, one per
    device, when a chunk first needs it (the grasps that need it are few: a wider chunk
    would be padded with repeats that cost as much as they do)."""
    inline = check_settle(settle)
    fn, seconds = compiled_evaluator(options, n_contacts, plan.chunk, plan.devices, masked, settle=inline)
    if inline:
        return fn, seconds, None
    size = plan.n_devices
    return fn, seconds, (lambda: compiled_evaluator(options, n_contacts, size, plan.devices, masked)[0], size)


def release_chunk_evaluator(settle: str, options: EvaluateOptions, n_contacts: int, plan: ChunkPlan,
                            masked: bool) -> None:
    """Forget what `chunk_evaluator` gave for these arguments in this process
    (`forget`): a batch in segments by contact count
    holds one program at a time, not one per segment."""
    inline = check_settle(settle)
    _compile.forget(_memo_key(options, n_contacts, plan.chunk, plan.devices, masked, inline))
    if not inline:
        _compile.forget(_memo_key(options, n_contacts, plan.n_devices, plan.devices, masked, True))
