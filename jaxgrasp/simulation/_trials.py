"""The simulated tests: hold under gravity, the six-axis disturbance, the energy kicks.

Every trial starts from a saved state of the scene, steps MuJoCo and samples the object's
pose every ``sample_s`` seconds: the distance of its centre of mass from the trial's
start, its rotation angle from the start, and how far each contact's surface point slid
under its fingertip (the tangential displacement of that point of the object, or its
torsion about the contact normal times the contact radius ``a = sqrt(r^2 - (r - d)^2)``).
Fingertips are fixed in the world and MuJoCo's friction (with the no-slip solver) stores
no tangential deformation, so any such motion is sliding; a contact slipped when it
exceeds the contact's slip threshold.

A trial diverged where MuJoCo met a position, velocity or acceleration beyond its limits
(one of `DIVERGENCE_WARNINGS`) or the state is no longer finite: MuJoCo then resets the
state to the model's start, which would look held. `Runner.run` reads MuJoCo's warning
counters after every sample and stops the trial at the first such sample (leaving it
out); the trial is reported diverged, never a success.
"""

from __future__ import annotations

import contextlib
import math
from typing import NamedTuple

import numpy as np

from jaxgrasp.simulation._limits import DIVERGENCE_WARNINGS
from jaxgrasp.simulation._result import AXES, Trial
from jaxgrasp.simulation._scene import Scene, load_mujoco, rotation_matrix, rotation_matrix_of_quat

__all__ = ["Runner", "Samples", "rotation_angle", "warnings_recorded"]

_GONE_M = 0.2
"""A trial stops early once the object is this far from its start, m (it has fallen)."""


class Samples(NamedTuple):
    """What one run of a trial recorded (`Runner.run`)."""

    t: np.ndarray  # (T,) s, simulated time
    disp: np.ndarray  # (T,) m, the centre of mass's distance from its start
    rot: np.ndarray  # (T,) rad, the rotation angle from the start
    most: np.ndarray  # (N,) m, each contact's largest sliding
    slip: tuple | None  # (contact, time) of the first slip
    forces: np.ndarray  # (T - 1, N) N, normal forces (where recorded)
    warnings: dict  # MuJoCo's warnings of the run, {name: count}
    diverged: bool  # MuJoCo met a state beyond its limits (the run stopped there)


@contextlib.contextmanager
def warnings_recorded():
    """While the trials run, MuJoCo's warnings are read from its counters (`Runner.warnings`)
    and said in the result, not printed: MuJoCo's own handler would print each to stderr
    and append it to ``MUJOCO_LOG.TXT`` in the working directory. The handler found is put
    back after."""
    mujoco = load_mujoco()
    before = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda _message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(before)


def rotation_angle(r) -> float:
    """The angle of a rotation matrix, rad, in ``[0, pi]``."""
    return math.acos(min(1.0, max(-1.0, (float(np.trace(r)) - 1.0) / 2.0)))


