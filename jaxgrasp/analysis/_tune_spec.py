"""The parameters [`jaxgrasp.tune`][jaxgrasp.tune] searches over: specs, their bounds, and the box.

Every tuned parameter is mapped to ``[0, 1]`` within its bounds (positions: to offsets
within the contact's face); `ParamBox` holds the bounds and the start of every spec
and maps the normalised vector back to SI values.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from jaxgrasp.model import FIELD, TUNABLE, Grasp, GraspValueError, check_corners

__all__ = [
    "ParamSpec",
    "ParamBox",
    "SHAREABLE",
    "parse_param",
    "param_specs",
    "face_basis",
    "default_bounds",
    "labelled_params",
    "labelled_bounds",
]

SHAREABLE = tuple(name for name in TUNABLE if FIELD[name].shape == "per_contact")
"""Per-contact scalar fields: one tuned value per contact, or one shared (``NAME:shared``)."""


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One tuned parameter (static, hashable)."""

    name: str  # Grasp field
    shared: bool  # one value for every contact

    @property
    def label(self) -> str:
        return f"{self.name}:shared" if self.shared else self.name


def parse_param(text: str) -> ParamSpec:
    """The spec of one parameter name from `TUNABLE`.

    * ``initial_deformation``, ``young_modulus``, ``friction``, ``max_force``, ``radius``:
      one value per contact; append ``:shared`` (e.g. ``"initial_deformation:shared"``)
      to tie every contact to one value (it starts at the contacts' mean);
    * ``positions``: each contact moves within its face, ``p0 + a t1 + b t2`` with
      ``t1, t2`` orthonormal and orthogonal to its normal, ``|a|, |b| <=`` the given
      half-width (normals stay fixed);
    * ``mass``: the object's mass (not a grasp design choice, but allowed).
    """
    if not isinstance(text, str):
        raise GraspValueError(f"tune: a parameter name must be a string, got {text!r}")
    name, sep, suffix = text.strip().partition(":")
    if name not in TUNABLE:
        raise GraspValueError(
            f"tune: unknown parameter {text!r}; choose from {', '.join(TUNABLE)} "
            "(per-contact ones may end in ':shared')"
        )
    if sep and suffix != "shared":
        raise GraspValueError(f"tune: unknown suffix in {text!r}; the only suffix is ':shared'")
    if sep and name not in SHAREABLE:
        raise GraspValueError(f"tune: {name!r} cannot be shared (only {', '.join(SHAREABLE)})")
    return ParamSpec(name, bool(sep))


