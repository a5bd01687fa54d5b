"""[`simulate`][jaxgrasp.simulate] of a hand grasp under the ``dexgraspbench`` protocol: the whole hand in MuJoCo.

The scene (`jaxgrasp.simulation._hand_scene`), the squeeze calibrated to the model's
normal forces and the six pushes (`jaxgrasp.simulation._hand_trials`), gathered in a
[`SimulationResult`][jaxgrasp.simulation.SimulationResult] whose per-contact arrays are one
per fingertip (``nan`` for a fingertip not in contact).
"""

from __future__ import annotations

import numpy as np

from jaxgrasp.simulation._protocols import DEXGRASPBENCH
from jaxgrasp.simulation._result import AXES, SimulationResult, SimulationStatus
from jaxgrasp.simulation._scene import load_mujoco
from jaxgrasp.simulation._trials import warnings_recorded

__all__ = ["simulate_hand"]

_UNITS = {"friction_torsional_m": "m (MuJoCo's torsional coefficient)", "stiffness_N_m": "N/m along the normal",
          "joint_kp": "N m/rad (hinge) or N/m (slide)", "initial_penetration_m": "m", "timestep_s": "s"}


def _friction(friction, settings) -> tuple[float, float]:
    """``(sliding, torsional m)``: the protocol's, or ``friction`` with the torsional scaled alike."""
    mu, mu_t = settings["friction_sliding"], settings["friction_torsional_m"]
    return (mu, mu_t) if friction is None else (float(friction), mu_t * float(friction) / mu)


