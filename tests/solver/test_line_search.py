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


def reference(merit, x, p, phi0, slope, needs_step):
    out, imp = [], []
    for k in range(x.shape[0]):
        if not needs_step[k]:
            out.append(None)
            imp.append(None)
            continue
        slack = ROUNDING * (abs(phi0[k]) + 1.0)
        best, best_val, chosen = 0, np.inf, None
        for i in range(STEPS):
            a = 0.5 ** i
            t = float(merit(jnp.asarray(x[k] + a * p[k]), k))
            t = t if np.isfinite(t) else np.inf
            if t <= phi0[k] + 1e-4 * a * slope[k] + slack:
                chosen = i
                break
            if t < best_val:
                best, best_val = i, t
        improve = chosen is not None or best_val < phi0[k]
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
    # ascent (no length helps), zero (no length lowers phi)
    scale = rng.choice([0.3, 1.0, 50.0, 1e4, -1.0, 0.0], size=size)
    p = -grad * scale[:, None]
    phi0 = np.asarray(jax.vmap(merit)(jnp.asarray(x), jnp.arange(size)))
    slope = np.einsum("bi,bi->b", grad, p)
    needs = rng.uniform(size=size) < 0.85
    x_new, improve = jax.jit(lambda *a: line_search(merit, *a, STEPS, ROUNDING))(
        jnp.asarray(x), jnp.asarray(p), jnp.asarray(phi0), jnp.asarray(slope), jnp.asarray(needs))
    ref_x, ref_imp = reference(merit, x, p, phi0, slope, needs)
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
