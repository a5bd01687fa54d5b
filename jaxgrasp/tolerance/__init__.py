"""The energy-tolerance method (Tsuji et al., eq. 1): from a grasp's problems to its evaluation.

The 1 + 2N problems of a grasp (the equilibrium, and a slip and a force-limit boundary
per contact; Sec. VI), their starts, settling of stalled lanes, the verdict (value,
status, limiting boundary), the minimum energies with their envelope-theorem
derivatives, and the :class:`Evaluation` result with its :class:`GraspStatus`. Running
it over many grasps, compiled and sharded, is :mod:`jaxgrasp.engine`'s job.
"""

from jaxgrasp.tolerance._envelope import envelope_energy, soft_minimum
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import Problems
from jaxgrasp.tolerance._result import Evaluation
from jaxgrasp.tolerance._status import GraspStatus
from jaxgrasp.tolerance._verdict import evaluations_of

__all__ = [
    "EvaluateOptions",
    "Evaluation",
    "Problems",
    "GraspStatus",
    "evaluations_of",
    "envelope_energy",
    "soft_minimum",
]
