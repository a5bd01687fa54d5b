"""Benchmark: jaxgrasp's batched solver vs CasADi + Ipopt on the same programs (issue #5).

For every grasp of a grid, jaxgrasp solves ``1 + 2N*D`` programs (:func:`jaxgrasp.evaluate.
solve_problems`): the equilibrium from the initial state and, for each boundary (slip or
force limit of each contact) and each of ``D`` start directions, one boundary program from
a start found by a ray search + bisection. Only the lanes whose start search succeeded
(``Problems.found``) are solved. This script solves *the same programs from the same
starting points* with CasADi + Ipopt (exact Hessians, MUMPS, the NLP of
``tests/ipopt_reference.py``: same model, same constraint and objective scaling) and
compares speed and results.

Scenes:

* ``cube``: the paper's grid, E = 2e5..1e6 Pa (9) x dr = 1..5 mm (41), m = 0 -> 369 grasps;
* ``prism``: E = 2e5..1e6 Pa (5) x dr = 1..5 mm (9) x m in {0, 0.1, 0.2} kg -> 135 grasps.

jaxgrasp: ``run_inline(grasps, stage_functions(opts, settle=False), until="problems")`` (what ``solve_problems`` solves
for one grasp) batched as ``evaluate_batch`` and ``sweep`` batch it
(:func:`jaxgrasp.engine.over_devices`: ``jit(shard_map(...))``,
the batch split over every JAX device, one work queue per device; ``import jaxgrasp``
creates one CPU device per core, see the [GPU and clusters](../../docs/guide/gpu.md) guide; ``JAXGRASP_CPU_DEVICES=1``
measures one) on the stacked batch, padded to a multiple of the device count by
repeating its last grasp (the padding's programs are not counted). This is the program that
``evaluate`` and ``evaluate_batch`` run first (the settling stage runs only on grasps with
an unsettled boundary problem; their count is recorded and is 0 on both grids);
compile (ahead of time, ``lower().compile()``) and first run timed, then the steady state is
the median of ``--repeats`` (>= 3) calls with ``block_until_ready``. Problems solved =
equilibrium programs + active boundary lanes; programs/s = programs / steady wall time.

Ipopt: serially, for each grasp of a seeded sample spread over the grid (``--ipopt-sample
K``, default 40 per scene; 0 = every grasp), the equilibrium from x = 0 and every active
boundary lane from jaxgrasp's start ``z`` converted to ``x = (z[:3] mm, z[3:] / lever rad)``
(Ipopt's variables are ``(dp [mm], w [rad])``). Only the solver calls are timed; the NLP
construction (symbolic model + ``nlpsol``) is per-grasp setup, reported separately.
Ipopt programs/s = sampled programs / their total solver time.

Fairness: the jaxgrasp steady-state calls and the Ipopt solves are interleaved (jaxgrasp
call, Ipopt chunk, jaxgrasp call, ...), so both see the same machine load; the load average
(``os.getloadavg()``) is recorded at every step. Wall and process-CPU times are both
recorded (jaxgrasp's XLA runtime may use every core, Ipopt runs on one).

Agreement (on the Ipopt sample):

* per program: both converged to the same point (``|z_jax - z_ipopt|_inf <= --same-tol``
  mm in jaxgrasp's scaled variables) -> relative difference of the minimum energies; both
  converged to different points -> a different local minimum from the same start (counted,
  with which solver found the lower energy); convergence disagreements counted;
* per grasp: ``jaxgrasp.evaluate(g).value`` vs the Ipopt value computed from Ipopt's own
  solves of the same programs (minimum over converged boundary lanes minus its
  equilibrium energy; unstable where an equilibrium slip/force margin is <= 1e-8, as in
  jaxgrasp), as a relative difference, where both call the grasp stable.

Also recorded: the first-call compile time of the engine's ``evaluate_batch_traced(.., settle=False)``, batched the same way, on
the cube's sweep grid (369 grasps).

    python experiments/ipopt_benchmark/benchmark.py [--quick] [--ipopt-sample K] [--repeats R] [--json PATH]

Writes ``experiments/ipopt_benchmark/benchmark_results.json`` (``--quick``: ``experiments/ipopt_benchmark/quick/
benchmark_results.json``) and prints the result as markdown tables.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import casadi as ca  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxgrasp  # noqa: E402  (first: float64, and one JAX CPU device per core)
from jaxgrasp.tolerance import GraspStatus  # noqa: E402
from jaxgrasp.solver import LaneStatus  # noqa: E402
from jaxgrasp import EvaluateOptions
from jaxgrasp.engine import batch_sharding, evaluate_batch_traced, over_devices, run_inline, stage_functions  # noqa: E402
from jaxgrasp.tolerance import needs_settling
from jaxgrasp.presets import cube, prism  # noqa: E402
from _lab.ipopt_reference import FEAS_TOL, _Model  # noqa: E402

HERE = Path(__file__).resolve().parent
BOUNDARY_TOL = EvaluateOptions().boundary_tol  # same 'unstable' test as jaxgrasp
IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')} load {load()[0]:.2f}] {msg}", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- grids


def cube_grid(quick: bool):
    E = np.linspace(2e5, 1e6, 3 if quick else 9)
    dr = np.linspace(1e-3, 5e-3, 4 if quick else 41)
    params = [(float(e), float(d), 0.0) for e in E for d in dr]
    return params, [cube(e, d, m) for e, d, m in params]


def prism_grid(quick: bool):
    E = np.linspace(2e5, 1e6, 2 if quick else 5)
    dr = np.linspace(1e-3, 5e-3, 3 if quick else 9)
    masses = (0.0, 0.2) if quick else (0.0, 0.1, 0.2)
    params = [(float(e), float(d), float(m)) for e in E for d in dr for m in masses]
    return params, [prism(e, d, m) for e, d, m in params]


def stack(grasps):
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *grasps)


def spread_sample(n: int, k: int, seed: int) -> np.ndarray:
    """``k`` of ``range(n)`` spread over the grid: one seeded random index per equal bin."""
    if k <= 0 or k >= n:
        return np.arange(n)
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, n, k + 1)
    out = [int(rng.integers(int(np.ceil(lo)), max(int(np.ceil(hi)), int(np.ceil(lo)) + 1))) for lo, hi in zip(edges[:-1], edges[1:])]
    return np.unique(np.minimum(out, n - 1))


# --------------------------------------------------------------------------- jaxgrasp


def timed_call(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - t0, time.process_time() - c0


def compile_aot(fn, batch):
    """``fn`` of a batch of grasps, run as jaxgrasp's engine runs it
    (:func:`jaxgrasp.engine.over_devices`: the batch split over every device, each running
    its own work queue), compiled ahead of time for ``batch``, which is padded by
    repeating its last grasp to a multiple of the device count and placed on the devices
    once, as the engine places a chunk before it runs it. Returns ``(call, seconds)``:
    ``call()`` runs it on that batch (results padded: see :func:`to_numpy`)."""
    sharding = batch_sharding()
    pad = -len(jax.tree_util.tree_leaves(batch)[0]) % len(sharding.device_set)
    padded = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]), batch)
    padded = jax.device_put(padded, sharding)
    t0 = time.perf_counter()
    compiled = over_devices(fn, sharding).lower(padded).compile()
    return (lambda: compiled(padded)), time.perf_counter() - t0


def to_numpy(tree, size: int):
    """The first ``size`` rows (the batch's own grasps, not the padding) as NumPy."""
    return jax.tree_util.tree_map(lambda a: np.asarray(a)[:size], tree)


# --------------------------------------------------------------------------- Ipopt


def ipopt_setup(grasp):
    """Build the CasADi model and Ipopt solver of one grasp (the reference's NLP:
    variables x = (dp [mm], w [rad]), objective U / (initial-state energy), constraints
    in the same order and scaling as jaxgrasp's flattened (3N,) margins). Timed apart."""
    t0 = time.perf_counter()
    model = _Model(grasp)
    model.solver  # noqa: B018 -- builds nlpsol
    return model, time.perf_counter() - t0


def ipopt_solve(model, x0, k: int | None):
    """Solve one program from ``x0 = (dp [mm], w [rad])``: the equilibrium (``k`` None) or
    the boundary program with the flattened constraint ``k`` as an equality. Only the
    solver call is timed. Converged = Ipopt succeeded and the point passes the
    reference's verification (violation <= 1e-9 scaled, cos(phi) > 0, finite, and a
    principal rotation vector ``|w| < pi``, as ``tests/ipopt_reference.py`` requires)."""
    n3 = 3 * model.n
    lbg = np.zeros(n3)
    ubg = np.full(n3, np.inf)
    if k is not None:
        ubg[k] = 0.0
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        sol = model.solver(x0=np.asarray(x0, dtype=np.float64), lbg=lbg, ubg=ubg)
        err = None
    except RuntimeError as e:  # pragma: no cover
        sol, err = None, str(e)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    stats = model.solver.stats()
    status = stats.get("return_status", err or "error")
    out = {"seconds": seconds, "cpu_seconds": cpu, "status": status, "iters": int(stats.get("iter_count", -1)),
           "converged": False, "x": None, "U": np.nan}
    if sol is None:
        return out
    x = np.asarray(sol["x"]).ravel()
    out["x"] = x
    if status in IPOPT_OK and np.all(np.isfinite(x)):
        U, g, _, cphi = model.evaluate(x)
        viol = float(np.max(np.maximum(np.maximum(lbg - g, g - ubg), 0.0)))
        # theta_i = w . n_i is the twist only for the principal rotation vector: beyond
        # |w| = pi the torsion is an artefact (a full turn read as a twist, which made the
        # batch benchmark's quick set's grasp 54 read 43 % below its value)
        principal = np.linalg.norm(x[3:]) < np.pi
        if np.isfinite(U) and viol <= FEAS_TOL and np.all(cphi > 0.0) and principal:
            out["converged"] = True
            out["U"] = U  # mJ
            out["g"] = g
    return out


def ipopt_grasp(model, progs, i: int, n: int):
    """Every program of grasp ``i`` of the batch ``progs`` (numpy Problems), serially."""
    lever = float(progs.lever[i])
    eq = ipopt_solve(model, np.zeros(6), None)
    lanes = []
    for lane in np.flatnonzero(progs.found[i]):
        z0 = progs.start[i, lane]
        x0 = np.concatenate([z0[:3], z0[3:] / lever])
        res = ipopt_solve(model, x0, int(progs.constraint_index[i, lane]))
        res["lane"] = int(lane)
        lanes.append(res)
    return {"eq": eq, "lanes": lanes}


def ipopt_value(rec, n: int):
    """Ipopt's grasp status and value (J) from its own solves."""
    eq = rec["eq"]
    if not eq["converged"]:
        return ("infeasible" if "Infeasible" in eq["status"] else "not_converged"), 0.0
    if np.min(eq["g"][n:]) <= BOUNDARY_TOL:
        return "unstable", 0.0
    ub = [r["U"] for r in rec["lanes"] if r["converged"]]
    if not ub:
        return "not_converged", 0.0
    return "stable", max(min(ub) - eq["U"], 0.0) * 1e-3


# --------------------------------------------------------------------------- comparison


def rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


def compare(params, progs, evals, sample, ipopt_recs, same_tol, energy_tol):
    """Program-level and grasp-level agreement on the Ipopt sample."""
    n = n_contacts(progs)
    counts = {"programs": 0, "both_converged": 0, "same_point": 0, "different_minimum": 0,
              "different_point_equal_energy": 0,
              "different_minimum_jax_lower": 0, "different_minimum_ipopt_lower": 0,
              "jax_only_converged": 0, "jax_only_converged_above_problem_min": 0, "ipopt_only_converged": 0, "neither_converged": 0,
              "neither_jax_infeasible": 0}
    ipopt_status = {}
    same_energy_rel, same_dist, diff_cases = [], [], []
    worst_same = []
    vals = {"grasps": 0, "status_agree": 0, "both_stable": 0}
    value_rel, value_cases, status_mismatch = [], [], []
    for i, rec in zip(sample, ipopt_recs):
        lever = float(progs.lever[i])
        scale = float(progs.scale[i])
        # lowest converged jaxgrasp energy of each boundary problem (constraint index)
        conv_i = progs.found[i] & (progs.boundary.status[i] == LaneStatus.CONVERGED)
        prob_min = {}
        for lane in np.flatnonzero(conv_i):
            k = int(progs.constraint_index[i, lane])
            prob_min[k] = min(prob_min.get(k, np.inf), float(progs.boundary.objective[i, lane]) * scale)
        pairs = [(progs.equilibrium, None, rec["eq"])] + [(progs.boundary, r["lane"], r) for r in rec["lanes"]]
        for res, lane, ip in pairs:
            idx = (i,) if lane is None else (i, lane)
            j_conv = int(res.status[idx]) == LaneStatus.CONVERGED
            j_U = float(res.objective[idx]) * scale
            j_z = np.asarray(res.x[idx])
            counts["programs"] += 1
            ipopt_status[ip["status"]] = ipopt_status.get(ip["status"], 0) + 1
            if j_conv and ip["converged"]:
                counts["both_converged"] += 1
                x = ip["x"]
                z = np.concatenate([x[:3], lever * x[3:]])
                dist = float(np.max(np.abs(z - j_z)))
                r_e = rel(j_U, ip["U"])
                if dist <= same_tol:
                    counts["same_point"] += 1
                    same_energy_rel.append(r_e)
                    same_dist.append(dist)
                    worst_same.append((r_e, dist, i, lane))
                elif r_e <= energy_tol:  # e.g. mirror-symmetric minima of the cube
                    counts["different_point_equal_energy"] += 1
                else:
                    counts["different_minimum"] += 1
                    lower = "jax" if j_U < ip["U"] else "ipopt"
                    counts[f"different_minimum_{lower}_lower"] += 1
                    diff_cases.append({"grasp": params[i], "lane": lane, "z_distance_mm": dist,
                                       "U_jax_mJ": j_U, "U_ipopt_mJ": ip["U"], "rel_energy_diff": r_e})
            elif j_conv:
                counts["jax_only_converged"] += 1
                if lane is not None and rel(j_U, prob_min[int(progs.constraint_index[i, lane])]) > energy_tol:
                    counts["jax_only_converged_above_problem_min"] += 1
            elif ip["converged"]:
                counts["ipopt_only_converged"] += 1
            else:
                counts["neither_converged"] += 1
                if int(res.status[idx]) == LaneStatus.INFEASIBLE:
                    counts["neither_jax_infeasible"] += 1
        # grasp value
        st_i, v_i = ipopt_value(rec, n)
        st_j = GraspStatus.labels()[int(evals.status[i])]
        v_j = float(evals.value[i])
        vals["grasps"] += 1
        if st_i == st_j:
            vals["status_agree"] += 1
        else:
            status_mismatch.append({"grasp": params[i], "jaxgrasp": st_j, "ipopt": st_i,
                                    "value_jax_J": v_j, "value_ipopt_J": v_i})
        if st_i == "stable" and st_j == "stable":
            vals["both_stable"] += 1
            r_v = rel(v_j, v_i)
            value_rel.append(r_v)
            value_cases.append({"grasp": params[i], "value_jax_J": v_j, "value_ipopt_J": v_i, "rel_diff": r_v})
    worst_same.sort(reverse=True)
    value_cases.sort(key=lambda c: -c["rel_diff"])
    diff_cases.sort(key=lambda c: -c["rel_energy_diff"])

    def q(a, p):
        return float(np.quantile(a, p)) if len(a) else None

    return {
        "same_point_tol_mm": same_tol,
        "equal_energy_rel_tol": energy_tol,
        "program_counts": counts,
        "ipopt_return_status": ipopt_status,
        "same_point_energy_rel_diff": {"max": q(same_energy_rel, 1.0), "median": q(same_energy_rel, 0.5),
                                       "p99": q(same_energy_rel, 0.99)},
        "same_point_z_distance_mm": {"max": q(same_dist, 1.0), "median": q(same_dist, 0.5)},
        "same_point_worst": [{"grasp": params[i], "lane": lane, "rel_energy_diff": r, "z_distance_mm": d}
                             for r, d, i, lane in worst_same[:5]],
        "different_minimum_fraction_of_both_converged": (counts["different_minimum"] / counts["both_converged"]
                                                         if counts["both_converged"] else None),
        "different_minimum_max_rel_energy_diff": q([c["rel_energy_diff"] for c in diff_cases], 1.0),
        "different_minimum_cases": diff_cases[:10],
        "value": {**vals, "max_rel_diff": q(value_rel, 1.0), "median_rel_diff": q(value_rel, 0.5),
                  "worst": value_cases[:5], "status_mismatches": status_mismatch[:10],
                  "num_status_mismatches": len(status_mismatch)},
    }


def n_contacts(progs) -> int:
    return int(progs.equilibrium.lam.shape[-1]) // 3


# --------------------------------------------------------------------------- one scene


def run_scene(name, params, grasps, opts, args):
    log(f"{name}: {len(grasps)} grasps")
    batch = stack(grasps)
    n = grasps[0].num_contacts
    out = {"scene": name, "grasps": len(grasps), "contacts": n,
           "lanes_per_grasp": 2 * n * opts.directions().shape[0]}

    # --- jaxgrasp solve_problems: compile + first run. The program without the settling
    # stage: what evaluate and evaluate_batch run first; the settling program runs only on
    # grasps with an unsettled boundary problem (counted below: none on these grids).
    fn = lambda gs: run_inline(gs, stage_functions(opts, settle=False), until="problems")  # noqa: E731
    la = load()
    compiled, t_compile = compile_aot(fn, batch)
    progs, t_first, _ = timed_call(compiled)
    progs = to_numpy(progs, len(grasps))
    num_active = int(progs.found.sum())
    programs = len(grasps) + num_active
    out["jaxgrasp"] = {"programs": programs, "equilibrium_programs": len(grasps), "active_boundary_lanes": num_active,
                       "compile_s": t_compile, "first_run_s": t_first, "first_call_s": t_compile + t_first,
                       "load_at_compile": la,
                       "equilibrium_converged": int((progs.equilibrium.status == LaneStatus.CONVERGED).sum()),
                       "boundary_lane_status": {LaneStatus.labels()[s]: int(c) for s, c in
                                                enumerate(np.bincount(np.where(progs.found, progs.boundary.status, LaneStatus.NO_START).ravel(), minlength=4))}}
    log(f"{name}: jaxgrasp compile {t_compile:.1f} s, first run {t_first:.2f} s, {programs} programs")

    # --- jaxgrasp.evaluate batch (values for the comparison; compile time recorded)
    efn = lambda gs: evaluate_batch_traced(gs, opts, settle=False)  # noqa: E731
    ecompiled, te_compile = compile_aot(efn, batch)
    evals, te_first, _ = timed_call(ecompiled)
    evals = to_numpy(evals, len(grasps))
    # the grasps evaluate and evaluate_batch would run again with the settling stage
    out["jaxgrasp"]["grasps_needing_settling"] = int(np.sum(needs_settling(evals.boundary_status)))
    log(f"{name}: {out['jaxgrasp']['grasps_needing_settling']} grasps needing the settling stage")
    _, te_second, _ = timed_call(ecompiled)
    out["evaluate"] = {"compile_s": te_compile, "first_run_s": te_first, "first_call_s": te_compile + te_first,
                       "second_call_s": te_second,
                       "status_counts": {GraspStatus.labels()[s]: int(c) for s, c in enumerate(np.bincount(evals.status, minlength=4))}}
    log(f"{name}: evaluate compile {te_compile:.1f} s, first run {te_first:.2f} s")

    # --- Ipopt setup (per-grasp NLP construction, not in the solver time)
    sample = spread_sample(len(grasps), args.ipopt_sample, args.seed)
    models, setup = [], []
    for i in sample:
        m, s = ipopt_setup(grasps[i])
        models.append(m)
        setup.append(s)

    # --- interleaved: jaxgrasp steady call, Ipopt chunk, jaxgrasp steady call, ...
    repeats = max(3, args.repeats)
    chunks = np.array_split(np.arange(len(sample)), repeats)
    j_wall, j_cpu, i_wall, i_cpu, loads = [], [], [], [], []
    recs = [None] * len(sample)
    for r in range(repeats):
        loads.append(load())
        res, w, c = timed_call(compiled)
        j_wall.append(w)
        j_cpu.append(c)
        if r == 0:
            same = all(np.array_equal(np.asarray(a), b, equal_nan=True) for a, b in
                       zip(jax.tree_util.tree_leaves(to_numpy(res, len(grasps))), jax.tree_util.tree_leaves(progs)))
        t0, c0 = time.perf_counter(), time.process_time()
        for s in chunks[r]:
            recs[s] = ipopt_grasp(models[s], progs, int(sample[s]), n)
        i_wall.append(time.perf_counter() - t0)
        i_cpu.append(time.process_time() - c0)
        log(f"{name}: round {r + 1}/{repeats}: jaxgrasp {w:.2f} s, Ipopt chunk of {len(chunks[r])} grasps {i_wall[-1]:.1f} s")
    loads.append(load())

    solves = [rec["eq"] for rec in recs] + [lr for rec in recs for lr in rec["lanes"]]
    ip_programs = len(solves)
    ip_solver_s = float(sum(s["seconds"] for s in solves))
    ip_solver_cpu = float(sum(s["cpu_seconds"] for s in solves))
    ok = [s for s in solves if s["converged"]]
    bad = [s for s in solves if not s["converged"]]
    ip_conv = int(sum(s["converged"] for s in solves))
    iters = [s["iters"] for s in solves]
    steady = statistics.median(j_wall)
    j_rate = programs / steady
    i_rate = ip_programs / ip_solver_s
    # the same jaxgrasp programs, restricted to the sample, for reference
    j_sample_programs = len(sample) + int(progs.found[sample].sum())
    out["jaxgrasp"].update({"steady_wall_s": j_wall, "steady_cpu_s": j_cpu, "steady_median_wall_s": steady,
                            "steady_median_cpu_s": statistics.median(j_cpu), "programs_per_s": j_rate,
                            "programs_per_cpu_s": programs / statistics.median(j_cpu),
                            "deterministic": bool(same),
                            "converged_programs": int((progs.equilibrium.status == LaneStatus.CONVERGED).sum()
                                                      + ((progs.boundary.status == LaneStatus.CONVERGED) & progs.found).sum())})
    out["ipopt"] = {"sample_grasps": len(sample), "sample_indices": sample.tolist(),
                    "sampled": len(sample) < len(grasps),
                    "programs": ip_programs, "converged_programs": ip_conv,
                    "solver_s": ip_solver_s, "wall_s_incl_bookkeeping": float(sum(i_wall)),
                    "cpu_s_incl_bookkeeping": float(sum(i_cpu)),
                    "solver_cpu_s": ip_solver_cpu, "programs_per_cpu_s": ip_programs / ip_solver_cpu,
                    "programs_per_s": i_rate, "median_solve_ms": 1e3 * statistics.median(s["seconds"] for s in solves),
                    "median_solve_cpu_ms": 1e3 * statistics.median(s["cpu_seconds"] for s in solves),
                    "median_converged_solve_ms": 1e3 * statistics.median(s["seconds"] for s in ok) if ok else None,
                    "failed_solves": len(bad), "failed_solver_s": float(sum(s["seconds"] for s in bad)),
                    "max_iter_solves": int(sum(s["status"] == "Maximum_Iterations_Exceeded" for s in solves)),
                    "iterations": {"median": float(np.median(iters)), "max": int(np.max(iters))},
                    "setup_s_total": float(sum(setup)), "setup_s_per_grasp": float(np.mean(setup)),
                    "extrapolated_solver_s_all_grasps": programs / i_rate,
                    "jaxgrasp_programs_same_sample": j_sample_programs}
    out["ratio_programs_per_s_jax_over_ipopt"] = j_rate / i_rate
    j_conv_rate = out["jaxgrasp"]["converged_programs"] / steady
    i_conv_rate = ip_conv / ip_solver_s
    out["converged_programs_per_s"] = {"jaxgrasp": j_conv_rate, "ipopt": i_conv_rate, "ratio": j_conv_rate / i_conv_rate}
    out["ratio_programs_per_cpu_s_jax_over_ipopt"] = (programs / statistics.median(j_cpu)) / (ip_programs / ip_solver_cpu)
    out["load_per_round"] = loads
    out["agreement"] = compare(params, progs, evals, sample, recs, args.same_tol, args.energy_tol)
    # jaxgrasp.evaluate's value vs the reduction of solve_problems (same lanes): sanity
    out["agreement"]["evaluate_matches_programs"] = check_reduction(progs, evals)
    log(f"{name}: jaxgrasp {j_rate:.0f} programs/s, Ipopt {i_rate:.0f} programs/s, ratio {j_rate / i_rate:.1f}")
    return out


def check_reduction(progs, evals) -> float:
    """Max relative difference between evaluate's value and min(converged lane energy) -
    equilibrium energy from solve_problems, over grasps evaluate calls stable."""
    worst = 0.0
    conv = progs.found & (progs.boundary.status == LaneStatus.CONVERGED)
    for i in np.flatnonzero(evals.status == GraspStatus.STABLE):
        ub = np.where(conv[i], progs.boundary.objective[i], np.inf).min()
        v = (ub - progs.equilibrium.objective[i]) * progs.scale[i] * 1e-3
        worst = max(worst, rel(float(evals.value[i]), float(v)))
    return worst


# --------------------------------------------------------------------------- tables


def fmt(x, spec=".3g"):
    if x is None:
        return "-"
    return format(x, spec)


def markdown_tables(results: dict) -> str:
    """The benchmark as two markdown tables (speed; agreement) and notes."""
    lines = ["| scene | grasps | jaxgrasp programs | jaxgrasp compile [s] | jaxgrasp steady [s] "
             "| jaxgrasp programs/s | jaxgrasp per program, amortised [ms] | Ipopt programs (grasps) "
             "| Ipopt solver [s] | Ipopt programs/s | Ipopt per solve: mean / median / median converged [ms] "
             "| ratio (wall) | ratio (CPU) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for s in results["scenes"]:
        j, i = s["jaxgrasp"], s["ipopt"]
        lines.append(
            f"| {s['scene']} | {s['grasps']} | {j['programs']} | {j['compile_s']:.1f} | {j['steady_median_wall_s']:.2f} "
            f"| {j['programs_per_s']:.0f} | {1e3 * j['steady_median_wall_s'] / j['programs']:.3f} "
            f"| {i['programs']} ({i['sample_grasps']}) | {i['solver_s']:.1f} "
            f"| {i['programs_per_s']:.1f} | {1e3 * i['solver_s'] / i['programs']:.2f} / {i['median_solve_ms']:.2f} / "
            f"{fmt(i['median_converged_solve_ms'], '.2f')} | {s['ratio_programs_per_s_jax_over_ipopt']:.1f} "
            f"| {s['ratio_programs_per_cpu_s_jax_over_ipopt']:.1f} |")
    lines += ["", "| scene | programs compared | both converged | same point: max rel. energy diff "
              "| other point, equal energy | other local minimum (jaxgrasp lower / Ipopt lower) "
              "| only jaxgrasp converged (above its problem's min) | only Ipopt converged | neither "
              "| grasp status agrees | value: max rel. diff (both stable) |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for s in results["scenes"]:
        a = s["agreement"]
        c = a["program_counts"]
        v = a["value"]
        lines.append(
            f"| {s['scene']} | {c['programs']} | {c['both_converged']} | {fmt(a['same_point_energy_rel_diff']['max'], '.1e')} "
            f"| {c['different_point_equal_energy']} "
            f"| {c['different_minimum']} ({c['different_minimum_jax_lower']} / {c['different_minimum_ipopt_lower']}) "
            f"| {c['jax_only_converged']} ({c['jax_only_converged_above_problem_min']}) | {c['ipopt_only_converged']} "
            f"| {c['neither_converged']} | {v['status_agree']}/{v['grasps']} "
            f"| {fmt(v['max_rel_diff'], '.1e')} ({v['both_stable']} grasps) |")
    notes = []
    for s in results["scenes"]:
        i = s["ipopt"]
        if i["sampled"]:
            notes.append(f"{s['scene']}: Ipopt ran on {i['sample_grasps']} of {s['grasps']} grasps (seeded, spread "
                         f"over the grid); at its rate all {s['jaxgrasp']['programs']} programs would take "
                         f"{i['extrapolated_solver_s_all_grasps']:.0f} s of solver time.")
        notes.append(f"{s['scene']}: Ipopt NLP construction {1e3 * i['setup_s_per_grasp']:.0f} ms per grasp (not "
                     f"in the solver time); {i['failed_solves']} of {i['programs']} Ipopt solves failed "
                     f"({i['max_iter_solves']} at the iteration limit), taking {i['failed_solver_s']:.1f} s; "
                     f"counting converged programs only: jaxgrasp {s['converged_programs_per_s']['jaxgrasp']:.0f}/s, "
                     f"Ipopt {s['converged_programs_per_s']['ipopt']:.1f}/s, ratio {s['converged_programs_per_s']['ratio']:.1f}.")
    for s in results["scenes"]:
        j, i = s["jaxgrasp"], s["ipopt"]
        amort = 1e3 * j["steady_median_wall_s"] / j["programs"]
        mean = 1e3 * i["solver_s"] / i["programs"]
        notes.append(f"{s['scene']}: per program, Ipopt (serial) takes {mean:.2f} ms on average, median "
                     f"{i['median_solve_ms']:.2f} ms wall, {fmt(i.get('median_solve_cpu_ms'), '.2f')} ms CPU "
                     f"(median over converged solves "
                     f"{fmt(i['median_converged_solve_ms'], '.2f')} ms); jaxgrasp's steady batch takes {amort:.3f} ms "
                     f"per program amortised. The ratios above divide totals (means); against Ipopt's median "
                     f"solve the ratio would be {i['median_solve_ms'] / amort:.1f}.")
    ev = results.get("evaluate_compile_cube_grid")
    if ev:
        notes.append(f"`evaluate_batch_traced(g, settle=False)` over the devices on the cube sweep grid ({ev['grasps']} grasps): "
                     f"compile {ev['compile_s']:.1f} s, first call {ev['first_call_s']:.1f} s "
                     f"(compile + first run), second call {ev['second_call_s']:.2f} s.")
    notes.append(f"Load average (1, 5, 15 min): {results['load_start']} at start, {results['load_end']} at end, "
                 f"on {results['machine']['cpu_count']} cores ({results['machine']['jax_backend']}, "
                 f"{results['machine'].get('jax_devices', 1)} JAX devices: jaxgrasp's batch is split over them, "
                 f"one work queue each; Ipopt runs on one core).")
    lines += [""] + [f"- {n}" for n in notes]
    return "\n".join(lines)


# --------------------------------------------------------------------------- main


def code_state() -> dict:
    """The commit benchmarked and the jaxgrasp files that differ from it."""
    import subprocess

    def git(*cmd):
        try:
            return subprocess.run(["git", *cmd], cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return None

    status = git("status", "--short", "--", "jaxgrasp")
    return {"commit": git("rev-parse", "HEAD"), "jaxgrasp_changes": status.splitlines() if status else []}



def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small grids (smoke test)")
    p.add_argument("--ipopt-sample", type=int, default=None,
                   help="grasps per scene solved with Ipopt, spread over the grid (default 40, quick 4; 0 = all)")
    p.add_argument("--repeats", type=int, default=3, help="steady-state jaxgrasp calls (>= 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Ipopt sample")
    p.add_argument("--same-tol", type=float, default=1e-4,
                   help="two solutions are the same point when |z_jax - z_ipopt|_inf <= this, mm (scaled variables)")
    p.add_argument("--energy-tol", type=float, default=1e-8,
                   help="two different points with energies within this relative difference are equivalent minima")
    p.add_argument("--scenes", default="cube,prism")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args()
    if args.ipopt_sample is None:
        args.ipopt_sample = 4 if args.quick else 40
    if args.json is None:
        args.json = (HERE / "quick" / "benchmark_results.json") if args.quick else HERE / "benchmark_results.json"
    opts = EvaluateOptions()
    results = {
        "description": "jaxgrasp vs CasADi+Ipopt on the same programs from the same starting points (issue #5)",
        "quick": args.quick,
        "ipopt_sample_per_scene": args.ipopt_sample,
        "ipopt_note": ("Ipopt programs/s is measured on the sample of grasps given in each scene's "
                       "ipopt.sample_indices (solver calls only; NLP construction reported as setup)"
                       if args.ipopt_sample > 0 else "Ipopt solved every grasp"),
        "options": {"num_random_starts": opts.num_random_starts, "directions": int(opts.directions().shape[0]),
                    "solver_tol": opts.solver.tol, "ipopt_tol": 1e-12, "ipopt_max_iter": 200},
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "jax": jax.__version__, "jaxgrasp": jaxgrasp.__version__, "jax_backend": jax.default_backend(), "jax_devices": jax.device_count(),
                    "casadi": ca.__version__},
        "code": code_state(),
        "load_start": load(),
        "started": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    t0 = time.perf_counter()
    scenes = []
    for name in args.scenes.split(","):
        params, grasps = (cube_grid if name == "cube" else prism_grid)(args.quick)
        scenes.append(run_scene(name, params, grasps, opts, args))
        if name == "cube":
            e = scenes[-1]["evaluate"]
            results["evaluate_compile_cube_grid"] = {"grasps": len(grasps), **{k: e[k] for k in
                                                     ("compile_s", "first_run_s", "first_call_s", "second_call_s")}}
    results["scenes"] = scenes
    results["load_end"] = load()
    results["total_s"] = time.perf_counter() - t0
    table = markdown_tables(results)
    results["markdown"] = table
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2, default=float))
    print(table)
    print(f"\nwritten {args.json} (total {results['total_s']:.0f} s)")


if __name__ == "__main__":
    main()
