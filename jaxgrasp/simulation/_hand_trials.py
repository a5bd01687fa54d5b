"""The hand's trials in its scene (`jaxgrasp.simulation._hand_scene`): pregrasp -> grasp -> squeeze, then a push.

Stages (DexGraspBench's ``_control_hand_with_interp``): the actuators' targets move from
one stage's joints to the next in ``outer`` equal steps, each held ``inner`` MuJoCo steps.
The pregrasp is the grasp with every finger joint at `PREGRASP_FACTOR` times its angle
(within the joint limits: DexGraspBench's own conversion of grasps that carry none; the
wrist's joints, those on every fingertip's chain, kept). The protocol's penetration check
is made there; then, where a link still overlaps or nearly touches the object (a
fingertip that meets the surface with the side of its cap opens along the surface, not
away from it), the fingers are opened further until every link stands `CLEARANCE` off
(`clear_pregrasp`): the object is free and weightless, and an overlap at the start
would throw it out of the hand before the fingers close.

Squeeze, and the actuators' gains. Each joint is a position actuator ``tau = kp (ctrl -
q) - kv qdot``. The protocol's contacts are nearly rigid, so the fingertips' softness of
the paper lives in the joints: the gains make each fingertip in contact about as stiff
along its normal as the secant of eq. 4 from no deformation to ``SQUEEZE_FACTOR * dr``,
``k_i = pi E dr_i / SQUEEZE_FACTOR`` (N/m) (an inactive fingertip as stiff as the softest
active one, at its centre), each joint ``kp_j = max_i m_i k_i J_ij^2``
over the fingertips it moves (``J_ij`` the fingertip's contact point's velocity along its
inward normal per unit joint velocity; ``m_i`` the joints that move fingertip ``i``, so
that its compliance ``sum_j J_ij^2 / kp_j`` is ``1 / k_i``), the joints that move none as
stiff as the stiffest (`gains`). ``kv = DAMPING_STEPS dt kp`` (`DAMPING_STEPS`). At the grasp's targets the rigid contact pushes each fingertip back by its
overlap ``dr``, pressing with about ``pi E dr^2 / SQUEEZE_FACTOR``; the squeeze moves the
targets further into the object by ``kp^-1 J^T (f* - f)`` (`calibrate`), ``f*`` the
model's normal force (eq. 4) at the equilibrium jaxgrasp finds (at ``dr`` where it
finds none), ``f`` the settled force, by Newton steps on the measured response of the
settled forces (`HandRunner.calibrate`), from the state at the end of the grasp stage,
until every fingertip presses within `FORCE_TOL` of ``f*`` or `MAX_ROUNDS` squeezes.

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

__all__ = ["CLEARANCE", "FORCE_TOL", "HandRunner", "MAX_ROUNDS", "SETTLE_STEPS", "clear_pregrasp", "gains", "pregrasp",
           "wrist_joints"]

FORCE_TOL = 0.02
"""The squeeze is calibrated until each fingertip's settled normal force is within this
fraction of its target."""

MAX_ROUNDS = 24
"""At most this many squeezes are tried in the calibration (the finite differences' included)."""

DAMPING_STEPS = 10.0
"""Each joint's damping ``kv = DAMPING_STEPS * dt * kp``: its spring's relaxation time is this
many timesteps. The integrator takes the damping implicitly, but with less of it the
object pinched between high-friction point contacts rocks and is thrown out (found on the
two-finger pinch: with 2 to 5 steps the cube of 0.1 kg was ejected at friction 0.6)."""

SETTLE_STEPS = 100
"""Steps held after the grasp and after a calibration squeeze before the forces are read
(their mean over the last quarter)."""

def wrist_joints(hand) -> np.ndarray:
    """``(J,)`` bool: the joints on every fingertip's chain (a wrist joint of the hand's own
    file, such as the Shadow hand's ``WRJ1``, ``WRJ0``): they move the whole hand, not a finger."""
    tree = hand.tree
    chains = []
    for body in np.asarray(hand.fingertip_body, dtype=int):
        on = np.zeros(hand.num_joints, dtype=bool)
        while body > 0:
            on[list(tree.body_joints[body])] = True
            body = int(tree.body_parent[body])
        chains.append(on)
    return np.logical_and.reduce(chains) if chains else np.zeros(hand.num_joints, dtype=bool)


def pregrasp(hand, qpos, factor: float) -> np.ndarray:
    """``(J,)`` the pregrasp: every finger joint at ``factor`` times its grasp position, within
    the limits; the wrist's joints (`wrist_joints`) kept at the grasp, as DexGraspBench keeps
    the wrist (scaling a wrist joint would swing the whole hand, not open it)."""
    q = np.asarray(qpos, dtype=np.float64)
    return np.where(wrist_joints(hand), q, np.clip(factor * q, hand.lower, hand.upper))


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


CLEARANCE = 0.005
"""m: how far the pregrasp's links stand from the object (`clear_pregrasp`)."""

CLEAR_ITERATIONS = 8
"""At most this many Gauss-Newton steps of `clear_pregrasp`."""


def _overlaps(runner, q, clearance):
    """``(rows (C, J), gaps (C,))`` at the hand's joints ``q``, the object at its start: each
    hand-object pair nearer than ``clearance``, its separation's rate per joint velocity and
    how far it is from ``clearance`` (m)."""
    mj, m, d, body = runner.mujoco, runner.model, runner.data, runner.scene.object_body
    d.qpos[:runner.J], d.qpos[runner.J:runner.J + 7] = q, runner.scene.object_start
    saved = m.geom_margin[runner.scene.object_geoms].copy()
    m.geom_margin[runner.scene.object_geoms] = clearance
    mj.mj_forward(m, d)
    m.geom_margin[runner.scene.object_geoms] = saved
    rows, gaps, jacp = [], [], np.zeros((3, m.nv))
    for j in range(d.ncon):
        c = d.contact[j]
        ends = (int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2]))
        if (ends[0] == body) == (ends[1] == body) or c.dist >= clearance:
            continue
        hand_body, sign = (ends[1], 1.0) if ends[0] == body else (ends[0], -1.0)  # normal: geom1 -> geom2
        mj.mj_jac(m, d, jacp, None, c.pos, hand_body)
        rows.append(sign * c.frame[:3] @ jacp[:, :runner.J])
        gaps.append(clearance - c.dist)
    return np.array(rows).reshape(-1, runner.J), np.array(gaps)


