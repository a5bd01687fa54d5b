"""The solver's Newton direction: eigenvalues mirrored and floored, paid for only where needed.

For a symmetric ``(n, n)`` Hessian ``H`` and gradient ``g`` the direction is

    p = -V diag(1 / max(|e|, floor)) V^T g,   H = V diag(e) V^T,   floor = 1e-10 max|e|,

a descent direction whatever the inertia of ``H`` (a Hessian modification, Nocedal &
Wright Sec. 3.4), and the same in any rotated or
mirrored frame of the variables (it is a function of the matrix, not of its entries'
order): a symmetric grasp stays symmetric along the solver's path.

Where ``H`` is safely positive definite (``tr(H) tr(H^-1) <= 1e10``, which implies
``e_min >= 1e-10 e_max``, so the floor and the mirror change nothing) that direction is
the plain Newton step ``-H^-1 g``, which an ``LDL^T`` factorisation without pivoting gives
at a fraction of ``eigh``'s cost (written out entry by entry, so that under ``vmap`` every
operation is one vector operation over the lanes). Under ``vmap`` (`newton_direction`
is a ``custom_vmap``) every lane takes the factorisation, and ``eigh`` runs only on the
lanes that fail the test, gathered in blocks of `EIGH_BLOCK`: on grasp grids a
minority of the Newton lanes of a loop step are indefinite, and lanes that take no
Newton step this loop step (``needed`` false) take no ``eigh``. A batch of at most one
block (a single grasp's few slots) takes ``eigh`` on every lane: a smaller executable,
nothing to gather.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgrasp.solver._rows import over_rows, put_rows

__all__ = ["newton_direction", "eigen_direction", "ldl_direction", "EIGH_BLOCK", "CONDITION_BOUND"]

#: lanes per block of the gathered ``eigh`` under ``vmap``
EIGH_BLOCK = 8
#: largest ``tr(H) tr(H^-1)`` for which the factorisation's step is taken
CONDITION_BOUND = 1e10
#: the eigenvalue floor, relative to the largest ``|e|``
FLOOR = 1e-10


def eigen_direction(hmat, g):
    """``(n,)`` direction ``-V diag(1/max(|e|, floor)) V^T g`` of the module docstring, by
    ``eigh`` (``hmat`` ``(n, n)`` symmetric, ``g`` ``(n,)``)."""
    evals, evecs = jnp.linalg.eigh(hmat)
    aevals = jnp.abs(evals)
    aevals = jnp.maximum(aevals, FLOOR * jnp.maximum(jnp.max(aevals), 1e-30))
    return -evecs @ ((evecs.T @ g) / aevals)


def ldl_direction(hmat, g):
    """``(p, ok)``: ``p`` ``(n,)`` = ``-hmat^-1 g`` by an ``LDL^T`` factorisation without
    pivoting, and ``ok`` ``()`` bool, true where every pivot is positive and
    ``tr(H) tr(H^-1) <= CONDITION_BOUND``: then ``hmat`` is positive definite with
    ``e_min >= FLOOR e_max`` (``e_max <= tr H``, ``1 / e_min <= tr H^-1``), so ``p`` is
    `eigen_direction`'s direction (to rounding). Where ``ok`` is false ``p`` is
    meaningless (a pivot near zero can overflow it).

    Written entry by entry (``n`` is small and static): under ``vmap`` each line is one
    vector operation over the lanes, which XLA fuses, instead of a LAPACK call per lane.
    """
    n = hmat.shape[-1]
    a = [[hmat[i, j] for j in range(n)] for i in range(n)]
    one = jnp.ones_like(a[0][0])
    low = [[None] * n for _ in range(n)]  # unit lower triangular L
    piv = []  # D
    inv_piv = []
    ok = jnp.ones(a[0][0].shape, bool)
    for j in range(n):
        dj = a[j][j] - sum((low[j][k] * low[j][k] * piv[k] for k in range(j)), 0.0 * one)
        ok = ok & (dj > 0)
        inv = 1.0 / jnp.where(dj > 0, dj, one)
        piv.append(dj)
        inv_piv.append(inv)
        for i in range(j + 1, n):
            low[i][j] = (a[i][j] - sum((low[i][k] * low[j][k] * piv[k] for k in range(j)), 0.0 * one)) * inv
    # solve L y = -g, then D L^T p = y
    y = []
    for i in range(n):
        y.append(-g[i] - sum((low[i][k] * y[k] for k in range(i)), 0.0 * one))
    p = [None] * n
    for i in reversed(range(n)):
        p[i] = y[i] * inv_piv[i] - sum((low[k][i] * p[k] for k in range(i + 1, n)), 0.0 * one)
    # H^-1 = M^T D^-1 M with M = L^-1 (unit lower triangular), so
    # tr(H^-1) = sum_k (1 / d_k) |row k of M|^2
    m = [[None] * n for _ in range(n)]
    for j in range(n):
        m[j][j] = one
        for i in range(j + 1, n):
            m[i][j] = -sum((low[i][k] * m[k][j] for k in range(j, i)), 0.0 * one)
    tr_inv = sum(inv_piv[k] * sum(m[k][i] * m[k][i] for i in range(k + 1)) for k in range(n))
    tr = sum(a[i][i] for i in range(n))
    ok = ok & (tr * tr_inv <= CONDITION_BOUND)
    return jnp.stack(p), ok


@jax.custom_batching.custom_vmap
def newton_direction(hmat, g, needed):
    """``(n,)`` Newton direction of the module docstring for the symmetric Hessian ``hmat``
    ``(n, n)`` and the gradient ``g`` ``(n,)``; ``needed`` ``()`` bool: where false the
    direction is not used and may be anything, even not finite (under ``vmap`` such lanes
    cost no ``eigh``). One lane: `eigen_direction`."""
    del needed
    return eigen_direction(hmat, g)


@newton_direction.def_vmap
def _newton_direction_batched(axis_size, in_batched, hmat, g, needed):
    hmat, g, needed = (
        a if batched else jnp.broadcast_to(a, (axis_size,) + jnp.shape(a))
        for a, batched in zip((hmat, g, needed), in_batched)
    )
    lead = hmat.shape[:-2]  # (axis_size,) or, under an outer vmap, more: flatten all
    n = hmat.shape[-1]
    hmat, g, needed = hmat.reshape(-1, n, n), g.reshape(-1, n), needed.reshape(-1)
    if hmat.shape[0] <= EIGH_BLOCK:  # one block: nothing to gather, eigh for every lane
        return jax.vmap(eigen_direction)(hmat, g).reshape(lead + (n,)), True
    p, ok = jax.vmap(ldl_direction)(hmat, g)
    p = _eigh_where(hmat, g, needed & ~ok, p)
    return p.reshape(lead + (n,)), True


def _eigh_where(hmat, g, use, p):
    """``p`` ``(B, n)`` with the rows where ``use`` ``(B,)`` replaced by
    `eigen_direction`, computed in gathered blocks of `EIGH_BLOCK` rows
    (`jaxgrasp.solver._rows.over_rows`: none where there are none)."""

    def update(rows, valid, p):
        return put_rows(p, rows, valid, jax.vmap(eigen_direction)(hmat[rows], g[rows]))

    return over_rows(use, EIGH_BLOCK, update, p)
