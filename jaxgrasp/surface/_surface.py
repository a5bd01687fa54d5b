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
  Cost ``O(points x faces)``.
* **Normal.** The outward normal of the face the point lies on: piecewise constant on the
  surface, as the paper's planar contact surface needs (the model's normal is the face's,
  Sec. V). Where the closest point lies on an edge or a vertex (several faces tie), the
  face whose plane is farthest from the query point along its normal is chosen: for a
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

__all__ = ["Surface", "SurfacePoint", "closest_on_triangles", "PAD_FACES"]

PAD_FACES = 256
"""Face counts are padded to this times a power of two by [`Surface.padded`][jaxgrasp.surface.Surface.padded], so that
meshes of similar size share one compiled shape."""

_TIE = 1e-12
"""Relative tie in squared distance (of the mesh's squared size) between faces sharing a
closest point (an edge or a vertex)."""


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
    """

    triangles: jax.Array
    normals: jax.Array
    scale: jax.Array

    @classmethod
    def create(cls, vertices, faces) -> "Surface":
        """The surface of ``vertices (V, 3)`` m and ``faces (F, 3)`` vertex indices
        (counter-clockwise seen from outside). Faces of zero area are left out.

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
        normals = cross[keep] / area2[keep, None]
        return cls(triangles=jnp.asarray(tri[keep]), normals=jnp.asarray(normals), scale=jnp.float64(scale))

    @classmethod
    def from_trimesh(cls, mesh, pad_to: int | None = None) -> "Surface":
        """The surface of a ``trimesh.Trimesh`` (its vertices in m, faces outward, e.g.
        ``trimesh.load(path)`` of a watertight mesh in metres); ``pad_to``: see [`padded`][jaxgrasp.surface.Surface.padded]."""
        surface = cls.create(mesh.vertices, mesh.faces)
        return surface if pad_to is None else surface.padded(pad_to)

    def padded(self, multiple: int) -> "Surface":
        """The same surface with its face count rounded up to a power of two times
        ``multiple`` by copies of a small triangle far away (a thousand mesh sizes), which
        is never the closest face nor within any contact radius: meshes of similar size
        then share one shape, so compiled functions of the surface are reused."""
        f = self.num_faces
        size = int(multiple)
        while size < f:
            size *= 2
        if size == f:
            return self
        far = np.asarray(self.triangles[0, 0]) + 1e3 * float(self.scale) * np.array([1.0, 1.0, 1.0])
        tri = far + 1e-3 * float(self.scale) * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        pad_t = np.broadcast_to(tri, (size - f, 3, 3))
        pad_n = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (size - f, 3))
        return dataclasses.replace(
            self,
            triangles=jnp.concatenate([self.triangles, jnp.asarray(pad_t)]),
            normals=jnp.concatenate([self.normals, jnp.asarray(pad_n)]),
        )

    @property
    def num_faces(self) -> int:
        """F, the number of faces."""
        return int(self.triangles.shape[-3])

    def translated(self, offset) -> "Surface":
        """The same surface moved by ``offset (3,)`` m (e.g. ``-center_of_mass`` for the
        grasp's centre-of-mass frame)."""
        return dataclasses.replace(self, triangles=self.triangles + jnp.asarray(offset, jnp.float64))

    def closest(self, points) -> SurfacePoint:
        """The closest surface point to each of ``points (..., 3)`` m (traceable).

        Returns:
            A `SurfacePoint` of shape ``(...)`` (see the module's notes on edges,
            vertices and derivatives).
        """
        pts = jnp.asarray(points, jnp.float64)
        hit = _closest_many(self, pts.reshape(-1, 3))
        return jax.tree_util.tree_map(lambda a: a.reshape(pts.shape[:-1] + a.shape[1:]), hit)

    def face_distances(self, points) -> jax.Array:
        """``(..., F)`` m: the distance from each of ``points (..., 3)`` to every face."""
        pts = jnp.asarray(points, jnp.float64)
        q = jax.vmap(lambda p: closest_on_triangles(p, self.triangles))(pts.reshape(-1, 3))
        d = jnp.linalg.norm(q - pts.reshape(-1, 1, 3), axis=-1)
        return d.reshape(pts.shape[:-1] + (self.num_faces,))


@jax.jit
def _closest_many(surface: Surface, points) -> SurfacePoint:
    """`_closest_one` of each of ``points (P, 3)`` (compiled once per shape when
    called eagerly; inlined where it is traced)."""
    return jax.vmap(lambda p: _closest_one(surface, p))(points)


def _closest_one(surface: Surface, p) -> SurfacePoint:
    """The `SurfacePoint` of one query point ``p (3,)``."""
    tri, normals = surface.triangles, surface.normals
    q = jax.lax.stop_gradient(closest_on_triangles(jax.lax.stop_gradient(p), tri))  # (F, 3): picks the face
    d2 = jnp.sum((q - p) ** 2, axis=-1)
    best = jnp.min(d2)
    tied = d2 <= best + _TIE * surface.scale**2
    height = jnp.abs(jnp.einsum("fd,fd->f", jax.lax.stop_gradient(p) - q, normals))
    face = jnp.argmax(jnp.where(tied, height, -1.0)).astype(jnp.int32)
    point = closest_on_triangles(p, tri[face][None])[0]  # again, differentiably, on the chosen face
    n = normals[face]
    diff = p - point
    dist = jnp.sqrt(jnp.maximum(jnp.sum(diff**2), 1e-300))
    side = jnp.where(jnp.dot(diff, n) < 0.0, -1.0, 1.0)
    return SurfacePoint(point=point, normal=n, face=face, distance=dist, signed_distance=side * dist)


def closest_on_triangles(p, tri, xp=jnp):
    """The closest point to ``p (3,)`` on each triangle of ``tri (F, 3, 3)``, ``(F, 3)``.

    Exact, by the triangle's Voronoi regions (Ericson, *Real-Time Collision Detection*,
    Sec. 5.1.5); denominators are guarded so that the branches not taken carry finite
    derivatives. Triangles must have non-zero area.

    ``xp`` is the array library: ``jax.numpy`` (the default: traceable, differentiable) or
    ``numpy``, for the host code that snaps a mesh grasp's contacts
    (`grasp_on_mesh`, once per grasp of a dataset or a plan), where
    dispatching each operation to JAX would cost more than the arithmetic. One rule, run
    by either library; the tests hold the two to each other.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac = b - a, c - a
    d1, d2 = _dot(ab, p - a, xp), _dot(ac, p - a, xp)
    d3, d4 = _dot(ab, p - b, xp), _dot(ac, p - b, xp)
    d5, d6 = _dot(ab, p - c, xp), _dot(ac, p - c, xp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    inside = a + ab * _ratio(vb, denom, xp) + ac * _ratio(vc, denom, xp)
    regions = [  # (condition, point), in Ericson's order: the first that holds applies
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + _ratio(d1, d1 - d3, xp) * ab),
        ((d6 >= 0) & (d5 <= d6), c),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + _ratio(d2, d2 - d6, xp) * ac),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + _ratio(d4 - d3, (d4 - d3) + (d5 - d6), xp) * (c - b)),
    ]
    out = inside
    for cond, point in reversed(regions):
        out = xp.where(cond[:, None], point, out)
    return out


def _dot(u, v, xp):
    return xp.einsum("fd,fd->f", u, xp.broadcast_to(v, u.shape))


def _ratio(num, den, xp):
    safe = xp.where(den == 0, 1.0, den)
    return (xp.where(den == 0, 0.0, num) / safe)[:, None]
