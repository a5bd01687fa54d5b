"""A second opinion from a physics engine: the grasp in MuJoCo (optional extra ``jaxgrasp[sim]``).

:func:`simulate` builds the grasp as a MuJoCo scene with the paper's fingertips calibrated
into it (:mod:`._scene`), holds it under gravity, disturbs it along six axes and kicks it
with kinetic energies that are multiples of the evaluation value (:mod:`._trials`), and
returns a :class:`SimulationResult` (:mod:`._result`); its options are checked before
anything is evaluated (:mod:`._options`). MuJoCo is imported only when
:func:`simulate` runs.
"""

from jaxgrasp.simulation._options import DEFAULTS
from jaxgrasp.simulation._result import AXES, DIRECTIONS, SimulationResult, SimulationStatus, Trial
from jaxgrasp.simulation._simulate import simulate

__all__ = ["AXES", "DEFAULTS", "DIRECTIONS", "SimulationResult", "SimulationStatus", "Trial", "simulate"]
