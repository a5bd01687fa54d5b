"""``jaxgrasp.dense.solve``, and the batch engine's program free of batched LAPACK solves.

jaxlib's LAPACK kernels split a large batch over XLA's thread pool and wait for the
pieces; with one device per core (the batch engine) every device can be waiting at once
and the process hangs (:mod:`jaxgrasp.dense`). The settling stage's polish used
``jnp.linalg.solve`` (``lapack_dgetrf_ffi``) on every grasp of a chunk and hung
``evaluate_batch`` on 2 devices; its systems are now solved by ``dense.solve``. The only
LAPACK call left is the Newton direction's ``eigh``, on gathered blocks of
``EIGH_BLOCK`` (16) lanes: a 2-device shard_map of 6 x 6 ``eigh`` hung at 2048 matrices
per device and ran at 1024.
"""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp import batch
from jaxgrasp.dense import solve
from jaxgrasp.direction import EIGH_BLOCK
from jaxgrasp.options import EvaluateOptions


@pytest.mark.parametrize("m", [1, 2, 6, 27])
def test_solve_agrees_with_numpy(m):
    """Residual at rounding level, and numpy's solution, on random systems whose first
    pivot is zero (elimination without row exchanges would divide by it)."""
    rng = np.random.default_rng(m)
    a = rng.standard_normal((40, m, m))
    if m > 1:
        a[:, 0, 0] = 0.0
    b = rng.standard_normal((40, m))
    x = np.asarray(jax.jit(jax.vmap(solve))(a, b))
    ref = np.linalg.solve(a, b[..., None])[..., 0]
    resid = np.abs(np.einsum("bij,bj->bi", a, x) - b).max(axis=1)
    scale = np.abs(a).max(axis=(1, 2)) * np.abs(x).max(axis=1) + np.abs(b).max(axis=1)
    assert np.all(resid <= 1e-13 * scale), resid / scale
    cond = np.linalg.cond(a)
    assert np.all(np.abs(x - ref).max(axis=1) <= 1e-14 * cond * np.abs(ref).max(axis=1)), cond


def test_singular_system_gives_non_finite():
    assert not np.all(np.isfinite(np.asarray(solve(jnp.zeros((3, 3)), jnp.ones(3)))))


def test_batched_program_calls_no_lapack_but_eigh():
    """The batch engine's programs, with and without the settling stage: every LAPACK
    custom call is the symmetric eigensolver (``syevd``), gathered in small blocks."""
    sharding = batch.batch_sharding()
    assert EIGH_BLOCK <= 64
    for settle in (False, True):
        fn = batch._batched_fn(EvaluateOptions(), sharding, masked=True, settle=settle)
        text = fn.lower(*batch._batch_spec(3, 2 * len(jax.devices()), sharding, masked=True)).as_text()
        targets = set(re.findall(r"custom_call @(\w+)", text))
        assert targets and all("syevd" in t for t in targets if "lapack" in t), (settle, targets)
