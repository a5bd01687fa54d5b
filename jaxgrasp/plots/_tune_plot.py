"""The value over the iterations of [`jaxgrasp.tune`][jaxgrasp.tune]."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from jaxgrasp.analysis import TuneResult
from jaxgrasp.model import MJ_TO_J
from jaxgrasp.plots._plots import VALUE_LABEL, _save, plain_text
from jaxgrasp.tolerance import GraspStatus

__all__ = ["plot_history", "plot_hand_history"]


def plot_history(result: TuneResult, path=None, *, title: str | None = None):
    """Plot the value over the iterations of [`jaxgrasp.tune`][jaxgrasp.tune] (mJ); save to ``path`` if given.

    Returns the matplotlib ``Figure`` (Agg canvas; no display needed). The best value
    so far is drawn as a line, each iterate as a dot (open where its evaluation did not
    converge). A ``path`` is written atomically (`save_figure`):
    never half an image.
    """
    fig = Figure(figsize=(6.0, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    it = np.arange(result.history.size)
    mj = result.history / MJ_TO_J
    ax.plot(it, np.maximum.accumulate(mj), "-", color="C0", label="best so far")
    ok = result.history_status != GraspStatus.NOT_CONVERGED
    ax.plot(it[ok], mj[ok], "o", color="C0", ms=4, label="iterate")
    if np.any(~ok):
        ax.plot(it[~ok], mj[~ok], "o", mfc="none", color="C3", ms=5, label="iterate (not converged)")
    ax.axhline(result.initial_value / MJ_TO_J, color="0.6", lw=0.8, ls="--", label="start")
    ax.set_xlabel("iteration")
    ax.set_ylabel(VALUE_LABEL)
    params = ", ".join(result.params)
    ax.set_title(plain_text(title) if title else f"tuning {params}: {result.initial_value / MJ_TO_J:.4g} → {result.value / MJ_TO_J:.4g} mJ")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    return _save(fig, path)


def plot_hand_history(result, path=None, *, title: str | None = None):
    """Plot the value over the iterations of [`jaxgrasp.tune_hand`][jaxgrasp.tune_hand] (mJ,
    left axis: best so far as a line, each iterate as a dot) and the deepest penetration of
    the hand's other links (mm, right axis; negative: clear); save to ``path`` if given.
    ``result``: a [`HandTuneResult`][jaxgrasp.hands.HandTuneResult]. Returns the ``Figure``."""
    fig = Figure(figsize=(6.0, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    it = np.arange(result.history.size)
    mj = np.asarray(result.history) / MJ_TO_J
    ax.plot(it, np.maximum.accumulate(mj), "-", color="C0", label="best so far")
    ax.plot(it, mj, "o", color="C0", ms=4, label="iterate")
    ax.axhline(result.start_value / MJ_TO_J, color="0.6", lw=0.8, ls="--", label="start")
    depth = ax.twinx()
    depth.plot(it, 1e3 * np.asarray(result.depth_history), ":", color="C3", lw=1.2, label="deepest link (right)")
    depth.set_ylabel("deepest link penetration, mm", color="C3")
    ax.set_xlabel("iteration")
    ax.set_ylabel(VALUE_LABEL)
    ax.set_title(plain_text(title) if title else
                 f"tuning the hand: {result.start_value / MJ_TO_J:.4g} → {result.value / MJ_TO_J:.4g} mJ")
    ax.grid(True, alpha=0.3)
    handles = ax.get_legend_handles_labels()[0] + depth.get_legend_handles_labels()[0]
    ax.legend(handles=handles, loc="lower right", fontsize=8)
    return _save(fig, path)
