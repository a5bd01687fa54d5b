"""A work queue that runs many lanes of the solver, finished lanes handing their slot on.

:func:`solve_lanes` gives each lane what :func:`jaxgrasp.solver._solver.solve` gives it, but
advances only a few slots per loop step instead of every lane in lockstep; under
``jax.vmap`` it folds the batch axis into its lanes (``custom_vmap``), so the lanes of
every grasp of a batch share one queue. It drives the solver through its pieces
:func:`~jaxgrasp.solver._solver.init`, the parts of :func:`~jaxgrasp.solver._solver.step`
(:func:`~jaxgrasp.solver._solver.propose`, one :func:`~jaxgrasp.solver._solver.line_search` over every
slot, :func:`~jaxgrasp.solver._solver.accept`), :func:`~jaxgrasp.solver._solver.running` and
:func:`~jaxgrasp.solver._solver.to_result`.

Lanes of one ``vmap`` advance in lockstep, so a plain batched loop costs ``L * max(steps)``
lane-steps although most lanes finish early (or never start). The queue keeps
``W = min(ceil(slot_fraction * L), max_slots)`` slots busy: each loop step advances every
slot; a slot whose lane has finished writes it back and takes the next lane not yet
started (active lanes only). One ``while_loop`` with static shapes, so it composes with
``jit`` and ``vmap``; the cost is near ``sum(steps) + W * max(steps)`` lane-steps.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from jaxgrasp.solver import _solver as solver
from jaxgrasp.solver._solver import SolverOptions, SolverResult

__all__ = ["solve_lanes", "solve_lane_batches"]


def solve_lanes(
    problem: Callable,
    theta,
    x0,
    eq_mask,
    nu0,
    active,
    options: SolverOptions = SolverOptions(),
    rank=None,
) -> SolverResult:
    """Solve a batch of lanes with early exit of finished lanes (leading axis ``L``).

    A work queue keeps ``W = min(ceil(slot_fraction * L), max_slots)`` slots busy (see the
    module docstring); each lane's result is what :func:`jaxgrasp.solver._solver.solve`
    gives. Under ``jax.vmap`` the batch axis is folded into the lane axis
    (:func:`_queue_over_lanes`), so ``problem`` must take every lane-dependent quantity
    through ``theta`` (it must not close over traced values).

    Args:
        problem: ``theta_lane -> Problem`` (or ``-> fg``, see
            :func:`~jaxgrasp.solver._solver.as_problem`): the lane's problem.
        theta: pytree of per-lane problem data, leading axis ``L`` (may be empty).
        x0: ``(L, n)`` starting points.
        eq_mask: ``(L, m)`` one-hot equality selectors (rows of zeros: no equality).
        nu0: ``(L,)`` initial equality multipliers (``NaN``: the least-squares estimate
            at ``x0``, see :func:`~jaxgrasp.solver._solver.init`).
        active: ``(L,)`` bool; inactive lanes end at once with status
            ``LaneStatus.NO_START``.
        options: :class:`~jaxgrasp.solver._solver.SolverOptions`.
        rank: ``(L,)`` int or ``None`` (all 0): the queue loads lanes in increasing rank,
            in lane order within a rank. Results do not depend on it (each lane's
            computation is its own); the time does: lanes expected to take many steps
            ranked first finish while others still fill the slots, instead of running
            alone at the end of the queue with the other slots idle.

    Returns:
        :class:`~jaxgrasp.solver._solver.SolverResult` with leading axis ``L``.
    """
    rank = jnp.zeros(jnp.shape(active), jnp.int32) if rank is None else jnp.asarray(rank, jnp.int32)
    run = _queue_over_lanes(problem, options)
    return run(theta, jnp.asarray(x0), jnp.asarray(eq_mask), jnp.asarray(nu0), jnp.asarray(active), rank)


def _queue_over_lanes(problem: Callable, options: SolverOptions):
    """``run(theta, x0, eq_mask, nu0, active, rank) -> SolverResult``: :func:`_solve_lanes`
    as a ``custom_vmap`` whose batching rule folds the batch axis into the lane axis.

    Under ``jax.vmap`` (e.g. one call per grasp, vmapped over grasps) all ``B * L`` lanes
    then share one queue of ``min(ceil(slot_fraction * B * L), max_slots)`` slots, instead
    of ``B`` queues advancing in lockstep until the slowest of them is empty. Results are
    the same lane by lane.
    """

    @jax.custom_batching.custom_vmap
    def run(theta, x0, eq_mask, nu0, active, rank):
        return _solve_lanes(problem, theta, x0, eq_mask, nu0, active, rank, options)

    @run.def_vmap
    def _fold_batch_into_lanes(axis_size, in_batched, theta, x0, eq_mask, nu0, active, rank):
        def batched(a, is_batched):
            a = jnp.asarray(a)
            return a if is_batched else jnp.broadcast_to(a, (axis_size,) + a.shape)

        args = jax.tree_util.tree_map(batched, (theta, x0, eq_mask, nu0, active, rank), tuple(in_batched))
        *args, rank = args
        out = solve_lane_batches(problem, *args, options, rank=rank)  # a nested vmap folds into it in turn
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return run


def solve_lane_batches(
    problem: Callable,
    theta,
    x0,
    eq_mask,
    nu0,
    active,
    options: SolverOptions = SolverOptions(),
    rank=None,
) -> SolverResult:
    """:func:`solve_lanes` of ``B`` batches of ``L`` lanes (every argument with leading
    axes ``(B, L)``), all ``B * L`` lanes in one queue; the result has leading axes
    ``(B, L)``.

    This is what :func:`solve_lanes` does under ``jax.vmap`` (its batching rule calls it),
    called directly: a caller that holds a batch, such as
    :func:`jaxgrasp.tolerance._stages.solve_stage`, gets the same lanes while the queue is
    traced once, where ``vmap`` traces it once for one batch (``custom_vmap`` builds a
    jaxpr of the function it wraps) and again folded.
    """
    x0 = jnp.asarray(x0)
    b, num_lanes = x0.shape[:2]
    flat = lambda a: jnp.asarray(a).reshape((b * num_lanes,) + jnp.shape(a)[2:])
    rank = None if rank is None else flat(jnp.broadcast_to(jnp.asarray(rank), x0.shape[:2]))
    out = solve_lanes(problem, jax.tree_util.tree_map(flat, theta), flat(x0), flat(eq_mask), flat(nu0),
                      flat(active), options, rank=rank)
    return jax.tree_util.tree_map(lambda a: a.reshape((b, num_lanes) + a.shape[1:]), out)


class _Queue(NamedTuple):
    """Loop carry of the queue: ``L`` lanes, ``W`` slots."""

    states: Any  # SolverState, leading axis L: every lane, as last written back
    slots: Any  # SolverState, leading axis W: the lanes in flight
    idx: Any  # (W,) int: the lane each slot holds
    ptr: Any  # () int: how many lanes of the queue order have been loaded into a slot


def _take(tree, idx):
    """``tree``'s rows ``idx`` (every index in range). Unsigned, so that JAX adds no
    wrap-around of negative indices (six ops per leaf, in every loop step)."""
    idx = jnp.asarray(idx).astype(jnp.uint32)
    return jax.tree_util.tree_map(lambda a: a[idx], tree)


def _queue_order(active, rank):
    """``(L,)`` the order in which the queue loads lanes: the active ones first, by rank,
    in lane order within a rank (only the first ``sum(active)`` are ever loaded)."""
    key = jnp.where(jnp.asarray(active), jnp.asarray(rank, jnp.int32), jnp.iinfo(jnp.int32).max)
    return jnp.argsort(key, stable=True)


def _num_slots(num_lanes: int, o: SolverOptions) -> int:
    """``W = min(ceil(slot_fraction * L), max_slots, L)``, at least 1 (static)."""
    return max(1, min(num_lanes, o.max_slots, -(-int(o.slot_fraction * num_lanes * 1e6) // 1_000_000)))


def _running_slots(slots, o: SolverOptions):
    """``(W,)`` bool: which slots still step."""
    return jax.vmap(lambda s: solver.running(s, o))(slots)


def _advance(problem, theta, order, num_active, o: SolverOptions, q: _Queue) -> _Queue:
    """One loop step: every slot steps and is written back; finished slots are refilled.

    ``order`` is the ``(L,)`` queue order of the lanes, its first ``num_active`` entries the
    active lanes.
    """
    th = _take(theta, q.idx)
    # solver.step of every slot, with one line search over all of them (only the slots
    # that need more than the full step walk the rest of the ladder)
    trials = jax.vmap(lambda s, t: solver.propose(problem(t), s, o))(q.slots, th)
    merit_of = lambda x, k: solver.merit(problem(_take(th, k)), _take(trials.state, k), x)
    x_new, improve = solver.line_search(merit_of, trials, o)
    slots = jax.vmap(lambda t, x, i: solver.accept(t, x, i, o))(trials, x_new, improve)
    at = q.idx.astype(jnp.uint32)  # in range: no wrap-around of negative indices
    states = jax.tree_util.tree_map(lambda a, b: a.at[at].set(b), q.states, slots)
    done = ~_running_slots(slots, o)
    # the k-th finished slot takes order[ptr + k], while lanes remain
    rank = jnp.cumsum(done) - 1
    cand = q.ptr + rank
    refill = done & (cand < num_active)
    new_idx = jnp.where(refill, order[jnp.minimum(cand, order.shape[0] - 1)], q.idx)
    slots = jax.tree_util.tree_map(
        lambda a, b: jnp.where(refill.reshape((-1,) + (1,) * (a.ndim - 1)), b, a),
        slots,
        _take(states, new_idx),
    )
    return _Queue(states, slots, new_idx, q.ptr + jnp.sum(refill))


def _solve_lanes(problem, theta, x0, eq_mask, nu0, active, rank, o: SolverOptions) -> SolverResult:
    """:func:`solve_lanes` on one flat batch of ``L`` lanes: the queue loop.

    One loop of ``W`` slots to the end. A second, narrower loop for the last long lanes
    once the queue is empty would copy the whole solver step into the executable again,
    for the same results lane by lane."""
    num_lanes = x0.shape[0]
    width = _num_slots(num_lanes, o)
    states = jax.vmap(lambda x, m, nu, a: solver.init(x, m, nu, a, o))(x0, eq_mask, nu0, active)
    order = _queue_order(active, rank)
    num_active = jnp.sum(jnp.asarray(active, jnp.int32))
    advance = partial(_advance, problem, theta, order, num_active, o)

    def cond(q: _Queue):
        return jnp.any(_running_slots(q.slots, o))

    idx0 = order[:width]
    ptr0 = jnp.minimum(jnp.asarray(width), num_active)
    q = jax.lax.while_loop(cond, advance, _Queue(states, _take(states, idx0), idx0, ptr0))
    # theta taken by lane index, as the slots take it: fg then compiles as in the loop (given
    # theta itself, XLA simplifies across its broadcasts and rounds f(x) differently).
    th = _take(theta, jnp.arange(num_lanes))
    return jax.vmap(lambda s, t: solver.to_result(problem(t), s))(q.states, th)
