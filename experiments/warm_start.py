"""A warm library (issue 35, item 4): the README's Python example, run twice in fresh processes.

Each run is a new Python process with a fresh, empty home folder (``HOME`` set to a new
temporary folder; ``JAXGRASP_CACHE_DIR`` and ``XDG_CACHE_HOME`` removed), so that the
only cache is the one ``import jaxgrasp`` turns on by itself, in
``~/.cache/jaxgrasp/xla/jaxgrasp-executables``. The first run compiles and stores the
evaluators; the second, another process with the same home, loads them. The script is
the README's example (evaluate the cube of ``examples/cube.toml``, then
``evaluate_batch`` of three cubes), with logging at INFO level so that the compilation
reports show, and the cache counters printed at the end.

Prints each run's wall time (process start to exit), the ratio first / second, the
1-minute load average before each run, the compilation reports of each run and the cache
counters, and appends it to ``experiments/warm_start.log``. Done when the second run is
at least 5x faster than the first.

    python experiments/warm_start.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LOG = ROOT / "experiments" / "warm_start.log"

EXAMPLE = """
import logging, json, sys
logging.basicConfig(level=logging.INFO, format="%(message)s")

import jaxgrasp

grasp = jaxgrasp.load("examples/cube.toml")      # SI units: m, Pa, N, kg
result = jaxgrasp.evaluate(grasp)
print(result.value, result.status_name)          # J, 'stable'

grasps = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=0.002) for e in (2e5, 6e5, 1e6)]
batch = jaxgrasp.evaluate_batch(grasps)          # one compiled evaluator for the whole list
print(batch.value, batch.status_names)           # (3,) J, one status each

print(json.dumps(jaxgrasp.engine._store.stats()), file=sys.stderr)
"""


def run_once(home: Path) -> dict:
    """One fresh process of :data:`EXAMPLE` with ``HOME=home``: wall seconds, load, output."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAXGRASP_CACHE_DIR", "XDG_CACHE_HOME")}
    env["HOME"] = str(home)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", EXAMPLE], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"warm_start: the example failed:\n{proc.stderr[-3000:]}")
    lines = proc.stderr.strip().splitlines()
    reports = [line for line in lines[:-1] if line.startswith("jaxgrasp")]  # not JAX's own INFO lines
    return {"wall": wall, "load": load, "stdout": proc.stdout.strip(), "reports": reports,
            "stats": json.loads(lines[-1])}


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="jaxgrasp-warm-start-") as tmp:
        home = Path(tmp)
        runs = [run_once(home), run_once(home)]
    ratio = runs[0]["wall"] / runs[1]["wall"]
    out = [f"warm_start.py  {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}  python {sys.version.split()[0]}  "
           f"cpus {os.cpu_count()}"]
    for name, r in zip(("first", "second"), runs):
        out.append(f"{name:>6}: wall {r['wall']:6.2f} s  load(1 min) {r['load']:.2f}  stats {r['stats']}")
        out += [f"        log: {line}" for line in r["reports"]]
        out += [f"        out: {line}" for line in r["stdout"].splitlines()]
    out.append(f"ratio first / second: {ratio:.1f}x ({'at least' if ratio >= 5 else 'BELOW'} the 5x asked)")
    text = "\n".join(out)
    print(text)
    with open(LOG, "a", encoding="utf-8") as f:
        f.write(text + "\n\n")
    return 0 if ratio >= 5 else 1


if __name__ == "__main__":
    raise SystemExit(main())