def _model_forces(hg, evaluation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(at dr, at the equilibrium, target)``, each ``(F,)`` N, ``nan`` where not in
    contact: eq. 4 at each fingertip's ``dr``; eq. 4 (13, 14) at the evaluation's
    equilibrium (``nan`` without one); the target, the latter where there is one."""
    from jaxgrasp.simulation._scene import Contacts, model_forces

    g = {k: np.asarray(v, dtype=np.float64) for k, v in hg.grasp.to_numpy().items() if k != "active"}
    f = len(g["positions"])
    per = lambda k: np.broadcast_to(g[k], (f,)).copy()  # noqa: E731
    n = g["normals"] / np.linalg.norm(g["normals"], axis=1, keepdims=True)
    c = Contacts(g["positions"], n, per("initial_deformation"), per("radius"), per("young_modulus"),
                 per("friction"), float(g["mass"]), g["gravity"])
    active = np.asarray(hg.active, dtype=bool)
    at_dr = np.where(active, np.pi * c.E * c.dr**2, np.nan)
    if evaluation is not None and int(np.asarray(evaluation.equilibrium_status)) == 0:
        dp = np.asarray(evaluation.equilibrium_translation, dtype=np.float64)
        w = np.asarray(evaluation.equilibrium_rotation, dtype=np.float64)
        at_eq = np.where(active, model_forces(c, dp, w)[2], np.nan)
    else:
        at_eq = np.full(f, np.nan)
    target = np.where(np.isfinite(at_eq) & (at_eq > 0), at_eq, at_dr)
    return at_dr, at_eq, target


def _runner(hg, scene, settings, target):
    """The `HandRunner` with its gains set from the fingertips' stiffness at the grasp."""
    from jaxgrasp.hands import PREGRASP_FACTOR, SQUEEZE_FACTOR
    from jaxgrasp.simulation._hand_trials import HandRunner, gains, pregrasp

    active = np.flatnonzero(np.asarray(hg.active, dtype=bool))
    g = hg.grasp
    points = (np.asarray(g.positions, float) + np.asarray(hg.center_of_mass, float))[active]
    runner = HandRunner(scene, settings, pregrasp(hg.hand, hg.qpos, PREGRASP_FACTOR), np.asarray(hg.qpos, float),
                        active, points, np.asarray(g.normals, float)[active])
    d = runner.data
    d.qpos[:runner.J] = runner.q_grasp
    d.qpos[runner.J:runner.J + 7] = scene.object_start
    load_mujoco().mj_kinematics(scene.model, d)
    load_mujoco().mj_comPos(scene.model, d)
    dr = np.broadcast_to(np.asarray(g.initial_deformation, float), (len(hg.active),))[active]
    stiffness = target[active] / (SQUEEZE_FACTOR * dr)
    jac, jac_n = runner.jacobians()
    other = _idle_jacobian(runner, scene, hg)
    kp = gains(np.concatenate([jac, other]), np.concatenate([jac_n, np.sqrt(np.sum(other**2, axis=1))]),
               np.r_[stiffness, np.full(len(other), np.min(stiffness))], hg.hand.tree.jnt_type == 2)
    runner.set_gains(kp)
    return runner, stiffness, kp


def _idle_jacobian(runner, scene, hg) -> np.ndarray:
    """``(I, 3, J)``: the velocity of each inactive fingertip's centre per unit joint velocity.

    A fingertip the model leaves out (its cylinder, not its cap, meets the object, or it
    does not reach it) is still part of the hand and may touch the object: its joints get
    the gains of a fingertip as stiff as the softest active one (`gains`), so that it
    presses no harder than the model's contacts do, rather than the stiffness of the
    wrist's lever (which would make it press the object out of the hand)."""
    mj, m, d = runner.mujoco, runner.model, runner.data
    idle = np.flatnonzero(~np.asarray(hg.active, dtype=bool))
    pos, rot = runner.object_pose()
    jacp, out = np.zeros((3, m.nv)), np.zeros((len(idle), 3, runner.J))
    for a, i in enumerate(idle):
        mj.mj_jac(m, d, jacp, None, pos + rot @ np.asarray(hg.centers[i], float), int(scene.fingertip_bodies[i]))
        out[a] = jacp[:, :runner.J]
    return out


def simulate_hand(hg, *, evaluation, friction=None, allowed_dirs=None) -> SimulationResult:
    """The [`HandGrasp`][jaxgrasp.hands.HandGrasp] ``hg`` under the ``dexgraspbench`` protocol
    (`jaxgrasp.simulation._protocols`; ``friction``: the sliding coefficient instead of
    its 0.6, the torsional one scaled alike)."""
    from jaxgrasp.simulation._hand_scene import build_hand_scene
    from jaxgrasp.simulation._hand_trials import clear_pregrasp

    settings = DEXGRASPBENCH
    mu = _friction(friction, settings)
    at_dr, at_eq, target = _model_forces(hg, evaluation)
    scene = build_hand_scene(hg, settings, mu, allowed_dirs)
    runner, stiffness, kp = _runner(hg, scene, settings, target)
    active = np.asarray(hg.active, dtype=bool)
    with warnings_recorded():
        runner.reset()
        pene = runner.penetration()
        params = _parameters(settings, mu, scene, stiffness, kp, pene, at_dr, at_eq, active)
        if max(pene) > settings["max_penetration_m"]:
            return _result(hg, evaluation, SimulationStatus.PENETRATING, (), np.full(len(active), np.nan), target,
                           params, f"the hand overlaps the object or itself by {1e3 * max(pene):.3g} mm at the "
                           f"pregrasp, more than the protocol's {1e3 * settings['max_penetration_m']:g} mm")
        runner.q_pre = clear_pregrasp(runner, hg.hand, runner.q_pre)
        cal = runner.calibrate(target[active])
        six = [runner.push(axis, cal["squeeze"], scene.mass) for axis in AXES]
    settled = np.full(len(active), np.nan)
    settled[active] = cal["settled"]
    params.update(squeeze_rounds=cal["rounds"], squeeze_qpos=[float(x) for x in cal["squeeze"]],
                  pregrasp_qpos=[float(x) for x in runner.q_pre])
    bad = [t for t in six if t.diverged]
    status = SimulationStatus.DIVERGED if bad else SimulationStatus.SIMULATED
    reason = f"MuJoCo diverged in {len(bad)} of 6 pushes (first: {bad[0].name})" if bad else ""
    return _result(hg, evaluation, status, tuple(six), settled, target, params, reason)


def _result(hg, evaluation, status, six, settled, target, params, reason) -> SimulationResult:
    value = float(np.asarray(evaluation.value)) if evaluation is not None else float("nan")
    return SimulationResult(status=status, grasp_status=evaluation.status_name if evaluation is not None else "",
                            value=value, reason=reason, hold=None, six_axis=six, kicks=(),
                            settled_normal_force_N=settled, model_normal_force_N=target, parameters=params,
                            protocol="dexgraspbench")


def _parameters(settings, mu, scene, stiffness, kp, pene, at_dr, at_eq, active) -> dict:
    lst = lambda a: [float(x) for x in np.asarray(a).reshape(-1)]  # noqa: E731
    spread = np.full(len(active), np.nan)
    spread[active] = stiffness
    return {
        "protocol": "dexgraspbench",
        **{k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.items()},
        "friction_sliding": mu[0], "friction_torsional_m": mu[1],
        "simulator": f"MuJoCo {load_mujoco().__version__}",
        "mass_kg": float(scene.mass), "convex_pieces": int(scene.pieces), "convex_from": scene.convex,
        "initial_penetration_m": {"hand_object": float(pene[0]), "hand_hand": float(pene[1])},
        "normal_force_at_dr_N": [x if np.isfinite(x) else None for x in lst(at_dr)],
        "normal_force_at_equilibrium_N": [x if np.isfinite(x) else None for x in lst(at_eq)],
        "stiffness_N_m": [x if np.isfinite(x) else None for x in lst(spread)],
        "joint_kp": lst(kp), "units": _UNITS,
    }
