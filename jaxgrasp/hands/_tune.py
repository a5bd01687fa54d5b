"""Tuning a hand's grasp: maximise the evaluation value over its joint angles (and wrist).

[`tune_hand`][jaxgrasp.tune_hand] maximises ``evaluate(hand.grasp(qpos, mesh, ...).grasp).value`` over the
joint positions within their limits (optionally the wrist pose within a box around its
start), keeping the hand's other links out of the object. The value's gradient with
respect to ``qpos`` is the envelope theorem's gradient with respect to the grasp's fields
([`jaxgrasp.evaluate`][jaxgrasp.evaluate]) chained through the contact (the closest surface point moves
within its face) and the hand's kinematics. As [`jaxgrasp.tune`][jaxgrasp.tune] does, the value and
its gradient are compiled once (per hand, [`EvaluateOptions`][jaxgrasp.EvaluateOptions] and mesh
size; kept in the executable store, so later processes load them) and SciPy's L-BFGS-B
runs on them in the box of the joint limits scaled to ``[0, 1]``
(`jaxgrasp.analysis._tune_drivers.run_search`).

Couplings: the hand's joint couplings (limited fixed tendons, linear joint equalities;
[`Hand.project_joints`][jaxgrasp.Hand.project_joints]) are kept by evaluating, at every
iterate ``q`` of the search (which stays in the box of the limits), the configuration
``project_joints(q)``, the value's gradient chained through the projection; every iterate
evaluated, and the result, are within the limits and the couplings. The start must satisfy
the couplings already (within `COUPLING_TOLERANCE`): one outside them is one the hand
cannot hold, and is refused.

Penetration: the hand's other links are sampled ([`link_depths`][jaxgrasp.Hand.link_depths],
`jaxgrasp.hands._links`), each sample's depth in the object measured by the signed
distance to the same surface the contacts use, and the hand's own collision pairs'
overlaps ([`Hand.self_overlap`][jaxgrasp.Hand.self_overlap]: fingers passing through each other) count as
depths too; the objective adds
``penetration_weight * sum(max(depth, 0)^2) / (1 mm)^2`` to minus the value over the
start's value, and the best iterate is the one of highest value whose deepest sample is
at most ``max_penetration``.
"""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.analysis import TuneStatus, run_search
from jaxgrasp.base import json_floats
from jaxgrasp.engine import COMPILER_OPTIONS, StoredFunction, value_and_grad_builder
from jaxgrasp.hands._couplings import COUPLING_TOLERANCE
from jaxgrasp.hands._grasp import DEFAULT_MAX_TILT, HandGrasp, _pose, contact_grasp, hand_grasp, material
from jaxgrasp.model import DEFAULT_GRAVITY, GraspValueError
from jaxgrasp.tolerance import EVALUATION_TREE, EvaluateOptions, GraspStatus

__all__ = ["tune_hand", "HandTuneResult", "HandValue", "hand_value", "PENETRATION_UNIT"]

PENETRATION_UNIT = 1e-3
"""m: the penetration penalty is ``weight * sum(depth^2) / PENETRATION_UNIT^2``."""

