"""Fig. 7a of Tsuji et al.: maximum over the initial deformation of the cube grasp's
evaluation value, for each Young's modulus (2 fingertips, m = 0 kg).

For each E the initial deformation is searched finer than Fig. 6, in two passes of 41
points each: over [1 mm, min(5 mm, d_lim)] where ``d_lim = sqrt(f_max / (pi E))`` (above
it the initial normal force exceeds f_max and no stable grasp exists, value 0), then
between the neighbours of the first pass's best point. Every pass is one 41-point sweep,
so the evaluator compiles once.

Writes into its folder fig7a_cube_max.{png,csv} (one row per E: max value, best dr, limiting
boundary at the max) and fig7a_cube_max_points.csv (every evaluated point), and
prints the numbers behind the paper's finding: the maximum value falls as E grows.

    python experiments/paper_figures/fig7a_cube_max.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import Progress, finding, force_limit_deformation, parse_args, refine_interval, timings, write_rows  # noqa: E402

import jaxgrasp
from jaxgrasp.plots import plot_max
from jaxgrasp.presets import MAX_FORCE, cube
from jaxgrasp.tolerance import GraspStatus
from jaxgrasp.analysis import SweepResult, sweep

STATUS_NAMES = GraspStatus.labels()

KIND_NAMES = tuple(jaxgrasp.model.BoundaryKind.labels()) + ("none",)


def best_over_dr(grasp, E: float, n: int, label: str):
    """Two-pass search of the best initial deformation at one E; returns (points, best)."""
    dlim = force_limit_deformation(E, MAX_FORCE)
    hi = min(5e-3, dlim * (1.0 - 1e-9))
    points = []  # (pass, dr, value, status, kind, contact, eq energy)
    compile_s = run_s = 0.0
    dr = np.linspace(1e-3, hi, n)
    for stage in (1, 2):
        r = sweep(grasp, young_modulus=[E], initial_deformation=dr, progress=Progress(f"{label} pass {stage}"))
        compile_s += r.compile_seconds
        run_s += r.run_seconds
        for j, d in enumerate(dr):
            points.append(
                (stage, d, r.value[0, j], r.status[0, j], r.limiting_kind[0, j], r.limiting_contact[0, j],
                 r.equilibrium_energy[0, j])
            )
        _, best_dr = r.max_over("initial_deformation")
        k = int(np.flatnonzero(dr == best_dr[0])[0])
        lo, hi2 = refine_interval(dr, k)
        dr = np.linspace(lo, hi2, n)
    trusted = [p for p in points if p[3] != jaxgrasp.GraspStatus.NOT_CONVERGED] or points
    best = max(trusted, key=lambda p: p[2])
    return points, best, dlim, compile_s, run_s


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], __file__)
    E = np.linspace(2e5, 1e6, 3 if args.quick else 9)
    n = 9 if args.quick else 41
    grasp = cube(mass=0.0)
    t0 = time.perf_counter()
    rows, all_points = [], []
    compile_s = run_s = 0.0
    for e in E:
        points, best, dlim, c, r = best_over_dr(grasp, e, n, f"E={e:.3g}")
        compile_s += c
        run_s += r
        rows.append((e, best, dlim))
        all_points += [(e, *p) for p in points]
    wall = time.perf_counter() - t0
    timings(f"fig7a ({len(all_points)} points)", wall, compile_s, run_s)

    write_rows(
        args.out / "fig7a_cube_max.csv",
        ["young_modulus_Pa", "max_value_J", "best_initial_deformation_m", "status", "limiting_kind",
         "limiting_contact", "equilibrium_energy_J", "force_limit_deformation_m"],
        [[e, b[2], b[1], STATUS_NAMES[b[3]], KIND_NAMES[b[4]], int(b[5]), b[6], dlim] for e, b, dlim in rows],
    )
    write_rows(
        args.out / "fig7a_cube_max_points.csv",
        ["young_modulus_Pa", "pass", "initial_deformation_m", "value_J", "status", "limiting_kind",
         "limiting_contact", "equilibrium_energy_J"],
        [[e, s, d, v, STATUS_NAMES[st], KIND_NAMES[k], int(c), u] for e, s, d, v, st, k, c, u in all_points],
    )
    reduced = SweepResult(
        axes={"young_modulus": E},
        value=np.array([b[2] for _, b, _ in rows]),
        status=np.array([b[3] for _, b, _ in rows]),
        limiting_kind=np.array([b[4] for _, b, _ in rows]),
        limiting_contact=np.array([b[5] for _, b, _ in rows]),
        equilibrium_energy=np.array([b[6] for _, b, _ in rows]),
    )
    best_dr = np.array([b[1] for _, b, _ in rows])
    plot_max(
        reduced,
        best_dr,
        args.out / "fig7a_cube_max.png",
        title="Fig. 7a: cube, maximum evaluation value for each Young's modulus",
    )

    print(f"\n{'E [Pa]':>10} {'max value [mJ]':>15} {'best dr [mm]':>12} {'d_lim [mm]':>10} "
          f"{'best/d_lim':>10} {'kind at max':>11}")
    for e, b, dlim in rows:
        print(f"{e:10.3g} {b[2] * 1e3:15.5f} {b[1] * 1e3:12.4f} {dlim * 1e3:10.4f} {b[1] / dlim:10.4f} "
              f"{KIND_NAMES[b[4]]:>11}")
    v = reduced.value
    if len(E) > 1 and np.all(v > 0):
        slope = np.polyfit(np.log(E), np.log(v), 1)[0]
        print(f"log-log slope of the max value vs E: {slope:.3f}")
    print()
    finding(
        f"the maximum value falls as E grows: {v[0] * 1e3:.4f} mJ at E = {E[0]:.3g} Pa -> "
        f"{v[-1] * 1e3:.4f} mJ at E = {E[-1]:.3g} Pa (ratio {v[0] / v[-1]:.2f})",
        bool(np.all(np.diff(v) < 0)),
    )
    finding("the best initial deformation shrinks as E grows", bool(np.all(np.diff(best_dr) < 0)))
    print(f"wrote {args.out}/fig7a_cube_max.png, fig7a_cube_max.csv, fig7a_cube_max_points.csv")


if __name__ == "__main__":
    main()
