"""Analyses built on the engine: parameter sweeps, gradient tuning, the Ferrari-Canny epsilon,
the robust value under uncertainty.
"""

from jaxgrasp.analysis._epsilon import EpsilonResult, epsilon
from jaxgrasp.analysis._robust import RobustBatch, RobustResult, RobustStatus, perturbed, robust, robust_batch
from jaxgrasp.analysis._sweep import PARAMETERS, SweepResult, sweep
from jaxgrasp.analysis._tune import TuneResult, tune
from jaxgrasp.analysis._tune_status import TuneStatus
from jaxgrasp.analysis._uncertainty import Uncertainty, parse_spec

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