@lru_cache(maxsize=16)
def _compiled(hand, options: EvaluateOptions, max_tilt: float):
    """``core(x, data) -> (value, dvalue_dx, penalty, dpenalty_dx, evaluation, deepest, tilt, qpos, in_contact)``,
    one per key; ``x = (qpos, wrist)`` ``(J + 6,)``; ``qpos`` ``(J,)`` the joints evaluated:
    ``hand.project_joints(x[:J])`` where ``data["project"]`` is true (`tune_hand`, the
    gradients chained through it), ``x[:J]`` itself otherwise (`hand_value`), one program
    for both. Compiled once per mesh size and kept in the executable store
    (`StoredFunction`), keyed by the hand's content ([`digest`][jaxgrasp.Hand.digest],
    couplings included)."""
    j = hand.num_joints

    def joints(x, data):
        return jnp.where(data["project"], hand.project_joints(x[:j]), x[:j])

    def grasp_of(x, data):
        grasp, tilt, _ = contact_grasp(hand, joints(x, data), x[j:], data["object_pose"], data["surface"],
                                       data["material"], max_tilt)
        return grasp, (tilt, grasp.active)

    value = value_and_grad_builder(grasp_of, options, counts=lambda grasp: jnp.sum(grasp.active) >= 2)

    def penalty(x, data):
        q = joints(x, data)
        depth = jnp.concatenate([hand.link_depths(q, x[j:], data["object_pose"], data["surface"]), hand.self_overlap(q)])
        return jnp.sum(jnp.maximum(depth, 0.0) ** 2) / PENETRATION_UNIT**2, jnp.max(depth)

    def core(x, data):
        (v, (ev, (tilt, active))), gv = value(x, data)
        (p, deepest), gp = jax.value_and_grad(penalty, has_aux=True)(x, data)
        return v, gv, p, jnp.where(jnp.isfinite(gp), gp, 0.0), ev, deepest, tilt, joints(x, data), jnp.sum(active)

    leaf = jax.tree_util.tree_structure(0.0)
    out_tree = jax.tree_util.treedef_tuple((leaf,) * 4 + (EVALUATION_TREE, leaf, leaf, leaf, leaf))
    # The hand's arrays are constants of the program: its digest stands for them.
    return StoredFunction(core, (hand.digest(), options, max_tilt), out_tree, name="tune-hand",
                          compiler_options=COMPILER_OPTIONS,
                          what=f"tune_hand's value and gradient ({hand.num_joints} joints)")


@dataclasses.dataclass(frozen=True)
class HandValue:
    """The value of a hand's grasp and its gradient (SI units; [`hand_value`][jaxgrasp.hands.hand_value]).

    Attributes:
        value: J, the evaluation value (0 with fewer than 2 fingertips in contact).
        grad_qpos: ``(J,)`` J/rad (J/m for slides), its gradient with respect to ``qpos``.
        grad_wrist: ``(6,)`` its gradient with respect to the wrist pose.
        evaluation: the [`Evaluation`][jaxgrasp.Evaluation].
        deepest: m, the deepest penetration of the hand's other links in the object or of two of
            its links in each other (negative: clear).
        tilt: ``(F,)`` rad, each fingertip's tilt.
    """

    value: float
    grad_qpos: np.ndarray
    grad_wrist: np.ndarray
    evaluation: object
    deepest: float
    tilt: np.ndarray

    @property
    def status(self) -> GraspStatus:
        """The evaluation's status, a [`GraspStatus`][jaxgrasp.GraspStatus]."""
        return GraspStatus(int(np.asarray(self.evaluation.status)))

    @property
    def status_name(self) -> str:
        """The name of ``status`` (``'stable'``, ...)."""
        return self.status.label

    def summary(self) -> str:
        """One line: the status, the value (J), the gradient's size and the deepest link."""
        grad = float(np.linalg.norm(np.concatenate([np.ravel(self.grad_qpos), np.ravel(self.grad_wrist)])))
        return (f"{self.status_name}: value {self.value:.6e} J, gradient norm {grad:.3e}, deepest link "
                f"penetration {self.deepest * 1e3:.3f} mm")

    def to_dict(self) -> dict:
        """As plain Python (JSON-ready, ``None`` where not finite): ``value`` (J),
        ``status`` by name, ``grad_qpos``, ``grad_wrist``, ``deepest`` (m), ``tilt``
        (rad) and ``evaluation`` ([`Evaluation.to_dict`][jaxgrasp.Evaluation.to_dict])."""
        return {"value": json_floats(self.value), "status": self.status_name, "grad_qpos": json_floats(self.grad_qpos),
                "grad_wrist": json_floats(self.grad_wrist), "deepest": json_floats(self.deepest), "tilt": json_floats(self.tilt),
                "evaluation": self.evaluation.to_dict()}




