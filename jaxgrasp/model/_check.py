"""The grasp rules as array code: [`check`][jaxgrasp.check] works on concrete, traced and batched grasps.

[`jaxgrasp.evaluate`][jaxgrasp.evaluate] validates a *concrete* grasp before anything is compiled
(`check_grasp_inputs`), but a grasp built inside the caller's
``jit``/``vmap``/``grad`` is made of tracers whose values are unknown when the code is
traced, so nothing there can raise: a negative friction would be evaluated as given.
[`check`][jaxgrasp.check] states the same rules in ``jax.numpy``, so it runs inside the caller's
trace and returns, per grasp, whether it is valid and the first rule it breaks::

    ok = jaxgrasp.check(grasps)                      # batched, jit or vmap: arrays
    value = jnp.where(ok.valid, result.value, jnp.nan)
    jaxgrasp.check(grasp).raise_if_invalid()         # concrete: a one-line ValueError

The rules and their order are those of `check_grasp_inputs`
(shapes are static and checked at once, with a [`GraspValueError`][jaxgrasp.GraspValueError]).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.model._fields import FIELDS
from jaxgrasp.model._grasp import Grasp
from jaxgrasp.model._units import MAX_CONTACT_DISTANCE, MAX_FINGERTIP_RADIUS
from jaxgrasp.model._validation import (
    COINCIDENT_DISTANCE,
    MAX_COORDINATE,
    MAX_FRICTION,
    MAX_LOAD_RATIO,
    MIN_ENERGY_SCALE,
    NORMAL_MIN_NORM,
    GraspValueError,
)
from jaxgrasp.base import Coded

__all__ = ["check", "GraspCheck", "CheckReason"]


class CheckReason(Coded):
    """The first rule a grasp breaks (`GraspCheck.reason`), in the order checked."""

    OK = 0, "every rule holds"
    NOT_FINITE = 1, "a field holds a NaN or an infinity"
    RADIUS = 2, "radius must be > 0 (m)"
    YOUNG_MODULUS = 3, "young_modulus must be > 0 (Pa)"
    FRICTION = 4, f"friction must be > 0 and at most {MAX_FRICTION:g}"
    MAX_FORCE = 5, "max_force must be > 0 (N)"
    MASS = 6, "mass must be >= 0 (kg)"
    DEFORMATION = 7, "initial_deformation must be in (0, radius) (m)"
    ENERGY_SCALE = 8, f"young_modulus * initial_deformation^3 must be at least {MIN_ENERGY_SCALE:g} J"
    ZERO_NORMAL = 9, f"a normal must be a non-zero vector (norm > {NORMAL_MIN_NORM:g})"
    TOO_FEW_CONTACTS = 10, "at least 2 contacts must be active"
    COINCIDENT = 11, f"two active contacts at the same position (closer than {COINCIDENT_DISTANCE:g} m)"
    OVERLOAD = 12, (
        f"mass * |gravity| must be at most {MAX_LOAD_RATIO:g} times the initial squeeze "
        "(sum of pi * young_modulus * initial_deformation^2 over the active contacts, N)"
    )
    FAR = 13, f"a position's coordinates must be at most {MAX_COORDINATE:g} m from the centre of mass"
    SIZE = 14, (
        f"radius must be at most {MAX_FINGERTIP_RADIUS:g} m and a contact at most {MAX_CONTACT_DISTANCE:g} m from "
        "the centre of mass (larger lengths look like millimetres: write them in metres)"
    )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class GraspCheck:
    """What [`check`][jaxgrasp.check] found, one entry per grasp (``batch`` is the grasp's batch shape,
    ``()`` for one grasp).

    Attributes:
        valid: ``batch`` bool, the grasp breaks no rule.
        reason: ``batch`` int32, the `CheckReason` code of the first rule broken
            (``0``, ``OK``, where valid).
        contact: ``batch`` int32, the first contact that breaks it (``-1`` where valid or
            where the rule is about the whole grasp: mass, gravity, the number of contacts).
    """

    valid: Any
    reason: Any
    contact: Any

    @property
    def reason_names(self) -> np.ndarray:
        """``reason`` as labels (``'ok'``, ``'friction'``, ...): an array of the batch shape, one label
        for one grasp (concrete only)."""
        return CheckReason.names_of(self.reason)

    def raise_if_invalid(self) -> GraspCheck:
        """Raise [`GraspValueError`][jaxgrasp.GraspValueError] (a ``ValueError``) with one line naming
        the first invalid grasp, its rule and contact; return ``self`` where every grasp is
        valid. Needs concrete values (outside ``jit``)."""
        if any(isinstance(x, jax.core.Tracer) for x in (self.valid, self.reason, self.contact)):
            raise GraspValueError("raise_if_invalid needs concrete values: call it outside jit/vmap")
        valid, reason, contact = (np.asarray(x) for x in (self.valid, self.reason, self.contact))
        if valid.all():
            return self
        first = np.unravel_index(int(np.argmin(valid.reshape(-1))), valid.shape)
        where = [f"grasp {first[0] if len(first) == 1 else first}"] if valid.ndim else []
        where += [f"contact {int(contact[first])}"] if int(contact[first]) >= 0 else []
        code = CheckReason(int(reason[first]))
        raise GraspValueError(f"{', '.join(where) or 'grasp'}: {code.message} (rule {code.label!r})")


def _rules(g: Grasp, n: int) -> list:
    """``(CheckReason, bad)`` in the order checked, for fields at their full shapes
    (`_broadcast`): ``bad`` of shape ``batch + (N,)`` for a rule of a contact,
    ``batch`` for one of the whole grasp."""
    f = {name: getattr(g, name) for name in ("initial_deformation", "radius", "young_modulus", "friction", "max_force")}
    pos, nrm, mass, gravity, on = g.positions, g.normals, g.mass, g.gravity, g.active
    finite = jnp.all(jnp.isfinite(pos), -1) & jnp.all(jnp.isfinite(nrm), -1)
    for a in f.values():
        finite &= jnp.isfinite(a)
    grasp_finite = jnp.isfinite(mass) & jnp.all(jnp.isfinite(gravity), -1)
    dr, r, e = f["initial_deformation"], f["radius"], f["young_modulus"]
    peak = jnp.max(jnp.abs(nrm), -1)  # scaled norm: no overflow or underflow (as validation)
    norm = peak * jnp.linalg.norm(nrm / jnp.where(peak > 0, peak, 1.0)[..., None], axis=-1)
    diff = pos[..., :, None, :] - pos[..., None, :, :]
    close = (jnp.sqrt(jnp.sum(diff * diff, -1)) < COINCIDENT_DISTANCE) & on[..., :, None] & on[..., None, :]
    close &= jnp.triu(jnp.ones((n, n), bool), k=1)
    weight = mass * jnp.linalg.norm(gravity, axis=-1)
    squeeze = jnp.sum(jnp.where(on, jnp.pi * e * dr**2, 0.0), -1)
    return [
        (CheckReason.NOT_FINITE, ~finite),
        (CheckReason.NOT_FINITE, ~grasp_finite),  # mass, gravity: a rule of the whole grasp
        (CheckReason.RADIUS, ~(r > 0)),
        (CheckReason.YOUNG_MODULUS, ~(e > 0)),
        (CheckReason.FRICTION, ~((f["friction"] > 0) & (f["friction"] <= MAX_FRICTION))),
        (CheckReason.MAX_FORCE, ~(f["max_force"] > 0)),
        (CheckReason.MASS, ~(mass >= 0)),
        (CheckReason.DEFORMATION, ~((dr > 0) & (dr < r))),
        (CheckReason.ENERGY_SCALE, ~(e * dr**3 >= MIN_ENERGY_SCALE)),
        (CheckReason.ZERO_NORMAL, ~(norm > NORMAL_MIN_NORM)),
        (CheckReason.TOO_FEW_CONTACTS, jnp.sum(on, -1) < 2),
        (CheckReason.COINCIDENT, jnp.any(close, -2)),  # the later contact of the pair
        (CheckReason.OVERLOAD, ~(weight <= MAX_LOAD_RATIO * squeeze)),
        (CheckReason.FAR, ~jnp.all(jnp.abs(pos) <= MAX_COORDINATE, -1)),
        (CheckReason.SIZE, ~((r <= MAX_FINGERTIP_RADIUS) & (jnp.sum(pos * pos, -1) <= MAX_CONTACT_DISTANCE**2))),
    ]


def check(grasp: Grasp) -> GraspCheck:
    """Check ``grasp`` against every rule of valid input, as arrays: usable on concrete
    grasps and inside the caller's ``jax.jit`` and ``jax.vmap``, where nothing can raise.

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] (SI units) of one grasp or a batch (leading
            axes on ``positions`` ``(..., N, 3)``; a field without them is shared by every
            grasp, a per-contact scalar by every contact).

    Returns:
        A `GraspCheck` of arrays of the batch shape: ``valid``, the first broken
        rule's `CheckReason` code and the first contact breaking it. Call
        ``.raise_if_invalid()`` on a concrete result for a one-line ``ValueError``.

    Raises:
        GraspValueError: not a [`Grasp`][jaxgrasp.Grasp], or fields of the wrong shape
            (shapes are static, so this holds under ``jit`` too).
    """
    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"check needs a jaxgrasp.Grasp, got {type(grasp).__name__}")
    shape = tuple(np.shape(grasp.positions))
    if len(shape) < 2 or shape[-1] != 3:
        raise GraspValueError(f"positions must have shape (..., N, 3), got {shape}")
    try:  # fields broadcast to one shape per (batch, N): one compiled check for them all
        return _check_arrays(_broadcast(grasp, shape[:-2], shape[-2]))
    except (ValueError, TypeError) as exc:  # a field that does not broadcast to the grasp's shape
        names = ", ".join(f"{f.name} {tuple(np.shape(getattr(grasp, f.name)))}" for f in FIELDS)
        raise GraspValueError(f"grasp fields do not fit positions {shape}: {names} ({exc})") from None


def _broadcast(g: Grasp, batch: tuple, n: int) -> Grasp:
    """``g`` with every field at its full shape: ``batch + (N,)`` per contact (``active``
    too, all true where ``None``), ``batch`` for the mass, ``batch + (3,)`` for gravity."""
    full = {name: jnp.broadcast_to(jnp.asarray(getattr(g, name)), batch + (n,)) for name in
            ("initial_deformation", "radius", "young_modulus", "friction", "max_force")}
    active = jnp.ones(batch + (n,), bool) if g.active is None else jnp.asarray(g.active, bool)
    return Grasp(
        positions=jnp.asarray(g.positions),
        normals=jnp.broadcast_to(jnp.asarray(g.normals), batch + (n, 3)),
        mass=jnp.broadcast_to(jnp.asarray(g.mass), batch),
        gravity=jnp.broadcast_to(jnp.asarray(g.gravity), batch + (3,)),
        active=jnp.broadcast_to(active, batch + (n,)),
        **full,
    )


@jax.jit
def _check_arrays(grasp: Grasp) -> GraspCheck:
    """[`check`][jaxgrasp.check] after its static checks, one compiled program per shape (the rules are
    some fifty small array operations: run one by one they cost more than the compile)."""
    shape = tuple(np.shape(grasp.positions))
    batch, n = shape[:-2], shape[-2]
    rules = _rules(grasp, n)
    per_contact = [jnp.broadcast_to(bad if bad.ndim > len(batch) else bad[..., None], batch + (n,))
                   for _, bad in rules]
    contact_rule = np.array([bad.ndim > len(batch) for _, bad in rules])
    flags = jnp.stack(per_contact, axis=-2)  # batch + (R, N)
    broken = jnp.any(flags, axis=-1)  # batch + (R,)
    valid = ~jnp.any(broken, axis=-1)
    first = jnp.argmax(broken, axis=-1)
    codes = jnp.asarray([int(code) for code, _ in rules], jnp.int32)
    at = jnp.argmax(jnp.take_along_axis(flags, first[..., None, None], axis=-2)[..., 0, :], axis=-1)
    contact = jnp.where(valid | ~jnp.asarray(contact_rule)[first], -1, at).astype(jnp.int32)
    reason = jnp.where(valid, CheckReason.OK, codes[first]).astype(jnp.int32)
    return GraspCheck(valid=valid, reason=reason, contact=contact)
