"""A work queue that runs many lanes of the solver, finished lanes handing their slot on.

`solve_lanes` gives each lane what `jaxgrasp.solver._solver.solve` gives it, but
advances only a few slots per loop step instead of every lane in lockstep; under
``jax.vmap`` it folds the batch axis into its lanes (``custom_vmap``), so the lanes of
every grasp of a batch share one queue. It drives the solver through its pieces
`init`, the parts of `step`
(`propose`, one `line_search` over every
slot, `accept`), `running` and
`to_result`.

Lanes of one ``vmap`` advance in lockstep, so a plain batched loop costs ``L * max(steps)``
lane-steps although most lanes finish early (or never start). The queue keeps
``W = min(ceil(slot_fraction * L), max_slots)`` slots busy: each loop step advances every
slot; a slot whose lane has finished writes it back and takes the next lane not yet
started (active lanes only). One ``while_loop`` with static shapes, so it composes with
``jit`` and ``vmap``; the cost is near ``sum(steps) + W * max(steps)`` lane-steps.
"""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from jaxgrasp.solver import _solver as solver
from jaxgrasp.solver._solver import SolverOptions, SolverResult
from jaxgrasp.solver._status import LaneStatus

__all__ = ["solve_lanes", "solve_lane_batches", "Held"]


class Held(NamedTuple):
    """Lanes a queue holds back until its ``release`` frees them (`solve_lanes`),
    each field with leading axis ``L``.

    Attributes:
        lanes: ``(L,)`` bool, the active lanes held back.
        group: ``(L,)`` int in ``[0, L)``: ``release`` is asked about a group's lanes once
            every lane of the group that was not held has finished.
        aux: pytree, what ``release`` reads besides the lanes' results (e.g. per-group
            data broadcast to its lanes).
    """

    lanes: Any
    group: Any
    aux: Any = ()


def solve_lanes(
    problem: Callable,
    theta,
    x0,
    eq_mask,
    nu0,
    active,
    options: SolverOptions = SolverOptions(),
    rank=None,
    held: Held | None = None,
    release: Callable | None = None,
) -> SolverResult:
    """Solve a batch of lanes with early exit of finished lanes (leading axis ``L``).

    A work queue keeps ``W = min(ceil(slot_fraction * L), max_slots)`` slots busy (see the
    module docstring); each lane's result is what `jaxgrasp.solver._solver.solve`
    gives. Under ``jax.vmap`` the batch axis is folded into the lane axis
    (`_queue_over_lanes`), so ``problem`` must take every lane-dependent quantity
    through ``theta`` (it must not close over traced values).

    Args:
        problem: ``theta_lane -> Problem`` (or ``-> fg``, see
            `as_problem`): the lane's problem.
        theta: pytree of per-lane problem data, leading axis ``L`` (may be empty).
        x0: ``(L, n)`` starting points.
        eq_mask: ``(L, m)`` one-hot equality selectors (rows of zeros: no equality).
        nu0: ``(L,)`` initial equality multipliers (``NaN``: the least-squares estimate
            at ``x0``, see `init`).
        active: ``(L,)`` bool; inactive lanes end at once with status
            ``LaneStatus.NO_START``.
        options: [`SolverOptions`][jaxgrasp.SolverOptions].
        rank: ``(L,)`` int or ``None`` (all 0): the queue loads lanes in increasing rank,
            in lane order within a rank. Results do not depend on it (each lane's
            computation is its own); the time does: lanes expected to take many steps
            ranked first finish while others still fill the slots, instead of running
            alone at the end of the queue with the other slots idle.
        held: `Held` lanes (default none), run only where ``release`` frees them:
            a second wave that shares the queue with the first, so that the slots the
            first wave's last lanes leave idle take the second's.
        release: ``release(status, objective, complete, aux) -> (L,) bool`` (static),
            called once before the first step and then at most every
            `RELEASE_EVERY` loop steps while some group has completed since the
            last call (at once where no lane waits): ``status`` ``(L,)`` and
            ``objective`` ``(L,)`` are every lane's as far as it ran (final for finished
            lanes; ``objective`` meaningful for converged ones), ``complete`` ``(L,)``
            whether the lane's group has completed (its unheld lanes all finished),
            ``aux`` is ``held.aux``. Of the lanes it returns, the held ones of complete
            groups run (before the unheld lanes still waiting, in ``rank`` order among
            those freed at one call); a held lane never freed ends ``NO_START``.

    Returns:
        `SolverResult` with leading axis ``L``.
    """
    rank = jnp.zeros(jnp.shape(active), jnp.int32) if rank is None else jnp.asarray(rank, jnp.int32)
    if held is None:
        held = Held(jnp.zeros(jnp.shape(active), bool), jnp.zeros(jnp.shape(active), jnp.int32))
    held = Held(jnp.asarray(held.lanes, bool), jnp.asarray(held.group, jnp.int32), held.aux)
    run = _queue_over_lanes(problem, options, release)
    return run(theta, jnp.asarray(x0), jnp.asarray(eq_mask), jnp.asarray(nu0), jnp.asarray(active), rank, held)


