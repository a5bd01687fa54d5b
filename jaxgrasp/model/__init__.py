"""The physical model: grasp fields and units, the :class:`Grasp` pytree and its
validation, and the potential field of a soft-fingertip grasp (Tsuji et al., eq. 3-21).
"""

from jaxgrasp.model._grasp import Grasp, stack, STANDARD_GRAVITY
from jaxgrasp.model._fields import Field, FIELDS, FIELD
from jaxgrasp.model._validation import GraspValueError, check_grasp_inputs
from jaxgrasp.model._potential import ModelParams, model_params, potential_energy, constraint_margins
from jaxgrasp.model._codes import BoundaryKind, Constraint, NO_BOUNDARY

__all__ = [
    "Grasp",
    "stack",
    "STANDARD_GRAVITY",
    "Field",
    "FIELDS",
    "FIELD",
    "GraspValueError",
    "check_grasp_inputs",
    "ModelParams",
    "model_params",
    "potential_energy",
    "constraint_margins",
    "BoundaryKind",
    "Constraint",
    "NO_BOUNDARY",
]
