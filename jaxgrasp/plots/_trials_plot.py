"""The plot of [`jaxgrasp.simulate`][jaxgrasp.simulate]'s trials: displacement and rotation over time."""

from __future__ import annotations

import numpy as np

__all__ = ["plot_trials"]


def plot_trials(result):
    """A figure with one row per kind of trial (hold, six-axis, kicks) and two columns: the
    object's displacement from the trial's start (mm) and its rotation (degrees) over time
    (s), one line per trial, dashed where the trial failed. ``result``: a
    [`SimulationResult`][jaxgrasp.simulation.SimulationResult] that was simulated."""
    import matplotlib.pyplot as plt

    groups = [("hold", [result.hold] if result.hold is not None else []), ("six-axis", list(result.six_axis)),
              ("energy kicks", list(result.kicks))]
    groups = [(name, trials) for name, trials in groups if trials]
    fig, axes = plt.subplots(len(groups), 2, figsize=(10, 2.8 * len(groups)), squeeze=False)
    for row, (name, trials) in enumerate(groups):
        for trial in trials:
            style = "-" if trial.success else "--"
            t = np.asarray(trial.time_s)
            axes[row, 0].plot(t, 1e3 * np.asarray(trial.displacement_m), style, lw=1, label=trial.label)
            axes[row, 1].plot(t, np.degrees(np.asarray(trial.rotation_rad)), style, lw=1, label=trial.label)
        axes[row, 0].set_ylabel(f"{name}\ndisplacement, mm")
        axes[row, 1].set_ylabel("rotation, deg")
        if len(trials) <= 12:
            axes[row, 1].legend(fontsize=6, ncol=2 if len(trials) > 6 else 1)
    for ax in axes[-1]:
        ax.set_xlabel("time, s")
    ok = result.six_axis_success
    fig.suptitle(f"MuJoCo: value {result.value:.3g} J ({result.grasp_status}); six-axis "
                 f"{'held' if ok else 'failed'}; dashed: failed trials", fontsize=10)
    fig.tight_layout()
    return fig
