"""Input validation for [`jaxgrasp.Grasp`][jaxgrasp.Grasp] (concrete values, SI units).

`check_grasp_inputs` is what [`Grasp.create`][jaxgrasp.Grasp.create] calls. It converts every field to
a float64 NumPy array, broadcasts per-fingertip scalars to one value per contact,
normalises the normals and checks the physical rules. Every failure raises
[`GraspValueError`][jaxgrasp.GraspValueError] with a one-line message naming the field, the offending value
and the rule it breaks.
"""

from __future__ import annotations

import itertools
from typing import Any, Mapping

import jax
import numpy as np

from jaxgrasp.model._fields import FIELD, FIELDS, MAX_CONTACTS, NAMES, PER_CONTACT
from jaxgrasp.model._units import LENGTH_UNITS, MAX_CONTACT_DISTANCE, MAX_FINGERTIP_RADIUS

__all__ = [
    "GraspValueError",
    "check_grasp_inputs",
    "check_batch_inputs",
    "check_corners",
    "MAX_COORDINATE",
    "MONOTONE",
    "format_value",
    "counted",
    "as_float_array",
    "inward_contacts",
]

NORMAL_MIN_NORM = 1e-12
"""A normal shorter than this (absolute) is treated as zero."""

MIN_ENERGY_SCALE = 1e-150
"""Smallest ``young_modulus * initial_deformation**3`` (J) of a contact: the solver scales
energies by the initial elastic energy, which must stay far from float64 underflow."""

COINCIDENT_DISTANCE = 1e-12
"""Two contacts closer than this, m, are at the same position."""

MAX_COORDINATE = 1e3
"""Largest magnitude of a contact position's coordinate (m, centre-of-mass frame), and of a
mesh vertex's (`jaxgrasp.io._mesh`, after its units). The model tells two contacts
apart down to `COINCIDENT_DISTANCE`; float64 numbers near 1e3 are 1.1e-13 apart, fine
enough for that, while near 1e4 they are 1.8e-12 apart, too coarse. A grasped object is at
most a few metres across, so a kilometre leaves room for a frame far from the object."""

MAX_FRICTION = 1e3
"""Largest static friction coefficient accepted. Real materials stay below about 10
(soft rubber on a rough surface: 1-4); past 1e3 the friction cone is a half-space for every
practical purpose, and its linearised edges (length ``mu``, torsion ``mu^2``) swamp the
Ferrari-Canny hull's unit normal forces in float64 ([`jaxgrasp.epsilon`][jaxgrasp.epsilon] fell from
1 to 0 at ``mu = 1e7``)."""

MAX_LOAD_RATIO = 1e4
"""Largest ratio of the object's weight ``mass * |gravity|`` (N) to the fingertips' initial
squeeze, the sum of their initial normal forces ``pi E dr^2`` (N, eq. 4). The evaluator
scales energies by the initial elastic energy, so the weight's pull grows with this ratio
until the equilibrium solve ends where the penalty and rounding leave it: on the cube of
``examples/cube.toml`` (squeeze 15 N) a single grasp and the same grasp in a batch agreed
on status and equilibrium (to 1e-15 m) up to a ratio of 2e4 and disagreed from 6.5e4
(issue 40). No grip holds an object ten thousand times heavier than it squeezes (the
paper's heavy examples are below 10), so such a grasp is rejected."""

MONOTONE: tuple[str, ...] = (*PER_CONTACT, "mass")
"""Fields in each of which every rule of `check_grasp_inputs` is monotone, so that a
box of their values is valid where its corners are (`check_corners`)."""

_UNIT_TOLERANCE = 1e-14
"""Normals within this of unit length are kept bit for bit (so validation is idempotent
and a saved grasp loads back exactly); longer or shorter ones are divided by their norm."""


