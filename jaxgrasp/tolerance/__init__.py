"""The energy-tolerance method (Tsuji et al., eq. 1): the 1 + 2N problems of a grasp,
their starts, settling, the verdict (value, status, limiting boundary), the
:class:`Evaluation` result and its :class:`GraspStatus`.
"""

from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._result import Evaluation
from jaxgrasp.tolerance._status import GraspStatus
from jaxgrasp.tolerance._verdict import evaluations_of
from jaxgrasp.tolerance._envelope import envelope_energy, soft_minimum

__all__ = [
    "EvaluateOptions",
    "Evaluation",
    "GraspStatus",
    "evaluations_of",
    "envelope_energy",
    "soft_minimum",
]
