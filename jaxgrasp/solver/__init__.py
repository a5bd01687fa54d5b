"""A batched augmented-Lagrangian solver for small smooth constrained problems.

It knows nothing of grasps: a `Problem` is an objective with equality and
inequality rows; `solve` runs one lane of it, `solve_lanes` many lanes as a
work queue. Its statuses are [`LaneStatus`][jaxgrasp.solver.LaneStatus] (a `jaxgrasp.base.Coded`).

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages and for the studies in ``experiments/``, not promised (the
faces' convention: ``docs/development.md``, "Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.solver._lanes import Held, solve_lane_batches, solve_lanes
    from jaxgrasp.solver._solver import FirstOrder, Problem, SolverOptions, SolverResult, solve
    from jaxgrasp.solver._status import LaneStatus

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.solver._dense import eigh as serial_eigh, solve as dense_solve
    from jaxgrasp.solver._rows import over_rows, put_rows
    from jaxgrasp.solver._solver import kkt_tol

    # For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
    from jaxgrasp.solver._direction import eigen_direction, ldl_direction
    from jaxgrasp.solver._solver import (
        as_problem,
        augmented_lagrangian,
        first_order,
        init,
        initial_multiplier,
        lagrangian_hessian,
        line_search,
        merit,
        penalty_terms,
        phi_hessian,
        propose,
        step,
        tolerances,
        violation_slope,
    )

__all__ = [
    "Problem",
    "FirstOrder",
    "SolverOptions",
    "SolverResult",
    "solve",
    "solve_lanes",
    "solve_lane_batches",
    "Held",
    "LaneStatus",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
