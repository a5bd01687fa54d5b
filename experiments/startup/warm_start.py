"""A warm library (issue 35, item 4): the README's Python example, run twice in fresh processes.

Each run is a new Python process with a fresh, empty home folder (``HOME`` set to a new
temporary folder; ``JAXGRASP_CACHE_DIR`` and ``XDG_CACHE_HOME`` removed), so that the
only cache is the one ``import jaxgrasp`` turns on by itself, in
``~/.cache/jaxgrasp/xla/jaxgrasp-executables``. The first run compiles and stores the
evaluators; the second, another process with the same home, loads them. The script is
the README's first Python block, read from README.md (so that it cannot drift from it),
with logging at INFO level so that the compilation
reports show, and the cache counters printed at the end.

Prints each run's wall time (process start to exit), the ratio first / second, the
1-minute load average before each run, the compilation reports of each run and the cache
counters, and appends it to ``experiments/startup/warm_start.log``. Done when the second run is
at least 5x faster than the first.

    python experiments/startup/warm_start.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402
LOG = Path(__file__).resolve().parent / "warm_start.log"

README = ROOT / "README.md"


def readme_example() -> str:
    """The README's Python example (its first ``python`` block), as written there, with
    logging at INFO level first (so the compilation reports show) and the cache counters
    printed last."""
    text = README.read_text(encoding="utf-8")
    block = text.split("```python\n", 1)[1].split("```", 1)[0]
    head = 'import logging, json, sys\nlogging.basicConfig(level=logging.INFO, format="%(message)s")\n'
    tail = '\nimport jaxgrasp\nprint(json.dumps(jaxgrasp.engine.stats()), file=sys.stderr)\n'
    return head + block + tail


def run_once(home: Path) -> dict:
    """One fresh process of the README's example with ``HOME=home``: wall seconds, load, output."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAXGRASP_CACHE_DIR", "XDG_CACHE_HOME")}
    env["HOME"] = str(home)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", readme_example()], cwd=ROOT, env=env, capture_output=True, text=True,
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
