"""Plan with the Shadow hand on real objects: how often a stable grasp, with how many fingertips, in what time.

Each of pybullet's generated objects (``pybullet_data/random_urdfs/NNN``, the watertight
ones), then its duck, bunny and teddy, scaled so its longest side is ``--size`` mm, written as an STL in mm, planned by ``jaxgrasp.plan(hand=...)`` with the
Shadow hand of ``examples/hands/shadow/`` and its five distal capsules as fingertips
(E = 3e5 Pa, mu = 0.8, f_max = 15 N, 500 kg/m^3). One line per object, then the shares and
the median time, with the load average at the start and the end. Each object's best grasp
is checked: its joints within their limits and the hand's tendon couplings
(``Hand.coupling_violation``), its other links' depth.

Objectives (``--objective``):

* ``value``: ``jaxgrasp.plan(hand=...)`` as it is, maximising the energy tolerance;
* ``epsilon``: the same planner (the same candidates: the same seed) maximising the
  Ferrari-Canny epsilon, its refinement a local random search of the same budget;
* ``random``: plain random sampling of closed-hand grasps under the same rules, with
  ``--random-factor`` (10) times the candidates: the planner's random wrist poses and
  pre-shapes, each closed by pressing its fingertips into the surface with its links kept
  out (the closing search without its facing and balance terms), evaluated, the eligible
  ranked by the value, none refined.

    python experiments/hand_planning/plan_hand_benchmark.py [--objects 10] [--objective value|epsilon|random]
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

import jaxgrasp
from jaxgrasp.planning import HAND_SAMPLES, CloseSettings, plan_hand

ROOT = Path(__file__).resolve().parents[2]
HAND = ROOT / "examples" / "hands" / "shadow" / "shadow_hand.xml"
TIPS = [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")]
FIELDS = dict(young_modulus=3e5, friction=0.8, max_force=15.0, density=500.0, units="mm")


NAMED = ("duck_vhacd", "bunny", "teddy2_VHACD_CHs")
"""pybullet_data's named objects of the study, after its generated ones."""
SKIPPED = (37,)
"""Generated objects left out: not watertight (no centre of mass of their own; plan refuses them)."""


def objects(count: int) -> list:
    """The study's first ``count`` objects: pybullet's generated ones (their index, ``SKIPPED``
    left out) up to ``count - 3``, then the duck, the bunny and the teddy (their names)."""
    generated = [k for k in range(count + len(SKIPPED)) if k not in SKIPPED][:max(count - len(NAMED), 0)]
    return generated + list(NAMED[:count - len(generated)])


STUDY_OBJECTS = 50
"""The study's objects: ``objects(STUDY_OBJECTS)``."""


def seed_of(obj) -> int:
    """The plan's seed for ``obj``: its position among the study's objects, whichever arm
    and however few objects a run takes, so that every arm plans it from the same candidates."""
    return objects(STUDY_OBJECTS).index(obj)


def object_file(obj, size_mm: float, folder: str) -> str:
    """pybullet's object ``obj`` (an index of ``random_urdfs`` or a name) scaled to ``size_mm``
    on its longest side, as an STL in mm."""
    import pybullet_data
    import trimesh

    name = f"{obj:03d}" if isinstance(obj, int) else obj
    data = pybullet_data.getDataPath()
    source = os.path.join(data, "random_urdfs", name, f"{name}.obj") if isinstance(obj, int) else os.path.join(
        data, f"{name}.obj")
    mesh = trimesh.load(source, force="mesh")
    mesh.apply_scale(size_mm / float(mesh.extents.max()))
    path = os.path.join(folder, f"{name}.stl")
    mesh.export(path)
    return path


def _plan(path: str, hand, args, seed: int):
    """The plan of one object by ``args.objective`` (module doc)."""
    if args.objective != "random":
        return jaxgrasp.plan(path, hand=hand, samples=args.samples, objective=args.objective, seed=seed,
                             progress=lambda *a: None, **FIELDS)
    plain = CloseSettings(face=0.0, balance=0.0)  # closed onto the surface, nothing aimed at a good grasp
    return plan_hand(path, hand, samples=args.random_factor * (args.samples or HAND_SAMPLES), refine=0, seed=seed,
                     settings=plain, progress=lambda *a: None, **FIELDS)


def _joints_check(hand, res) -> dict:
    """The best grasp's joints (rad), wrist, and how far outside the joint limits and the
    couplings they are (0: within)."""
    if not len(res.qpos):
        return {}
    q = np.asarray(res.qpos[0])
    limits = float(np.max(np.r_[hand.lower - q, q - hand.upper, 0.0]))
    couplings = float(np.max(np.r_[np.asarray(hand.coupling_violation(q)), 0.0]))
    return dict(limits_violation=limits, couplings_violation=couplings, qpos=q.tolist(),
                wrist=np.asarray(res.wrist[0]).tolist())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=10)
    ap.add_argument("--first", type=int, default=0, help="start at this position of the object list")
    ap.add_argument("--samples", type=int, default=None, help="closed candidates (default: the planner's)")
    ap.add_argument("--size", type=float, default=70.0, help="longest side, mm")
    ap.add_argument("--objective", default="value", choices=("value", "epsilon", "random"))
    ap.add_argument("--random-factor", type=int, default=10, help="candidates of the random arm per planner candidate")
    ap.add_argument("--json", default=None, help="write one JSON line per object here")
    args = ap.parse_args()
    hand = jaxgrasp.Hand.from_file(HAND, TIPS)
    print(f"load average at start {os.getloadavg()}; {args.objects} objects, {args.samples} candidates, "
          f"objective {args.objective}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for k in objects(args.first + args.objects)[args.first:]:
            path = object_file(k, args.size, folder)
            t0 = time.perf_counter()
            res = _plan(path, hand, args, seed_of(k))
            row = dict(object=k, objective=args.objective, status=res.status_name, seconds=time.perf_counter() - t0,
                       stable=bool(len(res.statuses) and res.statuses[0] == 0),
                       active=int(res.active[0]) if len(res.active) else 0,
                       penetration_mm=float(res.penetration[0]) * 1e3 if len(res.active) else None,
                       self_overlap_mm=float(res.self_overlap[0]) * 1e3 if len(res.active) else None,
                       value_J=res.value, epsilon=float(res.epsilon[0]) if len(res.epsilon) else None,
                       candidates=res.candidates, candidates_stable=res.stable,
                       timings={a: round(b, 1) for a, b in res.timings.items()}, **_joints_check(hand, res))
            rows.append(row)
            print(json.dumps(row), flush=True)
            if args.json:
                with open(args.json, "a") as fh:
                    fh.write(json.dumps(row) + "\n")
    n = len(rows)
    stable = sum(r["stable"] for r in rows)
    three = sum(r["stable"] and r["active"] >= 3 for r in rows)
    print(f"objects {n}: stable best {stable} ({100 * stable / n:.0f} %), stable with >= 3 fingertips {three} "
          f"({100 * three / n:.0f} %), median {statistics.median(r['seconds'] for r in rows):.1f} s per object; "
          f"load average at end {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
