"""100,000 mixed grasps through ``jaxgrasp batch``, stopped once and resumed (issue 41, item 4).

The set: ``--count`` (default 100,000) seeded random grasps from the property tests'
generator (``tests/grasp_draws.py:build_grasp_fields``), contact counts cycling 2..7
(``n = 2 + i % 6``), written as one ``.npz`` dataset padded to 7 contacts (``active``
marks each grasp's own), in a scratch folder (``--work``), not in the repository.

The run is the user's command, in a subprocess: ``python -m jaxgrasp batch SET.npz --out
DIR``. When ``--stop-at`` of the grasps are done (read from its progress lines) the script
sends SIGINT, as a user's Ctrl-C; the command must exit 130 with its finished chunks kept.
Then ``jaxgrasp batch SET.npz --out DIR --resume`` finishes the set. Throughout, a thread
samples the command's resident memory (``VmRSS`` of ``/proc/PID/status``) every
``--dt`` seconds, with the number of grasps done at that moment.

Logged: the grasps done and RSS at every tenth of the set, the peak RSS of each phase
(``VmHWM``), the steady rate (grasps/s between the first and the last progress line of a
phase, so compiling is apart), and the slope of RSS against grasps done over the steady
part of the resumed phase (MiB per 10,000 grasps: memory flat in the number of grasps
means a slope near the bytes of the result arrays each grasp adds, which the command holds
until it writes them). Where the engine runs the set as several programs by contact count
(``jaxgrasp.engine.plan_widths``), the RSS while each ran and its slope: a program is
compiled in its first chunk, so memory may step there (bounded by the number of
programs); within a program it should be flat once the result arrays' pages are touched.
Afterwards ``results.csv`` must hold every row once, in input order; ``--check K`` rows
drawn at random are evaluated again in this process with ``jaxgrasp.evaluate_batch`` and
must give the same statuses and values (rows from both phases, so the resume is checked
too).

    python experiments/memory_at_scale/batch_100k.py --log experiments/memory_at_scale/batch_100k.log
    python experiments/memory_at_scale/batch_100k.py --count 3000 --check 50     # a quick try
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

PER_CONTACT = ("initial_deformation", "radius", "young_modulus", "friction", "max_force")
PROGRESS = re.compile(r"chunk (\d+)/(\d+) \((\d+)/(\d+) grasps\)")
RESUMING = re.compile(r"resuming: (\d+) of")
PROGRAMS = re.compile(r"programs by contact count \((.*?); the first chunk")
SEGMENT = re.compile(r"^(\d+)(?:-(\d+))? contacts at width (\d+): (\d+) grasps$")


def log_line(fh, text: str) -> None:
    stamp = time.strftime("%H:%M:%S")
    load = os.getloadavg()[0]
    line = f"[{stamp} load {load:.2f}] {text}"
    print(line, flush=True)
    if fh is not None:
        fh.write(line + "\n")
        fh.flush()


def build_set(count: int, seed: int, path: Path, nmax: int = 7) -> None:
    """Write ``count`` seeded grasps, contacts ``2 + i % 6``, padded to ``nmax`` (SI units)."""
    from _lab.grasp_draws import NumpyDraw, build_grasp_fields

    rng = np.random.default_rng(seed)
    cols = {k: np.zeros((count, nmax, 3)) for k in ("positions", "normals")}
    cols.update({k: np.ones((count, nmax)) for k in PER_CONTACT})
    cols["normals"][:, :, 2] = 1.0  # padded contacts: ignored, but numbers of a valid shape
    cols["active"] = np.zeros((count, nmax), bool)
    cols["mass"], cols["gravity"] = np.zeros(count), np.zeros((count, 3))
    for i in range(count):
        n = 2 + i % 6
        f = build_grasp_fields(NumpyDraw(rng), n=n)
        cols["positions"][i, :n], cols["normals"][i, :n] = f["positions"], f["normals"]
        for k in PER_CONTACT:
            cols[k][i, :n] = np.broadcast_to(f[k], (n,))
            cols[k][i, n:] = cols[k][i, 0]
        cols["active"][i, :n] = True
        cols["mass"][i], cols["gravity"][i] = f["mass"], f["gravity"]
    np.savez(path, **cols)


def status_value(pid: int, key: str) -> float:
    """``key`` (``VmRSS``/``VmHWM``) of process ``pid`` in MiB, NaN once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


