"""Pictures (matplotlib, Agg backend): sweep and ranking plots, the 3-D scene of a grasp
and the way it fails (with a hand's links: `plot_hand_grasp`), the value over the
iterations of a tuning.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages and for the studies in ``experiments/``, not promised (the
faces' convention: ``docs/development.md``, "Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.plots._plots import draw_scene, plot_grasp, plot_max, plot_max_over, plot_ranking, plot_sweep, save_figure
    from jaxgrasp.plots._hand import hand_scene, plot_hand_grasp
    from jaxgrasp.plots._scene import grasp_scene
    from jaxgrasp.plots._tune_plot import plot_history

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.plots._trials_plot import plot_trials
    from jaxgrasp.plots._tune_plot import plot_hand_history

    # For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
    from jaxgrasp.plots._plots import new_figure

__all__ = [
    "plot_sweep",
    "plot_max",
    "plot_max_over",
    "plot_ranking",
    "plot_grasp",
    "draw_scene",
    "save_figure",
    "grasp_scene",
    "plot_hand_grasp",
    "hand_scene",
    "plot_history",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
