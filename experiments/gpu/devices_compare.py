"""The engine on each kind of device of one machine, side by side, in one process.

Runs the paper's cube sweep (Fig. 6 grid, 9 x 41 points) and ``evaluate_batch`` of
``--grasps`` seeded random grasps (2-5 contacts, ``tests/grasp_draws.py``) first on the
CPU devices and then on the accelerator (``jax.devices()`` when it is a GPU or TPU), and
prints for each: compile seconds, run seconds, points per second, and the ratio of the
accelerator to the CPU; then how far the accelerator's values are from the CPU's (the same
float64 problems solved by the same code: they agree to the solver's tolerance, not bit
for bit, since the two backends round differently). Prints the load average and the
devices. Without an accelerator it runs the CPU part alone.

    python experiments/gpu/devices_compare.py [--grasps 256]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jax  # noqa: E402

import jaxgrasp  # noqa: E402
from _lab.grasp_draws import seeded_grasps  # noqa: E402

GRID = dict(young_modulus=np.linspace(2e5, 1e6, 9), initial_deformation=np.linspace(1e-3, 5e-3, 41))


def run_on(devices, grasps) -> dict:
    """The sweep and the batch on ``devices``: timings and values."""
    t0 = time.perf_counter()
    s = jaxgrasp.sweep(jaxgrasp.presets.cube(), devices=devices, **GRID)
    sweep_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = jaxgrasp.evaluate_batch(grasps, devices=devices)
    batch_wall = time.perf_counter() - t0
    return dict(
        sweep=(s.compile_seconds, s.run_seconds, sweep_wall, s.size), sweep_value=np.asarray(s.value),
        sweep_status=np.asarray(s.status), batch=(b.compile_seconds, b.run_seconds, batch_wall, len(b)),
        batch_value=np.asarray(b.value), batch_status=np.asarray(b.status),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grasps", type=int, default=256)
    args = ap.parse_args()
    grasps = seeded_grasps(args.grasps, seed=7)
    cpu = jax.devices("cpu")
    acc = [d for d in jax.devices() if d.platform != "cpu"]
    print(f"jax {jax.__version__}; load average {os.getloadavg()[0]:.2f}; {len(cpu)} CPU devices; "
          f"accelerator: {acc[0].device_kind + ' x' + str(len(acc)) if acc else 'none'}", flush=True)
    results = {"cpu": run_on(cpu, grasps)}
    if acc:
        results["accelerator"] = run_on(acc, grasps)
    for what in ("sweep", "batch"):
        for name, r in results.items():
            comp, run, wall, n = r[what]
            print(f"{what:>5} on {name:>11}: compile {comp:6.2f} s, run {run:6.2f} s, wall {wall:6.2f} s, "
                  f"{n / run:9.1f} grasps/s", flush=True)
        if acc:
            c, a = results["cpu"][what], results["accelerator"][what]
            print(f"{what:>5} accelerator / CPU: compile {a[0] / c[0]:.2f}, run {a[1] / c[1]:.3f} "
                  f"(throughput x{c[1] / a[1]:.1f})")
            cv = np.nan_to_num(results["cpu"][f"{what}_value"])
            av = np.nan_to_num(results["accelerator"][f"{what}_value"])
            rel = np.max(np.abs(av - cv) / np.maximum(np.abs(cv), 1e-12))
            same = np.mean(results["accelerator"][f"{what}_status"] == results["cpu"][f"{what}_status"])
            print(f"{what:>5} values: max abs diff {np.max(np.abs(av - cv)):.2e} J, max rel diff {rel:.2e}, "
                  f"statuses equal {same:.1%} ({cv.size} grasps)")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
