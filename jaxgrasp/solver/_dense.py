"""Small dense linear algebra that never lets LAPACK split a batch over XLA's threads.

On the CPU, ``jnp.linalg.solve`` or ``jnp.linalg.eigh`` of a batch of matrices calls one
of jaxlib's LAPACK kernels (``lapack_dgetrf_ffi``, ``lapack_dsyevd_ffi``), which splits a
large enough batch over XLA's intra-op thread pool and waits for the pieces. The batch
engine runs one executable per device on that same pool (one device per core,
`jaxgrasp.engine._devices`): when every device is inside such a kernel at once,
every pool thread waits for pieces that no thread is left to run, and the process hangs,
using no CPU (a deadlock, not a slowdown: it happened with as many devices as cores, in
the settling stage's batched polish and in the start frames of a large chunk).

* `solve`: the systems solved here are tiny (at most ``6 + 3N`` unknowns), so
  Gaussian elimination written out in XLA (Golub & Van Loan, Sec. 3.4, partial
  pivoting) is cheap and never leaves the device's own thread.
* `eigh`: ``jnp.linalg.eigh`` that, under ``vmap`` on the CPU, calls LAPACK on one
  matrix at a time (``lax.map``): a batch of one is never split (other backends get the
  batched solver). Meant for a few matrices per grasp, whose count grows with the batch.
  (The solver's own ``eigh``, on every loop step, runs on gathered blocks of
  `jaxgrasp.solver._direction.EIGH_BLOCK` lanes, a batch far below any that was
  seen to split.)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["solve", "eigh"]


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


@jax.custom_batching.custom_vmap
def eigh(a):
    """``(w, v)``: ``jnp.linalg.eigh`` of the symmetric ``a`` ``(m, m)``, eigenvalues ``w``
    ``(m,)`` ascending and eigenvectors the columns of ``v`` ``(m, m)``; under ``vmap`` on
    the CPU one LAPACK call per matrix (the module docstring), with the same digits."""
    w, v = jnp.linalg.eigh(a)
    return w, v


@eigh.def_vmap
def _eigh_one_at_a_time(axis_size, in_batched, a):
    (batched,) = in_batched
    if not batched:
        a = jnp.broadcast_to(a, (axis_size,) + a.shape)
    m = a.shape[-1]
    lead = a.shape[:-2]  # (axis_size,) or, under an outer vmap, more: flatten all
    one = lambda x: tuple(jnp.linalg.eigh(x))
    # the CPU's LAPACK one matrix at a time; other backends' solvers have no such pool
    w, v = jax.lax.platform_dependent(
        a.reshape(-1, m, m), cpu=lambda x: jax.lax.map(one, x), default=lambda x: jax.vmap(one)(x)
    )
    return (w.reshape(lead + (m,)), v.reshape(lead + (m, m))), (True, True)