class GraspValueError(ValueError):
    """A grasp input is malformed or physically invalid; the message is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def format_value(value: Any) -> str:
    """Compact one-line text of a number or array: ``0.03``, ``-5``, ``[0, 0, 0]``, ``nan``."""
    arr = np.asarray(value)
    if arr.ndim == 0:
        x = float(arr)
        text = repr(x)
        if text.endswith(".0"):
            text = text[:-2]
        return text
    return "[" + ", ".join(format_value(v) for v in arr) + "]"


def counted(n: int, noun: str) -> str:
    """``"1 point"``, ``"2 points"``: a count with its noun, singular for one."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _with_unit(text: str, field: str) -> str:
    unit = FIELD[field].unit if field in FIELD else ""
    return f"{text} {unit}" if unit else text


def _is_tracer(value: Any) -> bool:
    try:
        leaves = jax.tree_util.tree_leaves(value)
    except Exception:  # pragma: no cover - exotic containers
        return False
    return any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def as_float_array(name: str, value: Any) -> np.ndarray:
    """Convert to float64, rejecting non-numeric, boolean, complex and ragged input."""
    try:
        raw = np.asarray(value)
    except (ValueError, TypeError, OverflowError) as exc:
        raise GraspValueError(
            f"{name} must be a number or an array of numbers, got {type(value).__name__} "
            f"that NumPy cannot convert ({exc})"
        ) from None
    kind = raw.dtype.kind
    if kind == "b":
        raise GraspValueError(f"{name} = {_short(value)} must be numeric, not boolean")
    if kind not in "iuf":
        raise GraspValueError(
            f"{name} = {_short(value)} must be a number or an array of numbers "
            f"(got dtype {raw.dtype}, shape {raw.shape})"
        )
    try:
        return np.array(raw, dtype=np.float64)
    except (ValueError, TypeError, OverflowError) as exc:  # pragma: no cover
        raise GraspValueError(f"{name} cannot be converted to float64: {exc}") from None


def _short(value: Any, limit: int = 60) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _check_finite(name: str, arr: np.ndarray) -> None:
    if np.all(np.isfinite(arr)):
        return
    if arr.ndim == 0:
        raise GraspValueError(f"{name} = {_with_unit(format_value(arr), name)} must be finite")
    bad = np.argwhere(~np.isfinite(arr))[0]
    row = int(bad[0])
    raise GraspValueError(
        f"{name}[{row}] = {_with_unit(format_value(arr[row]), name)} must be finite"
    )


def _index_name(name: str, original_ndim: int, i: int) -> str:
    return f"{name}[{i}]" if original_ndim > 0 else name


def check_grasp_inputs(**given) -> dict[str, np.ndarray]:
    """Validate and normalise the fields of one grasp (concrete values only).

    Keyword arguments are the [`Grasp`][jaxgrasp.Grasp] fields by name, with the units, shapes and
    ranges of `jaxgrasp.model.FIELDS`: ``positions`` ``(N, 3)`` m, each coordinate at
    most `MAX_COORDINATE` in magnitude and at most `MAX_CONTACT_DISTANCE` from the
    origin (the centre of mass); ``normals``
    ``(N, 3)`` (any non-zero length); ``initial_deformation`` m in ``(0, radius)``,
    ``radius`` m (at most `MAX_FINGERTIP_RADIUS`), ``young_modulus`` Pa, ``friction``, ``max_force`` N, each a scalar or
    ``(N,)`` and ``> 0``, friction at most `MAX_FRICTION`; ``mass`` kg ``>= 0`` and
    ``gravity`` ``(3,)`` m/s^2 may be left out (defaults ``0`` and ``(0, 0, -9.81)``), the
    weight at most `MAX_LOAD_RATIO` times the initial squeeze; ``active``, optional, ``None`` or ``(N,)``
    bool with at least 2 true (every contact, active or not, must hold valid values).

    Returns:
        A dict with exactly the [`Grasp`][jaxgrasp.Grasp] field names: float64 arrays, per-fingertip
        fields broadcast to ``(N,)``, normals of unit length; plus ``active`` (a bool
        array) where a mask was given.

    Raises:
        GraspValueError: a field is unknown, missing, not numeric, has the wrong shape, is
            not finite or breaks a physical rule (a radius or a position too large for a
            fingertip grasp: lengths written in mm, named as such); or a value is a JAX tracer (use
            ``Grasp(...)`` or ``grasp.replace(...)`` inside ``jit``).
    """
    active = given.pop("active", None)
    unknown = sorted(set(given) - set(NAMES))
    if unknown:
        raise GraspValueError(f"unknown grasp field {unknown[0]!r}; the fields are {', '.join(NAMES)}")
    missing = [f.name for f in FIELDS if f.name not in given and f.default is None]
    if missing:
        raise GraspValueError(f"grasp field {missing[0]!r} is missing")
    given = {f.name: given.get(f.name, f.default) for f in FIELDS}
    _reject_tracers(given)
    arrs = {name: as_float_array(name, value) for name, value in given.items()}
    n = _check_shapes(arrs)
    for name in NAMES:
        _check_finite(name, arrs[name])
    _check_ranges(arrs)
    _check_friction(arrs)
    out = {name: np.array(np.broadcast_to(arrs[name], (n,)), dtype=np.float64) for name in PER_CONTACT}
    _check_deformation(out, arrs)
    out["normals"] = _unit_normals(arrs["normals"])
    mask = _check_active(active, n)
    _check_distinct(arrs["positions"] if mask is None else arrs["positions"][mask])
    _check_load(out, arrs, mask)
    _check_reach(arrs["positions"])
    _check_size(arrs)
    out.update(positions=arrs["positions"], mass=arrs["mass"], gravity=arrs["gravity"])
    checked = {name: out[name] for name in NAMES}
    return checked if mask is None else {**checked, "active": mask}


