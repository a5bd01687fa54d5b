"""The results of [`jaxgrasp.simulate`][jaxgrasp.simulate]: one [`Trial`][jaxgrasp.simulation.Trial] per simulated test and the
[`SimulationResult`][jaxgrasp.simulation.SimulationResult] that gathers them, frozen dataclasses in SI units."""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxgrasp.base import Coded, json_floats

__all__ = ["AXES", "DIRECTIONS", "SimulationResult", "SimulationStatus", "Trial"]

AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
"""The six disturbance axes of the six-axis test, world (= object model) frame."""

DIRECTIONS = ("least_energy", "random")
"""The kinds of energy-kick direction."""


class SimulationStatus(Coded):
    """Whether [`jaxgrasp.simulate`][jaxgrasp.simulate] ran the simulator, and if not, why.

    ``SIMULATED``: the grasp was simulated (its trials are in the result). ``DIVERGED``:
    it was simulated, but in at least one trial MuJoCo met a state beyond its limits and
    reset it; those trials say ``diverged`` and are never a success (where the hold
    diverged, no other trial is run: there is no settled state to start from).
    ``PENETRATING`` (the ``dexgraspbench`` protocol): the hand overlapped the object or
    itself by more than the protocol's limit at the start, a failure. The others
    name the evaluation's status that kept it out of the simulator: ``UNSTABLE`` and
    ``NOT_CONVERGED`` (simulated only with ``simulate_unstable=True``) and ``INFEASIBLE``
    (never: there is no equilibrium pose to start from and calibrate at).
    """

    SIMULATED = 0, "the grasp was simulated: its trials are in the result"
    UNSTABLE = 1, "the evaluation found the grasp unstable: not simulated (simulate_unstable=True simulates it)"
    INFEASIBLE = 2, "the evaluation found no equilibrium: nothing to start from or calibrate at, never simulated"
    NOT_CONVERGED = 3, (
        "the evaluation did not converge: not simulated (simulate_unstable=True simulates it where its "
        "equilibrium settled)"
    )
    DIVERGED = 4, (
        "the simulator diverged in at least one trial (a state beyond MuJoCo's limits, which it reset): those "
        "trials are marked diverged, never held"
    )
    PENETRATING = 5, (
        "the hand overlaps the object (or itself) at the pregrasp more than the protocol allows: a failure, "
        "not simulated (DexGraspBench's rule)"
    )


