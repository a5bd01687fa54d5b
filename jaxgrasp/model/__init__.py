"""The physical model of a soft-fingertip grasp: its fields, the Grasp, the potential field.

The table of grasp fields and their units (:data:`FIELDS`), the :class:`Grasp` pytree and
its validation (:class:`GraspValueError`), the conversion to internal units
(:func:`model_params`), the potential energy and constraint margins of a grasp (Tsuji et
al., eq. 3-21), and the model's codes (:class:`BoundaryKind`, :class:`Constraint`).
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
