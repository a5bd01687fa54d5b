"""Inner minimiser of the augmented Lagrangian: jaxopt.LBFGS vs exact-Hessian Newton.

The issue asked for jaxopt as the inner solver unless something clearly better was
measured. This script solves the same boundary programs (cube grasps, the evaluator's own
starts and multiplier estimates) with the same PHR outer loop and two inner solvers:

* ``newton``: jaxgrasp.solver (exact 6x6 Hessian, mirrored eigenvalues, line search);
* ``lbfgs``: jaxopt.LBFGS on the same phi, warm-started, tol 1e-10, maxiter 200 per outer
  iteration, same multiplier/penalty updates.

It prints, for each: programs converged to the KKT tolerance (1e-10, scaled), wall time
(steady state, jit), and the largest energy difference on lanes where both converge.

    python experiments/solver_steps/inner_solver.py [--grasps 8]
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import jaxopt
import numpy as np

import jaxgrasp
from jaxgrasp import solver as S
from jaxgrasp import EvaluateOptions
from jaxgrasp.tolerance import constraints, objective, problem_data
from jaxgrasp.engine import solve_problems
from jaxgrasp.solver import LaneStatus
from jaxgrasp.model import model_params


def lbfgs_al(f, g, x0, eq_mask, nu0, o: S.SolverOptions, outer=40):
    """PHR augmented Lagrangian with jaxopt.LBFGS inner solves (one lane)."""

    def phi(x, lam, nu, rho):
        return S.augmented_lagrangian(f, g, x, lam, nu, rho, eq_mask)

    solver = jaxopt.LBFGS(fun=phi, maxiter=200, tol=o.tol)

    def body(carry, _):
        x, lam, nu, rho, prev, done = carry
        x_new = solver.run(x, lam=lam, nu=nu, rho=rho).params
        gx = g(x_new)
        is_eq = eq_mask > 0
        h = jnp.sum(eq_mask * gx)
        stat = jnp.max(jnp.abs(jax.grad(phi)(x_new, lam, nu, rho)))
        lam_new = jnp.where(is_eq, 0.0, jnp.maximum(0.0, lam - rho * gx))
        nu_new = nu + rho * h
        viol = jnp.maximum(jnp.abs(h), jnp.max(jnp.where(is_eq, 0.0, jnp.maximum(-gx, 0.0))))
        comp = jnp.max(jnp.where(is_eq, 0.0, jnp.abs(lam_new * gx)))
        conv = (stat <= o.tol) & (viol <= o.tol) & (comp <= o.tol)
        rho_new = jnp.where(viol > 0.25 * prev, jnp.minimum(rho * o.rho_growth, o.rho_max), rho)
        keep = lambda a, b: jnp.where(done, a, b)  # noqa: E731
        carry = (
            keep(x, x_new),
            keep(lam, lam_new),
            keep(nu, nu_new),
            keep(rho, rho_new),
            keep(prev, viol),
            done | conv,
        )
        return carry, None

    init = (x0, jnp.zeros_like(eq_mask), nu0, jnp.asarray(o.rho0), jnp.asarray(jnp.inf), jnp.asarray(False))
    (x, lam, nu, rho, viol, done), _ = jax.lax.scan(body, init, None, length=outer)
    return x, f(x), done


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grasps", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)

    opts = EvaluateOptions()
    sopt = opts.solver
    drs = np.linspace(1.5e-3, 4.0e-3, args.grasps)
    grasps = [jaxgrasp.presets.cube(2e5, dr) for dr in drs]
    batch = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *grasps)

    def lanes_for(grasp):
        p = model_params(grasp)
        data = problem_data(p)
        progs = solve_problems(grasp, opts)
        masks = jax.nn.one_hot(progs.constraint_index, 3 * p.c.shape[0])
        f = lambda z: objective(z, data)  # noqa: E731
        g = lambda z: constraints(z, data)  # noqa: E731
        # the evaluator's multiplier estimate at each start
        gf = jax.vmap(jax.grad(f))(progs.start)
        gh = jax.vmap(lambda z, k: jax.grad(lambda y: g(y)[k])(z))(progs.start, progs.constraint_index)
        nu0 = -jnp.sum(gf * gh, -1) / jnp.maximum(jnp.sum(gh * gh, -1), 1e-300)
        return f, g, progs, masks, nu0

    def run_newton(grasp):
        f, g, progs, masks, nu0 = lanes_for(grasp)
        r = jax.vmap(lambda z0, m, nu: S.solve(f, g, z0, m, nu, sopt))(progs.start, masks, nu0)
        return r.objective, r.status == LaneStatus.CONVERGED, progs.found

    def run_lbfgs(grasp):
        f, g, progs, masks, nu0 = lanes_for(grasp)
        x, obj, done = jax.vmap(lambda z0, m, nu: lbfgs_al(f, g, z0, m, nu, sopt))(progs.start, masks, nu0)
        return obj, done, progs.found

    out = {}
    for name, fn in (("newton", run_newton), ("lbfgs", run_lbfgs)):
        jf = jax.jit(jax.vmap(fn))
        t0 = time.perf_counter()
        res = jax.block_until_ready(jf(batch))
        first = time.perf_counter() - t0
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            res = jax.block_until_ready(jf(batch))
            times.append(time.perf_counter() - t0)
        obj, conv, found = (np.asarray(a) for a in res)
        out[name] = {
            "obj": obj,
            "conv": conv & found,
            "found": found,
            "first_call_s": first,
            "steady_s": float(np.median(times)),
        }
    found = out["newton"]["found"]
    both = out["newton"]["conv"] & out["lbfgs"]["conv"]
    diff = np.abs(out["newton"]["obj"] - out["lbfgs"]["obj"]) / np.abs(out["newton"]["obj"])
    same = both & (diff < 1e-6)
    summary = {
        "programs": int(found.sum()),
        "load_average": list(np.round(np.array(__import__("os").getloadavg()), 2)),
    }
    for name in ("newton", "lbfgs"):
        summary[name] = {
            "converged": int(out[name]["conv"].sum()),
            "first_call_s": round(out[name]["first_call_s"], 2),
            "steady_s": round(out[name]["steady_s"], 3),
        }
    summary["both_converged"] = int(both.sum())
    summary["same_point"] = int(same.sum())
    summary["max_rel_energy_diff_same_point"] = float(diff[same].max()) if same.any() else None
    print(json.dumps(summary, indent=2))
    print(
        f"newton: {summary['newton']['converged']}/{summary['programs']} converged, "
        f"{summary['newton']['steady_s']:.3f} s; lbfgs: {summary['lbfgs']['converged']}/"
        f"{summary['programs']} converged, {summary['lbfgs']['steady_s']:.3f} s"
    )


if __name__ == "__main__":
    main()
