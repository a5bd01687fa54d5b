"""The method's solve and finish stages: a batch's lanes solved in one work queue, the
solved `Problems` assembled (the pipeline that runs them is
`jaxgrasp.engine`'s)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.solver import Held, LaneStatus, SolverResult, solve_lane_batches
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import (
    ProblemData,
    Problems,
    _lane_equalities,
    _num_lanes,
    lane_problem,
)
from jaxgrasp.tolerance._settle import _at_equilibrium, settle_equilibrium, settle_stalled
from jaxgrasp.tolerance._starts import (
    LaneStarts,
    equilibrium_of,
)

__all__ = [
    "solve_stage",
    "unsolved",
    "finish_problems",
    "settled_equilibrium",
    "first_wave_lanes",
    "rest_needed",
    "first_wave_verdict",
    "SAME_POINT",
    "VALUE_MARGIN",
    "depend_on",
]


def settled_equilibrium(data: ProblemData, eq_lanes: SolverResult, options: EvaluateOptions,
                        settle: bool = True) -> SolverResult:
    """Each grasp's equilibrium (leading axis ``B``) from the lanes of the equilibrium stage
    (`equilibrium_of`), with ``settle`` (static) certified where it stalled
    (`settle_equilibrium`): the pipeline's settle stage.
    The starts stage and the finish stage both read its result, so the boundary problems
    start from the settled equilibrium, which is computed (traced, compiled) once."""
    eq = equilibrium_of(eq_lanes)
    return settle_equilibrium(data, eq, options.solver) if settle else eq


def solve_stage(data: ProblemData, starts: LaneStarts, options: EvaluateOptions) -> SolverResult:
    """The solve stage: the lanes ``starts`` of a batch ``data`` solved, every grasp's
    lanes in one work queue (`jaxgrasp.solver.solve_lane_batches`); leading axes
    ``(B, L)``.

    Each lane gets its grasp's data as its theta (not closed over): the queue then runs
    the lanes of all grasps (and, under a caller's vmap, of all batches) together. The
    queue starts the force-limit lanes first: they take more steps than the slip lanes
    (most of them prove their boundary infeasible), so started last they would run on
    with the other slots idle. The equilibrium stage has one lane per grasp.

    With ``options.first_wave`` the lanes run in two waves through the same queue: each
    boundary problem's first starts (`first_wave_lanes`) are loaded at once, the
    other starts are held (`Held`, one group per problem) and
    those of the problems the first wave leaves open (`rest_needed`) are freed as
    the queue runs: a problem whose first starts disagree as soon as they have ended, one
    near the value once the grasp's whole first wave has; a lane of a problem the first
    wave settled ends ``NO_START``."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    theta = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a[:, None], (b, num_lanes) + a.shape[1:]), data)
    rank = jnp.where(_lane_equalities(n, options.num_starts) >= 2 * n, 0, 1)

    first = first_wave_lanes(n, options)
    if first is None:
        return solve_lane_batches(lane_problem, theta, starts.x0, starts.eq_mask, starts.nu0, starts.active,
                                  options.solver, rank=rank)

    # One queue for both waves. Each problem is a group: the other starts of a problem
    # whose first wave disagrees are freed as soon as its own first lanes end, and those
    # of a problem near the value once the grasp's first wave has ended (the margin reads
    # the grasp's least minimum), so they fill the slots as the first wave drains.
    def release(status, objective, complete, aux):
        u0, at_eq = aux
        shape = (-1, num_lanes)
        agree, near = first_wave_verdict(status.reshape(shape), objective.reshape(shape), first,
                                         options.num_starts, u0.reshape(shape)[:, 0], at_eq.reshape(shape))
        done = complete.reshape(agree.shape + (options.num_starts,))[..., 0]
        free = done & (~agree | (jnp.all(done, axis=-1, keepdims=True) & near))
        return jnp.repeat(free, options.num_starts, axis=-1).reshape(-1)

    held = Held(
        lanes=jnp.broadcast_to(~first, (b, num_lanes)),
        group=jnp.broadcast_to(jnp.arange(num_lanes, dtype=jnp.int32) // options.num_starts, (b, num_lanes)),
        aux=(jnp.broadcast_to(jnp.asarray(starts.u0)[:, None], (b, num_lanes)), starts.at_eq),
    )
    return solve_lane_batches(lane_problem, theta, starts.x0, starts.eq_mask, starts.nu0, starts.active,
                              options.solver, rank=rank, held=held, release=release)


def depend_on(tree, *others):
    """``tree``'s arrays made to depend on every array of ``others`` (the same values):
    under a caller's ``vmap``, whichever fields it maps, a loop carry made of them is then
    batched from the start. A carry that is not would be batched only after the first
    iteration, and JAX's loop batching would trace the body (the whole solver) once more
    to find out."""
    leaves = jax.tree_util.tree_leaves(others)
    dtype = jnp.result_type(float)
    flag = jnp.isnan(sum(jnp.sum(jnp.asarray(a, dtype)) for a in leaves))
    return jax.tree_util.tree_map(lambda a: jnp.where(flag, a, a), tree)


VALUE_MARGIN = 30.0
"""A boundary problem whose first-wave minimum (above ``U0``) is at most this many times
the grasp's least runs every start whatever its first wave found (`rest_needed`):
a start the first wave left out could change the value only through a minimum more than
this many times below one that its first wave found from two directions. The widest
such gap seen on the benchmark's set was 21x (in an unstable grasp, where it could not
matter)."""

SAME_POINT = 1e-9
"""Converged lanes of the first wave whose energies (scaled) lie within this fraction of
the lowest one's magnitude (at least 1) reached one minimum (the solver settles each to
1e-10; lanes at one minimum end some 3e-10 apart): `rest_needed`."""


def first_wave_lanes(n: int, options: EvaluateOptions):
    """``(2N * D,)`` bool, static: the lanes of the first wave (starts ``0 .. first_wave -
    1`` of every boundary problem, lane ``b * D + s``), or ``None`` where every start runs
    at once (``first_wave`` ``None`` or at least ``num_starts``)."""
    k, d = options.first_wave, options.num_starts
    if k is None or k >= d:
        return None
    return np.tile(np.arange(d) < k, 2 * n)  # NumPy: a constant wherever it is used (not a tracer)


def rest_needed(status, objective, first, num_starts: int, u0, at_eq=None):
    """``(..., 2N * D)`` bool: the lanes of the boundary problems that the first wave
    (``first``, `first_wave_lanes`) leaves open, from the lanes' ``status`` and
    ``objective`` ``(..., 2N * D)`` (those of the first wave final); ``u0`` ``(...)`` the
    equilibrium's energy, ``at_eq`` ``(..., 2N * D)`` (default none) the lanes of
    problems the equilibrium solves (not run: their minimum is ``u0``, the value 0).

    A problem is settled by its first wave where every lane of it that ran ended alike:
    at least two converged and every converged energy is within `SAME_POINT` of
    the lowest (one minimum, found from two directions), or at least two proved the
    boundary infeasible; a lane that stalled (``NOT_CONVERGED``), converged and infeasible
    lanes together, or two minima leave it open, and so does a first wave of fewer than
    two lanes. And a problem whose first-wave minimum could set the value is never
    settled by it: one at most `VALUE_MARGIN` times the grasp's least first-wave
    minimum above ``u0`` runs every start, so the value and the boundaries near it are
    those of every start at once.

    Why two: on the benchmark's mixed set every boundary minimum that some start reached
    was reached by at least four of the twenty, and in its stable grasps no problem that
    the first wave settled had a lower minimum or a feasible point among its other starts
    (``experiments/first_wave/first_wave.py``). In its unstable grasps (value 0, where no boundary
    but one at ``u0`` can set it) 11 of the 2821 settled problems had."""
    agree, near = first_wave_verdict(status, objective, first, num_starts, u0, at_eq)
    return jnp.repeat(~(agree & ~near), num_starts, axis=-1)


def first_wave_verdict(status, objective, first, num_starts: int, u0, at_eq=None):
    """``(agree, near)``, each ``(..., 2N)`` bool, per boundary problem (arguments as
    `rest_needed`, which is ``~(agree & ~near)`` per lane): whether its first-wave
    lanes agree (one minimum from two, or two proofs of infeasibility, nothing else), and
    whether its first-wave minimum lies within `VALUE_MARGIN` times the grasp's least
    (``near`` reads every problem of the grasp; ``agree`` only the problem's own lanes)."""
    shape = status.shape[:-1] + (-1, num_starts)
    status = status.reshape(shape)
    energy = objective.reshape(shape)
    ran = first.reshape(-1, num_starts)[0]
    conv = ran & (status == LaneStatus.CONVERGED)
    infeasible = ran & (status == LaneStatus.INFEASIBLE)
    stalled = ran & (status == LaneStatus.NOT_CONVERGED)
    low = jnp.min(jnp.where(conv, energy, jnp.inf), axis=-1)
    high = jnp.max(jnp.where(conv, energy, -jnp.inf), axis=-1)
    one_minimum = high - low <= SAME_POINT * jnp.maximum(jnp.abs(low), 1.0)
    count = lambda m: jnp.sum(m, axis=-1)  # noqa: E731
    agree = ~jnp.any(stalled, axis=-1) & (
        ((count(conv) >= 2) & (count(infeasible) == 0) & one_minimum)
        | ((count(infeasible) >= 2) & (count(conv) == 0))
    )
    above = low - jnp.asarray(u0)[..., None]
    if at_eq is not None:
        above_value = jnp.where(jnp.any(jnp.asarray(at_eq).reshape(shape), axis=-1), 0.0, above)
    else:
        above_value = above
    value = jnp.maximum(jnp.min(above_value, axis=-1, keepdims=True), 0.0)
    near = jnp.isfinite(low) & (above <= VALUE_MARGIN * value)
    return agree, near


def finish_problems(data: ProblemData, eq: SolverResult, lanes: SolverResult, starts: LaneStarts,
                    options: EvaluateOptions, settle: bool = True) -> Problems:
    """The finish stage: the `Problems` of a batch ``data``
    from its equilibria ``eq`` (leading axis ``B``), its boundary lanes ``lanes`` as
    solved from ``starts`` (leading axes ``(B, L)``): lanes ``at_eq`` get the
    equilibrium's solution (`_at_equilibrium`), and with ``settle`` (static)
    `settle_stalled` certifies stalled ones."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    lane_k = _lane_equalities(n, options.num_starts)
    lanes = jax.vmap(lambda *a: _at_equilibrium(*a, lane_k))(eq, lanes, starts.at_eq, starts.g_eq)
    found = starts.active | starts.at_eq
    if settle:
        lanes = settle_stalled(data, lanes, lane_k, found, options.num_starts, options.solver)
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
    """The `SolverResult` of lanes ``starts`` not yet solved:
    zeros, shaped as `solve_stage` returns them (leading axes ``(B, L)``)."""
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
