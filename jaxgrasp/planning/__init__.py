"""Planning: finding the grasps of a meshed object that tolerate the most energy.

:func:`plan` draws candidates on the mesh, keeps those the paper's model describes (the
contact rules of :mod:`jaxgrasp.surface`), evaluates them in batches, refines the best by
surface-constrained gradient tuning and ranks them (:class:`PlanResult`), saying what it
does on the ``"jaxgrasp"`` logger (:class:`PlanProgress`).
"""

from jaxgrasp.planning._plan import SAMPLERS, plan
from jaxgrasp.planning._progress import PlanProgress
from jaxgrasp.planning._result import PlanResult, PlanStatus

__all__ = ["plan", "PlanResult", "PlanStatus", "PlanProgress", "SAMPLERS"]
