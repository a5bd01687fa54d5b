"""The polish's KKT derivatives (``jaxgrasp.tolerance._settle._relaxed_derivatives``),
written out from the contact kinematics' derivatives, equal autodiff of the relaxed
problem it polishes (``_relaxed_problem``): the objective's gradient, the constraints'
Jacobian and the Hessian of the Lagrangian, with contacts released to their pyramid rows,
slip rows in cone form, a masked contact, and rotations from exactly zero to large."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from grasp_draws import NumpyDraw, build_grasp

from jaxgrasp.model._potential import model_params
from jaxgrasp.tolerance import _settle
from jaxgrasp.tolerance._problems import problem_data

N = 3  # one contact count: each jitted function below compiles once


@jax.jit
def _both(data, z, lam, released, cone):
    """(written out, autodiff): each ``(grad f, J, Hessian of f - lam . g)``."""
    rows = jnp.arange(3 * N)
    relaxed = released[rows % N]
    v = jax.vmap(lambda j: _settle._pyramid_basis(z, data, j))(jnp.arange(N))
    fg = lambda z: _settle._relaxed_problem(z, data, v, relaxed, cone)  # noqa: E731
    auto = (
        jax.grad(lambda z: fg(z)[0])(z),
        jax.jacfwd(lambda z: fg(z)[1])(z),
        jax.hessian(lambda z: fg(z)[0] - lam @ fg(z)[1])(z),
    )
    return _settle._relaxed_derivatives(z, lam, data, v, relaxed, cone), auto


def _cases():
    """(grasp, z, released, cone): poses from exactly zero rotation (the rotation's
    series branch) to large, no contact / one / all released, cone form on and off, and a
    masked contact (never released: ``_released_contacts`` requires it active)."""
    rng = np.random.default_rng(17)
    cases = []
    for w_scale, released, cone in (
            (0.0, (False, False, False), False),
            (0.0, (True, False, False), True),
            (1e-4, (False, True, False), False),
            (0.05, (True, False, True), True),
            (0.05, (False, False, False), True),
            (0.6, (True, True, True), False),
            (0.6, (False, True, True), True),
    ):
        grasp = build_grasp(NumpyDraw(rng), n=N)
        z = np.concatenate([rng.normal(size=3) * 0.2, rng.normal(size=3) * w_scale])
        cases.append(pytest.param(grasp, z, released, cone, id=f"w{w_scale:g}-released{sum(released)}-cone{int(cone)}"))
    grasp = build_grasp(NumpyDraw(rng), n=N).replace(active=np.array([True, False, True]))
    cases.append(pytest.param(grasp, rng.normal(size=6) * 0.05, (True, False, False), True, id="masked"))
    return cases


@pytest.mark.parametrize("grasp, z, released, cone", _cases())
def test_written_out_equals_autodiff(grasp, z, released, cone):
    data = problem_data(model_params(grasp))
    z = jnp.asarray(z) * jnp.concatenate([jnp.ones(3), jnp.full(3, data.lever)])  # scaled pose
    lam = jnp.asarray(np.random.default_rng(5).normal(size=3 * N))
    got, want = _both(data, z, lam, jnp.asarray(released), jnp.asarray(cone))
    for g, w in zip(got, want):
        scale = max(float(jnp.max(jnp.abs(w))), 1e-300)
        np.testing.assert_allclose(g, w, rtol=1e-11, atol=1e-11 * scale)
    np.testing.assert_allclose(got[2], got[2].T, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(got[2]))))
