"""The 1 + 2N problems of a grasp (eq. 1; Sec. VI), their derivatives, and the
`Problems` type that holds them solved.

* the *equilibrium* problem ``U0 = min U`` subject to every contact, friction and
  force-limit constraint, solved from the initial grasping state;
* for each contact ``j`` a *slip* problem (friction of ``j`` as an equality, eq. 20) and
  a *max_force* problem (force limit of ``j`` as an equality, eq. 21), each with every
  other constraint kept.

Every problem has the same scaled objective and constraints (`objective`,
`constraints`), in the scaled pose ``z = (dp [mm], lever * w [mm])`` so that
rotations and translations move the contacts by comparable amounts, with the energy
divided by the initial elastic energy. A boundary problem is one equality row of the
same constraint vector (``eq_mask``), so every problem of every grasp runs as a lane of
one `jaxgrasp.solver.solve_lanes` call. `lane_problem` gives the solver the
first and second derivatives written from the contact kinematics
(`jaxgrasp.model._potential.kinematics_jacobian`) instead of autodiff.

The starts of the boundary problems are found in `jaxgrasp.tolerance._starts`,
stalled lanes are settled in `jaxgrasp.tolerance._settle`, and
the engine's pipeline (`jaxgrasp.engine.PIPELINE`) runs the whole sequence.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from jaxgrasp.model import (
    ModelParams,
    constraint_margins,
    contact_gradients,
    contact_hessians,
    energy_and_margins,
    energy_of,
    energy_scale,
    kinematics_curvature,
    kinematics_jacobian,
    margins_of,
    potential_energy,
)
from jaxgrasp.base import contract
from jaxgrasp.solver import FirstOrder, Problem, SolverResult
from jaxgrasp.tolerance._options import EvaluateOptions

__all__ = [
    "ProblemData",
    "problem_data",
    "to_pose",
    "objective",
    "constraints",
    "objective_and_constraints",
    "lane_problem",
    "lagrangian",
    "Problems",
    "problems_treedef",
    "batch_data",
]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ProblemData:
    """What the problems of one grasp depend on (a pytree; one per lane under ``solve_lanes``).

    Attributes:
        params: the grasp in internal units (`jaxgrasp.model.ModelParams`).
        lever: ``()`` mm, the length that scales rotations in ``z`` (no gradient).
        scale: ``()`` mJ, the energy scale dividing the objective (no gradient).
    """

    params: ModelParams
    lever: Any
    scale: Any


def problem_data(p: ModelParams) -> ProblemData:
    """The scaling of ``p``'s problems: lever = largest contact distance or radius, scale =
    initial elastic energy (active contacts only); both constants (``stop_gradient``)."""
    reach = jnp.where(p.on, jnp.maximum(jnp.linalg.norm(p.c, axis=-1), p.r), 0.0)
    lever = jax.lax.stop_gradient(jnp.max(reach))
    return ProblemData(params=p, lever=lever, scale=energy_scale(p))


def to_pose(z, lever):
    """Scaled pose ``z = (dp [mm], lever * w [mm])`` -> pose change ``x = (dp [mm], w [rad])``."""
    return jnp.concatenate([z[:3], z[3:] / lever])


def objective(z, data: ProblemData):
    """Scaled potential energy ``U(z) / scale`` (dimensionless), ``z`` of shape ``(6,)``."""
    return potential_energy(to_pose(z, data.lever), data.params) / data.scale


def constraints(z, data: ProblemData):
    """Scaled constraint margins ``(3N,)``, rows of `jaxgrasp.model.constraint_margins`
    flattened (index ``row * N + contact``), ``>= 0`` where satisfied."""
    return constraint_margins(to_pose(z, data.lever), data.params).reshape(-1)


def objective_and_constraints(z, data: ProblemData):
    """``(objective(z, data), constraints(z, data))`` from one evaluation of the contact
    kinematics: the function the solver's lanes run (`jaxgrasp.solver.solve`'s ``fg``)."""
    energy, margins = energy_and_margins(to_pose(z, data.lever), data.params)
    return energy / data.scale, margins.reshape(-1)


def _pose_scale(data: ProblemData, dtype):
    """``(6,)`` ``dx/dz``: 1 for the translation, ``1 / lever`` for the rotation."""
    one = jnp.ones(3, dtype)
    return jnp.concatenate([one, one / data.lever])


def _first_order(z, data: ProblemData) -> FirstOrder:
    """The problem at ``z`` with its gradient and constraint Jacobian, from the contact
    kinematics' Jacobian (`jaxgrasp.model._potential.kinematics_jacobian`) and each contact's
    derivatives in its own kinematics (`jaxgrasp.model._potential.contact_gradients`), both
    kept in ``aux`` for `_lagrangian_hessian`."""
    p = data.params
    x = to_pose(z, data.lever)
    q, dq, geometry = kinematics_jacobian(x, p)
    de, dm = contact_gradients(tuple(q.T), p)  # (N, 4), (3, N, 4)
    scale = _pose_scale(data, z.dtype)
    gravity = jnp.concatenate([p.weight, jnp.zeros(3, z.dtype)])
    grad_f = (contract("nk,nkj->j", de, dq) - gravity) * scale / data.scale
    jac = contract("rnk,nkj->rnj", dm, dq).reshape(-1, 6) * scale  # (3N, 6)
    fx = energy_of(x, tuple(q.T), p) / data.scale
    return FirstOrder(fx, margins_of(tuple(q.T), p).reshape(-1), grad_f, jac, aux=(q, dq, geometry, de, dm))


def _lagrangian_hessian(d: FirstOrder, z, weights, gauss_newton, data: ProblemData):
    """``(6, 6)`` Hessian in ``z`` of ``f + weights . g`` (``weights`` ``(3N,)`` fixed) plus
    ``J^T diag(gauss_newton) J`` (``gauss_newton`` ``(3N,)``, ``J`` the constraints'
    Jacobian in ``z``), from the kinematics' derivatives in ``d.aux``
    (`kinematic_hessian`), with ``psi_i`` contact ``i``'s share of the function of
    its own kinematics and its ``4 x 4`` Hessian
    `jaxgrasp.model._potential.contact_hessians`, written out.

    Row ``(r, i)`` of ``J`` is ``dm_ri . dq_i`` (times the pose scale), so the
    Gauss-Newton term is contact ``i``'s ``dq_i^T (sum_r gn_ri dm_ri dm_ri^T) dq_i``: a
    ``4 x 4`` block added to ``H_i`` in ``q_i``."""
    p = data.params
    q, dq, geometry, de, dm = d.aux
    w = weights.reshape(3, -1)
    he, hm = contact_hessians(tuple(q.T), p)
    gq = de / data.scale + contract("rn,rnk->nk", w, dm)  # (N, 4): d psi_i / dq_i
    hq = (he / data.scale + contract("rn,rnkl->nkl", w, hm)
          + contract("rn,rnk,rnl->nkl", gauss_newton.reshape(3, -1), dm, dm))  # (N, 4, 4)
    return kinematic_hessian(z, data, dq, geometry, gq, hq)


def kinematic_hessian(z, data: ProblemData, dq, geometry, gq, hq):
    """``(6, 6)`` Hessian in ``z`` of ``sum_i psi_i(q_i)``, a sum of functions of each
    contact's own kinematics ``q_i = (d, cos phi, dt^2, theta)``, from their gradients
    ``gq`` ``(N, 4)`` and Hessians ``hq`` ``(N, 4, 4)`` in ``q_i`` and the kinematics'
    Jacobian ``dq`` ``(N, 4, 6)`` and ``geometry`` at ``z``
    (`jaxgrasp.model._potential.kinematics_jacobian`): ``sum_i dq_i^T H_i dq_i +
    sum_ik (d psi_i / d q_ik) d2q_ik``, the second sum
    `jaxgrasp.model._potential.kinematics_curvature`."""
    hd = contract("nkl,nlj->nkj", hq, dq)  # (N, 4, 6): H_i dq_i
    hx = contract("njm,njl->ml", dq, hd) + kinematics_curvature(to_pose(z, data.lever), data.params, geometry, gq)
    scale = _pose_scale(data, z.dtype)
    return hx * scale[:, None] * scale[None, :]


def lane_problem(data: ProblemData) -> Problem:
    """The solver's view of a problem of the grasp ``data``: values, first and second
    derivatives from the contact kinematics (the equality row is the lane's ``eq_mask``)."""
    return Problem(
        fg=lambda z: objective_and_constraints(z, data),
        first_order=lambda z: _first_order(z, data),
        lagrangian_hessian=lambda d, z, w, gn: _lagrangian_hessian(d, z, w, gn, data),
    )


def lagrangian(z, lam, nu, eq_mask, data: ProblemData):
    """``L = f(z) + nu h(z) - lam . g(z)`` of the problem with equality row ``eq_mask``."""
    gz = constraints(z, data)
    return objective(z, data) + nu * jnp.sum(eq_mask * gz) - jnp.sum(lam * gz)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Problems:
    """Every problem of one grasp as solved, lane by lane (internal, scaled units).

    The pose variable of every problem is ``z = (dp [mm], lever * w [mm])``. With ``N``
    contacts and ``D`` starts per boundary problem (``EvaluateOptions.num_starts``):

    Attributes:
        equilibrium: `jaxgrasp.solver.SolverResult` of the equilibrium problem.
        boundary: `jaxgrasp.solver.SolverResult` with a leading lane axis
            ``(2N * D,)``: lane ``b * D + s`` is start ``s`` of boundary problem
            ``b = kind * N + contact``.
        start: ``(2N * D, 6)`` starting points of the boundary lanes.
        found: ``(2N * D,)`` whether the start search crossed the boundary (lanes where it
            did not carry status `jaxgrasp.solver.LaneStatus.NO_START`, as do found lanes
            of a problem that its first wave of starts settled:
            ``EvaluateOptions.first_wave``).
        constraint_index: ``(2N * D,)`` index ``k`` of the equality in the flattened
            ``(3N,)`` constraint vector (``N + b``).
        lever: ``()`` mm, the length that scales rotations.
        scale: ``()`` mJ, the energy scale dividing the objective.
        contact_on: ``(N,)`` bool, the active contacts (an inactive one's boundary
            lanes are never started).
    """

    equilibrium: SolverResult
    boundary: SolverResult
    start: Any
    found: Any
    constraint_index: Any
    lever: Any
    scale: Any
    contact_on: Any


def problems_treedef():
    """The pytree structure of `Problems` (it depends on no shape), to rebuild one
    from its leaves, in ``jax.tree_util`` order."""
    lanes = SolverResult(*(0,) * len(dataclasses.fields(SolverResult)))
    return jax.tree_util.tree_structure(
        Problems(lanes, lanes, *(0,) * (len(dataclasses.fields(Problems)) - 2))
    )


def _lane_equalities(n: int, num_starts: int):
    """``(2N * D,)`` the equality row of each boundary lane in the ``(3N,)`` constraints:
    lane ``b * D + s`` (start ``s`` of boundary ``b``) has row ``N + b`` (slip rows, then
    force rows)."""
    return jnp.repeat(n + jnp.arange(2 * n), num_starts)


def batch_data(p: ModelParams) -> ProblemData:
    """`problem_data` of a batch of grasps ``p`` (leading axis ``B``), with no
    gradient: the solver sees none."""
    return jax.vmap(problem_data)(jax.lax.stop_gradient(p))


def _num_lanes(data: ProblemData, options: EvaluateOptions) -> int:
    return 2 * data.params.c.shape[-2] * options.num_starts
