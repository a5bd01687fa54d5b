"""The two grasps of the paper's numerical examples (Tsuji et al., Sec. VII), SI units.

Both use the paper's fingertips: hemisphere radius 0.025 m, static friction
coefficient 0.5, normal-force limit 15 N. The object frame has its origin at the
object's centre of mass.

Each preset at its defaults is the example file of the same name (``presets.cube()`` is
``examples/cube.toml``, ``presets.prism()`` is ``examples/prism.toml``), so ``--preset
cube`` and ``examples/cube.toml`` give the same answer. The defaults are the first point
of the paper's sweeps (E = 2e5 Pa of 2e5 to 1e6, Figs. 6 and 7) at 2 mm, weightless.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from jaxgrasp.model import STANDARD_GRAVITY  # loads jaxgrasp.model._fields alone: PRESETS needs no JAX

if TYPE_CHECKING:
    from jaxgrasp.model import Grasp

__all__ = ["cube", "prism", "PRESETS", "FINGERTIP_RADIUS", "FRICTION", "MAX_FORCE", "SIDE"]

FINGERTIP_RADIUS = 0.025
"""Fingertip hemisphere radius, m."""
FRICTION = 0.5
"""Static friction coefficient, dimensionless."""
MAX_FORCE = 15.0
"""Upper limit of each normal contact force, N."""
SIDE = 0.1
"""Side length of the cube and of the prism's triangle (and the prism's length), m."""


def cube(
    young_modulus=2e5,
    initial_deformation=2e-3,
    mass=0.0,
    *,
    gravity=STANDARD_GRAVITY,
) -> Grasp:
    """Cube of side 0.1 m held by 2 fingertips at the centres of two opposite faces.

    Contacts at ``(+0.05, 0, 0)`` and ``(-0.05, 0, 0)`` m with outward normals
    ``(+1, 0, 0)`` and ``(-1, 0, 0)``.

    Args:
        young_modulus: fingertip Young's modulus, Pa (paper: 2e5 to 1e6).
        initial_deformation: initial deformation of each fingertip, m (paper: 1e-3 to
            5e-3); a scalar or one value per contact.
        mass: object mass, kg (paper: 0).
        gravity: gravitational acceleration, m/s^2, object frame.
    """
    h = SIDE / 2
    positions = [[h, 0.0, 0.0], [-h, 0.0, 0.0]]
    normals = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]
    return _paper_grasp(positions, normals, young_modulus, initial_deformation, mass, gravity)


def prism(
    young_modulus=2e5,
    initial_deformation=2e-3,
    mass=0.0,
    *,
    gravity=STANDARD_GRAVITY,
) -> Grasp:
    """Equilateral triangular prism held by 3 fingertips at the centres of its rectangular faces.

    Triangle side 0.1 m, prism length 0.1 m, axis along z (so the default gravity acts
    along the axis). The contacts lie in the plane ``z = 0`` at distance
    ``0.1 / (2 sqrt 3)`` m (the triangle's inradius, about 0.0289 m) from the axis, at
    angles 0, 120 and 240 degrees; the outward normals point radially outward:
    ``(1, 0, 0)``, ``(-1/2, +sqrt(3)/2, 0)``, ``(-1/2, -sqrt(3)/2, 0)``. The
    coordinates are written in closed form (``y = +-0.025`` m exactly) rather than via
    ``cos``/``sin`` so files can state them exactly.

    Args:
        young_modulus: fingertip Young's modulus, Pa (paper: 2e5 to 1e6).
        initial_deformation: initial deformation of each fingertip, m; a scalar or one
            value per contact.
        mass: object mass, kg.
        gravity: gravitational acceleration, m/s^2, object frame.
    """
    a = SIDE / (2.0 * math.sqrt(3.0))  # inradius, m
    s = math.sqrt(3.0) / 2.0
    positions = [[a, 0.0, 0.0], [-a / 2, SIDE / 4, 0.0], [-a / 2, -SIDE / 4, 0.0]]
    normals = [[1.0, 0.0, 0.0], [-0.5, s, 0.0], [-0.5, -s, 0.0]]
    return _paper_grasp(positions, normals, young_modulus, initial_deformation, mass, gravity)


def _paper_grasp(positions, normals, young_modulus, initial_deformation, mass, gravity) -> Grasp:
    """A grasp with the paper's fingertips (radius, friction, force limit)."""
    from jaxgrasp.model import Grasp  # here: the names of this module need no JAX

    return Grasp.create(
        positions=positions,
        normals=normals,
        initial_deformation=initial_deformation,
        radius=FINGERTIP_RADIUS,
        young_modulus=young_modulus,
        friction=FRICTION,
        max_force=MAX_FORCE,
        mass=mass,
        gravity=gravity,
    )


PRESETS = {"cube": cube, "prism": prism}
"""Preset grasps by name."""
