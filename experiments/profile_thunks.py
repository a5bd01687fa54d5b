"""Where one loop step of the solver's work queue goes, thunk by thunk (issue 41).

Traces the batch engine's ``lanes`` stage with ``jax.profiler`` on grasps of the
benchmark's random set (padded to 7 contacts) and prints, per loop step of one device's
queue, the time and count of XLA's thunks: the ``K`` most expensive with the shape they
produce (from the optimised HLO, dumped alongside), and the totals by opcode. Times are
inflated by the profiler's own cost per event, so compare within one run.

    python experiments/profile_thunks.py [--grasps 32] [--top 30] [--chunk N] [--release-every K]

``--chunk`` sets ``evaluate_batch``'s ``chunk_size`` (default: the engine's);
``--release-every`` replaces the queue's ``RELEASE_EVERY`` in this process (to compare).
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
for _p in (ROOT, ROOT / "tests", ROOT / "experiments"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grasps", type=int, default=32)
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--chunk", type=int, default=None)
    ap.add_argument("--release-every", type=int, default=None)
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="jaxgrasp-thunks-"))
    # set before jax starts: the optimised HLO names the thunks the trace times
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + f" --xla_dump_to={work / 'hlo'} "
                               "--xla_dump_hlo_as_text --xla_dump_hlo_module_re=.*run.*")
    os.environ["JAXGRASP_CACHE_DIR"] = str(work / "store")  # compile here, so that the HLO is dumped

    import jax

    import jaxgrasp
    from batch_benchmark import make_grasps
    from jaxgrasp.engine import _evaluator
    from jaxgrasp.solver import _lanes

    if a.release_every is not None:
        _lanes.RELEASE_EVERY = a.release_every

    real = _evaluator.compiled_evaluator
    tracing = {"on": False}

    def traced(*args, **kwargs):
        fn, seconds = real(*args, **kwargs)
        if not getattr(fn, "_traced", False):
            stage = fn.stages["lanes"]

            def wrap(*xs):
                if not tracing["on"]:
                    return stage(*xs)
                with jax.profiler.trace(str(work / "trace")):
                    return jax.block_until_ready(stage(*xs))

            fn.stages["lanes"] = wrap
            fn._traced = True
        return fn, seconds

    _evaluator.compiled_evaluator = traced
    grasps = make_grasps(1000, 0)[: a.grasps]
    jaxgrasp.evaluate_batch(grasps, chunk_size=a.chunk)  # compile
    tracing["on"] = True
    jaxgrasp.evaluate_batch(grasps, chunk_size=a.chunk)

    events = json.load(gzip.open(sorted(glob.glob(str(work / "trace" / "**" / "*.trace.json.gz"), recursive=True))[-1]))
    events = [e for e in events["traceEvents"] if e.get("ph") == "X"]
    thread = collections.Counter((e["pid"], e["tid"]) for e in events).most_common(1)[0][0]
    dur, cnt = collections.defaultdict(float), collections.Counter()
    for e in events:
        if (e["pid"], e["tid"]) == thread and not e["name"].startswith(("ThunkExecutor", "while")):
            dur[e["name"]] += e["dur"]
            cnt[e["name"]] += 1
    # most of the loop body's thunks run once a step (thunks outside the loop run once)
    steps = collections.Counter(c for c in cnt.values() if c >= 10).most_common(1)[0][0]
    # the lanes stage's module: the one whose instructions name the most traced thunks
    # (fusion names repeat across modules)
    modules = [Path(f).read_text() for f in glob.glob(str(work / "hlo" / "*after_optimizations.txt"))]
    defined = lambda text: set(re.findall(r"^\s*%?([\w.\-]+) = ", text, re.M))  # noqa: E731
    hlo = max(modules, key=lambda text: len(defined(text) & set(dur)))
    shape, opcode = {}, {}
    for m in re.finditer(r"^\s*%?([\w.\-]+) = (\S+) ([\w-]+)\(", hlo, re.M):
        shape[m.group(1)], opcode[m.group(1)] = m.group(2), m.group(3)
    print(f"$ python experiments/profile_thunks.py --grasps {a.grasps} --chunk {a.chunk} "
          f"--release-every {_lanes.RELEASE_EVERY}")
    print(f"{a.grasps} grasps; {steps} loop steps traced on one device; per loop step: "
          f"{sum(dur.values()) / steps:.0f} us in {sum(cnt.values()) / steps:.0f} thunks (profiled)")
    print(f"{'us/step':>8} {'n/step':>6}  thunk  [shape]")
    for k in sorted(dur, key=lambda k: -dur[k])[: a.top]:
        print(f"{dur[k] / steps:8.1f} {cnt[k] / steps:6.2f}  {k}  {shape.get(k, '')}")
    by_op = collections.defaultdict(lambda: [0.0, 0])
    for k in dur:
        op = opcode.get(k, "other")
        by_op[op][0] += dur[k]
        by_op[op][1] += cnt[k]
    print("by opcode: " + ", ".join(f"{op} {d / steps:.0f} us ({n / steps:.0f})" for op, (d, n) in
                                     sorted(by_op.items(), key=lambda kv: -kv[1][0])[:8]))
    print(f"load average {os.getloadavg()}; trace and HLO in {work}")


if __name__ == "__main__":
    main()
