"""The augmented-Lagrangian solver: one lane of a small smooth constrained problem.

Solves, for one lane,

    minimise f(x)  subject to  g_i(x) >= 0 (i not k),  g_k(x) = 0 (at most one equality),

where the equality, if any, is one of the constraint functions picked by a one-hot
``eq_mask``: problems with different equalities then share one code path, so every
problem of a grasp, every start and every grasp run as lanes of one ``vmap``.

Method (Powell-Hestenes-Rockafellar augmented Lagrangian, Nocedal & Wright Sec. 17.4):

    phi(x) = f + nu h + rho/2 h^2 + 1/(2 rho) sum_i (max(0, lam_i - rho g_i)^2 - lam_i^2)

is minimised by Newton's method with the exact Hessian (eigenvalues mirrored and floored,
so every step is a descent direction) and a backtracking line search evaluated on a fixed
ladder of step lengths; then ``lam <- max(0, lam - rho g)``, ``nu <- nu + rho h``, and
``rho`` grows when the violation does not fall fast enough (on a lane with an equality:
after an inner solve that finished, i.e. reached its tolerance or no step could lower
phi, or while the violation is still above `FAR_VIOLATION`, or once the lane has
taken ``grow_penalty_after`` steps), by ``rho_growth``, or at once to where the
infeasibility test is expected to pass where the violation stalls far from feasibility at
a nearly stationary point of the violation measure (`_penalty_growth`). The inner
and outer loops are
flattened into one ``lax.while_loop`` whose body does a multiplier update where the inner
solve is done and then a Newton step where the (updated) inner solve is not, so lanes that
need different iteration counts do not wait on nested loops. ``steps`` counts both kinds.

Derivatives: a problem is a `Problem`, ``fg(x) = (f, g)`` in one call. Each step
takes the problem's first-order data once (`FirstOrder`: ``f``, ``g``, ``grad f``
and the Jacobian ``J`` of ``g``; by default one forward-mode pass); every gradient it needs
is then ``grad f + J^T w`` for some weights ``w`` (phi's before and after the multiplier
update, the violation's), and phi's Hessian is ``hess(f + w . g) + rho J^T D J``. A
problem with structure may supply its own first-order data and Lagrangian Hessian
(`jaxgrasp.tolerance._problems` does, from the contact kinematics); otherwise autodiff.

Each lane ends with a status and its KKT residuals at ``(x, lam, nu)``:
stationarity ``|grad f + nu grad h - sum lam grad g|_inf``, feasibility
``max(|h|, max(-g_i, 0))`` and complementarity ``max |lam_i g_i|``.

`solve` runs one lane; its pieces `init`, `step` (itself
`propose`, `line_search` and `accept`), `running` and
`to_result` are public so that the work queue of `jaxgrasp.solver.solve_lanes`, which runs
many lanes with early exit, can drive them: it runs one line search over all its slots.
The direction is `jaxgrasp.solver._direction.newton_direction` and the ladder
`jaxgrasp.solver._line_search.line_search`; under ``vmap`` each pays for ``eigh`` and for
step lengths past the first only on the lanes that need them.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.base import contract, json_floats
from jaxgrasp.solver._direction import newton_direction
from jaxgrasp.solver._line_search import line_search as ladder_search
from jaxgrasp.solver._status import LaneStatus

__all__ = [
    "Problem",
    "FirstOrder",
    "as_problem",
    "SolverOptions",
    "SolverResult",
    "SolverState",
    "solve",
    "init",
    "step",
    "Trial",
    "propose",
    "merit",
    "line_search",
    "accept",
    "running",
    "to_result",
    "augmented_lagrangian",
    "kkt_tol",
]


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Static settings of the solver's lanes (`jaxgrasp.solver.solve`,
    `jaxgrasp.solver.solve_lanes`; hashable; all quantities in the scaled units).

    Attributes:
        tol: KKT tolerance on stationarity, feasibility and complementarity (float64;
            in lower precision it is raised to ``1e3 * eps`` of the dtype). Where phi is
            so stiff that one ulp of ``x`` moves its gradient by more, stationarity is
            held to that rounding floor instead, at most `MAX_STATIONARITY_TOL`
            times tol (`_stationarity_tol`).
        max_steps: budget of loop steps (Newton steps plus multiplier updates) per lane.
        max_inner: Newton steps before a multiplier update is forced.
        inner_tol_factor: inner solves stop at stationarity
            ``max(tol, inner_tol_factor * min(violation, 1))``.
        rho0: initial penalty. At 1 rather than 10 the first wave of a boundary
            problem's starts settles more problems and converging lanes take fewer steps;
            infeasible lanes take a few more, started a decade further from the penalty
            that shows the violation's floor (``experiments/solver_steps/initial_penalty.py``, the
            benchmark's mixed set). Larger values stiffen phi and lengthen every lane.
        rho_growth: factor by which the penalty grows when the violation stalls (more
            where ``stall_growth_max`` allows, below).
        rho_max: largest penalty.
        infeasible_tol: a lane whose violation stays above this, where the violation is
            stationary or at ``rho_max``, is infeasible.
        infeasible_stationarity: the violation measure counts as stationary where its
            gradient (inf-norm) is below this times the violation.
        max_step: largest Newton step (inf-norm, scaled variables).
        line_search_steps: number of step lengths ``1, 1/2, 1/4, ...`` tried per Newton step;
            a feasible lane that none of them lets lower its merit tries as many again,
            ``2^-line_search_steps, ...`` (`jaxgrasp.solver._line_search`).
        slot_fraction: `jaxgrasp.solver.solve_lanes` keeps ``ceil(slot_fraction * lanes)`` lanes in
            flight (finished lanes hand their slot to the next), at most ``max_slots``.
        max_slots: upper bound on those slots. A loop step over a few hundred lanes keeps
            its working set in the CPU caches; over thousands it spills to main memory
            and costs much more per lane.
        grow_penalty_after: loop steps after which a lane with an equality grows its
            penalty whenever its violation stalls, as a lane without one does (before, not after
            an inner solve cut short at ``max_inner`` while the violation is below
            `FAR_VIOLATION`; see `_multiplier_update`). A lane still running
            then is crawling: with the growth it ends converged, or infeasible at
            ``rho_max``, instead of unsettled at ``max_steps``.
        stall_growth_max: largest factor by which the penalty grows at one update where
            the violation stalls above `FAR_VIOLATION` at a point where the
            violation measure is already nearly stationary (its gradient at most
            `NEAR_STATIONARY` times the violation): there the factor is the one
            after which the ``infeasible_stationarity`` test is expected to pass
            (`_penalty_growth`), at least ``rho_growth``. ``rho_growth`` itself
            restores the fixed growth.
    """

    tol: float = 1e-10
    max_steps: int = 300
    max_inner: int = 15
    rho0: float = 1.0
    rho_growth: float = 10.0
    rho_max: float = 1e10
    infeasible_tol: float = 1e-7
    infeasible_stationarity: float = 1e-6
    inner_tol_factor: float = 1e-2
    max_step: float = 5.0
    line_search_steps: int = 16
    slot_fraction: float = 0.0625
    max_slots: int = 128
    grow_penalty_after: int = 100
    stall_growth_max: float = 1e6


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SolverResult:
    """Outcome of one lane (leading batch axes under ``vmap``).

    Attributes:
        x: ``(n,)`` final point.
        lam: ``(m,)`` inequality multipliers, ``>= 0`` (zero at the equality's index).
        nu: ``()`` equality multiplier (0 when there is no equality).
        objective: ``()`` ``f(x)``.
        status: ``()`` int32 [`LaneStatus`][jaxgrasp.solver.LaneStatus] (``NO_START`` for an
            inactive lane).
        stationarity, feasibility, complementarity: ``()`` KKT residuals at ``(x, lam, nu)``.
        steps: ``()`` int32, Newton steps plus multiplier updates taken.
    """

    x: jax.Array | np.ndarray
    lam: jax.Array | np.ndarray
    nu: jax.Array | np.ndarray
    objective: jax.Array | np.ndarray
    status: jax.Array | np.ndarray
    stationarity: jax.Array | np.ndarray
    feasibility: jax.Array | np.ndarray
    complementarity: jax.Array | np.ndarray
    steps: jax.Array | np.ndarray

    @property
    def status_name(self) -> str:
        """Name of ``status`` for one lane (a ``()`` status): ``'converged'``, ...

        Raises:
            ValueError: a batched result; its names are
                [`status_names`][jaxgrasp.solver.SolverResult.status_names].
        """
        if np.shape(self.status) != ():
            raise ValueError(f"status_name is one lane's, but status has shape {np.shape(self.status)}: "
                             "use status_names")
        return LaneStatus(int(self.status)).label

    @property
    def status_names(self) -> np.ndarray:
        """``status`` as an array of names, same shape (one lane's or a batch's)."""
        return LaneStatus.names_of(self.status)

    def summary(self) -> str:
        """One line on one lane: its status, objective, steps and KKT residuals (the
        solver's scaled units)."""
        return (f"{self.status_name}: objective {float(self.objective):.6e} after {int(self.steps)} steps; KKT "
                f"residuals stationarity {float(self.stationarity):.2e}, feasibility {float(self.feasibility):.2e}, "
                f"complementarity {float(self.complementarity):.2e}")

    def to_dict(self) -> dict:
        """One lane's result as plain Python (JSON-ready): ``x``, ``lam`` as lists, the
        numbers as floats (``None`` where not finite), ``status`` by name.

        Raises:
            ValueError: a batched result (index it first).
        """
        name = self.status_name
        return {
            "status": name,
            "objective": json_floats(self.objective),
            "x": json_floats(np.reshape(self.x, -1)),
            "lam": json_floats(np.reshape(self.lam, -1)),
            "nu": json_floats(self.nu),
            "stationarity": json_floats(self.stationarity),
            "feasibility": json_floats(self.feasibility),
            "complementarity": json_floats(self.complementarity),
            "steps": int(self.steps),
        }


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SolverState:
    """Loop state of one lane (leading batch axes under ``vmap``): ``n`` variables, ``m``
    constraint rows, scaled units.

    Attributes:
        x: ``(n,)`` current point.
        lam: ``(m,)`` inequality multipliers, ``>= 0`` (zero at the equality's index).
        nu: ``()`` equality multiplier.
        rho: ``()`` penalty.
        eq_mask: ``(m,)`` one-hot equality selector, or zeros.
        inner: ``()`` int32, Newton steps since the last multiplier update; ``max_inner + 1``
            once a step could not lower phi (the inner solve ended numerically converged).
        prev_viol: ``()`` constraint violation at the last multiplier update (``inf`` before
            the first).
        steps: ``()`` int32, Newton steps plus multiplier updates taken.
        status: ``()`` int32 [`LaneStatus`][jaxgrasp.solver.LaneStatus], ``NOT_CONVERGED``
            while running.
        stationarity, feasibility, complementarity: ``()`` KKT residuals at the last
            multiplier update (``inf`` before the first).
    """

    x: Any
    lam: Any
    nu: Any
    rho: Any
    eq_mask: Any
    inner: Any
    prev_viol: Any
    steps: Any
    status: Any
    stationarity: Any
    feasibility: Any
    complementarity: Any


