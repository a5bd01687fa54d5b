"""Planned Shadow-hand grasps in MuJoCo under DexGraspBench's protocol: do they hold, and do the fingertips press as the model says?

Each line of the JSONL file (default: ``planned_grasps.jsonl`` beside this script, the 49
stable best grasps of ``experiments/hand_planning/plan_hand_benchmark.py --objective value``)
holds a pybullet object (an index of ``random_urdfs`` or a name), the grasp's ``qpos`` and
``wrist``. The object is rebuilt as the planner had it (70 mm, in mm, E = 3e5 Pa, mu = 0.8,
f_max = 15 N, 500 kg/m^3: the hand-planning study's ``object_file`` and ``FIELDS``),
evaluated, and simulated with ``jaxgrasp.simulate(..., protocol="dexgraspbench")`` at the
protocol's friction (0.6) and at 0.01. One line per grasp and friction: the status, the
six pushes (success, largest displacement mm / rotation deg), the settled normal forces
against the model's (relative error per fingertip in contact), the squeeze's rounds, the
initial penetrations (hand-object, hand-hand, mm) and the wall time of the simulation
(the evaluation not counted; the object's convex pieces are CoACD's, computed once per
mesh and cached: the first run on a machine also pays for them); then the shares and
the median time with the load average.

    python experiments/hand_simulation/simulate_planned.py [GRASPS.jsonl] [--only K ...]
"""

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from _lab import reuse  # noqa: E402

reuse("hand_planning")
from plan_hand_benchmark import FIELDS, HAND, TIPS, object_file  # noqa: E402

import jaxgrasp  # noqa: E402

FRICTIONS = (None, 0.01)
"""The protocol's friction (0.6), then 0.01."""


def _line(k, row, friction, res, seconds) -> dict:
    err = np.asarray(res.normal_force_error, dtype=float)
    pene = res.parameters.get("initial_penetration_m", {})
    return dict(grasp=k, object=row["object"], friction=res.parameters.get("friction_sliding", friction),
                status=res.status.name, success=bool(res.success), seconds=round(seconds, 2),
                pushes=" ".join(f"{t.axis}:{'ok' if t.success else 'FAIL'}:{1e3 * t.max_displacement_m:.0f}mm/"
                                f"{np.degrees(t.max_rotation_rad):.0f}deg" for t in res.six_axis),
                force_error=[None if not np.isfinite(e) else round(float(e), 3) for e in err],
                settled_N=[None if not np.isfinite(f) else round(float(f), 2) for f in res.settled_normal_force_N],
                model_N=[None if not np.isfinite(f) else round(float(f), 2) for f in res.model_normal_force_N],
                squeeze_rounds=res.parameters.get("squeeze_rounds"),
                penetration_mm={k2: round(1e3 * v, 1) for k2, v in pene.items()})


def _summary(lines) -> None:
    for fr in FRICTIONS:
        got = [x for x in lines if (x["friction"] == fr) or (fr is None and x["friction"] == 0.6)]
        ok = sum(x["success"] for x in got)
        errs = [abs(e) for x in got for e in x["force_error"] if e is not None and x["status"] == "SIMULATED"]
        within = sum(e <= 0.10 for e in errs)
        print(f"friction {0.6 if fr is None else fr}: success {ok}/{len(got)}; penetrating at the pregrasp "
              f"{sum(x['status'] == 'PENETRATING' for x in got)}; fingertip forces within 10 % of eq. 4: "
              f"{within}/{len(errs)} (median |error| {statistics.median(errs) if errs else float('nan'):.2f})",
              flush=True)
    times = [x["seconds"] for x in lines if x["status"] == "SIMULATED"]
    if times:
        print(f"simulation wall time (simulated grasps): median {statistics.median(times):.2f} s, "
              f"max {max(times):.2f} s", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grasps", nargs="?", default=str(HERE / "planned_grasps.jsonl"))
    ap.add_argument("--only", type=int, nargs="*", default=None, help="these lines (0-based) only")
    args = ap.parse_args()
    rows = [json.loads(s) for s in Path(args.grasps).read_text().splitlines() if s.strip()]
    hand = jaxgrasp.Hand.from_file(HAND, TIPS)
    print(f"load average at start {os.getloadavg()}; {len(rows)} grasps from {args.grasps}; "
          f"jaxgrasp {jaxgrasp.__version__}", flush=True)
    lines = []
    with tempfile.TemporaryDirectory() as folder:
        for k, row in enumerate(rows):
            if args.only is not None and k not in args.only:
                continue
            hg = hand.grasp(row["qpos"], object_file(row["object"], 70.0, folder), wrist=row["wrist"], **FIELDS)
            evaluation = jaxgrasp.evaluate(hg.grasp)
            for fr in FRICTIONS:
                t0 = time.perf_counter()
                res = jaxgrasp.simulate(hg, protocol="dexgraspbench", friction=fr, evaluation=evaluation)
                lines.append(_line(k, row, fr, res, time.perf_counter() - t0))
                print(json.dumps(lines[-1]), flush=True)
    _summary(lines)
    print(f"load average at end {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