def check_batch_inputs(fields: dict[str, np.ndarray], skip=()) -> None:
    """Validate every grasp of batched fields (each with a leading axis ``B``, e.g.
    [`Grasp.to_numpy_batch`][jaxgrasp.Grasp.to_numpy_batch]) with `check_grasp_inputs`, except rows ``skip``.

    Raises:
        GraspValueError: ``grasp i: ...`` naming the first invalid grasp (one line).
    """
    skip = set(int(i) for i in skip)
    for i in range(len(fields["positions"])):
        if i in skip:
            continue
        try:
            check_grasp_inputs(**{k: v[i] for k, v in fields.items()})
        except GraspValueError as exc:
            raise GraspValueError(f"grasp {i}: {exc}") from None


def check_corners(fields: Mapping[str, Any], ends: Mapping[str, tuple[Any, Any]], where: str) -> None:
    """Validate with `check_grasp_inputs` the grasp ``fields`` at every corner of the
    box ``ends``: each field of ``ends`` at its lower or at its upper end, at every contact.

    Every point of the box is then valid too, because every rule is monotone in each field
    of `MONOTONE`, in the same direction at every contact: a range rule (``> 0``,
    ``>= 0``) breaks first at the lower end, ``friction <= MAX_FRICTION`` at the upper one,
    ``initial_deformation < radius`` at the upper deformation and the lower radius,
    ``radius <= MAX_FINGERTIP_RADIUS`` at the upper radius,
    ``E dr^3 >= MIN_ENERGY_SCALE`` at the lower modulus and deformation, and the load rule
    ``mass |g| <= MAX_LOAD_RATIO sum pi E dr^2`` at the upper mass and the lower modulus
    and deformation (products and sums of non-negative floats keep that order: rounding
    is monotone). So a point that breaks a rule has a corner that breaks it too: move each
    field to the end where that rule is hardest. The other rules (shapes, finite values,
    normals, distinct positions, ``active``) do not depend on these fields.

    Args:
        fields: the grasp's fields by name, as `check_grasp_inputs` takes them (SI).
        ends: field of `MONOTONE` -> ``(lo, hi)``: scalars or per-contact ``(N,)``
            arrays in its unit (m, Pa, dimensionless, N; ``mass`` kg); every value finite.
            ``2^k`` corners for ``k`` fields, fewer where ``lo`` equals ``hi``.
        where: what a corner is, for the message: ``"sweep grid point"``.

    Raises:
        GraspValueError: ``WHERE (name = value unit, ...): RULE``, one line, at the first
            corner (in the order of ``ends``, lower ends first) that breaks a rule.
    """
    names = list(ends)
    odd = [name for name in names if name not in MONOTONE]
    if odd:  # a caller's mistake, not the user's
        raise ValueError(f"check_corners: {odd[0]!r} is not one of {MONOTONE}")
    choices = [[lo] if np.array_equal(lo, hi) else [lo, hi] for lo, hi in ends.values()]
    for corner in itertools.product(*choices):
        at = dict(zip(names, corner))
        try:
            check_grasp_inputs(**{**fields, **at})
        except GraspValueError as exc:
            point = ", ".join(f"{name} = {_with_unit(format_value(v), name)}" for name, v in at.items())
            raise GraspValueError(f"{where} ({point}): {exc}") from None