def param_specs(params) -> tuple[ParamSpec, ...]:
    """The specs of ``params`` (a name or a sequence of names), each field at most once."""
    if isinstance(params, str):
        params = [params]
    specs = tuple(parse_param(p) for p in params)
    if not specs:
        raise GraspValueError("tune: give at least one parameter to tune")
    names = [s.name for s in specs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise GraspValueError(f"tune: parameter {dup[0]!r} given more than once")
    return specs


def _size(spec: ParamSpec, n: int) -> int:
    """Length of the spec's internal vector for ``n`` contacts."""
    if spec.name == "positions":
        return 2 * n
    if spec.name == "mass" or spec.shared:
        return 1
    return n


def face_basis(normals) -> np.ndarray:
    """``(N, 2, 3)`` orthonormal vectors spanning the plane orthogonal to each normal."""
    nrm = np.asarray(normals, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    out = np.empty(nrm.shape[:-1] + (2, 3))
    for i, v in enumerate(nrm):
        e = np.eye(3)[int(np.argmin(np.abs(v)))]  # the axis least aligned with v
        t1 = np.cross(v, e)
        t1 /= np.linalg.norm(t1)
        out[i, 0] = t1
        out[i, 1] = np.cross(v, t1)
    return out


def default_bounds(grasp: Grasp, name: str):
    """Default ``(lo, hi)`` per contact for ``name``, or ``None`` where bounds must be given.

    Only ``initial_deformation`` has defaults: from ``max(1e-6 m, 1% of the radius)`` to
    ``min(0.99 radius, sqrt(max_force / (pi young_modulus)))``, the deformation at which a
    fingertip alone already presses with its force limit in the initial state (beyond it
    a grasp without load is infeasible, value 0).
    """
    if name != "initial_deformation":
        return None
    a = grasp.to_numpy()
    r, e, fmax = a["radius"], a["young_modulus"], a["max_force"]
    lo = np.maximum(1e-6, 0.01 * r)
    hi = np.minimum(0.99 * r, np.sqrt(fmax / (math.pi * e)))
    return lo, hi


def _field_checks(name: str, lo, hi, grasp: Grasp):
    """Physical validity of one parameter's bounds against the grasp's other fields (the
    rules of every parameter together: `_check_corners`)."""
    a = grasp.to_numpy()
    if name == "mass":
        if np.any(lo < 0):
            raise GraspValueError(f"tune: bounds of 'mass' must be >= 0 kg, got lower bound {lo.min():g}")
        return
    if np.any(lo <= 0):
        raise GraspValueError(
            f"tune: bounds of {name!r} must be > 0 {FIELD[name].unit}".rstrip() + f", got lower bound {lo.min():g}"
        )
    if name == "initial_deformation" and np.any(hi >= a["radius"]):
        raise GraspValueError(
            f"tune: the upper bound of 'initial_deformation' ({hi.max():g} m) must stay below the "
            f"fingertip radius ({a['radius'].min():g} m)"
        )
    if name == "radius" and np.any(lo <= a["initial_deformation"]):
        raise GraspValueError(
            f"tune: the lower bound of 'radius' ({lo.min():g} m) must exceed the initial "
            f"deformation ({a['initial_deformation'].max():g} m)"
        )


def _check_corners(specs, los, his, grasp: Grasp) -> None:
    """Every iterate the box allows is a grasp [`jaxgrasp.evaluate`][jaxgrasp.evaluate] accepts: the rules
    of `check_grasp_inputs` (friction at most
    ``MAX_FRICTION``, ``young_modulus * initial_deformation^3`` at least
    ``MIN_ENERGY_SCALE`` J, a weight at most ``MAX_LOAD_RATIO`` times the initial squeeze
    ``sum pi E dr^2`` N, ``initial_deformation < radius`` m with both tuned) hold at the
    box's corners, each tuned parameter at its lower or at its upper bounds (SI units).

    The corners are enough: each rule is monotone in each of these parameters, in the same
    direction at every contact (e.g. the squeeze grows with ``E`` and ``dr``, the weight
    with the mass), so where any point of the box breaks a rule, the corner with every
    parameter at its worst end breaks it too (`check_corners`).
    ``positions`` stay at the grasp's own (no rule but distinct positions involves them).
    """
    ends = {}
    for spec, lo, hi in zip(specs, los, his):
        if spec.name == "positions":
            continue
        one = lo.size == 1  # mass, or a shared value: the same at every contact
        ends[spec.name] = (lo[0], hi[0]) if one else (lo, hi)
    check_corners(grasp.to_numpy(), ends, "tune: at the bounds' corner")


def _bounds_for(spec: ParamSpec, grasp: Grasp, given) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` of the spec's internal vector (length ``_size``), validated."""
    if spec.name == "positions":
        return _position_bounds(given, grasp.num_contacts)
    if given is None:  # the messages below show the defaults as the bounds given
        given = _required_defaults(grasp, spec.name)
        lo, hi = given
        if spec.shared:  # the range every contact accepts
            lo, hi = np.max(lo), np.min(hi)
    else:
        lo, hi = _pair(spec.name, given)
    size = _size(spec, grasp.num_contacts)
    try:
        lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), (size,)).copy()
        hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), (size,)).copy()
    except ValueError:
        raise GraspValueError(
            f"tune: bounds of {spec.label!r} must be scalars or have {size} entries, got {given!r}"
        ) from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GraspValueError(f"tune: bounds of {spec.name!r} must be finite, got {given!r}")
    if np.any(lo >= hi):
        raise GraspValueError(f"tune: bounds of {spec.label!r} need lo < hi, got ({lo.min():g}, {hi.max():g})")
    _field_checks(spec.name, lo, hi, grasp)
    return lo, hi


def _position_bounds(given, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(-h, h)`` ``(2N,)``: the in-face offsets of ``n`` contacts within the half-width
    ``given`` (m: a number, one per contact, or ``(N, 2)``)."""
    if given is None:
        raise GraspValueError(
            "tune: give the half-width (m) within which each contact may move in its face, "
            "e.g. bounds={'positions': 0.01}"
        )
    try:
        h = np.asarray(given, dtype=np.float64)
        h = np.broadcast_to(h[..., None] if h.ndim == 1 else h, (n, 2)).reshape(-1)
    except (TypeError, ValueError):
        raise GraspValueError(
            f"tune: bounds of 'positions' must be a half-width in m (a number, one per contact, "
            f"or (N, 2)), got {given!r}"
        ) from None
    if not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise GraspValueError(f"tune: half-widths of 'positions' must be finite and > 0 m, got {given!r}")
    return -h.copy(), h.copy()


def _required_defaults(grasp: Grasp, name: str):
    """`default_bounds` of ``name``; an error where it has none."""
    given = default_bounds(grasp, name)
    if given is None:
        raise GraspValueError(
            f"tune: give bounds for {name!r} ({FIELD[name].unit or 'dimensionless'}), e.g. "
            f"bounds={{{name!r}: (lo, hi)}}; only 'initial_deformation' has defaults"
        )
    return given


def _pair(name: str, given):
    """``(lo, hi)`` as float arrays from bounds given as a pair."""
    try:
        lo, hi = given
        return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    except (TypeError, ValueError):
        raise GraspValueError(f"tune: bounds of {name!r} must be a pair (lo, hi), got {given!r}") from None


def _start(spec: ParamSpec, grasp: Grasp) -> np.ndarray:
    """The spec's internal vector at ``grasp``."""
    n = grasp.num_contacts
    if spec.name == "positions":
        return np.zeros(2 * n)
    a = np.asarray(getattr(grasp, spec.name), dtype=np.float64).reshape(-1)
    if spec.name == "mass":
        return a.reshape(1)
    return np.array([a.mean()]) if spec.shared else a


@dataclasses.dataclass(frozen=True)
class ParamBox:
    """The tuned parameters' bounds and start: ``los``/``his``/``x0s`` per spec (SI),
    ``u0`` the start mapped to ``[0, 1]``, ``clipped`` the labels whose start was clipped,
    ``moved`` whether the start differs from the grasp as given (clipped, or a shared
    parameter whose contacts differed set to their mean)."""

    los: tuple
    his: tuple
    x0s: tuple
    u0: np.ndarray
    clipped: tuple
    moved: bool

    @classmethod
    def build(cls, specs, grasp: Grasp, bounds) -> "ParamBox":
        bounds = dict(bounds or {})
        known = {s.name for s in specs} | {s.label for s in specs}
        extra = sorted(k for k in bounds if k not in known)
        if extra:
            raise GraspValueError(f"tune: bounds given for {extra[0]!r}, which is not tuned")
        los, his, x0s, clipped = [], [], [], []
        moved = False
        for spec in specs:
            lo, hi = _bounds_for(spec, grasp, bounds.get(spec.label, bounds.get(spec.name)))
            x0 = _start(spec, grasp)
            if np.any(x0 < lo) or np.any(x0 > hi):
                clipped.append(spec.label)
            if spec.shared:
                per_contact = np.asarray(getattr(grasp, spec.name), dtype=np.float64)
                moved = moved or bool(np.any(per_contact != per_contact.reshape(-1)[0]))
            los.append(lo)
            his.append(hi)
            x0s.append(np.clip(x0, lo, hi))
        _check_corners(specs, los, his, grasp)
        u0 = np.concatenate([(x - lo) / (hi - lo) for x, lo, hi in zip(x0s, los, his)])
        return cls(tuple(los), tuple(his), tuple(x0s), u0, tuple(clipped), moved or bool(clipped))

    def params(self, u) -> list[np.ndarray]:
        """Each spec's vector (SI) at the normalised parameters ``u``."""
        out, off = [], 0
        for lo, hi in zip(self.los, self.his):
            k = lo.shape[0]
            out.append(lo + (hi - lo) * u[off : off + k])
            off += k
        return out


def labelled_params(specs, grasp: Grasp, x_by_spec) -> dict:
    """Each spec's values by label: per-contact ``(N,)``, shared and ``mass`` ``()``,
    ``positions`` the ``(N, 3)`` contact positions of ``grasp`` (m)."""
    out = {}
    for spec, x in zip(specs, x_by_spec):
        if spec.name == "positions":
            out[spec.label] = np.asarray(grasp.positions, dtype=np.float64).copy()
        elif spec.name == "mass" or spec.shared:
            out[spec.label] = np.float64(x[0])
        else:
            out[spec.label] = np.asarray(x, dtype=np.float64).copy()
    return out


def labelled_bounds(specs, box: ParamBox, n: int) -> dict:
    """``(lo, hi)`` by label as used: ``positions`` ``(N, 2)`` in-face offsets (m), a
    one-entry vector as scalars, else per contact."""
    out = {}
    for s, lo, hi in zip(specs, box.los, box.his):
        if s.name == "positions":
            out[s.label] = (lo.reshape(n, 2), hi.reshape(n, 2))
        elif lo.size == 1:
            out[s.label] = (np.float64(lo[0]), np.float64(hi[0]))
        else:
            out[s.label] = (lo, hi)
    return out
