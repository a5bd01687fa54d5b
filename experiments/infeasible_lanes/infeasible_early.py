"""Issue 41, item 2 (infeasible lanes end early): the penalty jump of
``SolverOptions.stall_growth_max`` against the fixed tenfold growth, side by side in one
process (``stall_growth_max = rho_growth`` is the old behaviour, bit for bit).

Three checks, each printed with the load average:

1. lane by lane, on the first ``--lane-grasps`` seven-contact grasps of the batch
   benchmark's seeded set: every boundary lane solved from the same start with both
   options (``jaxgrasp.solver.solve`` under ``vmap``): statuses, objectives of the lanes
   that converge, steps per lane kind;
2. the ``--count`` grasps of the mixed set (``batch_benchmark.make_grasps``), padded
   chunks as :func:`jaxgrasp.evaluate_batch` runs them, both options: lane-steps per lane
   kind and the CPU seconds of the pipeline stages (``profile_batch.profile``), grasp
   statuses and values;
3. CasADi + Ipopt (``experiments/ipopt_benchmark/benchmark.py``'s multi-start, from jaxgrasp's starts) on
   ``--ipopt`` grasps of the set (``batch_benchmark.ipopt_sample``): statuses equal, values
   within 1e-6 relative, none above Ipopt's, for both options; the number of infeasible
   boundary lanes of each sampled grasp is printed;
4. (``--cpu-repeats``) process CPU seconds of :func:`jaxgrasp.evaluate_batch` on the
   first ``--cpu-grasps`` grasps of the set, both options compiled first, then run
   alternately, so that both see the same load;
5. (``--pipeline-contacts N``) the solve stage's lanes of :func:`jaxgrasp.evaluate_batch`
   on the first ``--cpu-grasps`` grasps with ``N`` contacts (own width), both options,
   lane by lane: every lane whose status or step count differs, unless it ends
   infeasible with both; grasp values and statuses.

    nice python experiments/infeasible_lanes/infeasible_early.py [--count 1000] [--ipopt 30] [--lane-grasps 8]
    nice python experiments/infeasible_lanes/infeasible_early.py --count 0 --ipopt 0 --lane-grasps 0 --cpu-repeats 4
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark", "ipopt_benchmark")  # the studies whose scripts this one imports

from _lab import say
from batch_benchmark import OVER_REL, STATUS, ipopt_sample, make_grasps, own_programs, rel_diff

LANE_STATUS = ("converged", "infeasible", "not_converged", "no_start")


def options_pair():
    """``{"old": ..., "new": ...}`` EvaluateOptions: the fixed tenfold growth, and the default."""
    import jaxgrasp

    new = jaxgrasp.EvaluateOptions()
    old = dataclasses.replace(new, solver=dataclasses.replace(new.solver, stall_growth_max=new.solver.rho_growth))
    return {"old": old, "new": new}


def lanes_side_by_side(n_contacts: int, n_grasps: int) -> None:
    """Check 1: every boundary lane of the grasps from the same start, both options."""
    import jax
    import jax.numpy as jnp

    import jaxgrasp
    from jaxgrasp.engine import inputs_of, run_inline, stage_functions
    from jaxgrasp import solver as S
    from jaxgrasp.tolerance import lane_problem

    pair = options_pair()
    gs = [g for g in make_grasps(1000, 0) if g.num_contacts == n_contacts][:n_grasps]
    batch = jaxgrasp.stack(gs)
    starts = jax.jit(lambda b: run_inline(b, stage_functions(pair["new"], False), until="lane_starts"))(batch)
    data = inputs_of(batch)["data"]
    b, L = starts.x0.shape[:2]
    theta = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a[:, None], (b, L) + a.shape[1:]).reshape((b * L,) + a.shape[1:]), data)
    flat = lambda a: a.reshape((b * L,) + a.shape[2:])
    out = {}
    for name, opts in pair.items():
        o = opts.solver
        solve = jax.jit(jax.vmap(lambda x, m, nu, a, t, o=o: S.solve(lane_problem(t), x, m, nu, o, a)))
        r = solve(flat(starts.x0), flat(starts.eq_mask), flat(starts.nu0), flat(starts.active), theta)
        out[name] = tuple(np.asarray(a) for a in (r.status, r.steps, r.objective))
        st, sp, _ = out[name]
        kinds = ", ".join(f"{k} {np.sum(st == c)} lanes {sp[st == c].mean():.1f} steps/lane"
                          for c, k in enumerate(LANE_STATUS[:3]) if np.any(st == c))
        say(f"lanes, N={n_contacts}, {n_grasps} grasps, {name}: {kinds}; total {sp[st != 3].sum()} lane-steps")
    (so, _, fo), (sn, _, fn) = out["old"], out["new"]
    conv = (so == 0) & (sn == 0)
    say(f"lanes old vs new: statuses differ on {np.sum(so != sn)} of {so.size} lanes; converged objectives: "
        f"max rel diff {rel_diff(fo[conv], fn[conv]).max():.1e}, bit-identical {np.sum(fo[conv] == fn[conv])} of {conv.sum()}")


def profiled(grasps, name: str, opts) -> dict:
    """``profile_batch.profile`` of one option on ``grasps`` (one steady run), its CPU of
    the stages and lane-steps per lane kind printed; returns the profile."""
    from profile_batch import profile

    p = profile(grasps, name, repeats=1, options=opts)
    cpu = sum(v for k, v in p["stage_s"].items() if k.endswith(" cpu"))
    say(f"{len(grasps)} grasps, {name}: CPU of the stages {cpu:.2f} s = {1e3 * cpu / len(grasps):.2f} ms per grasp "
        f"(lanes stage {p['stage_s'].get('lanes cpu', 0.0):.2f} s); wall {p['wall_s']:.1f} s")
    total = 0
    for k, (n, s, m) in sorted(p["lanes"].items()):
        if n and not k.endswith("lanes_total") and not k.endswith("no_start"):
            total += s
            say(f"   {k:26s} lanes {n:7d} steps {s:8d} mean {s / n:6.1f} max {m}")
    say(f"   all lanes: {total} lane-steps")
    return p


def batch_side_by_side(grasps) -> dict:
    """Check 2: the mixed set, both options; returns each option's statuses and values."""
    res = {}
    for name, opts in options_pair().items():
        p = profiled(grasps, name, opts)
        res[name] = {"status": np.asarray(p["status"]), "value": np.asarray(p["value"])}
    o, n = res["old"], res["new"]
    d = rel_diff(o["value"], n["value"])
    say(f"grasps old vs new: statuses differ on {np.sum(o['status'] != n['status'])} of {len(grasps)}; "
        f"values max rel diff {d.max():.1e}, above 1e-9: {np.sum(d > 1e-9)}, new above old by > 1e-9 rel: "
        f"{np.sum(n['value'] > o['value'] * (1 + 1e-9) + 1e-300)}")
    counts = {STATUS[c]: int(np.sum(n["status"] == c)) for c in range(len(STATUS))}
    say(f"grasp statuses (new): {counts}")
    return res