def penalty_terms(gx, lam, nu, rho, eq_mask):
    """``(h, shifted, weights)`` of phi at constraint values ``gx`` ``(m,)``: the equality
    ``h``, ``shifted = max(0, lam - rho g)`` over the inequalities (0 at the equality) and
    ``weights = d phi / d g`` ``(m,)`` (``nu + rho h`` at the equality, ``-shifted``
    elsewhere), so that ``grad phi = grad f + J^T weights``."""
    h = jnp.sum(eq_mask * gx)
    shifted = jnp.where(eq_mask > 0, 0.0, jnp.maximum(0.0, lam - rho * gx))
    weights = jnp.where(eq_mask > 0, nu + rho * h, -shifted)
    return h, shifted, weights


def _phi_of(fx, gx, lam, nu, rho, eq_mask):
    """phi from the objective ``fx`` ``()`` and the constraints ``gx`` ``(m,)``."""
    h, shifted, _ = penalty_terms(gx, lam, nu, rho, eq_mask)
    return fx + nu * h + 0.5 * rho * h * h + jnp.sum(shifted**2 - lam**2) / (2.0 * rho)


def augmented_lagrangian(fg, x, lam, nu, rho, eq_mask):
    """``phi(x)`` of the module docstring: ``f + nu h + rho/2 h^2 + 1/(2 rho) sum_i
    (max(0, lam_i - rho g_i)^2 - lam_i^2)`` over the inequalities, ``h`` the ``eq_mask`` row
    (``fg(x) = (f(x), g(x))``)."""
    fx, gx = fg(x)
    return _phi_of(fx, gx, lam, nu, rho, eq_mask)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class FirstOrder:
    """A problem at one point: ``fx`` ``()``, ``gx`` ``(m,)``, ``grad_f`` ``(n,)``, the
    constraint Jacobian ``jac`` ``(m, n)``, and ``aux``: whatever the problem's
    `Problem.lagrangian_hessian` reuses (``None`` for the autodiff default). Every
    gradient a step needs is a product with ``jac``: phi's before and after the multiplier
    update and the violation's, with no reverse pass."""

    fx: Any
    gx: Any
    grad_f: Any
    jac: Any
    aux: Any = None


