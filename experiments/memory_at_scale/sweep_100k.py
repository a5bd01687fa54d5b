"""A sweep of 100,000 grasps: peak memory, time per chunk, throughput vs the 9 x 41 grid.

The grid is the paper's Fig. 6 cube grid made dense: 250 Young's moduli (2e5..1e6 Pa) x
400 initial deformations (1..5 mm) = 100,000 points (mass 0, like the 9 x 41 grid, so
the programs are of the same kind and the throughputs compare), run by
``jaxgrasp.sweep`` itself in chunks of ``--chunk-size``. On a 2-core CPU a full run takes hours (about 10 grasps/s), so
``--max-chunks K`` stops the real sweep after K chunks (from its progress callback) and
the script extrapolates the total time from the measured per-chunk throughput; the log
says which numbers are measured and which are extrapolated.

Also measured, in the same process and before the big sweep: the paper's 9 x 41 cube grid
with the CLI's default chunking (6 chunks of 62), as the throughput reference.

Memory: peak RSS from ``resource.getrusage`` (``ru_maxrss``) and ``/proc/self/status``
``VmHWM``, plus the RSS sampled every 0.1 s by a thread (peak per phase). After every
chunk the script records the RSS and the number of live JAX arrays
(``jax.live_arrays()``, less those alive before the sweep): both must stay flat, i.e. the sweep keeps no per-chunk device
buffers and builds nothing that grows with the grid beyond its output arrays.

    python experiments/memory_at_scale/sweep_100k.py --chunk-size 1024 --max-chunks 2 --log experiments/memory_at_scale/sweep_100k.log
    timeout 300 python experiments/memory_at_scale/sweep_100k.py --chunk-size 4096 --max-chunks 1 --no-reference --print-rss 5
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import threading
import time

import numpy as np


def rss_mib() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def hwm_mib() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class Sampler(threading.Thread):
    """Samples the RSS every ``dt`` s; ``reset()`` starts a new phase, ``peak`` its maximum."""

    def __init__(self, dt: float = 0.1, print_every: float | None = None):
        super().__init__(daemon=True)
        self.dt, self.peak, self._stop = dt, 0.0, threading.Event()
        self.print_every, self._t0 = print_every, time.perf_counter()

    def reset(self) -> None:
        self.peak = rss_mib()

    def run(self) -> None:
        last = time.perf_counter()
        while not self._stop.wait(self.dt):
            self.peak = max(self.peak, rss_mib())
            if self.print_every and time.perf_counter() - last >= self.print_every:
                last = time.perf_counter()
                print(
                    f"  [{last - self._t0:6.0f} s] RSS {rss_mib():.0f} MiB, VmHWM {hwm_mib():.0f} MiB",
                    flush=True,
                )

    def stop(self) -> None:
        self._stop.set()


class _Stop(Exception):
    pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chunk-size", type=int, default=4096)
    ap.add_argument("--max-chunks", type=int, default=None, help="stop after this many chunks")
    ap.add_argument("--no-reference", action="store_true", help="skip the 9 x 41 reference grid")
    ap.add_argument("--log", help="append the report to this file too")
    ap.add_argument("--no-cache", action="store_true", help="no persistent compilation cache")
    ap.add_argument(
        "--print-rss",
        type=float,
        metavar="S",
        help="print RSS and VmHWM every S seconds (to watch a run that is stopped from outside)",
    )
    args = ap.parse_args()

    lines: list[str] = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    sampler = Sampler(print_every=args.print_rss)
    sampler.start()
    import jax

    import jaxgrasp
    from jaxgrasp.engine import compiled_evaluator
    from jaxgrasp.engine import plan_chunks
    from jaxgrasp.tolerance import EvaluateOptions

    if not args.no_cache:
        jaxgrasp.engine.enable_compilation_cache()
    cube = jaxgrasp.presets.cube()
    n_dev = jax.device_count()
    say(
        f"# sweep_100k {time.strftime('%Y-%m-%d %H:%M:%S')}: jax {jax.__version__}, "
        f"{n_dev} x {jax.devices()[0].platform}, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.2f}, chunk size {args.chunk_size}, "
        f"max chunks {args.max_chunks}, RSS after imports {rss_mib():.0f} MiB"
    )

    ref_rate = None
    if not args.no_reference:
        E9, dr41 = np.linspace(2e5, 1e6, 9), np.linspace(1e-3, 5e-3, 41)
        chunk = plan_chunks(E9.size * dr41.size, auto=True).chunk  # as jaxgrasp sweep picks it
        sampler.reset()
        t0 = time.perf_counter()
        r = jaxgrasp.sweep(cube, young_modulus=E9, initial_deformation=dr41, chunk_size=chunk)
        wall = time.perf_counter() - t0
        ref_rate = r.size / r.run_seconds
        say(
            f"9 x 41 reference (measured): {r.size} points in chunks of {chunk}: compile "
            f"{r.compile_seconds:.1f} s, solve {r.run_seconds:.1f} s -> {ref_rate:.2f} grasps/s; "
            f"wall {wall:.1f} s; peak RSS in this phase {sampler.peak:.0f} MiB"
        )

    # the paper's Fig. 6 ranges, 100,000 points: the same kind of programs as the 9 x 41
    # grid (so throughputs compare), each chunk spanning every initial deformation
    axes = dict(
        young_modulus=np.linspace(2e5, 1e6, 250),
        initial_deformation=np.linspace(1e-3, 5e-3, 400),
    )
    total = math.prod(a.size for a in axes.values())
    chunk = plan_chunks(total, args.chunk_size).chunk
    nchunks = math.ceil(total / chunk)
    say(f"100k grid: {' x '.join(str(a.size) for a in axes.values())} = {total} points, {nchunks} chunks of {chunk}")

    sampler.reset()
    t0 = time.perf_counter()
    fn, comp = compiled_evaluator(EvaluateOptions(), 2, chunk, settle=False)  # memoised: the sweep below reuses it
    say(f"compile for chunk {chunk}: {comp:.1f} s (wall {time.perf_counter() - t0:.1f} s), "
        f"peak RSS while compiling {sampler.peak:.0f} MiB")
    try:
        m = fn.memory_analysis()
        say(
            f"XLA memory analysis for chunk {chunk}: temporaries {m.temp_size_in_bytes / 2**20:.0f} MiB, "
            f"arguments {m.argument_size_in_bytes / 2**20:.2f} MiB, outputs {m.output_size_in_bytes / 2**20:.2f} MiB"
        )
    except Exception as exc:  # not every backend reports it
        say(f"XLA memory analysis unavailable: {exc}")

    sampler.reset()
    live0 = len(jax.live_arrays())  # the base grasp's own fields, held by this script
    marks = []  # (time, done, rss, live arrays created since the sweep began)
    t_start = time.perf_counter()

    def progress(done: int, total_: int) -> None:
        marks.append((time.perf_counter(), done, rss_mib(), len(jax.live_arrays()) - live0))
        k = len(marks)
        t_prev = marks[-2][0] if k > 1 else t_start
        dt = marks[-1][0] - t_prev
        n = done - (marks[-2][1] if k > 1 else 0)
        say(
            f"chunk {k}/{nchunks} (measured): {n} points in {dt:.1f} s = {n / dt:.2f} grasps/s; "
            f"RSS {marks[-1][2]:.0f} MiB, peak RSS so far {sampler.peak:.0f} MiB, "
            f"live JAX arrays held by the sweep {marks[-1][3]}"
        )
        if args.max_chunks is not None and k >= args.max_chunks and done < total_:
            raise _Stop

    finished = True
    try:
        res = jaxgrasp.sweep(cube, chunk_size=args.chunk_size, progress=progress, **axes)
    except _Stop:
        finished = False
    elapsed = time.perf_counter() - t_start
    done = marks[-1][1]
    rate = done / elapsed
    say(
        f"100k sweep (measured): {done}/{total} points in {len(marks)} chunks, {elapsed:.1f} s "
        f"-> {rate:.2f} grasps/s"
        + (f" = {rate / ref_rate:.2f} x the 9 x 41 grid's {ref_rate:.2f} grasps/s" if ref_rate else "")
    )
    if finished:
        say(f"100k sweep finished: counts {res.counts()}")
    else:
        est = total / rate
        say(
            f"100k sweep (EXTRAPOLATED from the measured rate, not run): {total} points would "
            f"take {est:.0f} s = {est / 3600:.2f} h of solving (+ compile {comp:.0f} s)"
        )
    ru = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    say(
        f"peak memory (measured): ru_maxrss {ru:.0f} MiB, VmHWM {hwm_mib():.0f} MiB for the whole "
        f"process; sampled peak RSS during the chunks {sampler.peak:.0f} MiB; "
        f"RSS after chunk 1 {marks[0][2]:.0f} MiB, after chunk {len(marks)} {marks[-1][2]:.0f} MiB; "
        f"live JAX arrays held by the sweep after each chunk {[m[3] for m in marks]}"
    )
    sampler.stop()
    if args.log:
        with open(args.log, "a") as fh:
            fh.write("\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main()
