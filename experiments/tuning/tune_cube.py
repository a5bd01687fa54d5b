"""Gradient-based tuning (``jaxgrasp.tune``) against dense grids, and the cost of a gradient.

1. Cube (2 fingertips, m = 0), each Young's modulus of the paper's range (2e5..1e6 Pa, 9
   values): tune one shared initial deformation from dr = 1.5 mm and compare with the best
   point of a dense grid (161 points, 1..5 mm; the value is 0 above
   ``sqrt(f_max / (pi E))``).
2. ``examples/four_finger.json`` (4 fingertips, m = 0.15 kg, tilted gravity): tune each
   contact's deformation, then deformations and contact positions (each contact moves
   within +-10 mm in its face); table of the gains.
3. Cost of a gradient: steady-state time of a jitted ``value`` and a jitted
   ``jax.grad(value)`` (w.r.t. every field of the grasp) on the same grasp, several repeats.
4. Optimisers: the cube's shared deformation tuned from 1.5 mm with each of
   ``jaxgrasp.analysis.METHODS`` (SciPy's L-BFGS-B, ``jaxopt.LBFGSB``,
   ``jaxopt.ProjectedGradient``) at three Young's moduli: value reached, iterations,
   evaluations and time (the second call of each, so compilation is not counted).

Writes tune_cube.{csv,png} and tune_cube.log into its folder (the printed tables).

    python experiments/tuning/tune_cube.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import jax
import numpy as np

import jaxgrasp
from jaxgrasp.analysis import sweep, tune
from jaxgrasp.plots import plot_history
from jaxgrasp.presets import MAX_FORCE, cube

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent.parent / "examples"
KINDS = tuple(jaxgrasp.model.BoundaryKind.labels()) + ("none",)


class Tee:
    def __init__(self, path: Path):
        self.fh = open(path, "w")

    def __call__(self, *args):
        line = " ".join(str(a) for a in args)
        print(line, flush=True)
        self.fh.write(line + "\n")
        self.fh.flush()


def cube_study(out: Path, log, quick: bool):
    young = np.linspace(2e5, 1e6, 3 if quick else 9)
    dr = np.linspace(1e-3, 5e-3, 41 if quick else 161)
    t0 = time.perf_counter()
    grid = sweep(cube(), young_modulus=young, initial_deformation=dr)
    t_grid = time.perf_counter() - t0
    values = np.asarray(grid.value)  # (E, dr)
    rows = []
    histories = {}
    log(f"\n== cube: tune the shared initial deformation from 1.5 mm vs a grid of {dr.size} points ==")
    log(f"grid: {values.size} evaluations in {t_grid:.1f} s (incl. compilation)")
    log(
        f"{'E [Pa]':>9} {'grid best [mJ]':>15} {'at dr [mm]':>10} {'tuned [mJ]':>11} {'dr [mm]':>8} "
        f"{'tuned/grid':>10} {'iters':>5} {'evals':>5} {'time [s]':>8}  status"
    )
    for i, E in enumerate(young):
        j = int(np.argmax(values[i]))
        t0 = time.perf_counter()
        res = tune(cube(E, 1.5e-3), ["initial_deformation:shared"], maxiter=50)
        t_tune = time.perf_counter() - t0
        d = float(res.params["initial_deformation:shared"])
        ratio = res.value / values[i, j]
        kind = KINDS[int(res.evaluation.limiting_kind)]
        log(
            f"{E:9.3g} {values[i, j] * 1e3:15.6f} {dr[j] * 1e3:10.3f} {res.value * 1e3:11.6f} {d * 1e3:8.4f} "
            f"{ratio:10.5f} {res.iterations:5d} {res.evaluations:5d} {t_tune:8.1f}  {res.status} ({kind})"
        )
        rows.append(
            [E, values[i, j], dr[j], res.initial_value, res.value, d, ratio, res.iterations, res.evaluations,
             res.status, kind, math.sqrt(MAX_FORCE / (math.pi * E))]
        )
        histories[E] = res
    with open(out / "tune_cube.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            ["young_modulus_Pa", "grid_best_value_J", "grid_best_initial_deformation_m", "start_value_J",
             "tuned_value_J", "tuned_initial_deformation_m", "tuned_over_grid", "iterations", "evaluations",
             "status", "limiting_kind", "force_limit_deformation_m"]
        )
        for r in rows:
            w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in r])
    _plot_cube(out, young, dr, values, histories)
    return rows


def _plot_cube(out: Path, young, dr, values, histories):
    """tune_cube.png: the grid and the tuned optima (left), the tuning histories (right)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2))
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for i, E in enumerate(young):
        c = f"C{i % 10}"
        ax1.plot(dr * 1e3, values[i] * 1e3, "-", color=c, lw=1, label=f"E = {E:.3g} Pa")
        r = histories[E]
        ax1.plot(float(r.params["initial_deformation:shared"]) * 1e3, r.value * 1e3, "o", color=c, ms=6, mfc="none")
        ax2.plot(np.arange(r.history.size), r.history * 1e3, ".-", color=c, lw=1)
    ax1.set_xlabel("initial deformation dr [mm]")
    ax1.set_ylabel("evaluation value ΔU_min [mJ]")
    ax1.set_title(f"cube: grid ({dr.size} points, lines) and tuned optimum (circles)")
    ax1.legend(fontsize=7, ncol=2)
    ax1.grid(True, alpha=0.3)
    ax2.set_xlabel("L-BFGS-B iteration (start dr = 1.5 mm)")
    ax2.set_ylabel("evaluation value ΔU_min [mJ]")
    ax2.set_title("value over the iterations of jaxgrasp.tune")
    ax2.grid(True, alpha=0.3)
    fig.savefig(out / "tune_cube.png", dpi=150, bbox_inches="tight")