def _check_active(active, n: int) -> np.ndarray | None:
    """The contact mask as an ``(N,)`` bool array with at least 2 true, or ``None``."""
    if active is None:
        return None
    if _is_tracer(active):
        raise GraspValueError("active is a JAX tracer: Grasp.create needs concrete values")
    a = np.asarray(active)
    if a.dtype != np.bool_:
        raise GraspValueError(f"active must be booleans (one per contact), got {_short(active)}")
    if a.shape != (n,):
        raise GraspValueError(f"active must have shape ({n},), one per contact, got {a.shape}")
    if int(a.sum()) < 2:
        raise GraspValueError(f"active must mark at least 2 contacts, got {int(a.sum())}")
    return a.copy()


def _reject_tracers(given: dict) -> None:
    for name, value in given.items():
        if _is_tracer(value):
            raise GraspValueError(
                f"{name} is a JAX tracer: Grasp.create needs concrete values; inside "
                "jit/vmap/grad build the grasp with Grasp(...) directly or use "
                "grasp.replace(...) on a grasp created outside"
            )


def _check_shapes(arrs: dict) -> int:
    """Check every field's shape against the table; returns the number of contacts ``N``."""
    pos = arrs["positions"]
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise GraspValueError(f"positions must have shape (N, 3), got shape {pos.shape}")
    n = pos.shape[0]
    if n < 2:
        raise GraspValueError(f"need at least 2 contacts, got {n}")
    if n > MAX_CONTACTS:
        raise GraspValueError(
            f"{n} contacts, more than the {MAX_CONTACTS} one grasp may have (an evaluation's time grows "
            "faster than N^2 in its N contacts: 32 take seconds, 300 tens of minutes or more)"
        )
    for field in FIELDS:
        shape = arrs[field.name].shape
        if field.shape == "directions" and shape != (n, 3):
            raise GraspValueError(
                f"{field.name} must have shape ({n}, 3) like positions, got shape {shape}"
            )
        if field.shape == "per_contact" and shape not in ((), (n,)):
            raise GraspValueError(
                f"{field.name} must be a scalar or have shape ({n},) (one per contact), "
                f"got shape {shape}"
            )
        if field.shape == "scalar" and shape != ():
            raise GraspValueError(f"{field.name} must be a scalar, got shape {shape}")
        if field.shape == "vector" and shape != (3,):
            raise GraspValueError(f"{field.name} must have shape (3,), got shape {shape}")
    return n


def _check_ranges(arrs: dict) -> None:
    """Each field with a minimum respects it (`Field.rule`)."""
    for field in FIELDS:
        if field.minimum is None or field.name == "initial_deformation":
            continue  # the deformation's range depends on the radius: _check_deformation
        a = arrs[field.name]
        flat = np.atleast_1d(a)
        bad = np.flatnonzero(~field.allows(flat))
        if bad.size:
            i = int(bad[0])
            label = _index_name(field.name, a.ndim, i)
            raise GraspValueError(
                f"{label} = {_with_unit(format_value(flat[i]), field.name)} must be {field.rule} and finite"
            )


