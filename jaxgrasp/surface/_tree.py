"""A bounding volume hierarchy over a mesh's faces: built once in NumPy, searched in JAX or NumPy.

`FaceTree` is a balanced BVH: the faces split top down at the median of their centroids, cut into
``L`` leaves of `LEAF_SIZE` slots (``L`` a power of two), and an implicit complete binary
tree over the leaves whose node ``i`` (1-based, heap order: children ``2i`` and ``2i + 1``,
leaves ``L .. 2L - 1``) holds the box of every face below it. A leaf holds between half and
all of its slots' worth of distinct faces; its other slots repeat one of its own faces, and
a leaf of a mesh with fewer faces than leaves repeats a neighbouring face, so that a
repeated slot never changes an answer (same triangle, same face index). Face indices are
those of the triangles the tree was built from (``leaf_faces``).

The searches here are the host's (NumPy), level by level over every query and its
surviving nodes at once, in chunks of queries so that memory stays bounded:
`nearest_faces` (the closest faces of points, every face tied within a margin) and
`first_hits` (ray casting). The JAX searches (one query per lane, a stack in a
``while_loop``) are in `jaxgrasp.surface._search`; both prune with the same boxes and
run the same exact tests on the faces that survive, so they agree with a brute force over
every face.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict

import jax
import numpy as np

from jaxgrasp.surface._triangles import closest_on_triangles

__all__ = ["FaceTree", "LEAF_SIZE", "build_tree", "nearest_faces", "first_hits"]

_BUILT: OrderedDict = OrderedDict()
"""The last trees built (`build_tree`), by a digest of their faces: the host code that
snaps the grasps of one mesh one by one builds its tree once."""

_KEEP_BUILT = 2

LEAF_SIZE = 16
"""Face slots per leaf of a `FaceTree` (the leaf size that served closest points best of 4
to 32 in the study `experiments/surface_scale`)."""

_CHUNK = 256
"""Queries searched together on the host (bounds the level-by-level work arrays)."""

_PAIR_BLOCK = 1 << 16
"""(query, face) pairs given the exact test at once on the host."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class FaceTree:
    """A mesh's faces in a bounding volume hierarchy (see the module); NumPy or JAX arrays.

    Attributes:
        boxes: ``(2L, 2, 3)`` m, the lower and upper corner of node ``i``'s box (row 0 unused).
        leaf_triangles: ``(L, K, 3, 3)`` m, the faces of each leaf's slots.
        leaf_normals: ``(L, K, 3)``, their outward unit normals.
        leaf_faces: ``(L, K)`` int32, their face indices.
        normal_boxes: ``(2L, 2, 3)``, the box of the normals of every face below node ``i``
            (the flat-patch rule skips a node whose normals all lie near the contact's).
    """

    boxes: np.ndarray
    leaf_triangles: np.ndarray
    leaf_normals: np.ndarray
    leaf_faces: np.ndarray
    normal_boxes: np.ndarray

    @property
    def num_leaves(self) -> int:
        """L, a power of two."""
        return int(self.leaf_faces.shape[0])

    @property
    def depth(self) -> int:
        """Levels below the root: ``log2(L)``."""
        return self.num_leaves.bit_length() - 1


