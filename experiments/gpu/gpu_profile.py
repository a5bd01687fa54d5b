"""Where an accelerator's time goes in one steady ``evaluate_batch`` (issue 41, item 3).

The set is ``experiments/batch_benchmark/batch_benchmark.py``'s mixed grasps (``--count``, contact counts 2
to 7, padded to 7, float64). One chunk size (``--chunk``, grasps per compiled call). The
script evaluates the set three times on the first accelerator: compile and first run, a
steady run (timed), and a steady run under ``jax.profiler.trace``. It then reads the
trace's device plane (``jax.profiler.ProfileData``) and prints:

- the kernels launched, their summed time, and the device's busy share of the profiled
  run's wall time (the union of kernel and copy intervals over the wall time): a small
  share means the device waits on launches and on the loops' conditions, not on arithmetic;
- the copies between host and device (a ``while_loop``'s condition comes back to the host
  once per iteration on a GPU);
- the kernels that take most of the time, by name.

Without an accelerator it profiles the CPU device (a dry run of the script: the host
plane's events are printed instead). On the H100 lease of 2026-11-28 it had not finished
170 s after its profiled run started: the host and Python tracers were on then (they are
off now), and it then told kernels from copies in time quadratic in the events (linear
now), so it has not yet given a GPU profile: ``experiments/gpu_run_h100_2026-11-28.log``.

    python experiments/gpu/gpu_profile.py [--count 1000] [--chunk 1024] [--json out.json]

``XLA_FLAGS`` set by the caller reach the compilation (e.g. command buffers for loops:
``--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL``), so the same script compares them.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports

import jax  # noqa: E402
from _lab import agreement  # noqa: E402
from batch_benchmark import STATUS, log, make_grasps  # noqa: E402

import jaxgrasp  # noqa: E402


def union_seconds(intervals: list[tuple[int, int]]) -> float:
    """Length of the union of ``[start, end)`` nanosecond intervals, seconds."""
    total, reach = 0, None
    for start, end in sorted(intervals):
        if reach is None or start > reach:
            total += end - start
            reach = end
        elif end > reach:
            total += end - reach
            reach = end
    return total * 1e-9


def device_events(trace_dir: Path, accelerator: bool) -> tuple[str, list]:
    """The events of the profiled device's plane: ``(plane name, [(line, name, start_ns, duration_ns)])``."""
    from jax.profiler import ProfileData

    files = sorted(trace_dir.rglob("*.xplane.pb"))
    if not files:
        raise SystemExit(f"no *.xplane.pb under {trace_dir}: the profiler wrote nothing")
    data = ProfileData.from_file(str(files[-1]))
    prefix = "/device:" if accelerator else "/host:CPU"
    planes = [p for p in data.planes if p.name.startswith(prefix)]
    if not planes:
        raise SystemExit(f"no plane named {prefix}* in the trace; planes: {[p.name for p in data.planes]}")
    plane = planes[0]
    events = [(line.name, ev.name, ev.start_ns, ev.duration_ns) for line in plane.lines for ev in line.events]
    return plane.name, events


def summarize(events: list, wall_s: float, top: int) -> dict:
    """Kernels, copies and the busy share of a device plane's events over ``wall_s`` seconds."""
    # A GPU plane's stream lines hold one event per kernel or copy; its other lines
    # (XLA modules, XLA ops) restate the same time at coarser grain.
    streams = [e for e in events if e[0].startswith("Stream")] or events
    is_copy = [("memcpy" in e[1].lower() or "memset" in e[1].lower()) for e in streams]
    copies = [e for e, c in zip(streams, is_copy) if c]
    kernels = [e for e, c in zip(streams, is_copy) if not c] or streams
    by_name = collections.defaultdict(lambda: [0, 0])
    for _, name, _, dur in kernels:
        by_name[name][0] += 1
        by_name[name][1] += dur
    busy = union_seconds([(s, s + d) for _, _, s, d in streams])
    ranked = sorted(by_name.items(), key=lambda kv: -kv[1][1])[:top]
    copy_kinds = collections.Counter(name.split(":")[0].strip() for _, name, _, _ in copies)
    return {
        "lines": sorted({e[0] for e in events}),
        "kernels": len(kernels), "kernel_seconds": sum(e[3] for e in kernels) * 1e-9,
        "copies": len(copies), "copy_kinds": dict(copy_kinds.most_common(6)),
        "busy_seconds": busy, "wall_seconds": wall_s, "busy_share": busy / wall_s,
        "mean_kernel_us": 1e-3 * sum(e[3] for e in kernels) / max(len(kernels), 1),
        "top": [{"name": n[:90], "count": c, "seconds": t * 1e-9} for n, (c, t) in ranked],
    }


