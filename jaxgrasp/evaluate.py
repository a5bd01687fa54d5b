"""Energy-tolerance evaluation of a grasp (Tsuji et al., eq. 1), batched and differentiable.

One evaluation solves ``1 + 2N`` programs in the object's 6-D pose change:

* the *equilibrium* problem ``U0 = min U`` subject to every contact, friction and
  force-limit constraint;
* for each contact ``j`` a *slip* problem (friction of ``j`` active) and a *max_force*
  problem (force limit of ``j`` active), each with every other constraint kept.

Boundary problems are non-convex, so each is solved from several starts and the lowest
converged energy is kept (a missed lower point would overstate stability). A start is
found by walking from the equilibrium along a direction until the boundary's constraint
is crossed, then bisecting onto it: along the 12 coordinate half-axes of the scaled pose
space plus ``num_random_starts`` seeded random directions. Every problem of every start
runs as a lane of one ``vmap`` of :func:`jaxgrasp.solver.solve`.

Derivatives of ``value`` (and of every energy) are exact and cheap: by the envelope
theorem, the derivative of ``min_x U(x; theta)`` is the partial derivative of the
Lagrangian at the solution ``(x*, lam*, nu*)`` held fixed. The solver runs on
``stop_gradient`` parameters and its iterations are never differentiated; each minimum
energy is then passed through :func:`envelope_energy`, a ``jax.custom_jvp`` function
whose value is the solver's ``U*`` and whose tangent is ``dL/dtheta . dtheta`` at the fixed
solution. ``jax.grad``, ``jax.jacfwd``, ``jax.jvp`` and their ``vmap`` all go through that
rule. The derivative is that of the *selected* boundary: where two boundaries tie for the
minimum (e.g. the two contacts of a symmetric grasp) ``value`` has a kink and the
gradient is that of the one reported in ``limiting_*`` (a one-sided derivative).

Where ``value`` is 0 because the grasp is unstable or infeasible, its gradient is exactly 0
(never NaN): the Lagrangian of a discarded problem is evaluated at a safe point (the
initial state, zero multipliers) so that no non-finite partial derivative can leak into
the zero cotangent.

With ``EvaluateOptions(smooth_min_temperature=T)`` the hard minimum over boundaries is
replaced by a soft minimum (log-sum-exp, temperature ``T`` in J): see
:class:`EvaluateOptions`.
"""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import result as R
from . import solver as S
from .grasp import Grasp
from .lanes import solve_lanes
from .model import constraint_margins, energy_scale, model_params, potential_energy
from .result import Evaluation
from .status import LaneStatus
from .units import M_TO_MM, MJ_TO_J

__all__ = ["EvaluateOptions", "evaluate", "solve_programs", "Programs", "envelope_energy", "soft_minimum"]