def _queue_over_lanes(problem: Callable, options: SolverOptions, release: Callable | None = None):
    """``run(theta, x0, eq_mask, nu0, active, rank, held) -> SolverResult``:
    `_solve_lanes` as a ``custom_vmap`` whose batching rule folds the batch axis
    into the lane axis.

    Under ``jax.vmap`` (e.g. one call per grasp, vmapped over grasps) all ``B * L`` lanes
    then share one queue of ``min(ceil(slot_fraction * B * L), max_slots)`` slots, instead
    of ``B`` queues advancing in lockstep until the slowest of them is empty. Results are
    the same lane by lane (each batch's groups stay its own).
    """

    @jax.custom_batching.custom_vmap
    def run(theta, x0, eq_mask, nu0, active, rank, held):
        return _solve_lanes(problem, theta, x0, eq_mask, nu0, active, rank, held, release, options)

    @run.def_vmap
    def _fold_batch_into_lanes(axis_size, in_batched, theta, x0, eq_mask, nu0, active, rank, held):
        def batched(a, is_batched):
            a = jnp.asarray(a)
            return a if is_batched else jnp.broadcast_to(a, (axis_size,) + a.shape)

        args = jax.tree_util.tree_map(batched, (theta, x0, eq_mask, nu0, active, rank, held), tuple(in_batched))
        *args, rank, held = args
        # a nested vmap folds into it in turn
        out = solve_lane_batches(problem, *args, options, rank=rank, held=held, release=release)
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
    held: Held | None = None,
    release: Callable | None = None,
) -> SolverResult:
    """`solve_lanes` of ``B`` batches of ``L`` lanes (every argument with leading
    axes ``(B, L)``), all ``B * L`` lanes in one queue; the result has leading axes
    ``(B, L)``. Each batch's ``held.group`` ids are its own (``release`` sees them
    flattened, batch after batch).

    This is what `solve_lanes` does under ``jax.vmap`` (its batching rule calls it),
    called directly: a caller that holds a batch, such as
    `jaxgrasp.tolerance._stages.solve_stage`, gets the same lanes while the queue is
    traced once, where ``vmap`` traces it once for one batch (``custom_vmap`` builds a
    jaxpr of the function it wraps) and again folded.
    """
    x0 = jnp.asarray(x0)
    b, num_lanes = x0.shape[:2]
    flat = lambda a: jnp.asarray(a).reshape((b * num_lanes,) + jnp.shape(a)[2:])  # noqa: E731
    lanes_of = lambda a: jnp.broadcast_to(jnp.asarray(a), x0.shape[:2])  # noqa: E731
    rank = None if rank is None else flat(lanes_of(rank))
    if held is not None:
        # group ids made unique across the batches: batch k's ids are offset by k * L
        group = lanes_of(held.group) + num_lanes * jnp.arange(b, dtype=jnp.int32)[:, None]
        held = Held(flat(lanes_of(held.lanes)), flat(group), jax.tree_util.tree_map(flat, held.aux))
    out = solve_lanes(problem, jax.tree_util.tree_map(flat, theta), flat(x0), flat(eq_mask), flat(nu0),
                      flat(active), options, rank=rank, held=held, release=release)
    return jax.tree_util.tree_map(lambda a: a.reshape((b, num_lanes) + a.shape[1:]), out)


