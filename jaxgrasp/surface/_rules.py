"""When a fingertip contact on a mesh is one the paper's model describes: the candidate rules.

The paper's model assumes a planar contact surface under each fingertip and fingertips
fixed in space (Sec. V, eq. 4: a hemisphere pressed ``dr`` into a plane). On a mesh a
contact ``(p_i, n_i, dr_i)`` of a fingertip of radius ``r`` is *valid* when:

1. **on the surface**: ``p_i`` lies on the surface (within ``on_surface`` m), and ``n_i`` is the
   outward normal of a face it lies on (within ``normal_deg`` degrees);
2. **flat patch**: every face within the contact radius ``a_i = sqrt(r^2 - (r - dr_i)^2)`` of
   ``p_i`` (the radius of the disc the fingertip presses flat) has its normal within
   ``flatness_deg`` of ``n_i``;
3. **fingertips apart**: the fingertip spheres, centres ``c_i = p_i + (r - dr_i) n_i``, do not
   overlap: ``|c_i - c_j| >= r_i + r_j``;
4. **one contact per fingertip**: the fingertip touches the object only at its own contact:
   the distance from ``c_i`` to the surface is at least ``r - dr_i`` (less ``on_surface``:
   no other part of the object comes closer to the fingertip's centre than the pressed-in
   disc);
5. **deformation in range**: ``dr_min <= dr_i <= dr_max = min(0.9 r, sqrt(f_max / (pi E)))``,
   the second bound being the deformation at which eq. 4's normal force ``pi E dr^2``
   reaches the force limit.

Everything here is traceable (``jit``/``vmap`` over candidates) and in the mesh's frame.
Rules 1, 2 and 4 search the surface's face tree ([`Surface`][jaxgrasp.surface.Surface]):
their cost grows with the faces near each contact, not with the mesh's face count.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp

from jaxgrasp.model import GraspValueError
from jaxgrasp.surface._surface import Surface

__all__ = ["ContactRules", "RuleCheck", "check_contacts", "contact_radius", "fingertip_centers", "deformation_range"]


@dataclasses.dataclass(frozen=True)
class ContactRules:
    """The tolerances of the candidate rules (see the module).

    Attributes:
        flatness_deg: largest angle, degrees, between ``n_i`` and the normal of a face within
            the contact radius (rule 2).
        dr_min: smallest initial deformation, m (rule 5).
        on_surface: farthest a contact may lie from the surface, m (rule 1).
        normal_deg: largest angle, degrees, between ``n_i`` and the normal of the face it lies
            on (rule 1).
    """

    flatness_deg: float = 25.0
    dr_min: float = 5e-4
    on_surface: float = 1e-6
    normal_deg: float = 2.0

    def __post_init__(self):
        for name, lo, hi in (("flatness_deg", 0.0, 90.0), ("normal_deg", 0.0, 90.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and lo <= v < hi):
                raise GraspValueError(f"{name} = {v!r} must be a number of degrees in [{lo:g}, {hi:g})")
        for name in ("dr_min", "on_surface"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v < 1.0):
                raise GraspValueError(f"{name} = {v!r} must be a length >= 0 in m")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RuleCheck:
    """Which rules contacts keep (shapes: ``(..., N)`` per contact, ``(...)`` per grasp).

    Attributes:
        on_surface: ``(..., N)`` rule 1.
        flat: ``(..., N)`` rule 2.
        apart: ``(..., N)`` rule 3: the fingertip overlaps no other.
        alone: ``(..., N)`` rule 4.
        deformation: ``(..., N)`` rule 5.
        valid: ``(...)`` every rule holds for every contact.
    """

    on_surface: jax.Array
    flat: jax.Array
    apart: jax.Array
    alone: jax.Array
    deformation: jax.Array
    valid: jax.Array

    RULES = ("on_surface", "flat", "apart", "alone", "deformation")


def contact_radius(radius, dr):
    """``a = sqrt(r^2 - (r - dr)^2)`` m: the radius of the disc a hemisphere of radius ``r``
    pressed ``dr`` into a plane flattens (eq. 4's contact area is ``pi a^2`` to first order)."""
    return jnp.sqrt(jnp.maximum(radius**2 - (radius - dr) ** 2, 0.0))


def fingertip_centers(positions, normals, radius, dr):
    """``(..., N, 3)`` m: the fingertip sphere centres ``c_i = p_i + (r - dr_i) n_i``."""
    n = normals / jnp.linalg.norm(normals, axis=-1, keepdims=True)
    return positions + (radius - dr)[..., None] * n


def deformation_range(radius, young_modulus, max_force, dr_min):
    """``(lo, hi)`` m: rule 5's range of the initial deformation, ``hi = min(0.9 r,
    sqrt(f_max / (pi E)))`` (eq. 4 at the force limit)."""
    hi = jnp.minimum(0.9 * radius, jnp.sqrt(max_force / (jnp.pi * young_modulus)))
    return jnp.broadcast_to(jnp.asarray(dr_min, jnp.float64), jnp.shape(hi)), hi


@functools.partial(jax.jit, static_argnames=("rules",))
def check_contacts(surface: Surface, positions, normals, dr, radius, young_modulus, max_force,
                   rules: ContactRules = ContactRules()) -> RuleCheck:
    """Check one grasp's contacts against the rules (traceable; ``vmap`` it for many).

    Args:
        surface: the object's [`Surface`][jaxgrasp.surface.Surface], in the frame of ``positions``.
        positions: ``(N, 3)`` m contact points.
        normals: ``(N, 3)`` outward contact normals (unit or not).
        dr: ``(N,)`` m initial deformations.
        radius, young_modulus, max_force: ``(N,)`` fingertip radius m, Young's modulus Pa,
            force limit N (scalars broadcast).

    Returns:
        A [`RuleCheck`][jaxgrasp.surface.RuleCheck] of the grasp.
    """
    n = normals / jnp.linalg.norm(normals, axis=-1, keepdims=True)
    shape = dr.shape
    r, e, fmax = (jnp.broadcast_to(jnp.asarray(x, jnp.float64), shape) for x in (radius, young_modulus, max_force))
    hit = surface.closest(positions)
    cos_normal = jnp.cos(jnp.deg2rad(rules.normal_deg))
    on_surface = (hit.distance <= rules.on_surface) & (jnp.einsum("nd,nd->n", hit.normal, n) >= cos_normal)
    flat = ~surface.unaligned_within(positions, n, contact_radius(r, dr), rules.flatness_deg)  # the face tree's search
    c = fingertip_centers(positions, n, r, dr)
    gap = jnp.linalg.norm(c[:, None] - c[None], axis=-1) - (r[:, None] + r[None])
    apart = jnp.all(jnp.where(jnp.eye(shape[0], dtype=bool), True, gap >= 0.0), axis=-1)
    alone = surface.closest(c).distance >= (r - dr) - rules.on_surface
    lo, hi = deformation_range(r, e, fmax, rules.dr_min)
    deformation = (dr >= lo) & (dr <= hi)
    valid = jnp.all(on_surface & flat & apart & alone & deformation, axis=-1)
    return RuleCheck(on_surface=on_surface, flat=flat, apart=apart, alone=alone, deformation=deformation, valid=valid)
