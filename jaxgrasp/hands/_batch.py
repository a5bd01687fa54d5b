"""Hand batches: many configurations of one hand on one object, as one dataset of grasps.

[`hand_batch`][jaxgrasp.hands.hand_batch] turns ``B`` configurations (joints, wrist poses,
object poses and object scales) into the grasps they make, by the rules of
[`Hand.grasp`][jaxgrasp.Hand.grasp] (`jaxgrasp.hands._grasp`), in one compiled function of a
chunk of configurations (``jit(vmap(...))`` of the kinematics and the closest points), and
gives a [`HandBatch`][jaxgrasp.hands.HandBatch]: a [`GraspSet`][jaxgrasp.GraspSet] in input order, which
[`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] and ``jaxgrasp batch`` evaluate through the engine's
one runner, and each fingertip's contact, ``dr`` and tilt.

**One numbering.** Contact ``k`` of every grasp is fingertip ``k``, in the order the hand
was given its fingertips, whether it touches or not: the set's rows keep all ``F``
fingertips with a mask of those in contact (`GraspColumns.mask`), so a result's
``limiting_contact`` and its per-contact arrays name fingertips by that number.

A configuration with fewer than 2 fingertips in contact is not a grasp the model can
evaluate: its row is invalid (status ``invalid``, value NaN) with a one-line error naming
the fingertips that touch.

**Scale.** DexGraspNet scales its object meshes per grasp. A row's ``scale`` ``s`` scales
the mesh about its origin; the centre of mass scales by ``s``, a mass given by density
by ``s^3`` (a mass given in kg is that mass at every scale).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, Callable

import jax
import numpy as np

from jaxgrasp.hands._grasp import DEFAULT_MAX_TILT, contact_grasp, finite_vector, material
from jaxgrasp.model import DEFAULT_GRAVITY, GraspValueError, as_float_array

if TYPE_CHECKING:
    from jaxgrasp.io import GraspSet

__all__ = ["HandBatch", "hand_batch", "MAX_HAND_CHUNK"]

MAX_HAND_CHUNK = 256
"""Configurations per call of the compiled contact function, at most (a chunk is the smallest
of 1, 4, 16, 64, 256 that holds the rows, so batches of any size share four compilations)."""

_GRASP_FIELDS = ("positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force",
                 "mass", "gravity")


@dataclasses.dataclass(frozen=True, eq=False)
class HandBatch:
    """The grasps ``B`` configurations of one hand make on one object (SI units).

    Attributes:
        grasps: the [`GraspSet`][jaxgrasp.GraspSet] of the ``B`` grasps in input order, contact
            ``k`` = fingertip ``k`` (module notes), model frame of each row's object (origin
            at its centre of mass); rows with fewer than 2 fingertips in contact invalid.
            Evaluate it with [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch].
        active: ``(B, F)`` bool, the fingertips in contact (their cap on the surface).
        dr: ``(B, F)`` m, each fingertip's initial deformation ``r - d`` (eq. 13 at the
            initial state), NaN where not in contact.
        tilt: ``(B, F)`` rad, each fingertip's axis from the inward normal.
        centers: ``(B, F, 3)`` m, fingertip centres in the (scaled) mesh frame.
        fingertip_names: ``(F,)`` the fingertips' names, in order.
    """

    grasps: GraspSet
    active: np.ndarray
    dr: np.ndarray
    tilt: np.ndarray
    centers: np.ndarray
    fingertip_names: tuple

    def __len__(self) -> int:
        return len(self.active)

    def columns(self) -> dict[str, np.ndarray]:
        """``(B,)`` columns by name for a results table: ``active`` (fingertips in contact),
        ``in_contact`` (their names, space-separated), then per fingertip ``k``: ``dr_k``
        (m, NaN where not in contact) and ``tilt_k`` (deg)."""
        names = np.asarray(self.fingertip_names, dtype=object)
        out = {
            "active": self.active.sum(axis=1).astype(np.int64),
            "in_contact": np.asarray([" ".join(names[row]) for row in self.active], dtype=object),
        }
        for k in range(self.active.shape[1]):
            out[f"dr_{k}"] = self.dr[:, k]
        for k in range(self.active.shape[1]):
            out[f"tilt_{k}"] = np.degrees(self.tilt[:, k])
        return out


def _rows(value, b: int, n: int, name: str, what: str, default) -> np.ndarray:
    """``value`` as ``(b, n)`` finite float64 (one row ``(n,)``: every configuration's;
    ``None``: ``default``); one line naming ``name`` otherwise."""
    if value is None:
        return np.broadcast_to(np.asarray(default, dtype=np.float64), (b, n))
    a = as_float_array(name, value)
    if a.ndim == 1:
        return np.broadcast_to(finite_vector(a, n, name, what), (b, n))
    if a.shape != (b, n):
        raise GraspValueError(f"{name} must be ({b}, {n}) or ({n},) {what}, got shape {a.shape}")
    finite_vector(a.reshape(-1), a.size, name, what)
    return a


def _scales(scale, b: int) -> np.ndarray:
    """``(b,)`` positive finite scales (a number: every row's; ``None``: 1)."""
    if scale is None:
        return np.ones(b)
    a = as_float_array("scale", scale)
    s = finite_vector(np.full(b, a) if a.ndim == 0 else a, b, "scale", "object scales (one per configuration)")
    if np.any(s <= 0.0):
        raise GraspValueError(f"scale[{int(np.argmax(s <= 0.0))}] = {s[s <= 0.0][0]} must be > 0")
    return s


_COMPILED: dict = {}


def _contacts_function(hand, max_tilt: float) -> Callable:
    """The compiled ``(surface, material, qpos (C, J), wrist (C, 6), pose (C, 6)) ->
    (grasp, tilt, centers)`` of ``hand`` (one per hand content and ``max_tilt``)."""
    key = (hand.digest(), float(max_tilt))
    if key not in _COMPILED:
        if len(_COMPILED) >= 4:  # a few hands at a time: each entry holds its compiled programs
            _COMPILED.pop(next(iter(_COMPILED)))

        def one(surface, mat, q, w, p):
            return contact_grasp(hand, q, w, p, surface, mat, max_tilt)

        _COMPILED[key] = jax.jit(jax.vmap(one, in_axes=(None, None, 0, 0, 0)))
    return _COMPILED[key]


def _chunk(rows: int) -> int:
    """The chunk for ``rows`` configurations: the smallest of 1, 4, 16, 64, 256 holding them."""
    return min(MAX_HAND_CHUNK, 4 ** max(0, math.ceil(math.log(max(rows, 1), 4))))


def _contacts(fn, surface, mat, q, w, p, progress) -> dict[str, np.ndarray]:
    """The fields, tilts and centres of configurations ``q, w, p`` (each ``(R, .)``), in
    chunks of `_chunk` (the last padded by repeating its last row)."""
    r = len(q)
    c = _chunk(r)
    parts = []
    for start in range(0, r, c):
        take = np.minimum(np.arange(start, start + c), r - 1)
        grasp, tilt, centers = fn(surface, mat, q[take], w[take], p[take])
        n = min(c, r - start)
        parts.append({**{k: np.asarray(getattr(grasp, k))[:n] for k in (*_GRASP_FIELDS, "active")},
                      "tilt": np.asarray(tilt)[:n], "centers": np.asarray(centers)[:n]})
        if progress is not None:
            progress(start + n, r)
    return {k: np.concatenate([part[k] for part in parts]) for k in parts[0]}


def hand_batch(hand, mesh, qpos, *, wrist=None, object_pose=None, scale=None, objects=None, young_modulus, friction,
               max_force,
               mass=None, density=None, gravity=DEFAULT_GRAVITY, center_of_mass=None, units: str = "m",
               max_tilt: float = DEFAULT_MAX_TILT, progress: Callable[[int, int], Any] | None = None,
               source: str = "<memory>", source_sha256: str | None = None) -> HandBatch:
    """The grasps of ``B`` configurations of ``hand`` on the object ``mesh`` (module notes).

    Args:
        hand: a [`Hand`][jaxgrasp.Hand] with ``F`` fingertips and ``J`` joints.
        mesh: ``trimesh.Trimesh`` or a mesh file, in ``units``, its frame placed in the
            world by ``object_pose`` and scaled by ``scale``; or a sequence of them, each
            row's named by ``objects``.
        qpos: ``(B, J)`` joint positions, rad (m for slides).
        wrist: ``(B, 6)`` or ``(6,)`` the hand's model frame in the world: translation m,
            rotation vector rad (``None``: the world's).
        object_pose: ``(B, 6)`` or ``(6,)`` the mesh frame in the world, likewise.
        scale: ``(B,)`` or a number, > 0: the mesh scaled about its origin (``None``: 1).
        objects: ``(B,)`` int, the index of each row's mesh where ``mesh`` is a sequence.
        young_modulus, friction, max_force: Pa, -, N, a number or one per fingertip.
        mass, density: kg or kg/m^3 (one of them; neither: 0).
        gravity: ``(3,)`` m/s^2, world frame.
        center_of_mass: ``(3,)`` m in the unscaled mesh frame (default: the watertight mesh's).
        max_tilt: rad, as [`Hand.grasp`][jaxgrasp.Hand.grasp].
        progress: ``progress(done, total)`` after each chunk of configurations.
        source, source_sha256: the name and content hash of the file the rows came from
            (kept in the set, for ``jaxgrasp batch --resume``).

    Returns:
        A [`HandBatch`][jaxgrasp.hands.HandBatch].

    Raises:
        GraspValueError: a malformed ``qpos``, pose, scale or field; one line naming it.
    """
    q = np.asarray(qpos) if isinstance(qpos, np.ndarray) else qpos
    b = int(np.shape(q)[0]) if np.ndim(q) == 2 else -1
    if b < 1:
        raise GraspValueError(f"qpos must be (B, {hand.num_joints}) joint positions with B >= 1, got shape {np.shape(q)}")
    q = _rows(q, b, hand.num_joints, "qpos", "joint positions (rad, m for slides)", 0.0)
    w = _rows(wrist, b, 6, "wrist", "finite numbers (translation m, rotation vector rad)", np.zeros(6))
    p = _rows(object_pose, b, 6, "object_pose", "finite numbers (translation m, rotation vector rad)", np.zeros(6))
    s = _scales(scale, b)
    meshes, which = _meshes(mesh, objects, b, units)
    fn = _contacts_function(hand, max_tilt)
    out: dict[str, np.ndarray] = {}
    done = 0
    for o, value in sorted(set(zip(which.tolist(), s.tolist()))):  # one surface and material each (a dataset has a few)
        rows = np.flatnonzero((which == o) & (s == value))
        told = None if progress is None else (lambda k, _n, before=done: progress(before + k, b))
        part = _scaled_contacts(fn, hand, meshes[o], value, q[rows], w[rows], p[rows], told, young_modulus,
                                friction, max_force, mass, density, gravity, center_of_mass)
        for k, a in part.items():
            out.setdefault(k, np.empty((b, *a.shape[1:]), dtype=a.dtype))[rows] = a
        done += rows.size
    return _batch_of(out, hand, source, source_sha256)


def _meshes(mesh, objects, b: int, units: str) -> tuple[list, np.ndarray]:
    """``(meshes, which (b,))``: the checked meshes in m and each row's index among them."""
    from jaxgrasp.io import load_mesh

    many = isinstance(mesh, (list, tuple))
    if many != (objects is not None):
        raise GraspValueError("give objects (each row's mesh index) with a sequence of meshes, and only then")
    meshes = [load_mesh(m, units) for m in (mesh if many else [mesh])]
    if not many:
        return meshes, np.zeros(b, dtype=np.int64)
    which = np.asarray(objects)
    if which.shape != (b,) or which.dtype.kind not in "iu" or which.min() < 0 or which.max() >= len(meshes):
        raise GraspValueError(f"objects must be ({b},) indices into the {len(meshes)} meshes")
    return meshes, which.astype(np.int64)


def _scaled_contacts(fn, hand, base, s: float, q, w, p, progress, young_modulus, friction, max_force, mass, density,
                     gravity, center_of_mass) -> dict[str, np.ndarray]:
    """The contacts of rows ``q, w, p`` on ``base`` scaled by ``s`` (`_contacts`)."""
    from jaxgrasp.surface import PAD_FACES, Surface

    mesh = base.copy()
    if s != 1.0:
        mesh.apply_scale(s)
    com = None if center_of_mass is None else s * np.asarray(finite_vector(center_of_mass, 3, "center_of_mass", "m"))
    mat = material(len(hand.fingertip_names), mesh, young_modulus, friction, max_force, mass, density, gravity, com)
    # padded: meshes of similar size share one shape, so the contacts' program is compiled once for them
    return _contacts(fn, Surface.from_trimesh(mesh, pad_to=PAD_FACES), mat, q, w, p, progress)


def _batch_of(out: dict[str, np.ndarray], hand, source: str, source_sha256: str | None) -> HandBatch:
    """The `HandBatch` of the computed contacts ``out`` (`_contacts`, every row)."""
    from jaxgrasp.io import GraspColumns, GraspRows, GraspSet

    active = out["active"].astype(bool)
    counts = active.sum(axis=1)
    valid = counts >= 2
    names = hand.fingertip_names
    errors = tuple(None if ok else _too_few(i, row, names) for i, (ok, row) in enumerate(zip(valid, active)))
    mask = active & valid[:, None]
    columns = GraspColumns(fields={k: out[k] for k in _GRASP_FIELDS}, counts=np.where(valid, counts, 0), mask=mask)
    grasps = GraspSet(GraspRows(columns), errors, source, source_sha256)
    dr = np.where(active, out["initial_deformation"], np.nan)
    return HandBatch(grasps, active, dr, out["tilt"], out["centers"], tuple(names))


def _too_few(i: int, active: np.ndarray, names) -> str:
    """The error of row ``i``, whose fingertips ``active`` are fewer than 2."""
    touching = [n for n, a in zip(names, active) if a]
    which = f" ({', '.join(touching)})" if touching else ""
    return f"grasp {i}: {len(touching)} fingertip(s) in contact{which}; a grasp needs at least 2"
