"""Analyses built on the engine: parameter sweeps, gradient tuning, the Ferrari-Canny epsilon.
"""

from jaxgrasp.analysis._epsilon import EpsilonResult, epsilon
from jaxgrasp.analysis._sweep import PARAMETERS, SweepResult, sweep
from jaxgrasp.analysis._tune import TuneResult, tune
from jaxgrasp.analysis._tune_status import TuneStatus

__all__ = [
    "sweep",
    "SweepResult",
    "PARAMETERS",
    "tune",
    "TuneResult",
    "TuneStatus",
    "epsilon",
    "EpsilonResult",
]