@dataclasses.dataclass(frozen=True)
class Trial:
    """One simulated test of a grasp and what the object did.

    Attributes:
        kind: ``"hold"``, ``"six_axis"`` or ``"kick"``.
        success: hold: the object stayed within the hold tolerances; six-axis: it moved
            less than 5 cm and turned less than 15 degrees (DexGraspBench's protocol, the
            limits in ``SimulationResult.parameters``); kick: no fingertip slipped. Never
            where the trial ``diverged``.
        max_displacement_m: largest distance of the centre of mass from where the trial
            started, m.
        max_rotation_rad: largest rotation angle from the orientation the trial started
            with, rad.
        slipped_contact: the first contact (0-based) whose surface slid under its
            fingertip by more than its slip threshold, or ``None``.
        slip_time_s: when it did, s from the trial's start, or ``None``.
        time_s: ``(T,)`` sample times, s.
        displacement_m: ``(T,)`` distance of the centre of mass from its start, m.
        rotation_rad: ``(T,)`` rotation angle from the start, rad.
        max_sliding_m: ``(N,)`` largest sliding of each contact's surface point under its
            fingertip (tangential displacement, or torsion angle times the contact radius), m.
        axis: six-axis trials: ``"+x"`` ... ``"-z"``; else ``None``.
        scale: kicks: ``s``, the kick's kinetic energy over the evaluation value; else ``None``.
        direction: kicks: ``"least_energy"`` or ``"random"``; else ``None``.
        kinetic_energy_J: kicks: the object's initial kinetic energy, J; else ``None``.
        initial_velocity: kicks: ``(6,)`` the object's initial linear velocity (m/s, world
            axes) and angular velocity (rad/s, body axes, as MuJoCo's free joint); else ``None``.
        diverged: MuJoCo met a position, velocity or acceleration beyond its limits (or a
            state that is not finite) and reset the state: the trial stopped there, its
            samples end before it, and it is no success whatever the object did before.
        simulator_warnings: MuJoCo's warnings in the trial, ``{name: count}`` (such as
            ``{"mjWARN_BADQACC": 1}``; empty when none).
    """

    kind: str
    success: bool
    max_displacement_m: float
    max_rotation_rad: float
    slipped_contact: int | None
    slip_time_s: float | None
    time_s: np.ndarray
    displacement_m: np.ndarray
    rotation_rad: np.ndarray
    max_sliding_m: np.ndarray
    axis: str | None = None
    scale: float | None = None
    direction: str | None = None
    kinetic_energy_J: float | None = None
    initial_velocity: np.ndarray | None = None
    diverged: bool = False
    simulator_warnings: dict = dataclasses.field(default_factory=dict)

    @property
    def name(self) -> str:
        """A short name: ``"hold"``, ``"+x"``, ``"least_energy s=0.5"``."""
        if self.kind == "six_axis":
            return str(self.axis)
        if self.kind == "kick":
            return f"{self.direction} s={self.scale:g}"
        return self.kind

    @property
    def label(self) -> str:
        """`name`, and for a diverged trial ``" (diverged)"`` after it (the trials
        picture's legend shows it)."""
        return f"{self.name} (diverged)" if self.diverged else self.name

    def outcome(self, held: str = "held", failed: str = "failed") -> str:
        """``"diverged"``, else ``held`` where the trial succeeded and ``failed`` where not."""
        return "diverged" if self.diverged else held if self.success else failed

    def to_dict(self) -> dict:
        """The trial as JSON-ready numbers (``None`` where a field does not apply)."""
        out = {
            "success": bool(self.success),
            "diverged": bool(self.diverged),
            "simulator_warnings": {str(k): int(v) for k, v in self.simulator_warnings.items()},
            "max_displacement_m": float(self.max_displacement_m),
            "max_rotation_rad": float(self.max_rotation_rad),
            "slipped_contact": None if self.slipped_contact is None else int(self.slipped_contact),
            "slip_time_s": None if self.slip_time_s is None else float(self.slip_time_s),
            "max_sliding_m": [float(x) for x in np.asarray(self.max_sliding_m)],
        }
        if self.kind == "six_axis":
            out["axis"] = self.axis
        if self.kind == "kick":
            out.update(scale=float(self.scale), direction=self.direction, kinetic_energy_J=float(self.kinetic_energy_J),
                       initial_velocity=[float(x) for x in np.asarray(self.initial_velocity)])
        out["time_s"] = [round(float(x), 9) for x in np.asarray(self.time_s)]
        out["displacement_m"] = [float(x) for x in np.asarray(self.displacement_m)]
        out["rotation_rad"] = [float(x) for x in np.asarray(self.rotation_rad)]
        return out


