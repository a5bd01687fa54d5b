"""Issue 41, item 2 (infeasible lanes end early): a phase-1 certificate, measured.

A boundary lane is infeasible where the violation measure ``v = |h|^2/2 + sum min(g_i, 0)^2/2``
is stationary at a positive violation (the solver's lane status). The
augmented-Lagrangian lane reaches such a point only as its penalty grows, one inner solve
per growth. This experiment tries the direct route: at each multiplier update of a lane
with an equality whose violation is above ``CHECK_VIOLATION``, ``K`` Newton steps on ``v``
itself from the lane's point (truncated eigen-solve, a ladder of step lengths), then the
solver's own stationarity test. Lanes are stepped one loop step at a time with
``jaxgrasp.solver.step`` (the steps the work queue takes); the certificate only
reads them. Printed: infeasible lanes flagged, false flags (lanes flagged that end
otherwise), steps per infeasible lane with and without the early end, and certificates
computed per lane (each costs ``K`` Newton steps on ``v``, about a lane-step each:
first-order data, two Lagrangian Hessians, a ladder of trial points).

    python experiments/infeasible_lanes/infeasible_certificate.py --contacts 7 --grasps 8 --newton 6 12
"""

import argparse
import os
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports



import jaxgrasp  # noqa: F401,E402  (64-bit mode)
from jaxgrasp.solver import Problem, SolverOptions, as_problem, first_order, lagrangian_hessian, tolerances


CERTIFICATE_STEPS = 6
"""Newton steps on the violation measure per certificate (each one first-order
evaluation, two Lagrangian Hessians and a ladder of trial points)."""

CHECK_VIOLATION = 1e-3
"""A lane with an equality is checked at a multiplier update whose violation (scaled
constraint units, inf-norm) is above this: lanes that converge have usually fallen below
it by their first update, so the checks go to lanes that may be infeasible."""

_LADDER = 8  # step lengths 1, 1/2, ... 1/128 tried per Newton step on v


def _residual(gx, eq_mask):
    """``(m,)`` the violated part of ``g``: the equality's value, ``min(g_i, 0)`` elsewhere."""
    return jnp.where(eq_mask > 0, gx, jnp.minimum(gx, 0.0))


def _violation_measure(problem: Problem, x, eq_mask):
    r = _residual(problem.fg(x)[1], eq_mask)
    return 0.5 * jnp.dot(r, r)


def _newton_on_violation(problem: Problem, x, eq_mask, o: SolverOptions):
    """``(n,)`` one Newton step on ``v`` from ``x`` ``(n,)``, its length chosen on a ladder
    (``x`` itself where no length lowers ``v``).

    ``v``'s gradient is ``J^T r`` and its Hessian ``J_a^T J_a + sum_i r_i hess g_i`` (rows
    ``a``: the equality and the violated inequalities); the second term is the problem's
    Lagrangian Hessian with weights ``r`` less the one with weights zero."""
    d = first_order(problem, x)
    r = _residual(d.gx, eq_mask)
    active = ((eq_mask > 0) | (d.gx < 0.0)).astype(x.dtype)
    grad = d.jac.T @ r
    curvature = lagrangian_hessian(problem, d, x, r) - lagrangian_hessian(problem, d, x, jnp.zeros_like(r))
    hmat = (d.jac.T * active) @ d.jac + curvature
    p = _truncated_newton(0.5 * (hmat + hmat.T), grad)
    p = p * jnp.minimum(1.0, o.max_step / jnp.maximum(jnp.max(jnp.abs(p)), 1e-300))
    alphas = 0.5 ** jnp.arange(_LADDER, dtype=x.dtype)
    trial = jax.vmap(lambda a: _violation_measure(problem, x + a * p, eq_mask))(alphas)
    trial = jnp.where(jnp.isfinite(trial), trial, jnp.inf)
    best = jnp.argmin(trial)
    return jnp.where(trial[best] < 0.5 * jnp.dot(r, r), x + alphas[best] * p, x)


def _truncated_newton(hmat, g):
    """``(n,)`` ``-H^+ g`` over the eigenvalues of ``hmat`` ``(n, n)`` whose magnitude is
    above ``1e-8`` of the largest (negative ones mirrored): at a positive minimum of ``v``
    the minimisers often form a manifold (directions along which no constraint moves), and
    a floored eigenvalue there would send the step along it."""
    w, v = jnp.linalg.eigh(hmat)
    a = jnp.abs(w)
    keep = a > 1e-8 * jnp.max(a)
    coef = jnp.where(keep, (v.T @ g) / jnp.where(keep, a, 1.0), 0.0)
    return -(v @ coef)


