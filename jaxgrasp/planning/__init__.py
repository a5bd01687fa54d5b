"""Planning: finding the grasps of a meshed object that tolerate the most energy.

[`plan`][jaxgrasp.plan] draws candidates on the mesh, keeps those the paper's model describes (the
contact rules of `jaxgrasp.surface`), evaluates them in batches, refines the best by
surface-constrained gradient tuning and ranks them ([`PlanResult`][jaxgrasp.planning.PlanResult]), saying what it
does on the ``"jaxgrasp"`` logger (`PlanProgress`).

``__all__`` lists the names promised to users. The names imported below the comment
"For jaxgrasp's other packages" are what the library's other packages use from here
(they import from this face, never from its private modules); they are not in
``__all__`` and not promised to users.
The names imported below the comment "For the studies in experiments/" are the
instruments the lab's scripts use (stages, internals); they are not in ``__all__`` and not
promised to users either.
"""

from jaxgrasp.planning._plan import SAMPLERS, plan
from jaxgrasp.planning._progress import PlanProgress
from jaxgrasp.planning._result import PlanResult, PlanStatus

# For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
from jaxgrasp.planning._plan import check_plan

# For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
from jaxgrasp.planning._plan import CHUNK, draw_valid, grasps_of, setup

__all__ = ["plan", "PlanResult", "PlanStatus", "PlanProgress", "SAMPLERS"]
