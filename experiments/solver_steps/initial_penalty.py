"""Issue 41, item 2: the augmented Lagrangian's initial penalty (``SolverOptions.rho0``).

An infeasible boundary lane's violation falls at every multiplier update while the
penalty grows tenfold from ``rho0`` (``infeasible_trace.py``, at ``rho0`` = 10: 6.3e-2 at
10, 2.6e-2 at 1e4, its floor), so it reaches the floor only after several updates.
Started at a higher penalty, it would reach the floor sooner; a converging lane's inner
solves get stiffer. (Measured here: the opposite holds on the mixed set, and the default
went from 10 to 1; ``FINDINGS.md``, "The initial penalty".)

For each ``--rho0`` value, against the default, on the benchmark's seeded mixed set
(``batch_benchmark.make_grasps``, padded chunks as :func:`jaxgrasp.evaluate_batch` runs
them, ``profile_batch.profile``): lane-steps per lane kind, CPU seconds of the stages,
grasp statuses and values against the default; then (``--ipopt``) CasADi + Ipopt's
multi-start from jaxgrasp's starts on the benchmark's stratified sample, against every
option (statuses equal, values within 1e-6 relative, none above); (``--sweeps``) the
paper's cube and prism grids against the default; (``--cpu-repeats``) process CPU per
grasp of the 1000 grasps, the options run alternately. ``--field`` gives the values to
another :class:`jaxgrasp.SolverOptions` field instead (e.g. ``rho_growth``).

    nice python experiments/solver_steps/initial_penalty.py --rho0 100,1000 [--count 1000] [--ipopt 30]
    nice python experiments/solver_steps/initial_penalty.py --rho0 1 --count 0 --sweeps --cpu-repeats 3
    nice python experiments/solver_steps/initial_penalty.py --field rho_growth --rho0 5,20 --ipopt 0
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark", "infeasible_lanes")  # the studies whose scripts this one imports

from _lab import say
from batch_benchmark import OVER_REL, STATUS, ipopt_sample, make_grasps, rel_diff
from infeasible_early import cpu_alternating, profiled


FIELD = "rho0"  # the SolverOptions field compared (--field)


def options_for(rho0: float):
    import jaxgrasp

    o = jaxgrasp.EvaluateOptions()
    return dataclasses.replace(o, solver=dataclasses.replace(o.solver, **{FIELD: rho0}))


def run_option(grasps, rho0: float) -> dict:
    """Lane-steps per kind, CPU of the stages (printed), statuses and values of one option."""
    p = profiled(grasps, f"{FIELD}={rho0:g}", options_for(rho0))
    out = {f: np.asarray(p[f]) for f in ("status", "value", "limiting_kind", "limiting_contact", "equilibrium_energy")}
    return {**out, "lanes": p["lanes"]}


def compare(ref: dict, new: dict, rho0: float) -> None:
    d = rel_diff(ref["value"], new["value"])
    diff = np.flatnonzero(ref["status"] != new["status"])
    changed = ", ".join(f"{i}: {STATUS[ref['status'][i]]}->{STATUS[new['status'][i]]}" for i in diff[:12])
    say(f"{FIELD} {rho0:g} against the default: statuses differ on {diff.size} grasps "
        + (f"({changed}) " if diff.size else "")
        + f"values max rel diff {d.max():.1e}, above 1e-9: {np.sum(d > 1e-9)}, above 1e-6: {np.sum(d > 1e-6)}, "
        f"higher than the default by > 1e-6 rel: {np.sum(new['value'] > ref['value'] * (1 + 1e-6) + 1e-300)}; "
        f"limiting kind differs on {np.sum(ref['limiting_kind'] != new['limiting_kind'])}, contact on "
        f"{np.sum(ref['limiting_contact'] != new['limiting_contact'])}; value max diff / equilibrium energy "
        f"{np.max(np.abs(new['value'] - ref['value']) / np.abs(ref['equilibrium_energy'])):.1e}")


def ipopt_check(grasps, sample, results: dict) -> None:
    """Ipopt's multi-start from jaxgrasp's (default) starts on the sample
    (``batch_benchmark.phase_ipopt``), against every option (``ipopt_agreement``)."""
    from batch_benchmark import ipopt_agreement, phase_ipopt

    ipopt = phase_ipopt(grasps, sample)
    for name, r in results.items():
        a = ipopt_agreement({"results": r}, ipopt)
        rel = a["value_max_rel_diff"]
        say(f"Ipopt vs {name}: statuses {a['status_agree']}/{a['grasps']}, both stable {a['both_stable']}, value max "
            f"rel diff {float('nan') if rel is None else rel:.1e}, above Ipopt by > {OVER_REL:g} rel: {a['overstated']}")


def sweeps_check(rhos) -> None:
    """The paper's cube and prism grids (``jaxgrasp sweep``'s default axes: Young's modulus
    2e5-1e6 Pa, 9 points; initial deformation 1-5 mm, 41 points), every option against the
    default: statuses, limiting boundaries, values."""
    import jaxgrasp

    axes = {"young_modulus": np.linspace(2e5, 1e6, 9), "initial_deformation": np.linspace(1e-3, 5e-3, 41)}
    default = getattr(jaxgrasp.EvaluateOptions().solver, FIELD)
    for name in ("cube", "prism"):
        grasp = getattr(jaxgrasp.presets, name)()
        out = {r: jaxgrasp.sweep(grasp, options=options_for(r), **axes) for r in (default, *rhos)}
        ref = out[default]
        for r in rhos:
            new = out[r]
            d = rel_diff(np.asarray(ref.value), np.asarray(new.value))
            say(f"{name} grid ({ref.value.size} points), {FIELD} {r:g} against {default:g}: statuses differ on "
                f"{np.sum(np.asarray(ref.status) != np.asarray(new.status))}, limiting kind on "
                f"{np.sum(np.asarray(ref.limiting_kind) != np.asarray(new.limiting_kind))}, contact on "
                f"{np.sum(np.asarray(ref.limiting_contact) != np.asarray(new.limiting_contact))}; values max rel diff "
                f"{d.max():.1e}, above 1e-9: {np.sum(d > 1e-9)}; "
                f"run {ref.run_seconds:.2f} s against {new.run_seconds:.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rho0", default="100,1000", help="comma-separated values to try beside the default")
    ap.add_argument("--field", default="rho0", help="the SolverOptions field they are given to (default rho0)")
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--ipopt", type=int, default=30)
    ap.add_argument("--sweeps", action="store_true", help="also compare the cube and prism grids")
    ap.add_argument("--cpu-repeats", type=int, default=0, help="alternating CPU runs of the whole set")
    a = ap.parse_args()
    global FIELD
    FIELD = a.field
    import jaxgrasp

    default = getattr(jaxgrasp.EvaluateOptions().solver, FIELD)
    kind = type(default)  # an int field (max_inner, ...) takes ints
    rhos = tuple(kind(float(v)) for v in a.rho0.split(","))
    grasps = make_grasps(a.count, 0)
    if a.count:
        results = {f"{FIELD}={default:g}": run_option(grasps, default)}
        ref = results[f"{FIELD}={default:g}"]
        for r in rhos:
            results[f"{FIELD}={r:g}"] = new = run_option(grasps, r)
            compare(ref, new, r)
        if a.ipopt:
            ipopt_check(grasps, ipopt_sample([g.num_contacts for g in grasps], a.ipopt, 0), results)
    if a.sweeps:
        sweeps_check(rhos)
    if a.cpu_repeats:
        pair = {f"{FIELD} {r:g}": options_for(r) for r in (default, *rhos)}
        cpu_alternating(make_grasps(1000, 0), a.cpu_repeats, pair)


if __name__ == "__main__":
    main()
