"""The command's done-when checks on real objects: ``jaxgrasp plan OBJ --hand ... --out DIR``,
then ``jaxgrasp evaluate DIR/best.toml --json`` against the first row of ``DIR/results.csv``,
the best grasp's joints against their limits and the Shadow hand's tendon couplings, its
other links' depth; the command's wall time per object (each a fresh process, warm cache).

Objects as in ``plan_hand_benchmark.py`` (pybullet's generated objects scaled to 70 mm, in mm).
One JSON line per object, then a summary with the load average.

    python experiments/hand_planning/check_command.py [--objects 5] [--first 0]
"""

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plan_hand_benchmark import HAND, TIPS, object_file, objects, seed_of  # noqa: E402

import jaxgrasp  # noqa: E402

COMMAND = ["--units", "mm", "--hand", str(HAND), "--fingertips", ",".join(TIPS), "--young-modulus", "3e5",
           "--friction", "0.8", "--max-force", "15", "--density", "500", "--quiet"]


def check(k: int, obj, folder: str, hand) -> dict:
    """Plan ``obj`` (an object of `objects`, ``k`` its position in this run; seed `seed_of`) by the command and
    check what it wrote."""
    path, out = object_file(obj, 70.0, folder), os.path.join(folder, f"plan-{k:03d}")
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "jaxgrasp", "plan", path, *COMMAND, "--seed", str(seed_of(obj)), "--out", out],
                          capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        return dict(object=obj, seconds=seconds, error=done.stderr.strip().splitlines()[-1:])
    with open(os.path.join(out, "results.csv")) as fh:
        top = next(csv.DictReader(fh))
    ev = json.loads(subprocess.run([sys.executable, "-m", "jaxgrasp", "evaluate", os.path.join(out, "best.toml"),
                                    "--json"], capture_output=True, text=True, check=True).stdout)
    with open(os.path.join(out, "best.toml"), "rb") as fh:
        q = np.asarray(tomllib.load(fh)["hand"]["qpos"])
    return dict(object=obj, seconds=round(seconds, 1), status=top["status"], active=int(top["active"]),
                value_J=float(top["value_J"]), evaluate_value_J=ev["value"], evaluate_status=ev["status"],
                equal=ev["value"] == float(top["value_J"]) and ev["status"] == top["status"],
                penetration_mm=float(top["penetration_mm"]), self_overlap_mm=float(top["self_overlap_mm"]),
                limits_violation=float(np.max(np.r_[hand.lower - q, q - hand.upper, 0.0])),
                couplings_violation=float(np.max(np.r_[np.asarray(hand.coupling_violation(q)), 0.0])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=5)
    ap.add_argument("--first", type=int, default=0)
    args = ap.parse_args()
    hand = jaxgrasp.Hand.from_file(HAND, TIPS)
    print(f"load average at start {os.getloadavg()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for k, obj in enumerate(objects(args.first + args.objects)[args.first:], start=args.first):
            rows.append(check(k, obj, folder, hand))
            print(json.dumps(rows[-1]), flush=True)
    ok = [r for r in rows if "error" not in r]
    print(f"objects {len(rows)}: evaluate equals the first row on {sum(r['equal'] for r in ok)}, stable "
          f"{sum(r['status'] == 'stable' for r in ok)}, >= 3 fingertips {sum(r['active'] >= 3 for r in ok)}, "
          f"deepest link {max(r['penetration_mm'] for r in ok):.3f} mm, deepest self-overlap "
          f"{max(r['self_overlap_mm'] for r in ok):.3f} mm, joints outside limits by at most "
          f"{max(r['limits_violation'] for r in ok):.1e}, couplings by at most "
          f"{max(r['couplings_violation'] for r in ok):.1e}; median {statistics.median(r['seconds'] for r in rows):.1f} "
          f"s per command; load average at end {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
