"""Issue 42's regression check: no settled value of the synthetic robustness grasps moves.

``experiments/robustness/robustness.py``'s seeded grasps (``tests/grasp_draws.py``, 2-5 fingertips)
are evaluated with :func:`jaxgrasp.evaluate_batch` by the jaxgrasp on ``PYTHONPATH`` and
saved (``--save``); ``--against`` an earlier save (e.g. of the tree before the fix, from
``git archive``) compares: every grasp that was settled before must keep its status and
its value within 1e-9 relative::

    PYTHONPATH=/tmp/base nice python experiments/settling/settle_synthetic.py --save /tmp/before.npz
    nice python experiments/settling/settle_synthetic.py --save /tmp/after.npz --against /tmp/before.npz
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402
sys.path.insert(0, str(ROOT / "tests"))

REL = 1e-9


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--save", type=Path, required=True)
    p.add_argument("--against", type=Path, default=None)
    args = p.parse_args()
    import jaxgrasp
    from _lab.grasp_draws import seeded_grasps

    grasps = seeded_grasps(args.count, seed=args.seed)
    r = jaxgrasp.evaluate_batch(grasps)
    out = dict(value=np.asarray(r.value), status=np.asarray(r.status), eq=np.asarray(r.equilibrium_status),
               n=np.array([g.num_contacts for g in grasps]))
    np.savez(args.save, **out)
    print(f"{len(grasps)} grasps; statuses {np.bincount(out['status'], minlength=4).tolist()} "
          f"(stable, unstable, infeasible, not_converged)")
    if args.against is None:
        return 0
    b = np.load(args.against)
    settled = b["status"] != 3
    same_status = np.all(b["status"][settled] == out["status"][settled])
    scale = np.maximum(np.abs(b["value"]), 1e-300)
    rel = np.abs(out["value"] - b["value"]) / scale
    worst = float(np.max(np.where(settled & (b["value"] != 0), rel, 0.0)))
    zeros = bool(np.all(out["value"][settled & (b["value"] == 0)] == 0))
    print(f"settled before: {int(settled.sum())}; same status: {bool(same_status)}; "
          f"largest relative change of a value: {worst:.3g} (limit {REL:g}); zero values still zero: {zeros}")
    return 0 if same_status and worst <= REL and zeros else 1


if __name__ == "__main__":
    sys.exit(main())
