"""Robustness of ``jaxgrasp.evaluate`` on a seeded set of varied valid grasps (issue #6).

The grasps come from ``tests/grasp_draws.py:build_grasp`` (2 to 5 fingertips on a
sphere or a box around the centre of mass, outward normals, random fingertips, masses
and gravity directions), contact counts cycling 2, 3, 4, 5. Every grasp is evaluated at
the default :class:`jaxgrasp.EvaluateOptions` through one ``jit(vmap(evaluate))`` per
contact count (fixed chunk size, padded). The script counts:

* grasp statuses (per contact count), grasps not converged, and problems (equilibrium or
  boundary) not converged;
* inconsistent results: a NaN or negative value, or status ``stable`` with value 0;
* on a sample checked against the independent CasADi/Ipopt multi-start reference
  (``tests/ipopt_reference.py``, run in a worker process while JAX evaluates): status
  mismatches, values above Ipopt's by more than ``1e-6`` relative (stability overstated),
  and, for information, values below it.

It writes ``experiments/robustness/robustness.md`` (the counts, and a literal reproduction of every
failing grasp). Full size (about 10-20 minutes on 2 cores)::

    nohup python experiments/robustness/robustness.py > experiments/robustness/robustness.log 2>&1 &

``--count 64 --ipopt 8 --out /tmp/r.md`` is a quick run.
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import math
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

STATUS = ("stable", "unstable", "infeasible", "not_converged")
REL = 1e-6


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1000, help="number of grasps (default 1000)")
    p.add_argument("--ipopt", type=int, default=60, help="grasps checked against Ipopt (default 60)")
    p.add_argument("--n-starts", type=int, default=24, help="Ipopt starts per problem (default 24)")
    p.add_argument("--seed", type=int, default=0, help="seed of the grasp set (default 0)")
    p.add_argument("--chunk", type=int, default=25, help="grasps per compiled batch (default 25)")
    p.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "robustness.md")
    return p.parse_args()


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def evaluate_all(grasps, chunk: int):
    """Evaluate every grasp (one compiled batch shape per contact count); NumPy results."""
    import jax

    import jaxgrasp
    from _lab import stack_same as stack, unstack

    fn = jax.jit(jax.vmap(lambda g: jaxgrasp.evaluate(g)))
    out = [None] * len(grasps)
    by_n = collections.defaultdict(list)
    for i, g in enumerate(grasps):
        by_n[g.num_contacts].append(i)
    timing = {}
    for n, idx in sorted(by_n.items()):
        t0 = time.perf_counter()
        t_first = None
        for s in range(0, len(idx), chunk):
            part = idx[s : s + chunk]
            gs = [grasps[i] for i in part]
            gs = gs + [gs[-1]] * (chunk - len(gs))
            res = jax.tree_util.tree_map(np.asarray, fn(stack(gs)))
            if t_first is None:
                t_first = time.perf_counter() - t0
            for k, i in enumerate(part):
                out[i] = unstack(res, k)
            log(f"N={n}: {min(s + chunk, len(idx))}/{len(idx)} grasps")
        total = time.perf_counter() - t0
        calls = -(-len(idx) // chunk)
        per_call = (total - t_first) / max(calls - 1, 1) if calls > 1 else float("nan")
        timing[n] = dict(grasps=len(idx), first_call_s=t_first, total_s=total, per_grasp_s=per_call / chunk)
    return out, timing


def classify(res) -> dict:
    status = STATUS[int(res.status)]
    bs = np.asarray(res.boundary_status)
    return dict(
        status=status,
        value=float(res.value),
        eq_not_converged=int(res.equilibrium_status) == 2,
        boundary_not_converged=int(np.sum(bs == 2)),
        problems=1 + bs.size,
        stable_zero=status == "stable" and not float(res.value) > 0.0,
        bad_value=not math.isfinite(float(res.value)) or float(res.value) < 0.0,
    )


def compare(res, ref) -> dict:
    """jaxgrasp result vs Ipopt reference dict."""
    js, rs = STATUS[int(res.status)], ref["status"]
    jv, rv = float(res.value), float(ref["value"])
    d = dict(jax_status=js, ipopt_status=rs, jax_value=jv, ipopt_value=rv)
    d["status_mismatch"] = js != rs
    both_stable = js == rs == "stable"
    d["overstated"] = both_stable and jv > rv * (1 + REL)
    d["understated"] = both_stable and jv < rv * (1 - REL)
    d["rel"] = (jv - rv) / rv if both_stable and rv > 0 and math.isfinite(rv) else float("nan")
    return d


def main() -> int:
    args = parse_args()
    import os

    # before jaxgrasp is imported (grasp_draws imports it): this process and its
    # spawned workers start warm (jaxgrasp's executable store)
    os.environ.setdefault("JAXGRASP_CACHE_DIR", str(Path.home() / ".cache" / "jaxgrasp" / "xla"))
    from _lab.grasp_draws import literal, seeded_grasps

    t_start = time.perf_counter()
    grasps = seeded_grasps(args.count, seed=args.seed)
    sample = list(range(min(args.ipopt, len(grasps))))
    log(f"{len(grasps)} grasps, {len(sample)} checked against Ipopt")

    # Ipopt reference in a worker process while JAX evaluates
    futures = {}
    pool = None
    if sample:
        from _lab import ipopt_reference

        ctx = multiprocessing.get_context("spawn")
        pool = concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=ctx)
        for i in sample:
            futures[i] = pool.submit(
                ipopt_reference.reference_evaluate, grasps[i].to_numpy(), n_starts=args.n_starts, seed=0
            )

    results, timing = evaluate_all(grasps, args.chunk)
    t_jax = time.perf_counter() - t_start
    log(f"JAX done in {t_jax:.0f} s")
    rows = [classify(r) for r in results]

    refs = {}
    for k, i in enumerate(sample):
        refs[i] = futures[i].result()
        if (k + 1) % 10 == 0:
            log(f"Ipopt: {k + 1}/{len(sample)}")
    if pool is not None:
        pool.shutdown()
    t_total = time.perf_counter() - t_start
    comps = {i: compare(results[i], refs[i]) for i in sample}

    write_report(args, grasps, results, rows, timing, comps, refs, t_jax, t_total, literal)
    log(f"wrote {args.out}")
    return 0


def write_report(args, grasps, results, rows, timing, comps, refs, t_jax, t_total, literal):
    import jaxgrasp

    ns = sorted({g.num_contacts for g in grasps})
    L = []
    L.append("# Robustness of `jaxgrasp.evaluate` on varied valid grasps (issue #6)")
    L.append("")
    L.append(
        f"Generated by `experiments/robustness/robustness.py --count {args.count} --ipopt {args.ipopt} "
        f"--n-starts {args.n_starts} --seed {args.seed} --chunk {args.chunk}` "
        f"on {time.strftime('%Y-%m-%d %H:%M')}; wall time {t_total:.0f} s "
        f"(JAX part {t_jax:.0f} s, compilations included). Grasps: "
        "`tests/grasp_draws.py:build_grasp` (2-5 fingertips on a sphere or box around the "
        "centre of mass, outward normals, random fingertips, masses, gravity directions), "
        "default `EvaluateOptions`."
    )
    L.append("")
    # ---- headline
    not_conv = [i for i, r in enumerate(rows) if r["status"] == "not_converged"]
    prob_nc = sum(r["boundary_not_converged"] + r["eq_not_converged"] for r in rows)
    probs = sum(r["problems"] for r in rows)
    stable_zero = [i for i, r in enumerate(rows) if r["stable_zero"]]
    bad = [i for i, r in enumerate(rows) if r["bad_value"]]
    mism = [i for i, c in comps.items() if c["status_mismatch"]]
    over = [i for i, c in comps.items() if c["overstated"]]
    under = [i for i, c in comps.items() if c["understated"]]
    L.append("## Summary")
    L.append("")
    L.append("| count | result | target |")
    L.append("|---|---|---|")
    L.append(f"| grasps evaluated | {len(rows)} | >= 1000 |")
    L.append(f"| grasps not converged | {len(not_conv)} | 0 |")
    L.append(f"| problems (equilibrium + 2N boundary) not converged | {prob_nc} of {probs} | 0 |")
    L.append(
        f"| ... of them in stable or not-converged grasps (where they can matter) | "
        f"{sum(r['boundary_not_converged'] + r['eq_not_converged'] for r in rows if r['status'] in ('stable', 'not_converged'))} | 0 |"
    )
    L.append(f"| NaN or negative values | {len(bad)} | 0 |")
    L.append(f"| status stable but value 0 | {len(stable_zero)} | 0 |")
    L.append(f"| grasps checked against Ipopt ({args.n_starts} starts) | {len(comps)} | >= 50 |")
    L.append(f"| status mismatches vs Ipopt | {len(mism)} | 0 |")
    L.append(f"| values above Ipopt's by > 1e-6 rel. (stability overstated) | {len(over)} | 0 |")
    L.append(f"| values below Ipopt's by > 1e-6 rel. (Ipopt missed a lower point, or jaxgrasp wrong) | {len(under)} | (info) |")
    L.append("")
    # ---- statuses per N
    L.append("## Statuses")
    L.append("")
    L.append("| N | " + " | ".join(STATUS) + " | total |")
    L.append("|---|" + "---|" * (len(STATUS) + 1))
    for n in ns + ["all"]:
        sel = [r for g, r in zip(grasps, rows) if n == "all" or g.num_contacts == n]
        c = collections.Counter(r["status"] for r in sel)
        L.append(f"| {n} | " + " | ".join(str(c.get(s, 0)) for s in STATUS) + f" | {len(sel)} |")
    L.append("")
    kinds = collections.Counter(
        (jaxgrasp.model.BoundaryKind.labels()[int(r.limiting_kind)]) for r, row in zip(results, rows) if row["status"] == "stable" and int(r.limiting_kind) >= 0
    )
    L.append(f"Limiting boundary of the stable grasps: {dict(kinds)}.")
    vals = np.array([r["value"] for r in rows if r["status"] == "stable"])
    if vals.size:
        L.append(
            f"Stable values: min {vals.min():.3g} J, median {np.median(vals):.3g} J, max {vals.max():.3g} J."
        )
    L.append("")
    L.append("Timing (this machine, shared; the first call of each N includes its compilation):")
    L.append("")
    L.append("| N | grasps | first call s | total s | s per grasp after compilation |")
    L.append("|---|---|---|---|---|")
    for n, t in sorted(timing.items()):
        L.append(f"| {n} | {t['grasps']} | {t['first_call_s']:.1f} | {t['total_s']:.1f} | {t['per_grasp_s']:.3f} |")
    L.append("")
    # ---- Ipopt
    if comps:
        L.append("## Against Ipopt")
        L.append("")
        pairs = collections.Counter((c["jax_status"], c["ipopt_status"]) for c in comps.values())
        L.append("| jaxgrasp status | Ipopt status | grasps |")
        L.append("|---|---|---|")
        for (a, b), k in sorted(pairs.items()):
            L.append(f"| {a} | {b} | {k} |")
        L.append("")
        rels = np.array([c["rel"] for c in comps.values() if math.isfinite(c["rel"])])
        if rels.size:
            L.append(
                f"Both stable: {rels.size} grasps; relative difference (jaxgrasp - Ipopt)/Ipopt: "
                f"min {rels.min():.2e}, median {np.median(rels):.2e}, max {rels.max():.2e}."
            )
            L.append("")
    # ---- failures, literally
    def block(title, idx, extra=None):
        if not idx:
            return
        L.append(f"## {title}")
        L.append("")
        for i in idx:
            r = results[i]
            L.append(f"- grasp {i} (N={grasps[i].num_contacts}): {r.explain()}")
            L.append(
                f"  boundary_status={np.asarray(r.boundary_status).tolist()}, "
                f"equilibrium_status={int(r.equilibrium_status)}, value={float(r.value)!r}"
                f", min equilibrium slip/force margin={float(np.min(np.asarray(r.equilibrium_margins)[1:])):.3g}"
            )
            if extra is not None:
                L.append(f"  {extra(i)}")
            L.append("")
            L.append("  ```python")
            L.append("  " + literal(grasps[i]))
            L.append("  ```")
        L.append("")

    def ipopt_line(i):
        if i not in comps:
            return "(not in the Ipopt sample)"
        c = comps[i]
        ref = refs[i]
        return (
            f"Ipopt: {c['ipopt_status']} value={c['ipopt_value']!r} limiting={ref['limiting']}; "
            f"jaxgrasp: {c['jax_status']} value={c['jax_value']!r}"
        )

    block("Not converged", not_conv, ipopt_line)
    block("Status stable with value 0", stable_zero, ipopt_line)
    block("NaN or negative values", bad)
    block("Status mismatches against Ipopt", mism, ipopt_line)
    block("Values above Ipopt's (stability overstated)", over, ipopt_line)
    block("Values below Ipopt's (for information)", under, ipopt_line)
    args.out.write_text("\n".join(L) + "\n", encoding="utf-8")


if __name__ == "__main__":
    sys.exit(main())
