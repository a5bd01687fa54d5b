"""Write ``tests/data/settle_hard.json``: the hardest grasps of ``experiments/settle_real.py``
(issue 42), each with the value and status of the independent Ipopt multi-start
reference (``tests/ipopt_reference.py``, 24 starts, seed 0) beside it.

The reference takes 7-20 s a grasp, too long for the test suite, so it is stored here::

    python experiments/settle_hard_data.py [--pad P] UNSETTLED.npz N:I [N:I ...]

``UNSETTLED.npz`` is a ``--unsettled`` file of ``settle_real.py``; ``N:I`` picks row ``I``
of its ``N``-finger grasps. The grasps already in the file are kept and the new ones
appended (a grasp already there is not added twice). ``--pad P`` stores each grasp with
``P`` contacts, the added ones inactive (``active`` mask, as ``jaxgrasp.stack`` pads a
batch): the test then evaluates it with the file's ``P``-finger grasps, in one compiled
shape; Ipopt runs on the grasp itself.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT / "experiments"), str(ROOT / "tests")]

N_STARTS = 24


def padded(g: dict, p: int) -> dict:
    """The grasp fields ``g`` (``Grasp.to_numpy``, ``N`` contacts) with ``p - N`` inactive
    contacts appended that repeat the last one (none where ``p <= N``)."""
    n = len(g["positions"])
    if p <= n:
        return g
    pad = np.concatenate([np.arange(n), np.full(p - n, n - 1)])
    out = {k: (v[pad] if np.ndim(v) >= 1 and len(v) == n and k != "gravity" else v) for k, v in g.items()}
    return {**out, "active": np.arange(p) < n}


def main() -> int:
    import ipopt_reference
    from settle_real import grasp_of

    args = sys.argv[1:]
    pad = 0
    if args[0] == "--pad":
        pad, args = int(args[1]), args[2:]
    z = np.load(args[0])
    path = ROOT / "tests" / "data" / "settle_hard.json"
    rows = json.loads(path.read_text(encoding="utf-8"))["grasps"] if path.exists() else []
    for pick in args[1:]:
        n, i = (int(x) for x in pick.split(":"))
        d = {k: z[f"n{n}_{k}"] for k in ("pos", "nrm", "dr", "mass", "gravity", "object")}
        g = grasp_of(d, i).to_numpy()
        stored = padded(g, pad)
        if any(np.array_equal(np.asarray(r["grasp"]["positions"]), stored["positions"]) for r in rows):
            continue
        ref = ipopt_reference.reference_evaluate(g, n_starts=N_STARTS, seed=0)
        rows.append(dict(object=str(d["object"][i]), status_before=int(z[f"n{n}_status"][i]),
                         grasp={k: np.asarray(v).tolist() for k, v in stored.items()},
                         ipopt_status=ref["status"], ipopt_value=float(ref["value"])))
        print(n, i, rows[-1]["object"], ref["status"], ref["value"], flush=True)
    out = dict(
        note=("grasps of real meshes (pybullet_data) drawn by experiments/settle_real.py on which "
              "jaxgrasp's equilibrium or a boundary problem did not settle before one of issue 42's fixes; "
              f"ipopt_*: tests/ipopt_reference.py reference_evaluate(grasp, n_starts={N_STARTS}, seed=0), "
              "written by experiments/settle_hard_data.py; SI units"),
        grasps=rows,
    )
    path.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