@dataclasses.dataclass(frozen=True)
class Problem:
    """A smooth problem ``min f(x) s.t. g(x) >= 0`` (one row of ``g`` may be made an
    equality by the lane's ``eq_mask``), as the solver evaluates it.

    Attributes:
        fg: ``(n,) -> ((), (m,))``, the objective and the constraint margins from one
            call (so that they can share their work).
        first_order: ``(n,) -> FirstOrder`` at a point, or ``None``: one forward-mode
            Jacobian of ``fg`` (``n`` tangents).
        lagrangian_hessian: ``(FirstOrder, x, w, gn) -> (n, n)``, the Hessian of
            ``f + w . g`` at ``x`` for fixed weights ``w`` ``(m,)``, plus the Gauss-Newton
            term ``J^T diag(gn) J`` of the rows' weights ``gn`` ``(m,)`` (``J`` the
            Jacobian of ``g``; phi's penalty contributes it), given the ``first_order`` at
            ``x``; or ``None``: ``jax.hessian`` of ``f + w . g`` plus that term from
            ``FirstOrder.jac``. A problem with structure supplies both
            (`jaxgrasp.tolerance._problems` writes them from the contact kinematics'
            derivatives, cheaper than autodiff's nested passes).
    """

    fg: Callable
    first_order: Callable | None = None
    lagrangian_hessian: Callable | None = None


