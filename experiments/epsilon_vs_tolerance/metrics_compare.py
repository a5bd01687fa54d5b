"""Ferrari-Canny epsilon vs the energy tolerance on the same grasps (issue 15, item 4).

Computes, in one run:

1. on ``--count`` seeded random grasps (``tests/grasp_draws.py:seeded_grasps``:
   contact counts cycling 2..5): ``jaxgrasp.epsilon`` (torsion, 8 cone edges) and the
   energy tolerance ``J`` (``jaxgrasp.evaluate_batch``); force-closure vs stable counts, a
   2x2 contingency table, Spearman rank correlations;
2. on the paper's cube grid (Fig. 6: 9 E x 41 dr) and the prism grid (5 E x 9 dr x 3
   masses): Spearman, and the parameters each metric depends on (epsilon: exactly not E,
   not mass; dr only through eq. 10's eccentricity e; J: E, dr and mass);
3. worked examples where the two disagree, with the physics behind them;
4. ``experiments/epsilon_vs_tolerance/metrics_compare.png``: J (mJ, log) vs epsilon, coloured by status.

Timings and the load average are printed (the machine is shared). Full run (~5 min on 2
cores)::

    PYTHONPATH=. python experiments/epsilon_vs_tolerance/metrics_compare.py 2>/dev/null | tee experiments/epsilon_vs_tolerance/metrics_compare.log

``--quick`` evaluates 40 random grasps and small grids, and writes the figure to
``experiments/epsilon_vs_tolerance/quick/``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import rankdata, spearmanr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jaxgrasp  # noqa: E402
from jaxgrasp import plots  # noqa: E402

EDGES = 8
T0 = time.perf_counter()


def say(msg: str = "") -> None:
    print(msg, flush=True)


def load() -> str:
    return "load average %.2f %.2f %.2f" % os.getloadavg()


def spear(x, y) -> str:
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 3:
        return f"n={len(x)} (too few)"
    r = spearmanr(x, y)
    return f"rho = {r.statistic:+.3f} (p = {r.pvalue:.1e}, n = {len(x)})"


def energy_scale(f: dict) -> float:
    """sum_i pi E_i dr_i^3 / 3, J: the elastic energy stored by the initial squeeze."""
    on = np.ones(len(f["positions"]), bool) if f.get("active") is None else np.asarray(f["active"])
    e = np.broadcast_to(f["young_modulus"], on.shape)[on]
    dr = np.broadcast_to(f["initial_deformation"], on.shape)[on]
    return float(np.sum(np.pi * e * dr**3 / 3.0))


def eccentricity(mu, r, dr):
    return (8.0 / 15.0) * mu * np.sqrt(r**2 - (r - dr) ** 2)  # eq. 10, m


def describe(g: jaxgrasp.Grasp, label: str) -> dict:
    f = g.to_numpy()
    n = len(f["positions"])
    vec = lambda k: np.broadcast_to(np.asarray(f[k], float), (n,))  # noqa: E731
    E, dr, r, mu, fmax = (vec(k) for k in ("young_modulus", "initial_deformation", "radius", "friction", "max_force"))
    f0 = np.pi * E * dr**2
    say(f"    {label}: {n} contacts, mass {float(f['mass']):.3f} kg (m g = {float(f['mass']) * 9.81:.3f} N)")
    say("      E [kPa] " + " ".join(f"{x / 1e3:7.1f}" for x in E))
    say("      dr [mm] " + " ".join(f"{x * 1e3:7.3f}" for x in dr))
    say("      r [mm]  " + " ".join(f"{x * 1e3:7.2f}" for x in r))
    say("      mu      " + " ".join(f"{x:7.3f}" for x in mu))
    say("      f0 [N]  " + " ".join(f"{x:7.3f}" for x in f0) + "   (initial normal force pi E dr^2)")
    say("      fmax [N]" + " ".join(f"{x:7.3f}" for x in fmax) + f"   (max f0/fmax = {np.max(f0 / fmax):.3f})")
    nrm = np.asarray(f["normals"], float)
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    net = np.sum(-f0[:, None] * nrm, axis=0)
    say(f"      net force of the initial squeeze |sum -f0_i n_i| = {np.linalg.norm(net):.3f} N "
        f"(friction must carry it, with m g, at the equilibrium)")
    say(f"      stored energy sum pi E dr^3/3 = {energy_scale(f) * 1e3:.4f} mJ; "
        f"friction capacity sum mu f0 = {np.sum(mu * f0):.3f} N")
    return f


def margins_line(ev, n: int) -> str:
    m = np.asarray(ev.equilibrium_margins)[:, :n]
    return ("      equilibrium margins (>= 0 satisfied): slip " + " ".join(f"{x:+.3f}" for x in m[1])
            + " | force " + " ".join(f"{x:+.3f}" for x in m[2]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.count = min(args.count, 40)
    fig_dir = Path(__file__).resolve().parent / ("quick" if args.quick else "")
    fig_dir.mkdir(parents=True, exist_ok=True)
    import jaxgrasp

    jaxgrasp.engine.enable_compilation_cache()
    from _lab.grasp_draws import seeded_grasps

    say(f"# metrics_compare: Ferrari-Canny epsilon (torsion, {EDGES} edges) vs energy tolerance J")
    say(f"start: {load()} (2 cores shared)")

    # ---------------------------------------------------------------- random grasps
    grasps = seeded_grasps(args.count, seed=args.seed)
    stacked = jaxgrasp.stack(grasps)
    t = time.perf_counter()
    eps_res = jaxgrasp.epsilon(stacked, cone_edges=EDGES, torsion=True)
    t_eps = time.perf_counter() - t
    eps = np.asarray(eps_res.value)
    fc = np.asarray(eps_res.force_closure)
    t = time.perf_counter()
    batch = jaxgrasp.evaluate_batch(grasps)
    t_eval = time.perf_counter() - t
    J = np.asarray(batch.value)
    st = np.asarray(batch.status_names)
    ncon = np.asarray([len(g.to_numpy()["positions"]) for g in grasps])
    escale = np.asarray([energy_scale(g.to_numpy()) for g in grasps])
    say()
    say(f"## 1. {args.count} random grasps (seed {args.seed}, contact counts 2..5 cycling)")
    say(f"epsilon time: {t_eps:.2f} s for {args.count} grasps ({t_eps / args.count * 1e3:.2f} ms/grasp, NumPy/qhull)")
    say(f"evaluate_batch time: {t_eval:.1f} s (compile {batch.compile_seconds:.1f} s, run {batch.run_seconds:.1f} s, "
        f"{args.count / max(batch.run_seconds, 1e-9):.1f} grasps/s)")
    counts = {s: int(np.sum(st == s)) for s in ("stable", "unstable", "infeasible", "not_converged")}
    say(f"force closure: {int(fc.sum())} / {args.count}; status counts: {counts}")
    for n in sorted(set(ncon)):
        k = ncon == n
        say(f"  {n} contacts: {int(k.sum())} grasps, force closure {int(fc[k].sum())}, stable {int(np.sum(st[k] == 'stable'))}, "
            f"epsilon median {np.median(eps[k]):+.4f}")
    conv = st != "not_converged"
    stable = st == "stable"
    say(f"contingency table ({int(conv.sum())} grasps with a trusted J; {counts['not_converged']} not_converged left out):")
    say("                      stable   not stable (unstable+infeasible)")
    for name, row in (("force closure    ", fc), ("no force closure ", ~fc)):
        say(f"  {name}  {int(np.sum(row & stable & conv)):7d}   {int(np.sum(row & ~stable & conv)):7d}")
    fc_un = fc & (st == "unstable")
    fc_inf = fc & (st == "infeasible")
    nfc_st = ~fc & stable
    say(f"  force closure but unstable: {int(fc_un.sum())} (limiting boundary: "
        f"{ {str(a): int(b) for a, b in zip(*np.unique(np.asarray(batch.limiting_kind_names)[fc_un], return_counts=True))} }), "
        f"of them with mass > 0: {int(np.sum(fc_un & (np.asarray([float(g.mass) for g in grasps]) > 0)))}")
    ratio = np.asarray([np.max(np.pi * np.broadcast_to(f["young_modulus"], (len(f["positions"]),))
                               * np.broadcast_to(f["initial_deformation"], (len(f["positions"]),)) ** 2
                               / np.broadcast_to(f["max_force"], (len(f["positions"]),)))
                        for f in (g.to_numpy() for g in grasps)])
    marg = np.asarray(batch.evaluation.equilibrium_margins)  # (B, 3, N); padding 1
    slip0 = np.min(marg[:, 1, :], axis=-1) < 1e-6
    force0 = np.min(marg[:, 2, :], axis=-1) < 1e-6
    mass0 = np.asarray([float(g.mass) for g in grasps]) == 0
    say(f"    at their equilibrium: a slip margin 0 (a fingertip at its friction limit) in {int(np.sum(fc_un & slip0))}, "
        f"a force margin 0 in {int(np.sum(fc_un & force0))}; with mass > 0: slip {int(np.sum(fc_un & ~mass0 & slip0 & ~force0))}, "
        f"force {int(np.sum(fc_un & ~mass0 & force0))}; with no mass: slip only {int(np.sum(fc_un & mass0 & slip0 & ~force0))}, "
        f"force {int(np.sum(fc_un & mass0 & force0))}")
    say(f"  force closure but infeasible: {int(fc_inf.sum())}, of them with an initial normal force above its limit "
        f"(max pi E dr^2 / f_max > 1): {int(np.sum(fc_inf & (ratio > 1)))}")
    say(f"  stable but not force closure: {int(nfc_st.sum())} (contact counts { {int(a): int(b) for a, b in zip(*np.unique(ncon[nfc_st], return_counts=True))} })")
    say(f"Spearman(epsilon, J), all {int(conv.sum())} trusted grasps (J = 0 when not stable): {spear(eps[conv], J[conv])}")
    both = stable & fc
    say(f"Spearman(epsilon, J), stable and force closure: {spear(eps[both], J[both])}")
    say(f"Spearman(stored energy sum pi E dr^3/3, J), same grasps: {spear(escale[both], J[both])}")
    say(f"Spearman(epsilon, J / stored energy), same grasps: {spear(eps[both], J[both] / escale[both])}")
    say(f"  J over stable grasps: {J[stable].min() * 1e3:.3g} .. {J[stable].max() * 1e3:.3g} mJ; "
        f"epsilon over them: {eps[stable].min():+.4f} .. {eps[stable].max():+.4f}")

    # ---------------------------------------------------------------- sweeps
    cube_E = np.linspace(2e5, 1e6, 3 if args.quick else 9)
    cube_dr = np.linspace(1e-3, 5e-3, 9 if args.quick else 41)
    prism_E = np.linspace(2e5, 1e6, 2 if args.quick else 5)
    prism_dr = np.linspace(1e-3, 5e-3, 5 if args.quick else 9)
    masses = [0.0, 0.1, 0.2]
    t = time.perf_counter()
    cube0 = jaxgrasp.presets.cube()
    cube = jaxgrasp.sweep(cube0, young_modulus=cube_E, initial_deformation=cube_dr)
    prism0 = jaxgrasp.presets.prism()
    prism = jaxgrasp.sweep(prism0, young_modulus=prism_E, initial_deformation=prism_dr, mass=masses)
    t_sweep = time.perf_counter() - t

    def sweep_eps(base, res, radius=None, torsion=True):
        grid = res.grid()
        n = len(base.to_numpy()["positions"])
        flat = {k: v.ravel() for k, v in grid.items()}
        gs = []
        for i in range(len(flat["young_modulus"])):
            kw = dict(young_modulus=np.full(n, flat["young_modulus"][i]),
                      initial_deformation=np.full(n, flat["initial_deformation"][i]))
            if "mass" in flat:
                kw["mass"] = flat["mass"][i]
            if radius is not None:
                kw["radius"] = np.full(n, radius)
                r0 = float(np.asarray(base.radius).ravel()[0])
                dr = flat["initial_deformation"][i]
                a2 = 2 * r0 * dr - dr**2  # same contact radius, so the same e
                kw["initial_deformation"] = np.full(n, radius - np.sqrt(radius**2 - a2))
            gs.append(base.replace(**kw))
        return np.asarray(jaxgrasp.epsilon(jaxgrasp.stack(gs), cone_edges=EDGES, torsion=torsion).value).reshape(
            res.value.shape)

    say()
    say(f"## 2. paper grids (sweep time {t_sweep:.1f} s)")
    out = {}
    for name, base, res in (("cube", cube0, cube), ("prism", prism0, prism)):
        e = sweep_eps(base, res)
        e_nt = sweep_eps(base, res, torsion=False)
        e_r = sweep_eps(base, res, radius=0.040)
        v = np.asarray(res.value)
        s = np.asarray(res.status_names)
        out[name] = (e, v, s, res)
        say(f"### {name}: {v.size} points; status {res.counts() if hasattr(res, 'counts') else ''}")
        # axes: 0 = E, 1 = dr, (2 = mass)
        spread_E = np.max(np.ptp(e, axis=0))
        say(f"  epsilon: max spread over E at fixed dr (and mass) = {spread_E:.1e}")
        if e.ndim == 3:
            say(f"  epsilon: max spread over mass at fixed E, dr = {np.max(np.ptp(e, axis=2)):.1e}")
        e_dr = e[(0,) * 1 + (slice(None),) + (0,) * (e.ndim - 2)]
        r0 = float(np.asarray(base.radius).ravel()[0])
        mu0 = float(np.asarray(base.friction).ravel()[0])
        ecc = eccentricity(mu0, r0, cube_dr if name == "cube" else prism_dr)
        say(f"  epsilon over dr {res.axes['initial_deformation'][0] * 1e3:.1f}..{res.axes['initial_deformation'][-1] * 1e3:.1f} mm: "
            f"{e_dr[0]:.5f} .. {e_dr[-1]:.5f} (monotone: {bool(np.all(np.diff(e_dr) >= 0))}; "
            f"e = {ecc[0] * 1e3:.3f} .. {ecc[-1] * 1e3:.3f} mm)")
        say(f"  without torsion: epsilon spread over the whole grid = {np.ptp(e_nt):.1e} (value {e_nt.ravel()[0]:+.5f}, "
            f"force closure {bool(e_nt.ravel()[0] > 1e-12)})")
        say(f"  radius 40 mm with dr' chosen for the same e (eq. 10): max |epsilon - epsilon(25 mm)| = {np.max(np.abs(e_r - e)):.1e}")
        say(f"  J: {v.min() * 1e3:.4g} .. {v.max() * 1e3:.4g} mJ over the grid; status counts "
            f"{ {k: int(np.sum(s == k)) for k in np.unique(s)} }")
        Ev = res.axes["young_modulus"]
        ok = s == "stable"
        # J over E at fixed dr: largest ratio among stable points
        best = None
        for idx in np.ndindex(*[e.shape[a] for a in range(1, e.ndim)]):
            col = (slice(None),) + idx
            m = ok[col]
            if m.sum() >= 2:
                rr = v[col][m].max() / v[col][m].min()
                if best is None or rr > best[0]:
                    best = (rr, idx, m)
        rr, idx, m = best
        col = (slice(None),) + idx
        say(f"  J over E at fixed dr = {res.axes['initial_deformation'][idx[0]] * 1e3:.1f} mm"
            + (f", mass {masses[idx[1]]} kg" if e.ndim == 3 else "")
            + f" (epsilon {e[col][0]:.5f} at every E): "
            + ", ".join(f"{Ev[i] / 1e3:.0f} kPa {v[col][i] * 1e3:.4g} mJ" for i in range(len(Ev)) if m[i])
            + f"; ratio {rr:.2f}")
        i0 = 0
        say(f"  J over dr at E = {Ev[i0] / 1e3:.0f} kPa" + (", mass 0" if e.ndim == 3 else "") + ": "
            + ", ".join(f"{d * 1e3:.1f} mm {x * 1e3:.4g} ({st_[:4]})" for d, x, st_ in
                        zip(res.axes["initial_deformation"], v[(i0, slice(None)) + (0,) * (e.ndim - 2)],
                            s[(i0, slice(None)) + (0,) * (e.ndim - 2)])))
        if e.ndim == 3:
            iE, idr = 0, len(prism_dr) // 2
            say(f"  J over mass at E = {Ev[iE] / 1e3:.0f} kPa, dr = {prism_dr[idr] * 1e3:.1f} mm (epsilon {e[iE, idr, 0]:.5f}): "
                + ", ".join(f"{mm} kg {v[iE, idr, k] * 1e3:.4g} mJ ({s[iE, idr, k]})" for k, mm in enumerate(masses)))
        say(f"  Spearman(epsilon, J), all points: {spear(e.ravel(), v.ravel())}; stable points: {spear(e[ok], v[ok])}")
        fcs = e > 1e-12
        say(f"  force closure at {int(fcs.sum())} / {e.size} points; of them not stable: {int(np.sum(fcs & ~ok))} "
            f"({ {k: int(np.sum(fcs & (s == k))) for k in np.unique(s[fcs & ~ok])} })")

    # ---------------------------------------------------------------- examples
    say()
    say("## 3. worked examples where the two metrics disagree")
    e, v, s, res = out["cube"]
    Ev, drv = res.axes["young_modulus"], res.axes["initial_deformation"]
    ok = s == "stable"
    # (a) same epsilon (same dr), J differing by a large factor over E
    idr = int(np.argmin(np.abs(drv - 2e-3)))
    col = ok[:, idr]
    lo, hi = np.flatnonzero(col)[0], np.flatnonzero(col)[-1]
    say(f"(a1) cube, dr = {drv[idr] * 1e3:.1f} mm: E = {Ev[lo] / 1e3:.0f} kPa -> epsilon {e[lo, idr]:.5f}, J {v[lo, idr] * 1e3:.4g} mJ; "
        f"E = {Ev[hi] / 1e3:.0f} kPa -> epsilon {e[hi, idr]:.5f}, J {v[hi, idr] * 1e3:.4g} mJ "
        f"(ratio {v[hi, idr] / v[lo, idr]:.3f}; E ratio {Ev[hi] / Ev[lo]:.1f})")
    # epsilon higher, J lower: dr grows past the optimum
    iE = 0
    j_best = int(np.argmax(np.where(ok[iE], v[iE], -1)))
    j_last = int(np.flatnonzero(ok[iE])[-1])
    j_inf = int(np.flatnonzero(s[iE] == "infeasible")[0]) if np.any(s[iE] == "infeasible") else j_last
    say(f"(a2) cube, E = {Ev[iE] / 1e3:.0f} kPa: dr = {drv[j_best] * 1e3:.1f} mm -> epsilon {e[iE, j_best]:.5f}, J {v[iE, j_best] * 1e3:.4g} mJ (max); "
        f"dr = {drv[j_last] * 1e3:.1f} mm -> epsilon {e[iE, j_last]:.5f}, J {v[iE, j_last] * 1e3:.4g} mJ ({res.limiting_kind_names[iE, j_last]}); "
        f"dr = {drv[j_inf] * 1e3:.1f} mm -> epsilon {e[iE, j_inf]:.5f}, J 0 ({s[iE, j_inf]}; pi E dr^2 = "
        f"{np.pi * Ev[iE] * drv[j_inf] ** 2:.2f} N > f_max 15 N)")
    j1 = int(np.argmin(np.abs(drv - 1e-3)))
    say(f"(a3) cube: dr = {drv[j1] * 1e3:.1f} mm, E = {Ev[0] / 1e3:.0f} kPa -> epsilon {e[0, j1]:.5f}, J {v[0, j1] * 1e3:.4g} mJ; "
        f"dr = {drv[j_best] * 1e3:.1f} mm -> epsilon {e[0, j_best]:.5f} ({e[0, j_best] / e[0, j1]:.2f}x), "
        f"J {v[0, j_best] * 1e3:.4g} mJ ({v[0, j_best] / v[0, j1]:.0f}x)")
    ep, vp, sp, rp = out["prism"]
    iE, idr = 0, int(np.argmin(np.abs(prism_dr - 3e-3)))
    say(f"(a4) prism, E = {rp.axes['young_modulus'][iE] / 1e3:.0f} kPa, dr = {prism_dr[idr] * 1e3:.1f} mm: epsilon "
        + ", ".join(f"{ep[iE, idr, k]:.5f}" for k in range(3)) + " at mass " + ", ".join(map(str, masses))
        + "; J " + ", ".join(f"{vp[iE, idr, k] * 1e3:.4g}" for k in range(3)) + " mJ")

    # (b) force closure but not stable, random grasps
    cats = (("unstable, mass > 0, a slip margin 0 (gravity), no force margin 0", fc_un & ~mass0 & slip0 & ~force0),
            ("unstable, no mass, a slip margin 0 (unbalanced squeeze), no force margin 0", fc_un & mass0 & slip0 & ~force0),
            ("unstable, a force margin 0 (squeeze at its limit)", fc_un & force0),
            ("infeasible", fc_inf))
    for label, mask in cats:
        if not mask.any():
            say(f"(b) no force-closure grasp is {label}")
            continue
        idxs = np.flatnonzero(mask)
        for i in idxs[np.argsort(-eps[idxs])][:1]:
            say(f"(b) {label}: random grasp {i}: force closure (epsilon {eps[i]:+.4f}, rank {rankdata(eps)[i] / len(eps) * 100:.0f}th "
                f"percentile of {len(eps)}), status {st[i]}, J = {J[i]:.3g} J, limiting {batch.limiting_kind_names[i]} "
                f"at contact {batch.limiting_contact[i]}")
            describe(grasps[i], "parameters")
            say(margins_line(batch[i], ncon[i]))

    # (d) stable but not force closure
    for i in np.flatnonzero(nfc_st):
        fine = float(jaxgrasp.epsilon(grasps[i], cone_edges=64, torsion=True).value)
        say(f"(d) stable, not force closure: random grasp {i}: epsilon {eps[i]:+.5f} (64 cone edges: {fine:+.5f}), "
            f"J {J[i] * 1e3:.4g} mJ")
        f = describe(grasps[i], "parameters")
        nrm = np.asarray(f["normals"], float)
        nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
        pos = np.asarray(f["positions"], float)
        d = pos[1] - pos[0]
        mu = np.broadcast_to(np.asarray(f["friction"], float), (len(nrm),))
        ang = [np.degrees(np.arccos(abs(np.dot(d, nn)) / np.linalg.norm(d))) for nn in nrm]
        say("      angle between the contact line and each normal [deg]: " + ", ".join(f"{a:.2f}" for a in ang)
            + "; cone half-angle atan(mu): " + ", ".join(f"{np.degrees(np.arctan(m)):.2f}" for m in mu)
            + f"; the {EDGES}-edge polygon's inscribed half-angle atan(mu cos(pi/{EDGES})): "
            + ", ".join(f"{np.degrees(np.arctan(m * np.cos(np.pi / EDGES))):.2f}" for m in mu))

    # (c) stable and force closure: rank disagreement
    idx = np.flatnonzero(both)
    if len(idx) >= 3:
        re_ = rankdata(eps[idx]) / len(idx)
        rj = rankdata(J[idx]) / len(idx)
        for label, k in (("low epsilon rank, high J rank", np.argmax(rj - re_)), ("high epsilon rank, low J rank", np.argmax(re_ - rj))):
            i = idx[k]
            say(f"(c) {label}: random grasp {i}: epsilon {eps[i]:+.4f} (rank {re_[k] * 100:.0f}%), "
                f"J {J[i] * 1e3:.4g} mJ (rank {rj[k] * 100:.0f}%) among {len(idx)} stable force-closure grasps; "
                f"J / stored energy = {J[i] / escale[i]:.3f}")
            describe(grasps[i], "parameters")
        n_low_hi = int(np.sum((re_ < 0.25) & (rj > 0.75)))
        n_hi_low = int(np.sum((re_ > 0.75) & (rj < 0.25)))
        say(f"(c) grasps in the bottom quarter of epsilon and top quarter of J: {n_low_hi}; the reverse: {n_hi_low} "
            f"(of {len(idx)}; independence would give {len(idx) / 16:.0f} each)")

    # ---------------------------------------------------------------- figure
    fig = plots.new_figure(figsize=(8.0, 5.5))
    ax = fig.add_subplot(1, 1, 1)
    colors = {"stable": "tab:blue", "unstable": "tab:orange", "infeasible": "tab:red", "not_converged": "tab:gray"}
    vals = [J[stable]] + [out[k][1][out[k][2] == "stable"] for k in out]
    floor = 10 ** np.floor(np.log10(min(x.min() for x in vals if len(x)) * 1e3) - 1)
    rng = np.random.default_rng(0)

    def y_of(val, sts):
        y = np.where(sts == "stable", val * 1e3, floor * np.exp(rng.uniform(-0.25, 0.25, size=np.shape(val))))
        return y

    for k, c in colors.items():
        m = st == k
        if m.any():
            ax.scatter(eps[m], y_of(J[m], st[m]), s=8, c=c, alpha=0.5, lw=0,
                       label=f"random grasps: {k} ({int(m.sum())})")
    for name, marker in (("cube", "^"), ("prism", "s")):
        e, v, s, _ = out[name]
        for k, c in colors.items():
            m = s == k
            if m.any():
                ax.scatter(e[m], y_of(v[m], s[m]), s=26, marker=marker, facecolors="none", edgecolors=c, lw=0.9,
                           label=f"{name} grid: {k} ({int(m.sum())})")
    ax.set_yscale("log")
    ax.axhline(floor * 1.6, color="k", lw=0.5, ls=":")
    ax.text(ax.get_xlim()[0], floor * 1.8, "  below: J = 0 (unstable / infeasible), jittered", fontsize=7, va="bottom")
    top = max(x.max() for x in vals if len(x)) * 1e3
    ticks = [floor] + [10.0**k for k in range(int(np.log10(floor)) + 1, int(np.ceil(np.log10(top))) + 1)]
    ax.set_yticks(ticks, ["0"] + [f"$10^{{{int(np.log10(t))}}}$" for t in ticks[1:]])
    ax.minorticks_off()
    ax.axvline(0.0, color="k", lw=0.5, ls="--")
    ax.set_xlabel(f"Ferrari-Canny epsilon (torsion, {EDGES} cone edges; > 0: force closure)")
    ax.set_ylabel("energy tolerance J [mJ] (log)")
    ax.set_title(f"epsilon vs energy tolerance: {args.count} random grasps, cube and prism grids")
    ax.legend(fontsize=6.5, loc="upper left", ncol=2, framealpha=0.8)
    path = fig_dir / "metrics_compare.png"
    plots.save_figure(fig, path)
    say()
    say(f"figure: {path.relative_to(ROOT)}")
    say(f"end: {load()}; total {time.perf_counter() - T0:.0f} s")


if __name__ == "__main__":
    main()
