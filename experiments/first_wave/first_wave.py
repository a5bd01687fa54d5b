"""Issue 41: the first wave of starts (``EvaluateOptions.first_wave``) against every
start at once (``first_wave=None``), side by side in one process.

For the ``--count`` grasps of the batch benchmark's mixed set (``batch_benchmark.make_grasps``,
2 to 7 contacts, seed 0), each printed with the load average:

1. lane by lane (``solve_problems`` on the set padded to 7 contacts, both options): for
   every boundary problem whose first wave settled it (lanes found but not run), whether
   a start that the wave left out would have changed its answer: a converged energy
   lower than the first wave's lowest by more than ``SAME_POINT`` (a missed minimum), a
   converged lane where the first wave proved the boundary infeasible (a missed feasible
   boundary), or another problem status; and the lane-steps of each option by lane status;
2. grasp by grasp (``jaxgrasp.evaluate_batch``): statuses equal; values (largest relative
   difference, and how many are higher with the first wave, by more than 1e-12 and 1e-9);
3. CPU seconds per grasp of ``evaluate_batch``, both options compiled first, then run
   alternately (``--repeats``), so that both see the same load.

    nice python experiments/first_wave/first_wave.py [--count 1000] [--repeats 3] [--json experiments/first_wave/first_wave.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports

from _lab import say  # noqa: E402
from batch_benchmark import make_grasps  # noqa: E402

STATUS = ("converged", "infeasible", "not_converged", "no_start")


def options_pair():
    """``{"all": every start at once, "wave": the default first wave}``."""
    import jaxgrasp

    wave = jaxgrasp.EvaluateOptions()
    return {"all": dataclasses.replace(wave, first_wave=None), "wave": wave}


def lanes_of(grasps, options, chunk: int = 100):
    """Numpy ``Problems`` of the grasps (padded to their largest count), in chunks."""
    import jax

    import jaxgrasp
    from jaxgrasp.engine import solve_problems

    npad = max(g.num_contacts for g in grasps)
    run = jax.jit(jax.vmap(lambda g: solve_problems(g, options)))
    parts = []
    for i in range(0, len(grasps), chunk):
        batch = jaxgrasp.stack(grasps[i:i + chunk], num_contacts=npad)
        parts.append(jax.tree_util.tree_map(np.asarray, jax.block_until_ready(run(batch))))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *parts)


def lane_check(grasps) -> dict:
    """Check 1; returns the counts."""
    from jaxgrasp.tolerance import SAME_POINT

    pair = options_pair()
    d = pair["wave"].num_starts
    progs = {}
    for name, opts in pair.items():
        t0 = time.perf_counter()
        progs[name] = lanes_of(grasps, opts)
        say(f"lanes, {name}: solve_problems on {len(grasps)} grasps in {time.perf_counter() - t0:.1f} s (compile included)")
    out = {}
    for name, p in progs.items():
        st, sp, found = p.boundary.status, p.boundary.steps, p.found
        ran = found & (st != 3)
        kinds = {STATUS[c]: (int(np.sum(ran & (st == c))), int(np.sum(np.where(ran & (st == c), sp, 0)))) for c in range(3)}
        total = sum(s for _, s in kinds.values())
        out[name] = {"lanes_run": int(ran.sum()), "lane_steps": total, "by_status": kinds}
        say(f"lanes, {name}: {int(ran.sum())} boundary lanes run of {int(found.sum())} found, {total} lane-steps; "
            + "; ".join(f"{k} {n} lanes {s} steps ({s / max(n, 1):.1f}/lane)" for k, (n, s) in kinds.items()))
    a, w = progs["all"].boundary, progs["wave"].boundary
    found = progs["all"].found
    shape = found.shape[:1] + (-1, d)
    f = found.reshape(shape)
    sa, sw = a.status.reshape(shape), w.status.reshape(shape)
    ea, ew = a.objective.reshape(shape), w.objective.reshape(shape)
    skipped = f & (sw == 3)  # found, not run with the first wave
    settled = np.any(skipped, axis=-1)
    low_a = np.min(np.where(sa == 0, ea, np.inf), axis=-1)
    low_w = np.min(np.where(sw == 0, ew, np.inf), axis=-1)
    # the lanes the wave left out, as the full run solved them
    left = np.where(skipped, sa, 3)
    with np.errstate(invalid="ignore"):
        missed_min = settled & np.isfinite(low_w) & (low_a < low_w - SAME_POINT * np.maximum(np.abs(low_w), 1.0))
    missed_feasible = settled & ~np.isfinite(low_w) & np.any(left == 0, axis=-1)
    stalled_left = settled & np.any(left == 2, axis=-1)
    kind = lambda s: np.where(np.any(s == 0, -1), 0, np.where(np.all((s == 1) | (s == 3) | ~f, -1), 1, 2))  # noqa: E731
    status_diff = np.any(f, -1) & (kind(sa) != kind(sw))
    out["settled_problems"] = int(settled.sum())
    out["problems"] = int(np.sum(np.any(f, -1)))
    out["missed_minimum"] = int(missed_min.sum())
    out["missed_feasible"] = int(missed_feasible.sum())
    out["left_out_stalled"] = int(stalled_left.sum())
    out["problem_status_differs"] = int(status_diff.sum())
    out["left_out_lanes"] = int(skipped.sum())
    say(f"boundary problems with a found start: {out['problems']}; settled by the first wave: {out['settled_problems']} "
        f"({out['left_out_lanes']} lanes left out); of those, a left-out start below the wave's lowest energy: "
        f"{out['missed_minimum']}, converged where the wave proved infeasibility: {out['missed_feasible']}, "
        f"stalled: {out['left_out_stalled']}; problem statuses that differ: {out['problem_status_differs']}")
    out["simulated"] = simulate_waves(progs["all"], d)
    ratio = out["wave"]["lane_steps"] / out["all"]["lane_steps"]
    say(f"boundary lane-steps: first wave / every start = {ratio:.3f}")
    out["lane_step_ratio"] = ratio
    return out


def simulate_waves(p, d: int, sizes=(2, 4, 6, 8, 10, 12)) -> dict:
    """The rule of ``rest_needed`` applied to the full run's lanes for first waves of
    ``sizes`` starts (lanes are solved independently, so a wave's lanes are the full
    run's, to rounding): problems settled, settled problems whose lowest energy or
    feasibility the rest would have changed (in stable grasps, where a boundary sets the
    value, and in all), and the lane-steps run, as a fraction of the full run's."""
    import jax.numpy as jnp

    import jaxgrasp
    from jaxgrasp.tolerance import SAME_POINT, first_wave_lanes, rest_needed

    found, st, e, sp = p.found, p.boundary.status, p.boundary.objective, p.boundary.steps
    u0 = jnp.asarray(p.equilibrium.objective)
    st = np.where(found, st, 3)
    b, lanes = st.shape
    n = lanes // (2 * d)
    total = np.sum(np.where(st != 3, sp, 0))
    out = {}
    for k in sizes:
        first = np.asarray(first_wave_lanes(n, jaxgrasp.EvaluateOptions(first_wave=k)))
        need = np.asarray(rest_needed(jnp.asarray(np.where(first, st, 3)), jnp.asarray(e), jnp.asarray(first), d, u0))
        ran = (st != 3) & (first | need)
        settled = ~need.reshape(b, -1, d)[..., 0] & np.any((st != 3).reshape(b, -1, d), -1)
        s3, e3, f3 = st.reshape(b, -1, d), e.reshape(b, -1, d), first.reshape(-1, d)[0]
        low_w = np.min(np.where(f3 & (s3 == 0), e3, np.inf), -1)
        low_a = np.min(np.where(s3 == 0, e3, np.inf), -1)
        with np.errstate(invalid="ignore"):
            missed = settled & ((np.isfinite(low_w) & (low_a < low_w - SAME_POINT * np.maximum(np.abs(low_w), 1.0)))
                                | (~np.isfinite(low_w) & np.isfinite(low_a)))
        u = np.asarray(u0)
        stable = np.min(low_a, -1) - u > 1e-9 * np.abs(u)
        frac = float(np.sum(np.where(ran, sp, 0)) / total)
        out[k] = {"settled": int(settled.sum()), "missed": int(missed.sum()), "settled_in_stable": int(settled[stable].sum()),
                  "missed_in_stable": int(missed[stable].sum()), "lane_step_fraction": frac}
        say(f"   simulated first wave of {k:2d} starts: settles {int(settled.sum())} problems "
            f"({int(settled[stable].sum())} in stable grasps), {int(missed.sum())} of them changed by the rest "
            f"({int(missed[stable].sum())} in stable grasps); lane-steps {frac:.3f} of every start's")
    return out


def grasp_check(grasps) -> dict:
    """Checks 2 and 3 (the CPU part is :func:`cpu_alternating`)."""
    import jaxgrasp

    res = {name: jaxgrasp.evaluate_batch(grasps, options=o) for name, o in options_pair().items()}
    sa, sw = np.asarray(res["all"].status), np.asarray(res["wave"].status)
    va, vw = np.asarray(res["all"].value), np.asarray(res["wave"].value)
    rel = np.abs(va - vw) / np.maximum(np.abs(va), 1e-300)
    rel[(va == 0) & (vw == 0)] = 0.0
    eq = np.abs(np.asarray(res["all"].evaluation.equilibrium_energy))
    lim = lambda r: (np.asarray(r.evaluation.limiting_kind), np.asarray(r.evaluation.limiting_contact))  # noqa: E731
    (ka, ca), (kw, cw) = lim(res["all"]), lim(res["wave"])
    out = {"status_differs": int(np.sum(sa != sw)), "value_max_rel": float(rel.max()),
           "limiting_differs": int(np.sum((ka != kw) | (ca != cw))),
           "value_rel_over_1e-9": int(np.sum(rel > 1e-9)), "higher_1e-12": int(np.sum(vw > va * (1 + 1e-12) + 1e-300)),
           "higher_1e-9": int(np.sum(vw > va * (1 + 1e-9) + 1e-300)),
           "value_diff_over_eq_energy": float(np.max(np.abs(va - vw) / eq))}
    say(f"grasps all vs wave: statuses differ on {out['status_differs']} of {len(grasps)}, limiting boundary on "
        f"{out['limiting_differs']}; value max rel diff "
        f"{out['value_max_rel']:.1e} (> 1e-9: {out['value_rel_over_1e-9']}); higher with the first wave by > 1e-12 rel: "
        f"{out['higher_1e-12']}, by > 1e-9: {out['higher_1e-9']}; largest difference / equilibrium energy "
        f"{out['value_diff_over_eq_energy']:.1e}")
    return out


def cpu_alternating(grasps, repeats: int) -> dict:
    """Check 3: process CPU seconds per grasp of both options, run alternately."""
    import jaxgrasp

    pair = options_pair()
    for o in pair.values():
        jaxgrasp.evaluate_batch(grasps, options=o)  # compile (or load)
    cpu = {name: [] for name in pair}
    wall = {name: [] for name in pair}
    for _ in range(repeats):
        for name, o in pair.items():
            c0, t0 = time.process_time(), time.perf_counter()
            jaxgrasp.evaluate_batch(grasps, options=o)
            cpu[name].append(time.process_time() - c0)
            wall[name].append(time.perf_counter() - t0)
    out = {}
    for name in pair:
        ms = 1e3 * np.asarray(cpu[name]) / len(grasps)
        rate = len(grasps) / np.asarray(wall[name])
        out[name] = {"cpu_ms_per_grasp": ms.tolist(), "grasps_per_s": rate.tolist()}
        say(f"{name}: CPU per grasp " + ", ".join(f"{v:.2f}" for v in ms) + f" ms (median {np.median(ms):.2f}); "
            + "grasps/s " + ", ".join(f"{v:.1f}" for v in rate))
    r = np.median(out["all"]["cpu_ms_per_grasp"]) / np.median(out["wave"]["cpu_ms_per_grasp"])
    say(f"CPU per grasp, every start / first wave (medians): {r:.2f}")
    out["cpu_ratio"] = float(r)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        if not os.access(args.json.parent, os.W_OK):
            raise SystemExit(f"cannot write {args.json}")
    import jax

    import jaxgrasp  # noqa: F401  (before JAX starts its backend: one CPU device per core)

    say(f"first wave vs every start: {args.count} grasps, jax {jax.__version__} ({jax.default_backend()}, "
        f"{jax.device_count()} device(s)), {os.cpu_count()} CPUs, load average {os.getloadavg()}")
    grasps = make_grasps(args.count, 0)
    out = {"count": args.count, "load_start": os.getloadavg()}
    out["lanes"] = lane_check(grasps)
    out["grasps"] = grasp_check(grasps)
    if args.repeats:
        out["cpu"] = cpu_alternating(grasps, args.repeats)
    out["load_end"] = os.getloadavg()
    say(f"load average at the end {out['load_end']}")
    if args.json is not None:
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps(out, indent=1) + "\n")
        os.replace(tmp, args.json)


if __name__ == "__main__":
    main()
