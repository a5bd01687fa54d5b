"""Time to the first result, in fresh processes: trace, lower, XLA compile, cache loads.

Issue 13 ("every process starts warm") asks for these numbers before and after each
change to the solver or the caches. Every measurement runs in a new Python process; a
cold one gets its own empty cache folder (``JAXGRASP_CACHE_DIR``), a warm one the folder
a cold run of the same kind filled. Each is repeated ``--runs`` times (default 3) and the
median reported, with the load average (1 min) when it started:

* ``evaluate.*``: the cube (``jaxgrasp.presets.cube(6e5, 0.002)``, default options),
  caches off, in stages: ``import`` (``import jaxgrasp``), ``trace``, ``lower`` and
  ``compile`` (``evaluate_compiled.trace(..., settle=False).lower().compile(LATENCY_CPU_OPTIONS)``,
  the program a concrete ``evaluate`` runs first), ``first_run`` (the
  compiled program's first call); ``hlo_lines``: lines of the lowered StableHLO;
* ``evaluate_cold.first`` / ``evaluate_warm.first``: the first ``jaxgrasp.evaluate(cube)``
  call end to end, with ``JAXGRASP_CACHE_DIR`` set to an empty folder (trace, export,
  compile) and to a filled one (load the stored program); beside it ``.import`` and the
  part of the call JAX reports (``jax.monitoring`` time spans) as ``.trace``, ``.lower``
  (to StableHLO) and ``.xla`` (XLA compilation or persistent-cache load), ``.rest``
  the remainder (export, deserialization, the run);
* ``sweep_cold.*`` / ``sweep_warm.*``: the default ``jaxgrasp sweep`` (the paper's cube
  grid, 9 x 41 points): ``compile`` (``SweepResult.compile_seconds``), ``run`` (its
  solving) and ``wall`` (the process);
* ``cli_evaluate_cold.wall`` / ``cli_evaluate_warm.wall``: wall time of the process
  ``jaxgrasp evaluate examples/cube.toml``.

Writes the numbers to ``experiments/startup/compile_time.json`` and appends what it prints to
``experiments/startup/compile_time.log`` (``--quick``: ``compile_time_quick.*``, one run each).
``--compare OLD.json`` prints the medians of an earlier run beside these, with the ratio
new / old: rerun after a change and compare (same machine, similar load).

    python experiments/startup/compile_time.py [--runs 3] [--quick] [--compare OLD.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
CUBE_TOML = ROOT / "examples" / "cube.toml"

STAGES = r"""
import json, time
t0 = time.perf_counter()
import jax, numpy as np
import jaxgrasp
from jaxgrasp.engine import LATENCY_CPU_OPTIONS, evaluate_compiled, stats as store_stats
t1 = time.perf_counter()
grasp, options, temperature = jaxgrasp.presets.cube(6e5, 0.002), jaxgrasp.EvaluateOptions(), np.float64(0.0)
traced = evaluate_compiled.trace(grasp, temperature, options, False)  # settle=False: what evaluate runs first
t2 = time.perf_counter()
lowered = traced.lower()
t3 = time.perf_counter()
compiled = lowered.compile(LATENCY_CPU_OPTIONS)  # as jaxgrasp.evaluate compiles it on a CPU
t4 = time.perf_counter()
jax.block_until_ready(compiled(grasp, temperature))
t5 = time.perf_counter()
print("RESULT " + json.dumps({"import": t1 - t0, "trace": t2 - t1, "lower": t3 - t2, "compile": t4 - t3,
                              "first_run": t5 - t4, "hlo_lines": len(lowered.as_text().splitlines())}))
"""

FIRST_EVALUATE = r"""
import json, time
t0 = time.perf_counter()
import jax
spans = {}  # JAX's own stage events: name -> [(start, end)], nested traces included
jax.monitoring.register_event_time_span_listener(
    lambda event, start, end, **_: spans.setdefault(event.rsplit("/", 1)[-1], []).append((start, end)))
import jaxgrasp
t1 = time.perf_counter()
jax.block_until_ready(jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002)))
t2 = time.perf_counter()