@dataclasses.dataclass(frozen=True)
class EvaluateOptions:
    """Static settings of :func:`evaluate` (hashable, so it can be a ``jit`` static argument).

    Attributes:
        solver: settings of the augmented-Lagrangian solver.
        num_random_starts: random start directions per boundary problem, on top of the 12
            coordinate half-axes.
        seed: seed of those random directions (fixed, so results are reproducible).
        ray_length: how far a start search walks from the equilibrium: translations up to
            ``ray_length`` fingertip radii, rotations up to ``ray_length`` rad or that
            many radii of arc at the grasp's lever arm, whichever is larger.
        ray_points: points of the geometric grid on which the crossing is looked for.
        bisection_steps: bisection steps onto the boundary.
        boundary_tol: a slip or force-limit margin (scaled) at most this at the
            equilibrium, or a boundary energy at most this (relative to the energy
            scale) above ``U0``, means the equilibrium is on a boundary: status unstable.
            Also the feasibility a stalled lane must reach for its energy to count as an
            estimate.
        smooth_min_temperature: ``None`` (default) for the paper's hard minimum over
            boundaries. A temperature ``T > 0`` in J replaces it by the soft minimum

                ``value = max(0, -T log sum_b exp(-(U_b - U0) / T))``

            over the reachable boundaries ``b`` (computed stably, relative to the hard
            minimum; unreachable boundaries are left out). Its gradient is the
            softmin-weighted mean of the boundaries' gradients, so it is continuous where
            the limiting boundary switches (useful for gradient-based tuning). It is
            biased low: with ``K`` reachable boundaries,
            ``hard - T log K <= value <= hard``, where ``hard`` is the value without
            smoothing (equality on the right when one boundary dominates by many ``T``).
            Choose ``T`` well below the values of interest (e.g. 1% of them).
            ``Evaluation.value`` is then the smoothed value; ``limiting_kind`` and
            ``limiting_contact`` still name the hard minimiser and every other field is
            unchanged.
    """

    solver: S.SolverOptions = S.SolverOptions()
    num_random_starts: int = 8
    seed: int = 0
    ray_length: float = 1.0
    ray_points: int = 48
    bisection_steps: int = 60
    boundary_tol: float = 1e-8
    smooth_min_temperature: float | None = None

    def __post_init__(self):
        t = self.smooth_min_temperature
        if t is not None:
            try:
                ok = float(t) > 0.0 and np.isfinite(float(t)) and not isinstance(t, bool)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(
                    f"smooth_min_temperature must be None or a finite number > 0 (J), got {t!r}"
                )

    def directions(self) -> np.ndarray:
        """``(12 + num_random_starts, 6)`` unit start directions in the scaled pose space."""
        axes = np.concatenate([np.eye(6), -np.eye(6)])
        rng = np.random.default_rng(self.seed)
        rand = rng.standard_normal((self.num_random_starts, 6))
        rand /= np.linalg.norm(rand, axis=1, keepdims=True)
        return np.concatenate([axes, rand])


def _is_concrete(tree) -> bool:
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def evaluate(grasp: Grasp, options: EvaluateOptions = EvaluateOptions()) -> Evaluation:
    """Evaluate the energy tolerance of ``grasp`` (eq. 1 of Tsuji et al.).

    Args:
        grasp: a :class:`~jaxgrasp.Grasp` (SI units). Under ``jax.vmap``, any field may
            carry a batch axis.
        options: :class:`EvaluateOptions`.

    Returns:
        An :class:`~jaxgrasp.Evaluation` (SI units) with the value in J, a status, the
        limiting boundary, the equilibrium and every boundary problem's minimum.

    Raises:
        GraspValueError: for a concrete grasp with invalid fields (checked before
            anything is compiled).

    ``evaluate`` can be wrapped in ``jax.jit`` and ``jax.vmap`` and differentiated with
    ``jax.grad``/``jax.jacfwd`` (envelope theorem; see the module docstring).
    """
    if _is_concrete(grasp) and np.ndim(grasp.mass) == 0:
        from .validation import check_grasp_inputs

        check_grasp_inputs(**grasp.to_numpy())
    return _evaluate(grasp, options)


def _ray_start(gk, z0, v, t_grid, bisection_steps):
    """First crossing of ``gk >= 0`` -> ``< 0`` along ``z0 + t v``; returns (z, found)."""
    vals = jax.vmap(lambda t: gk(z0 + t * v))(t_grid)
    crossed = vals < 0.0  # NaN (invalid pose) never counts as a crossing
    found = jnp.any(crossed)
    j = jnp.argmax(crossed)
    lo = jnp.where(j == 0, 0.0, t_grid[jnp.maximum(j - 1, 0)])
    hi = t_grid[j]

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        neg = gk(z0 + mid * v) < 0.0
        return jnp.where(neg, lo, mid), jnp.where(neg, mid, hi)

    lo, hi = jax.lax.fori_loop(0, bisection_steps, bisect, (lo, hi))
    return z0 + hi * v, found


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Programs:
    """Every program of one grasp as solved, lane by lane (internal, scaled units).

    The pose variable of every program is ``z = (dp [mm], lever * w [mm])``.

    Attributes:
        equilibrium: :class:`~jaxgrasp.solver.SolverResult` of the equilibrium problem.
        boundary: :class:`~jaxgrasp.solver.SolverResult` with a leading lane axis
            ``(2N * D,)``: lane ``b * D + s`` is start ``s`` of boundary problem
            ``b = kind * N + contact``.
        start: ``(2N * D, 6)`` starting points of the boundary lanes.
        found: ``(2N * D,)`` whether the start search crossed the boundary (lanes where it
            did not carry status ``LaneStatus.NO_START``).
        constraint_index: ``(2N * D,)`` index ``k`` of the equality in the flattened
            ``(3N,)`` constraint vector (``N + b``).
        lever: ``()`` mm, the length that scales rotations.
        scale: ``()`` mJ, the energy scale dividing the objective.
    """

    equilibrium: S.SolverResult
    boundary: S.SolverResult
    start: Any
    found: Any
    constraint_index: Any
    lever: Any
    scale: Any