def _check_friction(arrs: dict) -> None:
    """``friction <= MAX_FRICTION`` (its ``> 0`` is a range rule of the table)."""
    a = arrs["friction"]
    flat = np.atleast_1d(a)
    bad = np.flatnonzero(flat > MAX_FRICTION)
    if bad.size:
        label = _index_name("friction", a.ndim, int(bad[0]))
        raise GraspValueError(
            f"{label} = {format_value(flat[int(bad[0])])} must be at most {MAX_FRICTION:g} "
            "(static friction coefficients of real materials stay below about 10)"
        )


def _check_reach(pos: np.ndarray) -> None:
    """Every contact (active or not) within `MAX_COORDINATE` m of the centre of mass
    along each axis."""
    far = np.flatnonzero(np.any(np.abs(pos) > MAX_COORDINATE, axis=-1))
    if far.size:
        i = int(far[0])
        raise GraspValueError(
            f"positions[{i}] = {format_value(pos[i])} m: a coordinate beyond {MAX_COORDINATE:g} m from the centre "
            f"of mass (past it float64 no longer resolves contacts {COINCIDENT_DISTANCE:g} m apart); "
            f"if it is in mm, write it in metres: {format_value(pos[i] * LENGTH_UNITS['mm'])}"
        )


def _check_size(arrs: dict) -> None:
    """Every radius at most `MAX_FINGERTIP_RADIUS`, every contact (active or not) within
    `MAX_CONTACT_DISTANCE` of the centre of mass: larger ones are lengths in mm."""
    radius = arrs["radius"]
    flat = np.atleast_1d(radius)
    big = np.flatnonzero(~(flat <= MAX_FINGERTIP_RADIUS))
    if big.size:
        i = int(big[0])
        label = _index_name("radius", radius.ndim, i)
        raise GraspValueError(
            f"{label} = {format_value(flat[i])} m is larger than any fingertip (at most {MAX_FINGERTIP_RADIUS:g} m): "
            f"the grasp's lengths look like millimetres; write every length in metres ({label} = "
            f"{format_value(flat[i] * LENGTH_UNITS['mm'])}; positions and initial_deformation likewise)"
        )
    pos = arrs["positions"]
    with np.errstate(over="ignore"):
        dist = np.sqrt(np.sum(pos * pos, axis=-1))
    far = np.flatnonzero(~(dist <= MAX_CONTACT_DISTANCE))
    if far.size:
        i = int(far[0])
        raise GraspValueError(
            f"positions[{i}] = {format_value(pos[i])} m is {dist[i]:.4g} m from the centre of mass, farther than a "
            f"fingertip grasp reaches (at most {MAX_CONTACT_DISTANCE:g} m): the positions look like millimetres; "
            f"write them in metres ({format_value(pos[i] * LENGTH_UNITS['mm'])})"
        )


def _check_load(out: dict, arrs: dict, mask) -> None:
    """The weight at most `MAX_LOAD_RATIO` times the active fingertips' initial
    squeeze ``sum pi E dr^2`` (N)."""
    on = np.ones(out["radius"].shape, bool) if mask is None else mask
    with np.errstate(over="ignore", under="ignore"):
        weight = float(arrs["mass"]) * float(np.linalg.norm(arrs["gravity"]))
        squeeze = float(np.sum((np.pi * out["young_modulus"] * out["initial_deformation"] ** 2)[on]))
    if weight > MAX_LOAD_RATIO * squeeze:
        raise GraspValueError(
            f"mass * |gravity| = {weight:.4g} N is more than {MAX_LOAD_RATIO:g} times the fingertips' initial "
            f"squeeze (sum of pi * young_modulus * initial_deformation^2 = {squeeze:.4g} N): no grip holds it, "
            "and the evaluation would be too ill-conditioned to trust"
        )


