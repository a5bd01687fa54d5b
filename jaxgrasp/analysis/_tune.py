"""Gradient-based tuning: maximise a grasp's evaluation value over chosen parameters.

::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=1.5e-3)
    res = jaxgrasp.tune(grasp, params=["initial_deformation:shared"])
    res.start_value, res.value          # J: the grasp as given, the tuned one
    res.params["initial_deformation"]   # m, the tuned (shared) deformation
    res.grasp                           # the tuned grasp

The value's gradient comes from the envelope theorem (see [`jaxgrasp.evaluate`][jaxgrasp.evaluate]), so
one gradient costs about one evaluation. Every chosen parameter is mapped to ``[0, 1]``
within its bounds (positions: to offsets within the contact's face;
`jaxgrasp.analysis._tune_spec`) and the negative value, divided by the starting
value, is minimised with a box-constrained quasi-Newton method (SciPy's L-BFGS-B by
default; ``method="jaxopt_lbfgsb"`` uses ``jaxopt.LBFGSB``, ``method="projected_gradient"``
``jaxopt.ProjectedGradient``; `jaxgrasp.analysis._tune_drivers`). This module holds
[`tune`][jaxgrasp.tune], the objective and [`TuneResult`][jaxgrasp.analysis.TuneResult]. The value and its gradient are
compiled once per parameter selection, number of contacts and
[`EvaluateOptions`][jaxgrasp.EvaluateOptions], and reused by later calls (other grasps, bounds,
starts, temperatures) and, through the executable store, by later processes.

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

from jaxgrasp.analysis._limits import MAX_TUNE_ITERATIONS, METHODS, TUNE_ITERATIONS_WHAT
from jaxgrasp.analysis._tune_drivers import SearchRecord, run_search
from jaxgrasp.analysis._tune_spec import (
    ParamBox,
    ParamSpec,
    face_basis,
    labelled_bounds,
    labelled_params,
    param_specs,
)
from jaxgrasp.analysis._tune_status import TuneStatus
from jaxgrasp.base import json_floats, over_limit
from jaxgrasp.engine import COMPILER_OPTIONS, StoredFunction, value_and_grad_builder
from jaxgrasp.model import MJ_TO_J, Grasp, GraspValueError, check_grasp_inputs, counted
from jaxgrasp.surface import PAD_FACES, MeshGrasp, Surface
from jaxgrasp.tolerance import EVALUATION_TREE, EvaluateOptions, Evaluation, GraspStatus

__all__ = ["tune", "TuneResult"]


# ------------------------------------------------------------------- compiled objective


def _apply(specs: tuple[ParamSpec, ...], u, data) -> Grasp:
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
            changes.update(_moved_contacts(base, x.reshape(n, 2), data))
        elif spec.name == "mass":
            changes["mass"] = x[0]
        elif spec.shared:
            changes[spec.name] = jnp.full((n,), x[0])
        else:
            changes[spec.name] = x
    given = data["as_given"]
    return base.replace(**{k: jnp.where(given, getattr(base, k), v) for k, v in changes.items()})


def _moved_contacts(base: Grasp, offsets, data) -> dict:
    """Contact positions (and, on a mesh, normals) after in-plane ``offsets (N, 2)`` m.

    Without a surface each contact moves in its tangent plane, its normal fixed. With one
    (``data["surface"]``, a [`Surface`][jaxgrasp.surface.Surface] in the grasp's frame) the
    moved point is put back on the surface at its closest point and takes the normal of the
    face there: the contact slides along the surface, across faces, and its normal follows.
    """
    moved = base.positions + jnp.einsum("nk,nkd->nd", offsets, data["basis"])
    if "surface" not in data:
        return {"positions": moved}
    hit = data["surface"].closest(moved)
    return {"positions": hit.point, "normals": hit.normal}


@lru_cache(maxsize=64)
def _compiled(specs: tuple[ParamSpec, ...], options: EvaluateOptions) -> StoredFunction:
    """``vg(u, data) -> ((objective, Evaluation), grad)``, one per key: the objective is
    minus the value (J) over ``data["value_scale"]``, 0 where not finite. Compiled once
    per shape of ``data`` (the grasp, bounds, face bases and, on a mesh, the surface) and
    kept in the executable store (`StoredFunction`): a
    second process tuning the same parameters of a grasp with as many contacts loads it."""

    vg = value_and_grad_builder(lambda u, data: (_apply(specs, u, data), None), options,
                                temperature_of=lambda data: data["temperature"],
                                objective=lambda v, data: -v / data["value_scale"])

    def safe_vg(u, data):
        (f, (ev, _)), g = vg(u, data)
        return (f, ev), g

    leaf = jax.tree_util.tree_structure(0.0)
    out_tree = jax.tree_util.treedef_tuple((jax.tree_util.treedef_tuple((leaf, EVALUATION_TREE)), leaf))
    return StoredFunction(safe_vg, (specs, options), out_tree, name="tune", compiler_options=COMPILER_OPTIONS,
                          what="tune's value and gradient of " + ", ".join(s.label for s in specs))


# ----------------------------------------------------------------------------- result


@dataclasses.dataclass(frozen=True)
class TuneResult:
    """Outcome of [`tune`][jaxgrasp.tune] (SI units).

    Attributes:
        grasp: the tuned grasp (the best iterate found).
        value: its evaluation value, J (smoothed if the options ask for it).
        initial_value: the value where the search started, J (``history[0]``): the grasp
            as given, or, where ``clipped`` names parameters, the grasp with them clipped
            into the bounds. Not the value before tuning: that is ``start_value``.
        history: ``(iterations + 1,)`` value at the search's start and after each iteration, J.
        history_status: ``(iterations + 1,)`` evaluation status at those iterates
            ([`GraspStatus`][jaxgrasp.GraspStatus] codes).
        params: tuned values by parameter label (``"initial_deformation"``,
            ``"initial_deformation:shared"``, ``"positions"`` ...): per-contact ``(N,)``,
            shared ``()``, ``"positions"`` the ``(N, 3)`` contact positions (m).
        initial_params: the same at the start.
        bounds: ``(lo, hi)`` by label as used (``"positions"``: in-face offsets, m).
        evaluation: the [`Evaluation`][jaxgrasp.Evaluation] of ``grasp``.
        status: a [`TuneStatus`][jaxgrasp.analysis.TuneStatus], equal to its string
            ([`status_name`][jaxgrasp.analysis.TuneResult.status_name] as a plain ``str``);
            ``grasp`` is usable after each (the best found): ``"converged"`` (projected
            gradient below ``tol``: a maximum), ``"stalled"`` (no relative improvement
            above ``ftol`` in ``patience`` iterations: typically a maximum on a kink,
            where the limiting boundary switches), ``"max_iterations"`` (still improving:
            more iterations may raise it) or ``"line_search_failed"`` (no better point
            along the search direction: perhaps not a maximum).
        iterations: optimiser iterations run.
        evaluations: value-and-gradient evaluations.
        not_converged_evaluations: iterates whose evaluation did not converge
            (``history_status`` not_converged); their values are not to be trusted.
        method: the optimiser.
        message: a one-line explanation of ``status`` and whether ``grasp`` is usable
            (``status.message`` with its numbers), then any note: a start clipped into
            the bounds, not-converged iterates, a best iterate whose evaluation did not
            converge (then its value is not to be trusted).
        start_value: the value before tuning, J: the grasp as given's, the value every
            result of a tuning names so. ``initial_value`` unless the start was moved (``clipped``, or a ``:shared`` parameter whose contacts
            differed set to their mean). ``gain`` is measured from it.
        clipped: labels of the parameters whose start lay outside the bounds and was
            clipped into them (``()`` when none).
        mesh_grasp: where a [`MeshGrasp`][jaxgrasp.MeshGrasp] was tuned, the tuned one (its
            mesh and centre of mass, ``grasp``); else ``None``.
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
    mesh_grasp: MeshGrasp | None = None

    @property
    def status_name(self) -> str:
        """The name of ``status`` (``'converged'``), a plain ``str``."""
        return TuneStatus(self.status).label

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
        """One line: value of the grasp as given -> tuned value, gain, status with its
        explanation (is the result usable?) and a note where the start was clipped."""
        note = self.start_note()
        return (
            f"tuned value: {self.start_value:.6e} J -> {self.value:.6e} J "
            f"(x{self.gain:.4f}) in {counted(self.iterations, 'iteration')}, {self.status}: {self.message}"
            + (f"; {note}" if note else "")
        )

    def to_dict(self) -> dict[str, Any]:
        """The tuning as plain Python (JSON-ready; ``None`` for a number that is not
        finite): ``value``, ``start_value``, ``initial_value`` (J), ``gain``, ``status``
        by name, ``converged``, ``message``, the counts, ``method``, ``clipped``,
        ``params`` and ``initial_params`` by label (SI, lists), ``bounds`` by label
        (``[lo, hi]``), ``history`` (J), ``history_status`` by name and ``evaluation``
        (the tuned grasp's [`Evaluation.to_dict`][jaxgrasp.Evaluation.to_dict])."""
        return {
            "value": json_floats(self.value), "start_value": json_floats(self.start_value),
            "initial_value": json_floats(self.initial_value), "gain": json_floats(self.gain),
            "status": self.status_name, "converged": self.converged, "message": self.message,
            "iterations": int(self.iterations), "evaluations": int(self.evaluations),
            "not_converged_evaluations": int(self.not_converged_evaluations), "method": self.method,
            "clipped": list(self.clipped),
            "params": {k: json_floats(v) for k, v in self.params.items()},
            "initial_params": {k: json_floats(v) for k, v in self.initial_params.items()},
            "bounds": {k: [json_floats(lo), json_floats(hi)] for k, (lo, hi) in self.bounds.items()},
            "history": json_floats(self.history),
            "history_status": GraspStatus.names_of(self.history_status).tolist(),
            "evaluation": self.evaluation.to_dict(),
        }




# ----------------------------------------------------------------------------- tune


def tune(
    grasp: Grasp | MeshGrasp, params: Sequence[str] | str = ("initial_deformation",), bounds: Mapping[str, Any] | None = None,
    *, maxiter: int = 50, options: EvaluateOptions = EvaluateOptions(), method: str = "scipy_lbfgsb",
    tol: float = 1e-6, ftol: float = 1e-7, patience: int = 4, callback=None,
) -> TuneResult:
    """Maximise ``evaluate(grasp).value`` over the chosen parameters within bounds.

    Args:
        grasp: the starting grasp (must be stable: value > 0), or a
            [`MeshGrasp`][jaxgrasp.MeshGrasp]: then ``positions`` move along the mesh's surface.
        params: parameter names from `TUNABLE` (see
            `parse_param`): a per-contact field, one
            value per contact or, with ``:shared``, one for every contact; ``positions``
            (each contact moves in its tangent plane, normal fixed; on a mesh grasp it
            slides along the surface, across faces, and its normal is the outward normal
            of the face it lies on: [`Surface`][jaxgrasp.surface.Surface]); ``mass``.
        bounds: by parameter name (with or without ``:shared``): ``(lo, hi)`` in SI
            units, scalars or one per contact; for ``positions`` the half-width in m (a
            number, one per contact, or ``(N, 2)``). Only ``initial_deformation`` has a
            default (`default_bounds`). A start outside
            its bounds is clipped into them: `TuneResult.clipped` names it, and
            ``start_value`` and ``gain`` stay those of the grasp as given.
        maxiter: largest number of optimiser iterations.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] of every evaluation (e.g. a
            ``smooth_min_temperature`` to smooth the kinks).
        method: one of `METHODS`.
        tol: stop when the projected gradient of the normalised objective (the value
            divided by the starting value, parameters scaled to ``[0, 1]``) is below this.
        ftol, patience: stop (``stalled``) when the best value has not improved by more
            than ``ftol`` (relative) in ``patience`` iterations.
        callback: called as ``callback(iteration, value_J, grasp_params_u)`` after each
            iteration (for progress output).

    Returns:
        A [`TuneResult`][jaxgrasp.analysis.TuneResult]; ``result.grasp`` is the best grasp found.

    Raises:
        GraspValueError: invalid parameters or bounds, or a start that is not stable
            (value 0: unstable or infeasible), where the gradient is 0 and there is
            nothing to follow; the message names the status.
    """
    mesh_grasp = grasp if isinstance(grasp, MeshGrasp) else None
    grasp = _checked_grasp(grasp.grasp if mesh_grasp is not None else grasp, method, maxiter)
    specs = param_specs(params)
    box = ParamBox.build(specs, grasp, bounds)
    surface = _surface_of(mesh_grasp, specs)
    if surface is not None:  # the start is put on the surface: its normals may differ from those given
        box = dataclasses.replace(box, moved=True)
    vg = _compiled(specs, dataclasses.replace(options, smooth_min_temperature=None))
    data, rec, start_value = _start_search(vg, box, grasp, options.smooth_min_temperature, surface)
    stop = dict(maxiter=maxiter, tol=tol, ftol=ftol, patience=patience, callback=callback)
    status, iters, evals = run_search(method, vg, box.u0, data, rec, **stop)
    message = status.message.format(ftol=ftol, patience=patience, maxiter=maxiter)
    result = _result(specs, grasp, box, data, rec, status, iters, evals, method, message, start_value)
    if mesh_grasp is None:
        return result
    return dataclasses.replace(result, mesh_grasp=mesh_grasp.replace(grasp=result.grasp))


def _surface_of(mesh_grasp: MeshGrasp | None, specs) -> Surface | None:
    """The mesh's surface in the grasp's centre-of-mass frame, where positions are tuned
    on a mesh grasp; else ``None``."""
    if mesh_grasp is None or not any(s.name == "positions" for s in specs):
        return None
    return Surface.from_trimesh(mesh_grasp.mesh, pad_to=PAD_FACES).translated(-np.asarray(mesh_grasp.center_of_mass))


def _start_search(vg, box: ParamBox, grasp: Grasp, temperature, surface: Surface | None = None):
    """``(data, record, start_value)``: the objective's data (the grasp, the bounds, the
    face bases, the soft-minimum ``temperature`` in J or ``None``, the value scale: the
    start's value), the record holding the start, and the value of the grasp as given."""
    data = {
        "grasp": grasp,
        "lo": tuple(jnp.asarray(v) for v in box.los),
        "hi": tuple(jnp.asarray(v) for v in box.his),
        "basis": jnp.asarray(face_basis(grasp.normals)),
        "temperature": jnp.float64(0.0 if temperature is None else temperature / MJ_TO_J),
        "value_scale": jnp.float64(1.0),
        "as_given": jnp.asarray(False),
    }
    if surface is not None:
        data["surface"] = surface
    rec = SearchRecord.start(vg, box, data)
    data["value_scale"] = jnp.float64(rec.initial_value)
    start_value = _value_as_given(vg, box, data) if box.moved else rec.initial_value
    return data, rec, start_value


def _value_as_given(vg, box: ParamBox, data) -> float:
    """The value of the grasp as given, J, where the search starts elsewhere (clipped
    into the bounds): the same compiled function at ``as_given``, one more evaluation."""
    (_, ev), _ = vg(jnp.asarray(box.u0), {**data, "as_given": jnp.asarray(True)})
    v = float(ev.value)
    return v if math.isfinite(v) else 0.0


def _checked_grasp(grasp: Grasp, method: str, maxiter) -> Grasp:
    """The validated float64 grasp [`tune`][jaxgrasp.tune] starts from; one-line errors for bad calls."""
    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"tune: expected a jaxgrasp.Grasp, got {type(grasp).__name__}")
    if np.ndim(grasp.mass) != 0:
        raise GraspValueError("tune: takes one grasp, not a batch")
    grasp = Grasp(**{k: jnp.asarray(v, jnp.float64) for k, v in check_grasp_inputs(**grasp.to_numpy()).items()})
    if method not in METHODS:
        raise GraspValueError(f"tune: unknown method {method!r}; choose from {', '.join(METHODS)}")
    if not (isinstance(maxiter, (int, np.integer)) and not isinstance(maxiter, bool) and maxiter >= 1):
        raise GraspValueError(f"tune: maxiter must be an integer >= 1, got {maxiter!r}")
    problem = over_limit("tune: maxiter", maxiter, MAX_TUNE_ITERATIONS, TUNE_ITERATIONS_WHAT)
    if problem:
        raise GraspValueError(problem)
    return grasp


