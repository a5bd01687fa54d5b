"""Analyses built on the engine: parameter sweeps, gradient tuning, the Ferrari-Canny epsilon,
the robust value under uncertainty.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.analysis._epsilon import EpsilonResult, epsilon
    from jaxgrasp.analysis._robust import RobustBatch, RobustResult, RobustStatus, perturbed, robust, robust_batch
    from jaxgrasp.analysis._sweep import PARAMETERS, SweepResult, sweep
    from jaxgrasp.analysis._tune import TuneResult, tune
    from jaxgrasp.analysis._tune_status import TuneStatus
    from jaxgrasp.analysis._uncertainty import Uncertainty, parse_spec

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.analysis._epsilon import prefetch_qhull
    from jaxgrasp.analysis._limits import (
        MAX_GRID_POINTS,
        MAX_ROBUST_SAMPLES,
        MAX_TUNE_ITERATIONS,
        METHODS,
        ROBUST_SAMPLES_WHAT,
        TUNE_ITERATIONS_WHAT,
    )
    from jaxgrasp.analysis._sweep import check_inputs, grid_grasp
    from jaxgrasp.analysis._tune_drivers import run_search
    from jaxgrasp.analysis._tune_spec import parse_param

__all__ = [
    "sweep",
    "SweepResult",
    "PARAMETERS",
    "tune",
    "TuneResult",
    "TuneStatus",
    "epsilon",
    "EpsilonResult",
    "robust",
    "robust_batch",
    "perturbed",
    "Uncertainty",
    "parse_spec",
    "RobustResult",
    "RobustBatch",
    "RobustStatus",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