class Phase:
    """One ``jaxgrasp batch`` subprocess: its progress lines, RSS samples, and peak."""

    def __init__(self, argv: list[str], dt: float, stop_at: int | None):
        self.argv, self.dt, self.stop_at = argv, dt, stop_at
        self.done, self.samples, self.progress, self.peak = 0, [], [], float("nan")
        self.base = 0  # grasps a resumed run found finished (its progress counts the rest)
        self.segments: list[tuple[str, int, int]] = []  # (program, grasps done before it, after it)
        self.stderr_tail: list[str] = []

    def _read(self, proc) -> None:
        for line in proc.stderr:
            self.stderr_tail = (self.stderr_tail + [line.rstrip()])[-20:]
            r = RESUMING.search(line)
            if r:
                self.base = self.done = int(r.group(1))
            g = PROGRAMS.search(line)
            if g:  # the engine's programs, in the order it runs them
                at = self.base
                for part in g.group(1).split("; "):
                    seg = SEGMENT.match(part)
                    if seg:
                        lo, hi, width, n = seg.groups()
                        name = f"{lo}{'-' + hi if hi else ''} at width {width}"
                        self.segments.append((name, at, at + int(n)))
                        at += int(n)
            m = PROGRESS.search(line)
            if m:
                self.done = self.base + int(m.group(3))
                self.progress.append((time.perf_counter(), self.done))
                if self.stop_at is not None and self.done >= self.stop_at and proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
                    self.stop_at = None

    def run(self) -> int:
        proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        reader = threading.Thread(target=self._read, args=(proc,), daemon=True)
        reader.start()
        while proc.poll() is None:
            rss = status_value(proc.pid, "VmRSS")
            hwm = status_value(proc.pid, "VmHWM")
            if rss == rss:
                self.samples.append((time.perf_counter(), self.done, rss))
                self.peak = hwm if self.peak != self.peak else max(self.peak, hwm)
            time.sleep(self.dt)
        reader.join(timeout=10)
        self.stdout = proc.stdout.read()
        return proc.returncode

    def rate(self) -> float:
        """Grasps/s between the first and last progress line (compiling is before the first)."""
        if len(self.progress) < 2:
            return float("nan")
        (t0, d0), (t1, d1) = self.progress[0], self.progress[-1]
        return (d1 - d0) / (t1 - t0)

    def slope(self, start: int) -> float:
        """RSS slope, MiB per 10,000 grasps done, over samples with at least ``start`` done."""
        s = np.array([(d, r) for _, d, r in self.samples if d >= start], float)
        if len(s) < 3 or np.ptp(s[:, 0]) == 0:
            return float("nan")
        return float(np.polyfit(s[:, 0], s[:, 1], 1)[0] * 1e4)

    def per_program(self) -> list[tuple[str, int, float, float, float]]:
        """Each program's ``(name, grasps, RSS MiB after its first chunk, RSS MiB before
        its last, slope MiB per 10,000 grasps)`` over the samples taken while it ran:
        after its first chunk (which holds its compilation) and before its last chunk
        ended (after which the next program compiles with the count unchanged)."""
        out = []
        for name, lo, hi in self.segments:
            first = next((d for _, d in self.progress if d > lo), None)
            s = np.array([(d, r) for _, d, r in self.samples if first is not None and first <= d < hi], float)
            if len(s) < 3 or np.ptp(s[:, 0]) == 0:
                out.append((name, hi - lo, float("nan"), float("nan"), float("nan")))
                continue
            out.append((name, hi - lo, s[0, 1], s[-1, 1], float(np.polyfit(s[:, 0], s[:, 1], 1)[0] * 1e4)))
        return out

    def at_tenths(self, total: int) -> list[tuple[int, float]]:
        """(grasps done, RSS MiB) at the first sample past each tenth of ``total``."""
        out = []
        for k in range(1, 11):
            hit = next(((d, r) for _, d, r in self.samples if d >= k * total // 10), None)
            if hit is not None and (not out or hit[0] != out[-1][0]):
                out.append(hit)
        return out


def result_bytes(path: Path) -> int:
    """Bytes of the arrays of ``results.npz``: what the finished run holds for its rows."""
    with np.load(path) as z:
        return sum(z[k].nbytes for k in z.files)


def read_results(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def check_rows(data: Path, rows: list[dict], k: int, seed: int, fh) -> None:
    """Evaluate ``k`` random rows again in this process, each contact count at the width
    the command planned for the whole set: statuses equal, values to 1e-9."""
    import jaxgrasp
    from jaxgrasp.io import load_dataset

    from jaxgrasp.engine import plan_widths
    from jaxgrasp.engine import grasps_by_count
    from jaxgrasp.engine import evaluate_dataset

    gset = load_dataset(data)
    pick = np.sort(np.random.default_rng(seed + 1).choice(len(rows), size=min(k, len(rows)), replace=False))
    # each row at the width the command gave its contact count (planned from the whole set)
    widths = plan_widths(grasps_by_count(gset.num_contacts))
    sample = jaxgrasp.GraspSet(grasps=tuple(gset.grasps[int(i)] for i in pick), errors=(None,) * len(pick),
                               source=str(data))
    ev, _ = evaluate_dataset(sample, widths=widths)
    value_key = next(c for c in rows[0] if c.startswith("value"))
    worst, mismatched = 0.0, 0
    for j, i in enumerate(pick):
        v_csv = float(rows[i][value_key])
        v = float(np.asarray(ev.value)[j])
        mismatched += str(rows[i]["status"]) != str(ev.status_names[j])
        worst = max(worst, abs(v - v_csv) / max(abs(v), 1e-300) if v != v_csv else 0.0)
    log_line(fh, f"check: {len(pick)} random rows evaluated again in-process: statuses differing {mismatched}, "
                 f"value max rel diff {worst:.1e} (csv {value_key})")
    if mismatched or worst > 1e-9:
        raise SystemExit("check failed: results.csv differs from a fresh evaluation")


def report_phase(name: str, ph: Phase, total: int, rc: int, fh) -> None:
    log_line(fh, f"{name}: exit {rc}, grasps done {ph.done}/{total}, steady rate {ph.rate():.1f} grasps/s, "
                 f"peak RSS (VmHWM) {ph.peak:.0f} MiB")
    tenths = ", ".join(f"{d}: {r:.0f}" for d, r in ph.at_tenths(total))
    log_line(fh, f"{name}: RSS MiB at grasps done (each tenth of the set reached) {tenths}")
    if ph.segments:
        rows = "; ".join(f"{p}: {n} grasps, {a:.0f} -> {b:.0f} MiB, {k:+.2f} MiB per 10,000"
                         for p, n, a, b, k in ph.per_program())
        log_line(fh, f"{name}: RSS while each program ran (after its first chunk, which compiles it) {rows}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stop-at", type=float, default=0.3, help="fraction of the set done when SIGINT is sent")
    ap.add_argument("--dt", type=float, default=0.5, help="RSS sampling period, s")
    ap.add_argument("--check", type=int, default=200, help="rows evaluated again in-process")
    ap.add_argument("--work", default=None, help="scratch folder (default: a new temporary one)")
    ap.add_argument("--log", default=None)
    args = ap.parse_args()
    fh = open(args.log, "w") if args.log else None
    work = Path(args.work or tempfile.mkdtemp(prefix="jaxgrasp-100k-"))
    work.mkdir(parents=True, exist_ok=True)
    data, out = work / "set.npz", work / "out"
    import jax

    log_line(fh, f"batch 100k: {args.count} grasps (seed {args.seed}, contacts 2..7), jax {jax.__version__}, "
                 f"{os.cpu_count()} CPUs, load average at start {os.getloadavg()}")
    t = time.perf_counter()
    if not data.exists():
        build_set(args.count, args.seed, data)
    log_line(fh, f"dataset {data} ({data.stat().st_size / 2**20:.1f} MiB) ready in {time.perf_counter() - t:.1f} s")
    cmd = [sys.executable, "-m", "jaxgrasp", "batch", str(data), "--out", str(out)]
    first = Phase(cmd, args.dt, int(args.stop_at * args.count))
    rc = first.run()
    report_phase("run 1 (stopped by SIGINT)", first, args.count, rc, fh)
    if rc != 130:
        log_line(fh, "run 1 stderr tail: " + " | ".join(first.stderr_tail))
        raise SystemExit(f"expected exit 130 after SIGINT, got {rc}")
    second = Phase(cmd + ["--resume"], args.dt, None)
    rc = second.run()
    report_phase("run 2 (--resume)", second, args.count, rc, fh)
    if rc != 0:
        log_line(fh, "run 2 stderr tail: " + " | ".join(second.stderr_tail))
        raise SystemExit(f"resumed run failed with exit {rc}")
    start = second.progress[0][1] if second.progress else 0
    log_line(fh, f"memory: RSS slope over the resumed run's steady part {second.slope(start):+.2f} MiB per 10,000 grasps "
                 f"(from {start} grasps done); run 1 {first.slope(first.progress[0][1] if first.progress else 0):+.2f}")
    held = result_bytes(out / "results.npz") / args.count * 1e4 / 2**20
    log_line(fh, f"memory: the result arrays themselves (results.npz, every Evaluation field) take {held:.2f} MiB "
                 f"per 10,000 grasps; the resumed run's slope beyond them {second.slope(start) - held:+.2f}")
    rows = read_results(out / "results.csv")
    counts = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    log_line(fh, f"results.csv: {len(rows)} rows (expected {args.count}); statuses {counts}")
    if len(rows) != args.count:
        raise SystemExit("results.csv does not hold every row")
    check_rows(data, rows, args.check, args.seed, fh)
    log_line(fh, "second run's last lines: " + " | ".join(second.stderr_tail[-3:]))
    log_line(fh, f"load average at end {os.getloadavg()}")


if __name__ == "__main__":
    main()
