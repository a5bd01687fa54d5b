"""Gradient-based tuning: maximise a grasp's evaluation value over chosen parameters.

::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=1.5e-3)
    res = jaxgrasp.tune(grasp, params=["initial_deformation:shared"])
    res.start_value, res.value          # J: the grasp as given, the tuned one
    res.params["initial_deformation"]   # m, the tuned (shared) deformation
    res.grasp                           # the tuned grasp

The value's gradient comes from the envelope theorem (see :mod:`jaxgrasp.evaluate`), so
one gradient costs about one evaluation. Every chosen parameter is mapped to ``[0, 1]``
within its bounds (positions: to offsets within the contact's face) and the negative
value, divided by the starting value, is minimised with a box-constrained quasi-Newton
method (SciPy's L-BFGS-B by default; ``method="jaxopt_lbfgsb"`` uses ``jaxopt.LBFGSB``,
``method="projected_gradient"`` ``jaxopt.ProjectedGradient``; see :data:`METHODS`). The value and its gradient are compiled once per
parameter selection, number of contacts and :class:`~jaxgrasp.EvaluateOptions`, and
reused by later calls (other grasps, bounds, starts, temperatures).

The value is a minimum over boundaries, so it has kinks where the limiting boundary
switches, and its maximum often lies on one (e.g. the cube's best deformation is where
the slip and force-limit boundaries cost the same energy). There the gradient does not
vanish and quasi-Newton steps shrink; the search then stops as ``stalled`` (no relative
improvement above ``ftol`` in ``patience`` iterations), which counts as converged.
``EvaluateOptions(smooth_min_temperature=T)`` smooths those kinks at the price of a bias
``<= T log(number of boundaries)``.
"""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from typing import Any, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.engine._evaluate import evaluate_compiled
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.model._fields import FIELD, TUNABLE
from jaxgrasp.engine._xla_options import COMPILER_OPTIONS
from jaxgrasp.model._grasp import Grasp
from jaxgrasp.tolerance._result import Evaluation
from jaxgrasp.tolerance._status import GraspStatus
from jaxgrasp.analysis._tune_status import TuneStatus
from jaxgrasp.model._units import MJ_TO_J
from jaxgrasp.model._validation import GraspValueError, check_grasp_inputs, counted

__all__ = ["tune", "TuneResult", "TUNABLE", "METHODS", "parse_param", "default_bounds", "plot_history"]

PER_CONTACT = tuple(name for name in TUNABLE if FIELD[name].shape == "per_contact")
"""Per-contact scalar fields: one tuned value per contact, or one shared (``NAME:shared``)."""

METHODS = ("scipy_lbfgsb", "jaxopt_lbfgsb", "projected_gradient")
"""Optimisers, all on the same compiled value and envelope gradient: SciPy's L-BFGS-B
(default; ``scipy.optimize.minimize``), ``jaxopt.LBFGSB`` and ``jaxopt.ProjectedGradient``
with ``projection_box``. On the cube's shared deformation (optimum on a kink) SciPy's
L-BFGS-B stops in ~7 iterations, ``jaxopt.LBFGSB`` needs ~30 (short steps near the kink)
and compiles its update separately, and projected gradient oscillates around the kink."""


# ----------------------------------------------------------------------------- specs


@dataclasses.dataclass(frozen=True)
class _Spec:
    """One tuned parameter (static, hashable)."""

    name: str  # Grasp field
    shared: bool  # one value for every contact

    @property
    def label(self) -> str:
        return f"{self.name}:shared" if self.shared else self.name


def parse_param(text: str) -> _Spec:
    """``"initial_deformation"``, ``"initial_deformation:shared"``, ``"positions"``, ``"mass"``."""
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
    if sep and name not in PER_CONTACT:
        raise GraspValueError(f"tune: {name!r} cannot be shared (only {', '.join(PER_CONTACT)})")
    return _Spec(name, bool(sep))


def _specs(params) -> tuple[_Spec, ...]:
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


def _size(spec: _Spec, n: int) -> int:
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
    """Physical validity of bounds (values every iterate may take)."""
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