@dataclasses.dataclass(frozen=True)
class SimulationResult:
    """The grasp in MuJoCo: its calibration and the trials ([`jaxgrasp.simulate`][jaxgrasp.simulate]).

    Attributes:
        status: a [`SimulationStatus`][jaxgrasp.simulation.SimulationStatus] (an integer given
            here is taken as its member; [`status_name`][jaxgrasp.simulation.SimulationResult.status_name] its name).
        grasp_status: the evaluation's status name (``'stable'``, ...).
        value: the evaluation value, J (eq. 1).
        reason: why the grasp was not simulated (the evaluation's explanation), or which
            trials diverged and what MuJoCo said (status ``DIVERGED``), or ``""``.
        hold: the hold trial (``None`` when not simulated, and in the ``dexgraspbench``
            protocol, which has none).
        six_axis: the six disturbance trials, in the order of `AXES`.
        kicks: the energy kicks, for each scale: the least-energy direction, then the random ones.
        settled_normal_force_N: ``(N,)`` each fingertip's normal force in the simulator at
            the end of the hold (mean over its last quarter), N (``nan`` when not simulated);
            a hand's (``dexgraspbench``): ``(F,)`` one per fingertip at the end of the
            calibrated squeeze (``nan`` for a fingertip not in contact).
        model_normal_force_N: ``(N,)`` the model's normal force at jaxgrasp's equilibrium,
            ``pi E d^2 / cos^2 phi`` (eq. 4, 13, 14), N (``nan`` where there is none); a
            hand's: ``(F,)``, at ``dr`` where the evaluation found no equilibrium.
        parameters: every parameter of the simulation (timestep, calibration, damping,
            friction, tolerances), SI units; the key ``units`` names them.
        protocol: ``"jaxgrasp"`` or ``"dexgraspbench"`` (`jaxgrasp.simulation._protocols`).
    """

    status: SimulationStatus
    grasp_status: str
    value: float
    reason: str
    hold: Trial | None
    six_axis: tuple
    kicks: tuple
    settled_normal_force_N: np.ndarray
    model_normal_force_N: np.ndarray
    parameters: dict
    protocol: str = "jaxgrasp"

    def __post_init__(self):
        object.__setattr__(self, "status", SimulationStatus(int(self.status)))

    @property
    def status_name(self) -> str:
        """The name of ``status``: ``'simulated'``, ``'diverged'``, ``'unstable'``, ``'infeasible'`` or
        ``'not_converged'``."""
        return self.status.label

    @property
    def simulated(self) -> bool:
        """Whether the simulator ran (``'simulated'`` or ``'diverged'``)."""
        return self.status in (SimulationStatus.SIMULATED, SimulationStatus.DIVERGED)

    @property
    def diverged(self) -> tuple:
        """The trials that diverged (`Trial.diverged`), in the order hold, six-axis, kicks."""
        return tuple(t for t in (self.hold, *self.six_axis, *self.kicks) if t is not None and t.diverged)

    @property
    def six_axis_success(self) -> bool | None:
        """All six disturbances withstood (``None`` when not simulated)."""
        return all(t.success for t in self.six_axis) if self.six_axis else None

    @property
    def success(self) -> bool | None:
        """The protocol's verdict: ``dexgraspbench``, all six pushes withstood (``False``
        where the hand penetrated at the start); ``jaxgrasp``, the hold and the six axes
        withstood (the kicks are reported apart). ``None`` when not simulated."""
        if self.status is SimulationStatus.PENETRATING:
            return False
        if not self.simulated:
            return None
        held = self.six_axis_success
        return bool(held) if self.hold is None else bool(held and self.hold.success)

    @property
    def normal_force_error(self) -> np.ndarray:
        """``settled / model - 1`` per contact: the settled normal force's relative error
        against the model's (eq. 4), ``nan`` where either is missing."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(self.settled_normal_force_N, float) / np.asarray(self.model_normal_force_N, float) - 1.0

    def summary(self) -> str:
        """A few lines: the status and the evaluation's, the value (J), then each trial
        (hold, the six disturbances, the kicks) withstood or not, or why the grasp was not
        simulated."""
        head = f"{self.status_name} (evaluation {self.grasp_status}): value {self.value:.6e} J"
        if self.protocol != "jaxgrasp":
            head += f"; protocol {self.protocol}: {'success' if self.success else 'failure'}"
        if not self.simulated:
            return f"{head}\nnot simulated: {self.reason}"
        said = lambda t, *words: t.label if t.diverged else f"{t.label} {t.outcome(*words)}"  # noqa: E731
        lines = [head]
        if self.hold is not None:
            lines.append(f"hold: {self.hold.outcome()}, moved {self.hold.max_displacement_m * 1e3:.3f} mm")
        if self.reason:
            lines.append(self.reason)
        if self.six_axis:
            lines.append("six-axis: " + ", ".join(said(t) for t in self.six_axis))
        if self.kicks:
            lines.append("kicks: " + ", ".join(said(t, "no slip", "slipped") for t in self.kicks))
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """``results.json``'s content: every field, JSON-ready (``null`` for ``nan``);
        the value's key is ``value_J`` there (the file's units in its names)."""
        return {
            "protocol": self.protocol,
            "status": self.status_name,
            "success": self.success,
            "grasp_status": self.grasp_status,
            "value_J": float(self.value),
            "reason": self.reason,
            "hold": None if self.hold is None else self.hold.to_dict(),
            "six_axis": [t.to_dict() for t in self.six_axis],
            "six_axis_success": self.six_axis_success,
            "kicks": [t.to_dict() for t in self.kicks],
            "settled_normal_force_N": json_floats(self.settled_normal_force_N),
            "model_normal_force_N": json_floats(self.model_normal_force_N),
            "normal_force_relative_error": json_floats(self.normal_force_error),
            "parameters": self.parameters,
        }