class _Queue(NamedTuple):
    """Loop carry of the queue: ``L`` lanes, ``W`` slots."""

    states: Any  # SolverState, leading axis L: every lane, as last written back
    slots: Any  # SolverState, leading axis W: the lanes in flight
    idx: Any  # (W,) int: the lane each slot holds
    ptr: Any  # () int: how many lanes of the queue order have been loaded into a slot
    objective: Any  # (L,) f at each lane's point when it last stepped (kept for a release rule only)
    left: Any  # (L,) int: per group, its unheld active lanes not yet finished
    freed: Any  # (L,) bool: held lanes released (queued)
    later: Any  # (L,) int: the freed lanes in the order they load, first num_later valid
    num_later: Any  # () int
    later_ptr: Any  # () int: how many of them have been loaded
    pending: Any  # () bool: a group has completed since release was last asked
    tick: Any  # () int: loop steps taken (counted for a release rule only)


RELEASE_EVERY = 64
"""Loop steps between two calls of a queue's ``release`` at most, while lanes wait to be
loaded. Each call reads every lane of the queue (tens of thousands in a batch's chunk),
where a loop step works on its ``W`` slots only, so a call costs a sizeable part of a
step; a group freed some steps late costs nothing while the slots are busy. Once fewer
lanes wait than slots have just finished, ``release`` is asked at once (where some group
has completed since the last call)."""


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


class _Lanes(NamedTuple):
    """What the loop reads and never changes."""

    theta: Any
    order: Any  # (L,) the unheld active lanes by rank, then the rest
    num_first: Any  # () int: how many of order are loaded
    by_rank: Any  # (L,) every lane by rank (the order freed lanes load in)
    held: Held
    nu0: Any  # (L,) the multipliers a freed lane starts with


def _free(release, lanes: _Lanes, q: _Queue) -> _Queue:
    """Ask ``release`` about the complete groups: their held lanes it frees are queued
    (``later``, in ``by_rank`` order) and made runnable."""
    num_lanes = q.freed.shape[0]
    complete = q.left[lanes.held.group] == 0
    new = lanes.held.lanes & ~q.freed & complete & release(q.states.status, q.objective, complete, lanes.held.aux)
    in_order = new[lanes.by_rank]
    pos = jnp.where(in_order, q.num_later + jnp.cumsum(in_order) - 1, num_lanes)
    later = q.later.at[pos].set(lanes.by_rank.astype(q.later.dtype), mode="drop")
    states = dataclasses.replace(
        q.states,
        status=jnp.where(new, LaneStatus.NOT_CONVERGED, q.states.status).astype(jnp.int32),
        nu=jnp.where(new, lanes.nu0, q.states.nu),
    )
    return q._replace(states=states, freed=q.freed | new, later=later, num_later=q.num_later + jnp.sum(new),
                      pending=jnp.asarray(False))


def _refill(lanes: _Lanes, q: _Queue, done) -> _Queue:
    """Finished slots ``done`` ``(W,)`` take the next lanes: freed ones first, then the
    unheld ones in order; a slot left without one holds its finished lane."""
    num_lanes = lanes.order.shape[0]
    avail = q.num_later - q.later_ptr
    k = jnp.cumsum(done) - 1  # the k-th finished slot takes the k-th lane waiting
    from_later = k < avail
    cand = q.ptr + k - avail
    refill = done & (from_later | (cand < lanes.num_first))
    pick = jnp.where(from_later, q.later[jnp.minimum(q.later_ptr + k, num_lanes - 1)],
                     lanes.order[jnp.clip(cand, 0, num_lanes - 1)])
    new_idx = jnp.where(refill, pick, q.idx)
    slots = jax.tree_util.tree_map(
        lambda a, b: jnp.where(refill.reshape((-1,) + (1,) * (a.ndim - 1)), b, a),
        q.slots,
        _take(q.states, new_idx),
    )
    return q._replace(slots=slots, idx=new_idx, ptr=q.ptr + jnp.sum(refill & ~from_later),
                      later_ptr=q.later_ptr + jnp.sum(done & from_later))


