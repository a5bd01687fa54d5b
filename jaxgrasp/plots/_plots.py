"""Plots of grasps, sweep and batch results (matplotlib, Agg backend: no display needed).

`plot_grasp` draws one grasp in 3-D (object, fingertips, friction cones, the
limiting contact) with the motion that makes it fail (`jaxgrasp.plots._scene`).

`plot_ranking` draws the grasps of a [`BatchResult`][jaxgrasp.BatchResult] ranked by value
(a log scale: values span decades), coloured by status, beside the count of each status.
The sweep plots below follow these conventions:

* the evaluation value is drawn in mJ (labelled), parameters in readable units (mm,
  kPa, kg, N; labelled);
* a line joins only points whose value can be trusted (stable and unstable ones);
  it is broken at infeasible and not-converged points;
* infeasible points (no stable equilibrium at all) are NOT drawn as zero values: they
  are marked ``x`` in the curve's colour in a grey band below the value axis' zero (one
  row per curve), outside the value scale;
* unstable points (value 0 because the equilibrium lies on a boundary) are open circles
  at value 0;
* not-converged points are open grey diamonds at their (untrusted) value;
* figures are built on the Agg canvas directly (``matplotlib.figure.Figure``), so
  pyplot's global backend is never touched.
* points whose value is set by a fingertip's force limit (``max_force``) carry a small
  filled triangle; the others are set by slip.
"""

from __future__ import annotations

import itertools
import math
import os

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from jaxgrasp import storage
from jaxgrasp.model import BoundaryKind
from jaxgrasp.model import FIELD
from jaxgrasp.model import MJ_TO_J
from jaxgrasp.tolerance import GraspStatus

__all__ = [
    "plot_sweep",
    "plot_max_over",
    "plot_max",
    "plot_ranking",
    "plot_grasp",
    "draw_scene",
    "new_figure",
    "save_figure",
    "plain_text",
    "J_TO_MJ",
]


J_TO_MJ = 1.0 / MJ_TO_J
"""Energy: J to mJ (plots show the value in mJ)."""

VALUE_LABEL = "evaluation value ΔU_min [mJ]"
_LINESTYLES = ["-", "--", ":", "-."]


def _axis_label(name: str) -> str:
    return FIELD[name].label


def _scale(name: str) -> float:
    """Factor from SI to the unit a plot shows ``name`` in (mm, kPa, ...)."""
    return FIELD[name].display[0]


def _fmt(name: str, x: float) -> str:
    field = FIELD[name]
    factor, unit = field.display
    return f"{field.symbol} = {x * factor:.4g}" + (f" {unit}" if unit else "")


def plain_text(text: str) -> str:
    """``text`` (a title that may hold a file name) drawn as written: its ``$`` escaped, so
    that matplotlib does not parse ``a$b$.toml`` as mathtext (which fails for ``$\\x$``
    only when the figure is saved, after all the computing)."""
    return text.replace("$", r"\$")


def new_figure(**kwargs) -> Figure:
    """A figure on the Agg canvas (no pyplot, no display)."""
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path, format: str | None = None) -> None:
    """Save ``fig`` (150 dpi, tight box) to ``path`` atomically, or into a binary file object.

    A path is written as a temporary file renamed into place (`jaxgrasp.storage`),
    so a failure or an interrupt never leaves half an image. The format is ``format``,
    else the path's suffix, else matplotlib's default (``png``; its suffix is then added,
    as ``savefig`` does).
    """
    if hasattr(path, "write"):
        fig.savefig(path, format=format or matplotlib.rcParams["savefig.format"], dpi=150, bbox_inches="tight")
        return
    path = os.fspath(path)
    fmt = format or os.path.splitext(path)[1][1:].lower()
    if not fmt:
        fmt = matplotlib.rcParams["savefig.format"]
        path = f"{path}.{fmt}"
    storage.write_file(path, lambda fh: fig.savefig(fh, format=fmt, dpi=150, bbox_inches="tight"))


