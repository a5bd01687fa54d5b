"""The start search's crossing onto a boundary (``programs._ray_start``): bracket on the
ray's grid, then safeguarded regula falsi (Illinois). Closed forms: the crossing of a
smooth margin along a ray is known exactly."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.tolerance._starts import _ray_start  # importing jaxgrasp turns on float64

GRID = 2.0 ** (-(47 - jnp.arange(48.0)) / 4.0)  # the default ray grid, t_max = 1


@pytest.mark.parametrize(
    "margin, t_star",
    [
        (lambda z: 0.3 - z[0], 0.3),  # linear: the secant is exact
        (lambda z: 1.0 - jnp.dot(z, z) / 0.04, 0.2 / np.sqrt(2.0)),  # a sphere of radius 0.2
        (lambda z: jnp.cos(5.0 * z[0]) - 0.5, np.pi / 15.0),  # cos(5t) = 1/2
        (lambda z: jnp.expm1(30.0 * (0.9 - z[0])), 0.9),  # steep: slow for plain regula falsi
    ],
)
def test_crossing_is_found_to_rounding(margin, t_star):
    v = jnp.asarray([1.0, 1.0, 0.0, 0.0, 0.0, 0.0]) if "dot" in margin.__code__.co_names else jnp.eye(6)[0]
    z, found, g0 = jax.jit(lambda: _ray_start(margin, jnp.zeros(6), v, GRID, 12))()
    assert float(g0) == pytest.approx(float(margin(jnp.zeros(6))), rel=1e-15)  # the origin's margin
    assert bool(found)
    t = float(z[0])
    assert t == pytest.approx(t_star, rel=1e-12, abs=0)
    assert abs(float(margin(z))) <= 1e-12  # on the boundary, to rounding


def test_no_crossing_and_nan_values():
    """No crossing on the ray: not found. A NaN region (an invalid pose) before the
    crossing is never taken for it, and a NaN inside the bracket makes the step bisect."""
    z, found, _ = _ray_start(lambda z: 1.0 + z[0], jnp.zeros(6), jnp.eye(6)[0], GRID, 12)
    assert not bool(found)
    nan_inside = lambda z: jnp.where((z[0] > 0.25) & (z[0] < 0.29), jnp.nan, 0.3 - z[0])
    z, found, _ = _ray_start(nan_inside, jnp.zeros(6), jnp.eye(6)[0], GRID, 40)
    assert bool(found) and float(z[0]) == pytest.approx(0.3, rel=1e-12)


def test_one_contact_data_gives_that_contacts_constraint_rows():
    """The start search evaluates a ray's own contact only (``programs._contact_data``):
    for every contact ``j`` of random 5-contact grasps (one with an inactive contact) at
    random poses, its three margins equal rows ``j, N + j, 2N + j`` of the whole grasp's."""
    from jaxgrasp.model._potential import model_params
    from jaxgrasp.tolerance._starts import _contact_data
    from jaxgrasp.tolerance._problems import constraints, problem_data
    from grasp_draws import NumpyDraw, build_grasp

    rng = np.random.default_rng(7)
    for case in range(4):
        g = build_grasp(NumpyDraw(rng), 5)
        if case == 3:
            g = g.replace(active=np.array([True, True, False, True, True]))
        data = problem_data(model_params(g))
        for _ in range(3):
            z = rng.normal(scale=0.5, size=6)
            whole = np.asarray(constraints(z, data)).reshape(3, 5)
            for j in range(5):
                one = np.asarray(constraints(z, _contact_data(data, jnp.asarray(j))))
                np.testing.assert_allclose(one, whole[:, j], rtol=1e-13, atol=1e-15, err_msg=f"case {case} contact {j}")
