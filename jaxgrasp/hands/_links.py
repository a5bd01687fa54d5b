"""The hand's other links as samples whose depth in the object can be measured.

Every link that is not a fingertip (a capsule, sphere, cylinder or box geom,
`links`; mesh geoms are left out) is sampled: a capsule or cylinder
by points on its axis (spacing at most ``radius / 2``) with its radius, a sphere by its
centre with its radius, a box by spheres of its smallest half-size ``h`` centred on a grid
in its mid-plane across that axis, inset by ``h`` from its edges (spacing at most
``h / 2``): the box with its edges rounded by ``h``.
A sample's depth is its radius minus the signed distance of its point to the object's
surface (`jaxgrasp.surface.SurfacePoint.signed_distance`): positive where the link
is inside the object. Between samples a link may go deeper than its deepest sample (an
object's edge or corner poking between them): the samples bound the penetration only as
finely as their spacing.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands._kinematics import wrist_transform
from jaxgrasp.hands._mjcf import BOX, CAPSULE, CYLINDER, KinematicTree

__all__ = ["link_samples", "link_positions", "link_depths", "segment_distance", "self_overlap", "self_segments"]

_SAFE = 1e-24  # m^2: below it a distance's square root is taken of this instead (finite gradient)

def link_samples(tree: KinematicTree, links) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(geom (P,), points (P, 3) m in the geom's frame, radius (P,) m)``: the sample
    points of the geoms ``links`` (module notes)."""
    geoms, points, radii = [], [], []
    for g in links:
        size = tree.geom_size[g]
        if tree.geom_type[g] in (CAPSULE, CYLINDER):
            k = max(2, int(math.ceil(2.0 * size[1] / (0.5 * size[0]))) + 1)
            pts, rad = np.stack([np.zeros(k), np.zeros(k), np.linspace(-size[1], size[1], k)], 1), np.full(k, size[0])
        elif tree.geom_type[g] == BOX:
            pts = _box_sheet(size[:3])
            rad = np.full(len(pts), np.min(size[:3]))
        else:  # a sphere
            pts, rad = np.zeros((1, 3)), np.full(1, size[0])
        geoms.append(np.full(len(pts), g))
        points.append(pts)
        radii.append(rad)
    if not geoms:
        return np.zeros(0, int), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(geoms), np.concatenate(points), np.concatenate(radii)


def _box_sheet(half: np.ndarray) -> np.ndarray:
    """The sphere centres of a box of half-sizes ``half`` (3,), m (module notes)."""
    r = float(np.min(half))
    axes = []
    for h in half:
        inner = max(float(h) - r, 0.0)
        axes.append(np.linspace(-inner, inner, int(math.ceil(2 * inner / (0.5 * r))) + 1) if inner > 0 else np.zeros(1))
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def link_positions(hand, qpos, wrist):
    """``(P, 3)`` m: the world positions of the hand's link samples (`link_samples`, the
    ``hand.link_points``) at ``qpos`` with the model frame at ``wrist`` (a pose ``(6,)`` or
    None). Traceable."""
    geom, local, _ = hand.link_points
    used = np.unique(geom)
    xpos, xmat = hand.geom_frames(qpos, wrist, used)
    row = np.searchsorted(used, geom)
    return xpos[row] + jnp.einsum("pij,pj->pi", xmat[row], jnp.asarray(local))


def link_depths(hand, qpos, wrist, object_pose, surface):
    """``(P,)`` m: how deep each of the hand's link samples (`link_samples`) lies in
    the object whose surface is ``surface`` (mesh frame) at ``object_pose`` ``(6,)`` (negative:
    outside); ``(1,)`` of -1 m for a hand without other links. Traceable."""
    radius = hand.link_points[2]
    if len(radius) == 0:
        return jnp.zeros(1) - 1.0
    world = link_positions(hand, qpos, wrist)
    rot, t = wrist_transform(object_pose)  # a pose (6,): translation m, rotation vector rad
    return jnp.asarray(radius) - surface.closest((world - t) @ rot).signed_distance


def self_segments(tree: KinematicTree):
    """The hand's collision pairs as swept spheres, for `self_overlap`: ``(pairs (P, 2),
    geoms (S,), ends (S, 2, 3) m in the geom's frame, radius (S,) m, row_a (R,), row_b (R,),
    row_pair (R,))``.

    A capsule is its axis segment with its radius (exact), a cylinder the capsule of its
    radius and half-length (rounded ends: it over-reaches its flat ends by up to a radius),
    a sphere a segment of length 0, a box the capsules of `_box_segments` (the box with its
    edges rounded by its smallest half-size, the union of `link_samples`' spheres and the
    gaps between them along its longest axis: it falls short of the box's edges and corners);
    pairs with a mesh or plane geom are left out. Each row ``r`` pairs the swept sphere
    ``row_a[r]`` of the first geom with ``row_b[r]`` of the second, of pair ``row_pair[r]``.
    """
    from jaxgrasp.hands._mjcf import SPHERE

    kinds = (SPHERE, CAPSULE, CYLINDER, BOX)
    pairs = np.array([p for p in tree.collision_pairs if all(tree.geom_type[g] in kinds for g in p)],
                     dtype=int).reshape(-1, 2)
    geoms, ends, radii, first = [], [], [], {}
    for g in np.unique(pairs):
        first[int(g)] = len(geoms)
        size = tree.geom_size[g]
        if tree.geom_type[g] in (CAPSULE, CYLINDER):
            pts, rad = np.array([[[0.0, 0.0, -size[1]], [0.0, 0.0, size[1]]]]), np.array([size[0]])
        elif tree.geom_type[g] == BOX:
            pts = _box_segments(size[:3])
            rad = np.full(len(pts), np.min(size[:3]))
        else:  # a sphere
            pts, rad = np.zeros((1, 2, 3)), np.array([size[0]])
        geoms += [int(g)] * len(rad)
        ends += list(pts)
        radii += list(rad)
    count = {g: geoms.count(g) for g in first}
    rows = [(first[a] + i, first[b] + j, k) for k, (a, b) in enumerate(pairs)
            for i in range(count[a]) for j in range(count[b])]
    rows = np.array(rows, dtype=int).reshape(-1, 3)
    return (pairs, np.array(geoms, dtype=int), np.array(ends, dtype=np.float64).reshape(-1, 2, 3),
            np.array(radii, dtype=np.float64), rows[:, 0], rows[:, 1], rows[:, 2])


