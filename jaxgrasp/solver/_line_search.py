"""Backtracking on a fixed ladder of step lengths, for a batch of lanes at once.

Each lane tries ``alpha = 1, 1/2, 1/4, ...`` (``line_search_steps`` lengths) along its
direction and takes the first that passes Armijo's test (backtracking, Nocedal & Wright
Alg. 3.1), or, where none does, the one with the lowest merit. Where no length lowers the
merit at all, it tries a deeper ladder of as many lengths again, ``2^-steps, ...``, with
the same rule made strict by the slack instead of loose (a length there must lower the
merit by more than its rounding), and where none of those does, it stays put. A lane needs the
deeper ladder where its Newton direction ignores constraints that are nearly active but
not yet penalised (an object sliding towards two slip boundaries at once): the full step
crosses them, and only a step far below the first ladder lowers the merit. Without it
such a lane stays where it is until its step budget runs out.

Almost every Newton step takes the full length, but in a batch of a hundred lanes some
lane nearly always walks the whole ladder (a converged lane whose merit cannot fall
below its rounding), and a batched loop over the ladder runs as long as its slowest lane.
So the full length is tried for every lane, and only the lanes that fail it walk the rest,
gathered in blocks of `LADDER_BLOCK` lanes whose remaining lengths are all
evaluated at once: the cost follows the number of such lanes (none: no block at all),
and each lane's step is what a walk of its own ladder would give. A batch of at most
one block (a single grasp's few slots, one lane of `jaxgrasp.solver.solve`) walks
each lane's ladder lazily instead: a smaller executable, and the same steps.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxgrasp.solver._rows import over_rows, put_rows

__all__ = ["line_search", "LADDER_BLOCK"]

#: lanes per gathered block of the rest of the ladder
LADDER_BLOCK = 8


def _finite(t):
    """A merit that is not a number (an invalid pose) counts as ``+inf``."""
    return jnp.where(jnp.isfinite(t), t, jnp.inf)


def _armijo(t, alpha, phi0, slope, slack):
    """Armijo's test with rounding slack: ``t <= phi0 + 1e-4 alpha slope + slack``."""
    return t <= phi0 + 1e-4 * alpha * slope + slack


def line_search(merit, x, p, phi0, slope, needs_step, steps: int, rounding: float, deeper):
    """Backtracking line search of a batch of ``B`` lanes with ``n`` variables.

    Args:
        merit: ``(x, lane) -> ()``, the merit of lane ``lane`` (a uint32 index into the
            batch) at the point ``x`` ``(n,)``.
        x: ``(B, n)`` current points.
        p: ``(B, n)`` descent directions.
        phi0: ``(B,)`` merit at ``x``.
        slope: ``(B,)`` directional derivative of the merit along ``p`` (negative).
        needs_step: ``(B,)`` bool; lanes where it is false try no length past the first
            (their result is not used).
        steps: number of lengths on the ladder ``1, 1/2, ..., 2^(1 - steps)``, and on the
            deeper one ``2^-steps, ..., 2^(1 - 2 steps)``.
        rounding: relative slack of Armijo's test (``slack = rounding (|phi0| + 1)``):
            near a minimiser at a large penalty the decrease a Newton step promises is
            below phi's rounding error, and a strict test would reject the very steps
            that converge.
        deeper: ``(B,)`` bool, the lanes that may walk the deeper ladder.

    Returns:
        ``(x_new, improve)``: ``x_new`` ``(B, n)`` is ``x + alpha p`` for the first
        ``alpha`` that passes Armijo (``merit <= phi0 + 1e-4 alpha slope + slack``), else
        for the one with the lowest merit; where no ``alpha`` of the ladder lowers the
        merit, the same on the deeper ladder with ``-slack`` for ``slack`` and
        ``phi0 - slack`` as the merit to lower; ``x`` itself where none of either does
        (``improve`` ``(B,)`` bool is then false).
    """
    size = x.shape[0]
    alphas = 0.5 ** jnp.arange(2 * steps, dtype=x.dtype)  # the ladder, then the deeper one
    slack = rounding * (jnp.abs(phi0) + 1.0)
    if size <= LADDER_BLOCK:  # one block: each lane walks its own ladder (a smaller executable)
        walk = partial(_walk, merit, alphas, steps)
        return jax.vmap(walk)(x, p, phi0, slope, slack, needs_step, deeper, jnp.arange(size, dtype=jnp.uint32))

    values = lambda xs, lanes: _finite(jax.vmap(merit)(xs, lanes))
    t0 = values(x + p, jnp.arange(size, dtype=jnp.uint32))
    ok0 = _armijo(t0, alphas[0], phi0, slope, slack)
    idx = jnp.zeros(size, jnp.int32)
    improve = ok0 | (t0 < phi0)
    if steps > 1:
        idx, improve = _rest_of_ladder(values, x, p, phi0, slope, slack, t0, needs_step & ~ok0, alphas[:steps],
                                       idx, improve)
    idx, improve = _deeper_ladder(values, x, p, phi0, slope, slack, needs_step & deeper & ~improve, alphas[steps:],
                                  idx, improve, steps)
    return jnp.where(improve[:, None], x + alphas[idx][:, None] * p, x), improve


