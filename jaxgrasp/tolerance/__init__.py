"""The energy-tolerance method (Tsuji et al., eq. 1): from a grasp's problems to its evaluation.

The 1 + 2N problems of a grasp (the equilibrium, and a slip and a force-limit boundary
per contact; Sec. VI), their starts, settling of stalled lanes, the verdict (value,
status, limiting boundary), the minimum energies with their envelope-theorem
derivatives, and the [`Evaluation`][jaxgrasp.Evaluation] result with its [`GraspStatus`][jaxgrasp.GraspStatus]. Running
it over many grasps, compiled and sharded, is `jaxgrasp.engine`'s job.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages and for the studies in ``experiments/``, not promised (the
faces' convention: ``docs/development.md``, "Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.tolerance._envelope import envelope_energy, soft_minimum
    from jaxgrasp.tolerance._options import EvaluateOptions
    from jaxgrasp.tolerance._problems import Problems
    from jaxgrasp.tolerance._result import Evaluation
    from jaxgrasp.tolerance._status import GraspStatus
    from jaxgrasp.tolerance._verdict import evaluations_of

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.tolerance._problems import batch_data, problems_treedef
    from jaxgrasp.tolerance._result import EVALUATION_TREE, FIELDS, SUMMARY_FIELDS, SummaryNames
    from jaxgrasp.tolerance._settle import needs_settling
    from jaxgrasp.tolerance._stages import depend_on, finish_problems, settled_equilibrium, solve_stage, unsolved
    from jaxgrasp.tolerance._starts import LaneStarts, boundary_starts, equilibrium_starts
    from jaxgrasp.tolerance._verdict import split_temperature

    # For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
    from jaxgrasp.tolerance._problems import constraints, lane_problem, objective, objective_and_constraints, problem_data
    from jaxgrasp.tolerance._stages import SAME_POINT, first_wave_lanes, rest_needed

__all__ = [
    "EvaluateOptions",
    "Evaluation",
    "Problems",
    "GraspStatus",
    "evaluations_of",
    "envelope_energy",
    "soft_minimum",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