def _setup(hand, mesh, kw):
    """``(data, mesh)``: the objective's data for a mesh and the grasp fields ``kw``."""
    from jaxgrasp.io import load_mesh
    from jaxgrasp.surface import PAD_FACES, Surface

    mesh = load_mesh(mesh, kw.pop("units", "m"))
    mat = material(hand.num_fingertips, mesh, kw.pop("young_modulus"), kw.pop("friction"), kw.pop("max_force"),
                   kw.pop("mass", None), kw.pop("density", None), kw.pop("gravity", DEFAULT_GRAVITY),
                   kw.pop("center_of_mass", None))
    if kw:
        raise GraspValueError(f"unknown argument {sorted(kw)[0]!r}")
    data = {"surface": Surface.from_trimesh(mesh, pad_to=PAD_FACES), "material": mat}
    return data, mesh


def hand_value(hand, qpos, mesh, *, wrist=None, object_pose=None, options: EvaluateOptions = EvaluateOptions(),
               max_tilt: float = DEFAULT_MAX_TILT, **fields) -> HandValue:
    """The value of the grasp ``hand.grasp(qpos, mesh, ...)`` and its gradient with respect
    to ``qpos`` and the wrist, from the function [`tune_hand`][jaxgrasp.tune_hand] compiles (so the two
    share one compilation). ``fields``: ``young_modulus``, ``friction``, ``max_force``,
    ``mass`` or ``density``, ``gravity``, ``center_of_mass``, ``units``, as for
    [`grasp`][jaxgrasp.Hand.grasp]. ``qpos`` is evaluated as given, within the couplings or not
    ([`tune_hand`][jaxgrasp.tune_hand] evaluates [`project_joints`][jaxgrasp.Hand.project_joints] of its
    iterates; the two agree, value and gradient, on a configuration within the limits and couplings)."""
    data, _ = _setup(hand, mesh, dict(fields))
    data["object_pose"] = _pose(object_pose, "object_pose")
    data["project"] = np.bool_(False)  # the value at qpos as given, as hand.grasp(qpos) makes it
    x = jnp.concatenate([jnp.asarray(hand.check_qpos(qpos)), _pose(wrist, "wrist")])
    v, gv, _, _, ev, deepest, tilt, _, _ = _compiled(hand, options, float(max_tilt))(x, data)
    j = hand.num_joints
    gv = np.asarray(gv)
    return HandValue(float(v), gv[:j], gv[j:], jax.tree_util.tree_map(np.asarray, ev), float(deepest), np.asarray(tilt))


class _Record:
    """Every iterate's value, deepest penetration and status; the best admissible one
    (highest value with its deepest link sample at most ``max_penetration`` and at least
    ``min_fingertips`` fingertips in contact)."""

    def __init__(self, x0, aux, max_penetration: float, min_fingertips: int = 2):
        self.limit, self.fewest = max_penetration, min_fingertips
        self.history, self.depths, self.statuses = [], [], []
        self.best = None
        self.add(x0, aux)

    def add(self, x, aux) -> float:
        v, ev, deepest, qpos, count = aux
        status = int(ev.status)
        self.history.append(float(v))
        self.depths.append(float(deepest))
        self.statuses.append(status)
        ok = (status in (GraspStatus.STABLE, GraspStatus.NOT_CONVERGED) and float(deepest) <= self.limit
              and int(count) >= self.fewest)
        if ok and (self.best is None or float(v) > self.best[0]):
            self.best = (float(v), np.array(x), ev, np.array(qpos))
        return float(v)


