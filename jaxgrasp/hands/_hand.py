"""A hand: its kinematic tree, its fingertips, and where they are at a configuration.

[`Hand`][jaxgrasp.Hand] is built from an MJCF or URDF file by [`Hand.from_file`][jaxgrasp.Hand.from_file]
([`Hand.from_mjcf`][jaxgrasp.Hand.from_mjcf]: MJCF only). A fingertip is a hemisphere fixed to one of
the hand's bodies (links): the end of a sphere or capsule geom, or a centre, axis and
radius given in a link's frame for fingertips that are meshes
(`jaxgrasp.hands._fingertips`), with its radius ``r`` (the paper's hemisphere, Sec. III)
and its axis, the direction the hemisphere points.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from typing import Sequence

import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands import _couplings
from jaxgrasp.hands._fingertips import resolve_fingertips
from jaxgrasp.hands._grasp import finite_vector
from jaxgrasp.hands._kinematics import body_frames, geom_frames
from jaxgrasp.hands._links import link_depths, link_positions, link_samples, self_overlap, self_segments
from jaxgrasp.hands._mjcf import BOX, CAPSULE, CYLINDER, SPHERE, KinematicTree, read_model

__all__ = ["Hand"]

_LINK_TYPES = (SPHERE, CAPSULE, CYLINDER, BOX)  # geoms whose penetration tune_hand keeps out of the object


@dataclasses.dataclass(frozen=True, eq=False)
class Hand:
    """A hand model read from MJCF or URDF: kinematics in JAX, fingertips as hemispheres (SI units).

    Build it with [`from_file`][jaxgrasp.Hand.from_file]. Not a pytree: its arrays are constants of the JAX
    functions that use it (compiled once per hand).

    Attributes:
        tree: the `KinematicTree`.
        fingertip_names: ``(F,)`` each fingertip's name as given (a geom's or a link's).
        fingertip_body: ``(F,)`` index of the body each fingertip is fixed to.
        fingertip_center: ``(F, 3)`` m, each hemisphere's centre in its body's frame.
        fingertip_axis: ``(F, 3)`` unit, the way each points, in its body's frame.
        radius: ``(F,)`` fingertip radius, m.
        fingertip_geoms: ``(F,)`` tuples of the geoms that belong to each fingertip.
        links: indices of the other geoms (spheres, capsules, cylinders, boxes not part of
            a fingertip: the links kept out of the object by [`tune_hand`][jaxgrasp.tune_hand];
            meshes and planes are left out).
        link_points: ``(geom (P,), points (P, 3) m, radius (P,) m)``, their samples
            (`link_samples`).
        self_segments: the hand's own collision pairs as swept spheres (`self_segments`),
            for [`self_overlap`][jaxgrasp.Hand.self_overlap].
    """

    tree: KinematicTree
    fingertip_names: tuple
    fingertip_body: np.ndarray
    fingertip_center: np.ndarray
    fingertip_axis: np.ndarray
    radius: np.ndarray
    fingertip_geoms: tuple
    links: np.ndarray
    link_points: tuple
    self_segments: tuple = ()

    @classmethod
    def from_file(cls, path: str | os.PathLike, fingertips: Sequence, allowed_dirs=None) -> "Hand":
        """Read the hand in the MJCF or URDF file ``path`` (told apart by the root element,
        ``<mujoco>`` or ``<robot>``; compiled by MuJoCo) with ``fingertips`` (at least 2).

        A fingertip is a geom name (a sphere or capsule), a body or link name (whose geoms
        include exactly one sphere or capsule), or a hemisphere on a link
        ``{"link": NAME, "center": [x, y, z], "axis": [x, y, z], "radius": r}`` (m, the
        link's frame) for fingertips that are meshes (`jaxgrasp.hands._fingertips`).

        The files the hand file names (MJCF includes and meshes, URDF collision meshes,
        ``package://`` paths resolved as ROS does) must lie in its folder after symlinks,
        or in one of the folders ``allowed_dirs``; they are read by jaxgrasp and checked
        (regular files under their caps, the model under its size caps) before MuJoCo
        sees them (`jaxgrasp.hands._mjcf_files`, `jaxgrasp.hands._urdf_files`).

        Raises:
            GraspValueError: MuJoCo missing (``pip install "jaxgrasp[hands]"``), a file
                outside the allowed folders or refused by the checks, a file MuJoCo cannot
                compile (for legacy MJCF: the element and the fix), a free, ball, floating
                or planar joint, an unknown fingertip name, a geom fingertip that is not a
                sphere or capsule, a bad hemisphere; one line.
        """
        tree, _ = read_model(path, allowed_dirs)
        return cls.of_tree(tree, fingertips)

    @classmethod
    def from_mjcf(cls, path: str | os.PathLike, fingertips: Sequence, allowed_dirs=None) -> "Hand":
        """Read the hand in the MJCF file ``path``: [`from_file`][jaxgrasp.Hand.from_file] for MJCF
        only (a URDF file is refused in one line)."""
        tree, _ = read_model(path, allowed_dirs, kinds=("mjcf",))
        return cls.of_tree(tree, fingertips)

    @classmethod
    def of_tree(cls, tree: KinematicTree, fingertips: Sequence) -> "Hand":
        """The hand of a `KinematicTree` with ``fingertips`` (as for [`from_file`][jaxgrasp.Hand.from_file])."""
        tips = resolve_fingertips(tree, fingertips)
        taken = {g for t in tips for g in t.geoms}
        links = np.array([g for g in range(len(tree.geom_body)) if g not in taken and tree.geom_type[g] in _LINK_TYPES],
                         dtype=int)
        return cls(tree, tuple(t.name for t in tips), np.array([t.body for t in tips], dtype=int),
                   np.array([t.center for t in tips], dtype=np.float64).reshape(-1, 3),
                   np.array([t.axis for t in tips], dtype=np.float64).reshape(-1, 3),
                   np.array([t.radius for t in tips], dtype=np.float64), tuple(t.geoms for t in tips), links,
                   link_samples(tree, links), self_segments(tree))

    def digest(self) -> str:
        """SHA-256 (hex) of the hand's content: every array, name and number of its
        kinematic tree (its couplings included), fingertips and link samples, but not the file it was read from,
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

    @property
    def coupling_names(self) -> tuple:
        """``(C,)`` the names of the joints' couplings (limited fixed tendons, then joint
        equalities; `KinematicTree`'s ``coupling_*`` fields hold their rows and ranges)."""
        return self.tree.coupling_names

    def coupling_violation(self, qpos):
        """``(..., C)`` m (a tendon's length) or rad (an equality of hinges): how far each of
        the hand's couplings ``lower <= A @ qpos <= upper`` is outside its range at ``qpos``
        ``(..., J)``, 0 within it. Traceable."""
        return _couplings.coupling_violation(self.tree, qpos)

    def project_joints(self, qpos, sweeps: int = _couplings.PROJECTION_SWEEPS):
        """``(..., J)``: a configuration within the joint limits (exactly) and the couplings
        (to the tolerance the sweeps reach: 1.4e-15 m on the Shadow hand from configurations
        within the limits), by ``sweeps`` sweeps of alternating projections, each row's slab
        ``[lower, upper]`` in turn then the limits (`jaxgrasp.hands._couplings`). ``qpos``
        ``(..., J)`` itself where it is within both, its derivative there the identity; the
        clip to the limits for a hand without couplings. Traceable, differentiable almost
        everywhere. [`tune_hand`][jaxgrasp.tune_hand] evaluates the configuration this returns."""
        return _couplings.project_joints(self.tree, qpos, sweeps)

    def check_qpos(self, qpos, name: str = "qpos") -> np.ndarray:
        """A concrete ``qpos`` as a ``(J,)`` float64 array; a one-line error naming ``name``
        otherwise (strings, nested or ragged lists, booleans, NaN, another length)."""
        return finite_vector(qpos, self.num_joints, name, "joint positions (rad, m for slides)")

    @property
    def num_fingertips(self) -> int:
        """Number of fingertips ``F``."""
        return len(self.fingertip_names)

    def fingertip_frames(self, qpos, wrist=None):
        """``(centers (F, 3) m, axes (F, 3))`` in the world frame: each fingertip's
        hemisphere centre and its unit axis (the way it points), at joint positions
        ``qpos`` ``(J,)`` and the wrist pose ``(6,)`` (translation m, rotation vector rad;
        ``None``: the model's world frame): its body's frame, then its offset in that
        frame. Traceable."""
        xpos, xmat = body_frames(self.tree, qpos, wrist)
        rot = xmat[self.fingertip_body]
        centers = xpos[self.fingertip_body] + jnp.einsum("fij,fj->fi", rot, jnp.asarray(self.fingertip_center))
        return centers, jnp.einsum("fij,fj->fi", rot, jnp.asarray(self.fingertip_axis))

    def fingertip_centers(self, qpos, wrist=None):
        """``(F, 3)`` fingertip centres (hemisphere centres), m, world frame, at ``qpos``
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

    def link_positions(self, qpos, wrist=None):
        """``(P, 3)`` m: the world positions of the other links' samples (``link_points``,
        each with its radius there) at ``qpos``. Traceable."""
        return link_positions(self, qpos, wrist)

    def link_depths(self, qpos, wrist, object_pose, surface):
        """``(P,)`` m: how deep each sample of the other links lies in the object
        (negative: clear of it), the object's [`jaxgrasp.surface.Surface`][jaxgrasp.surface.Surface] in its mesh
        frame placed by ``object_pose`` ``(6,)``; see `jaxgrasp.hands._links`. Traceable."""
        return link_depths(self, qpos, wrist, object_pose, surface)

    def self_overlap(self, qpos, wrist=None):
        """``(P,)`` m: how deep each pair of the hand's geoms that MuJoCo would collide
        (``tree.collision_pairs`` less those with a mesh) overlap at ``qpos`` (positive;
        negative: their clearance), spheres and capsules in closed form, boxes by their
        samples (`jaxgrasp.hands._links.self_overlap`); ``(1,)`` of -1 m for a hand
        without such pairs. Traceable and differentiable."""
        return self_overlap(self, qpos, wrist)

    def grasp(self, qpos, mesh, **kwargs):
        """The grasp this configuration makes on ``mesh``: see `hand_grasp`."""
        from jaxgrasp.hands._grasp import hand_grasp

        return hand_grasp(self, qpos, mesh, **kwargs)


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