def _check_deformation(out: dict, arrs: dict) -> None:
    """``0 < initial_deformation < radius`` at every contact, and an initial elastic energy
    ``E dr^3`` far from float64 underflow (the solver divides by it)."""
    dr_n, radius_n, e_n = out["initial_deformation"], out["radius"], out["young_modulus"]
    for i in range(dr_n.shape[0]):
        if not (0 < dr_n[i] < radius_n[i]):
            label = _index_name("initial_deformation", arrs["initial_deformation"].ndim, i)
            rlabel = _index_name("radius", arrs["radius"].ndim, i)
            raise GraspValueError(
                f"{label} = {format_value(dr_n[i])} m must be in "
                f"(0, {rlabel} = {format_value(radius_n[i])} m)" + _mm_deformation(dr_n[i], radius_n[i])
            )
    with np.errstate(under="ignore", over="ignore"):
        energy = e_n * dr_n**3
    for i in range(dr_n.shape[0]):
        if not energy[i] >= MIN_ENERGY_SCALE:
            raise GraspValueError(
                f"contact {i}: young_modulus * initial_deformation^3 = "
                f"{format_value(e_n[i])} Pa * ({format_value(dr_n[i])} m)^3 is below "
                f"{MIN_ENERGY_SCALE:g} J, too small to evaluate in floating point"
            )


def _mm_deformation(dr: float, radius: float) -> str:
    """The fix of a deformation beyond the radius that is one in mm (``2`` for 2 mm: more
    than any fingertip's radius, `MAX_FINGERTIP_RADIUS`, but below this one's in mm),
    else ``""``."""
    in_m = dr * LENGTH_UNITS["mm"]
    if dr > MAX_FINGERTIP_RADIUS and in_m < radius:
        return f": it looks like millimetres; write it in metres ({format_value(in_m)})"
    return ""


def _unit_normals(nrm: np.ndarray) -> np.ndarray:
    """Normals divided by their norm (kept bit for bit within `_UNIT_TOLERANCE`)."""
    # scaled norm: no overflow for huge components, no underflow for tiny ones
    peak = np.max(np.abs(nrm), axis=1)
    safe = np.where(peak > 0, peak, 1.0)
    norms = peak * np.linalg.norm(nrm / safe[:, None], axis=1)
    for i in range(nrm.shape[0]):
        if not norms[i] > NORMAL_MIN_NORM:
            raise GraspValueError(
                f"normals[{i}] = {format_value(nrm[i])} must be a non-zero vector "
                f"(norm > {NORMAL_MIN_NORM:g})"
            )
    unit = nrm.copy()
    rescale = np.abs(norms - 1.0) > _UNIT_TOLERANCE
    unit[rescale] = (nrm[rescale] / peak[rescale, None]) / (norms[rescale] / peak[rescale])[:, None]
    return unit


def inward_contacts(positions, normals) -> list[int]:
    """Contacts whose normal does not point away from the centre of mass: ``n_i . c_i <= 0``.

    Args:
        positions: ``(N, 3)`` contact positions ``c_i``, m, object frame (origin at the
            centre of mass).
        normals: ``(N, 3)`` surface normals ``n_i`` (any length).

    Returns:
        The 0-based indices, in order (``[]`` for a grasp of a convex object from outside,
        where every outward normal points away from the centre of mass).

    Such normals are valid input, not an error: on a non-convex or hollow object the
    outward normal can point towards the centre of mass (an inside grip on the walls of a
    cavity or ring, a pinch of a rim), and the model needs nothing else. But a normal
    flipped by mistake reads the same way, so the command line names these contacts.
    """
    c = np.asarray(positions, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    return [int(i) for i in np.flatnonzero(~(np.einsum("ij,ij->i", n, c) > 0.0))]


def _check_distinct(pos: np.ndarray) -> None:
    with np.errstate(over="ignore", invalid="ignore"):
        diff = pos[:, None, :] - pos[None, :, :]
        dist = np.sqrt(np.sum(diff * diff, axis=-1))
    close = np.argwhere(np.triu(dist < COINCIDENT_DISTANCE, k=1))
    if close.size:
        i, j = (int(k) for k in close[0])
        raise GraspValueError(
            f"positions[{i}] = positions[{j}] = {format_value(pos[i])} m: two contacts at the "
            f"same position (distance < {COINCIDENT_DISTANCE:g} m)"
        )