def violation_certificate(problem, x, eq_mask, o: SolverOptions, steps: int = CERTIFICATE_STEPS):
    """``()`` bool: whether :data:`CERTIFICATE_STEPS` Newton steps on the violation measure
    from ``x`` ``(n,)`` end at a point that the solver's lane status
    calls infeasible (violation above ``infeasible_tol``, the measure's gradient at most
    ``infeasible_stationarity`` times the violation).

    Args:
        problem: a :class:`~jaxgrasp.solver.Problem` (or its ``fg``).
        x: ``(n,)`` the lane's point (scaled units).
        eq_mask: ``(m,)`` the lane's one-hot equality selector.
        o: :class:`~jaxgrasp.solver.SolverOptions`.
        steps: Newton steps on the measure (static).
    """
    problem = as_problem(problem)
    y = jax.lax.fori_loop(0, steps, lambda _, y: _newton_on_violation(problem, y, eq_mask, o), x)
    d = first_order(problem, y)
    r = _residual(d.gx, eq_mask)
    viol = jnp.max(jnp.abs(r))
    _, infeasible_tol, _ = tolerances(x.dtype, o)
    stationary = jnp.max(jnp.abs(d.jac.T @ r)) <= o.infeasible_stationarity * viol
    return (viol > infeasible_tol) & stationary & jnp.all(jnp.isfinite(y))


def benchmark_lanes(n_contacts: int, n_grasps: int):
    """``(states, theta, options)``: every boundary and equilibrium lane (all starts) of the
    first ``n_grasps`` grasps with ``n_contacts`` contacts of the batch benchmark's mixed
    set, as initial solver states with their problem data (leading axis: lanes), and the
    default :class:`~jaxgrasp.SolverOptions`."""
    from batch_benchmark import make_grasps
    from jaxgrasp.engine import inputs_of, run_inline, stage_functions
    from jaxgrasp import solver as S

    opts = jaxgrasp.EvaluateOptions()
    o = opts.solver
    gs = [g for g in make_grasps(1000, 0) if g.num_contacts == n_contacts][:n_grasps]
    batch = jaxgrasp.stack(gs)
    starts = jax.jit(lambda b: run_inline(b, stage_functions(opts, False), until="lane_starts"))(batch)
    data = inputs_of(batch)["data"]
    B, L = starts.x0.shape[:2]
    theta = jax.tree_util.tree_map(
        lambda a: jnp.broadcast_to(a[:, None], (B, L) + a.shape[1:]).reshape((B * L,) + a.shape[1:]), data)
    flat = lambda a: a.reshape((B * L,) + a.shape[2:])  # noqa: E731
    st = jax.vmap(lambda x, m, nu, a: S.init(x, m, nu, a, o))(
        flat(starts.x0), flat(starts.eq_mask), flat(starts.nu0), flat(starts.active))
    return st, theta, o


def run(n_contacts: int, n_grasps: int, steps: int, check: float) -> str:
    from jaxgrasp import solver as S
    from jaxgrasp.tolerance import lane_problem

    st, theta, o = benchmark_lanes(n_contacts, n_grasps)
    step = jax.jit(jax.vmap(lambda s, t: S.step(lane_problem(t), s, o)))
    cert = jax.jit(jax.vmap(lambda x, m, t: violation_certificate(lane_problem(t), x, m, o, steps)))
    flag = np.full(st.x.shape[0], -1)
    checks = np.zeros(st.x.shape[0], int)
    for _ in range(o.max_steps):
        new = step(st, theta)
        pv0, pv1 = np.asarray(st.prev_viol), np.asarray(new.prev_viol)
        upd = ((pv0 != pv1) & (np.asarray(new.status) == 2) & (pv1 > check)
               & (np.asarray(st.eq_mask).sum(1) > 0) & (flag < 0))
        if upd.any():
            c = np.asarray(cert(st.x, st.eq_mask, theta)) & upd  # at the point of the update
            checks += upd
            flag[c] = np.asarray(new.steps)[c]
        st = new
        if not np.any((np.asarray(st.status) == 2) & (np.asarray(st.steps) < o.max_steps)):
            break
    fin, fs = np.asarray(st.status), np.asarray(st.steps)
    inf, fl, ran = fin == 1, flag >= 0, fin != 3
    return (f"N={n_contacts}, {n_grasps} grasps, K={steps} Newton steps on v, check above {check:g}: "
            f"{inf.sum()} infeasible lanes of {ran.sum()} run; flagged {(fl & inf).sum()}, false flags "
            f"{(fl & ~inf).sum()}; steps per infeasible lane {fs[inf].mean():.1f} -> "
            f"{np.where(fl, flag, fs)[inf].mean():.1f}; certificates per lane run {checks[ran].mean():.2f} "
            f"(infeasible lanes {checks[inf].mean():.2f}, converged {checks[fin == 0].mean():.2f}), "
            f"about {steps * checks[ran].mean():.1f} Newton steps on v per lane run")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--contacts", type=int, default=7)
    ap.add_argument("--grasps", type=int, default=8)
    ap.add_argument("--newton", type=int, nargs="+", default=[6, 12])
    ap.add_argument("--check", type=float, default=CHECK_VIOLATION)
    a = ap.parse_args()
    for k in a.newton:
        print(run(a.contacts, a.grasps, k, a.check), f"[load {os.getloadavg()[0]:.2f}]", flush=True)


if __name__ == "__main__":
    main()