def clear_pregrasp(runner, hand, q, clearance: float = CLEARANCE) -> np.ndarray:
    """``(J,)`` the pregrasp ``q`` with the fingers opened until no link of the hand is nearer
    the object than ``clearance`` (damped Gauss-Newton steps on the pairs' separations, the
    wrist's joints kept, within the joint limits), as a planner's pregrasp stands off its
    grasp (BODex's, which DexGraspBench replays): the object is free and, without gravity,
    any overlap at the start throws it out of the hand before the fingers close."""
    q = np.asarray(q, dtype=np.float64).copy()
    moving = ~wrist_joints(hand)
    for _ in range(CLEAR_ITERATIONS):
        rows, gaps = _overlaps(runner, q, clearance)
        if not len(gaps) or np.max(gaps) <= 0.1 * clearance:
            break
        rows = rows * moving
        step = rows.T @ np.linalg.solve(rows @ rows.T + 1e-6 * np.eye(len(gaps)), gaps)
        q = np.clip(q + step, hand.lower, hand.upper)
    return q


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

    def squeezed(self, held, squeeze) -> np.ndarray:
        """From the state ``held`` (the grasp's targets reached), the squeeze's targets
        ``squeeze`` ``(J,)``: ``(A,)`` N the settled normal forces (`settle`)."""
        self.restore(held)
        self.stage(self.q_grasp, squeeze)
        return self.settle()

    def within_limits(self, q) -> np.ndarray:
        """``q`` ``(J,)`` clipped to the limited joints' ranges (a target past a limit only
        presses the joint into it)."""
        m = self.model
        lo, hi = m.jnt_range[:self.J, 0], m.jnt_range[:self.J, 1]
        limited = np.asarray(m.jnt_limited[:self.J], dtype=bool)
        return np.where(limited, np.clip(q, lo, hi), q)

    def calibrate(self, target) -> dict:
        """The squeeze's targets (module notes): ``{"squeeze", "settled", "rounds", "grasp_settled"}``:
        ``(J,)`` joint targets, ``(A,)`` N the settled normal forces of the squeeze kept,
        how many squeezes were tried, ``(A,)`` N the forces at the grasp's targets.

        The squeeze is ``q_grasp + D a``, ``D = kp^-1 Jn^T`` (each column: fingertip ``i``'s
        joints moved as if to press it 1 N harder against a fixed object), ``a`` ``(A,)`` N.
        The object is free, so one fingertip's push moves it and changes every force: the
        settled forces' response ``S = df/da`` is measured by finite differences (one squeeze
        per fingertip), then Newton steps ``S da = f* - f`` (each at most twice the largest
        target, ``S`` updated by Broyden's rule after each; a step that makes the largest
        relative error worse is not taken), the best squeeze kept."""
        target = np.asarray(target, dtype=np.float64)
        kp = self.model.actuator_gainprm[:self.J, 0].copy()
        self.reset()
        self.stage(self.q_pre, self.q_grasp)
        held = self.save()
        basis = self.normal_jacobian().T / kp[:, None]  # (J, A)
        run = lambda a: self.squeezed(held, self.within_limits(self.q_grasp + basis @ a))  # noqa: E731
        a = np.zeros(len(target))
        f = at_grasp = run(a)  # the same path as every squeeze: the forces at the same time after the grasp
        h = 0.25 * np.maximum(target, 1e-3)
        slope = np.stack([(run(h[i] * np.eye(len(target))[i]) - f) / h[i] for i in range(len(target))], axis=1)
        best, rounds = (np.max(np.abs(f - target) / target), a, f), len(target)
        while rounds < MAX_ROUNDS and best[0] > FORCE_TOL and not self.diverged():
            step = np.linalg.lstsq(slope, target - f, rcond=1e-3)[0]
            step *= min(1.0, 2.0 * np.max(target) / max(np.max(np.abs(step)), 1e-300))
            f_new, rounds = run(a + step), rounds + 1
            err = np.max(np.abs(f_new - target) / target)
            slope += np.outer(f_new - f - slope @ step, step) / max(np.dot(step, step), 1e-300)
            if err < best[0]:
                a, f, best = a + step, f_new, (err, a + step, f_new)
        squeeze = self.within_limits(self.q_grasp + basis @ best[1])
        return {"squeeze": squeeze, "settled": best[2], "rounds": rounds, "grasp_settled": at_grasp}

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
