"""The augmented-Lagrangian solver and its work queue on their own, without grasp physics.

Small programs in ``x = (x0, x1, x2)`` with three constraint rows (``>= 0`` where
feasible) whose KKT points are derived by hand below. The sign convention is the
solver's: the Lagrangian is ``f + nu h - lam . g`` with ``h`` the row picked by
``eq_mask``, so at a KKT point ``grad f + nu grad h - sum_i lam_i grad g_i = 0`` and
``lam >= 0``.

Every program is a branch of one ``lax.switch`` whose index (and a shift of ``x``) is
lane data, so a whole batch of them is one compilation (under ``vmap`` every branch is
computed and the lane's own is selected), and :func:`solve_lanes`, which takes lane data
through ``theta`` only, runs the same programs.
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.solver._lanes import Held, solve_lanes  # importing jaxgrasp turns on float64
from jaxgrasp.solver._solver import SolverOptions, SolverResult, solve
from jaxgrasp.solver._status import LaneStatus

SQRT2 = math.sqrt(2.0)


@dataclasses.dataclass(frozen=True)
class Case:
    """``min f(x)`` s.t. ``g(x) >= 0``, row ``eq_row`` (if any) ``= 0`` instead, from ``x0``;
    its expected status and, where ``x`` is given, its KKT point and objective."""

    f: Callable  # (3,) -> ()
    g: Callable  # (3,) -> (3,)
    x0: tuple
    eq_row: int | None = None
    x: tuple | None = None  # expected minimiser, multipliers and objective (None: not checked)
    lam: tuple = (0.0, 0.0, 0.0)
    nu: float = 0.0
    objective: float | None = None
    status: LaneStatus = LaneStatus.CONVERGED
    active: bool = True


def _sq(v):
    return jnp.dot(v, v)


CASES = {
    # Unconstrained minimum (1, 2, -1) inside the ball |x|^2 <= 9: no multiplier.
    "inactive_inequality": Case(
        f=lambda x: _sq(x - jnp.array([1.0, 2.0, -1.0])),
        g=lambda x: jnp.stack([9.0 - _sq(x), x[2] + 5.0, 5.0 - x[2]]),
        x0=(0.0, 0.0, 0.0),
        x=(1.0, 2.0, -1.0),
        objective=0.0,
    ),
    # Projection of a = (2, 2, 0) onto the unit ball: x = a / |a|, and
    # 2 (x - a) + 2 lam x = 0 gives 1 + lam = |a| = 2 sqrt 2.
    "active_circle": Case(
        f=lambda x: _sq(x - jnp.array([2.0, 2.0, 0.0])),
        g=lambda x: jnp.stack([1.0 - _sq(x), x[2] + 5.0, 5.0 - x[2]]),
        x0=(0.0, 0.0, 0.0),
        x=(1.0 / SQRT2, 1.0 / SQRT2, 0.0),
        lam=(2.0 * SQRT2 - 1.0, 0.0, 0.0),
        objective=(2.0 * SQRT2 - 1.0) ** 2,
    ),
    # Projection of (3, 1) onto the half-plane x0 + x1 <= 2: x = (2, 0); grad f = (-2, -2)
    # and grad g0 = (-1, -1) give lam = 2.
    "active_linear": Case(
        f=lambda x: (x[0] - 3.0) ** 2 + (x[1] - 1.0) ** 2 + x[2] ** 2,
        g=lambda x: jnp.stack([2.0 - x[0] - x[1], x[2] + 1.0, 4.0 - x[2]]),
        x0=(0.0, 0.0, 0.5),
        x=(2.0, 0.0, 0.0),
        lam=(2.0, 0.0, 0.0),
        objective=2.0,
    ),
    # min x0^2 + 2 x1^2 + (x2 - 1)^2 on x0 + x1 = 3: 2 x0 + nu = 0, 4 x1 + nu = 0 give
    # x = (2, 1, 1), nu = -4, f = 6; the ball row (10 - 6 = 4) and x2 + 2 are inactive.
    "equality": Case(
        f=lambda x: x[0] ** 2 + 2.0 * x[1] ** 2 + (x[2] - 1.0) ** 2,
        g=lambda x: jnp.stack([10.0 - _sq(x), x[0] + x[1] - 3.0, x[2] + 2.0]),
        x0=(0.0, 0.0, 0.0),
        eq_row=1,
        x=(2.0, 1.0, 1.0),
        nu=-4.0,
        objective=6.0,
    ),
    # min |x - (1, 2, 3)|^2 on x0 + x1 + x2 = 3, x2 <= 1 (active), x0 >= -5 (inactive):
    # x = (0.5, 1.5, 1); grad f = (-1, -1, -4), so -1 + nu = 0 and -4 + nu + lam2 = 0:
    # nu = 1, lam2 = 3; f = 0.25 + 0.25 + 4.
    "mixed": Case(
        f=lambda x: _sq(x - jnp.array([1.0, 2.0, 3.0])),
        g=lambda x: jnp.stack([x[0] + 5.0, x[0] + x[1] + x[2] - 3.0, 1.0 - x[2]]),
        x0=(0.0, 0.0, 0.0),
        eq_row=1,
        x=(0.5, 1.5, 1.0),
        lam=(0.0, 0.0, 3.0),
        nu=1.0,
        objective=4.5,
    ),
    # Rosenbrock's valley (non-convex, indefinite Hessian at the start) from its classic
    # start (-1.2, 1): minimum (1, 1, 0) inside the ball |x|^2 <= 4.
    "rosenbrock": Case(
        f=lambda x: (1.0 - x[0]) ** 2 + 100.0 * (x[1] - x[0] ** 2) ** 2 + x[2] ** 2,
        g=lambda x: jnp.stack([4.0 - _sq(x), x[2] + 1.0, 1.0 - x[2]]),
        x0=(-1.2, 1.0, 0.5),
        x=(1.0, 1.0, 0.0),
        objective=0.0,
    ),
    # A saddle, -x0 x1, on the disc x0^2 + x1^2 <= 2: local minimum (1, 1, 0) in the
    # start's quadrant, grad f = (-1, -1, 0) = lam0 grad g0 = lam0 (-2, -2, 0): lam0 = 1/2.
    # The Lagrangian's Hessian along the circle, direction (1, -1, 0), is 4 > 0.
    "saddle_on_circle": Case(
        f=lambda x: -x[0] * x[1] + x[2] ** 2,
        g=lambda x: jnp.stack([2.0 - x[0] ** 2 - x[1] ** 2, x[2] + 1.0, 1.0 - x[2]]),
        x0=(0.5, 0.3, 0.2),
        x=(1.0, 1.0, 0.0),
        lam=(0.5, 0.0, 0.0),
        objective=-1.0,
    ),
    # x0 >= 1 and x0 <= -1: no feasible point (the least violation is at x0 = 0).
    "infeasible": Case(
        f=lambda x: _sq(x),
        g=lambda x: jnp.stack([x[0] - 1.0, -x[0] - 1.0, x[1] + 10.0]),
        x0=(3.0, 1.0, 0.0),
        status=LaneStatus.INFEASIBLE,
    ),
    # An inactive lane is not run at all.
    "inactive_lane": Case(
        f=lambda x: _sq(x - 1.0),
        g=lambda x: jnp.stack([1.0 - _sq(x), x[1] + 1.0, x[2] + 1.0]),
        x0=(0.3, -0.2, 0.1),
        status=LaneStatus.NO_START,
        active=False,
    ),
}
NAMES = tuple(CASES)


def _lane_functions(names):
    """``fg(x, theta) = (f, g)`` of lanes whose ``theta`` picks one of the programs ``names`` (index
    ``theta["kind"]``) and moves it by ``theta["shift"]`` (``(3,)``: x* moves by it)."""
    fs = [CASES[n].f for n in names]
    gs = [CASES[n].g for n in names]

    def f(x, theta):
        return jax.lax.switch(theta["kind"], fs, x - theta["shift"])

    def g(x, theta):
        return jax.lax.switch(theta["kind"], gs, x - theta["shift"])

    return lambda x, theta: (f(x, theta), g(x, theta))


@partial(jax.jit, static_argnames=("names", "options"))
def _solve_batch(names, theta, x0, eq_mask, nu0, active, options):
    """``vmap`` of :func:`solve` over lanes (the reference for the work queue)."""
    fg = _lane_functions(names)

    def one(t, x, m, nu, a):
        return solve(lambda z: fg(z, t), x, m, nu, options, a)

    return jax.vmap(one)(theta, x0, eq_mask, nu0, active)


@pytest.fixture(scope="module")
def known():
    """Every case of :data:`CASES` solved by :func:`solve`, one lane each, in one batch."""
    cases = [CASES[n] for n in NAMES]
    theta = {"kind": jnp.arange(len(cases)), "shift": jnp.zeros((len(cases), 3))}
    eq_mask = jnp.array([np.eye(3)[c.eq_row] if c.eq_row is not None else np.zeros(3) for c in cases])
    x0 = jnp.array([c.x0 for c in cases])
    active = jnp.array([c.active for c in cases])
    res = _solve_batch(NAMES, theta, x0, eq_mask, jnp.zeros(len(cases)), active, SolverOptions())
    assert res.x.dtype == jnp.float64
    return {n: jax.tree_util.tree_map(lambda a, i=i: np.asarray(a[i]), res) for i, n in enumerate(NAMES)}


@pytest.mark.parametrize("name", NAMES)
def test_status(known, name):
    assert LaneStatus(int(known[name].status)) == CASES[name].status


@pytest.mark.parametrize("name", [n for n in NAMES if CASES[n].x is not None])
def test_known_kkt_point(known, name):
    c, r = CASES[name], known[name]
    np.testing.assert_allclose(r.x, c.x, rtol=0, atol=1e-8)
    np.testing.assert_allclose(r.lam, c.lam, rtol=0, atol=1e-8)
    np.testing.assert_allclose(r.nu, c.nu, rtol=0, atol=1e-8)
    np.testing.assert_allclose(r.objective, c.objective, rtol=0, atol=1e-9)
    assert max(r.stationarity, r.feasibility, r.complementarity) <= SolverOptions().tol
    assert 0 < r.steps <= SolverOptions().max_steps


def test_infeasible_program(known):
    r = known["infeasible"]
    assert r.feasibility > SolverOptions().infeasible_tol
    assert 1 < r.steps < SolverOptions().max_steps  # it had to walk to x0 = 0 first


def test_inactive_lane_is_not_run(known):
    r = known["inactive_lane"]
    assert int(r.steps) == 0
    np.testing.assert_array_equal(r.x, CASES["inactive_lane"].x0)


# --- the work queue: solve_lanes must give every lane what solve gives it

# 32 slots for 96 lanes (for 288 under an outer vmap): finished lanes hand their slot on.
# A small step budget makes some lanes run to it while others finish in a few steps.
QUEUE_OPTIONS = SolverOptions(max_steps=40, slot_fraction=1.0 / 3.0, max_slots=32)
NUM_LANES = 96
# Fewer programs than above (each is a branch every lane computes): a quick one, one with
# an equality and two active rows, a non-convex valley and an infeasible one.
QUEUE_CASES = ("active_linear", "mixed", "rosenbrock", "infeasible")


def _lane_batch(seed: int):
    """``NUM_LANES`` distinct lanes: programs of :data:`QUEUE_CASES` drawn at random,
    each shifted and started elsewhere, with an equality row (or none) and its initial
    multiplier drawn at random, and about one lane in six inactive."""
    rng = np.random.default_rng(seed)
    kind = rng.integers(0, len(QUEUE_CASES), NUM_LANES)
    shift = rng.uniform(-3.0, 3.0, (NUM_LANES, 3))
    x0 = shift + rng.normal(0.0, 1.5, (NUM_LANES, 3))
    rows = rng.integers(-1, 3, NUM_LANES)  # -1: no equality
    eq_mask = np.where(rows[:, None] >= 0, np.eye(3)[np.maximum(rows, 0)], 0.0)
    nu0 = np.where(rows >= 0, rng.normal(0.0, 0.5, NUM_LANES), 0.0)
    active = rng.uniform(size=NUM_LANES) > 1.0 / 6.0
    theta = {"kind": jnp.asarray(kind), "shift": jnp.asarray(shift)}
    return theta, jnp.asarray(x0), jnp.asarray(eq_mask), jnp.asarray(nu0), jnp.asarray(active)


def _assert_same_lanes(got: SolverResult, want: SolverResult):
    """Every field equal lane by lane: the integers exactly, the floats to 1e-12 (the queue
    runs the same arithmetic compiled for another batch width, which may round apart)."""
    for field in dataclasses.fields(SolverResult):
        a = np.asarray(getattr(got, field.name))
        b = np.asarray(getattr(want, field.name))
        assert a.shape == b.shape, field.name
        if np.issubdtype(b.dtype, np.floating):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=field.name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=field.name)


def _queue_is_exercised(ref: SolverResult):
    """The batch makes the queue work: more active lanes than slots (refills), step
    counts from a few to the budget, and every status."""
    steps, status = np.asarray(ref.steps), np.asarray(ref.status)
    ran = status != LaneStatus.NO_START
    assert np.sum(ran) > QUEUE_OPTIONS.max_slots
    assert np.min(steps[ran]) <= 5
    for s in LaneStatus:
        assert np.any(status == s), s.label
    assert np.any(steps == QUEUE_OPTIONS.max_steps)


def _queue(theta, x0, eq_mask, nu0, active):
    fg = _lane_functions(QUEUE_CASES)
    return solve_lanes(lambda t: lambda x: fg(x, t), theta, x0, eq_mask, nu0, active, QUEUE_OPTIONS)


@pytest.mark.slow  # compiles solve_lanes batches
def test_solve_lanes_equals_vmap_of_solve():
    lanes = _lane_batch(0)
    want = _solve_batch(QUEUE_CASES, *lanes, QUEUE_OPTIONS)
    _queue_is_exercised(want)
    _assert_same_lanes(jax.jit(_queue)(*lanes), want)


@pytest.mark.slow  # compiles solve_lanes batches
def test_solve_lanes_under_outer_vmap():
    """An outer ``vmap`` folds its batch into the lanes (``custom_vmap``): one queue of 32
    slots for 3 x 96 lanes, each lane still what ``solve`` gives it. The equality rows are
    shared by the batch (not batched), the rest differs."""
    batches = [_lane_batch(seed) for seed in (1, 2, 3)]
    eq_mask = batches[0][2]
    theta, x0, _, nu0, active = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *batches)
    got = jax.jit(jax.vmap(_queue, in_axes=(0, 0, None, 0, 0)))(theta, x0, eq_mask, nu0, active)
    for b, (t, x, _, nu, a) in enumerate(batches):
        want = _solve_batch(QUEUE_CASES, t, x, eq_mask, nu, a, QUEUE_OPTIONS)
        _queue_is_exercised(want)
        _assert_same_lanes(jax.tree_util.tree_map(lambda a: a[b], got), want)


# --- held lanes: a second wave freed by a rule on the first wave's results, in one queue

GROUP = 8  # lanes per group; the first FIRST of each group run at once, the others are held
FIRST = 3


def _release_rule(status, objective, complete, aux):
    """A group's held lanes run where one of its first lanes did not converge, or where
    its least converged objective lies below the group's bar (``aux``, per lane)."""
    status, objective, bar = (jnp.reshape(a, (-1, GROUP)) for a in (status, objective, aux))
    first = jnp.arange(GROUP) < FIRST
    conv = first & (status == LaneStatus.CONVERGED)
    low = jnp.min(jnp.where(conv, objective, jnp.inf), axis=-1)
    free = jnp.any(first & (status != LaneStatus.CONVERGED) & (status != LaneStatus.NO_START), axis=-1) | (
        low < bar[:, 0]
    )
    return jnp.repeat(free, GROUP)


