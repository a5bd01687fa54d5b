"""What is uncertain about a grasp, and the perturbed copies of it that [`jaxgrasp.robust`][jaxgrasp.robust] evaluates.

[`Uncertainty`][jaxgrasp.analysis.Uncertainty] names each source and its spread (SI units); [`parse_spec`][jaxgrasp.analysis.parse_spec]
reads it from one line (``friction=0.1,position=1e-3``); `draw_normals` draws the
standard normals of every sample and `perturb` applies them to the fields of a
batch of grasps, clipping each sampled number into the field's valid range and counting
the clipped ones.

The draws depend only on the seed, the source and the contact's index (one NumPy
``PCG64`` stream for each, seeded with ``[seed, source, contact]``), never on the grasp,
the other grasps of a list, their contact count or the chunking: every grasp of a list
sees the same draws (common random numbers, so that comparing two grasps' robust values
is not blurred by different noise), and a run with twice the samples begins with the
samples of the first.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from jaxgrasp.analysis._epsilon import tangent_basis
from jaxgrasp.model import MAX_FRICTION, MAX_LOAD_RATIO, GraspValueError, format_value

__all__ = [
    "Uncertainty",
    "SOURCES",
    "CLIP_SOURCES",
    "MAX_RELATIVE_SPREAD",
    "DEFORMATION_MARGIN",
    "parse_spec",
    "draw_normals",
    "perturb",
]

SOURCES: tuple[str, ...] = (
    "friction",
    "friction_per_fingertip",
    "young_modulus",
    "initial_deformation",
    "position",
    "mass",
    "gravity_angle",
)
"""The sources of [`Uncertainty`][jaxgrasp.analysis.Uncertainty], in the order of its fields (and of a spec)."""

CLIP_SOURCES: tuple[str, ...] = ("friction", "initial_deformation", "mass")
"""The fields whose samples can leave their valid range, so are clipped and counted."""

_UNITS = {"initial_deformation": "m", "position": "m", "gravity_angle": "rad"}  # the others are relative

_STREAM = {name: i for i, name in enumerate(SOURCES)}  # the source's number in the seed of its stream

_DRAWS = {  # standard normals per sample: (per contact?, how many)
    "friction": (False, 1),
    "friction_per_fingertip": (True, 1),
    "young_modulus": (True, 1),
    "initial_deformation": (True, 1),
    "position": (True, 2),
    "mass": (False, 1),
    "gravity_angle": (False, 2),
}

MAX_RELATIVE_SPREAD = 3.0
"""Largest relative spread ``s``: a factor ``exp(s z)`` with ``|z| <= 3`` already ranges from
``1e-4`` to ``1e4`` at ``s = 3``."""

DEFORMATION_MARGIN = 1e-3
"""A sampled initial deformation is clipped into ``[DEFORMATION_MARGIN r, (1 - DEFORMATION_MARGIN) r]``
(``r`` the fingertip radius; widened to include the nominal value), inside the valid ``(0, r)``."""


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """The spread of each uncertain quantity of a grasp (SI units; 0: that source is exact).

    Each sample ``k`` of [`jaxgrasp.robust`][jaxgrasp.robust] draws independent standard normals ``z``
    (per sample, or per sample and fingertip) and builds a perturbed copy of the grasp:

    Attributes:
        friction: relative, one factor per sample shared by every fingertip: each
            fingertip's friction is multiplied by ``exp(friction * z)``.
        friction_per_fingertip: relative, one factor per sample and fingertip: friction
            ``i`` is multiplied by ``exp(friction_per_fingertip * z_i)`` as well. The
            friction is then clipped to at most ``MAX_FRICTION`` (1e3; counted).
        young_modulus: relative, per fingertip: ``E_i exp(young_modulus * z_i)``.
        initial_deformation: absolute, m, per fingertip: ``dr_i + initial_deformation * z_i``,
            clipped into ``[1e-3 r_i, (1 - 1e-3) r_i]`` (`DEFORMATION_MARGIN`; the
            interval widened to hold the nominal ``dr_i``; counted).
        position: absolute, m, per contact, tangential: the contact moves by
            ``position * (z_1 t_1 + z_2 t_2)`` in its tangent plane (``t_1, t_2`` an
            orthonormal basis of the plane orthogonal to the normal, so each tangential
            coordinate has standard deviation ``position`` and the move's length a Rayleigh
            distribution); the normal is unchanged. For a [`MeshGrasp`][jaxgrasp.MeshGrasp] the
            moved point is projected back onto the mesh (the closest surface point) and
            takes the surface's normal there.
        mass: relative: ``m exp(mass * z)``; where the weight would exceed
            ``MAX_LOAD_RATIO`` (1e4) times the sample's initial squeeze, the mass is clipped
            to that limit (counted).
        gravity_angle: rad: the gravity vector is turned by the angle ``|v|`` towards
            ``v / |v|``, where ``v = gravity_angle * (z_1 e_1 + z_2 e_2)`` and ``e_1, e_2``
            are orthonormal and orthogonal to gravity (each tilt coordinate has standard
            deviation ``gravity_angle``); its magnitude is unchanged.

    Relative spreads are at most `MAX_RELATIVE_SPREAD`, angles at most ``pi``; every
    spread is finite and ``>= 0``.

    Raises:
        GraspValueError: a spread that breaks these rules; the message names it.
    """

    friction: float = 0.0
    friction_per_fingertip: float = 0.0
    young_modulus: float = 0.0
    initial_deformation: float = 0.0
    position: float = 0.0
    mass: float = 0.0
    gravity_angle: float = 0.0

    def __post_init__(self):
        for name in SOURCES:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise GraspValueError(f"Uncertainty {name} must be a number, got {value!r}")
            x = float(value)
            limit = math.pi if name == "gravity_angle" else (math.inf if name in _UNITS else MAX_RELATIVE_SPREAD)
            if not (math.isfinite(x) and 0.0 <= x <= limit):
                rule = f"in [0, {limit:g}]" if math.isfinite(limit) else ">= 0 and finite"
                unit = f" {_UNITS[name]}" if name in _UNITS else ""
                raise GraspValueError(f"Uncertainty {name} = {format_value(x)}{unit} must be {rule}")
            object.__setattr__(self, name, x)

    @property
    def active(self) -> tuple[str, ...]:
        """The sources with a non-zero spread."""
        return tuple(name for name in SOURCES if getattr(self, name) > 0.0)

    def to_dict(self) -> dict[str, float]:
        """Every spread by name (SI units)."""
        return {name: getattr(self, name) for name in SOURCES}

    def to_spec(self) -> str:
        """The one-line spec of the non-zero spreads ([`parse_spec`][jaxgrasp.analysis.parse_spec] reads it back)."""
        return ",".join(f"{name}={getattr(self, name)!r}" for name in self.active) or "none"


def parse_spec(spec: str) -> Uncertainty:
    """An [`Uncertainty`][jaxgrasp.analysis.Uncertainty] from one line ``name=value,name=value`` (SI units), e.g.
    ``friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3``; the names
    are `SOURCES` (``-`` may stand for ``_``); ``none`` is no uncertainty.

    Raises:
        GraspValueError: one line naming the part that is wrong.
    """
    text = str(spec).strip()
    if text.lower() == "none":
        return Uncertainty()
    given: dict[str, float] = {}
    for part in text.split(","):
        name, eq, value = (s.strip() for s in part.partition("="))
        name = name.replace("-", "_")
        if not eq or not name or not value:
            raise GraspValueError(f"uncertainty spec {text!r}: {part.strip()!r} is not name=value")
        if name not in SOURCES:
            raise GraspValueError(f"uncertainty spec: unknown source {name!r}; the sources are {', '.join(SOURCES)}")
        if name in given:
            raise GraspValueError(f"uncertainty spec: {name} is given twice")
        try:
            given[name] = float(value)
        except ValueError:
            raise GraspValueError(f"uncertainty spec: {name} = {value!r} is not a number") from None
    return Uncertainty(**given)


def draw_normals(uncertainty: Uncertainty, samples: int, seed: int, n_contacts: int) -> dict[str, np.ndarray]:
    """The standard normals of ``samples`` samples for each active source: ``(S, k)`` for
    a per-grasp source, ``(S, N, k)`` for a per-contact one (``k`` of `_DRAWS`).
    Contact ``j``'s draws come from the stream ``[seed, source, j]``, so they do not depend
    on ``n_contacts``, and the first ``S`` samples do not depend on ``samples``."""
    out = {}
    for name in uncertainty.active:
        per_contact, k = _DRAWS[name]
        streams = range(n_contacts) if per_contact else [0]
        cols = [np.random.default_rng([seed, _STREAM[name], j]).standard_normal((samples, k)) for j in streams]
        out[name] = np.stack(cols, axis=1) if per_contact else cols[0]
    return out


def perturb(fields: dict[str, np.ndarray], uncertainty: Uncertainty, z: dict[str, np.ndarray], samples: int,
            project=None) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Perturbed copies of ``G`` grasps: each field ``(G, ...)`` becomes ``(G * S, ...)``,
    grasp ``g``'s sample ``k`` in row ``g * S + k`` (``active``, where present, repeated).

    Args:
        fields: the grasps' fields ([`to_numpy_batch`][jaxgrasp.Grasp.to_numpy_batch]), SI units.
        uncertainty: the spreads.
        z: `draw_normals` for this contact count and ``samples``.
        samples: ``S``, the copies of each grasp.
        project: ``None``, or ``project(positions) -> (positions, normals)`` that puts
            moved contacts ``(G, S, N, 3)`` back onto the grasps' surfaces (mesh grasps).

    Returns:
        ``(fields, clipped)``: the perturbed fields, and for each of `CLIP_SOURCES`
        the ``(G,)`` count of sampled numbers clipped into their valid range.
    """
    g = fields["positions"].shape[0]
    s = int(samples)
    rows = {k: np.repeat(v[:, None], s, axis=1) for k, v in fields.items()}  # (G, S, ...)
    clipped = {name: np.zeros(g, dtype=np.int64) for name in CLIP_SOURCES}
    _friction(rows, uncertainty, z, clipped)
    if "young_modulus" in z:
        rows["young_modulus"] = rows["young_modulus"] * np.exp(uncertainty.young_modulus * z["young_modulus"][..., 0])
    if "initial_deformation" in z:
        _deformation(rows, uncertainty.initial_deformation * z["initial_deformation"][..., 0], clipped)
    if "position" in z:
        _position(rows, uncertainty.position * z["position"], project)
    if "gravity_angle" in z:
        rows["gravity"] = _tilt(rows["gravity"], uncertainty.gravity_angle * z["gravity_angle"])
    if "mass" in z:
        rows["mass"] = rows["mass"] * np.exp(uncertainty.mass * z["mass"][:, 0])
    _load_limit(rows, clipped)
    return {k: v.reshape(g * s, *v.shape[2:]) for k, v in rows.items()}, clipped


