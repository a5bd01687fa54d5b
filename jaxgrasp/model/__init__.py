"""The physical model of a soft-fingertip grasp: its fields, the Grasp, the potential field.

The table of grasp fields and their units (:data:`FIELDS`), the :class:`Grasp` pytree and
its validation (:class:`GraspValueError`; :func:`check`, the same rules as array code
for traced and batched grasps), the conversion to internal units
(:func:`model_params`), the potential energy and constraint margins of a grasp (Tsuji et
al., eq. 3-21), and the model's codes (:class:`BoundaryKind`, :class:`Constraint`).
"""

from jaxgrasp.model._check import CheckReason, GraspCheck, check
from jaxgrasp.model._codes import NO_BOUNDARY, BoundaryKind, Constraint
from jaxgrasp.model._fields import FIELD, FIELDS, Field
from jaxgrasp.model._grasp import STANDARD_GRAVITY, Grasp, stack
from jaxgrasp.model._potential import ModelParams, constraint_margins, model_params, potential_energy
from jaxgrasp.model._validation import GraspValueError, check_grasp_inputs

__all__ = [
    "Grasp",
    "stack",
    "STANDARD_GRAVITY",
    "Field",
    "FIELDS",
    "FIELD",
    "GraspValueError",
    "check_grasp_inputs",
    "check",
    "GraspCheck",
    "CheckReason",
    "ModelParams",
    "model_params",
    "potential_energy",
    "constraint_margins",
    "BoundaryKind",
    "Constraint",
    "NO_BOUNDARY",
]
