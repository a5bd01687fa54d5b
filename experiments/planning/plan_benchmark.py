"""The planner on real objects against plain random sampling (issue 36, item 7).

For each object (pybullet's generated objects ``random_urdfs/NNN``, scaled to mm) and finger
count, in one run:

* ``jaxgrasp plan`` with default settings (antipodal pairs or spread tuples, the best refined
  by tuning along the surface), timed;
* plain random sampling under the same rules: independent uniform surface points, one
  uniform initial deformation, ``--random`` valid candidates (default 1500, ten times the
  plan's default), no refinement (``plan(sampler="uniform", refine=0)``);
* the ratio of the two best values, whether the best grasp's file is within 1e-6 m of the
  surface (checked with the NumPy closest point), candidates per second, unsettled counts.

Fingertip r = 10 mm, E = 3e5 Pa, mu = 0.8, f_max = 15 N, density 500 kg/m^3, gravity -z in the
mesh's axes. Each case is appended to ``plan_benchmark.jsonl`` as it finishes (a rerun skips
the cases there: ``--fresh`` starts over); the summary, ``plan_benchmark.log`` and the figure
``plan_benchmark.png`` are written from every case recorded.

    python experiments/planning/plan_benchmark.py --objects 50            # the full run
    python experiments/planning/plan_benchmark.py --objects 2 --fresh     # a smoke run
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
TIP = dict(radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0)
OBJECT = dict(units="mm", density=500.0, gravity=(0.0, 0.0, -9.81))


def object_file(i: int, folder: Path) -> Path:
    """Object ``i`` of pybullet_data's random_urdfs, scaled to mm (URDF scale 0.015 m per unit)."""
    import pybullet_data
    import trimesh

    out = folder / f"{i:03d}.obj"
    if not out.exists():
        mesh = trimesh.load(os.path.join(pybullet_data.getDataPath(), f"random_urdfs/{i:03d}/{i:03d}.obj"), force="mesh")
        mesh.apply_scale(15.0)
        mesh.export(out)
    return out


def on_surface_error(result) -> float:
    """Largest distance (m) of the best grasp's contacts from the mesh, NumPy brute force."""
    from jaxgrasp.surface import closest_on_triangles

    g = result.best
    tri = np.asarray(g.mesh.triangles)
    pts = result.mesh_positions[0]
    return max(float(np.linalg.norm(np.asarray(closest_on_triangles(p, tri, xp=np)) - p, axis=1).min())
               for p in pts)


def one_case(path: Path, fingers: int, random_count: int, seed: int) -> dict:
    import jaxgrasp

    t0 = time.perf_counter()
    planned = jaxgrasp.plan(path, fingers, seed=seed, **TIP, **OBJECT)
    t_plan = time.perf_counter() - t0
    t0 = time.perf_counter()
    rand = jaxgrasp.plan(path, fingers, seed=seed + 1000, sampler="uniform", refine=0, samples=random_count,
                         top=1, **TIP, **OBJECT)
    t_rand = time.perf_counter() - t0
    ratio = planned.value / rand.value if rand.value > 0 else (np.inf if planned.value > 0 else 1.0)
    return dict(
        object=path.stem, fingers=fingers, plan_value=planned.value, random_value=rand.value,
        ratio=float(ratio), plan_s=t_plan, random_s=t_rand, plan_valid=planned.valid, plan_sampled=planned.sampled,
        random_valid=rand.valid, random_sampled=rand.sampled, plan_dropped=planned.dropped, random_dropped=rand.dropped,
        plan_stable=planned.stable, random_stable=rand.stable, refine_kept=planned.refine_kept,
        surface_error_m=on_surface_error(planned) if planned.grasps else None,
        plan_rate=planned.valid / t_plan, random_rate=rand.valid / t_rand,
    )


