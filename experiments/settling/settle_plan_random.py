"""Do the planner's uniform candidates on real objects settle? (issue 42)

``experiments/planning/plan_benchmark.py`` runs ``jaxgrasp.plan(sampler="uniform", refine=0,
samples=1500, seed=seed + 1000)`` beside each plan as its random baseline, and its log counts
the candidates that came back ``not_converged`` ("unsettled ... random"). This script draws
exactly those candidates again (same objects, fingertips, rules and seeds, with the
planner's own sampler, ``jaxgrasp.planning.draw_valid``), evaluates them with the
tree's code and counts their statuses, and for the unsettled ones which program stalled
(the equilibrium, or a slip or force-limit boundary problem).

    python experiments/settling/settle_plan_random.py [--objects 8] [--fingers 2,3] [--out settle_plan_random]

Writes ``<out>.json`` (per case) and prints one line per case; load average printed.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("planning")  # the studies whose scripts this one imports

from plan_benchmark import OBJECT, TIP, object_file  # noqa: E402


def one_case(path: Path, fingers: int, count: int, seed: int) -> dict:
    """Statuses of plan_benchmark's random candidates for one object and finger count."""
    import jaxgrasp
    import jaxgrasp.solver
    from jaxgrasp.planning import CHUNK, draw_valid, grasps_of, setup as plan_setup
    from jaxgrasp.surface import ContactRules

    setup = plan_setup(str(path), OBJECT["units"], None, OBJECT["density"], None, OBJECT["gravity"],
                         TIP["radius"], TIP["young_modulus"], TIP["friction"], TIP["max_force"])
    rng = np.random.default_rng(seed + 1000)  # as plan(seed=seed + 1000) draws
    pos, nrm, dr, _, _ = draw_valid(setup, fingers, count, "uniform", ContactRules(), rng, None)
    t0 = time.perf_counter()
    ev = jaxgrasp.evaluate_batch(grasps_of(setup, pos, nrm, dr), chunk_size=CHUNK)
    seconds = time.perf_counter() - t0
    status = np.asarray(ev.status)
    nc = status == jaxgrasp.GraspStatus.NOT_CONVERGED
    stalled = np.asarray(ev.boundary_status)[nc] == jaxgrasp.solver.LaneStatus.NOT_CONVERGED
    names = jaxgrasp.GraspStatus.labels()
    return dict(
        object=path.stem, fingers=fingers, valid=len(pos), seconds=seconds,
        statuses={names[k]: int(np.sum(status == k)) for k in range(len(names))},
        unsettled_equilibria=int(np.sum(np.asarray(ev.equilibrium_status)[nc] == jaxgrasp.solver.LaneStatus.NOT_CONVERGED)),
        unsettled_slip=int(np.sum(stalled[:, 0])), unsettled_force_limit=int(np.sum(stalled[:, 1])),
        not_converged_rows=np.flatnonzero(nc).tolist(),
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", type=int, default=8)
    p.add_argument("--fingers", default="2,3")
    p.add_argument("--random", type=int, default=1500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(HERE / "settle_plan_random"))
    args = p.parse_args()
    out = Path(args.out).with_suffix(".json")
    if not os.access(out.parent, os.W_OK):
        sys.exit(f"settle_plan_random.py: cannot write {out}")
    folder = Path.home() / ".cache" / "jaxgrasp-experiments" / "objects"
    folder.mkdir(parents=True, exist_ok=True)
    cases = []
    for i in range(args.objects):
        for f in map(int, args.fingers.split(",")):
            c = one_case(object_file(i, folder), f, args.random, args.seed)
            cases.append(c)
            print(f"[{time.strftime('%H:%M:%S')}] {c['object']} {f} fingers: {c['valid']} valid, {c['statuses']}; "
                  f"unsettled equilibria {c['unsettled_equilibria']}, slip {c['unsettled_slip']}, force limit "
                  f"{c['unsettled_force_limit']}; {c['seconds']:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True)
    total = sum(c["statuses"]["not_converged"] for c in cases)
    print(f"{len(cases)} cases, {sum(c['valid'] for c in cases)} candidates, {total} not_converged", flush=True)
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(dict(args=vars(args), cases=cases), indent=1) + "\n")
    tmp.replace(out)


if __name__ == "__main__":
    main()