def _save(fig, path):
    if path is not None:
        save_figure(fig, path)
    return fig


def _draw_curve(ax, x, value, status, kind, *, color, linestyle, label):
    """One curve with the status conventions of this module (value in J, x in display units).

    Returns the x of the infeasible points (for `_infeasible_band`)."""
    value = np.asarray(value, dtype=float)
    status = np.asarray(status)
    kind = np.asarray(kind)
    y = value * J_TO_MJ
    ok = (status == GraspStatus.STABLE) | (status == GraspStatus.UNSTABLE)
    ax.plot(x, np.where(ok, y, np.nan), color=color, linestyle=linestyle, lw=1.6, label=label)
    m = status == GraspStatus.STABLE  # small dots, so that a stable point between gaps still shows
    ax.plot(x[m], y[m], ".", color=color, ms=3, ls="none")
    m = (status == GraspStatus.STABLE) & (kind == BoundaryKind.MAX_FORCE)
    if np.any(m):
        ax.plot(x[m], y[m], "^", color=color, ms=4, ls="none")
    m = status == GraspStatus.UNSTABLE
    if np.any(m):
        ax.plot(x[m], np.zeros(np.sum(m)), "o", mfc="white", mec=color, ms=6, mew=1.4, ls="none")
    m = status == GraspStatus.NOT_CONVERGED
    if np.any(m):
        ax.plot(x[m], y[m], "D", mfc="none", mec="0.45", ms=6, mew=1.2, ls="none")
    return x[status == GraspStatus.INFEASIBLE]  # drawn by _infeasible_band, below the zero line


def _infeasible_band(axes, entries, n_rows):
    """Mark infeasible points with ``x`` in a grey band below value 0, one row per curve.

    ``entries``: per axes, a list of ``(x, color, row)``. The value axis keeps its ticks at
    ``>= 0`` only; the band is not part of the value scale.
    """
    if not any(len(x) for per_ax in entries for x, _, _ in per_ax):
        for ax in axes:
            ax.set_ylim(bottom=0.0)
        return
    top = max(ax.get_ylim()[1] for ax in axes)
    frac = min(0.06 + 0.012 * n_rows, 0.2)
    bottom = -frac * top
    for ax, per_ax in zip(axes, entries):
        ax.axhspan(bottom, 0.0, color="0.93", zorder=0, lw=0)
        ax.axhline(0.0, color="0.55", lw=0.7, zorder=1)
        ax.text(0.005, bottom * 0.5, "infeasible", transform=ax.get_yaxis_transform(), fontsize=7,
                color="0.35", va="center", ha="left", zorder=1)
        for x, color, row in per_ax:
            if len(x):
                y = bottom * (row + 0.5) / max(n_rows, 1)
                ax.plot(x, np.full(len(x), y), "x", color=color, ms=4.5, mew=1.2, ls="none", zorder=3)
    for ax in axes:
        ax.set_ylim(bottom, top)
        ax.set_yticks([t for t in ax.get_yticks() if 0.0 <= t <= top])
        ax.set_ylim(bottom, top)


def _status_legend(ax, status, kind):
    s = np.asarray(status)
    handles = [Line2D([], [], color="k", lw=1.6, label="stable (value set by slip)")]
    if np.any((s == GraspStatus.STABLE) & (np.asarray(kind) == BoundaryKind.MAX_FORCE)):
        handles.append(
            Line2D([], [], color="k", marker="^", ms=4, ls="none", label="value set by force limit")
        )
    if np.any(s == GraspStatus.UNSTABLE):
        handles.append(
            Line2D([], [], marker="o", mfc="white", mec="k", ms=6, ls="none", label="unstable (value 0)")
        )
    if np.any(s == GraspStatus.INFEASIBLE):
        handles.append(
            Line2D(
                [], [], marker="x", color="k", ms=5, ls="none",
                label="infeasible: no stable equilibrium\n(in the grey band below 0)",
            )
        )
    if np.any(s == GraspStatus.NOT_CONVERGED):
        handles.append(
            Line2D(
                [], [], marker="D", mfc="none", mec="0.45", ms=6, ls="none", label="not converged (untrusted)"
            )
        )
    return handles


