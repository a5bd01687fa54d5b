"""Forward kinematics of a `KinematicTree` in pure JAX.

The same recursion as MuJoCo's ``mj_kinematics`` for hinge and slide joints: a body's
frame in its parent's is its fixed offset (``body_pos``, ``body_quat``) followed by its
joints in order, a hinge turning the frame by ``qpos - qpos0`` about its axis through its
anchor, a slide moving it by ``qpos - qpos0`` along its axis; the world frame of a body
is its parent's composed with that. Everything is float64 and differentiable in
``qpos`` and the wrist; the loop over bodies is unrolled when traced (a hand has tens).

The wrist ``(6,)`` is the pose of the model's world frame in the world: a translation
(m) then a rotation vector (rad), so a model point ``x`` lies at ``R(w) x + t``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands._mjcf import CAPSULE, CYLINDER, HINGE, KinematicTree
from jaxgrasp.model import rotation_matrix

__all__ = ["quat_to_matrix", "body_frames", "geom_frames", "wrist_transform", "cap_offsets"]


def quat_to_matrix(q) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices of unit quaternions ``(..., 4)`` ``(w, x, y, z)``."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def _axis_rotation(axis: np.ndarray, angle):
    """``(3, 3)`` rotation by ``angle`` (rad, traced) about the unit ``axis`` (constant)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return jnp.eye(3) + jnp.sin(angle) * k + (1.0 - jnp.cos(angle)) * (k @ k)


def wrist_transform(wrist):
    """``(R (3, 3), t (3,))`` of a wrist pose ``(6,)``: translation m, rotation vector rad."""
    wrist = jnp.asarray(wrist, dtype=jnp.float64)
    return rotation_matrix(wrist[3:]), wrist[:3]


def body_frames(tree: KinematicTree, qpos, wrist=None):
    """``(xpos (B, 3), xmat (B, 3, 3))``: every body's frame in the world at joint
    positions ``qpos`` ``(J,)`` (rad for hinges, m for slides) and the wrist pose ``(6,)``
    (``None``: the model's world frame is the world's)."""
    qpos = jnp.asarray(qpos, dtype=jnp.float64)
    rot0 = quat_to_matrix(tree.body_quat)
    if wrist is None:
        xpos, xmat = [jnp.zeros(3)], [jnp.eye(3)]
    else:
        rw, tw = wrist_transform(wrist)
        xpos, xmat = [tw], [rw]
    for b in range(1, len(tree.body_parent)):
        pos, rot = jnp.asarray(tree.body_pos[b]), jnp.asarray(rot0[b])
        for j in tree.body_joints[b]:
            delta = qpos[j] - tree.qpos0[j]
            if tree.jnt_type[j] == HINGE:
                anchor = pos + rot @ tree.jnt_pos[j]
                rot = rot @ _axis_rotation(tree.jnt_axis[j], delta)
                pos = anchor - rot @ tree.jnt_pos[j]
            else:  # slide
                pos = pos + (rot @ tree.jnt_axis[j]) * delta
        p = tree.body_parent[b]
        xpos.append(xpos[p] + xmat[p] @ pos)
        xmat.append(xmat[p] @ rot)
    return jnp.stack(xpos), jnp.stack(xmat)


def geom_frames(tree: KinematicTree, qpos, wrist=None, geoms=None):
    """``(xpos (G, 3), xmat (G, 3, 3))``: the world frames of the geoms ``geoms`` (indices;
    ``None``: all), at ``qpos`` and ``wrist`` as in `body_frames`."""
    geoms = np.arange(len(tree.geom_body)) if geoms is None else np.asarray(geoms, dtype=int)
    bx, bm = body_frames(tree, qpos, wrist)
    body = tree.geom_body[geoms]
    local_rot = jnp.asarray(quat_to_matrix(tree.geom_quat[geoms]))
    xpos = bx[body] + jnp.einsum("gij,gj->gi", bm[body], jnp.asarray(tree.geom_pos[geoms]))
    return xpos, jnp.einsum("gij,gjk->gik", bm[body], local_rot)


def cap_offsets(tree: KinematicTree, geoms) -> np.ndarray:
    """``(F,)`` signed offset, m, from each geom's centre to its fingertip's end-cap centre
    along the geom's ``z`` axis: a capsule's half-length towards the end farther from its
    body's origin (the finger's last joint; ``+z`` where both are as far), 0 for a sphere."""
    geoms = np.asarray(geoms, dtype=int)
    elongated = np.isin(tree.geom_type[geoms], (CAPSULE, CYLINDER))
    half = np.where(elongated, tree.geom_size[geoms, 1], 0.0)
    z_local = quat_to_matrix(tree.geom_quat[geoms])[:, :, 2]
    along = np.einsum("gi,gi->g", tree.geom_pos[geoms], z_local)  # > 0: the +z end is the farther
    return np.where(along < -1e-12, -half, half)
