"""Issue 41: the work queue's loop steps and the batch's run time by chunk size and by how
often the queue asks its release rule (``jaxgrasp.solver._lanes.RELEASE_EVERY``).

One process per setting: the batch benchmark's 1000 mixed grasps through
``evaluate_batch(chunk_size=CHUNK)`` (executable store off) with the queue's loop steps
and idle slots counted as ``queue_steps.py`` counts them; then, with the uncounted
queue compiled again, three timed runs (wall and process CPU seconds).

    python experiments/chunk_release.py CHUNK RELEASE_EVERY
"""

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
for _p in (ROOT, ROOT / "tests", ROOT / "experiments"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

import jax  # noqa: E402

import jaxgrasp  # noqa: E402
from _common import say  # noqa: E402
from jaxgrasp.engine import _compile, _store  # noqa: E402
from jaxgrasp.solver import _lanes  # noqa: E402


def main():
    from batch_benchmark import make_grasps
    from queue_steps import counting_queue

    chunk, every = int(sys.argv[1]), int(sys.argv[2])
    _lanes.RELEASE_EVERY = every
    _store.set_executable_dir(None)
    runs: list = []
    counting_queue(runs, jaxgrasp.SolverOptions().max_steps)
    grasps = make_grasps(1000, 0)
    jaxgrasp.evaluate_batch(grasps, chunk_size=chunk)
    steps, slots, idle = (sum(r[0] for r in runs), sum(r[0] * r[1] for r in runs), sum(r[2] for r in runs))
    _lanes.jax = jax  # the queue without its counters, for the timed runs
    _compile.clear_compiled()
    jaxgrasp.evaluate_batch(grasps, chunk_size=chunk)
    times = []
    for _ in range(3):
        c0 = time.process_time()
        res = jaxgrasp.evaluate_batch(grasps, chunk_size=chunk)
        times.append(f"{res.run_seconds:.2f} s (CPU {time.process_time() - c0:.1f} s)")
    say(f"chunk {chunk}, release every {every}: {steps} loop steps, idle slot-steps {idle / slots:.3f}; "
        f"runs {', '.join(times)}")


if __name__ == "__main__":
    main()