def _role(given, preferred: str, names: list) -> tuple:
    """The axis that plays a role (x, curves, panels): ``given``, else ``preferred`` where
    it is swept, else the first of ``names`` (``None`` when none is left); and the names
    left for the other roles."""
    if given is None:
        given = preferred if preferred in names else (names[0] if names else None)
    return given, [n for n in names if n != given]


def _pick_roles(names, x, curves, panels):
    x, rest = _role(x, "initial_deformation", list(names))
    curves, rest = _role(curves, "young_modulus", rest)
    panels, rest = _role(panels, "mass", rest)
    return x, curves, panels, rest


def plot_sweep(result, path=None, *, x=None, curves=None, panels=None, title=None, max_panels=12):
    """Value against one parameter, one curve per value of another, panels for a third.

    Defaults: ``x`` is ``initial_deformation`` (else the first axis), ``curves``
    ``young_modulus`` (else the next axis), ``panels`` ``mass`` (else the next axis).
    Any further axes become more panels (one per combination, at most ``max_panels``).

    Args:
        result: a [`SweepResult`][jaxgrasp.analysis.SweepResult].
        path: where to save the figure (PNG, ...); ``None`` returns it open.
        title: figure title, drawn as written (a ``$`` is a dollar sign, not mathtext).

    Returns:
        The matplotlib ``Figure``.
    """
    if not result.axes:
        raise ValueError("plot_sweep needs a sweep with at least one axis")
    x, curves, panels, rest = _pick_roles(result.names, x, curves, panels)
    order = [x] + ([curves] if curves else []) + ([panels] if panels else []) + rest
    perm = [result.names.index(n) for n in order]
    arrs = {
        f: np.transpose(np.asarray(getattr(result, f)), perm)
        for f in ("value", "status", "limiting_kind")
    }
    shape = arrs["value"].shape
    n_curves = shape[1] if curves else 1
    panel_names = ([panels] if panels else []) + rest
    panel_index = list(itertools.product(*[range(len(result.axes[n])) for n in panel_names]))
    truncated = len(panel_index) > max_panels
    panel_index = panel_index[:max_panels]
    n_p = len(panel_index)
    ncols = min(n_p, 3)
    nrows = math.ceil(n_p / ncols)
    fig = new_figure(figsize=(6.4 * ncols, 4.4 * nrows))
    axs = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    xs = np.asarray(result.axes[x]) * _scale(x)
    used_axes, band = [], []
    for p, pidx in enumerate(panel_index):
        ax = axs[p // ncols][p % ncols]
        used_axes.append(ax)
        band.append(_draw_panel(ax, result, arrs, xs, x, curves, n_curves, panel_names, pidx))
        if p % ncols == 0:
            ax.set_ylabel(VALUE_LABEL)
    for ax in used_axes:
        ax.set_ylim(bottom=0.0)
    _infeasible_band(used_axes, band, n_curves)
    for p in range(n_p, nrows * ncols):
        axs[p // ncols][p % ncols].set_visible(False)
    ax0 = axs[0][0]
    curve_handles, _ = ax0.get_legend_handles_labels()
    handles = curve_handles + _status_legend(ax0, arrs["status"], arrs["limiting_kind"])
    fig.legend(handles=handles, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=9, frameon=False)
    if title or truncated:
        t = title or ""
        if truncated:
            t += f" (first {max_panels} panels shown)"
        fig.suptitle(plain_text(t))
    fig.tight_layout()
    return _save(fig, path)


def _draw_panel(ax, result, arrs, xs, x, curves, n_curves, panel_names, pidx):
    """One panel of `plot_sweep`: a curve per value of ``curves`` at panel index
    ``pidx``; returns the infeasible points per curve for `_infeasible_band`."""
    cmap = matplotlib.colormaps.get_cmap("viridis")
    band = []
    for c in range(n_curves):
        sel = (slice(None), c, *pidx) if curves else (slice(None), *pidx)
        color = cmap(0.9 * c / max(n_curves - 1, 1))
        label = _fmt(curves, result.axes[curves][c]) if curves else None
        x_inf = _draw_curve(
            ax,
            xs,
            arrs["value"][sel],
            arrs["status"][sel],
            arrs["limiting_kind"][sel],
            color=color,
            linestyle="-",
            label=label,
        )
        band.append((x_inf, color, c))
    ax.set_xlabel(_axis_label(x))
    ax.grid(True, alpha=0.3)
    if panel_names:
        text = ", ".join(_fmt(n, result.axes[n][i]) for n, i in zip(panel_names, pidx))
        ax.set_title(text, fontsize=10)
    return band


def plot_max_over(result, path=None, *, over="initial_deformation", x=None, curves=None, title=None):
    """Maximum value over one axis (paper's Fig. 7), with the maximising parameter below.

    Top panel: ``max over <over>`` of the value against ``x`` (default
    ``young_modulus``), one curve per value of ``curves`` (default ``mass`` if swept, else
    the remaining axis). Bottom panel: the maximising value of ``over`` (e.g. the optimal
    initial deformation). Status conventions as in `plot_sweep`, for the maximising
    point.
    """
    reduced, arg = result.max_over(over)
    return plot_max(reduced, arg, path, over=over, x=x, curves=curves, title=title)


def plot_max(reduced, best, path=None, *, over="initial_deformation", x=None, curves=None, title=None):
    """Like `plot_max_over`, from an already reduced result.

    Args:
        reduced: a [`SweepResult`][jaxgrasp.analysis.SweepResult] of the maximising points (one or
            two axes), e.g. the first output of ``SweepResult.max_over``.
        best: the maximising value of parameter ``over`` at each of its points (SI).
    """
    arg = np.asarray(best)
    names = list(reduced.names)
    if not names:
        raise ValueError("plot_max_over needs a sweep with at least two axes")
    x, rest = _role(x, "young_modulus", names)
    curves, rest = _role(curves, "mass", rest)
    if rest:
        raise ValueError(f"plot_max_over: too many axes left ({', '.join(rest)}); reduce them first")
    order = [x] + ([curves] if curves else [])
    perm = [names.index(n) for n in order]
    val = np.transpose(np.asarray(reduced.value), perm)
    st = np.transpose(np.asarray(reduced.status), perm)
    kd = np.transpose(np.asarray(reduced.limiting_kind), perm)
    am = np.transpose(np.asarray(arg), perm)
    if not curves:
        val, st, kd, am = val[:, None], st[:, None], kd[:, None], am[:, None]
    n_curves = val.shape[1]
    fig = new_figure(figsize=(6.4, 6.4))
    ax, ax2 = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    xs = np.asarray(reduced.axes[x]) * _scale(x)
    of = _scale(over)
    cmap = matplotlib.colormaps.get_cmap("plasma")
    band = []
    for c in range(n_curves):
        color = cmap(0.85 * c / max(n_curves - 1, 1)) if n_curves > 1 else "C0"
        ls = _LINESTYLES[c % len(_LINESTYLES)]
        label = _fmt(curves, reduced.axes[curves][c]) if curves else None
        x_inf = _draw_curve(ax, xs, val[:, c], st[:, c], kd[:, c], color=color, linestyle=ls, label=label)
        band.append((x_inf, color, c))
        ok = st[:, c] == GraspStatus.STABLE
        ax2.plot(xs, np.where(ok, am[:, c] * of, np.nan), ls=ls, marker="o", ms=3, color=color)
    ax.set_ylabel(f"max over {FIELD[over].symbol} of value [mJ]")
    ax.set_ylim(bottom=0.0)
    _infeasible_band([ax], [band], n_curves)
    ax.grid(True, alpha=0.3)
    curve_handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=curve_handles + _status_legend(ax, st, kd), fontsize=8)
    ax2.set_xlabel(_axis_label(x))
    sym_o, unit_o = FIELD[over].symbol, FIELD[over].display[1]
    ax2.set_ylabel(f"best {sym_o} [{unit_o}]" if unit_o else f"best {sym_o}")
    ax2.grid(True, alpha=0.3)
    if title:
        ax.set_title(plain_text(title), fontsize=11)
    fig.tight_layout()
    return _save(fig, path)


# --------------------------------------------------------------------------- batch ranking

STATUS_COLORS = {
    "stable": "tab:blue",
    "unstable": "tab:orange",
    "infeasible": "tab:red",
    "not_converged": "0.55",
    "invalid": "k",
}
"""The colour of each grasp status in `plot_ranking`."""


def plot_ranking(result, path=None, *, top: int = 5, title=None):
    """The grasps of a [`BatchResult`][jaxgrasp.BatchResult] ranked by value, and their statuses.

    Left: the value (mJ, log scale) of every stable grasp, best first, points with their
    value set by a force limit marked with triangles; not_converged grasps (untrusted
    values) as grey diamonds after them; the ``top`` best labelled with their input index.
    Right: how many grasps have each status (unstable and infeasible grasps have value 0,
    invalid ones none, so they are counted, not drawn on the log scale).

    Returns the figure; with ``path``, also saves it (atomically).
    """
    names = np.asarray(result.status_names)
    value = np.asarray(result.value, dtype=np.float64) * J_TO_MJ
    kind = np.asarray(result.limiting_kind)
    order = np.asarray(result.rank())
    fig = new_figure(figsize=(10.0, 4.2))
    ax, bars = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3.2, 1.0]})
    ranked = order[np.isin(names[order], ("stable", "not_converged")) & (value[order] > 0)]
    x = np.arange(1, ranked.size + 1)
    for label, marker in (("stable", "o"), ("not_converged", "D")):
        m = names[ranked] == label
        if m.any():
            face = STATUS_COLORS[label] if label == "stable" else "none"
            ax.plot(x[m], value[ranked[m]], marker, ms=3.5, ls="none", mfc=face, mec=STATUS_COLORS[label])
            force = m & (kind[ranked] == BoundaryKind.MAX_FORCE)
            ax.plot(x[force], value[ranked[force]], "^", ms=6, ls="none", mfc="none", mec="k", mew=0.8)
    for r, i in enumerate(ranked[: max(0, top)], start=1):
        ax.annotate(f"grasp {i}", (r, value[i]), xytext=(4, 3), textcoords="offset points", fontsize=8)
    if ranked.size:
        ax.set_yscale("log")
    else:
        ax.text(0.5, 0.5, "no stable grasp", transform=ax.transAxes, ha="center", va="center", color="0.4")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("rank (1 = most stable)")
    ax.set_ylabel(VALUE_LABEL)
    ax.grid(True, which="both", alpha=0.25)
    handles = [
        Line2D([], [], marker="o", ls="none", color=STATUS_COLORS["stable"], label="stable"),
        Line2D([], [], marker="^", ls="none", mfc="none", mec="k", label="value set by force limit"),
        Line2D([], [], marker="D", ls="none", mfc="none", mec=STATUS_COLORS["not_converged"], label="not_converged (untrusted)"),
    ]
    ax.legend(handles=handles, fontsize=8, loc="upper right")
    counts = result.counts()
    labels = [k for k in STATUS_COLORS if counts.get(k, 0) or k != "invalid"]
    bars.barh(labels, [counts.get(k, 0) for k in labels], color=[STATUS_COLORS[k] for k in labels])
    for y, k in enumerate(labels):
        bars.text(counts.get(k, 0), y, f" {counts.get(k, 0)}", va="center", fontsize=9)
    bars.invert_yaxis()
    bars.set_xlabel("grasps")
    bars.set_xlim(0, max(1, max(counts.values())) * 1.25)
    fig.suptitle(plain_text(title or f"{len(result)} grasps ranked by evaluation value"))
    fig.tight_layout()
    return _save(fig, path)