def _box_segments(half: np.ndarray) -> np.ndarray:
    """``(K, 2, 3)`` m: the segments whose capsules of the box's smallest half-size ``r``
    make the box of half-sizes ``half`` (3,) with its edges rounded by ``r``: the lines of
    `_box_sheet`'s grid along the box's longest axis, each from end to end of the sheet.
    As many capsules as the grid has lines, not points: a pair of boxes costs the product
    of their lines, where their spheres' product ran to tens of thousands of rows."""
    r = float(np.min(half))
    inner = np.maximum(np.asarray(half, np.float64) - r, 0.0)
    long = int(np.argmax(inner))
    across = np.array(half, np.float64)
    across[long] = r  # the sheet's grid collapsed to one point along the long axis
    centres = _box_sheet(across)
    step = np.zeros(3)
    step[long] = inner[long]
    return np.stack([centres - step, centres + step], axis=1)


def segment_distance(p1, q1, p2, q2):
    """``(...)`` m: the distance between the segments ``p1 q1`` and ``p2 q2`` (each ``(..., 3)``
    m; a segment may have length 0), by the closest-point parameters of Ericson's
    *Real-Time Collision Detection* (sec. 5.1.9), clamped to the segments. Differentiable
    (its square root is safe where the segments meet)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = jnp.sum(d1 * d1, -1), jnp.sum(d2 * d2, -1)
    b, c, f = jnp.sum(d1 * d2, -1), jnp.sum(d1 * r, -1), jnp.sum(d2 * r, -1)
    tiny = 1e-18
    a_ok, e_ok = a > tiny, e > tiny
    a_s, e_s = jnp.where(a_ok, a, 1.0), jnp.where(e_ok, e, 1.0)
    denom = a * e - b * b
    d_ok = denom > 1e-12 * a_s * e_s
    s = jnp.where(d_ok, jnp.clip((b * f - c * e) / jnp.where(d_ok, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e_s
    s = jnp.where(t < 0.0, jnp.clip(-c / a_s, 0.0, 1.0), jnp.where(t > 1.0, jnp.clip((b - c) / a_s, 0.0, 1.0), s))
    t = jnp.clip(t, 0.0, 1.0)
    s = jnp.where(e_ok, s, jnp.clip(-c / a_s, 0.0, 1.0))  # the second segment a point
    t = jnp.where(e_ok, t, 0.0)
    t = jnp.where(a_ok, t, jnp.clip(f / e_s, 0.0, 1.0))  # the first segment a point
    s = jnp.where(a_ok, s, 0.0)
    t = jnp.where(a_ok | e_ok, t, 0.0)
    gap = p1 + s[..., None] * d1 - p2 - t[..., None] * d2
    sq = jnp.sum(gap * gap, -1)
    return jnp.where(sq > _SAFE, jnp.sqrt(jnp.where(sq > _SAFE, sq, 1.0)), 0.0)


def self_overlap(hand, qpos, wrist=None):
    """``(P,)`` m: for each collision pair of the hand's own geoms (`self_segments`, in the
    order of its ``pairs``), how deep the two geoms overlap (positive) or, negative, their
    clearance: the sum of the radii minus the distance of the axes, the deepest over the
    swept spheres of the two geoms; ``(1,)`` of -1 m for a hand without such pairs.
    Traceable and differentiable in ``qpos`` and ``wrist``."""
    pairs, geoms, ends, radius, row_a, row_b, row_pair = hand.self_segments
    if len(pairs) == 0:
        return jnp.zeros(1) - 1.0
    used = np.unique(geoms)
    xpos, xmat = hand.geom_frames(qpos, wrist, used)
    k = np.searchsorted(used, geoms)
    world = xpos[k][:, None, :] + jnp.einsum("sij,sej->sei", xmat[k], jnp.asarray(ends))
    dist = segment_distance(world[row_a, 0], world[row_a, 1], world[row_b, 0], world[row_b, 1])
    depth = jnp.asarray(radius[row_a] + radius[row_b]) - dist
    return jax.ops.segment_max(depth, jnp.asarray(row_pair), num_segments=len(pairs))
