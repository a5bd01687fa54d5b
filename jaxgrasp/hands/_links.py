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

import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands._kinematics import wrist_transform
from jaxgrasp.hands._mjcf import BOX, CAPSULE, CYLINDER, KinematicTree

__all__ = ["link_samples", "link_depths"]

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


def link_depths(hand, qpos, wrist, object_pose, surface):
    """``(P,)`` m: how deep each of the hand's link samples (`link_samples`) lies in
    the object whose surface is ``surface`` (mesh frame) at ``object_pose`` ``(6,)`` (negative:
    outside); ``(1,)`` of -1 m for a hand without other links. Traceable."""
    geom, local, radius = hand.link_points
    if len(geom) == 0:
        return jnp.zeros(1) - 1.0
    xpos, xmat = hand.geom_frames(qpos, wrist, np.unique(geom))
    row = np.searchsorted(np.unique(geom), geom)
    world = xpos[row] + jnp.einsum("pij,pj->pi", xmat[row], jnp.asarray(local))
    rot, t = wrist_transform(object_pose)  # a pose (6,): translation m, rotation vector rad
    return jnp.asarray(radius) - surface.closest((world - t) @ rot).signed_distance