# --------------------------------------------------------------------------- one grasp in 3-D


def plot_grasp(grasp, path=None, *, result=None, magnification=None, title=None, view=(22.0, -58.0)):
    """A 3-D picture of a grasp and the way it fails.

    The object (its mesh, or the contacts' hull when there is none), each fingertip as a
    hemisphere pressed into its contact, its outward normal and friction cone, the
    limiting contact's fingertip in red, and the object moved by the least-energy pose of
    the limiting boundary as an orange ghost, the motion magnified by the factor the
    title states (`jaxgrasp.plots.grasp_scene`). Axes in mm, the mesh's frame.

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] or [`MeshGrasp`][jaxgrasp.MeshGrasp] (one grasp).
        path: where to save the figure (PNG, ...); ``None`` returns it open.
        result: its [`Evaluation`][jaxgrasp.Evaluation] (default: evaluated here).
        magnification: the ghost's motion factor (default: a round one, see
            `jaxgrasp.plots._scene.nice_magnification`).
        title: first title line, drawn as written (default: the status, value and limiting boundary).
        view: ``(elevation, azimuth)`` of the camera, degrees.

    Returns:
        The matplotlib ``Figure``.
    """
    from jaxgrasp.plots._scene import grasp_scene

    if result is None:
        from jaxgrasp.engine import evaluate
        from jaxgrasp.surface import MeshGrasp

        result = evaluate(grasp.grasp if isinstance(grasp, MeshGrasp) else grasp)
    scene = grasp_scene(grasp, result, magnification=magnification)
    return _save(draw_scene(scene, title=title, view=view), path)