def build_tree(triangles, normals, min_leaves: int = 1, leaf_size: int = LEAF_SIZE) -> FaceTree:
    """The `FaceTree` of ``triangles (F, 3, 3)`` m with outward ``normals (F, 3)``, with at
    least ``min_leaves`` leaves (rounded up to a power of two, as is ``F / leaf_size``).
    NumPy arrays, read-only: the last trees built are kept and given again for the same faces."""
    tri = np.ascontiguousarray(triangles, dtype=np.float64)
    nrm = np.ascontiguousarray(normals, dtype=np.float64)
    digest = hashlib.blake2b(tri.tobytes(), digest_size=16)
    digest.update(nrm.tobytes())
    leaves = 1
    while leaves < max(-(-len(tri) // leaf_size), int(min_leaves)):
        leaves *= 2
    key = (digest.hexdigest(), tri.shape, leaves, int(leaf_size))
    if key not in _BUILT:
        _BUILT[key] = _build(tri, nrm, leaves, int(leaf_size))
        while len(_BUILT) > _KEEP_BUILT:
            _BUILT.popitem(last=False)
    _BUILT.move_to_end(key)
    return _BUILT[key]


def _build(tri, normals, leaves: int, leaf_size: int) -> FaceTree:
    """`build_tree`'s work with ``leaves`` leaves (see the module)."""
    f = len(tri)
    start = (np.arange(leaves + 1) * f) // leaves  # leaf i holds sorted faces start[i] .. start[i+1] - 1
    order = _median_order(tri.mean(axis=1), start)
    count = np.maximum(np.diff(start), 1)
    slot = start[:-1, None] + np.minimum(np.arange(leaf_size)[None], count[:, None] - 1)
    faces = order[np.minimum(slot, f - 1)].astype(np.int32)  # (L, K)
    leaf_tri = tri[faces]
    nrm = normals[faces]
    corners = leaf_tri.reshape(leaves, -1, 3)
    boxes = _node_boxes(corners.min(axis=1), corners.max(axis=1))
    normal_boxes = _node_boxes(nrm.min(axis=1), nrm.max(axis=1))
    tree = FaceTree(boxes=boxes, leaf_triangles=leaf_tri, leaf_normals=nrm, leaf_faces=faces, normal_boxes=normal_boxes)
    for a in jax.tree_util.tree_leaves(tree):
        a.flags.writeable = False
    return tree


def _node_boxes(lo, hi) -> np.ndarray:
    """``(2L, 2, 3)``: the boxes of every node, from the leaves' ``lo, hi (L, 3)`` up to the root."""
    leaves = len(lo)
    boxes = np.empty((2 * leaves, 2, 3))
    boxes[leaves:, 0], boxes[leaves:, 1] = lo, hi
    m = leaves // 2
    while m >= 1:  # parents from their children, level by level
        boxes[m : 2 * m, 0] = np.minimum(boxes[2 * m : 4 * m : 2, 0], boxes[2 * m + 1 : 4 * m : 2, 0])
        boxes[m : 2 * m, 1] = np.maximum(boxes[2 * m : 4 * m : 2, 1], boxes[2 * m + 1 : 4 * m : 2, 1])
        m //= 2
    boxes[0] = boxes[1]
    return boxes


def _median_order(centroids, start) -> np.ndarray:
    """``(F,)`` the faces in leaf order: top down, each node's faces split along the longest
    side of their centroids' box where its two children's leaves divide them (at the
    median), all nodes of a level at once (a partition of each node's row, padded)."""
    f, leaves = len(centroids), len(start) - 1
    order = np.arange(f)
    m = leaves
    while m > 1 and f > 1:
        bounds = start[::m]  # the nodes of this level: faces bounds[g] .. bounds[g + 1] - 1
        sizes, left = np.diff(bounds), start[m // 2 :: m][: len(bounds) - 1] - bounds[:-1]
        order = order[_split(centroids[order], bounds, sizes, left)]
        m //= 2
    return order


def _split(c, bounds, sizes, left) -> np.ndarray:
    """The permutation of ``c (F, 3)`` (rows of nodes ``bounds``) that puts each node's
    ``left`` faces of smallest centroid along its longest side first."""
    filled = sizes > 0
    lo, hi = np.minimum.reduceat(c, bounds[:-1][filled]), np.maximum.reduceat(c, bounds[:-1][filled])
    axis = np.zeros(len(sizes), dtype=np.int64)
    axis[filled] = np.argmax(hi - lo, axis=1)
    node = np.repeat(np.arange(len(sizes)), sizes)
    col = np.arange(len(c)) - bounds[:-1][node]
    keys = np.full((len(sizes), int(sizes.max())), np.inf)  # a node's row, padded past its faces
    keys[node, col] = c[np.arange(len(c)), axis[node]]
    kth = np.unique(left[left > 0] - 1)
    if kth.size == 0:
        return np.arange(len(c))
    idx = np.argpartition(keys, kth, axis=1)
    real = idx < sizes[:, None]  # the padding sorts last in its row, past every node's left part
    return (bounds[:-1, None] + idx)[real]


# ------------------------------------------------------------------------- host searches


def _anchor(tree: FaceTree, node) -> np.ndarray:
    """``(..., 3)`` m: a vertex of a face below each of ``node`` (its first leaf's first slot):
    a point on the surface, so its distance bounds the node's closest face from above."""
    level = np.floor(np.log2(node)).astype(np.int64)
    leaf = (node << (tree.depth - level)) - tree.num_leaves
    return tree.leaf_triangles[leaf, 0, 0]


def _box_distance(tree: FaceTree, node, p) -> np.ndarray:
    """``(...)`` m: the distance from ``p (..., 3)`` to each of ``node``'s boxes."""
    gap = np.maximum(np.maximum(tree.boxes[node, 0] - p, p - tree.boxes[node, 1]), 0.0)
    return np.sqrt(np.einsum("...d,...d->...", gap, gap))


def _point_leaves(tree: FaceTree, pts, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """``(query, leaf)`` pairs: every leaf that may hold a face within ``margin`` m of the
    closest face of each of ``pts (Q, 3)``. A node survives a level when its box lies no
    farther than the nearest anchor of that level (plus the margin and round-off)."""
    q, node = np.arange(len(pts)), np.ones(len(pts), dtype=np.int64)
    for _ in range(tree.depth):
        q, node = np.repeat(q, 2), (2 * node[:, None] + np.arange(2)).ravel()
        lower = _box_distance(tree, node, pts[q])
        upper = np.full(len(pts), np.inf)
        np.minimum.at(upper, q, np.linalg.norm(_anchor(tree, node) - pts[q], axis=-1))
        keep = lower <= upper[q] * (1.0 + 1e-12) + margin
        q, node = q[keep], node[keep]
    return q, node - tree.num_leaves


def nearest_faces(tree: FaceTree, points, margin: float = 0.0, scale: float = 1.0):
    """The closest faces of each of ``points (Q, 3)`` m, by the exact closest-point rule.

    Args:
        margin: m: faces within ``margin`` of the closest distance are kept too.
        scale: m, the mesh's size (sets the round-off slack of the search).

    Returns:
        ``(query (M,), face (M,), point (M, 3) m, distance (M,) m)``, sorted by query: for
        each query every face (once) whose closest point lies within ``margin`` of the
        smallest distance, the closest point on it and its distance.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = []
    for lo in range(0, len(pts), _CHUNK):
        chunk = pts[lo : lo + _CHUNK]
        q, leaf = _point_leaves(tree, chunk, margin + 1e-12 * scale)
        q, face, point, dist = _pairs_exact(tree, chunk, q, leaf)
        best = np.full(len(chunk), np.inf)
        np.minimum.at(best, q, dist)
        near = dist <= best[q] + margin
        q, face, point, dist = q[near], face[near], point[near], dist[near]
        first = np.unique(np.stack([q, face], axis=1), axis=0, return_index=True)[1]  # a face twice in a leaf: once
        out.append((q[first] + lo, face[first], point[first], dist[first]))
    if not out:
        return np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 3)), np.zeros(0)
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _pairs_exact(tree: FaceTree, pts, q, leaf):
    """Every slot of each ``(query, leaf)`` pair, its face, closest point and distance."""
    k = tree.leaf_faces.shape[1]
    q, leaf = np.repeat(q, k), np.repeat(leaf, k)
    slot = np.tile(np.arange(k), len(leaf) // k)
    points = np.empty((len(q), 3))
    for lo in range(0, len(q), _PAIR_BLOCK):
        s = slice(lo, lo + _PAIR_BLOCK)
        points[s] = closest_on_triangles(pts[q[s]], tree.leaf_triangles[leaf[s], slot[s]], xp=np)
    dist = np.linalg.norm(points - pts[q], axis=-1)
    return q, tree.leaf_faces[leaf, slot], points, dist


def first_hits(tree: FaceTree, origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """The first face each ray ``origins + t directions`` (``t > 0``) crosses.

    Möller and Trumbore's ray-triangle test (J. Graphics Tools 2(1), 1997) on the faces of
    the leaves whose boxes (widened by round-off: ``1e-9`` of the mesh's size) the ray
    enters; ties in ``t`` go to the smallest face index.

    Returns:
        ``(t (R,), face (R,) int)``: ``t = inf`` and ``face = -1`` where a ray hits nothing.
    """
    o_all = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d_all = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    ts, faces = np.full(len(o_all), np.inf), np.full(len(o_all), -1, dtype=np.int64)
    scale = float(np.ptp(tree.boxes[1], axis=0).max())
    for lo in range(0, len(o_all), _CHUNK):
        o, d = o_all[lo : lo + _CHUNK], d_all[lo : lo + _CHUNK]
        q, node = np.arange(len(o)), np.ones(len(o), dtype=np.int64)
        for level in range(tree.depth + 1):
            keep = _ray_enters(tree, node, o[q], d[q], 1e-9 * scale)
            q, node = q[keep], node[keep]
            if level < tree.depth:
                q, node = np.repeat(q, 2), (2 * node[:, None] + np.arange(2)).ravel()
        q, t, face = _ray_exact(tree, o, d, q, node - tree.num_leaves)
        order = np.lexsort((face, t, q))  # per ray: the smallest t, then the smallest face
        q, t, face = q[order], t[order], face[order]
        first = np.unique(q, return_index=True)[1]
        hit = np.isfinite(t[first])
        ts[lo + q[first][hit]], faces[lo + q[first][hit]] = t[first][hit], face[first][hit]
    return ts, faces


def _ray_enters(tree: FaceTree, node, o, d, pad: float) -> np.ndarray:
    """``(P,)`` bool: the ray ``o + t d`` (``t > 0``) meets each node's box widened by ``pad``."""
    lo, hi = tree.boxes[node, 0] - pad, tree.boxes[node, 1] + pad
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1, t2 = (lo - o) * inv, (hi - o) * inv
    flat = d == 0  # parallel to a slab: inside it or never
    inside = (o >= lo) & (o <= hi)
    near = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    far = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    enter, leave = near.max(axis=-1), far.min(axis=-1)
    return (enter <= leave) & (leave >= 0.0)


def _ray_exact(tree: FaceTree, o_all, d_all, q, leaf):
    """``(q, t, face)`` of every slot of each ``(ray, leaf)`` pair (``t = inf``: no hit)."""
    k = tree.leaf_faces.shape[1]
    q, leaf = np.repeat(q, k), np.repeat(leaf, k)
    slot = np.tile(np.arange(k), len(leaf) // k)
    t = np.empty(len(q))
    for lo in range(0, len(q), _PAIR_BLOCK):
        s = slice(lo, lo + _PAIR_BLOCK)
        t[s] = _moller_trumbore(tree.leaf_triangles[leaf[s], slot[s]], o_all[q[s]], d_all[q[s]])
    return q, t, tree.leaf_faces[leaf, slot].astype(np.int64)


def _moller_trumbore(tri, o, d) -> np.ndarray:
    """``(P,)`` the ``t > 0`` at which each ray ``o + t d`` crosses its triangle ``tri (P, 3, 3)``, else inf."""
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("pd,pd->p", p, e1)
    inv = 1.0 / np.where(np.abs(det) < 1e-300, np.inf, det)
    s = o - a
    u = np.einsum("pd,pd->p", s, p) * inv
    qv = np.cross(s, e1)
    v = np.einsum("pd,pd->p", d, qv) * inv
    t = np.einsum("pd,pd->p", qv, e2) * inv
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(inv)
    return np.where(hit, t, np.inf)
