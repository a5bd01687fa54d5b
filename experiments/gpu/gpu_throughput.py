"""Throughput of ``jaxgrasp.evaluate_batch`` on an accelerator as the chunk grows (issue 41, item 3).

The set is ``experiments/batch_benchmark/batch_benchmark.py``'s: ``--count`` (default 1000) seeded random
grasps of ``tests/grasp_draws.py:build_grasp`` with contact counts ``2 + i % 6`` (2 to 7),
default :class:`jaxgrasp.EvaluateOptions`, float64. One padded compilation serves each
chunk size (every grasp padded with inactive contacts to 7).

For each chunk size in ``--chunks`` (grasps per device per compiled call), the set is
repeated to ``max(count, 2 * chunk)`` grasps and evaluated twice on the accelerator
(``jax.devices()`` when they are not CPUs): the first call's ``compile_seconds``, then the
second call's ``run_seconds`` (the executable is reused), grasps/s = grasps / run
seconds, and the device's peak memory (``memory_stats()['peak_bytes_in_use']``, GiB)
where the backend reports it. A chunk that does not fit is reported and ends the climb.

Beside it, the same 1000 grasps on the same machine's CPU cores (one JAX device per core,
``import jaxgrasp``'s default): compile seconds, run seconds, grasps/s. The accelerator's
values of the set are compared with the CPU's: statuses equal, and the largest relative
value difference (the same float64 programs on two backends round differently, so they
agree to the solver's tolerance, not bit for bit).

Prints one table and the load average; ``--json PATH`` also writes every number.

    python experiments/gpu/gpu_throughput.py [--count 1000] [--chunks 1024,4096,16384] [--json out.json]

Without an accelerator it measures the CPU devices alone (a dry run of the script).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports

import jax  # noqa: E402

import jaxgrasp  # noqa: E402
from _lab import agreement_numbers  # noqa: E402
from batch_benchmark import STATUS, log, make_grasps  # noqa: E402

from jaxgrasp.engine import default_chunk_size  # noqa: E402


def peak_gib(device) -> float:
    """The device's peak bytes in use so far, GiB (NaN where the backend keeps no count)."""
    stats = device.memory_stats() or {}
    return stats.get("peak_bytes_in_use", float("nan")) / 2**30


def measure(grasps: list, devices, chunk: int | None) -> dict:
    """Two ``evaluate_batch`` calls on ``devices``: compile of the first, run of the second."""
    t0 = time.perf_counter()
    first = jaxgrasp.evaluate_batch(grasps, chunk_size=chunk, devices=devices)
    first_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    second = jaxgrasp.evaluate_batch(grasps, chunk_size=chunk, devices=devices)
    wall = time.perf_counter() - t0
    return {"grasps": len(grasps), "chunk": chunk, "compile_s": first.compile_seconds, "first_wall_s": first_wall,
            "run_s": second.run_seconds, "wall_s": wall, "rate": len(grasps) / second.run_seconds,
            "value": np.asarray(second.value), "status": np.asarray(second.status)}


def agreement(a: dict, b: dict, count: int) -> dict:
    """Statuses and values of the first ``count`` grasps of two runs (``b`` the reference,
    :func:`_common.agreement_numbers`)."""
    return agreement_numbers(a["status"][:count], a["value"][:count], b["status"][:count], b["value"][:count])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="grasps in the set (default 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunks", default="1024,4096,16384", help="chunk sizes on the accelerator, ascending")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    base = make_grasps(args.count, args.seed)
    cpu = jax.devices("cpu")
    acc = [d for d in jax.devices() if d.platform != "cpu"]
    load_start = os.getloadavg()
    head = (f"jax {jax.__version__}; {len(cpu)} CPU devices; accelerator: "
            f"{acc[0].device_kind + ' x' + str(len(acc)) if acc else 'none'}; set: {args.count} grasps, "
            f"2-7 contacts padded to 7, float64; load average at start {load_start[0]:.2f}")
    log(head)
    log("CPU devices: the set")
    rows = {"cpu": measure(base, cpu, None)}
    rows["cpu"]["chunk"] = default_chunk_size(cpu)
    log(f"CPU devices: compile {rows['cpu']['compile_s']:.1f} s, run {rows['cpu']['run_s']:.2f} s, "
        f"{rows['cpu']['rate']:.0f} grasps/s")  # each row as it comes: a run cut short keeps the ones done
    for chunk in [int(c) for c in args.chunks.split(",")] if acc else []:
        reps = -(-max(args.count, 2 * chunk * len(acc)) // args.count)
        grasps = (base * reps)[:max(args.count, 2 * chunk * len(acc))]
        log(f"accelerator: chunk {chunk}, {len(grasps)} grasps")
        try:
            r = measure(grasps, acc, chunk)
        except Exception as e:  # an out-of-memory chunk ends the climb; the smaller ones stand
            rows[f"acc{chunk}"] = {"chunk": chunk, "grasps": len(grasps), "error": f"{type(e).__name__}: {str(e)[:300]}"}
            log(f"chunk {chunk} failed: {rows[f'acc{chunk}']['error']}")
            break
        r["peak_gib"] = peak_gib(acc[0])
        r["agreement_with_cpu"] = agreement(r, rows["cpu"], args.count)
        rows[f"acc{chunk}"] = r
        log(f"chunk {chunk}: compile {r['compile_s']:.1f} s, run {r['run_s']:.2f} s, {r['rate']:.0f} grasps/s, "
            f"peak {r['peak_gib']:.1f} GiB; statuses differing from the CPU's: "
            f"{r['agreement_with_cpu']['status_mismatches']}")
    lines = [head, "", "| where | chunk | grasps | compile s | run s | grasps/s | peak GiB | statuses differ | value max rel diff |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in rows.items():
        where = f"{len(cpu)} CPU devices" if name == "cpu" else acc[0].device_kind
        if "error" in r:
            lines.append(f"| {where} | {r['chunk']} | {r['grasps']} | failed: {r['error'][:80]} | | | | | |")
            continue
        ag = r.get("agreement_with_cpu", {})
        lines.append(f"| {where} | {r['chunk']} | {r['grasps']} | {r['compile_s']:.1f} | {r['run_s']:.2f} | "
                     f"{r['rate']:.0f} | {r.get('peak_gib', float('nan')):.1f} | {ag.get('status_mismatches', '')} | "
                     f"{ag.get('value_max_rel_diff', float('nan')):.1e} |")
    counts = np.bincount(rows["cpu"]["status"], minlength=4)
    lines += ["", "CPU statuses: " + ", ".join(f"{s} {c}" for s, c in zip(STATUS, counts)),
              f"load average at end {os.getloadavg()[0]:.2f}"]
    print("\n".join(lines), flush=True)
    if args.json is not None:
        out = {k: {f: (v.tolist() if isinstance(v, np.ndarray) else v) for f, v in r.items() if f not in ("value", "status")}
               for k, r in rows.items()}
        out["header"], out["load_start"], out["load_end"] = head, load_start, os.getloadavg()
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
