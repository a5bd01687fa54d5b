"""A triangle mesh as JAX arrays: the exact closest surface point, its face and outward normal.

[`Surface`][jaxgrasp.surface.Surface] holds a mesh's triangles and their outward unit normals, so that contact
points can be put on the surface inside ``jit``, ``vmap`` and ``grad``:
[`Surface.closest`][jaxgrasp.surface.Surface.closest] maps any points to the closest surface point, the face it lies on
and that face's normal (a `SurfacePoint`).

Behaviour a caller relies on:

* **Closest point.** Exact over every face, by the triangle's Voronoi regions (Ericson,
  *Real-Time Collision Detection*, Sec. 5.1.5): `closest_on_triangles`, the one rule
  of jaxgrasp, which the host code that snaps a mesh grasp's contacts runs in NumPy
  (`jaxgrasp.surface._mesh`; the tests check one library against the other).
  The faces are found through a bounding volume hierarchy built once by
  [`Surface.create`][jaxgrasp.surface.Surface.create] (`jaxgrasp.surface._tree`,
  searched in JAX by `jaxgrasp.surface._search`): a search visits the tree's nodes near
  the query, about ``log(faces)`` of them near a surface, and skips a node only when none
  of its faces can be the answer, so the answer is a brute force's over every face. Memory
  is the queries times a stack and one leaf's faces, never the queries times the faces;
  building the tree costs ``O(faces log faces)`` once.
* **Normal.** The outward normal of the face the point lies on: piecewise constant on the
  surface, as the paper's planar contact surface needs (the model's normal is the face's,
  Sec. V). Where the closest point lies on an edge or a vertex (several faces tie: their
  distances within ``1e-12`` of the mesh's size, `jaxgrasp.surface._search.TIE`), the
  face whose plane is farthest from the query point along its normal is chosen (then the
  smallest face index): for a
  query point outside a convex edge that is the face that point "sees" most squarely, and
  the sign of `SurfacePoint.signed_distance` is right inside and outside a closed mesh.
* **Derivatives.** Within a face the closest point is the orthogonal projection onto the
  face's plane: its derivative with respect to the query point is the projection onto the
  plane (the tangential part of a move), and the normal's derivative is zero. On an edge the
  point moves along the edge; at a vertex it stays. Derivatives jump where the closest face
  changes; the point itself is continuous for query points near the surface.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.model import GraspValueError
from jaxgrasp.surface._search import nearest_slot, unaligned_within
from jaxgrasp.surface._tree import LEAF_SIZE, FaceTree, build_tree
from jaxgrasp.surface._triangles import closest_on_triangles

__all__ = ["Surface", "SurfacePoint", "PAD_FACES"]

PAD_FACES = 256
"""Face counts are padded to this times a power of two by [`Surface.padded`][jaxgrasp.surface.Surface.padded], and
the face tree to that many slots, so that meshes of similar size share one compiled shape."""



@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SurfacePoint:
    """Where query points meet the surface (the shapes follow the query's ``(...)``).

    Attributes:
        point: ``(..., 3)`` m, the closest surface point.
        normal: ``(..., 3)`` outward unit normal of the face it lies on.
        face: ``(...)`` int32, the index of that face in `Surface.triangles`.
        distance: ``(...)`` m, distance from the query point to ``point``.
        signed_distance: ``(...)`` m, ``distance`` with the sign of the query point's side of
            that face: negative inside a closed mesh.
    """

    point: jax.Array
    normal: jax.Array
    face: jax.Array
    distance: jax.Array
    signed_distance: jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Surface:
    """A triangle mesh in JAX (m): build it with [`from_trimesh`][jaxgrasp.surface.Surface.from_trimesh] or [`create`][jaxgrasp.surface.Surface.create].

    Attributes:
        triangles: ``(F, 3, 3)`` m, the corners of each face, counter-clockwise seen from
            outside.
        normals: ``(F, 3)`` outward unit normal of each face.
        scale: ``()`` m, the largest side of the mesh's bounding box (sets tolerances).
        tree: the faces in a bounding volume hierarchy (``jaxgrasp.surface._tree.FaceTree``),
            built once by `create`: the searches of `closest` and `unaligned_within`.
    """

    triangles: jax.Array
    normals: jax.Array
    scale: jax.Array
    tree: FaceTree

    @classmethod
    def create(cls, vertices, faces, min_faces: int = 0) -> "Surface":
        """The surface of ``vertices (V, 3)`` m and ``faces (F, 3)`` vertex indices
        (counter-clockwise seen from outside). Faces of zero area are left out. The face
        tree has room for at least ``min_faces`` faces (see [`padded`][jaxgrasp.surface.Surface.padded]).

        Raises:
            GraspValueError: no face of non-zero area, or vertices that are not finite.
        """
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            raise GraspValueError(f"surface vertices must be a (V, 3) array of finite numbers, m; got shape {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or f.size == 0 or f.min() < 0 or f.max() >= len(v):
            raise GraspValueError(f"surface faces must be an (F, 3) array of vertex indices; got shape {f.shape}")
        tri = v[f]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        scale = float(np.ptp(v, axis=0).max())
        keep = area2 > 1e-14 * scale**2
        if not keep.any():
            raise GraspValueError("the surface has no face of non-zero area (a degenerate mesh)")
        tri, normals = tri[keep], cross[keep] / area2[keep, None]
        tree = build_tree(tri, normals, min_leaves=-(-int(min_faces) // LEAF_SIZE))
        return cls(triangles=jnp.asarray(tri), normals=jnp.asarray(normals), scale=jnp.float64(scale),
                   tree=jax.tree_util.tree_map(jnp.asarray, tree))

    @classmethod
    def from_trimesh(cls, mesh, pad_to: int | None = None) -> "Surface":
        """The surface of a ``trimesh.Trimesh`` (its vertices in m, faces outward, e.g.
        ``trimesh.load(path)`` of a watertight mesh in metres); ``pad_to``: see [`padded`][jaxgrasp.surface.Surface.padded]."""
        surface = cls.create(mesh.vertices, mesh.faces)
        return surface if pad_to is None else surface.padded(pad_to)

    def padded(self, multiple: int) -> "Surface":
        """The same surface with its face count rounded up to a power of two times
        ``multiple`` by copies of a small triangle far away (a thousand mesh sizes), which
        is never the closest face nor within any contact radius, and its face tree built
        with as many slots (its leaves then hold fewer faces each): meshes of similar size
        then share one shape, so compiled functions of the surface are reused."""
        f = self.num_faces
        size = int(multiple)
        while size < f:
            size *= 2
        if size == f and self.tree.leaf_faces.size >= size:
            return self
        real = int(np.max(np.asarray(self.tree.leaf_faces))) + 1  # the faces before any padding
        tri, nrm = np.asarray(self.triangles)[:real], np.asarray(self.normals)[:real]
        far = tri[0, 0] + 1e3 * float(self.scale) * np.array([1.0, 1.0, 1.0])
        pad_t = np.broadcast_to(far + 1e-3 * float(self.scale) * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                                (size - real, 3, 3))
        pad_n = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (size - real, 3))
        tree = build_tree(tri, nrm, min_leaves=-(-size // LEAF_SIZE))  # the real faces only
        return dataclasses.replace(
            self,
            triangles=jnp.asarray(np.concatenate([tri, pad_t])),
            normals=jnp.asarray(np.concatenate([nrm, pad_n])),
            tree=jax.tree_util.tree_map(jnp.asarray, tree),
        )

    @property
    def num_faces(self) -> int:
        """F, the number of faces."""
        return int(self.triangles.shape[-3])

    def translated(self, offset) -> "Surface":
        """The same surface moved by ``offset (3,)`` m (e.g. ``-center_of_mass`` for the
        grasp's centre-of-mass frame)."""
        off = jnp.asarray(offset, jnp.float64)
        tree = dataclasses.replace(self.tree, boxes=self.tree.boxes + off, leaf_triangles=self.tree.leaf_triangles + off)
        return dataclasses.replace(self, triangles=self.triangles + off, tree=tree)

    def closest(self, points) -> SurfacePoint:
        """The closest surface point to each of ``points (..., 3)`` m (traceable).

        Returns:
            A `SurfacePoint` of shape ``(...)`` (see the module's notes on edges,
            vertices and derivatives).
        """
        pts = jnp.asarray(points, jnp.float64)
        hit = _closest_many(self, pts.reshape(-1, 3))
        return jax.tree_util.tree_map(lambda a: a.reshape(pts.shape[:-1] + a.shape[1:]), hit)

    def unaligned_within(self, points, normals, radius, max_angle_deg) -> jax.Array:
        """``(...)`` bool: some face lies within ``radius (...)`` m of each of ``points (..., 3)``
        m with its normal more than ``max_angle_deg`` degrees from the unit ``normals (..., 3)``
        (traceable; the flat-patch rule of `jaxgrasp.surface.check_contacts`).
        """
        pts = jnp.asarray(points, jnp.float64)
        shape = pts.shape[:-1]
        n = jnp.broadcast_to(jnp.asarray(normals, jnp.float64), shape + (3,)).reshape(-1, 3)
        r = jnp.broadcast_to(jnp.asarray(radius, jnp.float64), shape).reshape(-1)
        cos_max = jnp.cos(jnp.deg2rad(max_angle_deg))
        one = lambda p, m, a: unaligned_within(self.tree, p, m, a, cos_max, self.scale)  # noqa: E731
        return jax.vmap(one)(pts.reshape(-1, 3), n, r).reshape(shape)


@jax.jit
def _closest_many(surface: Surface, points) -> SurfacePoint:
    """`_closest_one` of each of ``points (P, 3)`` (compiled once per shape when
    called eagerly; inlined where it is traced)."""
    return jax.vmap(lambda p: _closest_one(surface, p))(points)


def _closest_one(surface: Surface, p) -> SurfacePoint:
    """The `SurfacePoint` of one query point ``p (3,)``: the face found by the tree's
    search (`nearest_slot`), the point again, differentiably, on that face."""
    tree = surface.tree
    leaf, slot = nearest_slot(tree, p, surface.scale)
    point = closest_on_triangles(p, tree.leaf_triangles[leaf, slot][None])[0]
    n = tree.leaf_normals[leaf, slot]
    diff = p - point
    dist = jnp.sqrt(jnp.maximum(jnp.sum(diff**2), 1e-300))
    side = jnp.where(jnp.dot(diff, n) < 0.0, -1.0, 1.0)
    return SurfacePoint(point=point, normal=n, face=tree.leaf_faces[leaf, slot], distance=dist, signed_distance=side * dist)