def as_problem(problem) -> Problem:
    """``problem`` itself, or a `Problem` of the plain ``fg`` callable (autodiff)."""
    return problem if isinstance(problem, Problem) else Problem(problem)


def first_order(problem: Problem, x) -> FirstOrder:
    if problem.first_order is not None:
        return problem.first_order(x)
    fx, gx = problem.fg(x)
    grad_f, jac = jax.jacfwd(problem.fg)(x)
    return FirstOrder(fx, gx, grad_f, jac)


def lagrangian_hessian(problem: Problem, d: FirstOrder, x, weights, gauss_newton=None):
    """``(n, n)`` Hessian of ``f + weights . g`` at ``x`` (weights held fixed), plus
    ``J^T diag(gauss_newton) J`` where ``gauss_newton`` ``(m,)`` is given (``J = d.jac``)."""
    weights = jax.lax.stop_gradient(weights)
    gauss_newton = jnp.zeros_like(weights) if gauss_newton is None else jax.lax.stop_gradient(gauss_newton)
    if problem.lagrangian_hessian is not None:
        return problem.lagrangian_hessian(d, x, weights, gauss_newton)

    def lagrangian(x):
        fx, gx = problem.fg(x)
        return fx + contract("m,m->", weights, gx)

    return jax.hessian(lagrangian)(x) + contract("mi,m,mj->ij", d.jac, gauss_newton, d.jac)


def init(x0, eq_mask, nu0, active, o: SolverOptions) -> SolverState:
    """The state of a lane before its first step (arguments as `solve`)."""
    x0 = jnp.asarray(x0)
    dtype = x0.dtype
    eq_mask = jnp.asarray(eq_mask, dtype)
    return SolverState(
        x=x0,
        lam=jnp.zeros(eq_mask.shape, dtype),
        nu=jnp.where(active, jnp.asarray(nu0, dtype), 0.0),  # NaN: estimated at the first step
        rho=jnp.asarray(o.rho0, dtype),
        eq_mask=eq_mask,
        inner=jnp.asarray(0, jnp.int32),
        prev_viol=jnp.asarray(jnp.inf, dtype),
        steps=jnp.asarray(0, jnp.int32),
        status=jnp.where(active, LaneStatus.NOT_CONVERGED, LaneStatus.NO_START).astype(jnp.int32),
        stationarity=jnp.asarray(jnp.inf, dtype),
        feasibility=jnp.asarray(jnp.inf, dtype),
        complementarity=jnp.asarray(jnp.inf, dtype),
    )


FAR_VIOLATION = 1e-2
"""A violation (scaled constraint units) above which the penalty of a lane with an
equality grows whenever the violation stalls, even after an inner solve cut short at
``max_inner`` Newton steps (`_multiplier_update`)."""


NEAR_STATIONARY = 1e-2
"""A lane whose violation stalls above `FAR_VIOLATION` where the violation
measure's gradient (inf-norm) is at most this times the violation grows its penalty by
more than ``rho_growth`` (`_penalty_growth`). Lanes that end converged stall far
from feasibility only where that gradient is of the order of the violation."""

PREDICT_MARGIN = 0.1
"""`_penalty_growth` aims the violation measure's gradient at this fraction of the
``infeasible_stationarity`` bound."""


def kkt_tol(dtype, o: SolverOptions) -> float:
    """The KKT tolerance a lane of ``dtype`` converges to: ``o.tol``, raised to ``1e3 *
    eps`` of the dtype (float32: ~1.2e-4)."""
    return max(o.tol, 1e3 * float(jnp.finfo(dtype).eps))


def tolerances(dtype, o: SolverOptions):
    """``(tol, infeasible_tol, rounding)`` for ``dtype``: the options' values, raised to
    what the precision can reach (float32: tol ~1.2e-4, infeasible_tol ~1.2e-3)."""
    eps = float(jnp.finfo(dtype).eps)
    return kkt_tol(dtype, o), max(o.infeasible_tol, 1e4 * eps), 100.0 * eps


def phi_hessian(problem: Problem, s: SolverState, d: FirstOrder):
    """``(n, n)`` exact Hessian of phi at ``s.x``: ``hess(f + w . g)`` with the weights
    ``w = d phi / d g`` held fixed, plus ``rho J^T D J`` with ``D`` selecting the equality
    and the inequalities whose shifted multiplier is positive (where phi's penalty is
    quadratic in ``g``), both from the problem's `lagrangian_hessian`. This equals
    ``jax.hessian`` of phi (to rounding) with a smaller traced graph and less work.

    The problem forms the second term with the first: a structured problem folds it into
    its per-row pieces (`jaxgrasp.tolerance._problems`: each contact's ``4 x 4``
    block). Formed here as a product of the whole ``(m, n)`` Jacobian, XLA's CPU backend
    fused the rows' mask into that product and, at some row counts (five contacts),
    recomputed it for every entry of the ``n x n`` result."""
    _, shifted, weights = penalty_terms(d.gx, s.lam, s.nu, s.rho, s.eq_mask)
    quadratic = ((s.eq_mask > 0) | (shifted > 0)).astype(d.jac.dtype)
    return lagrangian_hessian(problem, d, s.x, weights, s.rho * quadratic)