def _friction(rows: dict, u: Uncertainty, z: dict, clipped: dict) -> None:
    """Friction times ``exp(s z)`` (shared) and ``exp(s_f z_i)`` (each), at most ``MAX_FRICTION``."""
    log = 0.0
    if "friction" in z:
        log = log + u.friction * z["friction"]  # (S, 1): every contact
    if "friction_per_fingertip" in z:
        log = log + u.friction_per_fingertip * z["friction_per_fingertip"][..., 0]  # (S, N)
    if isinstance(log, float):
        return
    mu = rows["friction"] * np.exp(log)
    over = mu > MAX_FRICTION
    clipped["friction"] += _count(over, rows)
    rows["friction"] = np.where(over, MAX_FRICTION, mu)


def _count(flags: np.ndarray, rows: dict) -> np.ndarray:
    """``(G,)``: the flags ``(G, S, N)`` set at active contacts, per grasp."""
    if "active" in rows:
        flags = flags & rows["active"]
    return flags.reshape(flags.shape[0], -1).sum(axis=1)


def _deformation(rows: dict, shift: np.ndarray, clipped: dict) -> None:
    """``dr + shift`` clipped into ``[m r, (1 - m) r]`` widened to hold the nominal ``dr``."""
    dr, r = rows["initial_deformation"], rows["radius"]
    lo = np.minimum(DEFORMATION_MARGIN * r, dr)
    hi = np.maximum((1.0 - DEFORMATION_MARGIN) * r, dr)
    moved = dr + shift
    out = (moved < lo) | (moved > hi)
    clipped["initial_deformation"] += _count(out, rows)
    rows["initial_deformation"] = np.clip(moved, lo, hi)


