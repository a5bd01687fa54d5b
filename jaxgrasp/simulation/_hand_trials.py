"""The hand's trials in its scene (`jaxgrasp.simulation._hand_scene`): pregrasp -> grasp -> squeeze, then a push.

Stages (DexGraspBench's ``_control_hand_with_interp``): the actuators' targets move from
one stage's joints to the next in ``outer`` equal steps, each held ``inner`` MuJoCo steps.
The pregrasp is the grasp with every joint at `PREGRASP_FACTOR` times its angle (within
the joint limits: DexGraspBench's own conversion of grasps that carry none).

Squeeze, and the actuators' gains. Each joint is a position actuator ``tau = kp (ctrl -
q) - kv qdot``. The protocol's contacts are nearly rigid, so the fingertips' softness of
the paper lives in the joints: the gains make each fingertip in contact about as stiff
along its normal as the secant of eq. 4 from no deformation to ``SQUEEZE_FACTOR * dr``,
``k_i = pi E dr_i / SQUEEZE_FACTOR`` (N/m), each joint ``kp_j = max_i m_i k_i J_ij^2``
over the fingertips it moves (``J_ij`` the fingertip's contact point's velocity along its
inward normal per unit joint velocity; ``m_i`` the joints that move fingertip ``i``, so
that its compliance ``sum_j J_ij^2 / kp_j`` is ``1 / k_i``), the joints that move none as
stiff as the stiffest (`gains`). ``kv = DAMPING_STEPS dt kp`` (`DAMPING_STEPS`). At the grasp's targets the rigid contact pushes each fingertip back by its
overlap ``dr``, pressing with about ``pi E dr^2 / SQUEEZE_FACTOR``; the squeeze moves the
targets further into the object by ``kp^-1 J^T (f* - f)`` (`calibrate`), ``f*`` the
model's normal force (eq. 4) at the equilibrium jaxgrasp finds (at ``dr`` where it
finds none), ``f`` the settled force, and again from the grasp's settled state until
every fingertip presses within `FORCE_TOL` of ``f*`` or `MAX_ROUNDS` rounds.

Trials (DexGraspBench's ``fc_mocap``): for each of ``+x ... -z``, from a fresh reset at
the pregrasp: grasp, squeeze, then a force ``10 m`` N on the object for ``outer x inner``
steps, its pose checked after each ``inner`` steps against its pose at the start;
the trial fails at the first check where it moved 5 cm or turned 15 degrees.
"""

from __future__ import annotations

import numpy as np

from jaxgrasp.simulation._limits import DIVERGENCE_WARNINGS
from jaxgrasp.simulation._result import AXES, Trial
from jaxgrasp.simulation._scene import load_mujoco, rotation_matrix_of_quat
from jaxgrasp.simulation._trials import rotation_angle

__all__ = ["FORCE_TOL", "HandRunner", "MAX_ROUNDS", "SETTLE_STEPS", "gains", "pregrasp"]

FORCE_TOL = 0.02
"""The squeeze is calibrated until each fingertip's settled normal force is within this
fraction of its target."""

MAX_ROUNDS = 6
"""At most this many squeezes are tried in the calibration."""

DAMPING_STEPS = 10.0
"""Each joint's damping ``kv = DAMPING_STEPS * dt * kp``: its spring's relaxation time is this
many timesteps. The integrator takes the damping implicitly, but with less of it the
object pinched between high-friction point contacts rocks and is thrown out (found on the
two-finger pinch: with 2 to 5 steps the cube of 0.1 kg was ejected at friction 0.6)."""

SETTLE_STEPS = 100
"""Steps held after the grasp and after a calibration squeeze before the forces are read
(their mean over the last quarter)."""

def pregrasp(hand, qpos, factor: float) -> np.ndarray:
    """``(J,)`` the pregrasp: every joint at ``factor`` times its grasp position, within the limits."""
    return np.clip(factor * np.asarray(qpos, dtype=np.float64), hand.lower, hand.upper)


def gains(jac, jac_normal, stiffness, slide) -> np.ndarray:
    """``(J,)`` the joints' ``kp`` (N m/rad for hinges, N/m for slides) from ``jac`` ``(F, 3,
    J)`` (each active fingertip's contact point's velocity per unit joint velocity, m/rad or
    m/m), ``jac_normal`` ``(F, J)`` (its component along the inward normal), ``stiffness``
    ``(F,)`` N/m and ``slide`` ``(J,)`` bool (module notes)."""
    lever2 = np.sum(np.asarray(jac, dtype=np.float64) ** 2, axis=1)  # (F, J): |J_ij|^2
    on_chain = lever2 > 1e-18
    cos2 = np.where(on_chain, np.asarray(jac_normal) ** 2 / np.where(on_chain, lever2, 1.0), 0.0)
    alpha = np.asarray(stiffness, dtype=np.float64) * np.maximum(np.sum(cos2, axis=1), 1.0)
    kp = np.max(alpha[:, None] * lever2, axis=0)
    hinge_lever2 = float(np.max(lever2[:, ~slide], initial=0.0)) or 0.01
    floor = np.where(slide, np.max(stiffness), np.max(stiffness) * hinge_lever2)
    return np.where(kp > 0, kp, floor)