def _newton_direction(hmat, gphi, needed, o: SolverOptions):
    """``(n,)`` Newton direction for the Hessian ``hmat`` ``(n, n)`` and gradient ``gphi``,
    a descent direction (`jaxgrasp.solver._direction.newton_direction`: eigenvalues mirrored
    and floored at ``1e-10`` of the largest), capped at ``max_step`` (inf-norm). ``needed``
    ``()`` bool: whether the lane takes this step (under ``vmap`` the lanes that do not
    cost no eigendecomposition)."""
    p = newton_direction(0.5 * (hmat + hmat.T), gphi, needed)
    return p * jnp.minimum(1.0, o.max_step / jnp.maximum(jnp.max(jnp.abs(p)), 1e-300))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Trial:
    """A lane's loop step up to its line search (`propose`; leading batch axes
    under ``vmap``).

    Attributes:
        state: the lane's state after the multiplier update, where there was one.
        newton: ``()`` bool, whether the lane takes a Newton step now.
        p: ``(n,)`` the Newton direction (capped at ``max_step``).
        phi0: ``()`` phi at ``state.x``.
        slope: ``()`` phi's directional derivative along ``p``.
        fx: ``()`` ``f`` at ``state.x``: a lane that ends at this step (its multiplier
            update converged it) does not move, so this is its final objective.
    """

    state: SolverState
    newton: Any
    p: Any
    phi0: Any
    slope: Any
    fx: Any


def merit(problem, s: SolverState, x):
    """``()`` phi of the lane ``s`` (its multipliers and penalty) at the point ``x`` ``(n,)``:
    the merit its line search lowers."""
    return augmented_lagrangian(as_problem(problem).fg, x, s.lam, s.nu, s.rho, s.eq_mask)


def line_search(merit_of, trials: Trial, o: SolverOptions):
    """``(x_new, improve)`` ``(B, n)``, ``(B,)``: the backtracking line search
    (`jaxgrasp.solver._line_search.line_search`) of a batch of ``B`` lanes' trials (leading
    axis ``B``); ``merit_of(x, lane)`` is lane ``lane``'s `merit` at ``x``.

    Only lanes feasible at their last multiplier update may walk the deeper ladder: a
    feasible lane whose Newton direction crosses nearly active boundaries it does not yet
    penalise lowers its merit only by a very short step, while a lane far from
    feasibility that cannot lower its merit is left to the infeasibility test."""
    tol, _, rounding = tolerances(trials.p.dtype, o)
    return ladder_search(merit_of, trials.state.x, trials.p, trials.phi0, trials.slope, trials.newton,
                         o.line_search_steps, rounding, deeper=trials.state.feasibility <= tol)


def _lane_status(s: SolverState, d: FirstOrder, stat, viol, comp, floor, o: SolverOptions):
    """``()`` [`LaneStatus`][jaxgrasp.solver.LaneStatus] after a multiplier update, from the KKT
    residuals ``stat``, ``viol``, ``comp`` at ``s.x`` and the violation ``s.prev_viol``
    before it: converged (stationarity within `_stationarity_tol` of the rounding
    ``floor``, feasibility and complementarity within tol), infeasible, or not converged
    (yet)."""
    tol, infeasible_tol, _ = tolerances(s.x.dtype, o)
    converged = (stat <= _stationarity_tol(s, floor, o)) & (viol <= tol) & (comp <= tol)
    at_max = s.rho >= o.rho_max
    # Infeasible: the violation stays above infeasible_tol at a point where the
    # violation measure v = |h|^2/2 + sum min(g_i, 0)^2/2 is stationary (a local
    # minimiser of the violation, which no penalty can push further), or it stalls at
    # the largest penalty. grad v = J^T r, r the violated part of g.
    stationary_violation = violation_slope(s, d) <= o.infeasible_stationarity * viol
    infeasible = (viol > infeasible_tol) & (
        stationary_violation | (at_max & (viol >= 0.5 * s.prev_viol))
    )
    return jnp.where(
        converged,
        LaneStatus.CONVERGED,
        jnp.where(infeasible, LaneStatus.INFEASIBLE, LaneStatus.NOT_CONVERGED),
    )


def violation_slope(s: SolverState, d: FirstOrder):
    """``()`` ``|grad v|_inf`` at ``s.x`` (``d``: the problem there), ``v = |h|^2/2 + sum
    min(g_i, 0)^2/2`` the violation measure: ``grad v = J^T r``, ``r`` the violated part of
    ``g``."""
    r = jnp.where(s.eq_mask > 0, d.gx, jnp.minimum(d.gx, 0.0))
    return jnp.max(jnp.abs(contract("mi,m->i", d.jac, r)))


