"""The method's stage functions: lanes solved, problems finished, a batch solved in one traced function."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxgrasp.model._grasp import Grasp
from jaxgrasp.model._potential import (
    ModelParams,
    model_params,
)
from jaxgrasp.solver._lanes import solve_lane_batches
from jaxgrasp.solver._solver import SolverResult
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import (
    ProblemData,
    Problems,
    _lane_equalities,
    _num_lanes,
    batch_data,
    lane_problem,
)
from jaxgrasp.tolerance._settle import _at_equilibrium, _settle_where_stalled
from jaxgrasp.tolerance._starts import (
    LaneStarts,
    boundary_starts,
    equilibrium_of,
    equilibrium_starts,
)

__all__ = ['solve_problems', 'problems_of', 'problems_of_batch', 'solve_stage', 'finish_problems']


def problems_of(p: ModelParams, options: EvaluateOptions, settle: bool = True) -> Problems:
    """Solve every program of the grasp ``p`` (traceable; the solver sees no derivative):
    :func:`problems_of_batch` of a batch of one."""
    one = jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], p)
    return jax.tree_util.tree_map(lambda a: a[0], problems_of_batch(one, options, settle))


def solve_stage(data: ProblemData, starts: LaneStarts, options: EvaluateOptions) -> SolverResult:
    """Stages 2 and 4 of :func:`problems_of_batch`: the lanes ``starts`` of a batch
    ``data`` solved, every grasp's lanes in one work queue
    (:func:`~jaxgrasp.solver._lanes.solve_lane_batches`); leading axes ``(B, L)``.

    Each lane gets its grasp's data as its theta (not closed over): the queue then runs
    the lanes of all grasps (and, under a caller's vmap, of all batches) together. The
    queue starts the force-limit lanes first: on random grasps they take 46 steps on
    average against 27 for the slip lanes (two thirds of them prove their boundary
    infeasible), so started last they would run on with the other slots idle
    (experiments/BENCHMARK.md). The equilibrium stage has one lane per grasp."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    theta = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a[:, None], (b, num_lanes) + a.shape[1:]), data)
    rank = jnp.where(_lane_equalities(n, options.num_starts) >= 2 * n, 0, 1)
    return solve_lane_batches(lane_problem, theta, starts.x0, starts.eq_mask, starts.nu0, starts.active,
                              options.solver, rank=rank)


def finish_problems(data: ProblemData, eq: SolverResult, lanes: SolverResult, starts: LaneStarts,
                    options: EvaluateOptions, settle: bool = True) -> Problems:
    """Stage 5 of :func:`problems_of_batch`: the :class:`Problems` of a batch ``data``
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


def problems_of_batch(p: ModelParams, options: EvaluateOptions, settle: bool = True) -> Problems:
    """Solve every program of a batch of grasps ``p`` (leading axis ``B`` on every field;
    traceable; the solver sees no derivative). Returns :class:`Problems` with a leading
    ``B``.

    Its stages, each a function of the batch: the equilibrium's lanes
    (:func:`equilibrium_starts`), solved (:func:`solve_stage`); the boundary problems'
    lanes from starts around that equilibrium (:func:`boundary_starts`), solved; the
    :class:`Problems` (:func:`finish_problems`). The batch engine runs them as separate
    compiled programs (:mod:`jaxgrasp.engine._stages`); here they are one program.

    Both solves run through ONE :func:`solve_stage` call site, inside a two-iteration
    loop: iteration 0 solves the equilibrium problem, iteration 1 the boundary problems.
    The solver's loop is then compiled once rather than twice, which halves the program
    the solver contributes; each lane's result is what :func:`~jaxgrasp.solver._solver.solve`
    gives it. Taking the batch itself, rather than being vmapped over grasps, traces the
    queue once: under ``vmap`` it is traced for one grasp and again folded
    (``custom_vmap``), 0.3-0.4 s of a sweep's cold start (experiments/BENCHMARK.md). The
    stage is the loop counter, not batched data, so under a caller's ``vmap`` the
    ``lax.cond`` choosing the lanes stays a branch.

    With ``settle`` (static), :func:`settle_stalled` then certifies stalled boundary
    lanes. Without it the program is smaller and faster, and equal wherever no boundary
    problem ends unsettled (:func:`needs_settling`): the host-level drivers
    (:func:`jaxgrasp.evaluate` of a concrete grasp, the batch engine) run that program
    first and the settling one only on the grasps that need it.
    """
    data = batch_data(p)

    def stage(i, carry):
        eq, _, _ = carry
        starts = jax.lax.cond(
            i == 0,
            lambda eq: equilibrium_starts(data, options),
            lambda eq: boundary_starts(data, eq, options),
            eq,
        )
        res = solve_stage(data, starts, options)
        eq = jax.lax.cond(i == 0, lambda: equilibrium_of(res), lambda: eq)
        return eq, res, starts

    # the carry: each grasp's equilibrium lane, every lane's result (zeros until solved)
    # and the lanes' starts
    starts0 = equilibrium_starts(data, options)
    zero = lambda a, dt=None: jnp.zeros(a.shape, a.dtype if dt is None else dt)
    x0 = starts0.x0
    lanes0 = SolverResult(
        x=zero(x0),
        lam=zero(starts0.eq_mask),
        nu=zero(starts0.nu0),
        objective=zero(starts0.nu0),
        status=zero(starts0.nu0, jnp.int32),
        stationarity=zero(starts0.nu0),
        feasibility=zero(starts0.nu0),
        complementarity=zero(starts0.nu0),
        steps=zero(starts0.nu0, jnp.int32),
    )
    carry0 = (equilibrium_of(lanes0), lanes0, jax.tree_util.tree_map(zero, starts0))
    # The carry's zeros, made to depend on the grasps (jnp.where of a flag computed from
    # every field of their data; the values are the same zeros): under a caller's vmap over
    # grasps, whichever fields it maps, the carry is then batched from the start. Zeros
    # that are not would be batched only after the first stage, and JAX's loop batching
    # would trace the body (the whole solver) once more to find that out: 128 grasps over
    # 2 devices traced in 2.6 s instead of 4.0-4.5 s, with the same results
    # (experiments/BENCHMARK.md).
    dtype = data.params.c.dtype
    per_grasp = jnp.isnan(sum(jnp.sum(jnp.asarray(a, dtype)) for a in jax.tree_util.tree_leaves(data)))
    carry0 = jax.tree_util.tree_map(lambda a: jnp.where(per_grasp, a, a), carry0)
    eq, lanes, starts = jax.lax.fori_loop(0, 2, stage, carry0)
    return finish_problems(data, eq, lanes, starts, options, settle)


@partial(jax.jit, static_argnames=("options", "settle"))


def solve_problems(grasp: Grasp, options: EvaluateOptions = EvaluateOptions(), settle: bool = True) -> Problems:
    """Solve every program of ``grasp`` and return them lane by lane (for diagnostics and
    benchmarks; :func:`jaxgrasp.evaluate` is this plus the reduction to one value);
    ``settle`` as in :func:`problems_of`."""
    return problems_of(model_params(grasp), options, settle)