def ipopt_check(grasps, sample, res) -> None:
    """Check 3: Ipopt's multi-start from jaxgrasp's starts on the sample, against both options."""
    import jax

    import jaxgrasp
    import benchmark as bm
    from jaxgrasp.engine import solve_problems

    npad = max(g.num_contacts for g in grasps)
    batch = jaxgrasp.stack([grasps[i] for i in sample], num_contacts=npad)
    progs = jax.block_until_ready(jax.jit(jax.vmap(lambda g: solve_problems(g, jaxgrasp.EvaluateOptions())))(batch))
    progs = jax.tree_util.tree_map(np.asarray, progs)
    rows = []
    for s, i in enumerate(sample):
        n = grasps[i].num_contacts
        model, _ = bm.ipopt_setup(grasps[i])
        status, value = bm.ipopt_value(bm.ipopt_grasp(model, own_programs(progs, s, npad, n), 0, n), n)
        inf_lanes = int(np.sum(progs.boundary.status[s] == 1))
        rows.append((i, n, status, value, inf_lanes))
        say(f"ipopt {s + 1}/{len(sample)}: grasp {i} (N={n}) {status} {value:.9g} J; jaxgrasp old "
            f"{STATUS[res['old']['status'][i]]} {res['old']['value'][i]:.9g}, new {STATUS[res['new']['status'][i]]} "
            f"{res['new']['value'][i]:.9g}; infeasible boundary lanes {inf_lanes}")
    for name in ("old", "new"):
        st, val = res[name]["status"], res[name]["value"]
        agree = sum(STATUS[st[i]] == s for i, _, s, _, _ in rows)
        stable = [(i, v) for i, _, s, v, _ in rows if s == "stable" and STATUS[st[i]] == "stable"]
        rels = [float(rel_diff(val[i], v)) for i, v in stable]
        over = [i for i, v in stable if val[i] > v * (1 + OVER_REL)]
        say(f"Ipopt vs {name}: statuses {agree}/{len(rows)}, both stable {len(stable)}, value max rel diff "
            f"{max(rels) if rels else float('nan'):.1e}, above Ipopt by > {OVER_REL:g} rel: {over}")
    say(f"sampled grasps with infeasible boundary lanes: {sum(r[4] > 0 for r in rows)} of {len(rows)} "
        f"({sum(r[4] for r in rows)} lanes)")


