"""Issue 41, item 2: where an infeasible boundary lane's loop steps go, update by update.

Every lane of the first ``--grasps`` grasps with ``--contacts`` contacts of the batch
benchmark's mixed set (all 20 starts of every boundary problem, no first wave) is stepped
one loop step at a time with ``jaxgrasp.solver.step`` (the steps the work queue
takes). At each multiplier update the lane's step count, violation ``viol`` (scaled
constraint units, inf-norm), the ratio ``|grad v|_inf / viol`` of the violation measure
``v = |h|^2/2 + sum min(g_i, 0)^2/2`` (the infeasibility test asks for ``<= 1e-6``; the
stall growth of the solver's penalty growth for ``<= 1e-2``) and the
penalty ``rho`` are recorded. Printed: percentiles at the first update for lanes that end
infeasible and lanes with an equality that end converged, the number of updates, and the
first ``--show`` infeasible lanes' updates.

    python experiments/infeasible_lanes/infeasible_trace.py --contacts 7 --grasps 8 --show 8
"""

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxgrasp  # noqa: F401,E402  (64-bit mode)
from jaxgrasp import solver as S  # noqa: E402
from jaxgrasp.solver import LaneStatus  # noqa: E402


def trace(n_contacts: int, n_grasps: int):
    """``(status, has_equality, records)``: per lane its final status, whether it has an
    equality, and its updates as ``(steps, viol, ratio, rho)``."""
    from infeasible_certificate import benchmark_lanes
    from jaxgrasp.tolerance import lane_problem

    st, theta, o = benchmark_lanes(n_contacts, n_grasps)
    step = jax.jit(jax.vmap(lambda s, t: S.step(lane_problem(t), s, o)))
    slope = jax.jit(jax.vmap(lambda s, t: S.violation_slope(s, S.first_order(lane_problem(t), s.x))))
    records = [[] for _ in range(st.x.shape[0])]
    for _ in range(o.max_steps):
        new = step(st, theta)
        updated = np.asarray(st.prev_viol) != np.asarray(new.prev_viol)
        if updated.any():
            sl, viol = np.asarray(slope(new, theta)), np.asarray(new.feasibility)
            rho, steps = np.asarray(new.rho), np.asarray(new.steps)
            for i in np.flatnonzero(updated):
                records[i].append((int(steps[i]), float(viol[i]), float(sl[i] / max(viol[i], 1e-300)), float(rho[i])))
        st = new
        if not np.any((np.asarray(st.status) == LaneStatus.NOT_CONVERGED) & (np.asarray(st.steps) < o.max_steps)):
            break
    return np.asarray(st.status), np.asarray(st.eq_mask).sum(1) > 0, records, np.asarray(st.steps)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--contacts", type=int, default=7)
    ap.add_argument("--grasps", type=int, default=8)
    ap.add_argument("--show", type=int, default=8)
    a = ap.parse_args()
    print(f"$ python experiments/infeasible_lanes/infeasible_trace.py --contacts {a.contacts} --grasps {a.grasps} --show {a.show}"
          f"    [load {', '.join(f'{x:.2f}' for x in os.getloadavg())}]", flush=True)
    status, has_eq, records, steps = trace(a.contacts, a.grasps)
    groups = {"infeasible": np.flatnonzero(status == LaneStatus.INFEASIBLE),
              "converged (with an equality)": np.flatnonzero((status == LaneStatus.CONVERGED) & has_eq)}
    for name, ids in groups.items():
        first = np.array([records[i][0] for i in ids if records[i]])
        pct = lambda v, q: ", ".join(f"{x:.3g}" for x in np.percentile(v, q))  # noqa: E731
        print(f"{name}: {len(ids)} lanes, {steps[ids].mean():.1f} steps each; first update at step "
              f"[{pct(first[:, 0], [10, 50, 90])}] (10/50/90 %), violation there [{pct(first[:, 1], [10, 50, 90])}], "
              f"|grad v| / viol there [{pct(first[:, 2], [1, 10, 50, 90])}] (1/10/50/90 %); updates per lane "
              f"[{pct([len(records[i]) for i in ids], [10, 50, 90])}]")
    print("first infeasible lanes, each update as step: violation, |grad v| / viol, rho after it:")
    for i in groups["infeasible"][: a.show]:
        print("  " + " | ".join(f"{s}: {v:.1e}, {r:.1e}, {rho:.0e}" for s, v, r, rho in records[i]))


if __name__ == "__main__":
    main()