def _to_pose(z, lever):
    return jnp.concatenate([z[:3], z[3:] / lever])


def _lane_f(z, theta):
    """Scaled objective of a boundary lane; ``theta = (params, lever, scale)``."""
    q, lever, scale = theta
    return potential_energy(_to_pose(z, lever), q) / scale


def _lane_g(z, theta):
    """Scaled constraint margins ``(3N,)`` of a boundary lane; ``theta`` as :func:`_lane_f`."""
    q, lever, _ = theta
    return constraint_margins(_to_pose(z, lever), q).reshape(-1)


class _Problem:
    """Scaled objective and constraints of a grasp as functions of ``z`` and the params."""

    def __init__(self, p):
        self.n = p.c.shape[0]
        self.scale = energy_scale(p)  # mJ, constant
        # Scaled pose z = (dp [mm], lever * w [mm]): rotations and translations move the
        # contacts by comparable amounts.
        self.lever = jax.lax.stop_gradient(
            jnp.maximum(jnp.max(jnp.linalg.norm(p.c, axis=-1)), jnp.max(p.r))
        )

    def to_pose(self, z):
        return _to_pose(z, self.lever)

    def f(self, z, q):
        return potential_energy(self.to_pose(z), q) / self.scale

    def g(self, z, q):
        return constraint_margins(self.to_pose(z), q).reshape(-1)

    def lagrangian(self, z, lam, nu, eq_mask, q):
        gz = self.g(z, q)
        return self.f(z, q) + nu * jnp.sum(eq_mask * gz) - jnp.sum(lam * gz)


@jax.custom_jvp
def envelope_energy(params, z, lam, nu, eq_mask, objective):
    """A program's minimum energy with its envelope-theorem derivative, mJ.

    ``objective`` is the solver's scaled minimum ``f(z*) = U(z*) / scale`` of the program
    with constraints ``g(z; params) >= 0`` and equality row ``eq_mask``, attained at
    ``z`` with multipliers ``lam`` (inequalities) and ``nu`` (equality). Returns
    ``scale * objective``; its tangent in ``params`` is

        ``scale * dL/dparams . dparams``,  ``L = f(z) + nu h(z) - lam . g(z)``

    with ``(z, lam, nu)`` held fixed (envelope theorem, valid at a regular KKT point).
    Tangents of ``z``, ``lam``, ``nu``, ``eq_mask`` and ``objective`` are ignored: they
    are the solver's outputs, which are never differentiated. Works under ``jax.grad``,
    ``jax.jacfwd``, ``jax.jvp`` and ``jax.vmap`` (``params`` is a :class:`ModelParams`).
    """
    return energy_scale(params) * objective


@envelope_energy.defjvp
def _envelope_energy_jvp(primals, tangents):
    params, z, lam, nu, eq_mask, objective = primals
    dparams = tangents[0]
    scale = energy_scale(params)

    def lagrangian(q):
        return _Problem(q).lagrangian(z, lam, nu, eq_mask, q)

    _, dl = jax.jvp(lagrangian, (params,), (dparams,))
    return scale * objective, scale * dl