def _penalty_growth(s: SolverState, d: FirstOrder, viol, o: SolverOptions):
    """``()`` the factor by which a stalled lane's penalty grows at this update: ``rho_growth``,
    or more where the violation ``viol`` stalls above `FAR_VIOLATION` at a nearly
    stationary point of the violation measure (``d``: the problem at ``s.x``).

    WHY: on an infeasible problem the inner minimiser of phi sits at ``grad v ~ -grad f /
    rho`` from a stationary point of ``v``, so ``|grad v| / viol`` falls in proportion to
    ``1 / rho`` once the violation has stalled; the ``infeasible_stationarity`` test then
    passes only after several tenfold growths, one inner solve each. Growing at once by
    the factor that takes the ratio to `PREDICT_MARGIN` times the bound (at most
    ``stall_growth_max``) skips those solves. The gate (far, stalled, and a ratio already
    small) keeps lanes that end converged on their usual path: where they stall far from
    feasibility the ratio is of order one."""
    ratio = violation_slope(s, d) / jnp.maximum(viol, 1e-300)
    predicted = ratio / (PREDICT_MARGIN * o.infeasible_stationarity)
    near = (viol > FAR_VIOLATION) & (ratio <= NEAR_STATIONARY)
    return jnp.where(near, jnp.clip(predicted, o.rho_growth, max(o.stall_growth_max, o.rho_growth)), o.rho_growth)


def _multiplier_update(s: SolverState, d: FirstOrder, gphi, floor, o: SolverOptions) -> SolverState:
    """The multiplier and penalty update ending an inner solve, with the lane's new status
    and KKT residuals (``d``: the problem at ``s.x``; ``gphi``: ``(n,)`` gradient of phi
    there; ``floor``: `_rounding_floor` there)."""
    gx = d.gx
    is_eq = s.eq_mask > 0
    h = jnp.sum(s.eq_mask * gx)
    lam = jnp.where(is_eq, 0.0, jnp.maximum(0.0, s.lam - s.rho * gx))
    nu = s.nu + s.rho * h
    viol = jnp.maximum(jnp.abs(h), jnp.max(jnp.where(is_eq, 0.0, jnp.maximum(-gx, 0.0))))
    comp = jnp.max(jnp.where(is_eq, 0.0, jnp.abs(lam * gx)))
    stat = jnp.max(jnp.abs(gphi))
    # The penalty grows where the violation did not fall by a factor 4 (Powell's rule;
    # Nocedal & Wright Sec. 17.4), except on a lane with an equality after an inner solve
    # cut short at max_inner Newton steps while the violation is already small: on a
    # strongly curved equality each Newton step on phi leaves the constraint and the next
    # comes back, the inner solve runs out of steps, and a penalty raised at every update
    # only worsens phi's conditioning until the lane crawls into its step budget with
    # meaningless multipliers (seen on a 2-finger slip boundary). Far from feasibility
    # (FAR_VIOLATION), or on an infeasible problem, the penalty must grow either way: only a
    # large one shows a violation that cannot fall. Without an equality (the equilibrium)
    # the exception buys nothing and made a degenerate equilibrium (three contacts at their
    # force limits) end infeasible, so it does not apply there. Past grow_penalty_after
    # steps it ends: a lane of an infeasible boundary problem whose violation swings at a
    # moderate penalty, its inner solves cut short, would otherwise stall into the step
    # budget instead of ending infeasible at rho_max as the problem's other lanes do.
    late = s.steps >= o.grow_penalty_after
    finished = (stat <= _inner_tol(s, floor, o)) | (s.inner > o.max_inner) | ~jnp.any(is_eq) | late
    stalled = (viol > 0.25 * s.prev_viol) & (finished | (viol > FAR_VIOLATION))
    rho = jnp.where(stalled, jnp.minimum(s.rho * _penalty_growth(s, d, viol, o), o.rho_max), s.rho)
    return dataclasses.replace(
        s,
        lam=lam,
        nu=nu,
        rho=rho,
        inner=jnp.zeros_like(s.inner),
        prev_viol=viol,
        status=_lane_status(s, d, stat, viol, comp, floor, o).astype(jnp.int32),
        stationarity=stat,
        feasibility=viol,
        complementarity=comp,
    )


def _inner_done(s: SolverState, d: FirstOrder, floor, o: SolverOptions):
    """``(gphi, done)``: the ``(n,)`` gradient of phi at ``s.x`` (``d``: the problem there;
    ``floor``: `_rounding_floor`) and whether the inner solve is done (``()`` bool:
    stationary enough, or ``max_inner`` Newton steps taken)."""
    _, _, weights = penalty_terms(d.gx, s.lam, s.nu, s.rho, s.eq_mask)
    gphi = d.grad_f + contract("mi,m->i", d.jac, weights)
    return gphi, (jnp.max(jnp.abs(gphi)) <= _inner_tol(s, floor, o)) | (s.inner >= o.max_inner)


