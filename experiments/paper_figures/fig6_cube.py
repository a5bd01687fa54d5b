"""Fig. 6 of Tsuji et al.: evaluation value of the cube grasp vs initial deformation, one
curve per Young's modulus (2 fingertips, m = 0 kg, r = 25 mm, mu = 0.5, f_max = 15 N).

Grid: E = 2e5 .. 1e6 Pa (9 values) x initial deformation 1 .. 5 mm (41 values).
Writes into its folder fig6_cube.{png,csv,npz} and prints the numbers behind the paper's findings:
the value first rises with the initial deformation, then falls because a fingertip's
normal force approaches its limit (limiting boundary switches to max_force), and no
stable grasp exists once the initial force pi E dr^2 exceeds f_max.

    python experiments/paper_figures/fig6_cube.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import Progress, finding, force_limit_deformation, parse_args, timings  # noqa: E402

import jaxgrasp
from jaxgrasp.plots import plot_sweep
from jaxgrasp.presets import MAX_FORCE, cube
from jaxgrasp.tolerance import GraspStatus
from jaxgrasp.analysis import sweep

STABLE, INFEASIBLE = GraspStatus.STABLE, GraspStatus.INFEASIBLE

SLIP, FORCE = jaxgrasp.model.BoundaryKind.labels().index("slip"), jaxgrasp.model.BoundaryKind.labels().index("max_force")


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], __file__)
    E = np.linspace(2e5, 1e6, 3 if args.quick else 9)
    dr = np.linspace(1e-3, 5e-3, 9 if args.quick else 41)
    t0 = time.perf_counter()
    res = sweep(cube(mass=0.0), young_modulus=E, initial_deformation=dr, progress=Progress("fig6"), chunk_size=64)
    wall = time.perf_counter() - t0
    res.to_csv(args.out / "fig6_cube.csv")
    res.to_npz(args.out / "fig6_cube.npz")
    plot_sweep(
        res,
        args.out / "fig6_cube.png",
        title="Fig. 6: cube, evaluation value for each Young's modulus and initial deformation",
    )
    timings(f"fig6 ({res.size} points)", wall, res.compile_seconds, res.run_seconds)
    print("counts:", res.counts())

    print(f"\n{'E [Pa]':>10} {'v(1mm) [mJ]':>12} {'max [mJ]':>10} {'at dr [mm]':>10} {'kind@max':>9} "
          f"{'1st max_force dr':>16} {'1st infeasible dr':>17} {'sqrt(fmax/piE)':>14}")
    ok_rise = ok_fall = ok_force = ok_infeasible = True
    real_fall = []  # E values with a stable, force-limited point below the maximum after it
    for i, e in enumerate(E):
        v, st, kd = res.value[i], res.status[i], res.limiting_kind[i]
        k = int(np.argmax(v))
        stable = st == STABLE
        force_idx = np.flatnonzero(stable & (kd == FORCE))
        inf_idx = np.flatnonzero(st == INFEASIBLE)
        dlim = force_limit_deformation(e, MAX_FORCE)
        print(
            f"{e:10.3g} {v[0] * 1e3:12.5f} {v[k] * 1e3:10.5f} {dr[k] * 1e3:10.2f} "
            f"{jaxgrasp.model.BoundaryKind.labels()[kd[k]] if kd[k] >= 0 else 'none':>9} "
            f"{dr[force_idx[0]] * 1e3 if force_idx.size else float('nan'):16.2f} "
            f"{dr[inf_idx[0]] * 1e3 if inf_idx.size else float('nan'):17.2f} {dlim * 1e3:14.3f}"
        )
        # rises from dr = 1 mm up to the maximum (slip-limited part), falls after it
        ok_rise &= k > 0 and bool(np.all(np.diff(v[: k + 1]) > 0))
        after = slice(k + 1, None)
        ok_fall &= k < len(dr) - 1 and bool(np.all(v[after] < v[k]))
        # the fall region is limited by the force limit (or has no stable equilibrium)
        ok_force &= bool(np.all((stable[after] & (kd[after] == FORCE)) | (st[after] == INFEASIBLE)))
        if np.any(stable[after] & (kd[after] == FORCE) & (v[after] > 0) & (v[after] < v[k])):
            real_fall.append(e)
        # infeasible exactly where the initial normal force exceeds f_max
        ok_infeasible &= bool(np.array_equal(st == INFEASIBLE, dr > dlim))
    print()
    finding("the value rises with dr from 1 mm up to its maximum, for every E", ok_rise)
    finding("the value falls after its maximum (before 5 mm), for every E", ok_fall)
    finding("every point after the maximum is limited by max_force or infeasible", ok_force)
    finding(
        "the fall is a gradual decrease through stable, max_force-limited points (not only the jump "
        f"to infeasibility) at E = {', '.join(f'{e:.3g}' for e in real_fall) or 'none'} Pa "
        f"({len(real_fall)} of {len(E)}; the others fall between two grid points)",
        len(real_fall) > 0,
    )
    finding("infeasible exactly where pi E dr^2 > f_max (dr > sqrt(f_max / (pi E)))", ok_infeasible)
    slip_then_force = all(
        np.any((res.status[i] == STABLE) & (res.limiting_kind[i] == SLIP))
        and np.any((res.status[i] == STABLE) & (res.limiting_kind[i] == FORCE))
        for i in range(len(E))
    )
    finding("the limiting boundary switches from slip to max_force as dr grows, for every E", slip_then_force)
    print(f"wrote {args.out}/fig6_cube.png, fig6_cube.csv, fig6_cube.npz")


if __name__ == "__main__":
    main()