def _result(specs, grasp, box: ParamBox, data, rec: SearchRecord, status, iters, evals, method, message,
            start_value) -> TuneResult:
    """The [`TuneResult`][jaxgrasp.analysis.TuneResult] of a finished search."""
    v_best, u_best, ev_best = rec.best
    tuned = _apply(specs, jnp.asarray(u_best), data)
    tuned = jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a)), tuned)
    hst = np.asarray(rec.statuses, dtype=np.int32)
    n_nc = int(np.sum(hst == GraspStatus.NOT_CONVERGED))
    if box.clipped:
        message += f"; start of {', '.join(box.clipped)} clipped into the bounds"
    if n_nc:
        message += f"; {n_nc} iterate(s) had not-converged evaluations"
    if int(ev_best.status) == GraspStatus.NOT_CONVERGED:
        message += "; but the best iterate's evaluation did not converge: check it with jaxgrasp.evaluate before use"
    return TuneResult(
        grasp=tuned,
        value=v_best,
        initial_value=rec.initial_value,
        history=np.asarray(rec.history, dtype=np.float64),
        history_status=hst,
        params=labelled_params(specs, tuned, box.params(u_best)),
        initial_params=labelled_params(specs, grasp, box.x0s),
        bounds=labelled_bounds(specs, box, grasp.num_contacts),
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
