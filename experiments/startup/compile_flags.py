"""Issue 41 and the suite's time: do XLA's CPU compiler flags shorten the compile of the
batch evaluator without slowing it?

Each setting runs in a process of its own: ``jaxgrasp.evaluate_batch`` of the first 100
four-contact grasps of the batch benchmark's mixed set (two CPU devices, executable store
off, so every stage compiles), then the same batch twice more (the faster of the two is
the run time), with the flags added to jaxgrasp's own ``COMPILER_OPTIONS``. Printed per
setting: compile seconds, run seconds, and the largest relative difference of the values
from the first setting's.

    python experiments/startup/compile_flags.py
"""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports
SETTINGS = [
    {},
    {"xla_llvm_disable_expensive_passes": True},
    {"xla_cpu_copy_insertion_use_region_analysis": False},
    {"xla_cpu_parallel_codegen_split_count": 1},
]


def child(extra: dict) -> None:
    import numpy as np

    import jaxgrasp
    from batch_benchmark import make_grasps
    from jaxgrasp.engine import COMPILER_OPTIONS, set_executable_dir

    COMPILER_OPTIONS.update(extra)
    set_executable_dir(None)
    grasps = [g for g in make_grasps(600, 0) if g.num_contacts == 4][:100]
    res = jaxgrasp.evaluate_batch(grasps)
    runs = [jaxgrasp.evaluate_batch(grasps).run_seconds for _ in range(2)]
    print(json.dumps({"compile_s": res.compile_seconds, "run_s": min(runs),
                      "value": np.asarray(res.value).tolist(), "load": os.getloadavg()[0]}))


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        return child(json.loads(sys.argv[2]))
    print(f"$ python experiments/startup/compile_flags.py    [{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"load {', '.join(f'{x:.2f}' for x in os.getloadavg())}]", flush=True)
    base = None
    for extra in SETTINGS:
        out = subprocess.run([sys.executable, __file__, "--child", json.dumps(extra)], capture_output=True,
                             text=True, check=True).stdout.strip().splitlines()[-1]
        r = json.loads(out)
        base = base or r["value"]
        diff = max((abs(a - b) / abs(b) for a, b in zip(r["value"], base) if b), default=0.0)
        print(f"{json.dumps(extra) or '{}':55s} compile {r['compile_s']:5.1f} s, run {r['run_s']:.2f} s, "
              f"values max rel diff {diff:.1e}  [load {r['load']:.2f}]", flush=True)


if __name__ == "__main__":
    main()