def _advance(problem, release, lanes: _Lanes, o: SolverOptions, q: _Queue) -> _Queue:
    """One loop step: every slot steps, running ones are written back; finished slots
    are refilled (after ``release`` frees the held lanes of groups that just completed)."""
    num_lanes = q.freed.shape[0]
    th = _take(lanes.theta, q.idx)
    was = _running_slots(q.slots, o)
    # solver.step of every slot, with one line search over all of them (only the slots
    # that need more than the full step walk the rest of the ladder)
    trials = jax.vmap(lambda s, t: solver.propose(problem(t), s, o))(q.slots, th)
    merit_of = lambda x, k: solver.merit(problem(_take(th, k)), _take(trials.state, k), x)  # noqa: E731
    x_new, improve = solver.line_search(merit_of, trials, o)
    slots = jax.vmap(lambda t, x, i: solver.accept(t, x, i, o))(trials, x_new, improve)
    # only running slots write back: an idle slot's copy may be stale (a held lane since freed)
    at = jnp.where(was, q.idx, num_lanes).astype(jnp.uint32)
    states = jax.tree_util.tree_map(lambda a, b: a.at[at].set(b, mode="drop"), q.states, slots)
    done = ~_running_slots(slots, o)
    q = q._replace(states=states, slots=slots)
    if release is not None:  # what only the release rule reads
        q = q._replace(objective=q.objective.at[at].set(trials.fx, mode="drop"), tick=q.tick + 1)
        ended = was & done & ~lanes.held.lanes[q.idx]
        group = lanes.held.group[q.idx]
        left = q.left.at[jnp.where(ended, group, num_lanes)].add(-1, mode="drop")
        pending = q.pending | jnp.any(ended & (left[group] == 0))
        waiting = lanes.num_first - q.ptr + q.num_later - q.later_ptr
        fire = pending & ((q.tick % RELEASE_EVERY == 0) | (waiting < jnp.sum(done)))
        q = q._replace(left=left, pending=pending)
        q = jax.lax.cond(fire, partial(_free, release, lanes), lambda q: q, q)
    return _refill(lanes, q, done)


def _solve_lanes(problem, theta, x0, eq_mask, nu0, active, rank, held: Held, release, o: SolverOptions) -> SolverResult:
    """`solve_lanes` on one flat batch of ``L`` lanes: the queue loop.

    One loop of ``W`` slots to the end. A second, narrower loop for the last long lanes
    once the queue is empty would copy the whole solver step into the executable again,
    for the same results lane by lane."""
    num_lanes = x0.shape[0]
    width = _num_slots(num_lanes, o)
    active = jnp.asarray(active, bool)
    hold = held.lanes & active
    if release is None:  # nothing is ever freed: held lanes are inactive
        active, hold = active & ~hold, jnp.zeros_like(hold)
    first = active & ~hold
    states = jax.vmap(lambda x, m, nu, a: solver.init(x, m, nu, a, o))(x0, eq_mask, nu0, first)
    lanes = _Lanes(
        theta=theta,
        order=_queue_order(first, rank),
        num_first=jnp.sum(first.astype(jnp.int32)),
        by_rank=_queue_order(jnp.ones_like(first), rank),
        held=Held(hold, held.group, held.aux),
        nu0=jax.vmap(lambda x, m, nu: solver.init(x, m, nu, True, o).nu)(x0, eq_mask, nu0),
    )
    left = jnp.zeros(num_lanes, jnp.int32).at[held.group].add(first.astype(jnp.int32), mode="drop")
    q = _Queue(
        states=states,
        slots=_take(states, jnp.zeros(width, jnp.int32)),
        idx=jnp.zeros(width, jnp.int32),
        ptr=jnp.asarray(0, jnp.int32),
        objective=jnp.zeros(num_lanes, x0.dtype),
        left=left,
        freed=jnp.zeros(num_lanes, bool),
        later=jnp.zeros(num_lanes, jnp.int32),
        num_later=jnp.asarray(0, jnp.int32),
        later_ptr=jnp.asarray(0, jnp.int32),
        pending=jnp.asarray(False),
        tick=jnp.asarray(0, jnp.int32),
    )
    if release is not None:  # groups with no unheld lane are complete from the start
        q = _free(release, lanes, q)
    # every slot takes a lane; one left without holds lane 0's state, marked finished
    q = q._replace(slots=dataclasses.replace(q.slots, status=jnp.full(width, LaneStatus.NO_START, jnp.int32)))
    q = _refill(lanes, q, jnp.ones(width, bool))

    def cond(q: _Queue):
        return jnp.any(_running_slots(q.slots, o))

    q = jax.lax.while_loop(cond, partial(_advance, problem, release, lanes, o), q)
    # theta taken by lane index, as the slots take it: fg then compiles as in the loop (given
    # theta itself, XLA simplifies across its broadcasts and rounds f(x) differently).
    th = _take(theta, jnp.arange(num_lanes))
    return jax.vmap(lambda s, t: solver.to_result(problem(t), s))(q.states, th)
