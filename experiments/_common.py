"""Shared helpers of the figure scripts (options, output folder, progress, timing, findings)
and of the benchmark scripts (:func:`say`).

Every script writes into ``experiments/figures/`` (``--quick``: a small grid, into
``experiments/figures/quick/`` so the full-size outputs are not overwritten).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

FIGURES = Path(__file__).resolve().parent / "figures"


def say(msg: str) -> None:
    """One log line with the time and the 1-minute load average (timings are read against it)."""
    print(f"[{time.strftime('%H:%M:%S')} load {os.getloadavg()[0]:.2f}] {msg}", flush=True)


def agreement_numbers(status, value, ref_status, ref_value) -> dict:
    """Two runs of the same grasps compared: ``status_mismatches``, ``finite_mismatches``
    (finite against NaN values) and ``value_max_rel_diff`` (the largest relative
    difference of the values finite in both, relative to the reference)."""
    status, value, ref_status, ref_value = (np.asarray(a) for a in (status, value, ref_status, ref_value))
    both = np.isfinite(value) & np.isfinite(ref_value)
    rel = np.abs(value - ref_value)[both] / np.maximum(np.abs(ref_value[both]), 1e-300)
    return {"status_mismatches": int(np.sum(status != ref_status)),
            "finite_mismatches": int(np.sum(np.isfinite(value) != np.isfinite(ref_value))),
            "value_max_rel_diff": float(rel.max()) if rel.size else 0.0}


def agreement(status, value, ref_status, ref_value) -> str:
    """:func:`agreement_numbers` as one line."""
    a = agreement_numbers(status, value, ref_status, ref_value)
    return (f"statuses differing {a['status_mismatches']}, finite/NaN differing {a['finite_mismatches']}, "
            f"largest relative value difference {a['value_max_rel_diff']:.1e}")


def parse_args(description: str) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="small grid (minutes), written to figures/quick/")
    p.add_argument("--out", type=Path, default=None, help="output folder (default experiments/figures)")
    args = p.parse_args()
    if args.out is None:
        args.out = FIGURES / "quick" if args.quick else FIGURES
    args.out.mkdir(parents=True, exist_ok=True)
    # reuse compilations across runs (same cache as the jaxgrasp command)
    import jaxgrasp

    jaxgrasp.enable_compilation_cache()
    return args


class Progress:
    """A ``progress(done, total)`` callback printing chunk progress on stderr."""

    def __init__(self, label: str):
        self.label = label
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        el = time.perf_counter() - self.t0
        print(f"  [{self.label}] {done}/{total} points, {el:.1f} s", file=sys.stderr, flush=True)


def force_limit_deformation(young_modulus: float, max_force: float) -> float:
    """Initial deformation at which the initial normal force ``pi E dr^2`` reaches ``f_max``, m."""
    return math.sqrt(max_force / (math.pi * young_modulus))


def write_rows(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in r])


def finding(text: str, ok: bool) -> bool:
    print(f"FINDING [{'holds' if ok else 'DOES NOT HOLD'}]: {text}", flush=True)
    return ok


def timings(label: str, t_wall: float, compile_s: float, run_s: float) -> None:
    print(
        f"TIMING {label}: wall {t_wall:.1f} s (compile {compile_s:.1f} s, evaluation {run_s:.1f} s)",
        flush=True,
    )


def refine_interval(grid: np.ndarray, k: int) -> tuple[float, float]:
    """The interval between the neighbours of grid point ``k`` (for a second, finer pass)."""
    lo = grid[max(k - 1, 0)]
    hi = grid[min(k + 1, len(grid) - 1)]
    return float(lo), float(hi)
