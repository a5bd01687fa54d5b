"""Segments by contact count in the engine (issue 41, item 1): a mixed set evaluated by the
engine's plan (``jaxgrasp.engine.plan_widths``: each count at a width of its own
where the saving pays for a compilation) against the same set padded to its widest count
in one program, side by side in one run.

Sets (``tests/grasp_draws.py:build_grasp``, seeded):

* ``mixed``: ``--mixed`` grasps (default 1000), contact counts cycling 2..7 (the
  ``batch_benchmark.py`` set): a few hundred of each count, where the plan should keep
  one program;
* ``two-and-five``: ``--twos`` 2-contact grasps and ``--fives`` 5-contact ones (defaults
  20,000 and 2,000; a planner's two-finger grasps with a hand's): where it should split;
* ``mixed-large``: ``--large`` grasps (default 30,000) of counts cycling 2..7, 5000 of
  each: where it should split into a few programs, counts grouped.

Each (set, mode) runs in a fresh subprocess with an empty executable store of its own,
so compile time counts as a first run on a new machine pays it: wall seconds of one
``jaxgrasp.evaluate_batch`` call (compilation included), its compile and run seconds,
the process's CPU seconds over the call (every thread), peak RSS. Modes: ``padded``
(``plan_widths`` replaced by "every count at the widest") and ``planned`` (the engine's
default). The parent compares the two modes' statuses and values, prints the planned
widths, the cost model's CPU estimate of each mode beside the measured CPU, and the load
average.

Full size (about 15 minutes on 2 cores)::

    python experiments/padding_and_segments/segment_plan.py 2>&1 | tee experiments/padding_and_segments/segment_plan.log

Development: ``--quick`` (mixed 120, two-and-five 600 + 60, mixed-large 600).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

from _lab import agreement, say  # noqa: E402


def make_set(name: str, args) -> list:
    from _lab.grasp_draws import NumpyDraw, build_grasp

    if name in ("mixed", "mixed-large"):
        rng = np.random.default_rng([args.seed, 1])
        return [build_grasp(NumpyDraw(rng), n=2 + i % 6) for i in range(args.mixed if name == "mixed" else args.large)]
    rng = np.random.default_rng([args.seed, 2])
    counts = [2] * args.twos + [5] * args.fives
    rng.shuffle(counts)  # mixed through the file, as a dataset would have them
    return [build_grasp(NumpyDraw(rng), n=int(n)) for n in counts]


def run_mode(args) -> None:
    """In the subprocess: one evaluate_batch of the set in the mode; a JSON line of figures,
    the statuses and values to ``--save``."""
    import jaxgrasp
    from jaxgrasp.engine import plan_widths
    from jaxgrasp.engine import grasps_by_count

    grasps = make_set(args.set, args)
    if args.mode == "padded":
        plan_widths = lambda counts, platform: {c: max(counts) for c in counts}
    widths = plan_widths(grasps_by_count([g.num_contacts for g in grasps]), "cpu")
    cpu0, t0 = time.process_time(), time.perf_counter()
    res = jaxgrasp.evaluate_batch(grasps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    np.savez(args.save, status=np.asarray(res.status), value=np.asarray(res.value),
             energy=np.asarray(res.equilibrium_energy))
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "compile_s": res.compile_seconds, "run_s": res.run_seconds,
                      "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "widths": {int(k): int(v) for k, v in widths.items()}, "grasps": len(grasps)}))


def estimate(counts: dict[int, int], widths: dict[int, int]) -> float:
    """The cost model's CPU seconds for ``widths``: a compilation per width, each grasp at its width."""
    from jaxgrasp.engine import COMPILE_CPU_SECONDS, grasp_cpu_seconds

    return len(set(widths.values())) * COMPILE_CPU_SECONDS + sum(
        n * grasp_cpu_seconds(c, widths[c]) for c, n in counts.items())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mixed", type=int, default=1000)
    p.add_argument("--twos", type=int, default=20_000)
    p.add_argument("--fives", type=int, default=2_000)
    p.add_argument("--large", type=int, default=30_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--set", help=argparse.SUPPRESS)
    p.add_argument("--mode", help=argparse.SUPPRESS)
    p.add_argument("--save", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.quick:
        args.mixed, args.twos, args.fives, args.large = 120, 600, 60, 600
    if args.mode:
        return run_mode(args)

    import jax

    say(f"$ python experiments/padding_and_segments/segment_plan.py {' '.join(sys.argv[1:])}")
    say(f"jax {jax.__version__}, {os.cpu_count()} CPUs; load average {os.getloadavg()}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("mixed", "two-and-five", "mixed-large"):
            out = {}
            for mode in ("padded", "planned"):
                store = Path(tmp) / f"store-{name}-{mode}"
                save = Path(tmp) / f"{name}-{mode}.npz"
                env = dict(os.environ, JAXGRASP_CACHE_DIR=str(store))
                cmd = [sys.executable, __file__, "--set", name, "--mode", mode, "--save", str(save),
                       "--mixed", str(args.mixed), "--twos", str(args.twos), "--fives", str(args.fives),
                       "--large", str(args.large), "--seed", str(args.seed)]
                done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
                if done.returncode:
                    raise SystemExit(done.stderr[-3000:])
                fig = json.loads(done.stdout.strip().splitlines()[-1])
                fig["saved"] = dict(np.load(save))
                out[mode] = fig
                say(f"{name}, {mode}: {fig['grasps']} grasps, widths {fig['widths']}: wall {fig['wall_s']:.1f} s "
                    f"(compile {fig['compile_s']:.1f}, run {fig['run_s']:.1f}), CPU {fig['cpu_s']:.1f} s, "
                    f"{fig['grasps'] / fig['wall_s']:.1f} grasps/s incl. compile, peak {fig['peak_mib']:.0f} MiB")
            pad, plan = out["padded"], out["planned"]
            counts = {}
            for g in make_set(name, args):
                counts[g.num_contacts] = counts.get(g.num_contacts, 0) + 1
            line = agreement(plan["saved"]["status"], plan["saved"]["value"], pad["saved"]["status"],
                             pad["saved"]["value"])
            a, b = plan["saved"], pad["saved"]
            both = np.isfinite(a["value"]) & np.isfinite(b["value"])
            diff = np.abs(a["value"] - b["value"])[both]
            rel = diff / np.maximum(np.abs(b["value"][both]), 1e-300)
            of_energy = diff / np.maximum(np.abs(b["energy"][both]), 1e-300)
            say(f"{name}: planned against padded: {line}; values differing by more than 1e-9 relative: "
                f"{int(np.sum(rel > 1e-9))} of {both.sum()}; largest difference against the equilibrium energy "
                f"{of_energy.max() if of_energy.size else 0.0:.1e}")
            rows.append((name, counts, pad, plan, estimate(counts, {int(k): v for k, v in pad["widths"].items()}),
                         estimate(counts, {int(k): v for k, v in plan["widths"].items()})))
    print(f"\nsegments by contact count, {os.cpu_count()} CPUs, load average at the end {os.getloadavg()}\n")
    print("| set | grasps by count | mode | widths | compile s | run s | wall s | CPU s (model) | peak MiB |")
    print("|---|---|---|---|---:|---:|---:|---:|---:|")
    for name, counts, pad, plan, est_pad, est_plan in rows:
        for mode, fig, est in (("padded", pad, est_pad), ("planned", plan, est_plan)):
            widths = ", ".join(f"{k}->{v}" for k, v in sorted(fig["widths"].items(), key=lambda kv: int(kv[0])))
            print(f"| {name} | {dict(sorted(counts.items()))} | {mode} | {widths} | {fig['compile_s']:.1f} | "
                  f"{fig['run_s']:.1f} | {fig['wall_s']:.1f} | {fig['cpu_s']:.1f} ({est:.1f}) | {fig['peak_mib']:.0f} |")
    print()
    for name, _, pad, plan, _, _ in rows:
        print(f"{name}: planned / padded wall {plan['wall_s'] / pad['wall_s']:.2f}, CPU {plan['cpu_s'] / pad['cpu_s']:.2f}")


if __name__ == "__main__":
    main()
