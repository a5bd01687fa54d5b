"""Profile the batched solver on a fixed batch of cube grasps (float64, CPU).

Times ``jax.jit(jax.vmap(lambda g: solve_problems(g, opts)))`` in the steady state on a
fixed batch (cube grasps over E and dr), reports the step counts of the solver, and the
cost per lane of the pieces of one loop step (phi value, gradient, Hessian, eigh, line
search), measured on a batch of lanes.

    python experiments/solver_steps/profile_solver.py [--grasps-E 3 --grasps-dr 9] [--save ref.npz]
                                         [--compare ref.npz] [--parts] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxgrasp  # noqa: E402
from jaxgrasp import solver as S  # noqa: E402
from jaxgrasp import EvaluateOptions
from jaxgrasp.solver import ldl_direction  # noqa: E402
from jaxgrasp.tolerance import objective_and_constraints, problem_data
from jaxgrasp.engine import solve_problems  # noqa: E402
from jaxgrasp.model import model_params  # noqa: E402
from jaxgrasp.presets import cube, prism  # noqa: E402


def batch(scene: str, ne: int, ndr: int):
    E = np.linspace(2e5, 1e6, ne)
    dr = np.linspace(1e-3, 5e-3, ndr)
    if scene == "cube":
        gs = [cube(float(e), float(d)) for e in E for d in dr]
    else:
        gs = [prism(float(e), float(d), m) for e in E for d in dr for m in (0.0, 0.2)]
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *gs)


def timed(fn, *args, repeats=3):
    walls, cpus = [], []
    out = None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = jax.block_until_ready(fn(*args))
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return out, walls, cpus


def leaves(progs):
    """The compared values: every SolverResult field + starts, as a flat dict."""
    out = {}
    for name in ("equilibrium", "boundary"):
        r = getattr(progs, name)
        for f in ("x", "lam", "nu", "objective", "status", "steps"):
            out[f"{name}.{f}"] = np.asarray(getattr(r, f))
    out["found"] = np.asarray(progs.found)
    return out


def compare(cur: dict, ref: dict):
    found = ref["found"]
    st_c, st_r = cur["boundary.status"], ref["boundary.status"]
    same_status = np.mean((st_c == st_r)[found])
    conv = found & (st_c == 0) & (st_r == 0)
    print(f"  boundary lane status agrees on {same_status * 100:.2f}% of found lanes; "
          f"eq status agrees: {np.all(cur['equilibrium.status'] == ref['equilibrium.status'])}")
    def rel(a, b):
        return np.abs(a - b) / np.maximum(np.abs(b), 1e-300)
    ob = rel(cur["boundary.objective"][conv], ref["boundary.objective"][conv])
    eqc = (cur["equilibrium.status"] == 0) & (ref["equilibrium.status"] == 0)
    oe = rel(cur["equilibrium.objective"][eqc], ref["equilibrium.objective"][eqc])
    xd = np.max(np.abs(cur["boundary.x"][conv] - ref["boundary.x"][conv]), axis=-1)
    print(f"  objective rel diff: boundary max {ob.max() if ob.size else 0:.2e} "
          f"(lanes > 1e-8: {int((ob > 1e-8).sum())} of {ob.size}), equilibrium max {oe.max() if oe.size else 0:.2e}")
    print(f"  boundary x inf-diff: max {xd.max() if xd.size else 0:.2e}, lanes > 1e-4: {int((xd > 1e-4).sum())}")
    # what a value sees: min converged energy per boundary problem
    def minimum(d):
        e = np.where(d["found"] & (d["boundary.status"] == 0), d["boundary.objective"], np.inf)
        b, L = e.shape
        return e.reshape(b, -1, 20).min(-1)
    mc, mr = minimum(cur), minimum(ref)
    both = np.isfinite(mc) & np.isfinite(mr)
    print(f"  per-problem min energy rel diff: max {rel(mc[both], mr[both]).max():.2e}; "
          f"reachability agrees: {np.all(np.isfinite(mc) == np.isfinite(mr))}")
    return float(ob.max() if ob.size else 0.0)


def parts(scene, ne, ndr, lanes=4096, repeats=5):
    """Cost per lane of the pieces of a Newton step on phi, at the boundary starts."""
    opts = EvaluateOptions()
    g0 = jax.tree_util.tree_map(lambda a: a[0], batch(scene, ne, ndr))
    progs = solve_problems(g0, opts)
    p = model_params(g0)
    data = problem_data(p)
    L = progs.start.shape[0]
    reps = -(-lanes // L)
    z = jnp.tile(progs.start, (reps, 1))[:lanes]
    masks = jnp.tile(jax.nn.one_hot(progs.constraint_index, 3 * p.c.shape[0]), (reps, 1))[:lanes]
    lam = jnp.full(masks.shape, 0.1)
    fg = lambda z: objective_and_constraints(z, data)

    def phi(x, m):
        return S.augmented_lagrangian(fg, x, lam[0], 0.3, 100.0, m)

    fns = {
        "f + g (value of phi)": jax.jit(jax.vmap(phi)),
        "grad phi": jax.jit(jax.vmap(jax.grad(phi))),
        "hessian phi (jax.hessian)": jax.jit(jax.vmap(jax.hessian(phi))),
        "eigh 6x6": jax.jit(jax.vmap(lambda x, m: jnp.linalg.eigh(jnp.outer(x, x) + jnp.eye(6))[0])),
        "cholesky 6x6": jax.jit(jax.vmap(lambda x, m: jnp.linalg.cholesky(jnp.outer(x, x) + jnp.eye(6)))),
        "LDL^T direction 6x6 (direction.py)": jax.jit(jax.vmap(lambda x, m: ldl_direction(jnp.outer(x, x) + jnp.eye(6), x)[0])),
        "16 phi values (line search)": jax.jit(jax.vmap(lambda x, m: jax.vmap(lambda a: phi(x + a, m))(
            0.5 ** jnp.arange(16.0)))),
    }
    print(f"per-lane cost on {lanes} lanes ({scene}), microseconds:")
    for name, fn in fns.items():
        _, w, _ = timed(fn, z, masks, repeats=repeats)
        print(f"  {name:32s} {1e6 * min(w) / lanes:8.3f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="cube")
    ap.add_argument("--grasps-E", type=int, default=3)
    ap.add_argument("--grasps-dr", type=int, default=9)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--save", type=Path)
    ap.add_argument("--compare", type=Path)
    ap.add_argument("--parts", action="store_true")
    ap.add_argument("--no-solve", action="store_true")
    ap.add_argument("--slot-fraction", type=float, default=None)
    ap.add_argument("--max-steps", type=int, default=None)
    ap.add_argument("--max-slots", type=int, default=None)
    ap.add_argument("--solver-opt", action="append", default=[], help="SolverOptions field=value (float)")
    args = ap.parse_args()
    print(f"jaxgrasp from {jaxgrasp.__file__}; load {os.getloadavg()}")
    if args.parts:
        parts(args.scene, args.grasps_E, args.grasps_dr)
    if args.no_solve:
        return
    opts = EvaluateOptions()
    import dataclasses

    if args.slot_fraction is not None:
        opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, slot_fraction=args.slot_fraction))
    if args.max_slots is not None:
        opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, max_slots=args.max_slots))
    for kv in args.solver_opt:
        k, v = kv.split("=")
        typ = type(getattr(opts.solver, k))
        opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, **{k: typ(float(v))}))
    if args.max_steps is not None:
        import dataclasses
        opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, max_steps=args.max_steps))
    b = batch(args.scene, args.grasps_E, args.grasps_dr)
    fn = jax.vmap(lambda g: solve_problems(g, opts))
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(b).compile()
    t_compile = time.perf_counter() - t0
    progs, walls, cpus = timed(compiled, b, repeats=args.repeats + 1)
    walls, cpus = walls[1:], cpus[1:]
    found = np.asarray(progs.found)
    bsteps = np.asarray(progs.boundary.steps)
    esteps = np.asarray(progs.equilibrium.steps)
    n_prog = found.shape[0] + int(found.sum())
    print(f"{args.scene} {found.shape[0]} grasps, {n_prog} programs ({int(found.sum())} active lanes of {found.size}); "
          f"compile {t_compile:.1f} s")
    print(f"steady wall {np.median(walls):.3f} s (all {[round(w, 3) for w in walls]}), "
          f"cpu {np.median(cpus):.3f} s; load {os.getloadavg()}")
    print(f"  per program: {1e3 * np.median(walls) / n_prog:.3f} ms wall")
    print(f"steps: equilibrium sum {esteps.sum()} max {esteps.max()}; boundary (active) sum {bsteps[found].sum()} "
          f"mean {bsteps[found].mean():.1f} median {np.median(bsteps[found]):.0f} max {bsteps[found].max()}")
    print(f"  lane status counts: {np.bincount(np.where(found, np.asarray(progs.boundary.status), 3).ravel(), minlength=4)}")
    cur = leaves(progs)
    if args.save:
        np.savez(args.save, **cur)
        print(f"saved {args.save}")
    if args.compare:
        ref = dict(np.load(args.compare))
        print(f"compare with {args.compare}:")
        compare(cur, ref)
        print(f"  steps: ref sum {ref['boundary.steps'][ref['found']].sum()} -> {bsteps[found].sum()}")


if __name__ == "__main__":
    main()