class HandRunner:
    """Runs the stages and trials of one `HandScene` under a protocol's ``settings``."""

    def __init__(self, scene, settings, q_pre, q_grasp, fingertips, points, normals):
        """``fingertips`` ``(A,)`` the active fingertips' indices; ``points`` ``(A, 3)`` m and
        ``normals`` ``(A, 3)`` (outward) their contact points and normals in the object's
        mesh frame."""
        self.mujoco = load_mujoco()
        self.scene, self.settings = scene, settings
        self.model = scene.model
        self.data = self.mujoco.MjData(self.model)
        self.q_pre, self.q_grasp = np.asarray(q_pre, float), np.asarray(q_grasp, float)
        self.fingertips = np.asarray(fingertips, dtype=int)
        self.points, self.normals = np.asarray(points, float), np.asarray(normals, float)
        self.tip_body = np.asarray(scene.fingertip_bodies)[self.fingertips]
        self.J = scene.num_joints

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """The pregrasp: the hand at ``q_pre`` (its targets too), the object at its start, at rest."""
        mj, m, d = self.mujoco, self.model, self.data
        mj.mj_resetData(m, d)
        d.qpos[:self.J] = self.q_pre
        d.qpos[self.J:self.J + 7] = self.scene.object_start
        d.ctrl[:] = self.q_pre
        mj.mj_forward(m, d)

    def save(self) -> np.ndarray:
        mj = self.mujoco
        spec = mj.mjtState.mjSTATE_INTEGRATION
        out = np.empty(mj.mj_stateSize(self.model, spec))
        mj.mj_getState(self.model, self.data, out, spec)
        return out

    def restore(self, state) -> None:
        mj = self.mujoco
        mj.mj_setState(self.model, self.data, state, mj.mjtState.mjSTATE_INTEGRATION)
        mj.mj_forward(self.model, self.data)

    def set_gains(self, kp) -> None:
        kp = np.asarray(kp, dtype=np.float64)
        m = self.model
        m.actuator_gainprm[:self.J, 0] = kp
        m.actuator_biasprm[:self.J, 1] = -kp
        m.actuator_biasprm[:self.J, 2] = -DAMPING_STEPS * m.opt.timestep * kp

    # ---------------------------------------------------------------- readings
    def penetration(self) -> tuple[float, float]:
        """``(hand-object, hand-hand)`` m: the deepest overlap now (0 where none)."""
        d, body = self.data, self.scene.object_body
        ho, hh = 0.0, 0.0
        bodies = self.model.geom_bodyid
        for j in range(d.ncon):
            c = d.contact[j]
            on_object = (bodies[c.geom1] == body) + (bodies[c.geom2] == body)
            if on_object == 1:
                ho = max(ho, -float(c.dist))
            elif on_object == 0:
                hh = max(hh, -float(c.dist))
        return ho, hh

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        q = self.data.qpos[self.J:self.J + 7]
        return q[:3].copy(), rotation_matrix_of_quat(q[3:] / np.linalg.norm(q[3:]))

    def normal_forces(self) -> np.ndarray:
        """``(A,)`` N: the normal force between each active fingertip's body and the object now."""
        mj, m, d = self.mujoco, self.model, self.data
        out, buf = np.zeros(len(self.tip_body)), np.zeros(6)
        bodies = m.geom_bodyid
        for j in range(d.ncon):
            c = d.contact[j]
            if c.efc_address < 0:
                continue
            pair = {int(bodies[c.geom1]), int(bodies[c.geom2])}
            if self.scene.object_body not in pair:
                continue
            for a, b in enumerate(self.tip_body):
                if int(b) in pair:
                    mj.mj_contactForce(m, d, j, buf)
                    out[a] += buf[0]
        return out

    def jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """``((A, 3, J), (A, J))``: each active fingertip's contact point's velocity per unit
        joint velocity, and its component along the object's inward normal there, now."""
        mj, m, d = self.mujoco, self.model, self.data
        pos, rot = self.object_pose()
        jacp = np.zeros((3, m.nv))
        full = []
        for p, b in zip(self.points, self.tip_body):
            mj.mj_jac(m, d, jacp, None, pos + rot @ p, int(b))
            full.append(jacp[:, :self.J].copy())
        full = np.array(full).reshape(len(self.tip_body), 3, self.J)
        return full, np.einsum("ak,akj->aj", -(self.normals @ rot.T), full)

    def normal_jacobian(self) -> np.ndarray:
        """``(A, J)``: the second of `jacobians`."""
        return self.jacobians()[1]

    def diverged(self) -> bool:
        d, kinds = self.data, self.mujoco.mjtWarning
        if any(d.warning[int(getattr(kinds, name))].number > 0 for name in DIVERGENCE_WARNINGS):
            return True
        return not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))

    def warnings(self) -> dict[str, int]:
        out = {}
        for name, kind in self.mujoco.mjtWarning.__members__.items():
            if name != "mjNWARNING" and self.data.warning[int(kind)].number > 0:
                out[name] = int(self.data.warning[int(kind)].number)
        return out

    # ---------------------------------------------------------------- stages
    def stage(self, c1, c2) -> None:
        """Targets from ``c1`` to ``c2`` in ``outer`` steps of ``inner`` MuJoCo steps each."""
        outer, inner = self.settings["stage_steps"]
        for c in np.linspace(c1, c2, outer + 1)[1:]:
            self.data.ctrl[:] = c
            self.mujoco.mj_step(self.model, self.data, nstep=inner)

    def settle(self, steps: int = SETTLE_STEPS) -> np.ndarray:
        """Hold the targets ``steps`` steps: ``(A,)`` the mean normal forces over the last quarter, N."""
        forces = []
        for k in range(steps):
            self.mujoco.mj_step(self.model, self.data)
            if k >= steps - max(1, steps // 4):
                forces.append(self.normal_forces())
        return np.mean(forces, axis=0)

    def calibrate(self, target) -> dict:
        """The squeeze's targets (module notes): ``{"squeeze", "settled", "rounds", "grasp_settled"}``:
        ``(J,)`` joint targets, ``(A,)`` N the settled normal forces of the last squeeze,
        how many squeezes were tried, ``(A,)`` N the forces at the grasp's targets.

        Each round moves the targets by ``kp^-1 J^T (f* - f) / rho``: ``rho`` the share of
        the last move's intended change of force that came (fingers that press against
        each other through the object each get a part of a move), from 1 at the start."""
        target = np.asarray(target, dtype=np.float64)
        kp = self.model.actuator_gainprm[:self.J, 0].copy()
        self.reset()
        self.stage(self.q_pre, self.q_grasp)
        settled = self.settle()
        held, at_grasp = self.save(), settled
        squeeze, rho, rounds = self.q_grasp.copy(), 1.0, 0
        while rounds < MAX_ROUNDS:
            want = target - settled
            squeeze = squeeze + self.normal_jacobian().T @ (want / rho) / kp
            self.restore(held)
            self.stage(self.q_grasp, squeeze)
            before, (settled, rounds) = settled, (self.settle(), rounds + 1)
            if np.all(np.abs(settled - target) <= FORCE_TOL * target) or self.diverged():
                break
            rho = float(np.clip(np.dot(settled - before, want) / max(np.dot(want, want), 1e-300) * rho, 0.1, 10.0))
        return {"squeeze": squeeze, "settled": settled, "rounds": rounds, "grasp_settled": at_grasp}

    # ---------------------------------------------------------------- trials
    def push(self, axis: str, squeeze, mass: float) -> Trial:
        """One trial of the six (module notes) along ``axis`` (one of `AXES`)."""
        s, mj, d = self.settings, self.mujoco, self.data
        self.reset()
        pos0, rot0 = self.object_pose()
        self.stage(self.q_pre, self.q_grasp)
        self.stage(self.q_grasp, squeeze)
        k = AXES.index(axis)
        d.xfrc_applied[self.scene.object_body, k // 2] = (1.0 if axis[0] == "+" else -1.0) * s[
            "disturbance_acceleration_m_s2"] * mass
        outer, inner = s["disturbance_steps"]
        t, disp, rot, ok, diverged = [0.0], [], [], True, False
        for step in range(outer + 1):
            if step:
                mj.mj_step(self.model, d, nstep=inner)
                t.append(step * inner * self.model.opt.timestep)
                diverged = self.diverged()
                if diverged:
                    t.pop()
                    break
            pos, r = self.object_pose()
            disp.append(float(np.linalg.norm(pos - pos0)))
            rot.append(rotation_angle(r @ rot0.T))
            ok = disp[-1] < s["six_axis_tolerance_m"] and rot[-1] < s["six_axis_tolerance_rad"]
            if not ok:
                break
        return Trial(kind="six_axis", success=bool(ok and not diverged), max_displacement_m=max(disp),
                     max_rotation_rad=max(rot), slipped_contact=None, slip_time_s=None, time_s=np.array(t),
                     displacement_m=np.array(disp), rotation_rad=np.array(rot), max_sliding_m=np.zeros(0),
                     axis=axis, diverged=diverged, simulator_warnings=self.warnings())