def _position(rows: dict, offsets: np.ndarray, project) -> None:
    """Each contact moved by ``offsets[..., 0] t_1 + offsets[..., 1] t_2`` in its tangent
    plane (``offsets (S, N, 2)``, m); onto the surface by ``project`` where given."""
    n = rows["normals"][:, 0]  # (G, N, 3): the nominal normals
    t1, t2 = tangent_basis(n.reshape(-1, 3))
    t1, t2 = t1.reshape(n.shape), t2.reshape(n.shape)
    moved = rows["positions"] + offsets[None, ..., :1] * t1[:, None] + offsets[None, ..., 1:] * t2[:, None]
    if project is None:
        rows["positions"] = moved
    else:
        rows["positions"], rows["normals"] = project(moved)


def _tilt(gravity: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Gravity ``(G, S, 3)`` turned by ``|v|`` towards ``v`` (``v (S, 2)``, rad, in a basis
    orthogonal to gravity); the magnitude kept."""
    size = np.linalg.norm(gravity, axis=-1, keepdims=True)
    down = gravity / np.where(size > 0, size, 1.0)
    e1, e2 = tangent_basis(down.reshape(-1, 3))
    e1, e2 = e1.reshape(down.shape), e2.reshape(down.shape)
    angle = np.linalg.norm(v, axis=-1)[None, :, None]
    way = v / np.where(angle[0] > 0, angle[0], 1.0)
    towards = way[None, :, :1] * e1 + way[None, :, 1:] * e2
    return size * (np.cos(angle) * down + np.sin(angle) * towards)


def _load_limit(rows: dict, clipped: dict) -> None:
    """The mass clipped where the weight exceeds ``MAX_LOAD_RATIO`` times the squeeze
    ``sum pi E dr^2`` of the active contacts."""
    on = rows["active"] if "active" in rows else np.ones(rows["radius"].shape, bool)
    squeeze = np.sum(np.where(on, np.pi * rows["young_modulus"] * rows["initial_deformation"] ** 2, 0.0), axis=-1)
    g = np.linalg.norm(rows["gravity"], axis=-1)
    limit = MAX_LOAD_RATIO * squeeze / np.where(g > 0, g, 1.0) * (1.0 - 1e-12)
    over = (rows["mass"] * g > MAX_LOAD_RATIO * squeeze) & (g > 0)
    clipped["mass"] += over.sum(axis=1)
    rows["mass"] = np.where(over, limit, rows["mass"])