def _inner_tol(s: SolverState, floor, o: SolverOptions):
    """``()`` the stationarity ``|grad phi|_inf`` at which the inner solve of ``s`` is done
    (``floor``: `_rounding_floor` at ``s.x``).

    Inexact inner solves: while the violation is large, a rough minimiser of phi is enough
    to update the multipliers; the tolerance tightens to `_stationarity_tol` as the
    violation vanishes."""
    return jnp.maximum(_stationarity_tol(s, floor, o), o.inner_tol_factor * jnp.minimum(s.prev_viol, 1.0))


ROUNDING_ULPS = 10.0
"""How many units in the last place of ``x`` the stationarity floor of
`_rounding_floor` allows for (a Newton step lands within a few of phi's minimiser,
and ``g`` itself carries rounding)."""

MAX_STATIONARITY_TOL = 10.0
"""The most, in multiples of tol, that `_stationarity_tol` raises the stationarity
tolerance to: a point whose stationarity is 10 tol is as good a minimiser to the energy's
precision (its energy error is of order stationarity squared over curvature), and a lane
that needs more is crawling, not at rounding."""


def _rounding_floor(s: SolverState, d: FirstOrder):
    """``()`` per unit penalty, how far phi's gradient at ``s.x`` moves when ``x`` moves by
    ``u = ROUNDING_ULPS * eps |x|`` (componentwise; ``d``: the problem at ``s.x``).

    phi's penalty term has the Hessian ``rho J^T D J`` (``D``: the equality and the
    inequalities where phi is quadratic), so its gradient moves by up to
    ``rho max(|J|^T D |J| u)``. At a penalty of 1e4 on a degenerate equilibrium (five
    constraints active in six unknowns, rows of norm 17) that is 1-1.4e-10, and the
    gradient swung between 2e-10 and 1e-9 from one Newton step of 1e-14 to the next: with
    tol 1e-10 the lane converged only by luck in some batch layouts and ran its whole
    budget in others (the test ``test_boundaries_through_the_equilibrium`` holds it).
    Computed once per loop step, from the multipliers before its update (the rows where
    phi is quadratic barely change in an update)."""
    _, shifted, _ = penalty_terms(d.gx, s.lam, s.nu, s.rho, s.eq_mask)
    quadratic = (s.eq_mask > 0) | (shifted > 0)
    a = jnp.abs(d.jac)
    u = ROUNDING_ULPS * float(jnp.finfo(s.x.dtype).eps) * jnp.abs(s.x)
    return jnp.max(contract("mi,m->i", a, jnp.where(quadratic, contract("mi,i->m", a, u), 0.0)))


def _stationarity_tol(s: SolverState, floor, o: SolverOptions):
    """``()`` the stationarity ``|grad phi|_inf`` that counts as converged for ``s``: tol,
    or, where phi is so stiff that its gradient at the floating-point point nearest its
    minimiser cannot reach tol, that gradient's rounding floor ``s.rho * floor``
    (`_rounding_floor`), at most `MAX_STATIONARITY_TOL` tol."""
    tol, _, _ = tolerances(s.x.dtype, o)
    return jnp.clip(s.rho * floor, tol, MAX_STATIONARITY_TOL * tol)


def initial_multiplier(s: SolverState, d: FirstOrder) -> SolverState:
    """``s`` with a ``NaN`` equality multiplier before the first step (``nu0`` NaN in
    `init`) replaced by its least-squares estimate at ``s.x``: the ``nu`` that best
    solves ``grad f + nu grad h = 0`` (``d``: the problem there; 0 without an equality)."""
    grad_h = contract("m,mi->i", s.eq_mask, d.jac)
    estimate = -contract("i,i->", d.grad_f, grad_h) / jnp.maximum(contract("i,i->", grad_h, grad_h), 1e-300)
    return dataclasses.replace(s, nu=jnp.where(jnp.isnan(s.nu) & (s.steps == 0), estimate, s.nu))


def _select(pred, a, b):
    return jax.tree_util.tree_map(lambda u, v: jnp.where(pred, u, v), a, b)