def _walk(merit, alphas, steps, x, p, phi0, slope, slack, needs_step, deeper, lane):
    """One lane's ladder, then (where ``deeper``) its deeper one, walked lazily (a while
    loop that stops at the first length passing Armijo's test, or at the end of the first
    ladder where a length lowered the merit): ``(x_new, improve)`` as `line_search`
    gives them. ``alphas`` holds both ladders, ``steps`` lengths each."""

    def cond(c):
        k, found, best_val = c[0], c[1], c[4]
        return (k < alphas.shape[0]) & ~found & ~((k == steps) & ((best_val < phi0) | ~deeper))

    def body(c):
        k, found, first, best, best_val = c
        a = alphas[k]
        t = _finite(merit(x + a * p, lane))
        ok = _armijo(t, a, phi0, slope, jnp.where(k < steps, slack, -slack))
        first = jnp.where(ok, k, first)
        better = t < best_val
        best = jnp.where(better, k, best)
        best_val = jnp.where(better, t, best_val)
        return k + 1, found | ok, first, best, best_val

    zero = jnp.asarray(0, jnp.int32)
    _, armijo, first, best, best_val = jax.lax.while_loop(
        cond, body, (zero, ~needs_step, zero, zero, jnp.asarray(jnp.inf, x.dtype))
    )
    idx = jnp.where(armijo, first, best)
    improve = armijo | (best_val < jnp.where(best < steps, phi0, phi0 - slack))
    return jnp.where(improve, x + alphas[idx] * p, x), improve


def _block_values(values, x, p, rows, lengths):
    """``(block, L)`` merits of the lanes ``rows`` at ``x + alpha p`` for each of the ``L``
    ``lengths``, in one batched call of ``values``."""
    xs = x[rows][:, None, :] + lengths[:, None] * p[rows][:, None, :]  # (block, L, n)
    lanes = jnp.broadcast_to(rows[:, None], xs.shape[:2])
    return values(xs.reshape(-1, xs.shape[-1]), lanes.reshape(-1)).reshape(xs.shape[:2])


def _rest_of_ladder(values, x, p, phi0, slope, slack, t0, rest, alphas, idx, improve):
    """``(idx, improve)`` ``(B,)`` with the lanes where ``rest`` is true decided on the
    whole ladder: every length past the first, evaluated in gathered blocks of
    `LADDER_BLOCK` lanes (`jaxgrasp.solver._rows.over_rows`)."""
    more = alphas[1:]  # (steps - 1,)

    def update(rows, valid, c):
        idx, improve = c
        ts = _block_values(values, x, p, rows, more)  # (block, steps - 1)
        ok = _armijo(ts, more, phi0[rows][:, None], slope[rows][:, None], slack[rows][:, None])
        every = jnp.concatenate([t0[rows][:, None], ts], axis=1)  # (block, steps)
        armijo = jnp.any(ok, axis=1)
        k = jnp.where(armijo, jnp.argmax(ok, axis=1) + 1, jnp.argmin(every, axis=1))
        better = armijo | (jnp.min(every, axis=1) < phi0[rows])
        return put_rows(idx, rows, valid, k.astype(idx.dtype)), put_rows(improve, rows, valid, better)

    return over_rows(rest, LADDER_BLOCK, update, (idx, improve))


def _deeper_ladder(values, x, p, phi0, slope, slack, deep, deeper, idx, improve, offset: int):
    """``(idx, improve)`` ``(B,)`` with the lanes where ``deep`` is true (no length of the
    first ladder lowered their merit) decided on the lengths ``deeper``: the first that
    passes Armijo's test with ``-slack``, else the lowest merit below ``phi0 - slack``:
    so short a step must lower the merit by more than its rounding, or a lane at its
    rounding floor would wander by rounding noise. ``idx`` counts from the start of the
    first ladder (``offset`` lengths). Gathered in blocks of `LADDER_BLOCK` lanes,
    none where no lane needs it."""

    def update(rows, valid, c):
        idx, improve = c
        ts = _block_values(values, x, p, rows, deeper)  # (block, steps)
        ok = _armijo(ts, deeper, phi0[rows][:, None], slope[rows][:, None], -slack[rows][:, None])
        armijo = jnp.any(ok, axis=1)
        k = offset + jnp.where(armijo, jnp.argmax(ok, axis=1), jnp.argmin(ts, axis=1))
        better = armijo | (jnp.min(ts, axis=1) < phi0[rows] - slack[rows])
        return put_rows(idx, rows, valid, k.astype(idx.dtype)), put_rows(improve, rows, valid, better)

    return over_rows(deep, LADDER_BLOCK, update, (idx, improve))
