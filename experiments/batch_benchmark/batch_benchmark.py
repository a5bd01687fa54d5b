"""Batch benchmark (issue 12): one padded compilation against one per contact count, and Ipopt.

The set: ``--count`` (default 1000) seeded random grasps from the property tests'
generator (``tests/grasp_draws.py:build_grasp``), contact counts cycling 2, 3, 4, 5,
6, 7 (``n = 2 + i % 6``), default :class:`jaxgrasp.EvaluateOptions`, default chunk size.
Measured in one run of this script, each phase in its own subprocess of it (``--phase
NAME``), so that each phase's compile time starts from a cold process (no JAX tracing
caches left by another phase, and an empty executable store of its own: nothing loaded
from the user's cache folder) and its peak RSS (``ru_maxrss``) is its own:

* ``padded``: ``jaxgrasp.evaluate_batch(all grasps)`` after ``clear_compiled()``:
  the grasps are padded with inactive contacts to 7, so ONE compilation serves the set.
  Compile seconds (``BatchResult.compile_seconds``), first-run seconds, then the steady
  rate: grasps/s = B / ``run_seconds`` of a memoised call (median of ``--repeats``);
* ``per-count``: for each contact count, ``evaluate_batch(that count's grasps)`` unpadded
  after ``clear_compiled()``: one compilation per count. Compile seconds summed,
  steady grasps/s = B / (sum over counts of the median steady ``run_seconds``);
* ``ipopt``: a sample of ``--ipopt`` grasps (default 30), stratified over contact counts
  and seeded, solved with CasADi + Ipopt by ``experiments/ipopt_benchmark/benchmark.py``'s functions
  (``ipopt_setup``, ``ipopt_grasp``, ``ipopt_value``): the equilibrium from x = 0 and every
  boundary lane from jaxgrasp's own start. The starts come from one padded
  ``jax.vmap(solve_problems)`` call (padded to the set's largest count, like the padded
  evaluation), their constraint indices mapped back to each grasp's own ``3n``
  constraints; Ipopt's NLP is built on the unpadded grasp. Ipopt seconds per grasp =
  solver calls only; NLP construction reported apart as setup.

The parent process then compares:

* padded against per-count results: statuses, limiting kinds and contacts identical;
  values and equilibrium energies equal to ``1e-12`` relative (max relative difference
  and mismatch counts);
* jaxgrasp (padded) against Ipopt on the sample: status agreement, max relative value
  difference where both say stable, and how many jaxgrasp values are above Ipopt's by
  more than ``1e-6`` relative (stability overstated; should be 0);

and prints a table: compilations (``jaxgrasp.engine.stats()``: programs traced or
deserialized), compile s, steady grasps/s, peak MiB per mode; the ratios; the target
check (one compilation for the set and >= 50 grasps/s steady); the status counts; load
average at start and end. Times are wall seconds, memory MiB (``ru_maxrss`` / 1024).

Full size (the lead's run, on a quiet machine; about 20-25 minutes on 2 cores at the quick run's
rates: 7 compilations of ~30 s, 1000 grasps at ~7 grasps/s three times per mode)::

    python experiments/batch_benchmark/batch_benchmark.py --json experiments/batch_benchmark.json

Development: ``python experiments/batch_benchmark/batch_benchmark.py --quick`` (60 grasps, 6 Ipopt).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("ipopt_benchmark")  # the studies whose scripts this one imports

FIELDS = ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy")
STATUS = ("stable", "unstable", "infeasible", "not_converged")  # GraspStatus labels, by code
SAME_REL = 1e-12  # padded vs per-count: values and energies equal to this, relative
OVER_REL = 1e-6  # jaxgrasp above Ipopt by more than this, relative: stability overstated
TARGET_RATE = 50.0  # grasps/s, steady, padded, on the 2-core CPU
ISSUE41_RATE, ISSUE41_RATIO = 120.0, 300.0  # issue 41's done-when: grasps/s and ratio to Ipopt, same run


def load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')} load {load()[0]:.2f}] {msg}", file=sys.stderr, flush=True)


def peak_mib() -> float:
    """Peak resident set size of this process so far, MiB (``ru_maxrss`` is KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def make_grasps(count: int, seed: int) -> list:
    """``count`` seeded grasps of ``build_grasp``, contact counts ``2 + i % 6``."""
    from _lab.grasp_draws import NumpyDraw, build_grasp

    rng = np.random.default_rng(seed)
    return [build_grasp(NumpyDraw(rng), n=2 + i % 6) for i in range(count)]


def ipopt_sample(counts: list[int], k: int, seed: int) -> list[int]:
    """``k`` grasp indices spread evenly over the contact counts (seeded, sorted)."""
    rng = np.random.default_rng([seed, 12])
    by_n = collections.defaultdict(list)
    for i, n in enumerate(counts):
        by_n[n].append(i)
    ns = sorted(by_n)
    out = []
    for j, n in enumerate(ns):
        take = min(k // len(ns) + (j < k % len(ns)), len(by_n[n]))
        out += rng.choice(by_n[n], size=take, replace=False).tolist()
    return sorted(int(i) for i in out)


def compilations() -> int:
    """Executables traced or loaded by the engine in this process so far."""
    from jaxgrasp.engine import stats as store_stats

    s = store_stats()
    return s["traced"] + s["deserialized"]


def machine() -> dict:
    import jax

    return {"jax": jax.__version__, "backend": jax.default_backend(), "devices": len(jax.devices()),
            "cpu_count": os.cpu_count(), "cpus_usable": len(os.sched_getaffinity(0)),
            "persistent_compilation_cache": jax.config.jax_compilation_cache_dir}


# --------------------------------------------------------------------------- phases (subprocesses)


def timed_batch(grasps):
    """``evaluate_batch(grasps)`` and its wall seconds (host-side stacking included); the
    process's CPU seconds of the call (every thread: both devices' work, counted whatever
    else shares the cores) go to ``CPU_S``."""
    import jaxgrasp

    t0, c0 = time.perf_counter(), time.process_time()
    res = jaxgrasp.evaluate_batch(grasps)
    CPU_S.append(time.process_time() - c0)
    return res, time.perf_counter() - t0


CPU_S: list = []  # CPU seconds of each timed_batch call of this process


def counting_lanes():
    """Wrap the engine's chunk evaluators so that each solve stage's lanes are counted:
    returns ``(counts, undo)``; ``counts`` maps ``eq`` / ``boundary`` to, per
    :class:`jaxgrasp.solver.LaneStatus` name, ``[lanes, lane-steps]`` summed over calls (the
    stage's results are read back once each call, after the stage ran)."""
    from _lab import module_of
    from jaxgrasp.engine import compiled_evaluator

    # no public hook shows a stage's results: this instrument replaces the engine's evaluator factory
    _evaluator = module_of(compiled_evaluator)

    real = compiled_evaluator
    counts = {k: {n: [0, 0] for n in LANE_STATUS} for k in ("eq", "boundary")}
    calls = [0]

    def counted(*a, **k):
        fn, seconds = real(*a, **k)
        if "lanes" in fn.stages and not getattr(fn.stages["lanes"], "counted", False):
            stage = fn.stages["lanes"]

            def lanes(*xs):
                out = stage(*xs)  # SolverResult leaves: status 4th, steps 8th
                status, steps = np.asarray(out[4]).ravel(), np.asarray(out[8]).ravel()
                kind = ("eq", "boundary")[calls[0] % 2]
                calls[0] += 1
                for code, name in enumerate(LANE_STATUS):
                    sel = status == code
                    counts[kind][name][0] += int(sel.sum())
                    counts[kind][name][1] += int(steps[sel].sum())
                return out

            lanes.counted = True
            fn.stages["lanes"] = lanes
        return fn, seconds

    _evaluator.compiled_evaluator = counted

    def undo():
        _evaluator.compiled_evaluator = real

    return counts, undo


LANE_STATUS = ("converged", "infeasible", "not_converged", "no_start")  # LaneStatus labels, by code


def phase_padded(grasps, repeats: int) -> dict:
    """One padded compilation for the whole set; compile, first run, steady run seconds."""
    from jaxgrasp.engine import clear_compiled

    clear_compiled()
    c0 = compilations()
    first, wall = timed_batch(grasps)
    out = {"compilations": compilations() - c0, "compile_s": first.compile_seconds,
           "first_run_s": first.run_seconds, "first_wall_s": wall, "peak_mib_after_first": peak_mib()}
    log(f"padded: {out['compilations']} compilation(s), compile {first.compile_seconds:.1f} s, "
        f"first run {first.run_seconds:.2f} s")
    runs, walls, same = [], [], True
    for _ in range(repeats):
        res, wall = timed_batch(grasps)
        runs.append(res.run_seconds)
        walls.append(wall)
        same &= all(np.array_equal(getattr(res, f), getattr(first, f), equal_nan=True) for f in FIELDS)
    steady_cpu = statistics.median(CPU_S[-repeats:])
    counts, undo = counting_lanes()
    try:
        timed_batch(grasps)  # once more, its lanes counted (not timed)
    finally:
        undo()
    out.update(steady_run_s=statistics.median(runs), steady_runs_s=runs, steady_wall_s=statistics.median(walls),
               steady_cpu_s=steady_cpu, lanes=counts,
               deterministic=bool(same), compilations_total=compilations() - c0,
               num_contacts=np.asarray(first.num_contacts).tolist(),
               results={f: np.asarray(getattr(first, f)).tolist() for f in FIELDS})
    log(f"padded: steady {out['steady_run_s']:.2f} s ({len(grasps) / out['steady_run_s']:.1f} grasps/s)")
    return out


def phase_per_count(grasps, repeats: int) -> dict:
    """One unpadded compilation per contact count; per-count and summed seconds."""
    from jaxgrasp.engine import clear_compiled

    by_n = collections.defaultdict(list)
    for i, g in enumerate(grasps):
        by_n[g.num_contacts].append(i)
    results = {f: [None] * len(grasps) for f in FIELDS}
    groups = []
    c0 = compilations()
    for n, idx in sorted(by_n.items()):
        group = [grasps[i] for i in idx]
        clear_compiled()
        c1 = compilations()
        first, wall = timed_batch(group)
        runs = [timed_batch(group)[0].run_seconds for _ in range(repeats)]
        groups.append({"contacts": n, "grasps": len(idx), "compilations": compilations() - c1,
                       "compile_s": first.compile_seconds, "first_run_s": first.run_seconds,
                       "steady_run_s": statistics.median(runs), "steady_cpu_s": statistics.median(CPU_S[-repeats:]),
                       "peak_mib": peak_mib()})
        for f in FIELDS:
            for i, v in zip(idx, np.asarray(getattr(first, f)).tolist()):
                results[f][i] = v
        log(f"per count N={n}: {len(idx)} grasps, compile {first.compile_seconds:.1f} s, "
            f"steady {groups[-1]['steady_run_s']:.2f} s")
    return {"compilations": compilations() - c0, "compile_s": sum(g["compile_s"] for g in groups),
            "first_run_s": sum(g["first_run_s"] for g in groups),
            "steady_run_s": sum(g["steady_run_s"] for g in groups),
            "steady_cpu_s": sum(g["steady_cpu_s"] for g in groups), "groups": groups, "results": results}


def carried_segments(counts: list[int], chunk: int) -> list[tuple[int, list[int]]]:
    """Grasp indices by contact count, ascending, each count's leftover beyond whole
    ``chunk``s carried into the next larger count's segment (padded to it): ``(count,
    indices)`` per segment. Every chunk is then full but the last one, and a grasp is
    padded at most to the next count that has a chunk of its own."""
    by_n = collections.defaultdict(list)
    for i, n in enumerate(counts):
        by_n[n].append(i)
    ns, carry, segments = sorted(by_n), [], []
    for n in ns:
        pool = carry + by_n[n]
        whole = len(pool) if n == ns[-1] else len(pool) // chunk * chunk
        if whole:
            segments.append((n, pool[:whole]))
        carry = pool[whole:]
    return segments


def phase_bucketed(grasps, repeats: int) -> dict:
    """Bucketed by contact count inside one run, as an engine would do it: the
    :func:`carried_segments` of the set, each segment one ``evaluate_batch`` (padded to
    its own largest count), results put back in input order; the steady seconds are those
    of the whole set, segments one after the other."""
    from jaxgrasp.engine import clear_compiled
    from jaxgrasp.engine import default_chunk_size

    chunk = default_chunk_size()
    segments = carried_segments([g.num_contacts for g in grasps], chunk)
    clear_compiled()
    c0 = compilations()

    def run_all():
        out = {f: [None] * len(grasps) for f in FIELDS}
        compile_s = run_s = cpu = 0.0
        for _, idx in segments:
            res, _ = timed_batch([grasps[i] for i in idx])
            compile_s, run_s, cpu = compile_s + res.compile_seconds, run_s + res.run_seconds, cpu + CPU_S[-1]
            for f in FIELDS:
                for i, v in zip(idx, np.asarray(getattr(res, f)).tolist()):
                    out[f][i] = v
        return out, compile_s, run_s, cpu

    results, compile_s, first_s, _ = run_all()
    log(f"bucketed: {len(segments)} segments ({', '.join(f'N<={n}: {len(i)}' for n, i in segments)}), "
        f"compile {compile_s:.1f} s, first run {first_s:.2f} s")
    steady = [run_all()[2:] for _ in range(repeats)]
    out = {"compilations": compilations() - c0, "compile_s": compile_s, "first_run_s": first_s,
           "steady_run_s": statistics.median(r for r, _ in steady),
           "steady_cpu_s": statistics.median(c for _, c in steady), "chunk": chunk,
           "segments": [{"contacts": n, "grasps": len(i)} for n, i in segments], "results": results}
    log(f"bucketed: steady {out['steady_run_s']:.2f} s ({len(grasps) / out['steady_run_s']:.1f} grasps/s)")
    return out


def own_programs(progs, s: int, npad: int, n: int):
    """Grasp ``s`` of padded numpy ``Problems`` as a one-grasp batch for
    ``benchmark.ipopt_grasp``: constraint indices of the padded ``(3, npad)`` margins
    mapped to the grasp's own ``(3, n)`` (padding contacts' lanes are never found)."""
    from types import SimpleNamespace

    row, j = np.divmod(progs.constraint_index[s], npad)
    assert not np.any(progs.found[s] & (j >= n)), "a padding contact's lane was started"
    return SimpleNamespace(found=progs.found[s:s + 1], start=progs.start[s:s + 1], lever=progs.lever[s:s + 1],
                           constraint_index=np.where(j < n, row * n + j, -1)[None])


def phase_ipopt(grasps, sample: list[int]) -> dict:
    """CasADi + Ipopt on the sampled grasps from jaxgrasp's starts; seconds per grasp."""
    import jax

    import jaxgrasp
    import benchmark as bm
    from jaxgrasp.engine import solve_problems

    npad = max(g.num_contacts for g in grasps)
    batch = jaxgrasp.stack([grasps[i] for i in sample], num_contacts=npad)
    opts = jaxgrasp.EvaluateOptions()
    t0 = time.perf_counter()
    progs = jax.block_until_ready(jax.jit(jax.vmap(lambda g: solve_problems(g, opts)))(batch))
    programs_s = time.perf_counter() - t0
    progs = jax.tree_util.tree_map(np.asarray, progs)
    log(f"ipopt: jaxgrasp programs and starts of {len(sample)} grasps in {programs_s:.1f} s (compile included)")
    rows = []
    for s, i in enumerate(sample):
        n = grasps[i].num_contacts
        model, setup_s = bm.ipopt_setup(grasps[i])
        rec = bm.ipopt_grasp(model, own_programs(progs, s, npad, n), 0, n)
        status, value = bm.ipopt_value(rec, n)
        solves = [rec["eq"]] + rec["lanes"]
        rows.append({"index": i, "contacts": n, "status": status, "value": value, "setup_s": setup_s,
                     "solver_s": sum(r["seconds"] for r in solves), "solves": len(solves),
                     "converged_solves": sum(r["converged"] for r in solves)})
        log(f"ipopt {s + 1}/{len(sample)}: grasp {i} (N={n}) {status} {value:.6g} J, "
            f"{len(solves)} solves in {rows[-1]['solver_s']:.2f} s")
    return {"programs_s": programs_s, "grasps": rows, "solver_s": sum(r["solver_s"] for r in rows),
            "setup_s": sum(r["setup_s"] for r in rows)}


def run_phase_here(args) -> None:
    """Run one phase in this process and write its JSON to ``args.out``."""
    la = load()
    t0 = time.perf_counter()
    grasps = make_grasps(args.count, args.seed)
    out = {"phase": args.phase, "load_start": la, "build_s": time.perf_counter() - t0, "machine": machine()}
    if args.phase == "padded":
        out.update(phase_padded(grasps, args.repeats))
    elif args.phase == "bucketed":
        out.update(phase_bucketed(grasps, args.repeats))
    elif args.phase == "per-count":
        out.update(phase_per_count(grasps, args.repeats))
    else:
        out.update(phase_ipopt(grasps, ipopt_sample([g.num_contacts for g in grasps], args.ipopt, args.seed)))
    out.update(peak_mib=peak_mib(), load_end=load(), wall_s=time.perf_counter() - t0)
    Path(args.out).write_text(json.dumps(out))


def run_phase(name: str, args, tmp: Path) -> dict:
    """Run phase ``name`` in a fresh subprocess of this script; its JSON."""
    out = tmp / f"{name}.json"
    cmd = [sys.executable, str(Path(__file__).resolve()), "--phase", name, "--out", str(out),
           "--count", str(args.count), "--seed", str(args.seed), "--repeats", str(args.repeats),
           "--ipopt", str(args.ipopt)]
    log(f"phase {name} (subprocess)")
    # An executable store of its own, empty: with the user's (or an earlier run's) store a
    # phase would load its programs, and its compile seconds would be a read from disk.
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(tmp / f"store-{name}"))
    subprocess.run(cmd, check=True, cwd=ROOT, env=env)
    return json.loads(out.read_text())


# --------------------------------------------------------------------------- comparison and report


def rel_diff(a, b) -> np.ndarray:
    """Elementwise ``|a - b| / max(|a|, |b|)``: 0 where both are 0 (or both NaN), inf
    where only one is NaN."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.abs(a - b) / np.maximum(np.abs(a), np.abs(b))
    d = np.where((a == b) | (np.isnan(a) & np.isnan(b)), 0.0, d)
    return np.where(np.isnan(d), np.inf, d)


def agreement(padded: dict, per_count: dict) -> dict:
    """Padded vs per-count results: mismatch counts and max relative differences."""
    p, c = padded["results"], per_count["results"]
    out = {f"{f}_mismatches": int(np.sum(np.asarray(p[f]) != np.asarray(c[f])))
           for f in ("status", "limiting_kind", "limiting_contact")}
    for f in ("value", "equilibrium_energy"):
        d = rel_diff(p[f], c[f])
        out[f"{f}_max_rel_diff"] = float(d.max())
        out[f"{f}_mismatches"] = int(np.sum(d > SAME_REL))
    # a value is a difference of two energies: its rounding, relative to the energies
    dv = np.abs(np.asarray(p["value"]) - np.asarray(c["value"]))
    out["value_max_diff_over_equilibrium_energy"] = float(np.max(dv / np.abs(np.asarray(c["equilibrium_energy"]))))
    worst = int(np.argmax(rel_diff(p["value"], c["value"])))
    out["value_worst"] = {"index": worst, "padded_J": p["value"][worst], "per_count_J": c["value"][worst]}
    out["identical"] = all(v == 0 for k, v in out.items() if k.endswith("_mismatches"))
    return out


def ipopt_agreement(padded: dict, ipopt: dict) -> dict:
    """jaxgrasp (padded) vs Ipopt on the sample: statuses and values."""
    agree, both, rels, over, under, mism = 0, 0, [], [], [], []
    for r in ipopt["grasps"]:
        i = r["index"]
        js, jv = STATUS[padded["results"]["status"][i]], padded["results"]["value"][i]
        if js == r["status"]:
            agree += 1
        else:
            mism.append({"index": i, "contacts": r["contacts"], "jaxgrasp": js, "jaxgrasp_J": jv,
                         "ipopt": r["status"], "ipopt_J": r["value"]})
        if js == r["status"] == "stable":
            both += 1
            rels.append(float(rel_diff(jv, r["value"])))
            if jv > r["value"] * (1 + OVER_REL):
                over.append(i)
            if jv < r["value"] * (1 - OVER_REL):
                under.append(i)
    return {"grasps": len(ipopt["grasps"]), "status_agree": agree, "status_mismatches": mism,
            "both_stable": both, "value_max_rel_diff": max(rels) if rels else None,
            "overstated": over, "understated": under}


def summarize(padded: dict, per_count: dict, ipopt: dict, count: int, bucketed: dict | None = None) -> dict:
    """Rates (grasps/s), per-grasp seconds and the ratios of the report."""
    pr = count / padded["steady_run_s"]
    br = count / bucketed["steady_run_s"] if bucketed else float("nan")
    cr = count / per_count["steady_run_s"]
    k = len(ipopt["grasps"])
    ir = k / ipopt["solver_s"] if k else float("nan")  # grasps per solver second
    return {"padded_rate": pr, "per_count_rate": cr, "ipopt_rate": ir,
            "jaxgrasp_s_per_grasp": 1.0 / pr, "ipopt_s_per_grasp": 1.0 / ir if k else float("nan"),
            "ipopt_setup_s_per_grasp": ipopt["setup_s"] / k if k else float("nan"),
            "compile_ratio_per_count_over_padded": per_count["compile_s"] / padded["compile_s"],
            "rate_ratio_padded_over_per_count": pr / cr, "rate_ratio_jaxgrasp_over_ipopt": pr / ir,
            "target_met": padded["compilations"] == 1 and pr >= TARGET_RATE,
            "bucketed_rate": br, "rate_ratio_bucketed_over_ipopt": br / ir,
            "cpu_ms_per_grasp": {k: 1e3 * d["steady_cpu_s"] / count for k, d in
                                 (("padded", padded), ("bucketed", bucketed or {}), ("per_count", per_count))
                                 if "steady_cpu_s" in d},
            "issue41_met": max(pr, br) >= ISSUE41_RATE and max(pr, br) / ir >= ISSUE41_RATIO}


def lane_lines(lanes: dict) -> list[str]:
    """The solve stages' lanes by status: count, lane-steps, steps per lane, share."""
    total = sum(v[1] for k in lanes.values() for v in k.values())
    out = []
    for kind, by in lanes.items():
        out.append(f"{kind} lanes: " + "; ".join(
            f"{name} {n} lanes, {st} lane-steps ({st / max(n, 1):.1f} per lane, {100 * st / max(total, 1):.0f} %)"
            for name, (n, st) in by.items() if n and name != "no_start"))
    return out


def status_table(results: dict) -> list[str]:
    counts = np.asarray(results["num_contacts"])
    status = np.asarray(results["status"])
    lines = ["| N | " + " | ".join(STATUS) + " | total |", "|---|" + "---:|" * (len(STATUS) + 1)]
    for n in sorted(set(counts.tolist())) + ["all"]:
        sel = status if n == "all" else status[counts == n]
        lines.append(f"| {n} | " + " | ".join(str(int(np.sum(sel == c))) for c in range(len(STATUS))) + f" | {sel.size} |")
    return lines


def report(res: dict) -> str:
    p, c, i, s, a, ia = (res[k] for k in ("padded", "per_count", "ipopt", "summary", "agreement", "ipopt_agreement"))
    m = p["machine"]
    B = res["count"]
    L = [f"batch benchmark: {B} grasps (seed {res['seed']}, contacts 2..7), jax {m['jax']} ({m['backend']}, "
         f"{m['devices']} device(s)), {m['cpu_count']} CPUs ({m['cpus_usable']} usable), "
         f"persistent compilation cache: {m['persistent_compilation_cache'] or 'off'}",
         f"load average at start: {res['load_start']}", "",
         "| mode | compilations | compile s | first run s | steady s | steady grasps/s | peak MiB |",
         "|---|---:|---:|---:|---:|---:|---:|",
         f"| padded (one program) | {p['compilations']} | {p['compile_s']:.1f} | {p['first_run_s']:.2f} "
         f"| {p['steady_run_s']:.2f} | {s['padded_rate']:.1f} | {p['peak_mib']:.0f} |",
         f"| bucketed by count, leftovers carried up (one run) | {res['bucketed']['compilations']} "
         f"| {res['bucketed']['compile_s']:.1f} | {res['bucketed']['first_run_s']:.2f} "
         f"| {res['bucketed']['steady_run_s']:.2f} | {s['bucketed_rate']:.1f} | {res['bucketed']['peak_mib']:.0f} |",
         f"| per contact count | {c['compilations']} | {c['compile_s']:.1f} | {c['first_run_s']:.2f} "
         f"| {c['steady_run_s']:.2f} | {s['per_count_rate']:.1f} | {c['peak_mib']:.0f} |",
         f"| Ipopt, serial ({len(i['grasps'])} sampled) | - | - | - | {i['solver_s']:.2f} "
         f"| {s['ipopt_rate']:.2f} | {i['peak_mib']:.0f} |", "",
         f"ratios: per-count compile / padded compile = {s['compile_ratio_per_count_over_padded']:.2f}; "
         f"padded rate / per-count rate = {s['rate_ratio_padded_over_per_count']:.2f}; "
         f"jaxgrasp rate / Ipopt rate = {s['rate_ratio_jaxgrasp_over_ipopt']:.1f}",
         f"bucketed rate / Ipopt rate = {s['rate_ratio_bucketed_over_ipopt']:.1f}; CPU ms per grasp (steady, all "
         "threads): " + ", ".join(f"{k} {v:.1f}" for k, v in s["cpu_ms_per_grasp"].items()),
         f"issue 41 (>= {ISSUE41_RATE:.0f} grasps/s and >= {ISSUE41_RATIO:.0f}x Ipopt in one run): "
         f"{'met' if s['issue41_met'] else 'not met'}",
         f"target (one compilation, >= {TARGET_RATE:.0f} grasps/s): {'met' if s['target_met'] else 'not met'} "
         f"(measured {p['compilations']} compilation(s), {s['padded_rate']:.1f} grasps/s)", "",
         "bucketed segments (chunk " + str(res["bucketed"]["chunk"]) + "): " + ", ".join(
             f"padded to {g['contacts']}: {g['grasps']} grasps" for g in res["bucketed"]["segments"]),
         *lane_lines(p["lanes"]),
         "per contact count: " + "; ".join(
             f"N={g['contacts']}: {g['grasps']} grasps, compile {g['compile_s']:.1f} s, "
             f"{g['grasps'] / g['steady_run_s']:.1f} grasps/s, CPU {1e3 * g['steady_cpu_s'] / g['grasps']:.1f} ms/grasp"
             for g in c["groups"]),
         f"padded: steady wall incl. host-side stacking {p['steady_wall_s']:.2f} s, repeat runs "
         f"{', '.join(format(x, '.2f') for x in p['steady_runs_s'])} s, "
         f"deterministic {p['deterministic']}, compilations incl. repeats {p['compilations_total']}",
         "",
         f"padded vs per count: statuses {a['status_mismatches']} differ, limiting kind {a['limiting_kind_mismatches']}, "
         f"limiting contact {a['limiting_contact_mismatches']}; value max rel diff {a['value_max_rel_diff']:.1e} "
         f"({a['value_mismatches']} > {SAME_REL:g}), equilibrium energy max rel diff "
         f"{a['equilibrium_energy_max_rel_diff']:.1e} ({a['equilibrium_energy_mismatches']} > {SAME_REL:g}); "
         f"value max diff / equilibrium energy {a['value_max_diff_over_equilibrium_energy']:.1e}; "
         f"worst value: grasp {a['value_worst']['index']}, {a['value_worst']['padded_J']!r} J padded, "
         f"{a['value_worst']['per_count_J']!r} J per count",
         f"padded vs bucketed: statuses {res['bucketed_agreement']['status_mismatches']} differ, limiting kind "
         f"{res['bucketed_agreement']['limiting_kind_mismatches']}, limiting contact "
         f"{res['bucketed_agreement']['limiting_contact_mismatches']}; value max rel diff "
         f"{res['bucketed_agreement']['value_max_rel_diff']:.1e}; value max diff / equilibrium energy "
         f"{res['bucketed_agreement']['value_max_diff_over_equilibrium_energy']:.1e}",
         f"Ipopt (same starts): per grasp {s['ipopt_s_per_grasp']:.3f} s solver, "
         f"{s['ipopt_setup_s_per_grasp']:.3f} s NLP setup (apart); jaxgrasp {s['jaxgrasp_s_per_grasp'] * 1e3:.1f} ms "
         f"per grasp (steady padded); starts from one padded solve_problems call, {i['programs_s']:.1f} s",
         f"Ipopt agreement: status {ia['status_agree']}/{ia['grasps']}, value max rel diff "
         f"{'-' if ia['value_max_rel_diff'] is None else format(ia['value_max_rel_diff'], '.1e')} "
         f"({ia['both_stable']} both stable), jaxgrasp above Ipopt by > {OVER_REL:g} rel: {len(ia['overstated'])}"
         f", below: {len(ia['understated'])}"
         + (f"; status mismatches {ia['status_mismatches']}" if ia["status_mismatches"] else ""),
         f"Ipopt agreement of the bucketed run: status {res['bucketed_ipopt_agreement']['status_agree']}/"
         f"{res['bucketed_ipopt_agreement']['grasps']}, above Ipopt by > {OVER_REL:g} rel: "
         f"{len(res['bucketed_ipopt_agreement']['overstated'])}",
         "", "statuses of the set (padded):", *status_table(res["statuses"]), "",
         f"peak MiB by stage: padded after first call {p['peak_mib_after_first']:.0f}, at end {p['peak_mib']:.0f}; "
         "per count after each N: " + ", ".join(f"{g['peak_mib']:.0f}" for g in c["groups"]),
         "load average (1, 5, 15 min) at start / end of each phase: " + "; ".join(
             f"{k} {res[k]['load_start']} / {res[k]['load_end']}" for k in ("padded", "bucketed", "per_count", "ipopt")
            if "load_start" in res[k]),
         f"load average at end: {res['load_end']}; total {res['total_s']:.0f} s"
         + ("; LOAD ABOVE 3 during the run (other processes shared the 2 cores): wall rates are low, compare the "
            "CPU ms per grasp" if max(res["load_start"][0], res["load_end"][0], *(res[k]["load_end"][0] for k in
            ("padded", "bucketed", "per_count", "ipopt") if "load_end" in res[k])) > 3 else "")]
    return "\n".join(L)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="60 grasps, 6 Ipopt, 3 repeats (development)")
    p.add_argument("--count", type=int, default=None, help="grasps (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the grasp set and the Ipopt sample (default 0)")
    p.add_argument("--repeats", type=int, default=None, help="steady runs, median taken (default 2; quick 3)")
    p.add_argument("--ipopt", type=int, default=None, help="grasps solved with Ipopt (default 30)")
    p.add_argument("--json", type=Path, default=None, help="also write every number to this JSON file")
    p.add_argument("--phase", choices=("padded", "bucketed", "per-count", "ipopt"), default=None, help=argparse.SUPPRESS)
    p.add_argument("--out", type=Path, default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    quick = {"count": 60, "repeats": 3, "ipopt": 6} if args.quick else {"count": 1000, "repeats": 2, "ipopt": 30}
    for k, v in quick.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    return args


def main() -> None:
    args = parse_args()
    if args.phase is not None:
        run_phase_here(args)
        return
    res = {"count": args.count, "seed": args.seed, "repeats": args.repeats, "load_start": load()}
    t0 = time.perf_counter()
    log(f"{args.count} grasps, {args.ipopt} with Ipopt, {args.repeats} steady repeats")
    with tempfile.TemporaryDirectory() as tmp:
        res["padded"] = run_phase("padded", args, Path(tmp))
        res["bucketed"] = run_phase("bucketed", args, Path(tmp))
        res["per_count"] = run_phase("per-count", args, Path(tmp))
        res["ipopt"] = (run_phase("ipopt", args, Path(tmp)) if args.ipopt > 0 else
                        {"grasps": [], "solver_s": 0.0, "setup_s": 0.0, "programs_s": 0.0, "peak_mib": 0.0})
    res["agreement"] = agreement(res["padded"], res["per_count"])
    res["bucketed_agreement"] = agreement(res["padded"], res["bucketed"])
    res["bucketed_ipopt_agreement"] = ipopt_agreement(res["bucketed"], res["ipopt"])
    res["ipopt_agreement"] = ipopt_agreement(res["padded"], res["ipopt"])
    res["summary"] = summarize(res["padded"], res["per_count"], res["ipopt"], args.count, res["bucketed"])
    res["statuses"] = {"num_contacts": res["padded"]["num_contacts"], "status": res["padded"]["results"]["status"]}
    res["load_end"] = load()
    res["total_s"] = time.perf_counter() - t0
    print(report(res), flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
