"""The method's solve and finish stages: a batch's lanes solved in one work queue, the
solved :class:`~jaxgrasp.tolerance.Problems` assembled (the pipeline that runs them is
:mod:`jaxgrasp.engine`'s)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgrasp.solver._lanes import solve_lane_batches
from jaxgrasp.solver._solver import SolverResult
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import (
    ProblemData,
    Problems,
    _lane_equalities,
    _num_lanes,
    lane_problem,
)
from jaxgrasp.tolerance._settle import _at_equilibrium, _settle_where_stalled, settle_equilibrium
from jaxgrasp.tolerance._starts import (
    LaneStarts,
    equilibrium_of,
)

__all__ = ["solve_stage", "unsolved", "finish_problems", "settled_equilibrium"]


def settled_equilibrium(data: ProblemData, eq_lanes: SolverResult, options: EvaluateOptions,
                        settle: bool = True) -> SolverResult:
    """Each grasp's equilibrium (leading axis ``B``) from the lanes of the equilibrium stage
    (:func:`equilibrium_of`), with ``settle`` (static) certified where it stalled
    (:func:`~jaxgrasp.tolerance._settle.settle_equilibrium`). The starts stage and the
    finish stage both read it, so the boundary problems start from the settled equilibrium."""
    eq = equilibrium_of(eq_lanes)
    return settle_equilibrium(data, eq, options.solver) if settle else eq


def solve_stage(data: ProblemData, starts: LaneStarts, options: EvaluateOptions) -> SolverResult:
    """The solve stage: the lanes ``starts`` of a batch ``data`` solved, every grasp's
    lanes in one work queue (:func:`jaxgrasp.solver.solve_lane_batches`); leading axes
    ``(B, L)``.

    Each lane gets its grasp's data as its theta (not closed over): the queue then runs
    the lanes of all grasps (and, under a caller's vmap, of all batches) together. The
    queue starts the force-limit lanes first: they take more steps than the slip lanes
    (most of them prove their boundary infeasible), so started last they would run on
    with the other slots idle. The equilibrium stage has one lane per grasp."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    theta = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a[:, None], (b, num_lanes) + a.shape[1:]), data)
    rank = jnp.where(_lane_equalities(n, options.num_starts) >= 2 * n, 0, 1)
    return solve_lane_batches(lane_problem, theta, starts.x0, starts.eq_mask, starts.nu0, starts.active,
                              options.solver, rank=rank)


def finish_problems(data: ProblemData, eq: SolverResult, lanes: SolverResult, starts: LaneStarts,
                    options: EvaluateOptions, settle: bool = True) -> Problems:
    """The finish stage: the :class:`Problems` of a batch ``data``
    from its equilibria ``eq`` (leading axis ``B``), its boundary lanes ``lanes`` as
    solved from ``starts`` (leading axes ``(B, L)``): lanes ``at_eq`` get the
    equilibrium's solution (:func:`_at_equilibrium`), and with ``settle`` (static)
    :func:`settle_stalled` certifies stalled ones."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    lane_k = _lane_equalities(n, options.num_starts)
    lanes = jax.vmap(lambda *a: _at_equilibrium(*a, lane_k))(eq, lanes, starts.at_eq, starts.g_eq)
    found = starts.active | starts.at_eq
    if settle:
        lanes = _settle_where_stalled(data, lanes, lane_k, found, options.num_starts, options.solver)
    return Problems(
        equilibrium=eq,
        boundary=lanes,
        start=starts.x0,
        found=found,
        constraint_index=jnp.broadcast_to(lane_k, (b, num_lanes)),
        lever=data.lever,
        scale=data.scale,
        contact_on=data.params.on,
    )


def unsolved(starts: LaneStarts) -> SolverResult:
    """The :class:`~jaxgrasp.solver.SolverResult` of lanes ``starts`` not yet solved:
    zeros, shaped as :func:`solve_stage` returns them (leading axes ``(B, L)``)."""
    zero = lambda a, dtype=None: jnp.zeros(a.shape, a.dtype if dtype is None else dtype)  # noqa: E731
    return SolverResult(
        x=zero(starts.x0),
        lam=zero(starts.eq_mask),
        nu=zero(starts.nu0),
        objective=zero(starts.nu0),
        status=zero(starts.nu0, jnp.int32),
        stationarity=zero(starts.nu0),
        feasibility=zero(starts.nu0),
        complementarity=zero(starts.nu0),
        steps=zero(starts.nu0, jnp.int32),
    )
