"""A second opinion from a physics engine: the grasp in MuJoCo (optional extra ``jaxgrasp[sim]``).

Under the ``"jaxgrasp"`` protocol (`_protocols`), [`simulate`][jaxgrasp.simulate] builds the grasp as a MuJoCo scene with the paper's fingertips calibrated
into it (`_scene`), holds it under gravity, disturbs it along six axes and kicks it
with kinetic energies that are multiples of the evaluation value (`_trials`), and
returns a [`SimulationResult`][jaxgrasp.simulation.SimulationResult] (`_result`); its options are checked before
anything is evaluated (`_options`). Under ``"dexgraspbench"`` it puts the whole hand of a
[`HandGrasp`][jaxgrasp.hands.HandGrasp] in MuJoCo with the object's convex pieces
(`_hand_scene`, `_convex`), squeezes it to the model's normal forces and pushes the object
along six axes (`_hand_trials`, `_hand_simulate`). MuJoCo is imported only when
[`simulate`][jaxgrasp.simulate] runs.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.simulation._options import DEFAULTS
    from jaxgrasp.simulation._protocols import DEXGRASPBENCH, PROTOCOLS
    from jaxgrasp.simulation._result import AXES, DIRECTIONS, SimulationResult, SimulationStatus, Trial
    from jaxgrasp.simulation._simulate import simulate

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.simulation._limits import (MAX_KICK_SCALE, MAX_KICK_TRAVEL, MAX_SIMULATED_S, MAX_STEPS,
                                             TIMESTEP_FRACTION)
    from jaxgrasp.simulation._options import check_options
    from jaxgrasp.simulation._protocols import check_protocol
    from jaxgrasp.simulation._scene import load_mujoco

__all__ = ["AXES", "DEFAULTS", "DEXGRASPBENCH", "DIRECTIONS", "PROTOCOLS", "SimulationResult", "SimulationStatus",
           "Trial", "simulate"]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
