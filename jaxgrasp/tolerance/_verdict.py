"""Steps 2-6 of the method: from solved problems to the value, the status and the limiting boundary.

An evaluation of a grasp follows the paper (Sec. III, VI) in six steps, one named function
each:

1. solve the equilibrium problem and every boundary problem from its starts (the
   stages of `jaxgrasp.engine.PIPELINE` before its ``evaluation``);
2. keep the lowest converged start of each boundary problem (`best_starts`);
3. decide the grasp's status from the solver's outputs (`grasp_status`; Sec. III-B);
4. the minimum energies with their envelope-theorem derivatives (`energies`,
   `jaxgrasp.tolerance._envelope`);
5. the value, eq. 1: the least boundary energy above ``U0``, or a soft minimum
   (`value_of`);
6. the [`Evaluation`][jaxgrasp.Evaluation] in SI units (`to_evaluation`).

This module does steps 2-6 (`evaluation_of` for one grasp, `evaluations_of`
for a batch); the engine runs step 1 before them.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.model import MJ_TO_J, M_TO_MM, NO_BOUNDARY, Constraint, ModelParams
from jaxgrasp.solver import LaneStatus
from jaxgrasp.tolerance._envelope import envelope_energy, soft_minimum
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import Problems, constraints, problem_data, to_pose
from jaxgrasp.tolerance._result import Evaluation
from jaxgrasp.tolerance._status import GraspStatus

__all__ = [
    "split_temperature",
    "evaluations_of",
    "evaluation_of",
    "limiting_index",
    "Boundaries",
    "Verdict",
    "TIE_TOL",
    "initial_state_feasible",
    "SAME_MINIMUM",
]


TIE_TOL = 1e-8
"""Boundary energies within this fraction of the value of the least one are a tie (the
solver settles each to ``tol = 1e-10`` of the scaled energy, some ``1e-9`` of a typical
value); the limiting boundary is then the first of them in (kind, contact) order."""


def split_temperature(options: EvaluateOptions):
    """``(options, temperature)``: the smoothing temperature as a traced argument (mJ,
    ``0``: the hard minimum), so that evaluations with and without smoothing, or with
    different temperatures, share one compilation."""
    t = options.smooth_min_temperature
    if t is not None:
        options = dataclasses.replace(options, smooth_min_temperature=None)
    return options, np.float64(0.0 if t is None else float(t) / MJ_TO_J)


def evaluations_of(p: ModelParams, progs: Problems, temperature, options: EvaluateOptions) -> Evaluation:
    """Steps 2-6 for a batch of grasps ``p`` (`jaxgrasp.model.model_params` of each,
    leading axis ``B``): their evaluations from their solved problems ``progs``
    (`Problems` with the same leading axis;
    ``temperature``: mJ, ``0`` for the hard minimum)."""
    return jax.vmap(lambda p, progs: evaluation_of(p, progs, temperature, options))(p, progs)


def evaluation_of(p: ModelParams, progs: Problems, temperature, options: EvaluateOptions) -> Evaluation:
    """Steps 2-6 for one grasp ``p`` (internal units) whose problems ``progs`` are solved
    (``temperature``: mJ, ``0`` for the hard minimum)."""
    temperature = jnp.asarray(temperature, p.c.dtype)  # float32 grasps stay float32
    best = best_starts(progs, options.num_starts, options.boundary_tol)
    verdict = grasp_status(p, progs, best, options.boundary_tol)
    u_eq, u_b, v_eq, v_b = energies(p, progs.equilibrium, best, verdict.keep_value)
    value = value_of(v_eq, v_b, best.reached, verdict, temperature)
    return to_evaluation(progs, best, verdict, value, u_eq, u_b)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Boundaries:
    """Each boundary problem at its lowest converged start (``B = 2N`` problems,
    ``b = kind * N + contact``; scaled units as in `Problems`).

    Attributes:
        pick: ``(B,)`` lane index of the kept start.
        z: ``(B, 6)`` its solution (the equilibrium where the boundary was not reached).
        lam, nu: ``(B, 3N)``, ``(B,)`` its multipliers.
        objective: ``(B,)`` its scaled energy (the equilibrium's where not reached).
        reached: ``(B,)`` some start converged.
        status: ``(B,)`` [`LaneStatus`][jaxgrasp.solver.LaneStatus] of the problem: converged
            (reached), infeasible (every start infeasible or not started), not converged,
            or no start (the equilibrium did not converge).
        estimate: ``(B,)`` lowest scaled energy of a feasible start that did not converge
            (``+inf`` without one): tells whether an unsettled problem could limit.
    """

    pick: Any
    z: Any
    lam: Any
    nu: Any
    objective: Any
    reached: Any
    status: Any
    estimate: Any


SAME_MINIMUM = 3e-10
"""Converged lanes of one boundary problem whose energies above ``U0`` lie within this
(relative) of the lowest one's reached the same minimum: the solver stops at feasibility
and complementarity of 1e-10, and at stationarity of 1e-10 (or up to 1e-9 where phi is
too stiff to reach it, which moves the energy only at second order), so lanes at one
minimum end about that far apart. `best_starts` reports the first of them by
start, so the reported lane (its energy, pose and steps) does not depend on the rounding
of the executable it ran in (a single grasp, a batch, a grasp padded with inactive
contacts); the energy is at most this much above the lowest lane's."""


def best_starts(progs: Problems, num_starts: int, boundary_tol: float) -> Boundaries:
    """Keep the lowest converged start of each boundary problem (a missed lower point
    would overstate stability; of lanes at the same minimum, within
    `SAME_MINIMUM`, the first by start), and classify the problems that no start
    settled."""
    eq, lanes = progs.equilibrium, progs.boundary
    shape = (-1, num_starts)  # (2N, D)
    lane_status = jnp.where(progs.found, lanes.status, LaneStatus.NO_START).reshape(shape)
    lane_energy = jnp.where(lane_status == LaneStatus.CONVERGED, lanes.objective.reshape(shape), jnp.inf)
    low = jnp.min(lane_energy, axis=1, keepdims=True)
    # the first lane (by start) of those that reached the lowest minimum: which of them
    # ends lowest is rounding, and would differ between a single, a batched and a padded
    # executable (SAME_MINIMUM)
    same = lane_energy <= low + SAME_MINIMUM * jnp.maximum(low - eq.objective, 1e-300)
    best = jnp.argmax(same, axis=1)
    reached = jnp.isfinite(low[:, 0])
    unreachable = jnp.all((lane_status == LaneStatus.INFEASIBLE) | (lane_status == LaneStatus.NO_START), axis=1)
    status = jnp.where(
        reached,
        LaneStatus.CONVERGED,
        jnp.where(unreachable, LaneStatus.INFEASIBLE, LaneStatus.NOT_CONVERGED),
    )
    # without a converged equilibrium no boundary problem was started, nor any of an
    # inactive contact (whose lanes were never found)
    boundary_on = jnp.tile(progs.contact_on, 2)  # (2N,), b = kind * N + contact
    status = jnp.where((eq.status == LaneStatus.CONVERGED) & boundary_on, status, LaneStatus.NO_START)
    # Lowest feasible point of each boundary problem among lanes that did not converge
    # (e.g. degenerate active constraints, where multipliers grow without bound): an
    # estimate of that boundary's energy, used to tell whether it could be limiting.
    stalled_feasible = (lane_status == LaneStatus.NOT_CONVERGED) & (
        lanes.feasibility.reshape(shape) <= boundary_tol
    )
    estimate = jnp.min(jnp.where(stalled_feasible, lanes.objective.reshape(shape), jnp.inf), axis=1)
    pick = jnp.arange(reached.shape[0]) * num_starts + best
    return Boundaries(
        pick=pick,
        z=jnp.where(reached[:, None], lanes.x[pick], eq.x),
        lam=lanes.lam[pick],
        nu=lanes.nu[pick],
        objective=jnp.where(reached, lanes.objective[pick], eq.objective),
        reached=reached,
        status=status.astype(jnp.int32),
        estimate=estimate,
    )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Verdict:
    """The grasp's status and what decided it (no derivative).

    Attributes:
        status: ``()`` [`GraspStatus`][jaxgrasp.GraspStatus] code.
        limit: ``()`` index ``b`` of the lowest reached boundary problem (0 if none); of
            boundaries tied within `TIE_TOL` of the value, the first.
        any_reached: ``()`` some boundary problem was reached.
        keep_value: ``()`` the value is reported (stable or not converged).
        margins: ``(3, N)`` scaled constraint margins at the equilibrium.
    """

    status: Any
    limit: Any
    any_reached: Any
    keep_value: Any
    margins: Any


def limiting_index(objective, reached, equilibrium):
    """``()`` index of the limiting boundary problem: the least ``objective`` ``(B,)``
    among the ``reached`` ones (scaled energies; ``equilibrium``: the equilibrium's).

    Boundaries within the solver's accuracy of the least (`TIE_TOL` of the value,
    ``least - equilibrium``) are a tie, which goes to the first in (kind, contact) order:
    symmetric contacts then give the same limiting boundary whatever the rounding
    (padding, batching, platform). 0 where none is reached."""
    energies = jnp.where(reached, objective, jnp.inf)
    least = jnp.min(energies)
    tie = TIE_TOL * jnp.abs(least - equilibrium) + 1e-14 * jnp.abs(least)
    return jnp.argmax(energies <= least + tie)


def initial_state_feasible(p: ModelParams):
    """``()`` bool: the initial grasping state (no pose change) satisfies every constraint of
    ``p``'s active contacts, i.e. no fingertip starts above its force limit; the equilibrium
    region is then not empty."""
    zero = jnp.zeros(6, p.c.dtype)
    return jnp.min(jax.lax.stop_gradient(constraints(zero, problem_data(p)))) >= 0.0


def grasp_status(p: ModelParams, progs: Problems, best: Boundaries, boundary_tol: float) -> Verdict:
    """Decide the grasp's status from the solver's outputs only (no derivative)."""
    eq = progs.equilibrium
    n = p.c.shape[0]
    margins = jax.lax.stop_gradient(constraints(eq.x, problem_data(p))).reshape(3, n)
    load_margins = margins[Constraint.SLIP :]  # slip and force-limit rows
    on_boundary = jnp.min(load_margins) <= boundary_tol
    # An equilibrium problem that stalled (no KKT certificate: degenerate active constraints
    # make the multipliers grow without bound) at a feasible pose pressing a slip or force
    # constraint with a positive multiplier is on that boundary as well.
    stalled_on_boundary = (
        (eq.status == LaneStatus.NOT_CONVERGED)
        & (eq.feasibility <= boundary_tol)
        & jnp.any((load_margins <= boundary_tol) & (eq.lam.reshape(3, n)[Constraint.SLIP :] > 0.0))
    )
    any_reached = jnp.any(best.reached)
    limit = limiting_index(best.objective, best.reached, eq.objective)
    hard_scaled = best.objective[limit] - eq.objective  # value / energy scale
    # a boundary reached within the solver's accuracy of U0: the equilibrium is on it
    zero_value = any_reached & (hard_scaled <= boundary_tol)
    # a boundary problem that did not settle decides the status only if it could be
    # limiting: no feasible point of it found, or one at most a tenth above the value
    # (its energy is only an upper estimate of the problem's minimum)
    could_limit = ~(jnp.isfinite(best.estimate) & (best.estimate - eq.objective > 1.1 * hard_scaled))
    any_unsettled = jnp.any((best.status == LaneStatus.NOT_CONVERGED) & (could_limit | ~any_reached))
    # The region always holds the initial state unless a force limit is exceeded there
    # (no tangential deformation, no rotation yet: contact and slip margins are positive),
    # so an equilibrium lane that ends "infeasible" where it held is not an empty region:
    # the energy pulled the lane through a boundary with more than the largest penalty
    # could hold (a weight far beyond the fingertips' forces, or fingertips that let go at
    # the apex of their friction cones). The minimum then presses on that boundary.
    pulled_out = (eq.status == LaneStatus.INFEASIBLE) & initial_state_feasible(p)
    status = jnp.select(
        [
            pulled_out,
            eq.status == LaneStatus.INFEASIBLE,
            stalled_on_boundary,
            eq.status != LaneStatus.CONVERGED,
            on_boundary | zero_value,
            any_unsettled | ~any_reached,
        ],
        [
            GraspStatus.UNSTABLE,
            GraspStatus.INFEASIBLE,
            GraspStatus.UNSTABLE,
            GraspStatus.NOT_CONVERGED,
            GraspStatus.UNSTABLE,
            GraspStatus.NOT_CONVERGED,
        ],
        GraspStatus.STABLE,
    ).astype(jnp.int32)
    keep_value = (status == GraspStatus.STABLE) | (status == GraspStatus.NOT_CONVERGED)
    return Verdict(status=status, limit=limit, any_reached=any_reached, keep_value=keep_value, margins=margins)


def _all_finite(*xs):
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in xs]))


