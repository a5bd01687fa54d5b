"""The limits of one simulation run (`jaxgrasp.simulation._options` holds a run to them), in
plain Python: the command line's help states them without loading JAX
(`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["MAX_SIMULATED_S", "MAX_STEPS", "TIMESTEP_FRACTION"]

TIMESTEP_FRACTION = 0.01
"""A given timestep is at most this fraction of the shortest trial (at least 100 steps each)."""

MAX_SIMULATED_S = 600.0
"""The most simulated time (in seconds) all trials of one run may add up to."""

MAX_STEPS = 2_000_000
"""The most MuJoCo steps (simulated time / timestep) one run may take."""