def four_finger_study(out: Path, log, quick: bool):
    g = jaxgrasp.load(EXAMPLES / "four_finger.json")
    log("\n== examples/four_finger.json (4 fingertips, m = 0.15 kg): per-contact tuning ==")
    cases = [
        ("initial_deformation", ["initial_deformation"], None),
        ("initial_deformation + positions (+-10 mm)", ["initial_deformation", "positions"], {"positions": 0.01}),
    ]
    log(f"{'tuned':<42} {'start [mJ]':>10} {'tuned [mJ]':>10} {'gain':>7} {'iters':>5} {'time [s]':>8}  status")
    results = []
    for label, params, bounds in cases:
        t0 = time.perf_counter()
        res = tune(g, params, bounds, maxiter=15 if quick else 60)
        el = time.perf_counter() - t0
        log(
            f"{label:<42} {res.initial_value * 1e3:10.5f} {res.value * 1e3:10.5f} {res.gain:7.3f} "
            f"{res.iterations:5d} {el:8.1f}  {res.status}; limiting "
            f"{KINDS[int(res.evaluation.limiting_kind)]} of contact {int(res.evaluation.limiting_contact)}"
        )
        dr0 = np.asarray(g.initial_deformation) * 1e3
        dr1 = np.asarray(res.grasp.initial_deformation) * 1e3
        log(f"    dr [mm]: {np.array2string(dr0, precision=3)} -> {np.array2string(dr1, precision=3)}")
        if "positions" in params:
            moved = (np.asarray(res.grasp.positions) - np.asarray(g.positions)) * 1e3
            for j, m in enumerate(moved):
                log(f"    contact {j} moved by [{', '.join(f'{x:+.2f}' for x in m)}] mm")
        if res.not_converged_evaluations:
            log(f"    {res.not_converged_evaluations} iterate(s) with not-converged evaluations")
        results.append((label, res))
        plot_history(res, out / f"tune_four_finger_{len(results)}.png", title=f"four_finger: {label}")
    return results


def gradient_cost(log, repeats: int):
    log(f"\n== cost of jax.grad(value) w.r.t. every field vs one value (steady state, median of {repeats}) ==")
    log(f"{'grasp':<26} {'value [ms]':>10} {'grad [ms]':>10} {'grad/value':>10}")
    grasps = [("cube (N=2)", cube(6e5, 2e-3)), ("four_finger (N=4)", jaxgrasp.load(EXAMPLES / "four_finger.json"))]
    out = []
    for name, g in grasps:
        f = jax.jit(lambda g: jaxgrasp.evaluate(g).value)
        df = jax.jit(jax.grad(lambda g: jaxgrasp.evaluate(g).value))
        jax.block_until_ready(f(g))
        jax.block_until_ready(df(g))
        tv, tg = [], []
        for _ in range(repeats):  # interleaved, so that load changes hit both alike
            t = time.perf_counter()
            jax.block_until_ready(f(g))
            tv.append(time.perf_counter() - t)
            t = time.perf_counter()
            jax.block_until_ready(df(g))
            tg.append(time.perf_counter() - t)
        mv, mg = np.median(tv), np.median(tg)
        log(f"{name:<26} {mv * 1e3:10.2f} {mg * 1e3:10.2f} {mg / mv:10.3f}")
        out.append((name, mv, mg))
    return out


def method_study(log, quick: bool):
    from jaxgrasp.analysis import METHODS

    log("\n== optimisers on the cube's shared deformation (start 1.5 mm, maxiter 50) ==")
    log(f"{'E [Pa]':>9} {'method':<20} {'tuned [mJ]':>11} {'dr [mm]':>8} {'iters':>5} {'evals':>5} {'time [s]':>8}  status")
    for E in (2e5, 6e5) if quick else (2e5, 6e5, 1e6):
        for method in METHODS:
            tune(cube(E, 1.5e-3), ["initial_deformation:shared"], maxiter=2, method=method)  # compile
            t0 = time.perf_counter()
            res = tune(cube(E, 1.5e-3), ["initial_deformation:shared"], maxiter=50, method=method)
            el = time.perf_counter() - t0
            d = float(res.params["initial_deformation:shared"])
            log(
                f"{E:9.3g} {method:<20} {res.value * 1e3:11.6f} {d * 1e3:8.4f} {res.iterations:5d} "
                f"{res.evaluations:5d} {el:8.1f}  {res.status}"
            )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="3 E values, a 41-point grid; written to quick/")
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--skip", default="", help="comma list of parts to skip: cube,four,cost,methods")
    args = p.parse_args()
    out = args.out or (HERE / ("quick" if args.quick else ""))
    out.mkdir(parents=True, exist_ok=True)
    jaxgrasp.engine.enable_compilation_cache()
    log = Tee(out / "tune_cube.log")
    log(f"jaxgrasp {jaxgrasp.__version__}, jax {jax.__version__}, {jax.devices()[0].platform}")
    skip = set(filter(None, args.skip.split(",")))
    if "cube" not in skip:
        cube_study(out, log, args.quick)
    if "four" not in skip:
        four_finger_study(out, log, args.quick)
    if "cost" not in skip:
        gradient_cost(log, 5 if args.quick else 20)
    if "methods" not in skip:
        method_study(log, args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