def _solve_programs(p, prob: _Problem, options: EvaluateOptions) -> Programs:
    ps = jax.lax.stop_gradient(p)  # the solver never sees a derivative
    n = prob.n
    m = 3 * n
    sopt = options.solver
    f = lambda z: prob.f(z, ps)
    g = lambda z: prob.g(z, ps)
    dtype = p.c.dtype

    # --- equilibrium problem, from the initial grasping state
    eq = S.solve(f, g, jnp.zeros(6, dtype), jnp.zeros(m, dtype), 0.0, sopt)
    z_eq = eq.x

    # --- boundary problems: constraint index k = n + b for b in [0, 2n) (slip rows, then force)
    dirs = jnp.asarray(options.directions(), dtype)
    num_dirs = dirs.shape[0]
    # A ray walks until its translation reaches ray_length radii or its rotation reaches
    # ray_length rad, whichever is farther: torsion slip needs a rotation angle that does
    # not shrink with the lever arm (contacts far from the centre of mass).
    rot = jnp.linalg.norm(dirs[:, 3:], axis=1)
    t_max = options.ray_length * jnp.maximum(jnp.max(ps.r), prob.lever * rot)  # (D,) mm
    unit_grid = 2.0 ** (-(options.ray_points - 1 - jnp.arange(options.ray_points, dtype=dtype)) / 4.0)
    lane_k = jnp.repeat(n + jnp.arange(2 * n), num_dirs)
    lane_v = jnp.tile(dirs, (2 * n, 1))
    lane_t = jnp.tile(t_max[:, None] * unit_grid, (2 * n, 1))

    def start(k, v, t_grid):
        gk = lambda z: g(z)[k]
        on_boundary = gk(z_eq) <= 0.0
        z0, found = _ray_start(gk, z_eq, v, t_grid, options.bisection_steps)
        z0 = jnp.where(on_boundary, z_eq, z0)
        found = found | on_boundary
        # least-squares estimate of the equality multiplier: grad f + nu grad h = 0
        gf = jax.grad(f)(z0)
        gh = jax.grad(gk)(z0)
        nu0 = -jnp.dot(gf, gh) / jnp.maximum(jnp.dot(gh, gh), 1e-300)
        return z0, found, nu0

    z0s, found, nu0s = jax.vmap(start)(lane_k, lane_v, lane_t)
    # Without a converged equilibrium there is nothing to start from: skip every lane.
    found = found & (eq.status == LaneStatus.CONVERGED)
    masks = jax.nn.one_hot(lane_k, m, dtype=dtype)
    # Every lane gets this grasp's parameters as its theta (not closed over): under a vmap
    # over grasps, solve_lanes then runs the lanes of all grasps in one work queue.
    num_lanes = lane_k.shape[0]
    theta = jax.tree_util.tree_map(
        lambda a: jnp.broadcast_to(a, (num_lanes,) + jnp.shape(a)), (ps, prob.lever, prob.scale)
    )
    lanes = solve_lanes(_lane_f, _lane_g, theta, z0s, masks, nu0s, found, sopt)
    return Programs(
        equilibrium=eq,
        boundary=lanes,
        start=z0s,
        found=found,
        constraint_index=lane_k,
        lever=prob.lever,
        scale=prob.scale,
    )


@partial(jax.jit, static_argnames="options")
def solve_programs(grasp: Grasp, options: EvaluateOptions = EvaluateOptions()) -> Programs:
    """Solve every program of ``grasp`` and return them lane by lane (for diagnostics and
    benchmarks; :func:`evaluate` is this plus the reduction to one value)."""
    p = model_params(grasp)
    return _solve_programs(p, _Problem(p), options)


def soft_minimum(du, mask, temperature):
    """``-T log sum_{b in mask} exp(-du_b / T)``, computed stably; ``+inf`` for an empty mask.

    Entries outside ``mask`` (or infinite) are left out and get a zero gradient. Bias:
    ``min(du) - T log K <= result <= min(du)`` with ``K`` the number of entries kept.
    """
    du = jnp.asarray(du)
    mask = mask & jnp.isfinite(du)
    ref = jax.lax.stop_gradient(jnp.min(jnp.where(mask, du, jnp.inf)))
    any_kept = jnp.any(mask)
    ref_safe = jnp.where(any_kept, ref, 0.0)
    shifted = jnp.where(mask, du, ref_safe) - ref_safe  # >= 0 where kept, 0 elsewhere
    w = jnp.where(mask, jnp.exp(-shifted / temperature), 0.0)  # in [0, 1]; 1 at the min
    total = jnp.where(any_kept, jnp.sum(w), 1.0)
    return jnp.where(any_kept, ref_safe - temperature * jnp.log(total), jnp.inf)


