"""Write ``tests/data/settle_hard.json``: the hardest grasps of ``experiments/settling/settle_real.py``
(issue 42), each with the value and status of the independent Ipopt multi-start
reference (``tests/ipopt_reference.py``, 24 starts, seed 0) beside it.

The reference takes 7-20 s a grasp, too long for the test suite, so it is stored here::

    python experiments/settling/settle_hard_data.py UNSETTLED.npz N:I [N:I ...]

``UNSETTLED.npz`` is a ``--unsettled`` file of ``settle_real.py``; ``N:I`` picks row ``I``
of its ``N``-finger grasps. The grasps already in the file are kept and the new ones
appended (a grasp already there is not added twice).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

N_STARTS = 24


def main() -> int:
    from _lab import ipopt_reference
    from settle_real import grasp_of

    z = np.load(sys.argv[1])
    path = ROOT / "tests" / "data" / "settle_hard.json"
    rows = json.loads(path.read_text(encoding="utf-8"))["grasps"] if path.exists() else []
    for pick in sys.argv[2:]:
        n, i = (int(x) for x in pick.split(":"))
        d = {k: z[f"n{n}_{k}"] for k in ("pos", "nrm", "dr", "mass", "gravity", "object")}
        g = grasp_of(d, i).to_numpy()
        if any(np.array_equal(np.asarray(r["grasp"]["positions"]), g["positions"]) for r in rows):
            continue
        ref = ipopt_reference.reference_evaluate(g, n_starts=N_STARTS, seed=0)
        rows.append(dict(object=str(d["object"][i]), status_before=int(z[f"n{n}_status"][i]),
                         grasp={k: np.asarray(v).tolist() for k, v in g.items()},
                         ipopt_status=ref["status"], ipopt_value=float(ref["value"])))
        print(n, i, rows[-1]["object"], ref["status"], ref["value"], flush=True)
    out = dict(
        note=("grasps of real meshes (pybullet_data) drawn by experiments/settling/settle_real.py on which "
              "jaxgrasp's equilibrium or a boundary problem did not settle before one of issue 42's fixes; "
              f"ipopt_*: tests/ipopt_reference.py reference_evaluate(grasp, n_starts={N_STARTS}, seed=0), "
              "written by experiments/settling/settle_hard_data.py; SI units"),
        grasps=rows,
    )
    path.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
