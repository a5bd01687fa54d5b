"""Closest points at scale (issue 65, item 1): throughput and peak memory against face count.

For icospheres of about 1k, 20k, 80k and 1.3M faces, each measurement in a fresh process
(its peak RSS is the process's): the face tree's build, ``Surface.closest`` of 1500 points
near the surface (compiled once, then the best of three calls), the host search that snaps
a mesh grasp's contacts (`nearest_faces`), and, where it fits in memory, the brute force
that ``Surface.closest`` ran before the tree (every query against every face, vmapped: the
old code, with fewer queries as the faces grow). Prints one line per measurement with the
load average; then ``Surface.closest`` at 80k faces with leaves of 4 to 32 faces.
``--quick`` stops at 80k faces.

    python experiments/surface_scale/benchmark.py [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import time

SUBDIVISIONS = (3, 5, 6, 8)  # icosphere faces 20 * 4^s: 1280, 20480, 81920, 1310720
QUERIES = 1500
BRUTE_PAIRS = 2e7  # queries x faces of one brute-force call (its (Q, F, 3) arrays, several of them)
BRUTE_FACES = 2e5  # above this, even a few queries of the brute force take gigabytes


def _points(n, radius, seed=0):
    import numpy as np

    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True) * radius * rng.uniform(0.95, 1.05, size=(n, 1))


def _best_of(f, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t)
    return best


def one(kind: str, sub: int) -> dict:
    """One measurement in this process (``kind``: index, host or brute)."""
    import jax
    import numpy as np
    import trimesh

    import jaxgrasp  # noqa: F401  (float64)
    from jaxgrasp.surface import Surface, build_tree, closest_on_triangles, nearest_faces

    mesh = trimesh.creation.icosphere(subdivisions=sub, radius=0.04)
    out = {"kind": kind, "faces": len(mesh.faces)}
    tri, nrm = np.asarray(mesh.triangles), np.asarray(mesh.face_normals)
    if kind == "index" or kind.startswith("leaf"):
        t = time.perf_counter()
        surface = Surface.from_trimesh(mesh)
        out["build_s"] = time.perf_counter() - t
        if kind.startswith("leaf"):  # the same surface, its tree built with leaves of another size
            tree = build_tree(np.asarray(surface.triangles), np.asarray(surface.normals), leaf_size=int(kind[4:]))
            surface = dataclasses.replace(surface, tree=jax.tree_util.tree_map(jax.numpy.asarray, tree))
        pts = _points(QUERIES, 0.04)
        f = jax.jit(lambda s, p: s.closest(p))
        t = time.perf_counter()
        jax.block_until_ready(f(surface, pts))
        out["first_call_s"] = time.perf_counter() - t
        out["queries"] = QUERIES
        out["seconds"] = _best_of(lambda: jax.block_until_ready(f(surface, pts)))
    elif kind == "host":
        tree = build_tree(tri, nrm)
        pts = _points(QUERIES, 0.04)
        out["queries"] = QUERIES
        out["seconds"] = _best_of(lambda: nearest_faces(tree, pts, margin=1e-9 * 0.08, scale=0.08))
    else:
        q = int(min(QUERIES, max(1, BRUTE_PAIRS // len(tri))))
        pts, tj = _points(q, 0.04), jax.numpy.asarray(tri)

        def brute(p):  # the closest point as Surface.closest computed it before the tree
            c = closest_on_triangles(p, tj)
            return c[jax.numpy.argmin(jax.numpy.sum((c - p) ** 2, axis=-1))]

        f = jax.jit(jax.vmap(brute))
        jax.block_until_ready(f(pts))
        out["queries"] = q
        out["seconds"] = _best_of(lambda: jax.block_until_ready(f(pts)))
    out["rate"] = out["queries"] / out["seconds"]
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="stop at 80k faces")
    ap.add_argument("--one", nargs=2, metavar=("KIND", "SUBDIVISIONS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(args.one[0], int(args.one[1]))))
        return
    subs = SUBDIVISIONS[:-1] if args.quick else SUBDIVISIONS
    print(f"closest points, {QUERIES} queries near an icosphere's surface; each line a fresh process")
    for sub in subs:
        for kind in ("index", "host", "brute"):
            if kind == "brute" and 20 * 4**sub > BRUTE_FACES:
                print(f"faces {20 * 4**sub:>8}  brute   skipped: over {BRUTE_FACES:.0f} faces (a few queries take gigabytes)")
                continue
            run = subprocess.run([sys.executable, __file__, "--one", kind, str(sub)], capture_output=True, text=True)
            if run.returncode != 0:
                print(f"faces {20 * 4**sub:>8}  {kind:<5}  failed: {run.stderr.strip().splitlines()[-1]}")
                continue
            r = json.loads(run.stdout.strip().splitlines()[-1])
            _line(r)
    print("leaf size, 80k faces")
    for k in (4, 8, 16, 32):
        run = subprocess.run([sys.executable, __file__, "--one", f"leaf{k}", "6"], capture_output=True, text=True)
        _line(json.loads(run.stdout.strip().splitlines()[-1]))


def _line(r: dict) -> None:
    extra = f"  build {r['build_s']:.2f} s  first call {r['first_call_s']:.1f} s" if "build_s" in r else ""
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"faces {r['faces']:>8}  {r['kind']:<6}  {r['rate']:>9.0f} queries/s ({r['queries']} in {r['seconds']:.3f} s)"
          f"  peak RSS {r['peak_rss_mb']:>6.0f} MB{extra}  load {load}", flush=True)


if __name__ == "__main__":
    main()
