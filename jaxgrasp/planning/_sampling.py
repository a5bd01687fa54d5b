"""Geometric candidates on a mesh: surface samples, ray casts, antipodal pairs, spread tuples.

Everything here is NumPy on the mesh's triangles (m, mesh frame) and draws from a
``numpy.random.Generator`` it is given, so that a plan is reproducible from its seed.
"""

from __future__ import annotations

import numpy as np

from jaxgrasp.surface import FaceTree, build_tree
from jaxgrasp.surface import first_hits as tree_first_hits

__all__ = ["surface_points", "first_hits", "antipodal_pairs", "spread_tuples"]

def surface_points(triangles: np.ndarray, normals: np.ndarray, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points drawn uniformly by area on the surface, and their faces' normals.

    Args:
        triangles: ``(F, 3, 3)`` m; normals: ``(F, 3)`` outward unit normals.

    Returns:
        ``(points (count, 3) m, normals (count, 3))``.
    """
    area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    face = rng.choice(len(triangles), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0  # fold the unit square onto the triangle: uniform barycentric coordinates
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    t = triangles[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    return points, normals[face]


def first_hits(faces, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first face each ray ``origins + t directions`` (``t > 0``) crosses.

    Möller and Trumbore's ray-triangle test (J. Graphics Tools 2(1), 1997) on the faces
    whose boxes the ray enters in the mesh's face tree (``faces``: a
    `jaxgrasp.surface.FaceTree`, or the triangles ``(F, 3, 3)`` m, whose tree is built):
    the first hit over every face, at the cost of the faces along the ray.

    Returns:
        ``(t (R,) m, face (R,) int)``: ``t = inf`` and ``face = -1`` where a ray hits nothing.
    """
    return tree_first_hits(_tree(faces), origins, directions)


def _tree(faces) -> FaceTree:
    """The face tree of ``faces`` (a tree, or triangles ``(F, 3, 3)``)."""
    if isinstance(faces, FaceTree):
        return faces
    tri = np.asarray(faces, dtype=np.float64)
    return build_tree(tri, np.zeros(tri.shape[:2]))


def antipodal_pairs(faces, normals, p1, n1, friction: float) -> tuple[np.ndarray, np.ndarray]:
    """Two-finger candidates: from surface points ``p1 (K, 3)`` of normals ``n1 (K, 3)``, rays
    into the object along ``-n1`` (``faces``: the mesh's face tree or triangles, as
    `first_hits`; ``normals (F, 3)`` its faces' outward normals).

    A ray from ``p1`` into the object leaves it at ``p2`` on a face of normal ``n2``. The pair
    is antipodal when the line ``p1 p2`` (along ``n1``) lies inside the friction cone at
    ``p2``: ``angle(n2, -n1) <= atan(friction)`` (at ``p1`` it lies on the cone's axis).
    Points whose ray leaves through no face, or through one facing inward (the ray met an
    inner cavity's wall), are dropped.

    Returns:
        ``(positions (K', 2, 3) m, normals (K', 2, 3))``, ``K' <= K`` pairs.
    """
    tree = _tree(faces)
    scale = float(np.ptp(tree.boxes[1], axis=0).max())
    t, face = first_hits(tree, p1 - 1e-9 * scale * n1, -n1)
    ok = face >= 0
    n2 = normals[np.where(ok, face, 0)]
    ok &= np.einsum("kd,kd->k", n2, -n1) >= np.cos(np.arctan(friction))
    p2 = p1 - np.where(np.isfinite(t), t, 0.0)[:, None] * n1
    return np.stack([p1, p2], axis=1)[ok], np.stack([n1, n2], axis=1)[ok]


def spread_tuples(points, normals, fingers: int, count: int, rng, down=None, draws: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Candidates of ``fingers >= 3`` contacts drawn from a pool of surface samples, favouring
    force closure against the load: of ``draws x count`` random tuples the ``count`` whose
    unit normals sum closest to ``c down`` with ``0 <= c <= 1`` are kept. A fingertip pushes
    along ``-n_i``; pushes that nearly balance (normals summing to zero), or that add up to
    at most one fingertip's upward push carrying the weight, are what a grasp under gravity
    needs before friction does the rest (all fingertips below the object hold nothing in).

    Args:
        points: ``(P, 3)`` m; normals: ``(P, 3)`` unit, the pool.
        down: ``(3,)`` unit vector along gravity, or ``None`` (no load: normals summing to zero).

    Returns:
        ``(positions (count, fingers, 3) m, normals (count, fingers, 3))``.
    """
    keys = rng.random((draws * count, len(points)))
    idx = np.argpartition(keys, fingers, axis=1)[:, :fingers]  # ``fingers`` distinct pool points per tuple
    net = normals[idx].sum(axis=1)
    if down is not None:  # up to one fingertip's push may carry the weight, the rest must pinch
        net = net - np.clip(net @ down, 0.0, 1.0)[:, None] * down
    keep = idx[np.argsort(np.linalg.norm(net, axis=-1), kind="stable")[:count]]
    return points[keep], normals[keep]
