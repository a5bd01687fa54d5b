"""The batched backtracking ladder (:mod:`jaxgrasp.solver._line_search`) against a plain walk of
each lane's own ladder, written here from its definition: the first length passing
Armijo's test, else the length with the lowest merit, else no move."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.solver._line_search import LADDER_BLOCK, line_search  # importing jaxgrasp turns on float64

STEPS = 16
ROUNDING = 1e-13


def merit_of(centres, curv):
    """Lane ``k``'s merit: a quartic well ``sum curv_k (x - c_k)^2 + (x - c_k)^4``."""
    def merit(x, k):
        d = x - centres[k]
        return jnp.sum(curv[k] * d * d + d ** 4)
    return merit


def reference(merit, x, p, phi0, slope, needs_step, deeper):
    out, imp = [], []
    for k in range(x.shape[0]):
        if not needs_step[k]:
            out.append(None)
            imp.append(None)
            continue
        slack = ROUNDING * (abs(phi0[k]) + 1.0)
        ladders = (range(STEPS), range(STEPS, 2 * STEPS)) if deeper[k] else (range(STEPS),)
        for ladder, sign in zip(ladders, (1.0, -1.0)):  # the deeper one where the first lowers nothing
            best, best_val, chosen = 0, np.inf, None
            for i in ladder:
                a = 0.5 ** i
                t = float(merit(jnp.asarray(x[k] + a * p[k]), k))
                t = t if np.isfinite(t) else np.inf
                if t <= phi0[k] + 1e-4 * a * slope[k] + sign * slack:
                    chosen = i
                    break
                if t < best_val:
                    best, best_val = i, t
            # the deeper ladder must lower phi by more than its rounding
            improve = chosen is not None or best_val < phi0[k] - (sign < 0) * slack
            if improve:
                break
        i = chosen if chosen is not None else best
        out.append(x[k] + 0.5 ** i * p[k] if improve else x[k])
        imp.append(improve)
    return out, imp


@pytest.mark.parametrize("size", [1, 3, LADDER_BLOCK, 4 * LADDER_BLOCK + 3])
def test_batched_ladder_equals_each_lanes_walk(size):
    rng = np.random.default_rng(size)
    n = 4
    centres = jnp.asarray(rng.normal(size=(size, n)))
    curv = jnp.asarray(rng.uniform(0.1, 2.0, size=(size, n)))
    merit = merit_of(centres, curv)
    x = rng.normal(size=(size, n))
    grad = np.asarray(jax.vmap(jax.grad(merit))(jnp.asarray(x), jnp.arange(size)))
    # directions of every kind: exact-ish Newton (full step), far too long (many halvings),
    # so long that only the deeper ladder lowers phi, ascent (no length helps), zero (no
    # length lowers phi)
    scale = rng.choice([0.3, 1.0, 50.0, 1e4, 1e7, -1.0, 0.0], size=size)
    p = -grad * scale[:, None]
    phi0 = np.asarray(jax.vmap(merit)(jnp.asarray(x), jnp.arange(size)))
    slope = np.einsum("bi,bi->b", grad, p)
    needs = rng.uniform(size=size) < 0.85
    deeper = rng.uniform(size=size) < 0.7
    x_new, improve = jax.jit(lambda *a: line_search(merit, *a[:5], STEPS, ROUNDING, deeper=a[5]))(
        jnp.asarray(x), jnp.asarray(p), jnp.asarray(phi0), jnp.asarray(slope), jnp.asarray(needs), jnp.asarray(deeper))
    ref_x, ref_imp = reference(merit, x, p, phi0, slope, needs, deeper)
    x_new, improve = np.asarray(x_new), np.asarray(improve)
    for k in np.flatnonzero(needs):
        assert improve[k] == ref_imp[k], k
        if jax.default_backend() == "cpu":
            np.testing.assert_array_equal(x_new[k], ref_x[k])
        else:  # a GPU may fuse x + t p into one multiply-add, one rounding fewer than NumPy's
            bound = 2 * np.finfo(np.float64).eps * (np.abs(x[k]) + np.abs(ref_x[k] - x[k]))
            assert np.all(np.abs(x_new[k] - ref_x[k]) <= bound), (k, x_new[k] - ref_x[k])
    # the kinds above all occur when there are lanes enough
    if size > 8:
        assert improve[needs].any() and (~improve[needs]).any()
        moved = np.linalg.norm(x_new - x, axis=1) / np.maximum(np.linalg.norm(p, axis=1), 1e-300)
        deep = needs & improve & (moved > 0) & (moved < 0.5 ** (STEPS - 0.5))  # a deeper ladder's length
        assert np.any(deep) and not np.any(deep & ~deeper), (moved, deeper)
        assert np.any(needs & ~deeper & ~improve & (scale >= 1e7))  # the deeper ladder refused