@dataclasses.dataclass(frozen=True)
class HandTuneResult:
    """Outcome of [`tune_hand`][jaxgrasp.tune_hand] (SI units).

    Attributes:
        qpos: ``(J,)`` the tuned joint positions (the best admissible iterate, projected
            within the limits and couplings: [`project_joints`][jaxgrasp.Hand.project_joints]).
        wrist: ``(6,)`` the tuned wrist pose (the start's unless ``tune_wrist``).
        grasp: the [`HandGrasp`][jaxgrasp.hands.HandGrasp] there.
        value: its evaluation value, J. start_value: the start's (the value before
            tuning), J.
        deepest: m, the deepest penetration of the other links there, in the object or of two
            links in each other (`HandValue`; negative: clear).
        start_deepest: m, the same at the start.
        history: ``(iterations + 1,)`` value at the start and after each iteration, J.
        depth_history: ``(iterations + 1,)`` deepest link penetration there, m.
        status: a [`TuneStatus`][jaxgrasp.analysis.TuneStatus] (how L-BFGS-B stopped;
            [`status_name`][jaxgrasp.hands.HandTuneResult.status_name] its name).
        iterations, evaluations: optimiser iterations, value-and-gradient evaluations.
        message: one line: the status's explanation.
    """

    qpos: np.ndarray
    wrist: np.ndarray
    grasp: HandGrasp
    value: float
    start_value: float
    deepest: float
    start_deepest: float
    history: np.ndarray
    depth_history: np.ndarray
    status: TuneStatus
    iterations: int
    evaluations: int
    message: str

    @property
    def gain(self) -> float:
        """``value / start_value``."""
        return self.value / self.start_value if self.start_value > 0 else math.inf

    def summary(self) -> str:
        """One line: value before -> after, the gain, the deepest link penetration, the status."""
        return (f"hand tuned: {self.start_value:.6e} J -> {self.value:.6e} J (x{self.gain:.4f}), deepest link "
                f"penetration {self.deepest * 1e3:.3f} mm, {self.iterations} iterations, {self.status}: {self.message}")

    @property
    def status_name(self) -> str:
        """The name of ``status`` (``'converged'``), a plain ``str``."""
        return TuneStatus(self.status).label

    @property
    def converged(self) -> bool:
        """``status`` is ``"converged"`` or ``"stalled"``, as [`TuneResult.converged`][jaxgrasp.analysis.TuneResult.converged]."""
        return TuneStatus(self.status).converged

    def to_dict(self) -> dict:
        """The tuning as plain Python (JSON-ready, ``None`` where not finite): ``qpos``,
        ``wrist``, ``value`` and ``start_value`` (J), ``gain``, ``deepest`` and
        ``start_deepest`` (m), ``history`` (J), ``depth_history`` (m), ``status`` by name,
        ``converged``, ``iterations``, ``evaluations``, ``message``; the tuned grasp is
        the configuration (``qpos``, ``wrist``), not repeated."""
        return {
            "qpos": json_floats(self.qpos), "wrist": json_floats(self.wrist), "value": json_floats(self.value),
            "start_value": json_floats(self.start_value), "gain": json_floats(self.gain), "deepest": json_floats(self.deepest),
            "start_deepest": json_floats(self.start_deepest), "history": json_floats(self.history),
            "depth_history": json_floats(self.depth_history), "status": self.status_name, "converged": self.converged,
            "iterations": int(self.iterations), "evaluations": int(self.evaluations), "message": self.message,
        }


def _bounds(hand, q0, w0, tune_wrist: bool, wrist_bounds):
    """``(lo, hi)`` ``(J + 6,)`` of ``x = (qpos, wrist)``: the joint limits (the start
    where a joint is unlimited), the wrist within ``wrist_bounds = (m, rad)`` of its start
    when tuned, fixed otherwise."""
    lo = np.where(np.isfinite(hand.lower), hand.lower, q0)
    hi = np.where(np.isfinite(hand.upper), hand.upper, q0)
    if np.any(q0 < lo - 1e-12) or np.any(q0 > hi + 1e-12):
        k = int(np.argmax((q0 < lo - 1e-12) | (q0 > hi + 1e-12)))
        raise GraspValueError(f"qpos0[{k}] = {q0[k]:g} ({hand.joint_names[k]}) lies outside its limits [{lo[k]:g}, {hi[k]:g}]")
    span = np.repeat(np.asarray(wrist_bounds, dtype=np.float64), 3) if tune_wrist else np.zeros(6)
    return np.concatenate([lo, w0 - span]), np.concatenate([hi, w0 + span])