def cpu_beside(grasps: list, steady) -> str:
    """The set on all of this machine's CPU devices: compile, steady rate, agreement with ``steady``."""
    cpu = jax.devices("cpu")
    first = jaxgrasp.evaluate_batch(grasps, devices=cpu)
    again = jaxgrasp.evaluate_batch(grasps, devices=cpu)
    return (f"{len(cpu)} CPU devices: compile {first.compile_seconds:.1f} s, steady run {again.run_seconds:.2f} s = "
            f"{len(grasps) / again.run_seconds:.0f} grasps/s; against the profiled device: "
            + agreement(again.status, again.value, steady.status, steady.value))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="grasps in the set (default 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=int, default=1024, help="grasps per compiled call (default 1024)")
    ap.add_argument("--top", type=int, default=15, help="kernels listed (default 15)")
    ap.add_argument("--cpu", action="store_true", help="also the set on this machine's CPU devices, compared")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    acc = [d for d in jax.devices() if d.platform != "cpu"][:1]
    devices = acc or jax.devices("cpu")[:1]
    grasps = make_grasps(args.count, args.seed)
    head = (f"jax {jax.__version__}; device {devices[0].device_kind}; {args.count} grasps (2-7 contacts, padded "
            f"to 7), chunk {args.chunk}, float64; XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}; "
            f"load average at start {os.getloadavg()[0]:.2f}")
    log(head)
    first = jaxgrasp.evaluate_batch(grasps, chunk_size=args.chunk, devices=devices)
    log(f"compile {first.compile_seconds:.1f} s, first run {first.run_seconds:.2f} s")
    steady = jaxgrasp.evaluate_batch(grasps, chunk_size=args.chunk, devices=devices)
    log(f"steady run {steady.run_seconds:.2f} s, {args.count / steady.run_seconds:.0f} grasps/s")
    # The device's activity only: on the lease of 2026-11-28 the trace (default host and Python
    # tracers) and its reading (then quadratic in the events) had not ended 170 s after a run of
    # 9 s started.
    options = jax.profiler.ProfileOptions()
    if acc:  # on a CPU the host's events are the device's
        options.host_tracer_level, options.python_tracer_level, options.enable_hlo_proto = 0, 0, False
    with tempfile.TemporaryDirectory() as tmp:
        log("profiled run")
        t0 = time.perf_counter()
        with jax.profiler.trace(tmp, profiler_options=options):
            profiled = jaxgrasp.evaluate_batch(grasps, chunk_size=args.chunk, devices=devices)
        wall = time.perf_counter() - t0
        log(f"trace written: {wall:.1f} s with the profiler; reading it")
        plane, events = device_events(Path(tmp), bool(acc))
    s = summarize(events, profiled.run_seconds, args.top)
    same = bool(np.array_equal(np.asarray(profiled.status), np.asarray(steady.status)))
    counts = np.bincount(np.asarray(steady.status), minlength=4)
    lines = [head, "",
             f"steady run {steady.run_seconds:.2f} s = {args.count / steady.run_seconds:.0f} grasps/s; profiled run "
             f"{profiled.run_seconds:.2f} s (wall with the profiler {wall:.2f} s); statuses: "
             + ", ".join(f"{n} {c}" for n, c in zip(STATUS, counts)) + f"; profiled statuses equal: {same}",
             f"plane {plane}: lines {s['lines'][:8]}",
             f"kernels {s['kernels']} ({s['kernels'] / args.count:.0f} per grasp), {s['kernel_seconds']:.2f} s summed, "
             f"mean {s['mean_kernel_us']:.1f} us; copies {s['copies']} {s['copy_kinds']}",
             f"device busy {s['busy_seconds']:.2f} s of the profiled run's {profiled.run_seconds:.2f} s = "
             f"{100 * s['busy_share']:.0f} %",
             "", "| kernel | launches | seconds | mean us |", "|---|---:|---:|---:|"]
    lines += [f"| {k['name']} | {k['count']} | {k['seconds']:.3f} | {1e6 * k['seconds'] / k['count']:.1f} |"
              for k in s["top"]]
    print("\n".join(lines), flush=True)  # before the CPU's run: a run cut short keeps the profile
    if args.cpu:
        s["cpu"] = cpu_beside(grasps, steady)
        print(s["cpu"], flush=True)
    print(f"load average at end {os.getloadavg()[0]:.2f}", flush=True)
    if args.json is not None:
        s.update(header=head, steady_run_s=steady.run_seconds, compile_s=first.compile_seconds,
                 profiled_run_s=profiled.run_seconds)
        args.json.write_text(json.dumps(s, indent=1))


if __name__ == "__main__":
    main()
