"""The simulation protocols by name, with their settings in one table.

* ``"jaxgrasp"``: jaxgrasp's own (`jaxgrasp.simulation._simulate`): the fingertips as
  fixed spheres calibrated to eq. 4, the grasp's friction, a hold under gravity, the six
  axes and the energy kicks. A hand grasp is simulated as its fingertip contacts.
* ``"dexgraspbench"``: DexGraspBench's test of a hand grasp (Chen et al., BODex / the
  DexGraspBench benchmark), the whole hand in MuJoCo (`jaxgrasp.simulation._hand_trials`);
  `DEXGRASPBENCH` holds its settings, read from the benchmark's own source:
  ``src/util/hand_util.py`` (``HOMjSpec``: timestep, integrator, impratio, gravity off,
  elliptic cones, noslip iterations, condim and friction of every geom, the hand geoms'
  ``solref``/``solimp``), ``src/task/eval_func/base.py`` (``_control_hand_with_interp``:
  10 x 10 steps per stage; the penetration check at the pregrasp),
  ``src/task/eval_func/fc_mocap.py`` (the six directions, the force ``10 m``, 10 x 50
  steps, a fresh reset per direction) and ``config/task/eval.yaml`` (object mass,
  friction, thresholds): files of the repositories DexGrasp-TH/DexGraspBench and
  Mingrui-Yu/DexGraspBench on GitHub.
"""

from __future__ import annotations

import math

from jaxgrasp.model import GraspValueError

__all__ = ["DEXGRASPBENCH", "PROTOCOLS", "check_protocol"]

DEXGRASPBENCH = {
    "timestep_s": 0.004,
    "integrator": "implicitfast",
    "cone": "elliptic",
    "impratio": 10.0,
    "noslip_iterations": 2,
    "gravity": False,
    "condim": 4,
    "friction_sliding": 0.6,
    "friction_torsional_m": 0.02,
    "hand_solref": (0.005, 1.0),
    "hand_solimp": (0.5, 0.99, 0.0001),
    "default_object_mass_kg": 0.1,
    "stage_steps": (10, 10),
    "disturbance_acceleration_m_s2": 10.0,
    "disturbance_steps": (10, 50),
    "six_axis_tolerance_m": 0.05,
    "six_axis_tolerance_rad": math.radians(15.0),
    "max_penetration_m": 0.01,
}
"""DexGraspBench's settings (module doc: where each is read). ``stage_steps``: ``(outer,
inner)``, the hand's targets moved in ``outer`` equal steps from one stage's to the next,
each held for ``inner`` MuJoCo steps (pregrasp -> grasp, then grasp -> squeeze);
``disturbance_steps``: the force held for ``outer x inner`` steps, the object's
pose checked after each ``inner``; ``hand_solref``/``hand_solimp``: set on every geom of
the hand (the object's keep MuJoCo's defaults, mixed with them as MuJoCo mixes a pair's);
``max_penetration_m``: a hand that overlaps the object (or itself) more than this at the
pregrasp fails."""

PROTOCOLS = ("jaxgrasp", "dexgraspbench")
"""The protocols `check_protocol` knows."""


def check_protocol(name) -> str:
    """``name`` if it is one of `PROTOCOLS`; a one-line error otherwise."""
    if not isinstance(name, str) or name not in PROTOCOLS:
        raise GraspValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {name!r}")
    return name
