"""Fig. 1 of Tsuji et al., computed: a 2-D slice of the potential field U of the cube grasp
over two pose coordinates, with the equilibrium region's boundary, the equilibrium and the
lowest boundary point (whose height above the equilibrium is the evaluation value).

The slice passes through the equilibrium and is spanned by the pose coordinate along which
the limiting boundary minimum lies (for the cube: the rotation about the contact normal x,
i.e. torsional slip) and the coordinate that reaches the other boundary kind (translation
along x, which overloads one fingertip). The other four coordinates stay at the equilibrium.
The region boundary is the contour where the smallest scaled constraint margin
(jaxgrasp.model.constraint_margins: contact kept, no slip, force below limit) is 0.

Writes into its folder fig1_potential_slice.{png,csv} (the CSV holds every second grid line of
the plotted 241 x 241 grid) and prints the check: the lowest U along the
region boundary in the slice, minus the equilibrium energy, equals the evaluation value.

    python experiments/paper_figures/fig1_potential_slice.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import finding, parse_args, write_rows  # noqa: E402
from matplotlib.colors import LogNorm
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

import jaxgrasp
from jaxgrasp.engine import evaluate
from jaxgrasp.model import M_TO_MM, MJ_TO_J, constraint_margins, model_params, potential_energy
from jaxgrasp.plots import new_figure
from jaxgrasp.presets import cube

COORDS = [
    ("translation along x", "Δp_x", "mm"),
    ("translation along y", "Δp_y", "mm"),
    ("translation along z", "Δp_z", "mm"),
    ("rotation about x", "θ_x", "rad"),
    ("rotation about y", "θ_y", "rad"),
    ("rotation about z", "θ_z", "rad"),
]
ROW_NAMES = ("contact", "slip", "max_force")

YOUNG_MODULUS = 2e5  # Pa
INITIAL_DEFORMATION = 3e-3  # m (slip-limited; the force boundary is also in the window)


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], __file__)
    n = 81 if args.quick else 241
    grasp = cube(young_modulus=YOUNG_MODULUS, initial_deformation=INITIAL_DEFORMATION, mass=0.0)
    t0 = time.perf_counter()
    ev = evaluate(grasp)
    t_eval = time.perf_counter() - t0
    if ev.status_name != "stable":
        raise SystemExit(f"grasp is {ev.status_name}; choose another E / initial deformation")
    p = model_params(grasp)
    lever = float(max(np.max(np.linalg.norm(np.asarray(p.c), axis=-1)), np.max(np.asarray(p.r))))  # mm

    def pose(t, w):  # SI translation, rad -> internal pose (mm, rad)
        return np.concatenate([np.asarray(t) * M_TO_MM, np.asarray(w)])

    x_eq = pose(ev.equilibrium_translation, ev.equilibrium_rotation)
    k, c = int(ev.limiting_kind), int(ev.limiting_contact)
    bt, bw = np.asarray(ev.boundary_translation), np.asarray(ev.boundary_rotation)
    reached = np.isfinite(np.asarray(ev.boundary_energy))
    x_lim = pose(bt[k, c], bw[k, c])
    scale = np.array([1, 1, 1, lever, lever, lever])  # scaled pose: rotations as arc length, mm
    d_lim = (x_lim - x_eq) * scale
    i1 = int(np.argmax(np.abs(d_lim)))
    spans = np.zeros(6)
    for kk in range(2):
        for cc in range(bt.shape[1]):
            if reached[kk, cc]:
                spans = np.maximum(spans, np.abs((pose(bt[kk, cc], bw[kk, cc]) - x_eq) * scale))
    rest = [i for i in range(6) if i != i1]
    i2 = rest[int(np.argmax(spans[rest]))]
    ia, ib = sorted((i1, i2))  # translation first when there is one
    half = 1.4 * np.maximum(spans, 1e-3) / scale

    a = np.linspace(-half[ia], half[ia], n) + x_eq[ia]
    b = np.linspace(-half[ib], half[ib], n) + x_eq[ib]
    A, B = np.meshgrid(a, b, indexing="xy")  # rows: b, columns: a
    X = np.tile(x_eq, (A.size, 1))
    X[:, ia], X[:, ib] = A.ravel(), B.ravel()

    @jax.jit
    def field(xs):
        u = jax.vmap(lambda x: potential_energy(x, p))(xs)
        g = jax.vmap(lambda x: constraint_margins(x, p))(xs)  # (M, 3, N)
        return u, g

    t1 = time.perf_counter()
    u, g = field(jnp.asarray(X))
    u = np.asarray(u).reshape(A.shape) * MJ_TO_J  # J
    g = np.asarray(g)
    gmin = g.min(axis=(1, 2)).reshape(A.shape)
    grow = {name: g[:, r, :].min(axis=-1).reshape(A.shape) for r, name in enumerate(ROW_NAMES)}
    t_field = time.perf_counter() - t1
    u_eq = float(ev.equilibrium_energy)
    value = float(ev.value)

    # ---- figure
    fig = new_figure(figsize=(7.6, 7.4))
    ax = fig.subplots()
    du = (u - u_eq) * 1e3  # mJ above the equilibrium
    levels = np.geomspace(value * 1e3 / 64, max(du.max(), value * 1e3 * 2), 24)
    cf = ax.contourf(A, B, np.maximum(du, levels[0]), levels=levels, cmap="viridis", norm=LogNorm())
    cb = fig.colorbar(cf, ax=ax, label="U − min U  [mJ] (log scale)")
    decades = 10.0 ** np.arange(np.floor(np.log10(levels[0])), np.ceil(np.log10(levels[-1])) + 1)
    cb.set_ticks([t for t in decades if levels[0] <= t <= levels[-1]])
    cb.set_ticklabels([f"{t:g}" for t in decades if levels[0] <= t <= levels[-1]])
    ax.contour(A, B, du, levels=[value * 1e3], colors="white", linewidths=0.8, linestyles="--")
    outside = np.where(gmin < 0, 1.0, np.nan)
    ax.contourf(A, B, outside, levels=[0.5, 1.5], colors="none", hatches=["///"])
    cs = ax.contour(A, B, gmin, levels=[0.0], colors="k", linewidths=2.0)
    styles = {"slip": ("tab:red", "-."), "max_force": ("tab:orange", ":"), "contact": ("tab:gray", ":")}
    for name in ROW_NAMES:
        if np.any(grow[name] < 0) and np.any(grow[name] > 0):
            col, ls = styles[name]
            ax.contour(A, B, grow[name], levels=[0.0], colors=[col], linewidths=1.2, linestyles=ls)
    ax.plot([x_eq[ia]], [x_eq[ib]], "*", color="white", mec="k", ms=15, label="equilibrium (min U)")
    for kk in range(2):
        for cc in range(bt.shape[1]):
            if reached[kk, cc] and (kk, cc) != (k, c):
                xb = pose(bt[kk, cc], bw[kk, cc])
                ax.plot([xb[ia]], [xb[ib]], "s", mfc="none", mec="w", ms=7)
    ax.plot([x_lim[ia]], [x_lim[ib]], "o", color="tab:red", mec="w", ms=10,
            label=f"lowest boundary point ({jaxgrasp.model.BoundaryKind.labels()[k]}, contact {c})")
    handles, _ = ax.get_legend_handles_labels()
    handles += [
        Line2D([], [], color="k", lw=2, label="equilibrium region boundary (min margin = 0)"),
        Line2D([], [], color="tab:red", ls="-.", label="slip boundary"),
        Line2D([], [], color="tab:orange", ls=":", label="force-limit boundary"),
        Line2D([], [], color="0.55", ls="--", label=f"U = min U + ΔU_min ({value * 1e3:.4f} mJ)"),
        Line2D([], [], marker="s", mfc="none", mec="0.3", ls="none", label="other boundary minima"),
        Patch(facecolor="none", hatch="///", edgecolor="k", label="outside the region"),
    ]
    ax.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False)
    ax.set_xlabel(f"{COORDS[ia][0]} {COORDS[ia][1]} [{COORDS[ia][2]}]")
    ax.set_ylabel(f"{COORDS[ib][0]} {COORDS[ib][1]} [{COORDS[ib][2]}]")
    ax.set_title(
        f"Fig. 1: potential field of the cube grasp (E = {YOUNG_MODULUS:.3g} Pa, "
        f"Δr = {INITIAL_DEFORMATION * 1e3:g} mm)\nother pose coordinates at the equilibrium",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(args.out / "fig1_potential_slice.png", dpi=150, bbox_inches="tight")

    # ---- data
    si = lambda i, v: v / M_TO_MM if i < 3 else v  # internal -> SI
    unit = lambda i: "m" if i < 3 else "rad"
    names = ["translation_x", "translation_y", "translation_z", "rotation_x", "rotation_y", "rotation_z"]
    # every second grid line (the figure uses all of them): keeps the file ~2 MB
    keep = np.zeros(A.shape, dtype=bool)
    keep[::2, ::2] = True
    write_rows(
        args.out / "fig1_potential_slice.csv",
        [f"{names[ia]}_{unit(ia)}", f"{names[ib]}_{unit(ib)}", "potential_energy_J", "min_margin",
         "slip_margin", "max_force_margin", "in_region"],
        [
            [si(ia, A.flat[m]), si(ib, B.flat[m]), u.flat[m], gmin.flat[m], grow["slip"].flat[m],
             grow["max_force"].flat[m], int(gmin.flat[m] >= 0)]
            for m in np.flatnonzero(keep.ravel())
        ],
    )

    # ---- check: lowest U on the region boundary within the slice = min U + value
    verts = np.concatenate([seg for seg in cs.allsegs[0] if len(seg)], axis=0)
    XB = np.tile(x_eq, (len(verts), 1))
    XB[:, ia], XB[:, ib] = verts[:, 0], verts[:, 1]
    ub, _ = field(jnp.asarray(XB))
    ub_min = float(np.min(np.asarray(ub))) * MJ_TO_J - u_eq
    off = np.delete((x_lim - x_eq) * scale, [ia, ib])
    print(f"TIMING fig1: wall {time.perf_counter() - t0:.1f} s (evaluate incl. compilation {t_eval:.1f} s, "
          f"field on the slice {t_field:.1f} s)")
    print(f"grasp: cube, E = {YOUNG_MODULUS:g} Pa, dr = {INITIAL_DEFORMATION:g} m, status {ev.status_name}")
    print(f"slice: {COORDS[ia][0]} x {COORDS[ib][0]}, {n} x {n} points")
    print(f"evaluation value: {value:.6e} J, limiting boundary {jaxgrasp.model.BoundaryKind.labels()[k]} of contact {c}")
    print(f"limiting boundary point: {COORDS[ia][1]} = {x_lim[ia]:.4g} {COORDS[ia][2]}, "
          f"{COORDS[ib][1]} = {x_lim[ib]:.4g} {COORDS[ib][2]}; off-slice part {np.max(np.abs(off)):.2e} mm (scaled)")
    print(f"lowest U on the region boundary in the slice, above min U: {ub_min:.6e} J")
    finding(
        "the slice's lowest boundary point sits at the evaluation value above the equilibrium "
        f"(relative difference {abs(ub_min - value) / value:.1e})",
        ub_min >= value * (1 - 1e-3) and ub_min <= value * (1 + 1e-2),
    )
    finding("the equilibrium lies strictly inside the region (value > 0)", value > 0 and gmin[n // 2, n // 2] > 0)
    print(f"wrote {args.out}/fig1_potential_slice.png, fig1_potential_slice.csv")


if __name__ == "__main__":
    main()
