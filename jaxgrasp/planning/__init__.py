"""Planning: finding the grasps of a meshed object that tolerate the most energy.

[`plan`][jaxgrasp.plan] draws candidates on the mesh, keeps those the paper's model describes (the
contact rules of `jaxgrasp.surface`), evaluates them in batches, refines the best by
surface-constrained gradient tuning and ranks them ([`PlanResult`][jaxgrasp.planning.PlanResult]), saying what it
does on the ``"jaxgrasp"`` logger (`PlanProgress`).

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages and for the studies in ``experiments/``, not promised (the
faces' convention: ``docs/development.md``, "Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.planning._limits import SAMPLERS
    from jaxgrasp.planning._plan import plan
    from jaxgrasp.planning._progress import PlanProgress
    from jaxgrasp.planning._hand_result import HAND_RESULT_COLUMNS, HandPlanResult
    from jaxgrasp.planning._result import PlanResult, PlanStatus

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.planning._limits import (
        MAX_FINGERS,
        MAX_PLAN_REFINE,
        MAX_PLAN_SAMPLES,
        PLAN_REFINE_WHAT,
        PLAN_SAMPLES_WHAT,
    )
    from jaxgrasp.planning._hand_plan import HAND_SAMPLES, OBJECTIVES, check_hand_plan
    from jaxgrasp.planning._plan import check_plan

    # For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
    from jaxgrasp.planning._plan import CHUNK, draw_valid, grasps_of, setup
    from jaxgrasp.planning._hand_close import CloseSettings
    from jaxgrasp.planning._hand_plan import plan_hand

__all__ = ["plan", "PlanResult", "HandPlanResult", "PlanStatus", "PlanProgress", "SAMPLERS"]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
