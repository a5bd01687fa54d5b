"""Compile time of the default ``jaxgrasp sweep`` (the paper's cube grid), first and second run.

Runs ``jaxgrasp sweep --no-plot`` twice, each in a fresh process, with an empty cache
folder (``JAXGRASP_CACHE_DIR``): the first run traces, exports and compiles; the second
loads the exported program and the XLA executable from the cache. Prints, per run, the
sweep's ``compile_seconds`` (read back from ``sweep.npz``), its solve time and the
process's wall time.

    python experiments/compile_cache.py [--runs 2] [--keep-cache DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--keep-cache", metavar="DIR", help="use (and keep) this cache folder")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="jaxgrasp-compile-"))
    cache = Path(args.keep_cache) if args.keep_cache else tmp / "cache"
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(cache))
    print(f"cache folder: {cache}; load average {os.getloadavg()[0]:.2f}", flush=True)
    try:
        for k in range(1, args.runs + 1):
            out = tmp / f"out{k}"
            t0 = time.perf_counter()
            cmd = [sys.executable, "-m", "jaxgrasp.cli", "sweep", "--no-plot", "--quiet", "--out", str(out)]
            p = subprocess.run(cmd, env=env, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if p.returncode:
                sys.exit(f"run {k} failed: {p.stderr[-2000:]}")
            with np.load(out / "sweep.npz") as z:
                comp, run = float(z["compile_seconds"]), float(z["run_seconds"])
                value = np.array(z["value"])
            if k == 1:
                first = value
            same = np.array_equal(value, first)
            print(
                f"run {k}: compile {comp:.2f} s, solve {run:.1f} s, process wall {wall:.1f} s, "
                f"values identical to run 1: {same}; load average {os.getloadavg()[0]:.2f}",
                flush=True,
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
