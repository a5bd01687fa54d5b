"""Where a batch's time goes (issue 41): seconds per pipeline stage and lane-steps per
lane kind, for chunks of the batch benchmark's mixed set padded to 7 contacts and for
chunks of one contact count.

    python experiments/batch_benchmark/profile_batch.py [--grasps 128] [--counts 2,7] [--mixed] [--stall-growth-max 10]

Each stage of the compiled chunk evaluator is timed (``block_until_ready`` after each
call, so the pipeline's own overlap is lost: per-stage seconds, not the run's); each
solve stage's lanes are counted by status with their steps. Load average printed.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

from batch_benchmark import make_grasps  # noqa: E402

STATUS = ("converged", "infeasible", "not_converged", "no_start")

# What the current profile() call collects: the compiled evaluators are cached and keep
# the wrapped stages of their first profile, so the wrappers write here, not into the
# first call's own lists.
_SINK: dict = {}


def profile(grasps, label: str, repeats: int = 2, options=None, chunk_size=None) -> dict:
    import jax

    import jaxgrasp
    from _lab import module_of
    from jaxgrasp.engine import compiled_evaluator

    # no public hook shows a stage's results: this instrument replaces the engine's evaluator factory
    _evaluator = module_of(compiled_evaluator)

    options = options or jaxgrasp.EvaluateOptions()
    times = _SINK["times"] = collections.defaultdict(float)
    lanes = _SINK["lanes"] = []
    real = compiled_evaluator

    def timed(*a, **k):
        fn, s = real(*a, **k)
        if getattr(fn, "_profiled", False):
            return fn, s
        for name, stage in list(fn.stages.items()):
            def wrap(*xs, _stage=stage, _name=name):
                t0, c0 = time.perf_counter(), time.process_time()
                out = jax.block_until_ready(_stage(*xs))
                _SINK["times"][_name] += time.perf_counter() - t0
                _SINK["times"][_name + " cpu"] += time.process_time() - c0
                if _name == "lanes":
                    _SINK["lanes"].append((np.asarray(out[4]), np.asarray(out[8])))
                return out
            fn.stages[name] = wrap
        fn._profiled = True
        return fn, s

    _evaluator.compiled_evaluator = timed
    try:
        res = jaxgrasp.evaluate_batch(grasps, options=options, chunk_size=chunk_size)  # compile
        first_compile = res.compile_seconds
        times.clear(); lanes.clear()
        walls = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = jaxgrasp.evaluate_batch(grasps, options=options, chunk_size=chunk_size)
            walls.append(time.perf_counter() - t0)
    finally:
        _evaluator.compiled_evaluator = real
    count = grasps.positions.shape[0] if hasattr(grasps, "positions") else len(grasps)  # one batched Grasp, or a list
    out = {"label": label, "grasps": count, "compile_s": first_compile,
           "wall_s": min(walls), "rate": count / min(walls), "load": os.getloadavg()[0],
           "stage_s": {k: v / repeats for k, v in times.items()}}
    kinds = {}
    for i, (st, sp) in enumerate(lanes[: len(lanes) // repeats]):
        which = "eq" if i % 2 == 0 else "boundary"
        for code, name in enumerate(STATUS):
            sel = st == code
            k = kinds.setdefault(f"{which}:{name}", [0, 0, 0])
            k[0] += int(sel.sum()); k[1] += int(sp[sel].sum()); k[2] = max(k[2], int(sp[sel].max(initial=0)))
        k = kinds.setdefault(f"{which}:lanes_total", [0, 0, 0])
        k[0] += st.size
    out["lanes"] = kinds
    for f in ("status", "value", "limiting_kind", "limiting_contact", "equilibrium_energy"):
        out[f] = getattr(res, f)
    return out


def show(p: dict) -> None:
    print(f"== {p['label']}: {p['grasps']} grasps, compile {p['compile_s']:.1f} s, wall {p['wall_s']:.2f} s, "
          f"{p['rate']:.1f} grasps/s, load {p['load']:.2f}")
    print("   stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in p["stage_s"].items()))
    for k, (n, s, m) in sorted(p["lanes"].items()):
        if n:
            print(f"   {k:26s} lanes {n:7d} steps {s:8d} mean {s / max(n, 1):6.1f} max {m}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grasps", type=int, default=128)
    ap.add_argument("--counts", default="")
    ap.add_argument("--mixed", action="store_true")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=None)
    ap.add_argument("--slots", type=int, default=128)
    ap.add_argument("--stall-growth-max", type=float, default=None,
                    help="SolverOptions.stall_growth_max (10 = rho_growth: the fixed tenfold growth of before issue 41 item 2)")
    a = ap.parse_args()
    import jaxgrasp  # noqa: F401

    allg = make_grasps(1000, 0)
    import dataclasses
    opts = jaxgrasp.EvaluateOptions()
    opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, max_slots=a.slots))
    if a.stall_growth_max is not None:
        opts = dataclasses.replace(opts, solver=dataclasses.replace(opts.solver, stall_growth_max=a.stall_growth_max))
    if a.mixed:
        show(profile(allg[: a.grasps], f"mixed (padded to 7), chunk {a.chunk}, slots {a.slots}", a.repeats, options=opts, chunk_size=a.chunk))
    for n in [int(c) for c in a.counts.split(",") if c]:
        g = [x for x in allg if x.num_contacts == n][: a.grasps]
        show(profile(g, f"N={n}, chunk {a.chunk}, slots {a.slots}", a.repeats, options=opts, chunk_size=a.chunk))


if __name__ == "__main__":
    main()