def propose(problem, s: SolverState, o: SolverOptions) -> Trial:
    """A lane's loop step up to its line search: a multiplier update where the inner solve
    is done, then, where the (updated) inner solve is not, the Newton direction on phi.

    Stages, in order: `first_order` (the problem and its Jacobian at ``s.x``,
    shared by every later stage: the update does not move ``x``);
    `initial_multiplier` (at the first step); `_rounding_floor`; `_inner_done`;
    `_multiplier_update` (status from `_lane_status`); `_inner_done`
    again; `phi_hessian` and `_newton_direction`.
    """
    # A multiplier update, where the inner solve is done, then a Newton step where the
    # (updated) inner solve is not: the sequence of updates and the step count of a lane
    # are those of one kind of update per loop step, but under vmap (where both kinds are
    # computed for every lane) a lane no longer spends a whole loop step on an update.
    problem = as_problem(problem)
    is_running = running(s, o)
    d = first_order(problem, s.x)
    s = initial_multiplier(s, d)
    floor = _rounding_floor(s, d)
    gphi, inner_done = _inner_done(s, d, floor, o)
    update = is_running & inner_done
    s_upd = _multiplier_update(s, d, gphi, floor, o)
    s1 = _select(update, dataclasses.replace(s_upd, steps=s.steps + 1), s)
    gphi1, inner_done1 = _inner_done(s1, d, floor, o)
    # A running lane without an update takes its Newton step whatever the second test
    # says: it repeats the first on the same numbers, but XLA may round the two apart (far
    # out, phi's gradient is a difference of terms of 1e10), and a lane whose first test
    # said "not done" and second "done" took neither and stepped no more, its queue never
    # ending (a 7-contact grasp of the 100k benchmark set hung `jaxgrasp batch`).
    newton = is_running & running(s1, o) & (~inner_done1 | ~update)
    p = _newton_direction(phi_hessian(problem, s1, d), gphi1, newton, o)
    phi0 = _phi_of(d.fx, d.gx, s1.lam, s1.nu, s1.rho, s1.eq_mask)
    return Trial(state=s1, newton=newton, p=p, phi0=phi0, slope=contract("i,i->", gphi1, p), fx=d.fx)


def accept(t: Trial, x_new, improve, o: SolverOptions) -> SolverState:
    """The lane's state after its loop step: ``t.state`` moved to ``x_new`` ``(n,)`` (the
    line search's point) where it took a Newton step. A step that cannot decrease phi
    (``improve`` false) ends the inner loop (numerically converged: ``inner`` becomes
    ``max_inner + 1``)."""
    s = t.state
    inner = jnp.where(improve, s.inner + 1, o.max_inner + 1).astype(jnp.int32)
    return _select(t.newton, dataclasses.replace(s, x=x_new, inner=inner, steps=s.steps + 1), s)


def step(problem, s: SolverState, o: SolverOptions) -> SolverState:
    """One loop step of one lane: `propose`, the line search, `accept`. A
    finished lane is returned unchanged. (`jaxgrasp.solver.solve_lanes` runs the same
    three for many lanes, with one line search over all of them.)

    Args:
        problem: a `Problem`, or its ``fg`` alone (`as_problem`).
        s: the lane's state.
        o: [`SolverOptions`][jaxgrasp.SolverOptions].
    """
    problem = as_problem(problem)
    t = propose(problem, s, o)
    one = jax.tree_util.tree_map(lambda a: a[None], t)
    x_new, improve = line_search(lambda x, _: merit(problem, t.state, x), one, o)
    return accept(t, x_new[0], improve[0], o)


def running(s: SolverState, o: SolverOptions):
    """``()`` bool: whether the lane still steps (not finished, step budget left)."""
    return (s.status == LaneStatus.NOT_CONVERGED) & (s.steps < o.max_steps)


def to_result(problem, s: SolverState) -> SolverResult:
    """The `SolverResult` of a lane's final state (``problem`` as in `solve`)."""
    return SolverResult(
        x=s.x,
        lam=s.lam,
        nu=s.nu,
        objective=as_problem(problem).fg(s.x)[0],
        status=s.status,
        stationarity=s.stationarity,
        feasibility=s.feasibility,
        complementarity=s.complementarity,
        steps=s.steps,
    )


def solve(
    problem,
    x0,
    eq_mask,
    nu0=0.0,
    options: SolverOptions = SolverOptions(),
    active=True,
) -> SolverResult:
    """Solve one lane (``vmap`` it for many, or use `jaxgrasp.solver.solve_lanes`).

    ``init``, then ``step`` while ``running``, then ``to_result``.

    Args:
        problem: a `Problem`, or just its ``fg``: objective and constraint margins,
            ``(n,) -> ((), (m,))``, feasible where the margins are ``>= 0`` (one function,
            so that the two share their work), differentiated by autodiff.
        x0: ``(n,)`` starting point.
        eq_mask: ``(m,)`` one-hot vector selecting the equality constraint, or zeros.
        nu0: initial equality multiplier, or ``NaN``: its least-squares estimate at
            ``x0`` (``grad f + nu0 grad h = 0`` in the least-squares sense), computed at
            the lane's first step from the derivatives that step takes anyway.
        options: [`SolverOptions`][jaxgrasp.SolverOptions].
        active: ``False`` skips the lane (it ends at once with status ``LaneStatus.NO_START``).
    """
    s = init(x0, eq_mask, nu0, active, options)
    s = jax.lax.while_loop(lambda s: running(s, options), lambda s: step(problem, s, options), s)
    return to_result(problem, s)
