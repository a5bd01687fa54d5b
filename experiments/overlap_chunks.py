"""Issue 41: does reading a chunk's results while the next chunk already runs shorten a batch?

``jaxgrasp.evaluate_batch`` runs a chunk over both CPU devices, then reads its results
back before it sends the next one (``jaxgrasp.engine._run.run_chunks``). Each device
runs its own work queue, and one device's queue usually ends before the other's. This
experiment sends chunk ``k + depth`` before it reads chunk ``k`` (``depth`` 1 or 2,
JAX's asynchronous dispatch), so that a device whose queue ended could start the next
chunk at once. The three ways are run in turn, ``--repeats`` times each (the order
rotated from one round to the next, as the machine's speed drifts), in one process, on
the batch benchmark's 1000 mixed grasps (2 to 7 contacts), after one compiling run;
every result is compared with the first run's. The medians close the log.

    python experiments/overlap_chunks.py [--count 1000] [--repeats 6]
"""

import argparse
import collections
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
for _p in (ROOT, ROOT / "experiments"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

import numpy as np  # noqa: E402

import jaxgrasp  # noqa: E402
from _common import say  # noqa: E402
from jaxgrasp.engine import _batch, _run  # noqa: E402
from jaxgrasp.tolerance._result import FIELDS  # noqa: E402

IN_ORDER = _run.run_chunks


def overlapped(depth: int):
    """A ``run_chunks`` that keeps ``depth`` chunks in flight before it reads one back
    (no settling evaluator: a batch has the settling stage inline)."""

    def run_chunks(fn, chunk_fields, names, plan, progress=None, on_chunk=None, keep=FIELDS, settling=None):
        assert settling is None
        outs, pending = {}, collections.deque()
        deal, undeal = _run._dealt(plan.chunk, plan.n_devices)
        t0 = time.perf_counter()

        def read(start, stop, results):
            res = {f: _run._gather(r)[undeal] for f, r in zip(FIELDS, results) if f in keep}
            for f in keep:
                outs.setdefault(f, np.empty((plan.total, *res[f].shape[1:]), dtype=res[f].dtype))
                outs[f][start:stop] = res[f][: stop - start]
            if on_chunk is not None:
                on_chunk(start, stop, outs)
            if progress is not None:
                progress(stop, plan.total)

        for start in range(0, plan.total, plan.chunk):
            fields = chunk_fields(start)
            pending.append((start, min(start + plan.chunk, plan.total),
                            fn(*[_run._put(fields[k][deal], plan.sharding) for k in names])))
            if len(pending) > depth:
                read(*pending.popleft())
        while pending:
            read(*pending.popleft())
        return outs, time.perf_counter() - t0

    return run_chunks


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=6)
    a = ap.parse_args()
    from batch_benchmark import make_grasps

    say(f"$ python experiments/overlap_chunks.py --count {a.count} --repeats {a.repeats}")
    grasps = make_grasps(a.count, 0)
    first = jaxgrasp.evaluate_batch(grasps)
    say(f"compiling run: compile {first.compile_seconds:.1f} s, run {first.run_seconds:.2f} s")
    runs = collections.defaultdict(list)
    for rep in range(a.repeats):
        for depth in np.roll([0, 1, 2], -rep).tolist():
            chunks = IN_ORDER if depth == 0 else overlapped(depth)
            _run.run_chunks = _batch.run_chunks = chunks
            c0 = time.process_time()
            res = jaxgrasp.evaluate_batch(grasps)
            cpu = time.process_time() - c0
            same = all(np.array_equal(np.asarray(getattr(res, f)), np.asarray(getattr(first, f)), equal_nan=True)
                       for f in FIELDS)
            say(f"chunks in flight {depth + 1}: run {res.run_seconds:.2f} s ({a.count / res.run_seconds:.1f} grasps/s),"
                f" process CPU {cpu:.1f} s, results identical to the first run: {same}")
            runs[depth].append(res.run_seconds)
    base = statistics.median(runs[0])
    for depth in (0, 1, 2):
        m = statistics.median(runs[depth])
        say(f"chunks in flight {depth + 1}: median run {m:.2f} s over {len(runs[depth])} runs, "
            f"{m / base:.3f} of one in flight")
    _run.run_chunks = _batch.run_chunks = IN_ORDER


if __name__ == "__main__":
    main()