def cpu_alternating(grasps, repeats: int, pair: dict | None = None) -> None:
    """Check 4: CPU seconds per grasp of both options (or of every ``name: options`` of
    ``pair``), each compiled first, then run alternately so that all see the same load."""
    import jaxgrasp

    pair = pair or options_pair()
    for opts in pair.values():
        jaxgrasp.evaluate_batch(grasps, options=opts)  # compile (or load)
    cpu = {name: [] for name in pair}
    for _ in range(repeats):
        for name, opts in pair.items():
            c0 = time.process_time()
            jaxgrasp.evaluate_batch(grasps, options=opts)
            cpu[name].append(time.process_time() - c0)
    for name, c in cpu.items():
        ms = 1e3 * np.asarray(c) / len(grasps)
        say(f"CPU per grasp, {len(grasps)} grasps, {name}: " + ", ".join(f"{v:.2f}" for v in ms)
            + f" ms (median {np.median(ms):.2f}, min {ms.min():.2f})")


def pipeline_lanes(grasps) -> None:
    """Check 5: the solve stage's lanes inside evaluate_batch, both options, lane by lane."""
    import jax

    import jaxgrasp
    from _lab import module_of
    from jaxgrasp.engine import compiled_evaluator

    # no public hook shows a stage's results: this instrument replaces the engine's evaluator factory
    _evaluator = module_of(compiled_evaluator)

    real, got = compiled_evaluator, []

    def hooked(*a, **k):
        fn, s = real(*a, **k)
        if not getattr(fn, "_hooked", False):
            stage = fn.stages["lanes"]
            fn.stages["lanes"] = lambda *xs: got.append(jax.block_until_ready(stage(*xs))) or got[-1]
            fn._hooked = True
        return fn, s

    _evaluator.compiled_evaluator = hooked
    res = {}
    try:
        for name, opts in options_pair().items():
            got.clear()
            r = jaxgrasp.evaluate_batch(grasps, options=opts)
            # every chunk calls the lanes stage twice: the equilibrium, then the boundary lanes
            res[name] = ([[np.asarray(out[i]) for i in (3, 4, 8)] for out in got[1::2]], np.asarray(r.value), np.asarray(r.status))
    finally:
        _evaluator.compiled_evaluator = real
    moved = 0
    for (fo, so, po), (fn, sn, pn) in zip(res["old"][0], res["new"][0]):
        for idx in zip(*np.nonzero(((so != sn) | (po != pn)) & ~((so == 1) & (sn == 1)))):
            moved += 1
            say(f"   lane {tuple(int(i) for i in idx)}: old {LANE_STATUS[so[idx]]} {po[idx]} steps f {fo[idx]!r}, "
                f"new {LANE_STATUS[sn[idx]]} {pn[idx]} steps f {fn[idx]!r}")
    say(f"pipeline lanes, {len(grasps)} grasps of {grasps[0].num_contacts} contacts: {moved} lanes not ending "
        f"infeasible in both took another path; grasp statuses differ on {np.sum(res['old'][2] != res['new'][2])}, "
        f"values max rel diff {rel_diff(res['old'][1], res['new'][1]).max():.1e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--ipopt", type=int, default=30)
    ap.add_argument("--lane-grasps", type=int, default=8)
    ap.add_argument("--cpu-grasps", type=int, default=256)
    ap.add_argument("--cpu-repeats", type=int, default=0)
    ap.add_argument("--pipeline-contacts", type=int, default=0)
    a = ap.parse_args()
    import jaxgrasp  # noqa: F401  (64-bit mode)

    say(f"python experiments/infeasible_lanes/infeasible_early.py --count {a.count} --ipopt {a.ipopt} --lane-grasps {a.lane_grasps}"
        + f" --cpu-grasps {a.cpu_grasps} --cpu-repeats {a.cpu_repeats} --pipeline-contacts {a.pipeline_contacts}")
    if a.lane_grasps:
        lanes_side_by_side(7, a.lane_grasps)
    if a.count:
        grasps = make_grasps(a.count, 0)
        res = batch_side_by_side(grasps)
        if a.ipopt:
            ipopt_check(grasps, ipopt_sample([g.num_contacts for g in grasps], a.ipopt, 0), res)
    if a.cpu_repeats:
        cpu_alternating(make_grasps(a.cpu_grasps, 0), a.cpu_repeats)
    if a.pipeline_contacts:
        own = [g for g in make_grasps(1000, 0) if g.num_contacts == a.pipeline_contacts][: a.cpu_grasps]
        pipeline_lanes(own)


if __name__ == "__main__":
    main()
