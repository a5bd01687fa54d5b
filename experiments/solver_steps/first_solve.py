"""Issue 41, item 2: why an infeasible lane cannot end in half its steps by the solver's
options, and a first phase on the violation alone, measured (not part of jaxgrasp).

Three parts, each printed with the load average:

1. ``--count`` grasps of the batch benchmark's mixed set through
   :func:`jaxgrasp.evaluate_batch` (the engine's own run, first wave included): the
   boundary lanes' steps by final status, mean and percentiles
   (:func:`profile_batch.profile` collects the lanes);
2. every lane of the first ``--grasps`` grasps with ``--contacts`` contacts (all 20 starts
   of every problem, no first wave; :func:`infeasible_certificate.benchmark_lanes`),
   stepped one loop step at a time with :func:`jaxgrasp.solver.step`: the first
   inner solve of each boundary lane (the Newton steps before its first multiplier
   update): which step lengths the line search took, how often the direction was capped
   at ``max_step`` or met negative curvature, and how fast ``|grad phi|_inf`` fell per
   Newton step, apart for steps across which the set of rows where phi is quadratic
   (the equality and the inequalities with ``lam - rho g > 0``) changed and steps across
   which it did not;
3. the same lanes with a first phase before the augmented Lagrangian: Newton steps on
   the violation measure ``v = |r|^2 / 2`` (``r``: the equality's value and the violated
   part of the inequalities) with its exact Hessian ``J^T D J + sum_i r_i hess g_i``
   (the problem's own Lagrangian Hessian with weights ``r``, less the objective's),
   eigenvalues mirrored as the solver's direction has them, capped at ``max_step``,
   Armijo on ``v`` over the ladder ``1, 1/2, ... 2^-15``; it ends where the violation
   (inf-norm) is at most ``feasible`` (the lane then starts the augmented Lagrangian
   there, multipliers fresh), where ``|J^T r|_inf <= infeasible_stationarity * viol``
   with ``viol > infeasible_tol`` (the solver's infeasibility test: the lane ends
   infeasible), where no length lowers ``v``, or after ``K`` steps. Steps of both
   phases counted. Printed per ``(K, feasible)`` of ``--phase1``: how the first phase
   ended, lanes and mean steps by final status, lanes whose status changed.

    python experiments/solver_steps/first_solve.py [--count 1000] [--contacts 7] [--grasps 4]
        [--phase1 6:1e-3,10:1e-4,20:1e-8,30:1e-10]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark", "infeasible_lanes")  # the studies whose scripts this one imports

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxgrasp  # noqa: E402,F401  (64-bit mode)
from _lab import say  # noqa: E402
from jaxgrasp import solver as S  # noqa: E402
from jaxgrasp.solver import eigen_direction  # noqa: E402
from jaxgrasp.solver import LaneStatus  # noqa: E402
from jaxgrasp.tolerance import lane_problem  # noqa: E402

STATUS = ("converged", "infeasible", "not_converged")
PCT = (10, 25, 50, 75, 90, 99)
LADDER = 2.0 ** -np.arange(16)


def engine_lanes(count: int) -> None:
    """Part 1: the boundary lanes' steps by status in the engine's run of the mixed set."""
    import profile_batch
    from batch_benchmark import make_grasps

    profile_batch.profile(make_grasps(1000, 0)[:count], "mixed", repeats=1)
    lanes = profile_batch._SINK["lanes"]
    status = np.concatenate([s.ravel() for i, (s, _) in enumerate(lanes) if i % 2 == 1])
    steps = np.concatenate([n.ravel() for i, (_, n) in enumerate(lanes) if i % 2 == 1])
    say(f"boundary lanes of {count} grasps (engine, first wave), steps by status, percentiles {PCT}:")
    for code, name in enumerate(STATUS):
        s = steps[status == code]
        say(f"   {name:14s} lanes {s.size:6d} mean {s.mean():6.1f}  " + " ".join(f"{q:g}" for q in np.percentile(s, PCT)))


def run_al(step, st, theta, o):
    """Loop steps of every lane until none runs."""
    for _ in range(o.max_steps):
        st = step(st, theta)
        if not np.any((np.asarray(st.status) == LaneStatus.NOT_CONVERGED) & (np.asarray(st.steps) < o.max_steps)):
            break
    return st


def lane_steps(o):
    """One loop step of every lane (``jit(vmap(step))``), compiled once for the three parts."""
    return jax.jit(jax.vmap(lambda s, t: S.step(lane_problem(t), s, o)))


def first_inner(st0, theta, o, step) -> None:
    """Part 2: the first inner solve of every boundary lane, step by step (``step``:
    :func:`lane_steps`)."""

    def look(s, t):
        prob = lane_problem(t)
        d = S.first_order(prob, s.x)
        s = S.initial_multiplier(s, d)
        _, shifted, w = S.penalty_terms(d.gx, s.lam, s.nu, s.rho, s.eq_mask)
        trial = S.propose(prob, s, o)
        one = jax.tree_util.tree_map(lambda a: a[None], trial)
        x_new, _ = S.line_search(lambda x, _: S.merit(prob, trial.state, x), one, o)
        cap = jnp.max(jnp.abs(trial.p))
        frac = jnp.max(jnp.abs(x_new[0] - trial.state.x)) / jnp.maximum(cap, 1e-300)
        ev = jnp.linalg.eigvalsh(S.phi_hessian(prob, trial.state, d))
        quadratic = (s.eq_mask > 0) | (shifted > 0)
        return jnp.max(jnp.abs(d.grad_f + d.jac.T @ w)), quadratic, frac, cap, ev[0] < 0, trial.newton

    look = jax.jit(jax.vmap(look))
    boundary = np.asarray(st0.eq_mask).sum(1) > 0
    st, rec = st0, []
    for _ in range(40):
        info = [np.asarray(a) for a in look(st, theta)]
        new = step(st, theta)
        info.append(np.asarray(new.prev_viol) != np.asarray(st.prev_viol))  # a multiplier update this step
        rec.append(info)
        st = new
    final = run_al(step, st, theta, o)
    status = np.asarray(final.status)
    g, quad, frac, cap, neg, newton, upd = (np.stack([r[k] for r in rec]) for k in range(7))
    before = np.cumsum(upd, axis=0) == 0  # no update yet, up to and including this step
    first_update = np.argmax(upd, axis=0)
    for code, name in ((1, "infeasible"), (0, "converged")):
        lanes = boundary & (status == code)
        inner = before & newton.astype(bool) & lanes[None, :]
        say(f"{name} boundary lanes {lanes.sum()}: first update at step "
            + " ".join(f"{q:g}" for q in np.percentile(first_update[lanes], (10, 50, 90)))
            + f" (10/50/90 %); in the first inner solve: {inner.sum()} Newton steps, full length "
            f"{np.mean(frac[inner] > 0.999):.1%}, capped at max_step {np.mean(cap[inner] >= o.max_step * 0.9999):.1%}, "
            f"negative curvature {np.mean(neg[inner]):.1%}")
    # |grad phi| from one Newton step of the first inner solve to the next
    step_pair = before[:-1] & before[1:] & newton[:-1].astype(bool) & boundary[None, :]
    ratio = g[1:] / np.maximum(g[:-1], 1e-300)
    changed = np.any(quad[1:] != quad[:-1], axis=2)
    for label, sel in (("changed", step_pair & changed), ("unchanged", step_pair & ~changed)):
        say(f"   quadratic rows {label:9s}: {sel.sum()} steps, |grad phi| factor per step (25/50/75 %) "
            + " ".join(f"{q:.3f}" for q in np.percentile(ratio[sel], (25, 50, 75))))


def violation_first(st0, theta, o, step, k_max: int, feasible: float, base) -> None:
    """Part 3: a first phase of Newton steps on the violation, then the augmented Lagrangian
    (``step``: :func:`lane_steps`; ``base``: today's lanes, run to their end)."""

    def parts(prob, x, eq_mask):
        d = S.first_order(prob, x)
        is_eq = eq_mask > 0
        r = jnp.where(is_eq, d.gx, jnp.minimum(d.gx, 0.0))
        rows = (is_eq | (d.gx < 0)).astype(x.dtype)
        curvature = S.lagrangian_hessian(prob, d, x, r) - S.lagrangian_hessian(prob, d, x, jnp.zeros_like(r))
        hess = d.jac.T @ (rows[:, None] * d.jac) + curvature
        return 0.5 * jnp.sum(r * r), d.jac.T @ r, 0.5 * (hess + hess.T), jnp.max(jnp.abs(r))

    def newton_on_v(x, eq_mask, t):
        prob = lane_problem(t)
        v, gv, hv, viol = parts(prob, x, eq_mask)
        p = eigen_direction(hv, gv)
        p = p * jnp.minimum(1.0, o.max_step / jnp.maximum(jnp.max(jnp.abs(p)), 1e-300))
        ladder = jnp.asarray(LADDER)
        vs = jax.vmap(lambda a: parts(prob, x + a * p, eq_mask)[0])(ladder)
        ok = jnp.where(jnp.isfinite(vs), vs, jnp.inf) <= v + 1e-4 * ladder * (gv @ p)
        return jnp.where(jnp.any(ok), x + ladder[jnp.argmax(ok)] * p, x), jnp.any(ok), viol, jnp.max(jnp.abs(gv))

    newton_on_v = jax.jit(jax.vmap(newton_on_v))
    active = np.asarray(st0.status) == LaneStatus.NOT_CONVERGED
    boundary = active & (np.asarray(st0.eq_mask).sum(1) > 0)
    x, eq_mask = np.asarray(st0.x), st0.eq_mask
    steps = np.zeros(x.shape[0], int)
    ended = np.zeros(x.shape[0], int)  # 0 ran out of steps or lengths, 1 feasible, 2 infeasible
    running = boundary.copy()
    for _ in range(k_max + 1):
        x_new, improve, viol, slope = (np.asarray(a) for a in newton_on_v(jnp.asarray(x), eq_mask, theta))
        feas = running & (viol <= feasible)
        infeas = running & (viol > o.infeasible_tol) & (slope <= o.infeasible_stationarity * viol)
        ended[feas], ended[infeas] = 1, 2
        running &= ~(feas | infeas) & (steps < k_max)
        x = np.where(running[:, None], x_new, x)
        steps += running
        running &= improve
    certified = ended == 2
    st1 = jax.vmap(lambda x0, m, a: S.init(x0, m, jnp.nan, a, o))(jnp.asarray(x), eq_mask, jnp.asarray(active & ~certified))
    st1 = dataclasses.replace(st1, status=jnp.where(jnp.asarray(certified), LaneStatus.INFEASIBLE, st1.status)
                              .astype(jnp.int32))
    new = run_al(step, st1, theta, o)
    bs, ns = np.asarray(base.status), np.asarray(new.status)
    b_steps, n_steps = np.asarray(base.steps), np.asarray(new.steps) + steps
    say(f"first phase K={k_max}, feasible below {feasible:g}: ends feasible {np.sum(boundary & (ended == 1))}, "
        f"infeasible {np.sum(boundary & certified)}, neither {np.sum(boundary & (ended == 0))}; "
        f"its steps {steps[boundary].mean():.1f} per lane; lanes changing status {np.sum(boundary & (bs != ns))}")
    for code, name in ((0, "converged"), (1, "infeasible")):
        b, n = boundary & (bs == code), boundary & (ns == code)
        say(f"   {name:10s} today {b.sum():5d} lanes {b_steps[b].mean():5.1f} steps | with it {n.sum():5d} lanes "
            f"{n_steps[n].mean():5.1f} steps")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="grasps of the mixed set for part 1 (0: skip)")
    ap.add_argument("--contacts", type=int, default=7)
    ap.add_argument("--grasps", type=int, default=4)
    ap.add_argument("--phase1", default="6:1e-3,10:1e-4,20:1e-8,30:1e-10", help="K:feasible pairs for part 3")
    a = ap.parse_args()
    say(f"$ python experiments/solver_steps/first_solve.py --count {a.count} --contacts {a.contacts} --grasps {a.grasps} "
        f"--phase1 {a.phase1}")
    if a.count:
        engine_lanes(a.count)
    from infeasible_certificate import benchmark_lanes

    st0, theta, o = benchmark_lanes(a.contacts, a.grasps)
    step = lane_steps(o)
    first_inner(st0, theta, o, step)
    base = run_al(step, st0, theta, o)
    for pair in a.phase1.split(","):
        k, feasible = pair.split(":")
        violation_first(st0, theta, o, step, int(k), float(feasible), base)


if __name__ == "__main__":
    main()
