"""The distance grid (`jaxgrasp.surface._grid`): exact at its points, close between them,
never NaN in value or derivative (outside the box included), one shape for every object."""

import jax
import jax.numpy as jnp
import numpy as np
import trimesh

from jaxgrasp.surface import Surface, distance_grid


def _box():
    mesh = trimesh.creation.box(extents=(0.06, 0.04, 0.03))
    return mesh, Surface.from_trimesh(mesh)


def test_grid_points_hold_the_exact_signed_distance_and_interpolation_is_close():
    mesh, surface = _box()
    grid = distance_grid(surface, mesh.bounds[0] - 0.01, mesh.bounds[1] + 0.01, points_per_axis=24)
    assert grid.values.shape == (24, 24, 24)
    exact = jax.jit(lambda p: surface.closest(p).signed_distance)
    idx = np.array([[0, 0, 0], [5, 7, 11], [12, 12, 12], [23, 3, 17]])
    nodes = np.asarray(grid.origin) + float(grid.spacing) * idx
    np.testing.assert_allclose(np.asarray(grid(jnp.asarray(nodes))), np.asarray(exact(jnp.asarray(nodes))), atol=1e-15)
    # away from the box's edges the distance is linear in each cell: interpolation is exact there
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(-0.012, 0.012, 200), rng.uniform(-0.008, 0.008, 200), rng.uniform(0.017, 0.022, 200)]
    np.testing.assert_allclose(np.asarray(grid(jnp.asarray(p))), p[:, 2] - 0.015, atol=1e-12)
    # anywhere in the box: within a cell's diagonal of the truth
    q = rng.uniform(mesh.bounds[0] - 0.01, mesh.bounds[1] + 0.01, (2000, 3))
    err = np.abs(np.asarray(grid(jnp.asarray(q))) - np.asarray(exact(jnp.asarray(q))))
    assert err.max() < np.sqrt(3) * float(grid.spacing)


def test_outside_the_box_reads_far_with_finite_derivatives():
    mesh, surface = _box()
    grid = distance_grid(surface, mesh.bounds[0] - 0.005, mesh.bounds[1] + 0.005, points_per_axis=16)
    far = jnp.asarray([[0.5, 0.0, 0.0], [0.0, -0.2, 0.3], [0.0, 0.0, 0.0]])
    d = np.asarray(grid(far))
    assert d[0] > 0.4 and d[1] > 0.3 and d[2] < 0  # the centre is inside
    g = np.asarray(jax.vmap(jax.grad(lambda x: grid(x)))(far))
    assert np.all(np.isfinite(g))  # a point inside the box or on its face: derivative 0, not NaN, of the excess
    assert g[0, 0] > 0.9  # moving away along +x reads farther at the rate of the distance
