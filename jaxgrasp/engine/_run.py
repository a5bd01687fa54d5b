"""Running a compiled chunk evaluator over a batch, chunk by chunk, on the devices."""

from __future__ import annotations

import time
from typing import Callable, Mapping

import jax
import numpy as np

from jaxgrasp.engine._plan import ChunkPlan
from jaxgrasp.engine._settling import settle_then_retry
from jaxgrasp.tolerance import FIELDS as RESULT_FIELDS

__all__ = ["run_chunks"]


def run_chunks(fn, chunk_fields: Callable[[int], Mapping[str, np.ndarray]], names, plan: ChunkPlan,
               progress=None, on_chunk=None, keep=RESULT_FIELDS,
               settling: tuple[Callable[[], Callable], int] | None = None) -> float:
    """Evaluate the ``plan.total`` grasps of ``plan`` a chunk at a time with the compiled
    ``fn``; the run seconds. Each chunk's results go to ``on_chunk``.

    ``chunk_fields(start)`` gives the fields (``names``) of grasps ``start .. start +
    chunk - 1``, each with a leading axis of ``chunk`` (past ``total``: any valid grasp,
    e.g. the last one repeated). ``on_chunk(start, stop, results)`` (first: a checkpoint
    it writes is on disk before ``progress`` reports the chunk; ``results`` the
    [`Evaluation`][jaxgrasp.Evaluation] fields named in ``keep`` of grasps ``start .. stop - 1``,
    leading axis ``stop - start``) and ``progress(stop, total)`` are called after each
    chunk. No device buffer outlives its chunk.

    ``settling = (get, size)``, where given (``fn`` being the evaluator without the
    settling stage, `chunk_evaluator`): the settling
    policy `RETRY`, the grasps of a chunk that
    `needs_settling` evaluated again by ``get()``,
    ``size`` at a time, so every grasp's result is the same whatever chunk it is in.
    ``get`` is called (and compiles, its seconds counted as run time) only once a chunk
    has such grasps.
    """
    deal, undeal = _dealt(plan.chunk, plan.n_devices)
    sharding = plan.sharding
    want = tuple(dict.fromkeys((*keep, "boundary_status", "equilibrium_status"))) if settling else keep
    run_seconds = 0.0
    for start in range(0, plan.total, plan.chunk):
        stop = min(start + plan.chunk, plan.total)
        fields = chunk_fields(start)
        batch = [_put(fields[k][deal], sharding) for k in names]
        t0 = time.perf_counter()
        res = dict(zip(RESULT_FIELDS, fn(*batch)))
        res = {f: _gather(res[f])[undeal] for f in want}
        del batch
        if settling:
            res = _settled(res, fields, names, stop - start, settling, sharding)
        run_seconds += time.perf_counter() - t0
        if on_chunk is not None:
            on_chunk(start, stop, {f: res[f][: stop - start] for f in keep})
        if progress is not None:
            progress(stop, plan.total)
    return run_seconds


def _settled(res: dict, fields, names, count: int, settling, sharding) -> dict:
    """A chunk's results ``res`` by the `RETRY` policy
    (`settle_then_retry`): those of its first ``count``
    grasps that need the settling stage evaluated again by ``settling``'s evaluator
    (``size`` at a time, padded by repeats)."""
    get, size = settling

    def again(rows: np.ndarray) -> dict[str, np.ndarray]:
        settle = get()
        parts = []
        for first in range(0, rows.size, size):
            sel = rows[first : first + size]
            sub = [_put(fields[k][np.resize(sel, size)], sharding) for k in names]
            out = dict(zip(RESULT_FIELDS, settle(*sub)))
            parts.append({f: _gather(out[f])[: sel.size] for f in res})
        return {f: np.concatenate([p[f] for p in parts]) for f in res}

    return settle_then_retry(res, again, count)


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


def _dealt(chunk: int, n_devices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(deal, undeal)``: the order in which a chunk's grasps go to the devices, dealt
    as cards (device ``d`` gets grasps ``d, d + n_devices, ...``), and its inverse.
    Neighbouring points of a grid are alike (a row of a sweep shares its Young's modulus,
    say), so contiguous slices gave one device the chunk's hard grasps while the other
    waited. Each grasp's result is its own, wherever it runs."""
    deal = np.arange(chunk).reshape(-1, n_devices).T.reshape(-1)
    return deal, np.argsort(deal)