def covered(intervals):  # seconds covered by the union of the intervals
    total, reach = 0.0, float("-inf")
    for a, b in sorted(intervals):
        total += max(0.0, b - max(a, reach))
        reach = max(reach, b)
    return total

stages = {name: covered(spans.get(event, [])) for name, event in
          [("trace", "jaxpr_trace_duration"), ("lower", "jaxpr_to_mlir_module_duration"),
           ("xla", "backend_compile_duration")]}
stages["rest"] = (t2 - t1) - covered([iv for event in spans.values() for iv in event])
print("RESULT " + json.dumps({"import": t1 - t0, "first": t2 - t1, **stages, "stats": jaxgrasp.engine.stats()}))
"""
FIRST_EVALUATE_KEYS = ("first", "import", "trace", "lower", "xla", "rest")


class Log:
    """Prints a line and keeps it for the ``.log`` file."""

    def __init__(self):
        self.lines: list[str] = []

    def __call__(self, line: str = "") -> None:
        print(line, flush=True)
        self.lines.append(line)


def load() -> float:
    """The 1-minute load average."""
    return os.getloadavg()[0]


def run_process(argv: list[str], cache: Path | None) -> tuple[float, dict | None]:
    """Run ``argv`` in the repository with ``JAXGRASP_CACHE_DIR=cache`` (``None``: unset);
    its wall time in s and the JSON it printed after ``RESULT `` (``None`` without)."""
    env = {k: v for k, v in os.environ.items() if k != "JAXGRASP_CACHE_DIR"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    if cache is not None:
        env["JAXGRASP_CACHE_DIR"] = str(cache)
    t0 = time.perf_counter()
    p = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode:
        sys.exit(f"{' '.join(argv[:4])} ... failed ({p.returncode}):\n{p.stderr[-3000:]}")
    found = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    return wall, (json.loads(found[-1][len("RESULT ") :]) if found else None)


class Bench:
    """Collects samples (with the load average at their start) and prints each run."""

    def __init__(self, log: Log, tmp: Path):
        self.log, self.tmp = log, tmp
        self.samples: dict[str, list[float]] = {}
        self.loads: dict[str, list[float]] = {}
        self._folders = 0

    def folder(self) -> Path:
        """A new, empty (not yet created) cache folder."""
        self._folders += 1
        return self.tmp / f"cache{self._folders}"

    def add(self, label: str, numbers: dict[str, float], load_at_start: float) -> None:
        for name, x in numbers.items():
            key = f"{label}.{name}"
            self.samples.setdefault(key, []).append(float(x))
            self.loads.setdefault(key, []).append(load_at_start)
        shown = ", ".join(f"{n} {number(n, x)}" for n, x in numbers.items())
        self.log(f"  {label}: {shown} (load {load_at_start:.2f})")


def python(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def command(*args: str) -> list[str]:
    return [sys.executable, "-m", "jaxgrasp", *args]


def measure_stages(b: Bench, runs: int) -> None:
    for _ in range(runs):
        la = load()
        _, r = run_process(python(STAGES), None)
        b.add("evaluate", r, la)


def measure_first_evaluate(b: Bench, runs: int) -> None:
    """Cold: each in an empty folder; warm: in the folder of the last cold run."""
    for _ in range(runs):
        folder, la = b.folder(), load()
        _, r = run_process(python(FIRST_EVALUATE), folder)
        b.add("evaluate_cold", {k: r[k] for k in FIRST_EVALUATE_KEYS}, la)
    for _ in range(runs):
        la = load()
        _, r = run_process(python(FIRST_EVALUATE), folder)
        assert r["stats"]["traced"] == 0, r  # a warm run loads the stored program
        b.add("evaluate_warm", {k: r[k] for k in FIRST_EVALUATE_KEYS}, la)


def measure_cli_evaluate(b: Bench, runs: int) -> None:
    argv = command("evaluate", str(CUBE_TOML))
    for _ in range(runs):
        folder, la = b.folder(), load()
        wall, _ = run_process(argv, folder)
        b.add("cli_evaluate_cold", {"wall": wall}, la)
    for _ in range(runs):
        la = load()
        wall, _ = run_process(argv, folder)
        b.add("cli_evaluate_warm", {"wall": wall}, la)


def measure_sweep(b: Bench, runs: int) -> None:
    def one(label: str, folder: Path) -> None:
        import numpy as np

        out, la = b.tmp / f"sweep-{label}", load()
        wall, _ = run_process(command("sweep", "--no-plot", "--quiet", "--out", str(out)), folder)
        with np.load(out / "sweep.npz") as z:
            numbers = {"compile": float(z["compile_seconds"]), "run": float(z["run_seconds"]), "wall": wall}
        shutil.rmtree(out)
        b.add(label, numbers, la)

    for _ in range(runs):
        folder = b.folder()
        one("sweep_cold", folder)
    for _ in range(runs):
        one("sweep_warm", folder)


def summary(b: Bench) -> dict:
    """Per measurement: its samples, their median and the load averages."""
    return {
        k: {"median": statistics.median(v), "samples": v, "load": b.loads[k]}
        for k, v in b.samples.items()
    }


def number(key: str, x: float | None) -> str:
    """``x`` as the table shows it: seconds to 3 digits, a line count whole."""
    if x is None:
        return "-"
    return f"{x:.0f}" if key.endswith("hlo_lines") else f"{x:.3g} s"


def print_table(log: Log, results: dict, old: dict | None) -> None:
    if old is None:
        log(f"{'measurement':<28} {'median':>10}   samples")
        for k, r in results.items():
            samples = ", ".join(number(k, x) for x in r["samples"])
            log(f"{k:<28} {number(k, r['median']):>10}   {samples}")
        return
    log(f"{'measurement':<28} {'old':>10} {'new':>10} {'new/old':>8}")
    for k in list(old) + [k for k in results if k not in old]:
        o, n = old.get(k, {}).get("median"), results.get(k, {}).get("median")
        ratio = f"{n / o:.2f}" if o and n is not None else "-"
        log(f"{k:<28} {number(k, o):>10} {number(k, n):>10} {ratio:>8}")


def git_commit() -> str:
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "jaxgrasp"], cwd=ROOT, capture_output=True, text=True)
        return rev.stdout.strip() + (" + uncommitted changes" if dirty.stdout.strip() else "")
    except OSError:
        return "unknown"


def write_atomically(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=None, help="repetitions of each measurement (default 3, --quick 1)")
    ap.add_argument("--quick", action="store_true", help="one run each, written to compile_time_quick.*")
    ap.add_argument("--compare", type=Path, metavar="OLD.json", help="print an earlier run's medians beside")
    ap.add_argument("--only", nargs="+", choices=["stages", "evaluate", "cli", "sweep"], help="measure only these")
    args = ap.parse_args()
    runs = args.runs or (1 if args.quick else 3)
    stem = HERE / ("compile_time_quick" if args.quick else "compile_time")
    old = json.loads(args.compare.read_text())["results"] if args.compare else None

    import jax

    log = Log()
    meta = {
        "commit": git_commit(),
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "runs": runs,
        "jax": jax.__version__,
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "load_before": os.getloadavg(),
    }
    log(f"## compile_time.py --runs {runs}: commit {meta['commit']}, {meta['date']}, jax {meta['jax']}, "
        f"{meta['cpus']} CPUs, load average {meta['load_before'][0]:.2f} {meta['load_before'][1]:.2f} "
        f"{meta['load_before'][2]:.2f}")
    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="jaxgrasp-compile-time-"))
    steps = {"stages": measure_stages, "evaluate": measure_first_evaluate, "cli": measure_cli_evaluate,
             "sweep": measure_sweep}
    try:
        b = Bench(log, tmp)
        for name, step in steps.items():
            if args.only is None or name in args.only:
                step(b, runs)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    meta["load_after"] = os.getloadavg()
    meta["seconds"] = time.perf_counter() - t0
    results = summary(b)
    log(f"medians of {runs} (load average after: {meta['load_after'][0]:.2f}; {meta['seconds']:.0f} s in all)")
    print_table(log, results, old)
    write_atomically(stem.with_suffix(".json"), json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    with open(stem.with_suffix(".log"), "a") as fh:
        fh.write("\n".join(log.lines) + "\n\n")


if __name__ == "__main__":
    main()
