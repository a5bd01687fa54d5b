"""The limits of one simulation run (`jaxgrasp.simulation._options` holds a run to them), in
plain Python: the command line's help and its ``--scales`` check state them without loading
JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["DIVERGENCE_WARNINGS", "MAX_KICK_SCALE", "MAX_KICK_TRAVEL", "MAX_SIMULATED_S", "MAX_STEPS",
           "TIMESTEP_FRACTION"]

TIMESTEP_FRACTION = 0.01
"""A given timestep is at most this fraction of the shortest trial (at least 100 steps each)."""

MAX_SIMULATED_S = 600.0
"""The most simulated time (in seconds) all trials of one run may add up to."""

MAX_STEPS = 2_000_000
"""The most MuJoCo steps (simulated time / timestep) one run may take."""

MAX_KICK_TRAVEL = 1.0
"""The farthest a kick may carry the object's contact points in one timestep, in fingertip
radii (the smallest fingertip's).

MuJoCo finds contacts between steps: a surface point that moves more than a fingertip's
radius in one step passes through the fingertip or lands deep inside it, and the contact
force there is no longer the calibrated spring's (eq. 4) but whatever the penetration
makes it. Beyond that the simulator does not integrate the kick; far beyond it the contact
forces overflow MuJoCo's limits and it resets the state, which then looks held (the guide's
page on simulation gives the prism's numbers). A kick's initial speed
at its fastest contact point is ``|v| + |w| R`` (``v`` the linear velocity, ``w`` the
angular one, ``R`` the contacts' largest distance from the centre of mass), and
`jaxgrasp.simulation._options.check_kick_travel` refuses a scale whose kick moves that
point more than ``MAX_KICK_TRAVEL * r_min`` per timestep, once the scene (its timestep)
is known and before any trial runs."""

MAX_KICK_SCALE = 1e6
"""The largest kick scale ``s`` (kinetic energy over the evaluation value), checked with
the options, before anything is evaluated (the command: before JAX is loaded).

A scale of 1 is the energy that takes the grasp to its slip boundary; ``s = 10^6`` is a
kick of a thousand times that one's speed, far past any slip. The speed it gives depends
on the value and the mass, known only later, so `MAX_KICK_TRAVEL` is the limit that
decides whether a kick can be integrated; this one refuses at once the scales no grasp
could use (``1e20``, ``1e300``: initial speeds of thousands of km/s and more)."""

DIVERGENCE_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")
"""MuJoCo's warnings that it met a position, velocity or acceleration beyond its limits
(NaN, infinite or above ``mjMAXVAL``, 1e10) and reset the state: a trial that raises any
of them diverged (`jaxgrasp.simulation._trials.Runner.run`)."""