def energies(p: ModelParams, eq, best: Boundaries, keep_value):
    """Minimum energies with envelope-theorem derivatives, mJ: ``(u_eq, u_b, v_eq, v_b)``.

    ``u_*`` are the reported energies (derivative wherever the problem was solved),
    ``v_*`` the value's (derivative only where the value uses them); ``u_b``, ``v_b`` are
    ``(2N,)`` and ``+inf`` where the boundary was not reached. A problem whose solution is
    not used is differentiated at a safe point (initial state, zero multipliers), where
    the Lagrangian's partials are finite: a zero cotangent then gives an exact zero.
    """
    n = p.c.shape[0]
    zeros_mask = jnp.zeros(3 * n, p.c.dtype)
    b_masks = jax.nn.one_hot(n + jnp.arange(2 * n), 3 * n, dtype=p.c.dtype)
    eq_finite = _all_finite(eq.x, eq.lam, eq.nu)
    b_finite = jax.vmap(_all_finite)(best.z, best.lam, best.nu)

    def energy_pair(use_eq, use_b):
        u_eq = envelope_energy(
            p,
            jnp.where(use_eq, eq.x, 0.0),
            jnp.where(use_eq, eq.lam, 0.0),
            jnp.where(use_eq, eq.nu, 0.0),
            zeros_mask,
            eq.objective,
        )
        u_b = jax.vmap(envelope_energy, in_axes=(None, 0, 0, 0, 0, 0))(
            p,
            jnp.where(use_b[:, None], best.z, 0.0),
            jnp.where(use_b[:, None], best.lam, 0.0),
            jnp.where(use_b, best.nu, 0.0),
            b_masks,
            best.objective,
        )
        return u_eq, jnp.where(best.reached, u_b, jnp.inf)

    u_eq, u_b = energy_pair(eq_finite, best.reached & b_finite)
    v_eq, v_b = energy_pair(keep_value & eq_finite, keep_value & best.reached & b_finite)
    return u_eq, u_b, v_eq, v_b


