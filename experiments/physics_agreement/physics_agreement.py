"""Does the value predict what MuJoCo sees? (issue 38)

At least 500 grasps: the paper's presets (with and without weight), random grasps drawn as
in tests/grasp_draws.py, grasps on pybullet_data's random_urdfs objects (scale 0.015 m per
unit) built with jaxgrasp.from_mesh at random surface points (2 fingers: a random point
and the candidate most nearly opposite it; 3 fingers: random points), and the best grasps
jaxgrasp.planning.plan finds on other random_urdfs objects (2 and 3 fingers).
Every grasp with an equilibrium (stable, unstable, not converged) goes through
jaxgrasp.simulate with shortened trials; infeasible grasps are counted, not simulated.

Measured: ROC AUC of the value, of the Ferrari-Canny epsilon and of "value > 0" for
predicting six-axis success; the slip fraction of energy kicks per bin of s (below and
above 1), along the least-energy direction and along random ones.

    nice python experiments/physics_agreement/physics_agreement.py            # writes physics_agreement.{log,json}, physics_agreement.png
    python experiments/physics_agreement/physics_agreement.py --report        # the report of the saved rows again
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jaxgrasp
from jaxgrasp.simulation import simulate

HERE = os.path.dirname(os.path.abspath(__file__))
SCALES = (0.25, 0.5, 0.75, 0.9, 1.1, 1.5, 2.0, 4.0)
TRIALS = dict(hold_time_s=0.3, six_axis_time_s=0.5, kick_time_s=0.2)  # shortened (DexGraspBench: 2 s per axis)
N_RANDOM, N_MESH = 260, 200
N_PLANNED_OBJECTS = 6  # x 2 and 3 fingers x the 5 best grasps of each plan


def log(line: str) -> None:
    print(line, flush=True)
    LOG.append(line)


LOG: list[str] = []
PLAN_FAILURES: list[str] = []


def preset_grasps() -> list:
    out = []
    for e in (2e5, 6e5, 1e6):
        for dr in (1e-3, 2e-3, 3e-3):
            out.append(("preset", jaxgrasp.presets.cube(young_modulus=e, initial_deformation=dr)))
            out.append(("preset", jaxgrasp.presets.prism(young_modulus=e, initial_deformation=dr, mass=0.2)))
    return out


def random_grasps(count: int) -> list:
    from _lab.grasp_draws import NumpyDraw, build_grasp

    rng = np.random.default_rng(38)
    return [("random", build_grasp(NumpyDraw(rng), n=2 + i % 3)) for i in range(count)]


def mesh_grasps(count: int) -> list:
    import pybullet_data
    import trimesh

    rng = np.random.default_rng(380)
    root = os.path.join(pybullet_data.getDataPath(), "random_urdfs")
    out, k = [], 0
    while len(out) < count:
        mesh = trimesh.load(os.path.join(root, f"{k % 1000:03d}", f"{k % 1000:03d}.obj"), force="mesh")
        k += 1
        mesh.apply_scale(0.015)
        if not mesh.is_watertight:
            continue
        fingers = 2 + len(out) % 2
        cand, fid = trimesh.sample.sample_surface(mesh, 400, seed=int(rng.integers(1 << 31)))
        normals = mesh.face_normals[fid]
        if fingers == 2:  # the far side: the candidate most nearly opposite, on the inward normal's line
            off = cand - cand[0]
            line = np.linalg.norm(off - (off @ normals[0])[:, None] * normals[0], axis=1) / float(mesh.scale)
            j = int(np.argmax(-(normals @ normals[0]) - 5.0 * line))
            pts = cand[[0, j]]
        else:
            pts = cand[:3]
        f0_target = rng.uniform(1.0, 4.0)
        dr = rng.uniform(1e-3, 2.5e-3)
        e = f0_target / (math.pi * dr**2)
        try:
            g = jaxgrasp.from_mesh(mesh, pts, initial_deformation=dr, radius=rng.uniform(0.01, 0.02), young_modulus=e,
                                   friction=rng.uniform(0.4, 1.0), max_force=3.0 * f0_target,
                                   mass=rng.uniform(0.0, 0.3) * fingers * f0_target / 9.81)
        except jaxgrasp.GraspValueError:
            continue
        out.append(("mesh", g))
    return out


def planned_grasps(objects: int) -> list:
    """The 5 best grasps of jaxgrasp.planning.plan (issue 36; no refinement) on ``objects``
    random_urdfs objects, with 2 and with 3 fingers."""
    import pybullet_data
    import trimesh

    from jaxgrasp.planning import plan

    rng = np.random.default_rng(3836)
    root = os.path.join(pybullet_data.getDataPath(), "random_urdfs")
    out = []
    for k in range(objects):
        mesh = trimesh.load(os.path.join(root, f"{500 + k:03d}", f"{500 + k:03d}.obj"), force="mesh")
        mesh.apply_scale(0.015)
        for fingers in (2, 3):
            f0 = rng.uniform(1.0, 4.0)
            try:
                r = plan(mesh, fingers, radius=rng.uniform(0.01, 0.02), young_modulus=f0 / (math.pi * 0.002**2),
                         friction=rng.uniform(0.4, 1.0), max_force=3.0 * f0,
                         mass=rng.uniform(0.0, 0.3) * fingers * f0 / 9.81, samples=20, top=5, refine=0, seed=k)
            except ValueError as exc:  # the planner's antipodal sampler on a round with no candidate (main 3ebd3f8)
                PLAN_FAILURES.append(f"object {500 + k:03d}, {fingers} fingers: {type(exc).__name__}: {exc}")
                continue
            out.extend(("planned", g) for g in r.grasps)
            print(f"  planned {500 + k:03d} with {fingers} fingers: {len(r.grasps)} grasps", file=sys.stderr, flush=True)
    return out


def auc(score, label) -> float:
    """ROC AUC by the Mann-Whitney statistic (ties count one half)."""
    score, label = np.asarray(score, float), np.asarray(label, bool)
    pos, neg = score[label], score[~label]
    if len(pos) == 0 or len(neg) == 0:
        return float("nan")
    greater = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    return float(greater / (len(pos) * len(neg)))


def main() -> None:
    t0 = time.time()
    items = preset_grasps() + random_grasps(N_RANDOM) + mesh_grasps(N_MESH) + planned_grasps(N_PLANNED_OBJECTS)
    plain = [g.grasp if isinstance(g, jaxgrasp.MeshGrasp) else g for _, g in items]
    log(f"grasps: {len(items)} ({sum(s == 'preset' for s, _ in items)} presets, {sum(s == 'random' for s, _ in items)} "
        f"random, {sum(s == 'mesh' for s, _ in items)} at random points of random_urdfs meshes, "
        f"{sum(s == 'planned' for s, _ in items)} planned by jaxgrasp.planning.plan); built in {time.time() - t0:.0f} s")
    for line in PLAN_FAILURES:
        log(f"plan failed: {line}")
    batch = jaxgrasp.evaluate_batch(plain)
    eps = np.array([float(jaxgrasp.epsilon(g).value) for g in plain])
    log(f"evaluated in {time.time() - t0:.0f} s: {batch.counts()}")
    rows = []
    for i, ((source, g), p) in enumerate(zip(items, plain)):
        ev = batch[i]
        r = simulate(g, evaluation=ev, simulate_unstable=True, kick_scales=SCALES, random_kicks=1, seed=i, **TRIALS)
        rows.append(row_of(source, ev, eps[i], r))
        if (i + 1) % 50 == 0:
            print(f"  simulated {i + 1}/{len(items)} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
    report(rows, time.time() - t0)


def row_of(source, ev, eps, r) -> dict:
    return {
        "source": source, "status": ev.status_name, "value_J": float(np.asarray(ev.value)), "epsilon": eps,
        "simulated": r.simulated, "six_axis_success": r.six_axis_success,
        "hold_success": None if r.hold is None else r.hold.success,
        "settled_over_model": (np.asarray(r.settled_normal_force_N) / np.asarray(r.model_normal_force_N)).tolist()
        if r.simulated else None,
        "surfaces": r.parameters.get("contact_surfaces"),
        "kicks": [{"scale": k.scale, "direction": k.direction, "slipped": not k.success} for k in r.kicks],
    }


def report(rows, seconds: float) -> None:
    sim = [r for r in rows if r["simulated"]]
    log(f"simulated {len(sim)} of {len(rows)} (infeasible or without an equilibrium: {len(rows) - len(sim)}); {seconds:.0f} s in all")
    for name, sel in (("stable", [r for r in sim if r["status"] == "stable"]),
                      ("unstable", [r for r in sim if r["status"] != "stable"])):
        ratio = np.concatenate([np.asarray(r["settled_over_model"], float) for r in sel])
        log(f"{name} grasps ({len(sel)}): settled / model normal force over {ratio.size} fingertips: median "
            f"{np.nanmedian(ratio):.4f}, within 10 %: {np.mean(np.abs(ratio - 1) <= 0.1):.3f}; hold success "
            f"{np.mean([bool(r['hold_success']) for r in sel]):.3f}; six-axis success "
            f"{np.mean([bool(r['six_axis_success']) for r in sel]):.3f}")
    stable = [r for r in sim if r["status"] == "stable"]
    o = np.array([r["six_axis_success"] for r in stable], bool)
    log(f"among stable grasps only: AUC value {auc([r['value_J'] for r in stable], o):.3f}, "
        f"epsilon {auc([r['epsilon'] for r in stable], o):.3f}")
    ok = np.array([r["six_axis_success"] for r in sim], bool)
    value = np.array([r["value_J"] for r in sim])
    eps = np.array([r["epsilon"] for r in sim])
    log(f"six-axis success: {ok.sum()} of {len(sim)}; hold success {sum(bool(r['hold_success']) for r in sim)}")
    aucs = {"value": auc(value, ok), "epsilon": auc(eps, ok), "value_positive": auc(value > 0, ok)}
    log("ROC AUC for six-axis success: " + ", ".join(f"{k} {v:.3f}" for k, v in aucs.items()))
    for src in ("preset", "random", "mesh", "planned"):
        sel = [r for r in sim if r["source"] == src]
        o = np.array([r["six_axis_success"] for r in sel], bool)
        log(f"  {src}: {len(sel)} simulated, six-axis success {o.mean():.3f}, AUC value "
            f"{auc([r['value_J'] for r in sel], o):.3f}, epsilon {auc([r['epsilon'] for r in sel], o):.3f}")
    table = kick_table(sim)
    for line in table["lines"]:
        log(line)
    out = {"aucs": aucs, "kicks": table["fractions"], "trials": TRIALS, "scales": SCALES, "rows": rows, "seconds": seconds,
           "mujoco": __import__("mujoco").__version__}
    with open(os.path.join(HERE, "physics_agreement.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    with open(os.path.join(HERE, "physics_agreement.log"), "w") as fh:
        fh.write("\n".join(LOG) + "\n")
    figure(sim, table["fractions"], aucs)


def kick_table(sim) -> dict:
    fractions, lines = {}, ["slip fraction of energy kicks (stable grasps, value > 0), by s and direction:"]
    for direction in ("least_energy", "random"):
        fr = {}
        for s in SCALES:
            k = [kk["slipped"] for r in sim for kk in r["kicks"] if kk["direction"] == direction and kk["scale"] == s]
            fr[str(s)] = {"slip_fraction": float(np.mean(k)) if k else None, "kicks": len(k)}
        below = [kk["slipped"] for r in sim for kk in r["kicks"] if kk["direction"] == direction and kk["scale"] < 1]
        above = [kk["slipped"] for r in sim for kk in r["kicks"] if kk["direction"] == direction and kk["scale"] > 1]
        fr["below_1"] = {"slip_fraction": float(np.mean(below)) if below else None, "kicks": len(below)}
        fr["above_1"] = {"slip_fraction": float(np.mean(above)) if above else None, "kicks": len(above)}
        fractions[direction] = fr
        lines.append(f"  {direction:12s} " + "  ".join(
            f"s={s}: {fr[str(s)]['slip_fraction']:.3f} ({fr[str(s)]['kicks']})" for s in SCALES if fr[str(s)]["kicks"]))
        lines.append(f"  {direction:12s} s<1: {fr['below_1']['slip_fraction']:.3f} ({len(below)} kicks), "
                     f"s>1: {fr['above_1']['slip_fraction']:.3f} ({len(above)} kicks)")
    return {"fractions": fractions, "lines": lines}


def figure(sim, fractions, aucs) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for direction, marker in (("least_energy", "o-"), ("random", "s--")):
        xs = [s for s in SCALES if fractions[direction][str(s)]["kicks"]]
        ax[0].plot(xs, [fractions[direction][str(s)]["slip_fraction"] for s in xs], marker, label=direction)
    ax[0].axvline(1.0, color="0.5", lw=0.8)
    ax[0].set_xscale("log")
    ax[0].set_xticks(SCALES, [f"{x:g}" for x in SCALES], minor=False)
    ax[0].minorticks_off()
    ax[0].set_xlabel("kick energy / value, s")
    ax[0].set_ylabel("fraction of kicks with a slip (MuJoCo)")
    ax[0].legend()
    ok = np.array([r["six_axis_success"] for r in sim], bool)
    v = np.array([r["value_J"] for r in sim])
    bins = np.logspace(-7, -2, 26)
    ax[1].hist([np.clip(v[ok], 1e-7, None), np.clip(v[~ok], 1e-7, None)], bins=bins, label=["six-axis success", "failure"])
    ax[1].set_xscale("log")
    ax[1].set_xlabel("evaluation value, J (0 drawn at 1e-7)")
    ax[1].set_title(f"AUC value {aucs['value']:.2f}, epsilon {aucs['epsilon']:.2f}, value>0 {aucs['value_positive']:.2f}")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "physics_agreement.png"), dpi=110)


def report_again() -> None:
    """``--report``: the report of the saved rows again (no simulation)."""
    with open(os.path.join(HERE, "physics_agreement.json")) as fh:
        saved = json.load(fh)
    with open(os.path.join(HERE, "physics_agreement.log")) as fh:
        LOG.extend(fh.read().splitlines()[:2])
    report(saved["rows"], saved["seconds"])


if __name__ == "__main__":
    report_again() if "--report" in sys.argv[1:] else main()
