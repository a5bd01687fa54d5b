"""A batched augmented-Lagrangian solver for small smooth constrained problems.

It knows nothing of grasps: a :class:`Problem` is an objective with equality and
inequality rows; :func:`solve` runs one lane of it, :func:`solve_lanes` many lanes as a
work queue. Its statuses are :class:`LaneStatus`; :class:`Coded` is the base of every
named integer code of jaxgrasp.
"""

from jaxgrasp.solver._lanes import Held, solve_lane_batches, solve_lanes
from jaxgrasp.solver._solver import FirstOrder, Problem, SolverOptions, SolverResult, solve
from jaxgrasp.solver._status import Coded, LaneStatus

__all__ = [
    "Problem",
    "FirstOrder",
    "SolverOptions",
    "SolverResult",
    "solve",
    "solve_lanes",
    "solve_lane_batches",
    "Held",
    "Coded",
    "LaneStatus",
]