def value_of(v_eq, v_b, reached, verdict: Verdict, temperature):
    """The value, mJ: hard (``temperature == 0``) or soft minimum over the reachable
    boundaries of ``v_b - v_eq``, clipped at 0; 0 unless the verdict keeps the value."""
    hard = v_b[verdict.limit] - v_eq
    smooth = temperature > 0.0
    soft = soft_minimum(v_b - v_eq, reached, jnp.where(smooth, temperature, 1.0))
    raw = jnp.where(verdict.any_reached, jnp.where(smooth, soft, hard), 0.0)
    return jnp.where(verdict.keep_value, jnp.maximum(raw, 0.0), 0.0)


def _kkt(r):
    return jnp.stack([r.stationarity, r.feasibility, r.complementarity], axis=-1)


def to_evaluation(progs: Problems, best: Boundaries, verdict: Verdict, value, u_eq, u_b) -> Evaluation:
    """Pack the results in SI units (J, m, rad) as an [`Evaluation`][jaxgrasp.Evaluation]."""
    eq, lanes = progs.equilibrium, progs.boundary
    n = verdict.margins.shape[-1]
    has_limit = verdict.keep_value & verdict.any_reached
    eq_pose = to_pose(eq.x, progs.lever)
    b_pose = jax.vmap(lambda z: to_pose(z, progs.lever))(best.z)
    return Evaluation(
        value=value * MJ_TO_J,
        status=verdict.status,
        limiting_kind=jnp.where(has_limit, verdict.limit // n, NO_BOUNDARY).astype(jnp.int32),
        limiting_contact=jnp.where(has_limit, verdict.limit % n, NO_BOUNDARY).astype(jnp.int32),
        equilibrium_energy=u_eq * MJ_TO_J,
        equilibrium_translation=eq_pose[:3] / M_TO_MM,
        equilibrium_rotation=eq_pose[3:],
        boundary_energy=(u_b * MJ_TO_J).reshape(2, n),
        boundary_translation=(b_pose[:, :3] / M_TO_MM).reshape(2, n, 3),
        boundary_rotation=b_pose[:, 3:].reshape(2, n, 3),
        boundary_status=best.status.reshape(2, n),
        equilibrium_status=eq.status,
        equilibrium_margins=verdict.margins,
        kkt=jnp.concatenate([_kkt(eq)[None], jnp.where(best.reached[:, None], _kkt(lanes)[best.pick], jnp.nan)]),
        steps=jnp.concatenate([eq.steps[None], lanes.steps[best.pick]]),
    )
