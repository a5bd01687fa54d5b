"""The work queue's width on an accelerator (issue 41, item 3): grasps/s as the slots grow.

The solver's work queue (:func:`jaxgrasp.solver.solve_lanes`) advances
``W = min(ceil(slot_fraction * lanes), max_slots)`` lanes per loop step, 128 at most by
default (:class:`jaxgrasp.SolverOptions`), a width chosen for a CPU's caches. On one H100
(2026-11-28) the mixed set's time grew with the chunk (113 grasps/s at chunk 1024, 121 at
4096): what a loop step costs there hardly depends on its width, and the number of loop
steps grows with the lanes over ``W``. On this project's CPU, one device, chunk 1024, the
same 1000 grasps take 16,885 loop steps at ``W = 128`` and 676 at ``max_slots=16384,
slot_fraction=1``, with every status and value identical; repeated to 4096 in one chunk,
68,604 at ``W = 128`` and 680 at ``max_slots=65536`` (``experiments/solver_steps/queue_steps.py``, log
``queue_width.log``; ``FINDINGS.md``, "A second lease of an H100"). A run's seconds over
those counts are a loop step's cost at each width.

For each ``CHUNK:MAX_SLOTS:SLOT_FRACTION`` in ``--configs``, the set
(``batch_benchmark.py``'s mixed grasps, 2-7 contacts padded to 7, float64) repeated to
``max(count, chunk)`` grasps is evaluated twice on the first accelerator with
``EvaluateOptions(solver=SolverOptions(max_slots=..., slot_fraction=...))``: compile of the
first call, steady run of the second, grasps/s, peak device memory, and the first
``count`` grasps' statuses and values against the first configuration's (the same
lanes, so the same answers up to rounding: a wider program is another program and XLA
may fuse it differently). Each row is printed as it comes; ``--json`` writes them all.

    python experiments/gpu/gpu_slots.py [--count 1000] [--configs 1024:128:0.0625,1024:16384:1] [--json out.json]

Without an accelerator it runs on one CPU device (a dry run of the script).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports

import jax  # noqa: E402
from _lab import agreement  # noqa: E402
from batch_benchmark import log, make_grasps  # noqa: E402

import jaxgrasp  # noqa: E402

DEFAULT_CONFIGS = "1024:128:0.0625,1024:16384:1,4096:65536:1,16384:65536:1,16384:262144:1"


def parse_configs(text: str) -> list[tuple[int, int, float]]:
    """``"CHUNK:MAX_SLOTS:SLOT_FRACTION,..."`` as ``[(chunk, max_slots, slot_fraction)]``."""
    out = []
    for part in text.split(","):
        chunk, slots, fraction = part.split(":")
        out.append((int(chunk), int(slots), float(fraction)))
    return out


def measure(base: list, device, chunk: int, max_slots: int, slot_fraction: float) -> dict:
    """Two ``evaluate_batch`` calls of ``base`` repeated to ``max(len(base), chunk)`` grasps."""
    n = max(len(base), chunk)
    grasps = (base * -(-n // len(base)))[:n]
    solver = dataclasses.replace(jaxgrasp.SolverOptions(), max_slots=max_slots, slot_fraction=slot_fraction)
    options = jaxgrasp.EvaluateOptions(solver=solver)
    first = jaxgrasp.evaluate_batch(grasps, chunk_size=chunk, devices=[device], options=options)
    second = jaxgrasp.evaluate_batch(grasps, chunk_size=chunk, devices=[device], options=options)
    stats = device.memory_stats() or {}
    return {"chunk": chunk, "max_slots": max_slots, "slot_fraction": slot_fraction, "grasps": n,
            "compile_s": first.compile_seconds, "first_run_s": first.run_seconds, "run_s": second.run_seconds,
            "rate": n / second.run_seconds, "peak_gib": stats.get("peak_bytes_in_use", float("nan")) / 2**30,
            "status": np.asarray(second.status)[: len(base)], "value": np.asarray(second.value)[: len(base)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="grasps in the set (default 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--configs", default=DEFAULT_CONFIGS, help=f"CHUNK:MAX_SLOTS:SLOT_FRACTION,... ({DEFAULT_CONFIGS})")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    configs = parse_configs(args.configs)
    device = ([d for d in jax.devices() if d.platform != "cpu"] or jax.devices("cpu"))[0]
    base = make_grasps(args.count, args.seed)
    log(f"jax {jax.__version__}; device {device.device_kind}; {args.count} grasps (2-7 contacts, padded to 7), "
        f"float64; load average {os.getloadavg()[0]:.2f}")
    rows: list[dict] = []
    for chunk, slots, fraction in configs:
        try:
            row = measure(base, device, chunk, slots, fraction)
        except Exception as e:  # an out-of-memory width ends the climb; the rows done stand
            log(f"chunk {chunk}, max_slots {slots}, slot_fraction {fraction:g}: failed: "
                f"{type(e).__name__}: {str(e)[:300]}")
            break
        row["agreement"] = agreement(row["status"], row["value"], rows[0]["status"], rows[0]["value"]) if rows \
            else "reference"
        rows.append(row)
        log(f"chunk {chunk}, max_slots {slots}, slot_fraction {fraction:g}: {row['grasps']} grasps, compile "
            f"{row['compile_s']:.1f} s, first run {row['first_run_s']:.2f} s, steady {row['run_s']:.2f} s = "
            f"{row['rate']:.0f} grasps/s, peak {row['peak_gib']:.1f} GiB; {row['agreement']}")
    log(f"load average at end {os.getloadavg()[0]:.2f}")
    if args.json is not None:
        args.json.write_text(json.dumps([{k: v for k, v in r.items() if k not in ("status", "value")} for r in rows],
                                        indent=1))


if __name__ == "__main__":
    main()
