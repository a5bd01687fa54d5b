"""Analyses built on the engine: parameter sweeps, gradient tuning, the Ferrari-Canny epsilon.
"""

from jaxgrasp.analysis._sweep import sweep, SweepResult, PARAMETERS
from jaxgrasp.analysis._tune import tune, TuneResult
from jaxgrasp.analysis._tune_status import TuneStatus
from jaxgrasp.analysis._epsilon import epsilon, EpsilonResult

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