def tune_hand(hand, mesh, qpos0, wrist0=None, *, object_pose=None, tune_wrist: bool = False,
              wrist_bounds=(0.01, 0.1), penetration_weight: float = 10.0, max_penetration: float = 1e-3,
              maxiter: int = 50, ftol: float = 1e-7, tol: float = 1e-6, options: EvaluateOptions = EvaluateOptions(),
              max_tilt: float = DEFAULT_MAX_TILT, min_fingertips: int = 2, callback=None, **fields) -> HandTuneResult:
    """Maximise the evaluation value of ``hand``'s grasp on ``mesh`` over its joint angles.

    Args:
        hand: a [`Hand`][jaxgrasp.Hand]. mesh: the object (as for [`grasp`][jaxgrasp.Hand.grasp]).
        qpos0: ``(J,)`` the start, within the joint limits and the couplings (within
            `COUPLING_TOLERANCE`, 1e-9 m or rad); its grasp must be stable.
        wrist0: ``(6,)`` the wrist pose (translation m, rotation vector rad; ``None``: 0).
        object_pose: ``(6,)`` the object's mesh frame in the world.
        tune_wrist: also move the wrist, within ``wrist_bounds = (m, rad)`` of ``wrist0``.
        penetration_weight: weight of the links' penetration penalty (module notes).
        max_penetration: m, the deepest link penetration an accepted iterate may have.
        maxiter, ftol, tol: L-BFGS-B's iteration limit and stopping tolerances (on minus
            the value over the start's value, variables scaled to ``[0, 1]``).
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] of every evaluation.
        max_tilt: rad, see [`grasp`][jaxgrasp.Hand.grasp].
        min_fingertips: the fewest fingertips in contact an accepted iterate has (the
            start must have as many).
        callback: ``callback(iteration, value_J, x)`` after each iteration.
        fields: ``young_modulus``, ``friction``, ``max_force``, ``mass`` or ``density``,
            ``gravity``, ``center_of_mass``, ``units`` as for [`grasp`][jaxgrasp.Hand.grasp].

    Returns:
        A [`HandTuneResult`][jaxgrasp.hands.HandTuneResult]: the configuration, its grasp, the
        history and a [`TuneStatus`][jaxgrasp.analysis.TuneStatus].

    Raises:
        GraspValueError: a start outside the limits or the couplings (naming the worst
            coupling, its value and range), with value 0 (not stable: nothing to follow) or
            whose links penetrate deeper than ``max_penetration``; one line.
    """
    data, mesh = _setup(hand, mesh, dict(fields))
    data["object_pose"] = _pose(object_pose, "object_pose")
    data["project"] = np.bool_(True)
    q0, w0 = hand.check_qpos(qpos0, "qpos0"), np.asarray(_pose(wrist0, "wrist0"))
    lo, hi = _bounds(hand, q0, w0, tune_wrist, wrist_bounds)
    _check_couplings(hand, q0)
    core = _compiled(hand, options, float(max_tilt))
    x0 = np.concatenate([q0, w0])
    v0, _, _, _, ev0, deep0, _, p0, n0 = core(jnp.asarray(x0), data)
    _check_start(float(v0), ev0, float(deep0), max_penetration, int(n0), min_fingertips)
    scale = {"value": float(v0)}
    vg = _objective(core, lo, hi, scale, penetration_weight)
    u0 = np.where(hi > lo, (x0 - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0)
    rec = _Record(u0, (float(v0), ev0, float(deep0), p0, int(n0)), max_penetration, min_fingertips)
    status, iters, evals = run_search("scipy_lbfgsb", vg, u0, data, rec, maxiter=maxiter, tol=tol, ftol=ftol,
                                      patience=4, callback=callback)
    v_best, u_best, _, q_best = rec.best
    x = np.concatenate([q_best, (lo + (hi - lo) * u_best)[hand.num_joints:]])  # the joints evaluated: projected
    hg = hand_grasp(hand, x[: hand.num_joints], mesh, wrist=x[hand.num_joints:], object_pose=object_pose, max_tilt=max_tilt,
                    young_modulus=data["material"].young_modulus, friction=data["material"].friction,
                    max_force=data["material"].max_force, mass=float(data["material"].mass),
                    gravity=np.asarray(data["material"].gravity), center_of_mass=np.asarray(data["material"].center_of_mass))
    best = rec.history.index(v_best) if v_best in rec.history else 0
    message = status.message.format(ftol=ftol, patience=4, maxiter=maxiter)
    return HandTuneResult(x[: hand.num_joints], x[hand.num_joints:], hg, v_best, float(v0), rec.depths[best], float(deep0),
                          np.asarray(rec.history), np.asarray(rec.depths), status, iters, int(evals) + 1, message)


def _check_couplings(hand, q0: np.ndarray) -> None:
    """A start outside the hand's couplings by more than `COUPLING_TOLERANCE` is an error
    (one line naming the worst coupling, its value and range)."""
    if hand.tree.num_couplings == 0:
        return
    violation = np.asarray(hand.coupling_violation(q0))
    k = int(np.argmax(violation))
    if violation[k] > COUPLING_TOLERANCE:
        t = hand.tree
        value = float(t.coupling_matrix[k] @ q0)
        raise GraspValueError(
            f"tune_hand: qpos0 is one the hand cannot hold: its coupling {t.coupling_names[k]!r} is {value:.6g}, "
            f"outside its range [{t.coupling_lower[k]:.6g}, {t.coupling_upper[k]:.6g}] by {violation[k]:.3g} "
            f"(Hand.project_joints gives a configuration within it)")


def _check_start(v0: float, ev0, deep0: float, max_penetration: float, count: int = 2, fewest: int = 2) -> None:
    """A start with value 0, links too deep in the object or in each other, or fewer than ``fewest`` fingertips
    in contact (it has ``count``) is an error (one line)."""
    if not (v0 > 0.0 and math.isfinite(v0)):
        raise GraspValueError(
            f"tune_hand: the start has value {v0:g} J (status {GraspStatus(int(ev0.status)).label}): its gradient is 0, "
            "so there is nothing to follow; start from a stable grasp (at least 2 fingertips pressed into the object)"
        )
    if deep0 > max_penetration:
        raise GraspValueError(
            f"tune_hand: at the start a link lies {deep0 * 1e3:.3g} mm deep in the object or in another of the "
            f"hand's links (max_penetration {max_penetration * 1e3:.3g} mm; Hand.link_depths, Hand.self_overlap): "
            "start from a configuration whose links are clear"
        )
    if count < fewest:
        raise GraspValueError(f"tune_hand: the start has {count} fingertips in contact, fewer than min_fingertips = "
                              f"{fewest}")


def _objective(core, lo, hi, scale, weight: float):
    """``vg(u, data) -> ((f, (value, evaluation, deepest, qpos)), grad)`` on ``[0, 1]^(J + 6)``:
    ``f = -value / start value + weight * penalty``, ``qpos`` the joints evaluated, ``in_contact``
    the fingertips in contact there, for `run_search`."""
    span = jnp.asarray(hi - lo)

    def vg(u, data):
        x = jnp.asarray(lo) + span * jnp.asarray(u)
        v, gv, p, gp, ev, deepest, _, qpos, count = core(x, data)
        f = -float(v) / scale["value"] + weight * float(p)
        g = (-np.asarray(gv) / scale["value"] + weight * np.asarray(gp)) * np.asarray(span)
        return (jnp.float64(f), (float(v), ev, float(deepest), np.asarray(qpos), int(count))), jnp.asarray(g)

    return vg