def _bounds_for(spec: _Spec, grasp: Grasp, given) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` of the spec's internal vector (length ``_size``), validated."""
    n = grasp.num_contacts
    size = _size(spec, n)
    name = spec.name
    if name == "positions":
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
    if given is None:
        given = default_bounds(grasp, name)
        if given is None:
            raise GraspValueError(
                f"tune: give bounds for {name!r} ({FIELD[name].unit or 'dimensionless'}), e.g. "
                f"bounds={{{name!r}: (lo, hi)}}; only 'initial_deformation' has defaults"
            )
        lo, hi = given
        if spec.shared:  # the range every contact accepts
            lo, hi = np.max(lo), np.min(hi)
    else:
        try:
            lo, hi = given
            lo = np.asarray(lo, dtype=np.float64)
            hi = np.asarray(hi, dtype=np.float64)
        except (TypeError, ValueError):
            raise GraspValueError(f"tune: bounds of {name!r} must be a pair (lo, hi), got {given!r}") from None
    try:
        lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), (size,)).copy()
        hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), (size,)).copy()
    except ValueError:
        raise GraspValueError(
            f"tune: bounds of {spec.label!r} must be scalars or have {size} entries, got {given!r}"
        ) from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GraspValueError(f"tune: bounds of {name!r} must be finite, got {given!r}")
    if np.any(lo >= hi):
        raise GraspValueError(f"tune: bounds of {spec.label!r} need lo < hi, got ({lo.min():g}, {hi.max():g})")
    _field_checks(name, lo, hi, grasp)
    return lo, hi


def _start(spec: _Spec, grasp: Grasp) -> np.ndarray:
    """The spec's internal vector at ``grasp``."""
    n = grasp.num_contacts
    if spec.name == "positions":
        return np.zeros(2 * n)
    a = np.asarray(getattr(grasp, spec.name), dtype=np.float64).reshape(-1)
    if spec.name == "mass":
        return a.reshape(1)
    return np.array([a.mean()]) if spec.shared else a


# ------------------------------------------------------------------- compiled objective


def _apply(specs: tuple[_Spec, ...], u, data) -> Grasp:
    """The grasp at the normalised parameters ``u`` (traceable); the grasp as given,
    ``data["grasp"]``, where ``data["as_given"]`` is true (its value when the start was
    clipped into the bounds, from the same compiled function)."""
    base: Grasp = data["grasp"]
    changes = {}
    off = 0
    n = base.positions.shape[-2]
    for spec, lo, hi in zip(specs, data["lo"], data["hi"]):
        k = lo.shape[0]
        x = lo + (hi - lo) * u[off : off + k]
        off += k
        if spec.name == "positions":
            ab = x.reshape(n, 2)
            changes["positions"] = base.positions + jnp.einsum("nk,nkd->nd", ab, data["basis"])
        elif spec.name == "mass":
            changes["mass"] = x[0]
        elif spec.shared:
            changes[spec.name] = jnp.full((n,), x[0])
        else:
            changes[spec.name] = x
    given = data["as_given"]
    return base.replace(**{k: jnp.where(given, getattr(base, k), v) for k, v in changes.items()})


@lru_cache(maxsize=64)
def _compiled(specs: tuple[_Spec, ...], options: EvaluateOptions):
    """``vg(u, data) -> ((objective, (value_J, Evaluation)), grad)``, jitted once per key."""

    def objective(u, data):
        ev = evaluate_compiled(_apply(specs, u, data), data["temperature"], options)
        v = jnp.where(jnp.isfinite(ev.value), ev.value, 0.0)
        return -v / data["value_scale"], ev

    vg = jax.value_and_grad(objective, has_aux=True)

    def safe_vg(u, data):
        (f, ev), g = vg(u, data)
        g = jnp.where(jnp.isfinite(g), g, 0.0)
        return (f, ev), g

    return jax.jit(safe_vg, compiler_options=COMPILER_OPTIONS)


# ----------------------------------------------------------------------------- result


@dataclasses.dataclass(frozen=True)
class TuneResult:
    """Outcome of :func:`tune` (SI units).

    Attributes:
        grasp: the tuned grasp (the best iterate found).
        value: its evaluation value, J (smoothed if the options ask for it).
        initial_value: the value where the search started, J: the grasp as given, or,
            where ``clipped`` names parameters, the grasp with them clipped into the bounds.
        history: ``(iterations + 1,)`` value at the search's start and after each iteration, J.
        history_status: ``(iterations + 1,)`` evaluation status at those iterates
            (:data:`~jaxgrasp.STATUS_NAMES`).
        params: tuned values by parameter label (``"initial_deformation"``,
            ``"initial_deformation:shared"``, ``"positions"`` ...): per-contact ``(N,)``,
            shared ``()``, ``"positions"`` the ``(N, 3)`` contact positions (m).
        initial_params: the same at the start.
        bounds: ``(lo, hi)`` by label as used (``"positions"``: in-face offsets, m).
        evaluation: the :class:`~jaxgrasp.Evaluation` of ``grasp``.
        status: a :class:`~jaxgrasp.analysis._tune_status.TuneStatus`, equal to its string:
            ``"converged"`` (projected gradient below ``tol``), ``"stalled"`` (no
            relative improvement above ``ftol`` in ``patience`` iterations: typically a
            maximum on a kink, where the limiting boundary switches),
            ``"max_iterations"`` or ``"line_search_failed"``.
        iterations: optimiser iterations run.
        evaluations: value-and-gradient evaluations.
        not_converged_evaluations: iterates whose evaluation did not converge
            (``history_status`` not_converged); their values are not to be trusted.
        method: the optimiser.
        message: a one-line explanation of ``status``.
        start_value: the value of the grasp as given, J: ``initial_value`` unless the
            start was moved (``clipped``, or a ``:shared`` parameter whose contacts
            differed set to their mean). ``gain`` is measured from it.
        clipped: labels of the parameters whose start lay outside the bounds and was
            clipped into them (``()`` when none).
    """

    grasp: Grasp
    value: float
    initial_value: float
    history: np.ndarray
    history_status: np.ndarray
    params: dict
    initial_params: dict
    bounds: dict
    evaluation: Evaluation
    status: TuneStatus
    iterations: int
    evaluations: int
    not_converged_evaluations: int
    method: str
    message: str
    start_value: float
    clipped: tuple = ()

    @property
    def converged(self) -> bool:
        """``status`` is ``"converged"`` or ``"stalled"`` (derived from it, never stored)."""
        return self.status.converged

    @property
    def gain(self) -> float:
        """``value / start_value``: the gain over the grasp as given (``inf`` where that
        grasp had value 0 and the clipped start did not)."""
        return self.value / self.start_value if self.start_value > 0.0 else math.inf

    def start_note(self) -> str:
        """``""``, or where the start was moved into the bounds, e.g.
        ``"start of initial_deformation clipped into its bounds (value there 2.946e-04 J)"``."""
        if not self.clipped:
            return ""
        return (
            f"start of {', '.join(self.clipped)} clipped into {'its' if len(self.clipped) == 1 else 'their'} "
            f"bounds (value there {self.initial_value:.4g} J)"
        )

    def summary(self) -> str:
        """One line: value of the grasp as given -> tuned value, gain, status (and a note
        where the start was clipped into the bounds)."""
        note = self.start_note()
        return (
            f"tuned value: {self.start_value:.6e} J -> {self.value:.6e} J "
            f"(x{self.gain:.4f}) in {counted(self.iterations, 'iteration')}, {self.status}"
            + (f"; {note}" if note else "")
        )


def _labelled_params(specs, grasp: Grasp, x_by_spec) -> dict:
    out = {}
    for spec, x in zip(specs, x_by_spec):
        if spec.name == "positions":
            out[spec.label] = np.asarray(grasp.positions, dtype=np.float64).copy()
        elif spec.name == "mass" or spec.shared:
            out[spec.label] = np.float64(x[0])
        else:
            out[spec.label] = np.asarray(x, dtype=np.float64).copy()
    return out


# ----------------------------------------------------------------------------- tune


def tune(
    grasp: Grasp,
    params: Sequence[str] | str = ("initial_deformation",),
    bounds: Mapping[str, Any] | None = None,
    *,
    maxiter: int = 50,
    options: EvaluateOptions = EvaluateOptions(),
    method: str = "scipy_lbfgsb",
    tol: float = 1e-6,
    ftol: float = 1e-7,
    patience: int = 4,
    callback=None,
) -> TuneResult:
    """Maximise ``evaluate(grasp).value`` over the chosen parameters within bounds.

    Args:
        grasp: the starting grasp (must be stable: value > 0).
        params: parameter names, from :data:`TUNABLE`:

            * ``initial_deformation``, ``young_modulus``, ``friction``, ``max_force``,
              ``radius``: one value per contact; append ``:shared`` (e.g.
              ``"initial_deformation:shared"``) to tie every contact to one value (it
              starts at the contacts' mean);
            * ``positions``: each contact moves within its face, ``p0 + a t1 + b t2``
              with ``t1, t2`` orthonormal and orthogonal to its normal, ``|a|, |b| <=``
              the given half-width (normals stay fixed);
            * ``mass``: the object's mass (not a grasp design choice, but allowed).
        bounds: by parameter name (with or without ``:shared``): ``(lo, hi)`` in SI
            units, scalars or one per contact; for ``positions`` the half-width in m (a
            number, one per contact, or ``(N, 2)``). Only ``initial_deformation`` has a
            default (:func:`default_bounds`). A start outside its bounds is clipped into
            them: :attr:`TuneResult.clipped` names it, and ``start_value`` and ``gain``
            stay those of the grasp as given.
        maxiter: largest number of optimiser iterations.
        options: :class:`~jaxgrasp.EvaluateOptions` of every evaluation (e.g. a
            ``smooth_min_temperature`` to smooth the kinks).
        method: one of :data:`METHODS`.
        tol: stop when the projected gradient of the normalised objective (the value
            divided by the starting value, parameters scaled to ``[0, 1]``) is below this.
        ftol, patience: stop (``stalled``) when the best value has not improved by more
            than ``ftol`` (relative) in ``patience`` iterations.
        callback: called as ``callback(iteration, value_J, grasp_params_u)`` after each
            iteration (for progress output).

    Returns:
        A :class:`TuneResult`; ``result.grasp`` is the best grasp found.

    Raises:
        GraspValueError: invalid parameters or bounds, or a start that is not stable
            (value 0: unstable or infeasible), where the gradient is 0 and there is
            nothing to follow; the message names the status.
    """
    grasp = _checked_grasp(grasp, method, maxiter)
    specs = _specs(params)
    box = _Box.build(specs, grasp, bounds)
    t = options.smooth_min_temperature
    hard_options = dataclasses.replace(options, smooth_min_temperature=None)
    data = {
        "grasp": grasp,
        "lo": tuple(jnp.asarray(v) for v in box.los),
        "hi": tuple(jnp.asarray(v) for v in box.his),
        "basis": jnp.asarray(face_basis(grasp.normals)),
        "temperature": jnp.float64(0.0 if t is None else t / MJ_TO_J),
        "value_scale": jnp.float64(1.0),
        "as_given": jnp.asarray(False),
    }
    vg = _compiled(specs, hard_options)
    rec = _Record.start(vg, box, data)
    data["value_scale"] = jnp.float64(rec.initial_value)
    start_value = _value_as_given(vg, box, data) if box.moved else rec.initial_value
    run = dict(maxiter=maxiter, tol=tol, ftol=ftol, patience=patience, callback=callback)
    if method == "scipy_lbfgsb":
        status, iters, evals = _run_scipy(vg, box.u0, data, rec, **run)
    else:
        status, iters, evals = _run_jaxopt(_jaxopt_solver(specs, hard_options, method), box.u0, data, rec, **run)
    message = status.message.format(ftol=ftol, patience=patience, maxiter=maxiter)
    return _result(specs, grasp, box, data, rec, status, iters, evals, method, message, start_value)


def _value_as_given(vg, box: "_Box", data) -> float:
    """The value of the grasp as given, J, where the search starts elsewhere (clipped
    into the bounds): the same compiled function at ``as_given``, one more evaluation."""
    (_, ev), _ = vg(jnp.asarray(box.u0), {**data, "as_given": jnp.asarray(True)})
    v = float(ev.value)
    return v if math.isfinite(v) else 0.0


def _checked_grasp(grasp: Grasp, method: str, maxiter) -> Grasp:
    """The validated float64 grasp :func:`tune` starts from; one-line errors for bad calls."""
    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"tune: expected a jaxgrasp.Grasp, got {type(grasp).__name__}")
    if np.ndim(grasp.mass) != 0:
        raise GraspValueError("tune: takes one grasp, not a batch")
    grasp = Grasp(**{k: jnp.asarray(v, jnp.float64) for k, v in check_grasp_inputs(**grasp.to_numpy()).items()})
    if method not in METHODS:
        raise GraspValueError(f"tune: unknown method {method!r}; choose from {', '.join(METHODS)}")
    if not (isinstance(maxiter, (int, np.integer)) and not isinstance(maxiter, bool) and maxiter >= 1):
        raise GraspValueError(f"tune: maxiter must be an integer >= 1, got {maxiter!r}")
    return grasp


@dataclasses.dataclass(frozen=True)
class _Box:
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
    def build(cls, specs, grasp: Grasp, bounds) -> "_Box":
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


class _Record:
    """The value and status of every iterate, and the best trusted one."""

    def __init__(self, v0: float, u0, ev0):
        self.history = [v0]
        self.statuses = [int(ev0.status)]
        self.best = (v0, np.asarray(u0), ev0)

    @property
    def initial_value(self) -> float:
        return self.history[0]

    @classmethod
    def start(cls, vg, box: _Box, data) -> "_Record":
        """Evaluate the start; a start without a positive value is an error."""
        (_, ev0), _ = vg(jnp.asarray(box.u0), data)
        v0 = float(ev0.value)
        if not (v0 > 0.0 and math.isfinite(v0)):
            where = f" after clipping {', '.join(box.clipped)} to its bounds" if box.clipped else ""
            raise GraspValueError(
                f"tune: the starting grasp{where} has value {v0:g} J "
                f"(status {GraspStatus(int(ev0.status)).label}): "
                "its gradient is 0, so there is nothing to follow; start from a stable grasp"
            )
        return cls(v0, box.u0, ev0)

    def add(self, u, ev) -> float:
        """Record an iterate; returns its value, J."""
        v = float(ev.value)
        s = int(ev.status)
        self.history.append(v)
        self.statuses.append(s)
        if s in (GraspStatus.STABLE, GraspStatus.NOT_CONVERGED) and v > self.best[0]:
            self.best = (v, np.asarray(u), ev)
        return v


def _result(specs, grasp, box: _Box, data, rec: _Record, status, iters, evals, method, message, start_value) -> TuneResult:
    """The :class:`TuneResult` of a finished search."""
    v_best, u_best, ev_best = rec.best
    tuned = _apply(specs, jnp.asarray(u_best), data)
    tuned = jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a)), tuned)
    hst = np.asarray(rec.statuses, dtype=np.int32)
    n_nc = int(np.sum(hst == GraspStatus.NOT_CONVERGED))
    if box.clipped:
        message += f"; start of {', '.join(box.clipped)} clipped into the bounds"
    if n_nc:
        message += f"; {n_nc} iterate(s) had not-converged evaluations"
    n = grasp.num_contacts
    bounds_used = {}
    for s, lo, hi in zip(specs, box.los, box.his):
        if s.name == "positions":
            bounds_used[s.label] = (lo.reshape(n, 2), hi.reshape(n, 2))
        elif lo.size == 1:
            bounds_used[s.label] = (np.float64(lo[0]), np.float64(hi[0]))
        else:
            bounds_used[s.label] = (lo, hi)
    return TuneResult(
        grasp=tuned,
        value=v_best,
        initial_value=rec.initial_value,
        history=np.asarray(rec.history, dtype=np.float64),
        history_status=hst,
        params=_labelled_params(specs, tuned, box.params(u_best)),
        initial_params=_labelled_params(specs, grasp, box.x0s),
        bounds=bounds_used,
        evaluation=jax.tree_util.tree_map(np.asarray, ev_best),
        status=status,
        iterations=iters,
        evaluations=int(evals) + 1 + int(box.moved),  # the start, and the grasp as given
        not_converged_evaluations=n_nc,
        method=method,
        message=message,
        start_value=float(start_value),
        clipped=box.clipped,
    )


def _run_jaxopt(solver, u0, data, rec: _Record, *, maxiter, tol, ftol, patience, callback):
    """A jaxopt solver's iterations, one record each; ``(status, iterations, evaluations)``."""
    box = (jnp.zeros_like(jnp.asarray(u0)), jnp.ones_like(jnp.asarray(u0)))
    u = jnp.asarray(u0)
    state = solver.init_state(u, box, data)
    status, iters, stall = TuneStatus.MAX_ITERATIONS, 0, 0
    for it in range(1, maxiter + 1):
        u_prev = u
        prev_best = rec.best[0]
        u, state = solver.update(u, state, box, data)
        iters = it
        v = rec.add(u, state.aux)
        if callback is not None:
            callback(it, v, np.asarray(u))
        stall = stall + 1 if rec.best[0] <= prev_best * (1.0 + ftol) else 0
        if float(state.error) <= tol:
            status = TuneStatus.CONVERGED
            break
        if bool(getattr(state, "failed_linesearch", False)) and np.array_equal(np.asarray(u), np.asarray(u_prev)):
            status = TuneStatus.LINE_SEARCH_FAILED
            break
        if stall >= patience:
            status = TuneStatus.STALLED
            break
    return status, iters, int(getattr(state, "num_fun_eval", iters + 1))


@lru_cache(maxsize=32)
def _jaxopt_solver(specs: tuple[_Spec, ...], options: EvaluateOptions, method: str):
    """A jitted jaxopt solver, cached so that its ``update`` compiles once per key."""
    import jaxopt

    vg = _compiled(specs, options)
    if method == "jaxopt_lbfgsb":
        return jaxopt.LBFGSB(fun=vg, value_and_grad=True, has_aux=True, maxiter=10**6, tol=0.0)
    from jaxopt.projection import projection_box

    return jaxopt.ProjectedGradient(
        fun=vg, projection=projection_box, value_and_grad=True, has_aux=True, maxiter=10**6, tol=0.0
    )


def _run_scipy(vg, u0, data, rec: _Record, *, maxiter, tol, ftol, patience, callback):
    """SciPy's L-BFGS-B on the compiled value and gradient in ``[0, 1]^k``, one record per
    iteration; ``(status, iterations, evaluations)``. (``patience`` is jaxopt's: SciPy
    stops on ``ftol`` itself.)"""
    import scipy.optimize

    last = {}
    count = {"it": 0, "evals": 0}

    def fun(u):
        count["evals"] += 1
        (f, ev), g = vg(jnp.asarray(u), data)
        last["u"], last["ev"] = np.array(u), ev
        return float(f), np.asarray(g, dtype=np.float64)

    def cb(intermediate_result):
        xk = np.asarray(intermediate_result.x)
        count["it"] += 1
        if "u" in last and np.array_equal(last["u"], xk):
            ev = last["ev"]  # the line search's last point is the accepted iterate
        else:
            count["evals"] += 1
            (_, ev), _ = vg(jnp.asarray(xk), data)
        v = rec.add(xk, ev)
        if callback is not None:
            callback(count["it"], v, xk)

    out = scipy.optimize.minimize(
        fun,
        np.asarray(u0, dtype=np.float64),
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, 1.0)] * len(u0),
        callback=cb,
        options={"maxiter": maxiter, "gtol": tol, "ftol": ftol},
    )
    if out.success:
        status = TuneStatus.CONVERGED if "PROJ" in str(out.message).upper() else TuneStatus.STALLED
    elif count["it"] >= maxiter:
        status = TuneStatus.MAX_ITERATIONS
    else:
        status = TuneStatus.LINE_SEARCH_FAILED
    return status, count["it"], count["evals"]


def plot_history(result: TuneResult, path=None, *, title: str | None = None):
    """Plot the value over the iterations of :func:`tune` (mJ); save to ``path`` if given.

    Returns the matplotlib ``Figure`` (Agg canvas; no display needed). The best value
    so far is drawn as a line, each iterate as a dot (open where its evaluation did not
    converge).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    it = np.arange(result.history.size)
    mj = result.history / MJ_TO_J
    ax.plot(it, np.maximum.accumulate(mj), "-", color="C0", label="best so far")
    ok = result.history_status != GraspStatus.NOT_CONVERGED
    ax.plot(it[ok], mj[ok], "o", color="C0", ms=4, label="iterate")
    if np.any(~ok):
        ax.plot(it[~ok], mj[~ok], "o", mfc="none", color="C3", ms=5, label="iterate (not converged)")
    ax.axhline(result.initial_value / MJ_TO_J, color="0.6", lw=0.8, ls="--", label="start")
    ax.set_xlabel("iteration")
    ax.set_ylabel("evaluation value ΔU_min [mJ]")
    params = ", ".join(result.params)
    ax.set_title(title or f"tuning {params}: {result.initial_value / MJ_TO_J:.4g} → {result.value / MJ_TO_J:.4g} mJ")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    if path is not None:
        from jaxgrasp.plots._plots import save_figure  # atomic: never half an image

        save_figure(fig, path)
    return fig