def _evaluate(grasp: Grasp, options: EvaluateOptions) -> Evaluation:
    # The smoothing temperature is a traced argument: evaluations with and without
    # smoothing, or with different temperatures, share one compilation.
    t = options.smooth_min_temperature
    if t is not None:
        options = dataclasses.replace(options, smooth_min_temperature=None)
    temperature = np.float64(0.0 if t is None else float(t) / MJ_TO_J)  # mJ; 0: hard minimum
    return _evaluate_jit(grasp, temperature, options)


@partial(jax.jit, static_argnames="options")
def _evaluate_jit(grasp: Grasp, temperature, options: EvaluateOptions) -> Evaluation:
    p = model_params(grasp)
    temperature = jnp.asarray(temperature, p.c.dtype)  # float32 grasps stay float32
    prob = _Problem(p)
    n = prob.n
    m = 3 * n
    progs = _solve_programs(p, prob, options)
    eq, lanes, found = progs.equilibrium, progs.boundary, progs.found
    z_eq = eq.x
    num_dirs = options.directions().shape[0]
    ks = n + jnp.arange(2 * n)
    zeros_mask = jnp.zeros(m, p.c.dtype)
    lane_status = jnp.where(found, lanes.status, LaneStatus.NO_START)
    lane_energy = jnp.where(lane_status == LaneStatus.CONVERGED, lanes.objective, jnp.inf)

    # --- keep the lowest converged start of each boundary problem
    lane_status = lane_status.reshape(2 * n, num_dirs)
    lane_energy = lane_energy.reshape(2 * n, num_dirs)
    best = jnp.argmin(lane_energy, axis=1)
    reached = jnp.isfinite(jnp.min(lane_energy, axis=1))
    unreachable = jnp.all((lane_status == LaneStatus.INFEASIBLE) | (lane_status == LaneStatus.NO_START), axis=1)
    b_status = jnp.where(reached, LaneStatus.CONVERGED, jnp.where(unreachable, LaneStatus.INFEASIBLE, LaneStatus.NOT_CONVERGED))
    # without a converged equilibrium no boundary problem was started
    b_status = jnp.where(eq.status == LaneStatus.CONVERGED, b_status, LaneStatus.NO_START)
    # Lowest feasible point of each boundary problem among lanes that did not converge
    # (e.g. degenerate active constraints, where multipliers grow without bound): an
    # estimate of that boundary's energy, used to tell whether it could be limiting.
    stalled_feasible = (lane_status == LaneStatus.NOT_CONVERGED) & (
        lanes.feasibility.reshape(2 * n, num_dirs) <= options.boundary_tol
    )
    b_estimate = jnp.min(jnp.where(stalled_feasible, lanes.objective.reshape(2 * n, num_dirs), jnp.inf), axis=1)
    pick = jnp.arange(2 * n) * num_dirs + best

    def take(a):
        return a[pick]

    b_z = jnp.where(reached[:, None], take(lanes.x), z_eq)
    b_x, b_lam, b_nu = take(lanes.x), take(lanes.lam), take(lanes.nu)
    b_obj = jnp.where(reached, take(lanes.objective), eq.objective)
    b_masks = jax.nn.one_hot(ks, m, dtype=p.c.dtype)

    # --- grasp status (from the solver's outputs only: no derivative)
    margins_eq = jax.lax.stop_gradient(prob.g(z_eq, p)).reshape(3, n)
    load_margins = margins_eq[1:]  # slip and force-limit rows
    on_boundary = jnp.min(load_margins) <= options.boundary_tol
    # An equilibrium problem that stalled (no KKT certificate: degenerate active constraints
    # make the multipliers grow without bound) at a feasible pose pressing a slip or force
    # constraint with a positive multiplier is on that boundary as well.
    stalled_on_boundary = (
        (eq.status == LaneStatus.NOT_CONVERGED)
        & (eq.feasibility <= options.boundary_tol)
        & jnp.any((load_margins <= options.boundary_tol) & (eq.lam.reshape(3, n)[1:] > 0.0))
    )
    any_reached = jnp.any(reached)
    b_limit = jnp.argmin(jnp.where(reached, b_obj, jnp.inf))
    hard_scaled = b_obj[b_limit] - eq.objective  # value / energy scale
    # a boundary reached within the solver's accuracy of U0: the equilibrium is on it
    zero_value = any_reached & (hard_scaled <= options.boundary_tol)
    # a boundary problem that did not settle decides the status only if it could be
    # limiting: no feasible point of it found, or one within 10 % of the value
    could_limit = ~(jnp.isfinite(b_estimate) & (b_estimate - eq.objective > 1.1 * hard_scaled))
    any_unsettled = jnp.any((b_status == LaneStatus.NOT_CONVERGED) & (could_limit | ~any_reached))
    status = jnp.select(
        [
            eq.status == LaneStatus.INFEASIBLE,
            stalled_on_boundary,
            eq.status != LaneStatus.CONVERGED,
            on_boundary | zero_value,
            any_unsettled | ~any_reached,
        ],
        [R.INFEASIBLE, R.UNSTABLE, R.NOT_CONVERGED, R.UNSTABLE, R.NOT_CONVERGED],
        R.STABLE,
    ).astype(jnp.int32)
    keep_value = (status == R.STABLE) | (status == R.NOT_CONVERGED)

    # --- energies with envelope-theorem derivatives (mJ). A program whose solution is not
    # used is differentiated at a safe point (initial state, zero multipliers), where the
    # Lagrangian's partials are finite: a zero cotangent then gives an exact zero.
    def finite(*xs):
        return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in xs]))

    eq_finite = finite(z_eq, eq.lam, eq.nu)
    b_finite = jax.vmap(finite)(b_x, b_lam, b_nu)

    def energies(use_eq, use_b):
        u_eq = envelope_energy(
            p,
            jnp.where(use_eq, z_eq, 0.0),
            jnp.where(use_eq, eq.lam, 0.0),
            jnp.where(use_eq, eq.nu, 0.0),
            zeros_mask,
            eq.objective,
        )
        u_b = jax.vmap(envelope_energy, in_axes=(None, 0, 0, 0, 0, 0))(
            p,
            jnp.where(use_b[:, None], b_x, 0.0),
            jnp.where(use_b[:, None], b_lam, 0.0),
            jnp.where(use_b, b_nu, 0.0),
            b_masks,
            b_obj,
        )
        return u_eq, jnp.where(reached, u_b, jnp.inf)

    # reported energies: derivative wherever the program was solved
    u_eq, u_b = energies(eq_finite, reached & b_finite)
    # the value's energies: derivative only where the value uses them
    v_eq, v_b = energies(keep_value & eq_finite, keep_value & reached & b_finite)

    # --- value: hard (or soft) minimum over the reachable boundaries, above U0
    hard = v_b[b_limit] - v_eq
    smooth = temperature > 0.0
    soft = soft_minimum(v_b - v_eq, reached, jnp.where(smooth, temperature, 1.0))
    raw = jnp.where(any_reached, jnp.where(smooth, soft, hard), 0.0)
    value = jnp.where(keep_value, jnp.maximum(raw, 0.0), 0.0)
    has_limit = keep_value & any_reached
    limiting_kind = jnp.where(has_limit, b_limit // n, -1).astype(jnp.int32)
    limiting_contact = jnp.where(has_limit, b_limit % n, -1).astype(jnp.int32)

    def kkt(r):
        return jnp.stack([r.stationarity, r.feasibility, r.complementarity], axis=-1)

    lane_kkt = kkt(lanes)[pick]
    eq_pose = prob.to_pose(z_eq)
    b_pose = jax.vmap(prob.to_pose)(b_z)
    return Evaluation(
        value=value * MJ_TO_J,
        status=status,
        limiting_kind=limiting_kind,
        limiting_contact=limiting_contact,
        equilibrium_energy=u_eq * MJ_TO_J,
        equilibrium_translation=eq_pose[:3] / M_TO_MM,
        equilibrium_rotation=eq_pose[3:],
        boundary_energy=(u_b * MJ_TO_J).reshape(2, n),
        boundary_translation=(b_pose[:, :3] / M_TO_MM).reshape(2, n, 3),
        boundary_rotation=b_pose[:, 3:].reshape(2, n, 3),
        boundary_status=b_status.astype(jnp.int32).reshape(2, n),
        equilibrium_status=eq.status,
        equilibrium_margins=margins_eq,
        kkt=jnp.concatenate([kkt(eq)[None], jnp.where(reached[:, None], lane_kkt, jnp.nan)]),
        steps=jnp.concatenate([eq.steps[None], lanes.steps[pick]]),
    )
