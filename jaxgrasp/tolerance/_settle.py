"""Settling: stalled boundary lanes certified by a polish on a relaxed, well-conditioned problem."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.model import (
    Constraint,
    contact_hessians,
    contact_kinematics,
    energy_of,
    margins_of,
    rotation_hessian_along,
    rotation_matrix,
    slip_torsion,
)
from jaxgrasp.solver import LaneStatus, SolverOptions, SolverResult, dense_solve, kkt_tol, over_rows, put_rows
from jaxgrasp.tolerance._problems import (
    ProblemData,
    _first_order,
    _pose_scale,
    constraints,
    kinematic_hessian,
    objective,
    to_pose,
)

__all__ = ["settle_stalled", "settle_equilibrium", "needs_settling", "RELEASED_TOL"]


def _at_equilibrium(eq: SolverResult, lanes: SolverResult, at_eq, g_eq, lane_k) -> SolverResult:
    """The boundary lanes ``at_eq`` ``(L,)`` (leading axis ``L`` of ``lanes``; ``lane_k``
    their equality rows, ``g_eq`` that row's margin at the equilibrium) given the
    equilibrium's solution ``eq``: an equilibrium whose
    margin of row ``k`` is within the solver's tolerance of 0 is a KKT point of boundary
    problem ``k`` too, with the same residuals (the equality's multiplier
    ``nu = -lam_k``, row ``k``'s ``lam`` 0), and its minimiser, as no point of the
    boundary lies below the minimum of the region that holds it. Such lanes all start at
    the equilibrium (where a degenerate one, several constraints active at once, could
    stall: a grasp of the long property profile settled such a boundary in one
    orientation and not in another), so they are not solved but given this solution."""
    rows = jnp.arange(lanes.lam.shape[-1])
    is_k = rows[None, :] == lane_k[:, None]  # (L, 3N)
    given = SolverResult(
        x=jnp.broadcast_to(eq.x, lanes.x.shape),
        lam=jnp.where(is_k, 0.0, eq.lam[None, :]),
        nu=-jnp.sum(jnp.where(is_k, eq.lam[None, :], 0.0), axis=1),
        objective=jnp.broadcast_to(eq.objective, lanes.objective.shape),
        status=jnp.full(lanes.status.shape, LaneStatus.CONVERGED, lanes.status.dtype),
        stationarity=jnp.broadcast_to(eq.stationarity, lanes.stationarity.shape),
        feasibility=jnp.maximum(eq.feasibility, jnp.abs(g_eq)),
        complementarity=jnp.broadcast_to(eq.complementarity, lanes.complementarity.shape),
        steps=jnp.zeros(lanes.steps.shape, lanes.steps.dtype),
    )
    return jax.tree_util.tree_map(
        lambda a, b: jnp.where(at_eq.reshape((-1,) + (1,) * (a.ndim - 1)), a.astype(b.dtype), b), given, lanes
    )


_PYRAMID = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)  # face angles, rad

RELEASED_TOL = 1e-6
"""A stalled lane's contact ``j`` is released where its contact and slip margins are
both within this (scaled margins), and the lane's violation too."""

_POLISH_STEPS = 8

LM_FLOOR = 1e-8
"""The polish's damping relative to its Jacobian's size (`_levenberg_marquardt_step`):
``sqrt(eps)`` of float64, so that ``mu`` is above the rounding of ``J^T J`` (``eps |J|^2``)
and singular values below ``LM_FLOOR |J|_F`` count as null."""

SETTLE_BLOCK = 8
"""Lanes polished per block of the settling (`settle_stalled`,
`settle_equilibrium`), gathered over the batch."""


def _tangential(z, data: ProblemData, j):
    """``(3,)`` mm, the displacement of contact ``j`` at scaled pose ``z`` (eq. 11), and
    its normal ``n_j``."""
    x = to_pose(z, data.lever)
    u = (rotation_matrix(x[3:]) - jnp.eye(3, dtype=z.dtype)) @ data.params.c[j] + x[:3]
    return u, data.params.n[j]


def _pyramid_basis(z0, data: ProblemData, j):
    """``(3, 3)`` the pyramid's face directions ``v_k`` for contact ``j``, with ``v_0``
    against the tangential displacement at the stalled point ``z0``: the objective pushes
    the stalled iterate out of the cone there, and a pyramid with a face across that push
    certifies the apex exactly where the circular cone does (the tangential reaction
    ``sum_k lam_k v_k`` may then reach the cone's bound ``2 / (mu / cos^2 phi)`` of the
    normal one). Falls back to a fixed basis where that displacement vanishes."""
    u, n = _tangential(z0, data, j)
    t = u - jnp.dot(n, u) * n
    tn = jnp.linalg.norm(t)
    a = jax.nn.one_hot(jnp.argmin(jnp.abs(n)), 3, dtype=z0.dtype)
    fixed = jnp.cross(n, a)
    e1 = jnp.where(tn > 1e-14, -t / jnp.where(tn > 1e-14, tn, 1.0), fixed / jnp.linalg.norm(fixed))
    e2 = jnp.cross(n, e1)
    angles = jnp.asarray(_PYRAMID, z0.dtype)
    return jnp.cos(angles)[:, None] * e1 + jnp.sin(angles)[:, None] * e2


def _relaxed_problem(z, data: ProblemData, v, relaxed_rows, cone):
    """``(f, g)`` of the problem at scaled pose ``z`` with the rows ``relaxed_rows``
    ``(3N,)`` (every row of each released contact) replaced by that contact's pyramid rows
    ``P_kj = (mu_j d_j / (2 cos^2 phi_j) + v_jk . u_j) / dr_j`` (``v``: the ``(N, 3, 3)``
    face directions of each contact; row ``k * N + j`` holds ``P_kj``), and where ``cone``
    ``()`` every other slip row in its cone form (`_cone_margins`). One evaluation of
    the contact kinematics serves every row. Its derivatives are written out
    (`_relaxed_derivatives`)."""
    p = data.params
    n = p.c.shape[0]
    x = to_pose(z, data.lever)
    kinematics = contact_kinematics(x, p)
    f = energy_of(x, kinematics, p) / data.scale
    g = margins_of(kinematics, p)  # (3, N)
    u = jax.vmap(lambda j: _tangential(z, data, j)[0])(jnp.arange(n))  # (N, 3)
    pyramid = _slope_row(jnp.stack(kinematics, axis=-1), p)[:, None] + jnp.einsum(
        "jkc,jc->jk", v, u) / jax.lax.stop_gradient(p.dr)[:, None]
    g = g.at[Constraint.SLIP].set(jnp.where(cone & p.on, _cone_margins(kinematics, u, p), g[Constraint.SLIP]))
    return f, jnp.where(relaxed_rows, pyramid.T.reshape(-1), g.reshape(-1))


def _slope_row(q, p):
    """``(N,)`` the part of each pyramid row (`_relaxed_problem`) in the contact's
    own kinematics ``q`` ``(N, 4)``, ``mu d / (2 cos^2 phi dr)``."""
    return p.mu * q[:, 0] / (2.0 * q[:, 1] ** 2) / jax.lax.stop_gradient(p.dr)


def _cone_margins(kinematics, u, p):
    """``(N,)`` `_cone_row` at the contact kinematics ``(d, cos phi, dt^2, theta)``
    and displacements ``u`` ``(N, 3)``, mm, with ``dt^2`` taken as ``|t|^2`` of the vector
    ``t = u - (u . n) n``."""
    t = u - jnp.sum(u * p.n, axis=-1, keepdims=True) * p.n
    return _cone_row(jnp.stack(kinematics, axis=-1).at[:, 2].set(jnp.sum(t * t, axis=-1)), p)


def _cone_row(q, p):
    """``(N,)`` the slip margins in cone form, ``(mu d / cos^2 phi - sqrt(4 |t|^2 + K d
    theta^2)) / dr``, from each contact's kinematics ``q`` ``(N, 4)`` with ``dt^2 = |t|^2``
    (``t = u - (u . n) n`` the tangential displacement, mm; ``K d theta^2`` the torsion
    term, `slip_torsion`): where ``d >= 0`` the
    same region as the squared margin ``(mu^2 d^2 / cos^4 phi - 4 dt^2 - K d theta^2) /
    (mu dr)^2``, but with a gradient of order 1 up to the cone's apex, where the squared
    margin's vanishes with ``d``. A fingertip held on its cone a few tenths of a micrometre
    from its apex (``random_urdfs`` 015, issue 42) gives the squared row a multiplier of
    4e3 and a KKT system that Newton's method cannot solve to ``tol``; in cone form the
    multiplier is 2 and it converges. ``|t|^2`` is taken from the vector ``t``, not from
    ``|u|^2 - (u . n)^2``, whose cancellation leaves ``|t|`` a relative error of 1e-8
    there and the stationarity a floor of 1e-8."""
    d, cphi, dt2, theta = q.T
    b2 = 4.0 * dt2 + slip_torsion(d, theta, p)
    safe = b2 > 0.0  # the square root's derivative is infinite at 0: where-guarded
    b = jnp.where(safe, jnp.sqrt(jnp.where(safe, b2, 1.0)), 0.0)
    return (p.mu * d / cphi**2 - b) / jax.lax.stop_gradient(p.dr)


def _per_contact_derivatives(row, q):
    """``(N, 4)`` gradients and ``(N, 4, 4)`` Hessians of ``row(q)`` ``(N,)`` whose entry
    ``j`` depends on ``q_j`` ``(4,)`` alone, each in its own ``q_j``: the gradient of the
    sum, and its derivative along each coordinate of every ``q_j`` at once."""
    grad = jax.grad(lambda q: jnp.sum(row(q)))
    tangents = jnp.broadcast_to(jnp.eye(4, dtype=q.dtype)[:, None, :], (4,) + q.shape)
    g, h = jax.vmap(lambda t: jax.jvp(grad, (q,), (t,)), out_axes=(None, 0))(tangents)
    return g, jnp.moveaxis(h, 0, -1)


def _relaxed_derivatives(z, lam, data: ProblemData, v, relaxed_rows, cone):
    """``(grad_f (6,), jac (3N, 6), hess (6, 6))`` of `_relaxed_problem` at scaled
    pose ``z``: the objective's gradient, the constraints' Jacobian and the Hessian of the
    Lagrangian ``f - lam . g`` (``lam`` ``(3N,)``), written out from the contact
    kinematics' derivatives as the lanes' are
    (`lane_problem`). Every row is a function of its
    contact's kinematics ``q_j`` (the problem's own rows, `_slope_row`,
    `_cone_row`) plus, for a pyramid row, ``v_jk . u_j / dr_j``, linear in the
    contact's displacement ``u_j = (R - I) c_j + dp``: ``d u_j / dx = [I | dR/dw_k c_j]``,
    and the second derivatives of ``sum_j m_j . u_j`` are those of ``R : sum_j m_j c_j^T``
    (`rotation_hessian_along`). Autodiff of the relaxed
    problem (``jacfwd`` of its ``grad``) gives the same to rounding
    (``tests/tolerance/test_settle_derivatives.py``) from more code to trace."""
    p = data.params
    n = p.c.shape[0]
    first = _first_order(z, data)
    q, dq, geometry, de, dm = first.aux
    _, _, pu, a_c, _ = geometry
    he, hm = contact_hessians(tuple(q.T), p)
    dr = jax.lax.stop_gradient(p.dr)
    sg, sh = _per_contact_derivatives(lambda q: _slope_row(q, p), q)
    cg, ch = _per_contact_derivatives(lambda q: _cone_row(q, p), q.at[:, 2].set(jnp.sum(pu * pu, axis=-1)))
    rel = relaxed_rows.reshape(3, n)
    in_cone = jnp.zeros((3, n), bool).at[Constraint.SLIP].set(cone & p.on & ~rel[Constraint.SLIP])
    gq_rows = jnp.where(rel[..., None], sg, jnp.where(in_cone[..., None], cg, dm))  # (3, N, 4)
    hq_rows = jnp.where(rel[..., None, None], sh, jnp.where(in_cone[..., None, None], ch, hm))
    gu_rows = jnp.where(rel[..., None], jnp.swapaxes(v, 0, 1) / dr[None, :, None], 0.0)  # (3, N, 3)
    du = jnp.concatenate([jnp.broadcast_to(jnp.eye(3, dtype=z.dtype), (n, 3, 3)), jnp.swapaxes(a_c, 1, 2)], -1)
    scale = _pose_scale(data, z.dtype)
    jac = (jnp.einsum("rnk,nkj->rnj", gq_rows, dq) + jnp.einsum("rna,naj->rnj", gu_rows, du)).reshape(-1, 6) * scale
    w = -lam.reshape(3, n)
    gq = de / data.scale + jnp.einsum("rn,rnk->nk", w, gq_rows)
    hq = he / data.scale + jnp.einsum("rn,rnkl->nkl", w, hq_rows)
    rot = rotation_hessian_along(to_pose(z, data.lever)[3:], jnp.einsum("rn,rna,nb->ab", w, gu_rows, p.c))
    hess = kinematic_hessian(z, data, dq, geometry, gq, hq).at[3:, 3:].add(rot * scale[3:, None] * scale[None, 3:])
    return first.grad_f, jac, hess


def _polish(data: ProblemData, z0, k, released, warm, cone, o: SolverOptions):
    """Newton's method on the KKT equations of boundary problem ``k`` (equality row), with
    the active set fixed at the stalled point ``z0``: on the relaxation at every contact
    ``released`` ``(N,)`` (none: the problem itself), from the multipliers 0, or where
    ``warm`` ``()`` from the active rows' least-squares multipliers at ``z0``
    (`_kkt_newton`); where ``cone`` ``()``, with the other slip rows in cone form
    (`_cone_row`), and a contact held on its cone not held at ``d = 0`` as well
    (the cone holds ``d >= 0``; holding both pins the apex).

    Returns ``(z, lam_rel, ok, (stat, feas, comp))``: ``lam_rel`` ``(3N,)`` multipliers
    of the (relaxed) problem (the equality's included, free in sign); ``ok`` whether ``z``
    is a KKT point of it within tol and feasible for the original problem."""
    n = data.params.c.shape[0]
    tol = kkt_tol(z0.dtype, o)
    rows = jnp.arange(3 * n)
    j_rows = released[rows % n]
    # a released contact's own slip equality is relaxed away
    has_eq = ~((k >= n) & (k < 2 * n) & released[jnp.clip(k - n, 0, n - 1)])
    is_eq = (rows == k) & has_eq
    v = jax.vmap(lambda j: _pyramid_basis(z0, data, j))(jnp.arange(n))  # (N, 3, 3)

    def problem(z, lam):  # the relaxed problem's constraints and derivatives, for the polish
        return (_relaxed_problem(z, data, v, j_rows, cone)[1],) + _relaxed_derivatives(z, lam, data, v, j_rows, cone)

    near = constraints(z0, data) <= RELEASED_TOL
    on_cone = cone & near[n + rows % n] & (rows < n)  # a contact row whose slip row is held
    active = j_rows | is_eq | (near & ~on_cone)
    y, r, gz = _kkt_newton(problem, active, z0, warm)
    z, lam = y[:6], y[6:]
    stat = jnp.max(jnp.abs(r[:6]))
    feas = jnp.max(jnp.where(is_eq, jnp.abs(gz), jnp.maximum(-gz, 0.0)))
    comp = jnp.max(jnp.where(is_eq, 0.0, jnp.abs(lam * gz)))
    # With torsion (theta_j != 0) the slip margin is d_j (mu_j^2 d_j / cos^4 phi_j - K theta_j^2)
    # - 4 dt_j^2 with K = (225/32) r_j / mu_j^2 at d_j = 0: negative for 0 < d_j < gap below,
    # so near the apex contact j's rows hold exactly where d_j = 0 and t_j = 0, the pyramid
    # rows' common zero: their multipliers are then free in sign.
    p = data.params
    _, cphi, _, theta = contact_kinematics(to_pose(z, data.lever), p)
    gap = (225.0 / 32.0) * p.r * theta**2 * cphi**4 / p.mu**4  # (N,)
    free = is_eq | (j_rows & (gap >= RELEASED_TOL * p.dr)[rows % n])
    dual = jnp.all(free | (lam >= -tol))  # rows held at lam = 0 end at +-1e-30
    lam = jnp.where(free, lam, jnp.maximum(lam, 0.0))
    g_orig = constraints(z, data)
    orig_feas = jnp.max(jnp.where(rows == k, jnp.abs(g_orig), jnp.maximum(-g_orig, 0.0)))
    ok = (stat <= tol) & (feas <= tol) & (comp <= tol) & dual & (orig_feas <= tol) & jnp.all(jnp.isfinite(y))
    return z, lam, ok, (stat, jnp.maximum(feas, orig_feas), comp)


def _polish_released(data: ProblemData, z0, k, released, o: SolverOptions):
    """`_polish` relaxing the first contact ``released`` ``(N,)``, and where that
    gives no certificate, every released contact; each from the multipliers 0 and, where
    neither of those certifies, from least-squares multipliers; where none of those
    certifies, from least-squares multipliers with the slip rows in cone form, relaxing
    the first released contact, then the others. Returns `_polish`'s tuple, the
    ``(N,)`` contacts relaxed in the answer and whether it is in cone form.

    Several fingertips can let go at once (a four-finger grasp hanging on two of them):
    relaxing only one leaves the other's apex degenerate, and that polish fails there.
    Relaxing all of them pins each at its apex, so it is tried second. A stalled point can
    be far from its multipliers (an augmented Lagrangian that stalled at its largest
    penalty holds one slip multiplier at 9e3 where the minimum's is 2e-2): from 0 Newton's
    method then wanders off towards another fingertip's apex and creeps (3-finger
    equilibria of ``random_urdfs`` 073, issue 42), while from the least-squares
    multipliers it converges in three steps. Two released fingertips need not both be at
    their apexes at the minimum: a four-finger grasp of ``random_urdfs`` 015 (issue 42)
    stalls with two released, and its minimum has one at its apex and the other on its
    cone 3e-4 mm deep, which only the cone form certifies (relaxing the other one). The
    attempts are tried in this order, so that a lane certified before is certified at
    the same point."""
    first = jax.nn.one_hot(jnp.argmax(released), released.shape[0], dtype=bool) & released
    masks = jnp.stack([first, released, first, released, first, released & ~first])
    warm = jnp.asarray([False, False, True, True, True, True])
    cone = jnp.asarray([False, False, False, False, True, True])
    # one traced polish over every attempt: the settling stage is in every compiled evaluation
    tries = jax.vmap(lambda m, w, c: _polish(data, z0, k, m, w, c, o))(masks, warm, cone)
    use = jnp.argmax(tries[2])  # the first attempt that certifies (where none does: unused)
    return jax.tree_util.tree_map(lambda a: a[use], tries) + (masks[use], cone[use])


def _kkt_newton(problem, active, z0, warm):
    """`_POLISH_STEPS` damped Newton steps (`_levenberg_marquardt_step`) on
    the KKT equations of ``problem`` (``(z, lam) -> (g (3N,), grad f (6,), J (3N, 6),
    Hessian of f - lam . g (6, 6))``) with the rows ``active`` ``(3N,)``
    held at ``g = 0`` and the others at ``lam = 0``, from ``(z0, lam = 0)``, or where
    ``warm`` ``()`` from ``(z0, lam_A)``: the least-squares multipliers of the active rows,
    ``min |grad f - J_A^T lam_A|``, read off the KKT Jacobian at ``(z0, 0)`` (its block
    ``d grad_L / d lam = -J^T``), by the same damped normal equations. Returns ``(y, r,
    gz)``: ``y = (z, lam)`` ``(6 + 3N,)``, the residual ``r`` and the constraints ``gz``
    at the last point."""
    n3 = active.shape[0]
    dtype = z0.dtype
    held = jnp.diag(jnp.where(active, 0.0, 1.0).astype(dtype))

    def newton(i, carry):
        # Pass 0 of a warm polish only sets the multipliers, then _POLISH_STEPS damped Newton
        # steps, then passes for the residual at the last point. Pass 0's least squares go
        # through the same step function, so that a pass has one solve: zero columns for z
        # (no step in z), the active rows' block -J_A^T against grad f = r[:6], and the
        # inactive multipliers held at 0.
        y, _, _ = carry
        z, lam = y[:6], y[6:]
        gz, grad_f, jg, hess = problem(z, lam)
        r = jnp.concatenate([grad_f - jg.T @ lam, jnp.where(active, gz, lam)])
        jac = jnp.block([[hess, -jg.T], [jnp.where(active[:, None], jg, 0.0), held]])
        first = warm & (i == 0)
        lam_rows = jnp.where(active[None, :], jac[:6, 6:], 0.0)
        jac0 = jnp.zeros_like(jac).at[:6, 6:].set(lam_rows).at[6:, 6:].set(held)
        r0 = jnp.zeros_like(r).at[:6].set(r[:6])
        steps = jnp.where(warm, (i >= 1) & (i <= _POLISH_STEPS), i < _POLISH_STEPS)
        step = _levenberg_marquardt_step(jnp.where(first, jac0, jac), jnp.where(first, r0, r))
        return y - jnp.where(first | steps, step, 0.0), r, gz

    y0 = jnp.concatenate([z0, jnp.zeros(n3, dtype)])
    carry = (y0, jnp.zeros(6 + n3, dtype), jnp.zeros(n3, dtype))
    return jax.lax.fori_loop(0, _POLISH_STEPS + 2, newton, carry)


def _levenberg_marquardt_step(jac, r):
    """``(m,)`` the polish's step on the KKT equations, ``(J^T J + mu I)^-1 J^T r``
    (``jac`` ``(m, m)`` their Jacobian ``J``, ``r`` ``(m,)`` their residual, scaled units),
    with ``mu = (LM_FLOOR |J|_F)^2``: a Levenberg-Marquardt step of fixed, tiny damping.

    Why not Newton's ``J^-1 r``: a grasp with a symmetry (the cube about the axis of its
    two fingertips, here with a 10 m fingertip radius) has a whole circle of boundary
    minima, so ``J`` is singular along it and elimination's pivot there is rounding; the
    step along the circle was rounding divided by rounding, and whether the polish reached
    ``tol`` depended on the stalled point's last digits, i.e. on the program that solved
    the lane (``evaluate``, or a batch chunk of given companions: issue 40). Here a
    direction of singular value ``s`` takes ``s / (s^2 + mu)`` of the residual, bounded
    by ``1 / (2 sqrt(mu))``, and where ``s^2 >> mu`` the step is Newton's. (A damping
    ``|r|^2`` as in Yamashita & Fukushima's method is too strong here: the polish starts
    at ``lam = 0``, far from the multipliers, and would crawl.) No LAPACK: see
    `jaxgrasp.solver._dense`."""
    mu = (LM_FLOOR**2) * jnp.sum(jac * jac)
    normal = jac.T @ jac + mu * jnp.eye(jac.shape[0], dtype=jac.dtype)
    return dense_solve(normal, jac.T @ r)


def _polish_candidates(lanes: SolverResult, found, num_starts: int):
    """``(2N, D)`` bool: the lanes `settle_stalled` may polish, those that stalled
    (``NOT_CONVERGED``) at a point feasible within `RELEASED_TOL`, of problems
    that no start settled (a settled problem keeps its answer: a stalled lane of one can
    sit far from the converged ones, e.g. at a large rotation)."""
    stalled = found & (lanes.status == LaneStatus.NOT_CONVERGED) & (lanes.feasibility <= RELEASED_TOL)
    converged = (found & (lanes.status == LaneStatus.CONVERGED)).reshape(-1, num_starts)
    return stalled.reshape(-1, num_starts) & ~jnp.any(converged, axis=1, keepdims=True)


def _lanes_to_polish(lanes: SolverResult, found, num_starts: int):
    """``(pick (2N,), wanted (2N,))`` of one grasp (``lanes`` and ``found`` with leading
    axis ``2N * D``): for each boundary problem the lane `settle_stalled` polishes,
    its lowest-energy candidate (`_polish_candidates`), and whether it has one."""
    candidate = _polish_candidates(lanes, found, num_starts)  # (2N, D)
    best = jnp.argmin(jnp.where(candidate, lanes.objective.reshape(-1, num_starts), jnp.inf), axis=1)
    return jnp.arange(candidate.shape[0]) * num_starts + best, jnp.any(candidate, axis=1)


def settle_stalled(data: ProblemData, lanes: SolverResult, lane_k, found, num_starts: int, o: SolverOptions):
    """Certify boundary lanes that stalled at a feasible point (a post-solve stage).

    For each boundary problem of each grasp of the batch that no start settled, the
    lowest-energy lane that ended ``NOT_CONVERGED`` with its violation within
    `RELEASED_TOL` is polished (`_polished_lane`): Newton's method on the KKT
    equations, its active set (margins within `RELEASED_TOL`, and the equality)
    fixed, on the relaxation above at the contacts released there
    (`_released_contacts`), else on the problem itself (bounded multipliers, but an
    inner solve that stalled, e.g. at the largest penalty). Where that gives a KKT point
    within ``tol`` (inequality multipliers ``>= 0``) that is feasible for the original
    problem, the lane becomes ``CONVERGED`` there, with the polish's KKT residuals and
    the relaxation's multipliers mapped back (`_original_multipliers`). Every other
    lane is returned unchanged; a lane that converged is never touched.

    The problems to polish are gathered over the whole batch, `SETTLE_BLOCK` at a
    time (`jaxgrasp.solver._rows.over_rows`): stalls are rare, so a batch pays for
    the problems that need it, however they fall on its grasps (with four fingertips a
    released contact can stall three or four force-limit problems of one grasp at once,
    issue 42), and the polish is batched once, not per grasp and again per problem.

    Args:
        data: the batch's `ProblemData`, leading axis ``B``.
        lanes: the boundary lanes, leading axes ``(B, 2N * D)``.
        lane_k: ``(2N * D,)`` equality row of each lane.
        found: ``(B, 2N * D)`` the lanes that were started.
        num_starts: ``D``.
        o: the [`SolverOptions`][jaxgrasp.SolverOptions] the lanes were solved with.
    """
    b = found.shape[0]
    pick, wanted = jax.vmap(lambda lane, f: _lanes_to_polish(lane, f, num_starts))(lanes, found)  # (B, 2N)
    two_n = pick.shape[1]
    pick = pick.reshape(-1)

    def update(rows, valid, lanes):
        grasp, lane = rows // two_n, pick[rows]
        gathered = jax.tree_util.tree_map(lambda a: a[grasp], data)
        new, ok = jax.vmap(lambda d, x, k, steps: _polished_lane(d, x, k, steps, o))(
            gathered, lanes.x[grasp, lane], lane_k[lane], lanes.steps[grasp, lane]
        )
        to = jnp.where(valid & ok, grasp, b)  # a padding row, or a polish that did not certify: dropped
        return jax.tree_util.tree_map(lambda a, s: a.at[to, lane].set(s.astype(a.dtype), mode="drop"), lanes, new)

    return over_rows(wanted.reshape(-1), SETTLE_BLOCK, update, lanes)


NO_EQUALITY = -1
"""The equality row of the equilibrium problem for `_polish`: none."""


def settle_equilibrium(data: ProblemData, eq: SolverResult, o: SolverOptions) -> SolverResult:
    """Certify equilibria that stalled at a feasible point: each grasp's equilibrium lane of
    a batch (leading axis ``B`` on ``data`` and ``eq``) that ended ``NOT_CONVERGED`` with
    its violation within `RELEASED_TOL` is polished as `settle_stalled`
    polishes a boundary lane (`_polished_lane`, no equality), in gathered blocks of
    `SETTLE_BLOCK` grasps, and becomes ``CONVERGED`` where that certifies it; every
    other equilibrium is returned as it is.

    Why: on grasps of real objects the equilibrium often lets go of a fingertip (the
    weight pulls the object off it, e.g. two fingertips on a tilted face of a mesh): the
    minimum is then at that contact's apex, ``d_j = 0`` and ``dt_j = 0``, where the slip
    margin ``mu^2 d^2 / cos^4 phi - 4 dt^2 - ...`` is quadratic with a zero gradient.
    LICQ fails there, the multipliers of the contact and slip rows have no bounded limit,
    and the augmented Lagrangian crawls at its largest penalty with a violation of
    1e-8..2e-8 until its step budget runs out (issue 42). The pyramid relaxation of the
    released contact is regular at that apex and certifies it exactly where the cone
    does (`_pyramid_basis`)."""
    need = (eq.status == LaneStatus.NOT_CONVERGED) & (eq.feasibility <= RELEASED_TOL)
    k = jnp.asarray(NO_EQUALITY, jnp.int32)

    def update(rows, valid, eq):
        new, ok = jax.vmap(lambda d, x, steps: _polished_lane(d, x, k, steps, o))(
            jax.tree_util.tree_map(lambda a: a[rows], data), eq.x[rows], eq.steps[rows]
        )
        return jax.tree_util.tree_map(lambda a, s: put_rows(a, rows, valid & ok, s.astype(a.dtype)), eq, new)

    return over_rows(need, SETTLE_BLOCK, update, eq)


def _polished_lane(data: ProblemData, x, k, steps, o: SolverOptions):
    """``(new, ok)``: the lane that stalled at scaled pose ``x`` ``(6,)`` of the problem
    with equality row ``k`` (`NO_EQUALITY`: the equilibrium) after ``steps``,
    polished (`_polish_released`, relaxing the contacts released at ``x``): the
    `SolverResult` of one lane, ``CONVERGED`` at the polished point, with the
    multipliers mapped back to the original rows (`_original_multipliers`; for the
    equilibrium ``nu`` is 0), and whether it certifies that point."""
    released = _released_contacts(data, x, k)
    z, lam_rel, ok, (stat, feas, comp), relaxed, cone = _polish_released(data, x, k, released, o)
    lam, nu = _original_multipliers(data, z[None], lam_rel[None], k[None], relaxed[None], cone[None])
    new = SolverResult(
        x=z,
        lam=lam[0],
        nu=nu[0],
        objective=objective(z, data),
        status=jnp.asarray(LaneStatus.CONVERGED, jnp.int32),
        stationarity=stat,
        feasibility=feas,
        complementarity=comp,
        steps=steps + _POLISH_STEPS,
    )
    return new, ok


def _released_contacts(data: ProblemData, x, k):
    """``(N,)`` bool: the contacts released at the scaled pose ``x`` ``(6,)`` of the
    problem with equality row ``k`` (contact and slip margins within
    `RELEASED_TOL`, active, their force row not ``k``)."""
    n = data.params.c.shape[0]
    g = constraints(x, data).reshape(3, n)
    released = (g[0] <= RELEASED_TOL) & (g[1] <= RELEASED_TOL) & data.params.on
    return released & (k != 2 * n + jnp.arange(n))


def _original_multipliers(data: ProblemData, z, lam_rel, k, released, cone):
    """``(lam (P, 3N), nu (P,))``: the polish's multipliers ``lam_rel`` ``(P, 3N)`` at
    ``z`` ``(P, 6)`` in the original problem's rows (``k`` ``(P,)`` the equality row,
    ``released`` ``(P, N)`` the relaxed contacts, ``cone`` ``(P,)`` whether the other slip
    rows were in cone form). The equality's goes to ``nu``; each
    released contact ``j``'s pyramid rows' ``d_j`` part to its contact row, ``d P_k /
    d d_j = mu_j / (2 cos^2 phi_j)`` per ``dr_j``, clipped at 0 (the tangential part has
    no row of the original problem, so the envelope derivative of such a boundary misses
    it). A cone-form slip row's multiplier is scaled to the squared row's: on the cone
    (``a = b``, ``a = mu d / cos^2 phi``) the squared margin's gradient is ``2 a / (mu^2
    dr)`` times the cone margin's, so ``lam = lam_cone mu^2 dr / (2 a)``."""
    p = data.params
    n = p.c.shape[0]
    rows = jnp.arange(3 * n)
    is_eq = rows[None, :] == k[:, None]
    j_rows = released[:, rows % n]  # (P, 3N)
    kin = jax.vmap(lambda z: contact_kinematics(to_pose(z, data.lever), p))(z)
    d, cphi = kin[0], kin[1]  # (P, N)
    slope = p.mu[None, :] / (2.0 * cphi**2)
    per_contact = jnp.sum(jnp.where(j_rows, lam_rel, 0.0).reshape(-1, 3, n), axis=1)  # (P, N)
    lam_d = jnp.where(released, jnp.maximum(slope * per_contact, 0.0), 0.0)
    a = p.mu[None, :] * d / cphi**2
    lam_slip = lam_rel[:, n : 2 * n]
    held = cone[:, None] & (lam_slip != 0.0) & (a > 0.0)
    to_squared = jnp.where(held, p.mu**2 * jax.lax.stop_gradient(p.dr) / (2.0 * jnp.where(held, a, 1.0)), 1.0)
    lam_rel = lam_rel.at[:, n : 2 * n].set(lam_slip * to_squared)
    lam = jnp.where(is_eq | j_rows, 0.0, lam_rel).at[:, :n].add(lam_d)
    return lam, -jnp.sum(jnp.where(is_eq, lam_rel, 0.0), axis=1)


def needs_settling(boundary_status, equilibrium_status=None) -> np.ndarray:
    """``(...)`` bool: whether an evaluation with this ``boundary_status`` ``(..., 2, N)``
    and ``equilibrium_status`` ``(...)`` ([`Evaluation`][jaxgrasp.Evaluation] fields, host-side)
    has a boundary problem that no start settled or an equilibrium that did not settle,
    the only cases in which `settle_stalled` and `settle_equilibrium` can
    change anything."""
    out = np.any(np.asarray(boundary_status) == LaneStatus.NOT_CONVERGED, axis=(-2, -1))
    if equilibrium_status is not None:
        out = out | (np.asarray(equilibrium_status) == LaneStatus.NOT_CONVERGED)
    return out