class Runner:
    """Runs trials on one scene; ``thresholds`` ``(N,)`` m are the contacts' slip thresholds."""

    def __init__(self, scene: Scene, thresholds, sample_s: float):
        self.mujoco = load_mujoco()
        self.scene = scene
        self.model = scene.model
        self.data = self.mujoco.MjData(self.model)
        self.thresholds = np.asarray(thresholds, dtype=np.float64)
        self.every = max(1, int(round(sample_s / scene.timestep)))
        c = scene.contacts
        self.radius_a = np.sqrt(np.maximum(c.r**2 - (c.r - np.clip(scene.calibration["d_eq"], 0, c.r)) ** 2, 0.0))

    def start_state(self) -> np.ndarray:
        """The scene's start: the equilibrium pose at rest."""
        return np.concatenate([self.scene.start_qpos, np.zeros(6)])

    def _reset(self, state, velocity=None, force=None) -> None:
        d = self.data
        self.mujoco.mj_resetData(self.model, d)
        d.qpos[:] = state[:7]
        d.qvel[:] = state[7:] if velocity is None else velocity
        if force is not None:
            d.xfrc_applied[1, :3] = force
        self.mujoco.mj_forward(self.model, d)

    def _sliding(self, pos0, rot0, pos, rot) -> np.ndarray:
        """``(N,)`` sliding of each contact's surface point since the start, m."""
        c = self.scene.contacts
        moved = (pos + c.p @ rot.T) - (pos0 + c.p @ rot0.T)
        n0 = c.n @ rot0.T
        tangential = np.linalg.norm(moved - np.sum(moved * n0, axis=1, keepdims=True) * n0, axis=1)
        rel = rot @ rot0.T
        wv = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]]) / 2.0
        ang = rotation_angle(rel)
        axis = wv / (np.linalg.norm(wv) + 1e-300) * ang
        torsion = np.abs(n0 @ axis) * self.radius_a
        return np.maximum(tangential, torsion)

    def run(self, duration: float, force_record=None):
        """Step ``duration`` s from the current state: its `Samples`; ``force_record``: also
        the normal forces. Where it diverged (`diverged`) the run stopped before the
        sample that saw it."""
        m, d, mj = self.model, self.data, self.mujoco
        pos0, rot0 = d.qpos[:3].copy(), rotation_matrix_of_quat(d.qpos[3:7])
        n_samples = max(1, int(math.ceil(duration / (self.every * m.opt.timestep))))
        t, disp, rot, forces = [0.0], [0.0], [0.0], []
        most = np.zeros(len(self.thresholds))
        slip, diverged = None, False
        for _ in range(n_samples):
            mj.mj_step(m, d, nstep=self.every)
            diverged = self.diverged()
            if diverged:  # MuJoCo reset the state (or it is not finite): nothing after this is the trial's
                break
            pos, r = d.qpos[:3].copy(), rotation_matrix_of_quat(d.qpos[3:7] / np.linalg.norm(d.qpos[3:7]))
            t.append(float(d.time))
            disp.append(float(np.linalg.norm(pos - pos0)))
            rot.append(rotation_angle(r @ rot0.T))
            sl = self._sliding(pos0, rot0, pos, r)
            most = np.maximum(most, sl)
            over = np.flatnonzero(sl > self.thresholds)
            if slip is None and over.size:
                slip = (int(over[np.argmax(sl[over] / self.thresholds[over])]), float(d.time))
            if force_record:
                forces.append(self.normal_forces())
            if disp[-1] > _GONE_M:
                break
        return Samples(np.array(t), np.array(disp), np.array(rot), most, slip, np.array(forces), self.warnings(),
                       diverged)

    def warnings(self) -> dict[str, int]:
        """MuJoCo's warnings since the trial's start (`_reset` clears them): ``{name:
        count}`` of those raised, such as ``{"mjWARN_BADQACC": 1}``."""
        out = {}
        for name, kind in self.mujoco.mjtWarning.__members__.items():
            if name != "mjNWARNING" and self.data.warning[int(kind)].number > 0:
                out[name] = int(self.data.warning[int(kind)].number)
        return out

    def diverged(self) -> bool:
        """Whether MuJoCo met a state beyond its limits since the trial's start (one of
        `DIVERGENCE_WARNINGS`: it reset the state) or the state is not finite."""
        d, kinds = self.data, self.mujoco.mjtWarning
        if any(d.warning[int(getattr(kinds, name))].number > 0 for name in DIVERGENCE_WARNINGS):
            return True
        return not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))

    def normal_forces(self) -> np.ndarray:
        """``(N,)`` each fingertip's normal force now, N (0 where it does not touch)."""
        mj, m, d = self.mujoco, self.model, self.data
        out = np.zeros(len(self.thresholds))
        buf = np.zeros(6)
        for j in range(d.ncon):
            con = d.contact[j]
            if con.exclude != 0 or con.efc_address < 0:
                continue
            mj.mj_contactForce(m, d, j, buf)
            geom = int(con.geom1)
            name = mj.mj_id2name(m, mj.mjtObj.mjOBJ_GEOM, geom)
            out[int(name[3:])] += buf[0]
        return out

    def hold(self, duration: float, tol_m: float, tol_rad: float):
        """The hold trial from the start state; ``(trial, settled state, settled forces)``."""
        self._reset(self.start_state())
        run = self.run(duration, force_record=True)
        state = np.concatenate([self.data.qpos, self.data.qvel])
        tail = run.forces[max(0, int(0.75 * len(run.forces))):]
        settled = tail.mean(axis=0) if len(tail) and not run.diverged else np.full(len(self.thresholds), np.nan)
        ok = run.disp.max() < tol_m and run.rot.max() < tol_rad and len(run.t) > 1
        return _trial("hold", ok, run), state, settled

    def six_axis(self, state, accel: float, duration: float, tol_m: float, tol_rad: float) -> list[Trial]:
        """Six trials from ``state``: a force ``m * accel`` along each of `AXES`."""
        out = []
        for k, axis in enumerate(AXES):
            f = np.zeros(3)
            f[k // 2] = (1.0 if axis[0] == "+" else -1.0) * self.scene.sim_mass * accel
            self._reset(state, force=f)
            run = self.run(duration)
            ok = run.t[-1] >= duration - 1e-9 and run.disp.max() < tol_m and run.rot.max() < tol_rad
            out.append(_trial("six_axis", ok, run, axis=axis))
        return out

    def kinetic_energy(self, velocity) -> float:
        """``0.5 v^T M v`` at the current pose, J (MuJoCo's mass matrix)."""
        mj, m, d = self.mujoco, self.model, self.data
        mv = np.zeros(m.nv)
        mj.mj_mulM(m, d, mv, np.asarray(velocity, dtype=np.float64))
        return 0.5 * float(np.dot(velocity, mv))

    def kick_velocity(self, state, direction, energy: float) -> np.ndarray:
        """``(6,)`` the object's velocity along ``direction`` (free joint coordinates)
        with kinetic energy ``energy`` J at the pose of ``state``."""
        self._reset(state)
        unit = self.kinetic_energy(direction)
        return np.asarray(direction, dtype=np.float64) * math.sqrt(energy / unit)

    def kick(self, state, direction, energy: float, duration: float, scale: float, kind: str) -> Trial:
        """A trial from ``state`` with the object's velocity along ``direction`` (6,) (free
        joint coordinates) scaled to kinetic energy ``energy`` J; success: no slip."""
        v = self.kick_velocity(state, direction, energy)
        self._reset(state, velocity=v)
        ke = self.kinetic_energy(v)
        run = self.run(duration)
        return _trial("kick", run.slip is None and run.t[-1] >= duration - 1e-9, run, scale=scale, direction=kind,
                      kinetic_energy_J=ke, initial_velocity=v)


def least_energy_direction(evaluation) -> np.ndarray | None:
    """``(6,)`` free-joint velocity direction from the equilibrium towards the pose of the
    least-energy boundary (translation in world axes, rotation in body axes), or ``None``."""
    kind, j = int(np.asarray(evaluation.limiting_kind)), int(np.asarray(evaluation.limiting_contact))
    if kind < 0 or j < 0:
        return None
    dp_b = np.asarray(evaluation.boundary_translation, dtype=np.float64)[kind, j]
    w_b = np.asarray(evaluation.boundary_rotation, dtype=np.float64)[kind, j]
    dp_e = np.asarray(evaluation.equilibrium_translation, dtype=np.float64)
    w_e = np.asarray(evaluation.equilibrium_rotation, dtype=np.float64)
    r_e, r_b = rotation_matrix(w_e), rotation_matrix(w_b)
    rel = r_e.T @ r_b  # body-frame rotation from the equilibrium to the boundary pose
    ang = rotation_angle(rel)
    wv = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    axis = wv / (np.linalg.norm(wv) + 1e-300) * ang
    out = np.concatenate([dp_b - dp_e, axis])
    return out if np.linalg.norm(out) > 0 else None


def _trial(kind, ok, run: Samples, **extra) -> Trial:
    """The `Trial` of one run; a diverged run is never a success."""
    t, slip = run.t, run.slip
    return Trial(
        kind=kind, success=bool(ok) and not run.diverged, max_displacement_m=float(np.max(run.disp)),
        max_rotation_rad=float(np.max(run.rot)), slipped_contact=None if slip is None else slip[0],
        slip_time_s=None if slip is None else slip[1] - t[0], time_s=t - t[0], displacement_m=run.disp,
        rotation_rad=run.rot, max_sliding_m=run.most, diverged=run.diverged, simulator_warnings=dict(run.warnings),
        **extra,
    )
