"""Plan time and peak memory against face count: one real object, subdivided.

pybullet's generated object ``random_urdfs/002`` (348 faces, scaled to mm as in
``experiments/planning``) is subdivided 0-4 times (348 to 89,088 faces: every new face lies
in an old face's plane, so the object and its grasps are the same at every size) and
``jaxgrasp plan --fingers 3`` runs on each as a user would, in its own process, on the
command line's defaults, with an empty executable store (every compilation counted, as
for a new user's first plan). The wall time, the child's peak resident memory (``ru_maxrss``)
and the best value are printed side by side, with the load average. Issue 65's bound:
about 90k faces within 300 s and 4 GiB on 2 cores.

    python experiments/surface_scale/plan_scale.py [--levels 0,1,2,3,4] [--fingers 3]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def object_file(levels: int, folder: Path) -> Path:
    """random_urdfs/002 in mm, subdivided ``levels`` times (4**levels times the faces)."""
    import pybullet_data
    import trimesh

    mesh = trimesh.load(os.path.join(pybullet_data.getDataPath(), "random_urdfs/002/002.obj"), force="mesh")
    mesh.apply_scale(15.0)
    for _ in range(levels):
        mesh = mesh.subdivide()
    out = folder / f"002_x{levels}.stl"
    mesh.export(out)
    return out


def one_plan(path: Path, fingers: int, out: Path) -> dict:
    """``jaxgrasp plan`` of ``path`` in a fresh process: wall s, peak RSS GiB of that process."""
    cmd = [sys.executable, "-m", "jaxgrasp", "plan", str(path), "--units", "mm", "--fingers", str(fingers),
           "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(out.parent / f"cache-{out.name}"))  # cold: every compile counted
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    _, _, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read()
    proc.returncode = 0  # reaped by wait4
    rows = list(csv.DictReader((out / "results.csv").open())) if (out / "results.csv").exists() else []
    best = {"value_J": float(rows[0]["value_J"]), "status": rows[0]["status"]} if rows else {}
    return dict(wall_s=wall, peak_rss_gib=usage.ru_maxrss / 2**20, value_J=best.get("value_J"),
                status=best.get("status"), error=err.strip().splitlines()[-1] if err.strip() and not best else "")


def main() -> None:
    import trimesh

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,1,2,3,4")
    ap.add_argument("--fingers", type=int, default=3)
    args = ap.parse_args()
    print(f"# plan_scale: load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on {os.cpu_count()} cores")
    print(f"{'faces':>8} {'wall_s':>8} {'rss_GiB':>8} {'value_J':>12}  status")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for level in (int(x) for x in args.levels.split(",")):
            path = object_file(level, tmp)
            faces = len(trimesh.load(path, force="mesh").faces)
            r = one_plan(path, args.fingers, tmp / f"plan{level}")
            v = "" if r["value_J"] is None else f"{r['value_J']:.6e}"
            print(f"{faces:>8} {r['wall_s']:>8.1f} {r['peak_rss_gib']:>8.2f} {v:>12}  {r['status'] or r['error']}",
                  flush=True)
    print(f"# load average at the end {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")


if __name__ == "__main__":
    main()