def summary(cases: list[dict]) -> list[str]:
    lines = []
    for f in sorted({c["fingers"] for c in cases}):
        cs = [c for c in cases if c["fingers"] == f]
        r = np.array([c["ratio"] for c in cs])
        found = np.mean([c["plan_value"] > 0 for c in cs])
        lines.append(
            f"{f} fingers: {len(cs)} objects; plan found a stable grasp on {found:.0%}; plan/random best value: "
            f"median {np.median(r):.3f}, >= 0.9 on {np.mean(r >= 0.9):.0%}, >= 1 on {np.mean(r >= 1):.0%}; "
            f"plan time median {np.median([c['plan_s'] for c in cs]):.1f} s, max {max(c['plan_s'] for c in cs):.1f} s; "
            f"candidates/s plan {np.median([c['plan_rate'] for c in cs]):.0f}, random "
            f"{np.median([c['random_rate'] for c in cs]):.0f}; unsettled plan {sum(c['plan_dropped'] for c in cs)}, "
            f"random {sum(c['random_dropped'] for c in cs)}; surface error max "
            f"{max((c['surface_error_m'] or 0.0) for c in cs):.1e} m"
        )
    r = np.array([c["ratio"] for c in cases])
    lines.append(f"all: {len(cases)} cases, plan >= 0.9 x random on {np.mean(r >= 0.9):.0%}")
    return lines


def figure(cases: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    for f, m in ((2, "o"), (3, "s"), (4, "^")):
        cs = [c for c in cases if c["fingers"] == f]
        if cs:
            ax[0].scatter([c["random_value"] * 1e3 for c in cs], [c["plan_value"] * 1e3 for c in cs], marker=m,
                          label=f"{f} fingers", alpha=0.7)
            ax[1].hist([c["plan_s"] for c in cs], bins=15, alpha=0.6, label=f"{f} fingers")
    lim = max([c["plan_value"] for c in cases] + [c["random_value"] for c in cases]) * 1e3 * 1.05
    ax[0].plot([0, lim], [0, lim], "k-", lw=0.8, label="equal")
    ax[0].plot([0, lim], [0, 0.9 * lim], "k:", lw=0.8, label="0.9 x random")
    ax[0].set(xlabel="best value, plain random sampling (mJ)", ylabel="best value, jaxgrasp plan (mJ)",
              title="plan vs random sampling under the same rules")
    ax[1].set(xlabel="plan time per object (s)", ylabel="objects", title="planning time, default settings")
    for a in ax:
        a.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=120)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", type=int, default=50, help="objects 000.. (default 50)")
    p.add_argument("--fingers", default="2,3")
    p.add_argument("--random", type=int, default=1500, help="valid random candidates per case (default 1500)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fresh", action="store_true")
    args = p.parse_args()
    import jaxgrasp

    jaxgrasp.engine.enable_compilation_cache()
    folder = Path.home() / ".cache" / "jaxgrasp-experiments" / "objects"  # generated meshes, not committed
    folder.mkdir(parents=True, exist_ok=True)
    record = HERE / "plan_benchmark.jsonl"
    if args.fresh and record.exists():
        record.unlink()
    done = {(c["object"], c["fingers"]) for c in map(json.loads, record.read_text().splitlines())} if record.exists() else set()
    for i in range(args.objects):
        for f in map(int, args.fingers.split(",")):
            if (f"{i:03d}", f) in done:
                continue
            case = one_case(object_file(i, folder), f, args.random, args.seed)
            with record.open("a") as fh:
                fh.write(json.dumps(case) + "\n")
            print(f"{case['object']} {f} fingers: plan {case['plan_value']:.4e} J in {case['plan_s']:.1f} s, random "
                  f"{case['random_value']:.4e} J in {case['random_s']:.1f} s, ratio {case['ratio']:.3f}", flush=True)
    cases = [json.loads(x) for x in record.read_text().splitlines()]
    lines = [f"# plan_benchmark.py, {time.strftime('%Y-%m-%d %H:%M')}, load average {os.getloadavg()[0]:.1f} "
             f"(1 min) at the end, {os.cpu_count()} cores, jaxgrasp {jaxgrasp.__version__}"] + summary(cases)
    (HERE / "plan_benchmark.log").write_text("\n".join(lines) + "\n")
    figure(cases, HERE / "plan_benchmark.png")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
