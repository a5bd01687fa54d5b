"""Small dense linear solves in plain XLA operations, with no LAPACK call.

On the CPU, ``jnp.linalg.solve`` of a batch of matrices calls jaxlib's LAPACK LU kernel,
which splits a large enough batch over XLA's intra-op thread pool and waits for the
pieces. The batch engine runs one program per device on that same pool (one device per
core, :mod:`jaxgrasp.cores`): when every device is inside such a kernel at once, every
pool thread waits for pieces that no thread is left to run, and the process hangs
(seen with 2 devices on 2 cores: the settling stage's batched polish, each device in
``lapack_dgetrf_ffi`` -> ``ParallelBatchMap`` -> ``BlockingCounter::Wait``, no CPU used).
The systems solved here are tiny (at most ``6 + 3N`` unknowns), so Gaussian elimination
written out in XLA costs nothing noticeable and never leaves the device's own thread.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["solve"]


def solve(a, b):
    """``x`` ``(m,)`` with ``a x = b`` for ``a`` ``(m, m)``, ``b`` ``(m,)`` (``vmap`` it for a
    batch): Gaussian elimination with partial pivoting, then back substitution.

    A singular ``a`` gives non-finite entries (as ``jnp.linalg.solve`` does), never an
    error: callers test ``jnp.isfinite``.
    """
    m = a.shape[0]
    rows = jnp.arange(m)

    def eliminate(i, carry):
        a, b = carry
        pivot = jnp.argmax(jnp.where(rows >= i, jnp.abs(a[:, i]), -1.0))
        swap = jnp.where(rows == i, pivot, jnp.where(rows == pivot, i, rows))
        a, b = a[swap], b[swap]
        factor = jnp.where(rows > i, a[:, i] / a[i, i], 0.0)
        return a - factor[:, None] * a[i][None, :], b - factor * b[i]

    a, b = jax.lax.fori_loop(0, m, eliminate, (a, b))

    def substitute(k, x):
        i = m - 1 - k
        return x.at[i].set((b[i] - jnp.dot(a[i], x)) / a[i, i])  # x[i:] beyond i already set, x[i] still 0

    return jax.lax.fori_loop(0, m, substitute, jnp.zeros_like(b))