def _held(seed: int):
    """``Held`` lanes of :func:`_lane_batch`'s size: all but the first ``FIRST`` of each
    group of ``GROUP``, with a bar per group drawn at random."""
    lane = np.arange(NUM_LANES)
    bar = np.repeat(np.random.default_rng(seed + 100).uniform(-1.0, 3.0, NUM_LANES // GROUP), GROUP)
    return Held(jnp.asarray(lane % GROUP >= FIRST), jnp.asarray(lane // GROUP), jnp.asarray(bar))


def _freed(want: SolverResult, held: Held, active) -> np.ndarray:
    """``(L,)`` the held lanes the rule frees, applied to the first lanes' final results
    (every held lane ``NO_START``, as the queue shows them)."""
    first = ~np.asarray(held.lanes)
    status = np.where(first, np.asarray(want.status), LaneStatus.NO_START)
    complete = jnp.ones(status.shape, bool)
    return np.asarray(_release_rule(jnp.asarray(status), want.objective, complete, held.aux)) & ~first & np.asarray(active)


def _released_queue(theta, x0, eq_mask, nu0, active, held):
    fg = _lane_functions(QUEUE_CASES)
    return solve_lanes(lambda t: lambda x: fg(x, t), theta, x0, eq_mask, nu0, active, QUEUE_OPTIONS,
                       held=held, release=_release_rule)


def _check_release(got: SolverResult, want: SolverResult, theta, x0, eq_mask, nu0, active, held):
    """``got`` is ``want`` (every lane solved) where a lane ran, and an inactive lane's
    result (``solve`` with ``active`` false) for each held lane the rule did not free."""
    free = _freed(want, held, active)
    idle = np.asarray(held.lanes) & ~free
    unrun = _solve_batch(QUEUE_CASES, theta, x0, eq_mask, nu0, jnp.zeros(x0.shape[0], bool), QUEUE_OPTIONS)
    expected = jax.tree_util.tree_map(
        lambda u, w: np.where(idle.reshape((-1,) + (1,) * (np.ndim(w) - 1)), np.asarray(u), np.asarray(w)), unrun, want
    )
    _assert_same_lanes(got, expected)
    # the batch exercises the rule: groups freed and groups not, more lanes than slots
    groups = free.reshape(-1, GROUP).any(axis=1)
    assert groups.any() and not groups.all()
    assert np.sum(free) + np.sum(~np.asarray(held.lanes) & np.asarray(active)) > QUEUE_OPTIONS.max_slots


@pytest.mark.slow  # compiles solve_lanes batches
def test_held_lanes_run_where_released():
    """Held lanes run only where ``release``, shown every first lane's final result,
    frees them; each lane that runs is what ``solve`` gives it, the others never start."""
    lanes = _lane_batch(0)
    held = _held(0)
    want = _solve_batch(QUEUE_CASES, *lanes, QUEUE_OPTIONS)
    got = jax.jit(_released_queue)(*lanes, held)
    _check_release(got, want, *lanes, held)


@pytest.mark.slow  # compiles solve_lanes batches
def test_held_lanes_under_outer_vmap():
    """Folded into one queue by an outer ``vmap``, each batch's groups are still its own:
    a group of one batch is freed by its own first lanes only."""
    batches = [_lane_batch(seed) for seed in (1, 2, 3)]
    helds = [_held(seed) for seed in (1, 2, 3)]
    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *batches)
    held = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *helds)
    got = jax.jit(jax.vmap(_released_queue))(*stacked, held)
    for b, (lanes, h) in enumerate(zip(batches, helds)):
        want = _solve_batch(QUEUE_CASES, *lanes, QUEUE_OPTIONS)
        _check_release(jax.tree_util.tree_map(lambda a: a[b], got), want, *lanes, h)


def test_solve_lanes_rank_orders_the_queue_not_the_results():
    """``rank`` decides which lanes the queue loads first (active lanes by rank, in lane
    order within a rank, inactive ones never), and nothing else: every lane's result is
    the same, bit for bit, whatever the order."""
    from jaxgrasp.solver._lanes import _queue_order

    active = jnp.array([True, False, True, True, True, False, True])
    rank = jnp.array([1, 0, 0, 2, 1, 0, 0])
    np.testing.assert_array_equal(np.asarray(_queue_order(active, rank))[:5], [2, 6, 0, 4, 3])
    theta, x0, eq_mask, nu0, act = _lane_batch(0)
    fg = _lane_functions(QUEUE_CASES)
    rank = jnp.asarray(np.random.default_rng(5).integers(0, 3, x0.shape[0]))
    ranked = jax.jit(
        lambda *a: solve_lanes(lambda t: lambda x: fg(x, t), *a, QUEUE_OPTIONS, rank=rank)
    )(theta, x0, eq_mask, nu0, act)
    _assert_same_lanes(ranked, jax.jit(_queue)(theta, x0, eq_mask, nu0, act))


@pytest.mark.parametrize(
    "viol, stationarity, inner, grows",
    [
        (9e-4, 0.5, 15, True),  # inner solve reached its tolerance
        (9e-4, 10.0, 15, False),  # cut short at max_inner near feasibility: keep the penalty
        (9e-4, 10.0, 16, True),  # ended because no step lowered phi (numerically converged)
        (0.5, 10.0, 15, True),  # cut short, but far from feasible (above FAR_VIOLATION)
    ],
)
def test_penalty_growth_after_a_stalled_violation(viol, stationarity, inner, grows):
    """The violation stalled (not 4x below the last update's) in every case; whether the
    penalty of a lane with an equality grows depends on how the inner solve ended and on
    how far from feasible the lane is (``solver._multiplier_update``). The multipliers are
    updated either way."""
    from jaxgrasp.solver._solver import (
        FAR_VIOLATION,
        FirstOrder,
        _inner_tol,
        _multiplier_update,
        _rounding_floor,
        init,
    )

    o = SolverOptions()
    assert o.max_inner == 15 and (viol > FAR_VIOLATION) == (viol == 0.5)
    s = init(jnp.zeros(3), jnp.array([0.0, 1.0, 0.0]), 0.5, True, o)
    s = dataclasses.replace(s, prev_viol=jnp.asarray(viol), inner=jnp.asarray(inner, jnp.int32))
    d = FirstOrder(fx=jnp.asarray(0.0), gx=jnp.array([1.0, viol, 1.0]), grad_f=jnp.zeros(3), jac=jnp.eye(3))
    floor = _rounding_floor(s, d)
    new = _multiplier_update(s, d, jnp.full(3, stationarity * float(_inner_tol(s, floor, o))), floor, o)
    assert float(new.rho) == (o.rho0 * o.rho_growth if grows else o.rho0)
    assert float(new.nu) == pytest.approx(0.5 + o.rho0 * viol)
    # without an equality (the equilibrium problem) the penalty grows as before: a stalled
    # violation of row 1 (g < 0) raises it whatever the inner solve did
    s_ineq = dataclasses.replace(s, eq_mask=jnp.zeros(3))
    d_ineq = dataclasses.replace(d, gx=jnp.array([1.0, -viol, 1.0]))
    new = _multiplier_update(s_ineq, d_ineq, jnp.full(3, stationarity * float(_inner_tol(s, floor, o))), floor, o)
    assert float(new.rho) == o.rho0 * o.rho_growth


def test_penalty_grows_after_grow_penalty_after_steps():
    """A lane with an equality whose inner solve was cut short near feasibility keeps its
    penalty, until it has taken ``grow_penalty_after`` steps: from then on a stalled
    violation raises it (a crawling lane ends converged or infeasible, not at the budget)."""
    from jaxgrasp.solver._solver import (
        FirstOrder,
        _inner_tol,
        _multiplier_update,
        _rounding_floor,
        init,
    )

    o = SolverOptions()
    s = init(jnp.zeros(3), jnp.array([0.0, 1.0, 0.0]), 0.5, True, o)
    s = dataclasses.replace(s, prev_viol=jnp.asarray(9e-4), inner=jnp.asarray(o.max_inner, jnp.int32))
    d = FirstOrder(fx=jnp.asarray(0.0), gx=jnp.array([1.0, 9e-4, 1.0]), grad_f=jnp.zeros(3), jac=jnp.eye(3))
    floor = _rounding_floor(s, d)
    gphi = jnp.full(3, 10.0 * float(_inner_tol(s, floor, o)))
    for steps, grows in [(0, False), (o.grow_penalty_after - 1, False), (o.grow_penalty_after, True)]:
        new = _multiplier_update(dataclasses.replace(s, steps=jnp.asarray(steps, jnp.int32)), d, gphi, floor, o)
        assert float(new.rho) == (o.rho0 * o.rho_growth if grows else o.rho0), steps


@pytest.mark.parametrize(
    "viol, slope, cap, factor",
    [
        (0.5, 1e-4, 1e6, 1e3),  # far, stalled, |grad v| / v = 1e-4: to 1e-4 / (0.1 * 1e-6)
        (0.5, 1e-2, 1e3, 1e3),  # the predicted 1e5 capped at stall_growth_max
        (0.5, 1e-5, 1e6, 100.0),  # close to passing: a smaller jump
        (0.5, 0.5, 1e6, 10.0),  # |grad v| of the order of v (a lane that may still converge)
        (9e-4, 1e-4, 1e6, 10.0),  # near feasibility (below FAR_VIOLATION)
        (0.5, 1e-4, 10.0, 10.0),  # stall_growth_max = rho_growth: the fixed growth
    ],
)
def test_penalty_jump_at_a_nearly_stationary_violation(viol, slope, cap, factor):
    """A stalled violation grows the penalty by ``rho_growth``, except far from
    feasibility at a point where the violation measure's gradient is already small
    (``NEAR_STATIONARY``): there by the factor that takes ``|grad v| / v`` to
    ``PREDICT_MARGIN * infeasible_stationarity`` (``solver._penalty_growth``)."""
    from jaxgrasp.solver._solver import FirstOrder, _multiplier_update, _rounding_floor, init

    o = SolverOptions(stall_growth_max=cap)
    s = init(jnp.zeros(3), jnp.array([0.0, 1.0, 0.0]), 0.5, True, o)
    s = dataclasses.replace(s, prev_viol=jnp.asarray(viol), inner=jnp.asarray(o.max_inner + 1, jnp.int32))
    # the equality's row scaled so that grad v = J^T r has |.|_inf = slope * viol
    jac = jnp.diag(jnp.array([1.0, slope, 1.0]))
    d = FirstOrder(fx=jnp.asarray(0.0), gx=jnp.array([1.0, viol, 1.0]), grad_f=jnp.zeros(3), jac=jac)
    new = _multiplier_update(s, d, jnp.zeros(3), _rounding_floor(s, d), o)
    assert float(new.rho) == pytest.approx(o.rho0 * factor, rel=1e-12)
    assert int(new.status) == LaneStatus.NOT_CONVERGED  # the jump decides nothing by itself


def test_infeasible_lane_ends_sooner_with_the_penalty_jump():
    """An infeasible program whose objective pulls away from the violation's minimiser
    (the unit disc and the half-plane ``x0 + x1 >= 3``, ``f`` pulling ``(x0, x1)`` to
    ``(5, 3)``): ``|grad v| / v`` at the inner minimisers falls like ``1 / rho``. With the
    jump the lane ends infeasible at the same point in fewer steps than with the fixed
    tenfold growth."""
    fg = lambda x: (_sq(x - jnp.array([5.0, 3.0, 0.0])),
                    jnp.stack([1.0 - _sq(x[:2]), x[0] + x[1] - 3.0, x[2] + 10.0]))
    x0, mask = jnp.array([3.0, 1.0, 0.5]), jnp.zeros(3)
    new = solve(fg, x0, mask, 0.0, SolverOptions())
    old = solve(fg, x0, mask, 0.0, SolverOptions(stall_growth_max=SolverOptions().rho_growth))
    assert int(new.status) == int(old.status) == LaneStatus.INFEASIBLE
    assert int(new.steps) < int(old.steps)
    np.testing.assert_allclose(new.x, old.x, rtol=0, atol=1e-6)
    assert float(new.feasibility) == pytest.approx(float(old.feasibility), rel=1e-8)


@pytest.mark.slow  # compile-heavy
def test_nan_nu0_is_the_least_squares_multiplier():
    """``nu0 = NaN``: the equality multiplier starts at its least-squares estimate at x0
    (``grad f + nu grad h = 0``; here ``f = |x - a|^2 / 2``, ``h = b . x - 1``, x0 = 0, so
    ``nu = a . b / |b|^2``), and the lane is the one started there by hand. An inactive
    lane's multiplier is 0, not NaN."""
    from jaxgrasp.solver._solver import init, propose

    a, b = jnp.array([1.0, -2.0, 0.5]), jnp.array([0.3, 1.0, -0.7])
    fg = lambda x: (0.5 * _sq(x - a), jnp.stack([x[0] + 4.0, jnp.dot(b, x) - 1.0, 4.0 - x[2]]))
    mask = jnp.array([0.0, 1.0, 0.0])
    o = SolverOptions()
    nu_ls = float(jnp.dot(a, b) / _sq(b))
    t = propose(fg, init(jnp.zeros(3), mask, jnp.nan, True, o), o)
    assert float(t.state.nu) == pytest.approx(nu_ls, rel=1e-14)
    got, want = solve(fg, jnp.zeros(3), mask, jnp.nan), solve(fg, jnp.zeros(3), mask, nu_ls)
    assert int(got.status) == LaneStatus.CONVERGED
    _assert_same_lanes(got, want)
    off = solve(fg, jnp.zeros(3), mask, jnp.nan, active=False)
    assert float(off.nu) == 0.0


@pytest.mark.parametrize("eq_row, minimiser", [(None, -2.0), (1, -0.5)])
def test_a_running_lane_steps_whatever_its_two_stationarity_tests_say(monkeypatch, eq_row, minimiser):
    """``propose`` asks whether the inner solve is done twice: before the multiplier update
    and, after it, of the updated lane. Where there was no update the second asks the
    same of the same numbers, but XLA may round the two apart (far from feasibility phi's
    gradient is a difference of terms of 1e10). A lane whose first test says "not done"
    and whose second says "done" must still take its Newton step: before, it took neither,
    its step count stood still and its work queue never ended (a 7-contact grasp of
    ``experiments/memory_at_scale/batch_100k.py``'s set hung ``jaxgrasp batch``). Here the two tests are
    made to disagree on every step."""
    from jaxgrasp.solver import _solver as S

    real, calls = S._inner_done, []

    def disagreeing(s, d, floor, o):
        gphi, _ = real(s, d, floor, o)
        calls.append(None)
        return gphi, jnp.asarray(len(calls) % 2 == 0)  # first test of a step: not done; second: done

    monkeypatch.setattr(S, "_inner_done", disagreeing)
    fg = lambda x: (0.5 * _sq(x - jnp.array([1.0, -2.0, 0.5])), jnp.stack([x[0] + 4.0, 1.0 - x[1], 4.0 - x[2]]))
    o = SolverOptions()
    mask = jnp.zeros(3) if eq_row is None else jnp.eye(3)[eq_row]
    s = S.init(jnp.zeros(3), mask, 0.0, True, o)
    for k in range(3):
        calls.clear()
        new = S.step(fg, s, o)
        assert len(calls) == 2
        assert int(new.steps) == int(s.steps) + 1, k  # the Newton step (no update was asked for)
        s = new
    # the steps were taken: phi's minimiser (with the equality h = 1 - x1, rho 1 and nu 0,
    # (x1 + 2)^2 / 2 + h^2 / 2 is least at x1 = -0.5)
    np.testing.assert_allclose(s.x, [1.0, minimiser, 0.5], rtol=0, atol=1e-12)


def test_stationarity_tolerance_is_the_gradient_rounding_floor_capped():
    """Where phi's penalty Hessian ``rho J^T D J`` is so stiff that moving ``x`` by a few
    ulps moves phi's gradient by more than tol, a lane counts as stationary at that floor
    (``ROUNDING_ULPS * eps * rho * max(|J|^T D |J| |x|)``), at most
    ``MAX_STATIONARITY_TOL * tol``; elsewhere at tol. Rows where phi is not quadratic (an
    inactive inequality) do not count."""
    from jaxgrasp.solver._solver import (
        MAX_STATIONARITY_TOL,
        ROUNDING_ULPS,
        FirstOrder,
        _lane_status,
        _rounding_floor,
        _stationarity_tol,
        init,
    )

    o = SolverOptions()
    eps = float(jnp.finfo(jnp.float64).eps)
    x = jnp.array([0.1, -0.2, 0.05])
    jac = jnp.array([[17.0, 3.0, 0.0], [0.0, 0.0, 50.0], [1.0, 1.0, 1.0]])
    # row 0 active (lam > 0, g = 0: quadratic), row 1 inactive (lam = 0, g > 0), row 2
    # the equality
    d = FirstOrder(fx=jnp.asarray(0.0), gx=jnp.array([0.0, 1.0, 0.0]), grad_f=jnp.zeros(3), jac=jac)
    s = init(x, jnp.array([0.0, 0.0, 1.0]), 0.3, True, o)
    s = dataclasses.replace(s, lam=jnp.array([2.0, 0.0, 0.0]))
    a = np.abs(np.asarray(jac))[[0, 2]]
    floor_per_rho = ROUNDING_ULPS * eps * np.max(a.T @ (a @ np.abs(np.asarray(x))))
    floor = _rounding_floor(s, d)
    assert float(floor) == pytest.approx(floor_per_rho, rel=1e-12)
    for rho in (10.0, 1e4, 1e5, 1e12):
        sr = dataclasses.replace(s, rho=jnp.asarray(rho))
        expected = min(max(o.tol, rho * floor_per_rho), MAX_STATIONARITY_TOL * o.tol)
        assert float(_stationarity_tol(sr, floor, o)) == pytest.approx(expected, rel=1e-12), rho
    assert float(_stationarity_tol(dataclasses.replace(s, rho=jnp.asarray(10.0)), floor, o)) == o.tol
    assert 1e4 * floor_per_rho > o.tol and 1e5 * floor_per_rho > MAX_STATIONARITY_TOL * o.tol  # both regimes hit
    # the status follows it: stationarity 3 tol converges at penalty 1e5, not at 10
    for rho, status in [(10.0, LaneStatus.NOT_CONVERGED), (1e5, LaneStatus.CONVERGED)]:
        sr = dataclasses.replace(s, rho=jnp.asarray(rho), prev_viol=jnp.asarray(1.0))
        got = _lane_status(sr, d, 3.0 * o.tol, 0.0, 0.0, _rounding_floor(sr, d), o)
        assert int(got) == status, rho
