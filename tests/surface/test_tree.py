"""The face tree (issue 65, item 1): every search it answers equals a brute force over every
face, in JAX and on the host, on icospheres, subdivided boxes, a real object and a soup of
random triangles, for points near and far, inside and outside, on edges and vertices; the
derivative through the point still matches finite differences; padding changes nothing."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import jaxgrasp  # noqa: F401  (float64)
from jaxgrasp.io._mesh import load_mesh
from jaxgrasp.planning._sampling import first_hits
from jaxgrasp.surface import Surface, build_tree, closest_on_triangles, nearest_faces
from jaxgrasp.surface._tree import LEAF_SIZE

MESH = Path(__file__).resolve().parents[2] / "examples" / "meshes" / "pybullet_000_mm.obj"
PAD = 4096  # every surface here padded to one shape: one compilation of each search
QUERIES = 640


def _soup(rng, count=900):
    """Random triangles, overlapping and of every size: no structure a tree could lean on."""
    centre = rng.uniform(-0.05, 0.05, size=(count, 1, 3))
    tri = centre + rng.normal(scale=rng.uniform(0.001, 0.02, size=(count, 1, 1)), size=(count, 3, 3))
    return trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * count).reshape(-1, 3), process=False)


def _meshes():
    rng = np.random.default_rng(7)
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.04])
    for _ in range(3):
        box = box.subdivide()  # 768 faces, coplanar neighbours: ties everywhere
    return {
        "icosphere": trimesh.creation.icosphere(subdivisions=3, radius=0.04),
        "box": box,
        "object": load_mesh(MESH, "mm"),
        "soup": _soup(rng),
    }


MESHES = _meshes()


def _queries(mesh, rng):
    """``(QUERIES, 3)`` m: on vertices and edge midpoints (exactly, and nudged in and out),
    near the surface, inside, and far (ten mesh sizes) away."""
    v, e = np.asarray(mesh.vertices), np.asarray(mesh.edges_unique)
    size = float(np.ptp(v, axis=0).max())
    on = np.concatenate([v[rng.choice(len(v), 80)], v[e[rng.choice(len(e), 80)]].mean(axis=1)])
    nudged = on + rng.normal(scale=1e-3 * size, size=on.shape)
    near = mesh.sample(160, seed=1) + rng.normal(scale=0.02 * size, size=(160, 3))
    box = rng.uniform(mesh.bounds[0] - 0.1 * size, mesh.bounds[1] + 0.1 * size, size=(100, 3))
    far = rng.normal(size=(QUERIES - 580, 3))
    far = mesh.centroid + 10 * size * far / np.linalg.norm(far, axis=1, keepdims=True)
    return np.concatenate([on, nudged, near, box, far])


def _brute(surface: Surface, p):
    """The closest point rule over every face (NumPy): point, face, normal, distance, signed,
    and the faces as good as that face within round-off (tied in distance, their planes as
    far from ``p`` within ``1e-15`` of the mesh's size)."""
    tri, nrm, scale = (np.asarray(x) for x in (surface.triangles, surface.normals, surface.scale))
    q = closest_on_triangles(p, tri, xp=np)
    d2 = np.sum((q - p) ** 2, axis=1)
    tied = d2 <= (np.sqrt(d2.min()) + 1e-12 * scale) ** 2  # within 1e-12 of the mesh's size in distance
    height = np.where(tied, np.abs(np.einsum("fd,fd->f", p - q, nrm)), -1.0)
    f = int(np.argmax(height))
    d = float(np.linalg.norm(p - q[f]))
    return q[f], f, nrm[f], d, (-d if np.dot(p - q[f], nrm[f]) < 0 else d), set(np.flatnonzero(height >= height[f] - 1e-15 * scale))


@pytest.fixture(scope="module")
def closest():
    return jax.jit(lambda s, p: s.closest(p))


@pytest.mark.parametrize("name", sorted(MESHES))
def test_closest_equals_the_brute_force_over_every_face(name, closest):
    mesh = MESHES[name]
    surface = Surface.from_trimesh(mesh, pad_to=PAD)
    assert surface.tree.leaf_faces.size == PAD and surface.num_faces == PAD  # one shape for every mesh here
    pts = _queries(mesh, np.random.default_rng(3))
    hit = jax.tree_util.tree_map(np.asarray, closest(surface, pts))
    same = 0
    for i, p in enumerate(pts):
        point, face, normal, d, signed, as_good = _brute(surface, p)
        assert np.abs(hit.point[i] - point).max() <= 1e-12, (name, i)
        assert abs(hit.distance[i] - d) <= 1e-12, (name, i)
        # the face: the brute force's, or one tied with it within round-off (a point on an edge,
        # where JAX's and NumPy's arithmetic round the planes' heights of 0 differently)
        assert hit.face[i] in as_good, (name, i, hit.face[i], face)
        same += hit.face[i] == face
        if hit.face[i] == face:
            assert np.array_equal(hit.normal[i], normal) and abs(hit.signed_distance[i] - signed) <= 1e-12, (name, i)
    assert same >= len(pts) - 20, same


def test_a_point_near_an_edge_stays_on_its_own_face(closest):
    # 10 nm inside a face from its edge with a coplanar neighbour: the neighbour is 10 nm
    # away, no tie (a tie in squared distance of 1e-12 of the size squared, 100 nm here,
    # once took the neighbour, whichever index was smaller, and a point 10 nm off)
    grid = trimesh.creation.box(extents=[0.1, 0.06, 0.04]).subdivide().subdivide()
    surface = Surface.from_trimesh(grid, pad_to=PAD)
    tri = np.asarray(surface.triangles)[: len(grid.faces)]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    mid = 0.5 * (a + b)
    inward = (c - mid) / np.linalg.norm(c - mid, axis=1, keepdims=True)
    pts = (mid + 1e-8 * inward)[:QUERIES]
    hit = closest(surface, np.concatenate([pts, np.zeros((QUERIES - len(pts), 3))]))
    np.testing.assert_array_less(np.asarray(hit.distance)[: len(pts)], 1e-15)
    np.testing.assert_array_equal(np.asarray(hit.face)[: len(pts)], np.arange(len(pts)))


def test_padding_and_the_tree_change_no_answer(closest):
    mesh = MESHES["object"]
    bare, padded = Surface.from_trimesh(mesh), Surface.from_trimesh(mesh, pad_to=PAD)
    assert bare.tree.num_leaves == 32 and padded.tree.num_leaves == PAD // LEAF_SIZE  # 474 faces: 30 leaves of 16, rounded up
    pts = _queries(mesh, np.random.default_rng(4))
    a, b = closest(bare, pts), closest(padded, pts)
    np.testing.assert_allclose(np.asarray(a.point), np.asarray(b.point), atol=1e-15)
    np.testing.assert_allclose(np.asarray(a.signed_distance), np.asarray(b.signed_distance), atol=1e-15)
    # the face and normal too, but for the points exactly on a vertex or an edge (the first
    # 160), whose faces tie in distance and, within round-off, in the planes' heights (0)
    np.testing.assert_array_equal(np.asarray(a.face)[160:], np.asarray(b.face)[160:])
    np.testing.assert_array_equal(np.asarray(a.normal)[160:], np.asarray(b.normal)[160:])
    # a leaf holds between half and all of its slots' faces, once each; every face is in one leaf
    faces = np.asarray(bare.tree.leaf_faces)
    distinct = [len(set(row)) for row in faces]
    assert min(distinct) >= LEAF_SIZE // 2 and sorted(set(faces.ravel())) == list(range(bare.num_faces))
    # a moved surface moves its tree: the same answers, moved
    offset = np.array([0.3, -0.2, 0.1])
    moved = closest(padded.translated(offset), pts + offset)
    np.testing.assert_allclose(np.asarray(moved.point), np.asarray(b.point) + offset, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(moved.face)[160:], np.asarray(b.face)[160:])


def test_a_tiny_mesh_padded_to_many_leaves_repeats_its_faces():
    tet = trimesh.creation.icosphere(subdivisions=0, radius=0.01)  # 20 faces, 256 leaves
    s = Surface.from_trimesh(tet, pad_to=PAD)
    assert s.tree.num_leaves == PAD // LEAF_SIZE and set(np.asarray(s.tree.leaf_faces).ravel()) == set(range(20))
    p = np.random.default_rng(5).normal(scale=0.02, size=(50, 3))
    hit = s.closest(p)
    for i in range(len(p)):
        assert int(hit.face[i]) == _brute(s, p[i])[1]
        assert abs(float(hit.signed_distance[i]) - _brute(s, p[i])[4]) <= 1e-15


@pytest.mark.parametrize("name", ["icosphere", "box", "object"])
def test_flat_patch_rule_equals_the_faces_within_the_radius(name):
    # the old rule: every face within the radius (its closest point) has its normal within the angle
    mesh = MESHES[name]
    surface = Surface.from_trimesh(mesh, pad_to=PAD)
    rng = np.random.default_rng(6)
    p, fi = trimesh.sample.sample_surface(mesh, QUERIES, seed=2)
    n = np.asarray(mesh.face_normals)[fi] + rng.normal(scale=0.1, size=(QUERIES, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    size = float(np.ptp(mesh.vertices, axis=0).max())
    radius = rng.uniform(0.0, 0.2 * size, size=QUERIES)
    angle = 25.0
    got = np.asarray(jax.jit(lambda s, *a: s.unaligned_within(*a, angle))(surface, p, n, radius))
    tri, nrm = np.asarray(surface.triangles), np.asarray(surface.normals)
    want = []
    for i in range(QUERIES):
        d = np.linalg.norm(closest_on_triangles(p[i], tri, xp=np) - p[i], axis=1)
        want.append(np.any((d <= radius[i]) & (nrm @ n[i] < np.cos(np.deg2rad(angle)))))
    assert 0.1 < np.mean(want) < 0.9, np.mean(want)  # both answers are common
    np.testing.assert_array_equal(got, np.array(want))


def _old_first_hits(triangles, origins, directions):
    """The ray cast before the tree: Möller-Trumbore against every face."""
    a, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    o, d = origins[:, None, :], directions[:, None, :]
    p = np.cross(d, e2)
    det = np.einsum("rfd,fd->rf", p, e1)
    inv = 1.0 / np.where(np.abs(det) < 1e-300, np.inf, det)
    s = o - a
    u = np.einsum("rfd,rfd->rf", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("rfd,rfd->rf", d * np.ones_like(q), q) * inv
    t = np.einsum("rfd,fd->rf", q, e2) * inv
    t = np.where((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(inv), t, np.inf)
    best = np.argmin(t, axis=1)
    tb = t[np.arange(len(best)), best]
    return tb, np.where(np.isfinite(tb), best, -1)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_rays_equal_the_brute_force_over_every_face(name):
    mesh = MESHES[name]
    tri = np.asarray(mesh.triangles)
    rng = np.random.default_rng(8)
    p, fi = trimesh.sample.sample_surface(mesh, 300, seed=3)
    inward = -np.asarray(mesh.face_normals)[fi]
    outside = rng.normal(size=(200, 3)) * 0.2
    towards = mesh.centroid - outside + rng.normal(scale=0.01, size=(200, 3))
    axis = np.zeros((100, 3))
    axis[np.arange(100), rng.integers(0, 3, 100)] = rng.choice([-1.0, 1.0], 100)  # along the box's faces: parallel slabs
    origins = np.concatenate([p - 1e-9 * inward, outside, np.asarray(mesh.vertices)[rng.choice(len(mesh.vertices), 100)]])
    directions = np.concatenate([inward, towards, axis])
    t, face = first_hits(tri, origins, directions)
    t0, face0 = _old_first_hits(tri, origins, directions)
    assert (face0 >= 0).sum() > 300
    np.testing.assert_array_equal(face, face0)
    np.testing.assert_array_equal(t, t0)


@pytest.mark.parametrize("name", ["box", "soup"])
def test_host_search_keeps_every_face_tied_within_the_margin(name):
    mesh = MESHES[name]
    tri = np.asarray(mesh.triangles)
    tree = build_tree(tri, np.asarray(mesh.face_normals))
    pts = _queries(mesh, np.random.default_rng(9))
    margin = 1e-9
    query, face, point, dist = nearest_faces(tree, pts, margin=margin, scale=0.1)
    for i, p in enumerate(pts):
        d = np.linalg.norm(closest_on_triangles(p, tri, xp=np) - p, axis=1)
        mine = query == i
        assert sorted(face[mine]) == list(np.flatnonzero(d <= d.min() + margin)), i
        np.testing.assert_array_equal(dist[mine], d[face[mine]])


def test_reverse_mode_derivative_through_the_tree_matches_finite_differences():
    ball = Surface.from_trimesh(trimesh.creation.icosphere(subdivisions=4, radius=0.03), pad_to=PAD)
    rng = np.random.default_rng(10)
    q = jnp.asarray(rng.normal(size=(20, 3)))
    q = 0.032 * q / jnp.linalg.norm(q, axis=1, keepdims=True)  # 2 mm outside, over faces' interiors mostly
    w = jnp.asarray(rng.normal(size=(20, 3)))
    f = lambda x: jnp.sum(w * ball.closest(x).point) + jnp.sum(ball.closest(x).signed_distance)  # noqa: E731
    g = np.asarray(jax.jit(jax.grad(f))(q))
    h = 1e-7
    for i in range(5):
        for k in range(3):
            e = np.zeros((20, 3))
            e[i, k] = h
            fd = (float(f(q + e)) - float(f(q - e))) / (2 * h)
            assert abs(g[i, k] - fd) < 1e-5, (i, k, g[i, k], fd)
