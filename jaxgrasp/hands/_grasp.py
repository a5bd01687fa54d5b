"""The grasp a hand configuration makes on an object: fingertips to contacts.

Each fingertip is the sphere of its radius ``r`` about its end-cap centre ``c``
([`fingertip_frames`][jaxgrasp.Hand.fingertip_frames]). With the object's surface in its mesh frame
([`jaxgrasp.surface.Surface`][jaxgrasp.surface.Surface]), a fingertip's contact is the surface point ``p``
closest to ``c``, its normal the outward normal of the face there, and its initial
deformation ``dr = r - d``, ``d`` the signed distance of ``c`` (``|c - p|`` outside the
object; the paper's ``dr``, eq. 13 at the initial state). The contact positions go into
the model's frame (origin at the centre of mass, the mesh's axes) and the world's
gravity into the object's axes, so the [`Grasp`][jaxgrasp.Grasp] is the one
[`jaxgrasp.evaluate`][jaxgrasp.evaluate] expects.

Modelling choices the paper forces (Sec. III and V):

* **Fingertips are fixed during the grasp.** The hand's joints are held: only the object
  moves from the initial grasping state; the configuration sets the initial state.
* **The fingertip is the end cap's hemisphere.** The paper's hemisphere is pressed along
  its axis, its base parallel to the contact surface. A hand's cap rarely meets the
  surface that way: each fingertip's **tilt** (the angle between its axis and the
  inward normal ``-n``, rad) is reported. The elastic model is applied as if the
  hemisphere met the surface along its axis (the energy of eq. 3-8 depends on ``dr``
  alone, not on the tilt): an approximation that grows with the tilt.
* **A contact on the capsule's cylinder is not a fingertip contact.** Where the tilt is
  at least ``max_tilt`` (default 90 degrees: the contact direction leaves the cap's
  hemisphere) the part of the capsule that would touch is its cylinder, a line contact
  that the paper's model does not describe: that fingertip is left out (inactive), as is
  a fingertip that does not reach the surface (``dr <= 0``) or whose centre is inside
  the object (``dr >= r``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.hands._kinematics import wrist_transform
from jaxgrasp.model import DEFAULT_GRAVITY, Grasp, GraspValueError, as_float_array, check_grasp_inputs

__all__ = ["HandGrasp", "hand_grasp", "contact_grasp", "Material", "material", "DEFAULT_MAX_TILT", "finite_vector"]

DEFAULT_MAX_TILT = 0.5 * math.pi
"""Largest fingertip tilt, rad, at which a fingertip is still a contact (the cap's edge)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Material:
    """The grasp's fields a hand does not set (SI units; a pytree).

    Attributes:
        young_modulus: ``(F,)`` Pa. friction: ``(F,)``. max_force: ``(F,)`` N.
        mass: ``()`` kg. gravity: ``(3,)`` m/s^2, world frame.
        center_of_mass: ``(3,)`` m, mesh frame.
    """

    young_modulus: jax.Array
    friction: jax.Array
    max_force: jax.Array
    mass: jax.Array
    gravity: jax.Array
    center_of_mass: jax.Array


def material(num_fingertips: int, mesh, young_modulus, friction, max_force, mass=None, density=None,
             gravity=DEFAULT_GRAVITY, center_of_mass=None) -> Material:
    """A checked `Material` (scalars broadcast to every fingertip); the centre of
    mass and mass from the mesh as [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] has them (``mass`` or
    ``density``, kg or kg/m^3; neither: 0)."""
    from jaxgrasp.surface import mass_properties

    com, m = mass_properties(mesh, mass, density, center_of_mass)
    angle = 2.0 * np.pi * np.arange(num_fingertips) / num_fingertips
    ring = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    probe = check_grasp_inputs(  # the rules of every field, on a stand-in geometry (a ring of contacts)
        positions=ring, normals=ring, initial_deformation=1e-9,
        radius=1.0, young_modulus=young_modulus, friction=friction, max_force=max_force, mass=0.0, gravity=gravity,
    )
    if not (np.isfinite(m) and m >= 0.0):
        raise GraspValueError(f"mass = {m!r} must be >= 0 (kg)")
    return Material(*(jnp.asarray(probe[k]) for k in ("young_modulus", "friction", "max_force")),
                    jnp.float64(m), jnp.asarray(probe["gravity"]), jnp.asarray(com, dtype=jnp.float64))


def object_transform(object_pose):
    """``(R (3, 3), t (3,))`` of the object's mesh frame in the world: ``object_pose``
    ``(6,)``, translation m then rotation vector rad (``None``: the world frame)."""
    if object_pose is None:
        return jnp.eye(3), jnp.zeros(3)
    return wrist_transform(object_pose)


def contact_grasp(hand, qpos, wrist, object_pose, surface, mat: Material, max_tilt=DEFAULT_MAX_TILT):
    """``(grasp, tilt, centers)`` (traceable): the [`Grasp`][jaxgrasp.Grasp] (model frame,
    ``active`` the fingertips in contact), each fingertip's tilt ``(F,)`` rad, and the
    fingertip centres ``(F, 3)`` m in the mesh frame."""
    centers, axes = hand.fingertip_frames(qpos, wrist)
    rot, t = object_transform(object_pose)
    c = (centers - t) @ rot  # R^T (c - t): the mesh frame
    a = axes @ rot
    hit = surface.closest(c)
    r = jnp.asarray(hand.radius)
    dr = r - hit.signed_distance
    cos_tilt = -jnp.sum(a * hit.normal, axis=-1)
    tilt = jnp.arccos(jnp.clip(jax.lax.stop_gradient(cos_tilt), -1.0, 1.0))  # reported, never differentiated
    active = (dr > 0.0) & (dr < r) & (cos_tilt > math.cos(max_tilt))
    grasp = Grasp(
        positions=hit.point - mat.center_of_mass,
        normals=hit.normal,
        initial_deformation=jnp.where(active, dr, 0.5 * r),  # a valid stand-in where inactive
        radius=r,
        young_modulus=mat.young_modulus,
        friction=mat.friction,
        max_force=mat.max_force,
        mass=mat.mass,
        gravity=mat.gravity @ rot,
        active=active,
    )
    return grasp, tilt, c


@dataclasses.dataclass(frozen=True, eq=False)
class HandGrasp:
    """The grasp a hand configuration makes, with what is needed to draw it (SI units).

    Attributes:
        grasp: the [`Grasp`][jaxgrasp.Grasp], model frame (origin at the object's centre of
            mass, the mesh's axes), ``active`` the fingertips in contact. Evaluate it with
            [`jaxgrasp.evaluate`][jaxgrasp.evaluate].
        active: ``(F,)`` bool, the fingertips that touch the object with their cap.
        tilt: ``(F,)`` rad, each fingertip's axis from the inward normal (0: the paper's
            assumption, the hemisphere's base parallel to the surface).
        centers: ``(F, 3)`` m, fingertip centres in the mesh frame.
        mesh: the object's ``trimesh.Trimesh``, m, mesh frame.
        center_of_mass: ``(3,)`` m, mesh frame.
        object_pose: ``(6,)`` the mesh frame in the world (translation m, rotation vector rad).
        qpos: ``(J,)`` the configuration. wrist: ``(6,)`` the wrist pose.
        hand: the [`Hand`][jaxgrasp.Hand].
        status: ``"grasp"`` (at least 2 fingertips in contact) or ``"too_few_contacts"``
            (fewer: the grasp cannot be evaluated; its value would be 0).
    """

    grasp: Grasp
    active: jax.Array
    tilt: jax.Array
    centers: jax.Array
    mesh: Any
    center_of_mass: jax.Array
    object_pose: jax.Array
    qpos: jax.Array
    wrist: jax.Array
    hand: Any
    status: str

    @property
    def num_active(self) -> int:
        """Number of fingertips in contact."""
        return int(np.sum(np.asarray(self.active)))

    def mesh_grasp(self):
        """The grasp as a [`MeshGrasp`][jaxgrasp.MeshGrasp] (the grasp, the mesh, the centre of
        mass): what `jaxgrasp.plots.plot_grasp` and ``jaxgrasp show`` draw."""
        from jaxgrasp.surface import MeshGrasp

        return MeshGrasp(self.grasp, self.mesh, np.asarray(self.center_of_mass), "<hand>")

    def to_mesh_frame(self, points) -> np.ndarray:
        """World points ``(..., 3)`` m in the mesh frame."""
        rot, t = object_transform(self.object_pose)
        return (np.asarray(points) - np.asarray(t)) @ np.asarray(rot)


def finite_vector(value, n: int, name: str, what: str) -> np.ndarray:
    """``value`` as ``(n,)`` finite float64 numbers; one line naming ``name`` otherwise
    (strings, booleans, nested or ragged lists, NaN or infinity, another length)."""
    q = as_float_array(name, value)
    if q.shape != (n,):
        raise GraspValueError(f"{name} must be {n} {what}, got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise GraspValueError(f"{name}[{int(np.argmin(np.isfinite(q)))}] = {q[~np.isfinite(q)][0]} must be finite")
    return q


def _pose(value, name: str):
    """A pose ``(6,)`` float64 (``None``: zeros); a one-line error for anything else."""
    if value is None:
        return jnp.zeros(6)
    if isinstance(value, jax.core.Tracer):
        return value
    return jnp.asarray(finite_vector(value, 6, name, "finite numbers (translation m, rotation vector rad)"))


def hand_grasp(hand, qpos, mesh, *, wrist=None, object_pose=None, young_modulus, friction, max_force,
               mass=None, density=None, gravity=DEFAULT_GRAVITY, center_of_mass=None, units: str = "m",
               max_tilt: float = DEFAULT_MAX_TILT) -> HandGrasp:
    """The grasp the configuration ``qpos`` of ``hand`` makes on the object ``mesh``.

    Args:
        hand: a [`Hand`][jaxgrasp.Hand].
        qpos: ``(J,)`` joint positions, rad (hinges) or m (slides); may be traced
            (``jax.grad`` of ``evaluate(hand.grasp(qpos, ...).grasp).value`` works).
        mesh: ``trimesh.Trimesh`` or a mesh file ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh]'s rules), in
            ``units``; its frame is placed in the world by ``object_pose``.
        wrist: ``(6,)`` the hand's model frame in the world: translation m, rotation
            vector rad (``None``: the world's).
        object_pose: ``(6,)`` the mesh frame in the world, likewise.
        young_modulus, friction, max_force: Pa, -, N, a scalar or one per fingertip.
        mass, density: kg or kg/m^3 (one of them; neither: 0).
        gravity: ``(3,)`` m/s^2 in the world frame.
        center_of_mass: ``(3,)`` m, mesh frame (default: the watertight mesh's).
        max_tilt: rad, a fingertip tilted this much or more is not a contact (module notes).

    Returns:
        A [`HandGrasp`][jaxgrasp.hands.HandGrasp]: the [`Grasp`][jaxgrasp.Grasp] in the object's centre-of-mass
        frame (each contact at the surface point closest to its fingertip centre,
        ``dr = r - |c - p|``, the surface's outward normal there), the active mask, each
        fingertip's tilt and the mesh.

    Raises:
        GraspValueError: a malformed ``qpos``, pose or field; one line naming it.
    """
    from jaxgrasp.io import load_mesh
    from jaxgrasp.surface import PAD_FACES, Surface

    if not isinstance(qpos, jax.core.Tracer):
        qpos = jnp.asarray(hand.check_qpos(qpos))
    wrist, object_pose = _pose(wrist, "wrist"), _pose(object_pose, "object_pose")
    mesh = load_mesh(mesh, units)
    mat = material(hand.num_fingertips, mesh, young_modulus, friction, max_force, mass, density, gravity, center_of_mass)
    surface = Surface.from_trimesh(mesh, pad_to=PAD_FACES)  # one shape for meshes of similar size: compiled once for them
    grasp, tilt, centers = contact_grasp(hand, qpos, wrist, object_pose, surface, mat, max_tilt)
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((grasp, qpos, wrist, object_pose)))
    status = "grasp" if traced or int(np.sum(np.asarray(grasp.active))) >= 2 else "too_few_contacts"
    return HandGrasp(grasp, grasp.active, tilt, centers, mesh, mat.center_of_mass, object_pose, qpos, wrist, hand, status)
