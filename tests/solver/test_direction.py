"""The solver's Newton direction (:mod:`jaxgrasp.solver._direction`) on its own.

The direction is a function of the Hessian as a matrix, ``-|H|^-1 g`` with ``|H|``'s
eigenvalues floored at ``1e-10`` of the largest: checked against that closed form
(numpy's ``eigh``), for single lanes and for batches mixing positive definite,
indefinite, singular and badly conditioned Hessians, where under ``vmap`` the
factorisation serves the first kind and the gathered ``eigh`` the others. Its invariance
under a rotation of the variables (which a pivoted or modified factorisation breaks) is
checked too.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.solver._direction import (
    CONDITION_BOUND,
    EIGH_BLOCK,
    eigen_direction,
    ldl_direction,
    newton_direction,
)  # importing jaxgrasp turns on float64


def closed_form(h, g):
    e, v = np.linalg.eigh(h)
    a = np.maximum(np.abs(e), 1e-10 * np.max(np.abs(e)))
    return -v @ ((v.T @ g) / a)


def tolerance(h, p_ref):
    """What any backward-stable solve of ``h`` can promise on ``p_ref``: ``100 eps`` times
    the condition number of ``|h|`` (floored as the direction floors it), times ``|p|``."""
    a = np.abs(np.linalg.eigvalsh(h))
    a = np.maximum(a, 1e-10 * a.max())
    return 100 * np.finfo(float).eps * (a.max() / a.min()) * np.max(np.abs(p_ref))


def random_symmetric(rng, eigenvalues):
    q, _ = np.linalg.qr(rng.normal(size=(len(eigenvalues),) * 2))
    return (q * np.asarray(eigenvalues)) @ q.T


def mixed_batch(rng, size):
    """Hessians of every kind, in a shuffled order: positive definite (well and badly
    conditioned), indefinite, singular, negative definite."""
    kinds = [
        lambda: rng.uniform(0.5, 3.0, 6),
        lambda: np.geomspace(1.0, 1e8, 6) * rng.uniform(0.5, 2.0),  # PD, cond 1e8
        lambda: np.geomspace(1.0, 1e12, 6),  # PD beyond the factorisation's bound
        lambda: rng.uniform(0.5, 3.0, 6) * np.array([1, 1, -1, 1, 1, 1]),
        lambda: np.array([2.0, 1.0, 0.0, 3.0, 1.0, 5.0]),
        lambda: -rng.uniform(0.5, 3.0, 6),
    ]
    hs = np.stack([random_symmetric(rng, kinds[i % len(kinds)]()) for i in range(size)])
    perm = rng.permutation(size)
    return hs[perm], rng.normal(size=(size, 6))


def test_factorisation_is_newton_on_positive_definite():
    rng = np.random.default_rng(0)
    for cond in (1.0, 1e3, 1e8):
        h = random_symmetric(rng, np.geomspace(1.0, cond, 6))
        g = rng.normal(size=6)
        p, ok = ldl_direction(jnp.asarray(h), jnp.asarray(g))
        assert bool(ok)
        np.testing.assert_allclose(np.asarray(p), -np.linalg.solve(h, g), rtol=1e-12 * cond, atol=0)
        np.testing.assert_allclose(np.asarray(p), closed_form(h, g), rtol=1e-12 * cond, atol=0)


@pytest.mark.parametrize("eigenvalues", [
    [1.0, 2.0, -1.0, 3.0, 1.0, 1.0],  # indefinite
    [1.0, 2.0, 0.0, 3.0, 1.0, 1.0],  # singular
    [-1.0, -2.0, -1.0, -3.0, -1.0, -1.0],  # negative definite
    list(np.geomspace(1.0, 1e12, 6)),  # positive definite, tr(H) tr(H^-1) > bound
])
def test_factorisation_declines_what_it_cannot_serve(eigenvalues):
    h = random_symmetric(np.random.default_rng(1), eigenvalues)
    _, ok = ldl_direction(jnp.asarray(h), jnp.ones(6))
    assert not bool(ok)


def test_condition_bound_implies_the_floor_is_inactive():
    # tr(H) tr(H^-1) <= bound  =>  e_min >= e_max / bound >= 1e-10 e_max
    assert CONDITION_BOUND <= 1e10


def test_one_lane_is_eigh():
    rng = np.random.default_rng(2)
    hs, gs = mixed_batch(rng, 12)
    for h, g in zip(hs, gs):
        p = newton_direction(jnp.asarray(h), jnp.asarray(g), True)
        ref = closed_form(h, g)
        assert np.max(np.abs(np.asarray(p) - ref)) <= tolerance(h, ref)


@pytest.mark.parametrize("size", [1, 5, EIGH_BLOCK, 3 * EIGH_BLOCK + 5])
def test_batched_equals_closed_form(size):
    rng = np.random.default_rng(size)
    hs, gs = mixed_batch(rng, size)
    needed = np.ones(size, bool)
    p = jax.jit(jax.vmap(newton_direction))(jnp.asarray(hs), jnp.asarray(gs), jnp.asarray(needed))
    for h, g, pk in zip(hs, gs, np.asarray(p)):
        ref = closed_form(h, g)
        assert np.max(np.abs(pk - ref)) <= tolerance(h, ref)
    # every lane is a descent direction
    assert np.all(np.einsum("bi,bi->b", np.asarray(p), gs) < 0)


def test_lanes_not_needed_take_no_eigh_and_the_rest_are_exact():
    rng = np.random.default_rng(3)
    hs, gs = mixed_batch(rng, 40)
    needed = rng.uniform(size=40) < 0.5
    p = np.asarray(jax.jit(jax.vmap(newton_direction))(jnp.asarray(hs), jnp.asarray(gs), jnp.asarray(needed)))
    assert np.all(np.isfinite(p[needed]))
    for i in np.flatnonzero(needed):
        ref = closed_form(hs[i], gs[i])
        assert np.max(np.abs(p[i] - ref)) <= tolerance(hs[i], ref)


def test_nested_vmap_equals_closed_form():
    rng = np.random.default_rng(4)
    hs, gs = mixed_batch(rng, 24)
    needed = jnp.ones(24, bool)
    flat = jax.vmap(newton_direction)(jnp.asarray(hs), jnp.asarray(gs), needed)
    nested = jax.vmap(jax.vmap(newton_direction))(
        jnp.asarray(hs).reshape(4, 6, 6, 6), jnp.asarray(gs).reshape(4, 6, 6), needed.reshape(4, 6))
    for h, g, pf, pn in zip(hs, gs, np.asarray(flat), np.asarray(nested).reshape(24, 6)):
        ref = closed_form(h, g)
        assert np.max(np.abs(pf - ref)) <= tolerance(h, ref)
        assert np.max(np.abs(pn - ref)) <= tolerance(h, ref)


def test_rotation_invariance():
    """p(Q H Q^T, Q g) = Q p(H, g) for any orthogonal Q: the direction does not depend on
    the order or the frame of the variables."""
    rng = np.random.default_rng(5)
    hs, gs = mixed_batch(rng, 18)
    q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    run = jax.jit(jax.vmap(newton_direction))
    needed = jnp.ones(18, bool)
    p = np.asarray(run(jnp.asarray(hs), jnp.asarray(gs), needed))
    p_rot = np.asarray(run(jnp.asarray(q @ hs @ q.T), jnp.asarray(gs @ q.T), needed))
    for h, pk, pk_rot in zip(hs, p, p_rot):
        assert np.max(np.abs(pk_rot - q @ pk)) <= tolerance(h, pk)


def test_eigen_direction_matches_closed_form():
    rng = np.random.default_rng(6)
    hs, gs = mixed_batch(rng, 6)
    for h, g in zip(hs, gs):
        ref = closed_form(h, g)
        assert np.max(np.abs(np.asarray(eigen_direction(jnp.asarray(h), jnp.asarray(g))) - ref)) <= tolerance(h, ref)
