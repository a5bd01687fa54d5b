"""Input validation for :class:`jaxgrasp.grasp.Grasp` (concrete values, SI units).

:func:`check_grasp_inputs` is what :meth:`Grasp.create` calls. It converts every field to
a float64 NumPy array, broadcasts per-fingertip scalars to one value per contact,
normalises the normals and checks the physical rules. Every failure raises
:class:`GraspValueError` with a one-line message naming the field, the offending value
and the rule it breaks.
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np

__all__ = ["GraspValueError", "check_grasp_inputs", "format_value"]

PER_FINGERTIP = ("initial_deformation", "radius", "young_modulus", "friction", "max_force")
"""Fields with one value per contact (a scalar is broadcast to every contact)."""

FIELDS = (
    "positions",
    "normals",
    "initial_deformation",
    "radius",
    "young_modulus",
    "friction",
    "max_force",
    "mass",
    "gravity",
)
"""The :class:`Grasp` field names, in order."""

UNITS = {
    "positions": "m",
    "normals": "",
    "initial_deformation": "m",
    "radius": "m",
    "young_modulus": "Pa",
    "friction": "",
    "max_force": "N",
    "mass": "kg",
    "gravity": "m/s^2",
}
"""SI unit of each field (empty: dimensionless)."""

NORMAL_MIN_NORM = 1e-12
"""A normal shorter than this (absolute) is treated as zero."""

MIN_ENERGY_SCALE = 1e-150
"""Smallest ``young_modulus * initial_deformation**3`` (J) of a contact: the solver scales
energies by the initial elastic energy, which must stay far from float64 underflow."""

COINCIDENT_DISTANCE = 1e-12
"""Two contacts closer than this, m, are at the same position."""

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


def _with_unit(text: str, field: str) -> str:
    unit = UNITS.get(field, "")
    return f"{text} {unit}" if unit else text


def _is_tracer(value: Any) -> bool:
    try:
        leaves = jax.tree_util.tree_leaves(value)
    except Exception:  # pragma: no cover - exotic containers
        return False
    return any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def _as_float_array(name: str, value: Any) -> np.ndarray:
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


def check_grasp_inputs(
    *,
    positions,
    normals,
    initial_deformation,
    radius,
    young_modulus,
    friction,
    max_force,
    mass=0.0,
    gravity=(0.0, 0.0, -9.81),
) -> dict[str, np.ndarray]:
    """Validate and normalise the fields of one grasp (concrete values only).

    Args:
        positions: ``(N, 3)`` contact positions, m, object frame.
        normals: ``(N, 3)`` outward surface normals (any non-zero length).
        initial_deformation: scalar or ``(N,)``, m, each in ``(0, radius)``.
        radius: scalar or ``(N,)``, m, ``> 0``.
        young_modulus: scalar or ``(N,)``, Pa, ``> 0``.
        friction: scalar or ``(N,)``, dimensionless, ``> 0``.
        max_force: scalar or ``(N,)``, N, ``> 0``.
        mass: scalar, kg, ``>= 0``.
        gravity: ``(3,)``, m/s^2.

    Returns:
        A dict with exactly the :class:`Grasp` field names: float64 arrays, per-fingertip
        fields broadcast to ``(N,)``, normals of unit length.

    Raises:
        GraspValueError: a field is not numeric, has the wrong shape, is not finite or
            breaks a physical rule; or a value is a JAX tracer (use ``Grasp(...)`` or
            ``grasp.replace(...)`` inside ``jit``).
    """
    given = dict(
        positions=positions,
        normals=normals,
        initial_deformation=initial_deformation,
        radius=radius,
        young_modulus=young_modulus,
        friction=friction,
        max_force=max_force,
        mass=mass,
        gravity=gravity,
    )
    for name, value in given.items():
        if _is_tracer(value):
            raise GraspValueError(
                f"{name} is a JAX tracer: Grasp.create needs concrete values; inside "
                "jit/vmap/grad build the grasp with Grasp(...) directly or use "
                "grasp.replace(...) on a grasp created outside"
            )

    arrs = {name: _as_float_array(name, value) for name, value in given.items()}

    # --- shapes -------------------------------------------------------------------
    pos = arrs["positions"]
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise GraspValueError(f"positions must have shape (N, 3), got shape {pos.shape}")
    n = pos.shape[0]
    if n < 2:
        raise GraspValueError(f"need at least 2 contacts, got {n}")
    nrm = arrs["normals"]
    if nrm.shape != (n, 3):
        raise GraspValueError(
            f"normals must have shape ({n}, 3) like positions, got shape {nrm.shape}"
        )
    original_ndim = {}
    for name in PER_FINGERTIP:
        a = arrs[name]
        original_ndim[name] = a.ndim
        if a.shape not in ((), (n,)):
            raise GraspValueError(
                f"{name} must be a scalar or have shape ({n},) (one per contact), "
                f"got shape {a.shape}"
            )
    if arrs["mass"].shape != ():
        raise GraspValueError(f"mass must be a scalar, got shape {arrs['mass'].shape}")
    if arrs["gravity"].shape != (3,):
        raise GraspValueError(f"gravity must have shape (3,), got shape {arrs['gravity'].shape}")

    # --- finiteness -----------------------------------------------------------------
    for name in FIELDS:
        _check_finite(name, arrs[name])

    # --- physical rules ---------------------------------------------------------------
    for name in ("radius", "young_modulus", "friction", "max_force"):
        a = arrs[name]
        flat = np.atleast_1d(a)
        bad = np.flatnonzero(~(flat > 0))
        if bad.size:
            i = int(bad[0])
            label = _index_name(name, original_ndim[name], i)
            raise GraspValueError(
                f"{label} = {_with_unit(format_value(flat[i]), name)} must be positive and finite"
            )
    if not arrs["mass"] >= 0:
        raise GraspValueError(
            f"mass = {_with_unit(format_value(arrs['mass']), 'mass')} must be >= 0 and finite"
        )

    radius_n = np.broadcast_to(arrs["radius"], (n,))
    dr = arrs["initial_deformation"]
    dr_n = np.broadcast_to(dr, (n,))
    for i in range(n):
        if not (0 < dr_n[i] < radius_n[i]):
            label = _index_name("initial_deformation", original_ndim["initial_deformation"], i)
            rlabel = _index_name("radius", original_ndim["radius"], i)
            raise GraspValueError(
                f"{label} = {format_value(dr_n[i])} m must be in "
                f"(0, {rlabel} = {format_value(radius_n[i])} m)"
            )
    # The solver divides by the initial elastic energy ~ E dr^3: it must not underflow.
    e_n = np.broadcast_to(arrs["young_modulus"], (n,))
    with np.errstate(under="ignore", over="ignore"):
        energy = e_n * dr_n**3
    for i in range(n):
        if not energy[i] >= MIN_ENERGY_SCALE:
            raise GraspValueError(
                f"contact {i}: young_modulus * initial_deformation^3 = "
                f"{format_value(e_n[i])} Pa * ({format_value(dr_n[i])} m)^3 is below "
                f"{MIN_ENERGY_SCALE:g} J, too small to evaluate in floating point"
            )

    # scaled norm: no overflow for huge components, no underflow for tiny ones
    peak = np.max(np.abs(nrm), axis=1)
    safe = np.where(peak > 0, peak, 1.0)
    norms = peak * np.linalg.norm(nrm / safe[:, None], axis=1)
    for i in range(n):
        if not norms[i] > NORMAL_MIN_NORM:
            raise GraspValueError(
                f"normals[{i}] = {format_value(nrm[i])} must be a non-zero vector "
                f"(norm > {NORMAL_MIN_NORM:g})"
            )
    unit = nrm.copy()
    rescale = np.abs(norms - 1.0) > _UNIT_TOLERANCE
    unit[rescale] = (nrm[rescale] / peak[rescale, None]) / (norms[rescale] / peak[rescale])[:, None]

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

    out = {
        "positions": pos,
        "normals": unit,
        "mass": arrs["mass"],
        "gravity": arrs["gravity"],
    }
    for name in PER_FINGERTIP:
        out[name] = np.array(np.broadcast_to(arrs[name], (n,)), dtype=np.float64)
    return {name: out[name] for name in FIELDS}
