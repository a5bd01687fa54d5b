"""The surface in JAX: closest points, normals and signed distances against closed forms, the
derivative of a point on a face, padding, and the contact rules on shapes whose answer is known."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import jaxgrasp  # noqa: F401  (float64)
from jaxgrasp.io._mesh import load_mesh
from jaxgrasp.surface import ContactRules, Surface, check_contacts, closest_on_triangles, contact_radius, deformation_range

HALF = np.array([0.05, 0.03, 0.02])  # m, half-extents of the test box
MESH = Path(__file__).resolve().parents[2] / "examples" / "meshes" / "pybullet_000_mm.obj"


@pytest.fixture(scope="module")
def box():
    return Surface.from_trimesh(trimesh.creation.box(extents=2 * HALF))


def test_box_closest_point_and_signed_distance_are_the_closed_forms(box):
    # outside a box the closest point is the clamp; inside it is the nearest face, at the
    # smallest of the half-extent gaps, with a negative sign
    p = np.random.default_rng(0).uniform(-0.07, 0.07, size=(400, 3))
    hit = box.closest(p)
    out = np.any(np.abs(p) > HALF, axis=1)
    assert out.sum() > 100 and (~out).sum() > 10
    clamp = np.clip(p, -HALF, HALF)
    np.testing.assert_allclose(np.asarray(hit.point)[out], clamp[out], atol=1e-15)
    signed = np.where(out, np.linalg.norm(p - clamp, axis=1), -np.min(HALF - np.abs(p), axis=1))
    np.testing.assert_allclose(np.asarray(hit.signed_distance), signed, atol=1e-15)
    # the normal is the face's: along the axis of the nearest face, pointing out
    axis = np.argmin(HALF - np.abs(p[~out]), axis=1)
    n = np.asarray(hit.normal)[~out]
    np.testing.assert_allclose(n[np.arange(len(axis)), axis], np.sign(p[~out][np.arange(len(axis)), axis]))


def test_closest_agrees_with_the_numpy_snap_on_a_real_mesh():
    mesh = load_mesh(MESH, "mm")
    s = Surface.from_trimesh(mesh)
    tri = np.asarray(mesh.triangles)
    p = np.random.default_rng(1).uniform(mesh.bounds[0] - 0.01, mesh.bounds[1] + 0.01, size=(30, 3))
    hit = s.closest(p)
    for i, q in enumerate(p):
        d = np.linalg.norm(closest_on_triangles(q, tri, xp=np) - q, axis=1)  # the rule run in NumPy
        assert abs(float(hit.distance[i]) - d.min()) < 1e-12
    # a point on the surface is its own closest point; padding changes nothing
    again = s.padded(256).closest(hit.point)
    np.testing.assert_allclose(np.asarray(again.point), np.asarray(hit.point), atol=1e-15)
    assert s.padded(256).num_faces == 512 and s.num_faces == len(mesh.faces)


def test_derivative_on_a_face_is_the_tangential_projection():
    ball = Surface.from_trimesh(trimesh.creation.icosphere(subdivisions=2, radius=0.03))
    face = 17
    n = np.asarray(ball.normals[face])
    q = jnp.asarray(np.asarray(ball.triangles[face]).mean(axis=0) + 0.002 * n)  # above the face's middle
    assert int(ball.closest(q).face) == face
    jac = np.asarray(jax.jit(jax.jacfwd(lambda x: ball.closest(x).point))(q))
    np.testing.assert_allclose(jac, np.eye(3) - np.outer(n, n), atol=1e-12)
    h = 1e-7  # central differences agree inside the face
    fd = np.stack([(np.asarray(ball.closest(q + h * e).point) - np.asarray(ball.closest(q - h * e).point)) / (2 * h)
                   for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(jac, fd, atol=1e-6)
    assert np.allclose(np.asarray(jax.jit(jax.jacfwd(lambda x: ball.closest(x).normal))(q)), 0.0)


def test_deformation_range_and_contact_radius_closed_forms():
    lo, hi = deformation_range(0.01, 3e5, 15.0, 5e-4)
    assert float(lo) == 5e-4 and float(hi) == pytest.approx(np.sqrt(15.0 / (np.pi * 3e5)), rel=1e-15)
    _, hi_stiff = deformation_range(0.01, 1e3, 15.0, 5e-4)  # soft: the 0.9 r cap
    assert float(hi_stiff) == pytest.approx(0.009)
    assert float(contact_radius(0.01, 0.004)) == pytest.approx(np.sqrt(0.01**2 - 0.006**2), rel=1e-15)


def _one(box, positions, normals, dr, rules=ContactRules()):
    n = len(positions)
    return check_contacts(box, jnp.asarray(positions, float), jnp.asarray(normals, float), jnp.full(n, dr), 0.01,
                          3e5, 15.0, rules)


def test_rules_on_a_box(box):
    x = np.array([1.0, 0.0, 0.0])
    good = _one(box, [[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]], [x, -x], 0.002)
    assert bool(good.valid)
    # the contact radius at dr = 2 mm is sqrt(10^2 - 8^2) = 6 mm: a contact closer than that to
    # the box's edge (at y = 30 mm) has the side face, at 90 degrees, under its fingertip
    edge = lambda y, rules=ContactRules(): _one(box, [[0.05, y, 0.0], [-0.05, 0.0, 0.0]], [x, -x], 0.002, rules)  # noqa: E731
    assert list(np.asarray(edge(0.0245).flat)) == [False, True] and not bool(edge(0.0245).valid)
    assert bool(edge(0.0235).valid)
    assert bool(edge(0.0245, ContactRules(flatness_deg=89.99)).flat[0]) is False  # 90 degrees
    # two fingertips 10 mm apart on one face: spheres of radius 10 mm overlap
    y = np.array([0.0, 1.0, 0.0])
    near = _one(box, [[0.0, 0.03, 0.0], [0.01, 0.03, 0.0]], [y, y], 0.002)
    assert not np.any(np.asarray(near.apart))
    # a normal that is not the face's, a point off the surface, a deformation beyond the force limit
    tilted = _one(box, [[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]], [x + 0.1 * y, -x], 0.002)
    assert list(np.asarray(tilted.on_surface)) == [False, True]
    off = _one(box, [[0.0501, 0.0, 0.0], [-0.05, 0.0, 0.0]], [x, -x], 0.002)
    assert list(np.asarray(off.on_surface)) == [False, True]
    deep = _one(box, [[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]], [x, -x], 0.0045)  # > sqrt(15 / (pi 3e5)) = 3.99 mm
    assert not np.any(np.asarray(deep.deformation))


def test_a_fingertip_in_a_corner_touches_a_second_wall():
    # an L-shaped block: a fingertip on the floor next to the inner wall touches that wall too
    lower = trimesh.creation.box(extents=[0.1, 0.1, 0.02])
    upper = trimesh.creation.box(extents=[0.02, 0.1, 0.06])
    upper.apply_translation([0.04, 0.0, 0.03])
    block = Surface.from_trimesh(trimesh.util.concatenate([lower, upper]))  # overlapping: distances are the same
    z = np.array([0.0, 0.0, 1.0])
    floor = lambda x: check_contacts(block, jnp.array([[x, 0.0, 0.01]]), jnp.array([z]), jnp.array([0.002]),  # noqa: E731
                                     0.01, 3e5, 15.0, ContactRules(flatness_deg=89.9))
    assert bool(floor(-0.02).alone[0])  # 40 mm from the wall
    assert not bool(floor(0.025).alone[0])  # the fingertip's centre is 5 mm from the wall: closer than r - dr