def draw_scene(scene, *, title=None, view=(22.0, -58.0)):
    """The figure of a `GraspScene` (see `plot_grasp`).

    Each mesh is drawn as its ``Part.drawn`` (decimated for drawing past
    `jaxgrasp.plots._drawing.DRAW_FACES` faces), the object, its ghost and a hand's links
    lit from near the camera; the object's sharp edges and its outline as the camera sees
    it are drawn as lines (solid; dashed at the ghost pose), so that a smooth object shows
    its shape as well as a box does."""
    from matplotlib.patches import Patch

    from jaxgrasp.plots._scene import COLORS

    mm = 1e3
    fig = new_figure(figsize=(7.6, 7.4))
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    _set_view(ax, scene, view)
    _draw_meshes(ax, scene, view)
    for (start, end), name in zip(scene.axes * mm, "xyz"):
        ax.text(*(start + 1.08 * (end - start)), name, fontsize=8, color="0.25", ha="center", va="center", zorder=6)
    c = scene.contacts * mm
    for i, (p, k) in enumerate(zip(c, scene.numbers)):
        lim = k == scene.limiting_contact
        ax.scatter(*p, s=60 if lim else 25, color=COLORS["limiting" if lim else "fingertip"][:3], depthshade=False,
                   edgecolors="k", linewidths=0.6, zorder=5)
        r = scene.radius[i] * mm
        above = p + scene.normals[i] * r + np.array([0.0, 0.0, 1.5 * r])  # over the fingertip
        text = scene.label(k) + (f"\nlimiting: {scene.limiting_kind.replace('_', ' ')}" if lim else "")
        ax.text(*above, text, fontsize=8.5, color="darkred" if lim else "k", ha="center", va="bottom", zorder=6)
    for name, axis in zip("xyz", (ax.set_xlabel, ax.set_ylabel, ax.set_zlabel)):
        axis(f"{name} [mm]", fontsize=8, labelpad=-2)
    ax.tick_params(labelsize=7, pad=0)
    handles = [
        Patch(color=COLORS["object"], label="object" if scene.has_mesh else "object (contacts' hull: no mesh)"),
        Patch(color=COLORS["fingertip"], label="fingertip (pressed in by its initial deformation)"),
        Patch(color=COLORS["limiting"], label="fingertip of the limiting boundary"),
        Patch(color=COLORS["cone"], label="friction cone (forces on the object)"),
        Line2D([], [], color=COLORS["normal"], lw=1.5, label="outward normal"),
    ]
    if scene.part("ghost") is not None:
        handles.insert(1, Line2D([], [], color=COLORS["ghost"][:3], ls="--", lw=1.5,
                                 label=f"object at the least-energy pose on that boundary (motion x{scene.magnification:g})"))
        handles.insert(2, Line2D([], [], color="0.25", lw=1.2, label="object axes at the centre of mass"))
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle(plain_text(title) if title else _grasp_title(scene), fontsize=10.5)
    fig.subplots_adjust(left=0.0, right=1.0, top=0.93, bottom=0.15)
    return fig


