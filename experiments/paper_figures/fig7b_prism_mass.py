"""Fig. 7b of Tsuji et al.: maximum over the initial deformation of the triangular prism
grasp's evaluation value, for each Young's modulus, one curve per object mass
(3 fingertips; gravity along the prism's axis).

For each E the initial deformation is searched in two passes over a (mass x dr) grid:
first over [1 mm, min(5 mm, d_lim)] with ``d_lim = sqrt(f_max / (pi E))`` (above it the
initial normal force exceeds f_max: no stable grasp, value 0), then over the interval that
spans every mass's best point and its neighbours. Every pass has the same number of
points, so the evaluator compiles once.

Writes into its folder fig7b_prism_mass.{png,csv} (one row per E and mass) and
fig7b_prism_mass_points.csv (every evaluated point), and prints the numbers behind
the paper's finding: heavier objects give lower values.

    python experiments/paper_figures/fig7b_prism_mass.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import Progress, finding, force_limit_deformation, parse_args, timings, write_rows  # noqa: E402

import jaxgrasp
from jaxgrasp.plots import plot_max
from jaxgrasp.presets import MAX_FORCE, prism
from jaxgrasp.tolerance import GraspStatus
from jaxgrasp.analysis import SweepResult, sweep

STATUS_NAMES = GraspStatus.labels()

KIND_NAMES = tuple(jaxgrasp.model.BoundaryKind.labels()) + ("none",)
FIELDS = ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy")


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], __file__)
    E = np.linspace(2e5, 1e6, 2 if args.quick else 5)
    masses = np.array([0.0, 0.2] if args.quick else [0.0, 0.1, 0.2, 0.3])
    n = 7 if args.quick else 17
    grasp = prism()
    t0 = time.perf_counter()
    compile_s = run_s = 0.0
    points = []  # (E, pass, mass, dr, value, status, kind, contact, energy)
    best = {}  # (i_E, i_mass) -> point
    for i, e in enumerate(E):
        dlim = force_limit_deformation(e, MAX_FORCE)
        dr = np.linspace(1e-3, min(5e-3, dlim * (1.0 - 1e-9)), n)
        for stage in (1, 2):
            r = sweep(grasp, mass=masses, initial_deformation=dr, young_modulus=[e],
                      progress=Progress(f"E={e:.3g} pass {stage}"))
            compile_s += r.compile_seconds
            run_s += r.run_seconds
            for a, m in enumerate(masses):
                for j, d in enumerate(dr):
                    p = (e, stage, m, d, *(getattr(r, f)[a, j, 0] for f in FIELDS))
                    points.append(p)
                    trusted = p[5] != jaxgrasp.GraspStatus.NOT_CONVERGED
                    old = best.get((i, a))
                    if old is None or (trusted and (old[5] == jaxgrasp.GraspStatus.NOT_CONVERGED or p[4] > old[4])):
                        best[(i, a)] = p
            # second pass: span every mass's best point and its neighbours
            _, best_dr = r.max_over("initial_deformation")
            ks = [int(np.flatnonzero(dr == b)[0]) for b in best_dr[:, 0]]
            lo = dr[max(min(ks) - 1, 0)]
            hi = dr[min(max(ks) + 1, n - 1)]
            dr = np.linspace(lo, hi, n)
    wall = time.perf_counter() - t0
    timings(f"fig7b ({len(points)} points)", wall, compile_s, run_s)

    shape = (len(E), len(masses))
    grid = {f: np.zeros(shape, dtype=float if f in ("value", "equilibrium_energy") else int) for f in FIELDS}
    best_dr = np.zeros(shape)
    for (i, a), p in best.items():
        for f, v in zip(FIELDS, p[4:]):
            grid[f][i, a] = v
        best_dr[i, a] = p[3]
    reduced = SweepResult(axes={"young_modulus": E, "mass": masses}, **grid)
    write_rows(
        args.out / "fig7b_prism_mass.csv",
        ["young_modulus_Pa", "mass_kg", "max_value_J", "best_initial_deformation_m", "status",
         "limiting_kind", "limiting_contact", "equilibrium_energy_J"],
        [
            [E[i], masses[a], grid["value"][i, a], best_dr[i, a], STATUS_NAMES[grid["status"][i, a]],
             KIND_NAMES[grid["limiting_kind"][i, a]], int(grid["limiting_contact"][i, a]),
             grid["equilibrium_energy"][i, a]]
            for i in range(len(E)) for a in range(len(masses))
        ],
    )
    write_rows(
        args.out / "fig7b_prism_mass_points.csv",
        ["young_modulus_Pa", "pass", "mass_kg", "initial_deformation_m", "value_J", "status",
         "limiting_kind", "limiting_contact", "equilibrium_energy_J"],
        [[e, s, m, d, v, STATUS_NAMES[st], KIND_NAMES[k], int(c), u] for e, s, m, d, v, st, k, c, u in points],
    )
    plot_max(
        reduced,
        best_dr,
        args.out / "fig7b_prism_mass.png",
        title="Fig. 7b: triangular prism, maximum evaluation value for each E and mass",
    )

    print("\nmax value over dr [mJ] (best dr [mm]):")
    print(f"{'E [Pa]':>10} " + " ".join(f"{'m=' + format(m, 'g') + ' kg':>20}" for m in masses))
    for i, e in enumerate(E):
        cells = " ".join(
            f"{grid['value'][i, a] * 1e3:10.5f} ({best_dr[i, a] * 1e3:5.3f})  " for a in range(len(masses))
        )
        print(f"{e:10.3g} {cells}")
    v = grid["value"]
    print()
    finding(
        "heavier objects give lower maximum values at every E "
        f"(E = {E[0]:.3g} Pa: {v[0, 0] * 1e3:.4f} mJ at m = 0 -> {v[0, -1] * 1e3:.4f} mJ at m = {masses[-1]:g} kg)",
        bool(np.all(np.diff(v, axis=1) < 0)),
    )
    finding("the maximum value falls as E grows, for every mass", bool(np.all(np.diff(v, axis=0) < 0)))
    print(f"wrote {args.out}/fig7b_prism_mass.png, fig7b_prism_mass.csv, fig7b_prism_mass_points.csv")


if __name__ == "__main__":
    main()
