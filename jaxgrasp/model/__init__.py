"""The physical model of a soft-fingertip grasp: its fields, the Grasp, the potential field.

The table of grasp fields and their units (`FIELDS`), the [`Grasp`][jaxgrasp.Grasp] pytree and
its validation ([`GraspValueError`][jaxgrasp.GraspValueError]; [`check`][jaxgrasp.check], the same rules as array code
for traced and batched grasps), the conversion to internal units
(`model_params`), the potential energy and constraint margins of a grasp (Tsuji et
al., eq. 3-21), and the model's codes ([`BoundaryKind`][jaxgrasp.model.BoundaryKind], `Constraint`).

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.model._check import CheckReason, GraspCheck, check
    from jaxgrasp.model._codes import NO_BOUNDARY, BoundaryKind, Constraint
    from jaxgrasp.model._fields import FIELD, FIELDS, STANDARD_GRAVITY, Field
    from jaxgrasp.model._grasp import Grasp, stack
    from jaxgrasp.model._potential import ModelParams, constraint_margins, model_params, potential_energy
    from jaxgrasp.model._validation import GraspValueError, check_grasp_inputs

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.model._fields import (
        DEFAULT_GRAVITY,
        DEFAULT_MASS,
        FINGERTIP,
        MAX_CONTACTS,
        NAMES,
        SWEEPABLE,
        TUNABLE,
    )
    from jaxgrasp.model._potential import (
        KINDS,
        contact_gradients,
        contact_hessians,
        contact_kinematics,
        energy_and_margins,
        energy_of,
        energy_scale,
        kinematics_curvature,
        kinematics_jacobian,
        margins_of,
        rotation_hessian_along,
        rotation_matrix,
        slip_torsion,
    )
    from jaxgrasp.model._units import (
        LENGTH_UNITS,
        MAX_CONTACT_DISTANCE,
        MAX_FINGERTIP_RADIUS,
        MAX_OBJECT_SIZE,
        MJ_TO_J,
        M_TO_MM,
    )
    from jaxgrasp.model._validation import (
        COINCIDENT_DISTANCE,
        MAX_COORDINATE,
        MAX_FRICTION,
        MAX_LOAD_RATIO,
        as_float_array,
        check_batch_inputs,
        check_corners,
        counted,
        format_value,
        inward_contacts,
    )

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

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
