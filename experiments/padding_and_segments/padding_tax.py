"""Issue 41, item 1: what a grasp pays for being padded to the widest grasp of a mixed set.

For each contact count ``N`` of ``--counts``, the batch benchmark's grasps with ``N``
contacts (``batch_benchmark.make_grasps(1000, 0)``, about 167 each) are evaluated by
:func:`jaxgrasp.evaluate_batch` twice: at their own width (``jaxgrasp.stack``: ``N``
contacts) and padded with inactive contacts to ``--width`` (``stack(..., num_contacts=
width)``), as a mixed set pads them. Printed per count: the boundary lanes run and their
lane-steps at both widths (one run each, counted as ``profile_batch.profile`` counts
them: the padded lanes are the same lanes, so these should be equal), the process CPU
seconds per grasp of both (median of ``--repeats`` runs, own and padded alternating,
after one run of each to compile), their ratio (the padding tax), and whether statuses
and values agree. The process reads an empty executable store of its own
(``JAXGRASP_CACHE_DIR``), so nothing is read from an earlier run.

With ``--queue`` each count is evaluated twice more, in a child process of its own with
the executable store off (the evaluators are memoised per process, and the timed runs
must not carry the counter), with the work queue's loop counted
(``queue_steps.counting_queue``): loop steps and idle slot-steps summed over the queue
runs, own width against padded. A loop step costs every slot, running or idle, so these
tell a dearer step from more of them.

    python experiments/padding_and_segments/padding_tax.py [--counts 2,3,4,5,6,7] [--width 7] [--repeats 3]
        [--queue]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark", "solver_steps")  # the studies whose scripts this one imports

os.environ["JAXGRASP_CACHE_DIR"] = tempfile.mkdtemp(prefix="padding_tax_store_")

from _lab import agreement, say  # noqa: E402


def boundary_lane_steps(grasps) -> tuple[int, int]:
    """``(lanes run, lane-steps)`` of the boundary lanes of one run of ``grasps``."""
    import profile_batch

    p = profile_batch.profile(grasps, "", repeats=1)
    run = sum(n for k, (n, _, _) in p["lanes"].items() if k.startswith("boundary:") and k != "boundary:lanes_total"
              and k != "boundary:no_start")
    steps = sum(s for k, (_, s, _) in p["lanes"].items() if k.startswith("boundary:"))
    return run, steps


def queue_counts(batch) -> tuple[int, int, int]:
    """``(loop steps, slot-steps, idle slot-steps)`` over every queue run of one evaluation
    of ``batch`` (the executable store off, so that the counting queue is compiled)."""
    import queue_steps

    import jaxgrasp
    from jaxgrasp.engine import executable_dir, set_executable_dir

    runs: list = []
    queue_steps.counting_queue(runs, jaxgrasp.SolverOptions().max_steps)
    stored = executable_dir()
    set_executable_dir(None)
    try:
        jaxgrasp.evaluate_batch(batch)
    finally:
        set_executable_dir(stored)
    return sum(r[0] for r in runs), sum(r[0] * r[1] for r in runs), sum(r[2] for r in runs)


def queue_line(n: int, width: int) -> str:
    """:func:`queue_counts` of count ``n``'s grasps, own width and padded, in a child process."""
    import subprocess

    out = subprocess.run([sys.executable, __file__, "--counts", str(n), "--width", str(width), "--queue-child"],
                         check=True, capture_output=True, text=True).stdout
    return out.strip().splitlines()[-1]


def cpu_seconds(batch) -> tuple[float, object]:
    import jaxgrasp

    c0 = time.process_time()
    res = jaxgrasp.evaluate_batch(batch)
    return time.process_time() - c0, res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default="2,3,4,5,6,7")
    ap.add_argument("--width", type=int, default=7)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--queue", action="store_true", help="also count the work queue's loop steps and idle slots")
    ap.add_argument("--queue-child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    import jax

    import jaxgrasp
    from batch_benchmark import make_grasps

    say(f"$ python experiments/padding_and_segments/padding_tax.py --counts {a.counts} --width {a.width} --repeats {a.repeats}"
        + (" --queue" if a.queue else ""))
    say(f"jax {jax.__version__} ({jax.default_backend()}, {jax.device_count()} device(s)), "
        f"{os.cpu_count()} CPUs; load average {os.getloadavg()}")
    everything = make_grasps(1000, 0)
    if a.queue_child:
        grasps = [g for g in everything if g.num_contacts == int(a.counts)]
        q_own = queue_counts(jaxgrasp.stack(grasps))
        # at the full width the padded batch is the same program: memoised, it counts nothing
        q_pad = q_own if int(a.counts) >= a.width else queue_counts(jaxgrasp.stack(grasps, num_contacts=a.width))
        print(f"N={a.counts}: work queue, own width / padded: loop steps {q_own[0]} / {q_pad[0]}, idle slot-steps "
              f"{q_own[2] / q_own[1]:.1%} / {q_pad[2] / q_pad[1]:.1%} of {q_own[1]} / {q_pad[1]}")
        return
    rows = []
    for n in [int(c) for c in a.counts.split(",")]:
        grasps = [g for g in everything if g.num_contacts == n]
        own, padded = jaxgrasp.stack(grasps), jaxgrasp.stack(grasps, num_contacts=a.width)
        lanes_own, steps_own = boundary_lane_steps(own)
        lanes_pad, steps_pad = boundary_lane_steps(padded)
        cpu = {"own": [], "padded": []}
        results = {}
        for _ in range(a.repeats):
            for label, batch in (("own", own), ("padded", padded)):
                s, results[label] = cpu_seconds(batch)
                cpu[label].append(s)
        ms_own = 1e3 * np.median(cpu["own"]) / len(grasps)
        ms_pad = 1e3 * np.median(cpu["padded"]) / len(grasps)
        r_own, r_pad = results["own"], results["padded"]
        say(f"N={n}: {len(grasps)} grasps; boundary lanes run {lanes_own} / {lanes_pad}, lane-steps {steps_own} / "
            f"{steps_pad} (own width / padded to {a.width}); CPU per grasp {ms_own:.2f} ms / {ms_pad:.2f} ms "
            f"(runs {', '.join(f'{x:.2f}' for x in cpu['own'])} / {', '.join(f'{x:.2f}' for x in cpu['padded'])} s): "
            f"padded / own {ms_pad / ms_own:.2f}; {agreement(r_pad.status, r_pad.value, r_own.status, r_own.value)}")
        if a.queue:
            say(queue_line(n, a.width))
        rows.append((n, len(grasps), steps_own, steps_pad, ms_own, ms_pad))
    print(f"\npadding tax, {os.cpu_count()} CPUs, load average at the end {os.getloadavg()}\n")
    print("| contacts | grasps | boundary lane-steps, own / padded | CPU ms per grasp, own width "
          f"| padded to {a.width} | padded / own |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n, count, s_own, s_pad, m_own, m_pad in rows:
        print(f"| {n} | {count} | {s_own} / {s_pad} | {m_own:.2f} | {m_pad:.2f} | {m_pad / m_own:.2f} |")


if __name__ == "__main__":
    main()
