"""What the caps of issue 65 bound: the time of one evaluation against its contact count, the
memory of a robust copy, and the size of the executables jaxgrasp stores.

Each measurement runs in a fresh subprocess (the executable store off, so every process
compiles; peak RSS from ``resource``):

* ``contacts``: one grasp of N contacts (at most ``MAX_CONTACTS``, which ``Grasp.create`` holds to) spread over a sphere of 5 cm, evaluated twice (the
  second evaluation, with a friction 1 % higher, is the one timed: no compilation);
* ``robust``: ``jaxgrasp.analysis.perturbed`` of the paper's cube (its draws and perturbed
  fields, bytes per copy) and the result arrays of ``evaluate_batch`` over 256 copies
  (bytes per copy), which ``robust`` holds until its statistics;
* ``chunks`` (with ``--chunks``): peak RSS of ``evaluate_batch`` over C perturbed copies
  of the cube in one chunk of C, for each C given (the growth per grasp is what a chunk's
  temporaries cost);
* ``store``: the sizes of the files in the default executable store, if any.

    python experiments/limits/limits_cost.py                       # contacts 8, 16, 32 (the cap)
    python experiments/limits/limits_cost.py --contacts 8,16       # a quick look
    python experiments/limits/limits_cost.py --contacts 8 --chunks 64,1024,4096
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

_CONTACTS = """
import json, os, resource, sys, time
import numpy as np, jaxgrasp
jaxgrasp.configure()
n = int(sys.argv[1])
v = np.random.default_rng(0).normal(size=(n, 3)); v /= np.linalg.norm(v, axis=1, keepdims=True)
g = jaxgrasp.Grasp.create(positions=0.05 * v, normals=v, initial_deformation=1e-3, radius=0.025,
                          young_modulus=2e5, friction=0.5, max_force=15.0)
t = time.perf_counter(); jaxgrasp.evaluate(g); first = time.perf_counter() - t
t = time.perf_counter(); r = jaxgrasp.evaluate(g.replace(friction=g.friction * 1.01)); again = time.perf_counter() - t
print(json.dumps({"contacts": n, "first_s": first, "evaluation_s": again, "status": r.status_name,
                  "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

_ROBUST = """
import json, jax, numpy as np, jaxgrasp
jaxgrasp.configure()
from jaxgrasp.analysis import parse_spec, perturbed
from jaxgrasp.presets import cube
u = parse_spec("friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3")
p = perturbed(cube(), u, samples=256)
r = jaxgrasp.evaluate_batch(p, chunk_size=256)
leaves = jax.tree_util.tree_leaves(r.evaluation) + [r.num_contacts, r.active]
print(json.dumps({"perturbed_bytes_per_copy": sum(np.asarray(x).nbytes for x in jax.tree_util.tree_leaves(p)) / 256,
                  "result_bytes_per_copy": sum(np.asarray(x).nbytes for x in leaves) / 256}))
"""

_CHUNK = """
import json, resource, sys, time
import jaxgrasp
jaxgrasp.configure()
from jaxgrasp.analysis import parse_spec, perturbed
from jaxgrasp.presets import cube
c = int(sys.argv[1])
u = parse_spec("friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3")
p = perturbed(cube(), u, samples=c)
t = time.perf_counter(); jaxgrasp.evaluate_batch(p, chunk_size=c)
print(json.dumps({"chunk": c, "s": time.perf_counter() - t,
                  "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def child(code: str, *args: str) -> dict:
    env = {**os.environ, "JAXGRASP_CACHE_DIR": "off"}
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def store_sizes() -> list[int]:
    import jaxgrasp.engine

    folder = jaxgrasp.engine.enable_from_environment()
    return sorted(p.stat().st_size for p in folder.glob("*.xla")) if folder else []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--contacts", default="8,16,32", help="contact counts, comma-separated")
    ap.add_argument("--chunks", default="", help="chunk sizes to measure, comma-separated (default none)")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}", flush=True)
    for n in args.contacts.split(","):
        r = child(_CONTACTS, n)
        print(f"contacts {r['contacts']:3d}: first (with compiling) {r['first_s']:7.1f} s, evaluation "
              f"{r['evaluation_s']:7.2f} s, peak RSS {r['peak_mib']:.0f} MiB ({r['status']})", flush=True)
    r = child(_ROBUST)
    print(f"robust copy of the cube: draws and perturbed fields {r['perturbed_bytes_per_copy']:.0f} B, "
          f"evaluation result {r['result_bytes_per_copy']:.0f} B", flush=True)
    for c in filter(None, args.chunks.split(",")):
        r = child(_CHUNK, c)
        print(f"chunk {r['chunk']:5d}: evaluate_batch of as many copies {r['s']:.1f} s, peak RSS "
              f"{r['peak_mib']:.0f} MiB", flush=True)
    sizes = store_sizes()
    if sizes:
        print(f"stored executables: {len(sizes)}, {sizes[0] / 2**20:.2f} to {sizes[-1] / 2**20:.2f} MiB")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