def _set_view(ax, scene, view) -> None:
    """A cube of axes (mm) around every part, seen from ``view`` (elevation, azimuth)."""
    bounds = np.concatenate([np.asarray(p.mesh.bounds) for p in scene.parts]) * 1e3
    lo, hi = bounds.min(0), bounds.max(0)
    centre, half = (hi + lo) / 2, (hi - lo).max() / 2 * 1.02
    for set_lim, x in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        set_lim(x - half, x + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.1)
    ax.view_init(*view)


_LIT = ("object", "ghost", "link")  # parts drawn lit: the shapes; fingertips, cones, arrows keep their colour


def _draw_meshes(ax, scene, view) -> None:
    """Every part's drawn mesh, the object's axes, its sharp edges and outline (at the
    ghost pose too, dashed). ``ax`` already has its limits and view (`_set_view`): the
    outline depends on them."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    from jaxgrasp.plots._drawing import light_direction, polylines, shaded_colors, silhouette_edges
    from jaxgrasp.plots._scene import COLORS

    mm, light = 1e3, light_direction(*view)
    tris, colors = [], []
    for p in scene.parts:
        tris.append(np.asarray(p.drawn.triangles) * mm)
        lit = p.role in _LIT
        colors.append(shaded_colors(p.drawn, p.color, light) if lit else np.tile(p.color, (len(p.drawn.faces), 1)))
    ax.add_collection3d(Poly3DCollection(np.concatenate(tris), facecolors=np.concatenate(colors), linewidths=0,
                                         zorder=1), autolim=False)
    seen_in_m = ax.get_proj() @ np.diag([mm, mm, mm, 1.0])  # the axes are in mm, the meshes in m
    lines = np.concatenate([scene.object_edges, silhouette_edges(scene.part("object").drawn, seen_in_m)]) * mm
    # autolim=False: the limits are set, and matplotlib's autolim fails on no lines (a smooth mesh has no sharp edge)
    ax.add_collection3d(Line3DCollection(polylines(lines), colors="0.25", linewidths=0.9, zorder=2), autolim=False)
    ax.add_collection3d(Line3DCollection(scene.axes * mm, colors="0.25", linewidths=1.2, zorder=2), autolim=False)
    ghost = scene.part("ghost")
    if ghost is not None:
        dashed = np.concatenate([scene.ghost_edges, silhouette_edges(ghost.drawn, seen_in_m), scene.ghost_axes]) * mm
        ax.add_collection3d(Line3DCollection(polylines(dashed), colors=[COLORS["ghost"][:3]], linewidths=1.4,
                                             linestyles="--", zorder=3), autolim=False)


def _grasp_title(scene) -> str:
    """``stable: value 0.2638 mJ, limited by slip of contact 0`` and the ghost's factor."""
    line = f"{scene.status}: value {scene.value * J_TO_MJ:.4g} mJ"
    if scene.limiting_kind is None:
        return line + " (no limiting boundary)"
    kind = scene.limiting_kind.replace("_", " ")
    return (f"{line}, limited by {kind} of {scene.label(scene.limiting_contact)}\n"
            f"ghost: the object at the least-energy pose on that boundary, motion magnified x{scene.magnification:g}")
