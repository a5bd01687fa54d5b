"""A hand: its kinematic tree, its fingertips, and where they are at a configuration.

[`Hand`][jaxgrasp.Hand] is built from an MJCF file by [`Hand.from_mjcf`][jaxgrasp.Hand.from_mjcf]. A fingertip is the
hemispherical end of a sphere or capsule geom: a sphere's centre, or the centre of a
capsule's end cap (MuJoCo's capsules run along their local ``z``), with
the geom's radius as the fingertip's radius ``r`` (the paper's hemisphere, Sec. III). The
cap is the one at the capsule's end farther from its body's origin (the finger's last
joint), the fingertip's axis the geom's ``z`` axis turned towards that end: the
direction the hemisphere points.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from typing import Sequence

import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands._grasp import finite_vector
from jaxgrasp.hands._kinematics import body_frames, cap_offsets, geom_frames
from jaxgrasp.hands._links import link_depths, link_samples
from jaxgrasp.hands._mjcf import BOX, CAPSULE, CYLINDER, SPHERE, KinematicTree, read_mjcf
from jaxgrasp.model import GraspValueError

__all__ = ["Hand"]

_LINK_TYPES = (SPHERE, CAPSULE, CYLINDER, BOX)  # geoms whose penetration tune_hand keeps out of the object


@dataclasses.dataclass(frozen=True, eq=False)
class Hand:
    """A hand model read from MJCF: kinematics in JAX, fingertips as hemispheres (SI units).

    Build it with [`from_mjcf`][jaxgrasp.Hand.from_mjcf]. Not a pytree: its arrays are constants of the JAX
    functions that use it (compiled once per hand).

    Attributes:
        tree: the `KinematicTree`.
        fingertips: ``(F,)`` geom indices of the fingertips.
        fingertip_names: ``(F,)`` their geom names.
        radius: ``(F,)`` fingertip radius, m (the geom's radius).
        cap_offset: ``(F,)`` m from the geom centre to the end-cap centre along the
            geom's ``z`` (a capsule's half-length, negative where the cap is at ``-z``;
            0 for a sphere).
        links: indices of the other geoms (spheres, capsules, cylinders, boxes: the
            links kept out of the object by [`tune_hand`][jaxgrasp.tune_hand]; meshes and planes
            are left out).
        link_points: ``(geom (P,), points (P, 3) m, radius (P,) m)``, their samples
            (`link_samples`).
    """

    tree: KinematicTree
    fingertips: np.ndarray
    fingertip_names: tuple
    radius: np.ndarray
    cap_offset: np.ndarray
    links: np.ndarray
    link_points: tuple

    @classmethod
    def from_mjcf(cls, path: str | os.PathLike, fingertips: Sequence[str], allowed_dirs=None) -> "Hand":
        """Read the hand in the MJCF file ``path`` (compiled by MuJoCo), with the geoms named
        ``fingertips`` (at least 2, each a sphere or a capsule) as its fingertips.

        The files the MJCF file names (includes, meshes, textures) must lie in its folder
        after symlinks, or in one of the folders ``allowed_dirs``; they are read by
        jaxgrasp and checked (regular files under their caps, the model under its size
        caps) before MuJoCo sees them (`jaxgrasp.hands._mjcf_files`).

        Raises:
            GraspValueError: MuJoCo missing (``pip install "jaxgrasp[hands]"``), a file
                outside the allowed folders or refused by the checks, a file MuJoCo cannot
                compile, a free or ball joint, an unknown geom name, or a fingertip geom
                that is not a sphere or capsule; one line.
        """
        tree, _ = read_mjcf(path, allowed_dirs)
        if isinstance(fingertips, str) or not isinstance(fingertips, Sequence) or len(fingertips) < 2 \
                or not all(isinstance(n, str) for n in fingertips):
            raise GraspValueError(f"fingertips must be at least 2 geom names, got {_short(fingertips)}")
        idx = np.array([tree.geom_index(n) for n in fingertips], dtype=int)
        wrong = [n for n, g in zip(fingertips, idx) if tree.geom_type[g] not in (SPHERE, CAPSULE)]
        if wrong:
            raise GraspValueError(f"fingertips: geom {wrong[0]!r} is neither a sphere nor a capsule")
        links = np.array([g for g in range(len(tree.geom_body)) if g not in idx and tree.geom_type[g] in _LINK_TYPES], dtype=int)
        return cls(tree, idx, tuple(fingertips), tree.geom_size[idx, 0].copy(), cap_offsets(tree, idx), links,
                   link_samples(tree, links))

    def digest(self) -> str:
        """SHA-256 (hex) of the hand's content: every array, name and number of its
        kinematic tree, fingertips and link samples, but not the file it was read from,
        so that hands read from equal files have one digest wherever the files lie (the
        key of [`tune_hand`][jaxgrasp.tune_hand]'s stored executable)."""
        h = hashlib.sha256()
        _digest_into(h, self)
        return h.hexdigest()

    @property
    def num_joints(self) -> int:
        """Number of joints ``J``: the length of ``qpos``."""
        return self.tree.num_joints

    @property
    def joint_names(self) -> tuple:
        """``(J,)`` joint names, in ``qpos`` order."""
        return self.tree.jnt_names

    @property
    def lower(self) -> np.ndarray:
        """``(J,)`` lower joint limits, rad (hinge) or m (slide); ``-inf`` if unlimited."""
        return self.tree.jnt_range[:, 0]

    @property
    def upper(self) -> np.ndarray:
        """``(J,)`` upper joint limits, rad or m; ``inf`` if unlimited."""
        return self.tree.jnt_range[:, 1]

    def check_qpos(self, qpos, name: str = "qpos") -> np.ndarray:
        """A concrete ``qpos`` as a ``(J,)`` float64 array; a one-line error naming ``name``
        otherwise (strings, nested or ragged lists, booleans, NaN, another length)."""
        return finite_vector(qpos, self.num_joints, name, "joint positions (rad, m for slides)")

    def fingertip_frames(self, qpos, wrist=None):
        """``(centers (F, 3) m, axes (F, 3))`` in the world frame: each fingertip's
        end-cap centre and its unit axis (the geom's ``z`` towards the cap: the way it points), at
        joint positions ``qpos`` ``(J,)`` and the wrist pose ``(6,)`` (translation m,
        rotation vector rad; ``None``: the model's world frame). Traceable."""
        xpos, xmat = geom_frames(self.tree, qpos, wrist, self.fingertips)
        z = xmat[:, :, 2]
        axes = z * jnp.asarray(np.where(self.cap_offset < 0.0, -1.0, 1.0))[:, None]
        return xpos + z * jnp.asarray(self.cap_offset)[:, None], axes

    def fingertip_centers(self, qpos, wrist=None):
        """``(F, 3)`` fingertip centres (end-cap centres), m, world frame, at ``qpos``
        ``(J,)`` and ``wrist`` ``(6,)`` (see [`fingertip_frames`][jaxgrasp.Hand.fingertip_frames]). Traceable and
        differentiable."""
        return self.fingertip_frames(qpos, wrist)[0]

    def geom_frames(self, qpos, wrist=None, geoms=None):
        """``(xpos (G, 3) m, xmat (G, 3, 3))``: world frames of the geoms ``geoms`` (indices;
        ``None``: all) at ``qpos`` and ``wrist``."""
        return geom_frames(self.tree, qpos, wrist, geoms)

    def body_frames(self, qpos, wrist=None):
        """``(xpos (B, 3) m, xmat (B, 3, 3))``: world frames of every body."""
        return body_frames(self.tree, qpos, wrist)

    def link_depths(self, qpos, wrist, object_pose, surface):
        """``(P,)`` m: how deep each sample of the other links lies in the object
        (negative: clear of it), the object's [`jaxgrasp.surface.Surface`][jaxgrasp.surface.Surface] in its mesh
        frame placed by ``object_pose`` ``(6,)``; see `jaxgrasp.hands._links`. Traceable."""
        return link_depths(self, qpos, wrist, object_pose, surface)

    def grasp(self, qpos, mesh, **kwargs):
        """The grasp this configuration makes on ``mesh``: see `hand_grasp`."""
        from jaxgrasp.hands._grasp import hand_grasp

        return hand_grasp(self, qpos, mesh, **kwargs)


def _short(value) -> str:
    """``repr(value)``, at most 80 characters (a message echoes a user's value, not a whole file)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _digest_into(h, obj) -> None:
    """Feed ``obj`` (dataclasses, arrays, tuples, lists, names and numbers, nested) to the
    hash ``h``, each value tagged with its kind and size, so that no two contents feed
    the same bytes; a ``source`` field (a file name) is left out."""
    if dataclasses.is_dataclass(obj):
        h.update(f"<{type(obj).__name__}>".encode())
        for f in dataclasses.fields(obj):
            if f.name != "source":
                h.update(f"{f.name}=".encode())
                _digest_into(h, getattr(obj, f.name))
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"a{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    elif isinstance(obj, (tuple, list)):
        h.update(f"t{len(obj)}(".encode())
        for x in obj:
            _digest_into(h, x)
        h.update(b")")
    elif obj is None or isinstance(obj, (str, bool, int, float, np.generic)):
        text = repr(obj.item() if isinstance(obj, np.generic) else obj)
        h.update(f"s{len(text)}:{text}".encode())
    else:
        raise TypeError(f"Hand.digest: cannot hash a {type(obj).__name__}")
