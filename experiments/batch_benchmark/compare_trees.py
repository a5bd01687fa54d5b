"""Cold start of two source trees of jaxgrasp, side by side, in alternating fresh processes.

For a change that should not cost time (issue 34 moved every module and declared the
evaluation pipeline once), this times the same work on the tree before and the tree after,
alternating ``A, B, A, B, ...`` so that both see the same load, and prints each median and
the ratio B / A with the load average (1 min) of every run:

* ``evaluate``: ``import jaxgrasp`` and the first ``jaxgrasp.evaluate(cube)`` (trace,
  lower, compile, run), caches off;
* ``sweep``: the default sweep's compile (``SweepResult.compile_seconds``) and run, caches
  off, on the paper's cube grid (9 x 41 points);
* the values of both, which must agree (to 1e-12 relative).

    git worktree add /tmp/before <commit>
    python experiments/batch_benchmark/compare_trees.py /tmp/before . [--runs 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

PROBE = r"""
import json, os, sys, time
t0 = time.perf_counter()
import numpy as np
import jaxgrasp
t1 = time.perf_counter()
cube = jaxgrasp.presets.cube(6e5, 0.002)
r = jaxgrasp.evaluate(cube)
float(r.value)
t2 = time.perf_counter()
out = {"import": t1 - t0, "evaluate": t2 - t1, "value": float(r.value)}
if sys.argv[1] == "sweep":
    s = jaxgrasp.sweep(jaxgrasp.presets.cube(), young_modulus=np.linspace(2e5, 1e6, 9),
                       initial_deformation=np.linspace(1e-3, 5e-3, 41))
    out.update(sweep_compile=s.compile_seconds, sweep_run=s.run_seconds,
               sweep_values=np.nan_to_num(np.asarray(s.value)).ravel().tolist())
print(json.dumps(out))
"""


def run_once(tree: Path, what: str) -> dict:
    """One fresh process of ``tree``, caches off, in an empty folder."""
    with tempfile.TemporaryDirectory() as folder:
        env = {k: v for k, v in os.environ.items() if k != "JAXGRASP_CACHE_DIR"}
        env["PYTHONPATH"] = str(tree)
        load = os.getloadavg()[0]
        proc = subprocess.run([sys.executable, "-c", PROBE, what], capture_output=True, text=True, env=env,
                              cwd=folder, timeout=900)
    if proc.returncode:
        raise SystemExit(f"{tree}: {proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["load"] = load
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--what", choices=("evaluate", "sweep"), default="sweep")
    args = ap.parse_args()
    trees = {"A": args.before.resolve(), "B": args.after.resolve()}
    runs: dict[str, list[dict]] = {"A": [], "B": []}
    for i in range(args.runs):
        for name, tree in trees.items():
            r = run_once(tree, args.what)
            runs[name].append(r)
            print(f"run {i + 1} {name}: " + ", ".join(
                f"{k} {v:.3f}" for k, v in r.items() if k not in ("value", "sweep_values")), flush=True)
    print(f"A = {trees['A']}\nB = {trees['B']}")
    for key in [k for k in runs["A"][0] if k not in ("value", "sweep_values", "load")]:
        a = statistics.median(r[key] for r in runs["A"])
        b = statistics.median(r[key] for r in runs["B"])
        print(f"{key:>14}: A {a:7.3f} s   B {b:7.3f} s   B/A {b / a:5.2f}")
    va = [r["value"] for r in runs["A"] + runs["B"]]
    print(f"evaluate value: A {runs['A'][0]['value']!r}  B {runs['B'][0]['value']!r}  "
          f"max rel diff {max(abs(v - va[0]) for v in va) / abs(va[0]):.1e}")
    if args.what == "sweep":
        import numpy as np

        sa, sb = np.array(runs["A"][0]["sweep_values"]), np.array(runs["B"][0]["sweep_values"])
        print(f"sweep values: max abs diff {np.max(np.abs(sa - sb)):.1e} J over {sa.size} points")


if __name__ == "__main__":
    main()
