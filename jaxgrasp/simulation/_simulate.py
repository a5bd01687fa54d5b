"""[`simulate`][jaxgrasp.simulate]: a grasp in MuJoCo, held, disturbed along six axes and kicked.

* hold: ``hold_time_s`` under gravity from the equilibrium pose; success if the object
  moves less than ``hold_tolerance_m`` and turns less than ``hold_tolerance_rad``; its end
  is the settled state the other trials start from, and the mean normal forces over its
  last quarter are the settled forces;
* six-axis (DexGraspBench's protocol): a force ``m * disturbance_acceleration_m_s2`` along
  each of ``+x ... -z`` for ``six_axis_time_s``, gravity on; success if the object moves
  less than ``six_axis_tolerance_m`` (5 cm) and turns less than ``six_axis_tolerance_rad``
  (15 degrees);
* energy kicks: the object's initial velocity with kinetic energy ``s * value`` for each
  ``s`` of ``kick_scales``, along the least-energy boundary's direction (from the
  equilibrium to `boundary_translation` and ``_rotation`` of
  the limiting boundary) and ``random_kicks`` random directions; success if no contact
  slides more than its slip threshold within ``kick_time_s`` (no kicks where the value is 0).

Every kick's velocity is known before the first trial: a scale whose kick MuJoCo could not
integrate (`check_kick_travel`) is refused then. A trial in which MuJoCo still met a state
beyond its limits is reported diverged (`Trial.diverged`), the result's status
``DIVERGED``; where the hold diverged no other trial runs (no settled state to start from).
"""

from __future__ import annotations

import math

import numpy as np

from jaxgrasp.model import GraspValueError
from jaxgrasp.simulation._options import check_kick_travel, check_number, check_options, check_steps
from jaxgrasp.simulation._protocols import check_protocol
from jaxgrasp.simulation._result import SimulationResult, SimulationStatus
from jaxgrasp.simulation._scene import IMPEDANCE, build_scene, load_mujoco
from jaxgrasp.simulation._trials import Runner, least_energy_direction, warnings_recorded

__all__ = ["simulate"]

_UNITS = {
    "timestep_s": "s", "stiffness_N_m": "N/m", "spring_offset_m": "m (force zero at this penetration)",
    "damping_N_s_m": "N s/m", "friction_torsional_m": "m (mu e, eq. 10)", "slip_threshold_m": "m",
}


def simulate(
    grasp, *, evaluation=None, friction=None, nominal_mass=0.1, damping_ratio=0.05, timestep=None,
    kick_scales=(0.5, 0.9, 1.1, 2.0), random_kicks=2, seed=0, simulate_unstable=False, slip_threshold=None,
    protocol="jaxgrasp", allowed_dirs=None, **durations,
) -> SimulationResult:
    """A second opinion from MuJoCo: the grasp held, disturbed and kicked in a physics engine.

    ``protocol="dexgraspbench"``: a hand grasp's whole hand (`_dexgraspbench`). Else (a hand
    grasp as its fingertip contacts) the scene (`jaxgrasp.simulation._scene`): the object (its mesh, or the contacts'
    hull) at jaxgrasp's equilibrium pose, each fingertip a sphere fixed at ``p_i + (r -
    dr_i) n_i``, condim 4, elliptic cones, friction ``mu`` and ``mu e_i`` (eq. 9, 10), normal
    springs through eq. 4 at ``dr`` and at the equilibrium, gravity. The trials (module
    doc): hold, six-axis (DexGraspBench: ``m * 10 m/s^2`` along ``+x ... -z``, success below
    5 cm and 15 degrees), and energy kicks of kinetic energy ``s * value`` along the
    least-energy boundary's direction and random ones (success: no contact slips).

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp], [`MeshGrasp`][jaxgrasp.MeshGrasp] or [`HandGrasp`][jaxgrasp.hands.HandGrasp] (SI units).
        evaluation: its [`Evaluation`][jaxgrasp.Evaluation] (default: [`jaxgrasp.evaluate`][jaxgrasp.evaluate]).
        friction: the simulator's friction coefficient instead of the grasp's (a what-if).
        nominal_mass: kg, the simulated mass of a weightless grasp (mass 0: no gravity).
        damping_ratio: of each contact's normal spring against the object's mass (light:
            the paper's model has no damping at all).
        timestep: s, at most 1/100 of the shortest trial (default: resolves the stiffest contact mode).
        kick_scales: the ``s`` of the energy kicks, each ``>= 0`` and at most
            ``_limits.MAX_KICK_SCALE``; a scale whose kick would move the contacts more
            than ``_limits.MAX_KICK_TRAVEL`` fingertip radii per timestep is refused once
            the scene is built, before any trial (beyond what MuJoCo integrates).
        random_kicks: random directions per scale; ``seed`` seeds them.
        simulate_unstable: also simulate unstable and not-converged grasps (from their
            equilibrium pose); infeasible grasps are never simulated.
        slip_threshold: m, the sliding that counts as a slip (default per contact
            ``mu_i d_i / 2``: the tangential deformation at which the paper's fingertip
            starts to slip without torsion, eq. 6 and 9).
        **durations: any of `DEFAULTS` (s, m, rad, m/s^2); all trials
            together at most ``_limits.MAX_SIMULATED_S`` and ``_limits.MAX_STEPS`` steps.

    Returns:
        A [`SimulationResult`][jaxgrasp.simulation.SimulationResult]; its ``parameters`` hold every
        parameter, the timestep and the calibration. Status ``diverged`` where MuJoCo met
        a state beyond its limits in some trial (those trials are never a success).

    Raises:
        ImportError: MuJoCo is not installed (one line: ``pip install "jaxgrasp[sim]"``).
        GraspValueError: a bad grasp or option (one line naming it; options before evaluating).
    """
    load_mujoco()
    grasp = _for_protocol(grasp, check_protocol(protocol))
    if protocol == "dexgraspbench":
        return _dexgraspbench(grasp, evaluation, friction, allowed_dirs, timestep, durations)
    opts = check_options(friction=friction, nominal_mass=nominal_mass, damping_ratio=damping_ratio, timestep=timestep,
                         kick_scales=kick_scales, random_kicks=random_kicks, **durations)
    slip_threshold = None if slip_threshold is None else check_number("slip_threshold", slip_threshold)
    plain = _one_grasp(grasp)
    evaluation = _evaluated(plain, evaluation)
    skip = _skip_status(evaluation, simulate_unstable)
    if skip is not None:
        return _not_simulated(plain, evaluation, skip, opts)
    return _simulated(grasp, plain, evaluation, opts, seed, slip_threshold)


def _evaluated(plain, evaluation):
    """``evaluation``, or [`jaxgrasp.evaluate`][jaxgrasp.evaluate] of ``plain`` where it is ``None``."""
    if evaluation is not None:
        return evaluation
    from jaxgrasp.engine import evaluate

    return evaluate(plain)


def _for_protocol(grasp, protocol: str):
    """``grasp``, or a hand grasp's fingertip contacts under the jaxgrasp protocol; a
    one-line error for a plain grasp under ``dexgraspbench``."""
    from jaxgrasp.hands import HandGrasp

    if isinstance(grasp, HandGrasp):
        return grasp if protocol == "dexgraspbench" else grasp.mesh_grasp()
    if protocol == "dexgraspbench":
        raise GraspValueError(f"the dexgraspbench protocol simulates a hand: give a jaxgrasp.hands.HandGrasp "
                              f"(jaxgrasp.hands.load_hand_grasp), got {type(grasp).__name__}")
    return grasp


def _dexgraspbench(hg, evaluation, friction, allowed_dirs, timestep, durations) -> SimulationResult:
    """The hand grasp ``hg`` under DexGraspBench's protocol (`jaxgrasp.simulation._hand_simulate`):
    its whole hand (MJCF; a URDF hand is refused) under the benchmark's settings, squeezed
    to the model's normal forces (eq. 4) and pushed along six axes. Every grasp is
    simulated (``simulate_unstable`` has no part); ``friction`` replaces the protocol's
    sliding friction (its torsional one scaled alike); ``allowed_dirs``: the folders the
    hand's files may lie in besides its own (as for [`Hand.from_file`][jaxgrasp.Hand.from_file]);
    the jaxgrasp protocol's ``timestep`` and durations are refused."""
    from jaxgrasp.simulation._hand_simulate import simulate_hand

    given = [*sorted(durations), *(["timestep"] if timestep is not None else [])]
    if given:
        raise GraspValueError(f"{given[0]} is an option of the jaxgrasp protocol; the dexgraspbench protocol runs "
                              "with its own settings")
    if hg.num_active < 1:
        raise GraspValueError("the hand grasp has no fingertip in contact: nothing to squeeze")
    friction = None if friction is None else check_number("friction", friction)
    return simulate_hand(hg, evaluation=_evaluated(hg.grasp, evaluation), friction=friction, allowed_dirs=allowed_dirs)


def _one_grasp(grasp):
    """The plain grasp of ``grasp`` (a Grasp or MeshGrasp of one grasp), compacted."""
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.model import Grasp

    if not isinstance(grasp, (Grasp, MeshGrasp)):
        raise GraspValueError(f"simulate needs a jaxgrasp.Grasp or MeshGrasp, got {type(grasp).__name__}")
    plain = (grasp.grasp if isinstance(grasp, MeshGrasp) else grasp).compact()
    if np.ndim(plain.positions) != 2:
        raise GraspValueError(f"simulate takes one grasp, got positions of shape {np.shape(plain.positions)}")
    return plain


def _skip_status(evaluation, simulate_unstable: bool):
    """The [`SimulationStatus`][jaxgrasp.simulation.SimulationStatus] that keeps the grasp out of the simulator, or ``None``."""
    name = evaluation.status_name
    if name == "stable":
        return None
    if name == "infeasible" or int(np.asarray(evaluation.equilibrium_status)) != 0:
        return SimulationStatus.INFEASIBLE if name == "infeasible" else SimulationStatus.NOT_CONVERGED
    if simulate_unstable:
        return None
    return SimulationStatus.UNSTABLE if name == "unstable" else SimulationStatus.NOT_CONVERGED


def _not_simulated(plain, evaluation, status, opts) -> SimulationResult:
    n = plain.num_contacts
    return SimulationResult(
        status=status, grasp_status=evaluation.status_name, value=float(np.asarray(evaluation.value)),
        reason=evaluation.explain(), hold=None, six_axis=(), kicks=(), settled_normal_force_N=np.full(n, np.nan),
        model_normal_force_N=np.full(n, np.nan), parameters={k: v for k, v in opts.items()},
    )


def _directions(evaluation, count: int, seed: int, scene) -> list[tuple[str, np.ndarray]]:
    """The kick directions: the least-energy one (where there is a limiting boundary) and
    ``count`` random ones (rotation components scaled by the radius of gyration)."""
    out = []
    least = least_energy_direction(evaluation)
    if least is not None:
        out.append(("least_energy", least))
    rng = np.random.default_rng(seed)
    gyration = math.sqrt(float(np.trace(scene.inertia)) / (3.0 * scene.sim_mass))
    for _ in range(count):
        z = rng.normal(size=6)
        out.append(("random", np.concatenate([z[:3], z[3:] / gyration])))
    return out


def _kicks(runner, evaluation, opts, seed, scene, value) -> list[tuple[float, str, np.ndarray]]:
    """``(scale, kind, direction)`` of every kick, checked against `check_kick_travel` at
    the start pose (a free body's kinetic energy does not depend on its pose), before any
    trial runs."""
    if value <= 0:  # no energy to scale: no kicks
        return []
    kicks = [(s, kind, d) for s in opts["kick_scales"]
             for kind, d in _directions(evaluation, opts["random_kicks"], seed, scene)]
    start = runner.start_state()
    c = scene.contacts
    check_kick_travel([(s, runner.kick_velocity(start, d, s * value)) for s, _, d in kicks], scene.timestep,
                      float(np.min(c.r)), float(np.max(np.linalg.norm(c.p, axis=1))))
    return kicks


def _simulated(grasp, plain, evaluation, opts, seed, slip_threshold) -> SimulationResult:
    dp = np.asarray(evaluation.equilibrium_translation, dtype=np.float64)
    w = np.asarray(evaluation.equilibrium_rotation, dtype=np.float64)
    scene = build_scene(grasp, plain, dp, w, friction=opts["friction"], nominal_mass=opts["nominal_mass_kg"],
                        damping_ratio=opts["damping_ratio"], timestep=opts["timestep"])
    check_steps(opts, scene.timestep)  # the automatic timestep is known now, before any trial
    cal, c = scene.calibration, scene.contacts
    thresholds = (0.5 * c.mu * np.clip(cal["d_eq"], 0.0, None) if slip_threshold is None
                  else np.full(len(c.r), slip_threshold))
    runner = Runner(scene, thresholds, opts["sample_s"])
    value = float(np.asarray(evaluation.value))
    with warnings_recorded():  # MuJoCo's warnings are read from its counters (the trials' records)
        kicks = _kicks(runner, evaluation, opts, seed, scene, value)
        hold, six, done, settled = _trials(runner, opts, kicks, value)
    status, reason = _divergence([hold, *six, *done])
    return SimulationResult(
        status=status, grasp_status=evaluation.status_name, value=value, reason=reason,
        hold=hold, six_axis=tuple(six), kicks=tuple(done), settled_normal_force_N=settled,
        model_normal_force_N=cal["f_eq"], parameters=_parameters(opts, scene, thresholds),
    )


def _trials(runner, opts, kicks, value):
    """``(hold, six-axis trials, kicks, settled forces)``; where the hold diverged, no other
    trial (it leaves no settled state to start from)."""
    hold, state, settled = runner.hold(opts["hold_time_s"], opts["hold_tolerance_m"], opts["hold_tolerance_rad"])
    if hold.diverged:
        return hold, [], [], settled
    six = runner.six_axis(state, opts["disturbance_acceleration_m_s2"], opts["six_axis_time_s"],
                          opts["six_axis_tolerance_m"], opts["six_axis_tolerance_rad"])
    done = [runner.kick(state, d, s * value, opts["kick_time_s"], s, kind) for s, kind, d in kicks]
    return hold, six, done, settled


def _divergence(trials) -> tuple[SimulationStatus, str]:
    """``(status, reason)`` of the simulated trials: ``DIVERGED`` and which trials, with
    MuJoCo's warnings, where any diverged; else ``SIMULATED`` and ``""``."""
    bad = [t for t in trials if t.diverged]
    if not bad:
        return SimulationStatus.SIMULATED, ""
    said = ", ".join(f"{k} x{n}" for k, n in bad[0].simulator_warnings.items()) or "a state that is not finite"
    rest = " (no other trial: the hold left no settled state)" if trials[0].diverged else ""
    return SimulationStatus.DIVERGED, (
        f"MuJoCo diverged in {len(bad)} of {len(trials)} trials (first: {bad[0].name}, {said}): its state went "
        f"beyond the simulator's limits and was reset; those trials are not held{rest}")


def _parameters(opts, scene, thresholds) -> dict:
    cal, c = scene.calibration, scene.contacts
    lst = lambda a: [float(x) for x in np.asarray(a).reshape(-1)]
    return {
        **{k: v for k, v in opts.items() if k != "timestep"},
        "timestep_s": float(scene.timestep),
        "simulator": f"MuJoCo {load_mujoco().__version__}",
        "mass_kg": float(scene.sim_mass),
        "gravity_m_s2": lst(scene.sim_gravity),
        "inertia_kg_m2": [lst(row) for row in scene.inertia],
        "contact_surfaces": list(scene.surfaces),
        "condim": 4,
        "cone": "elliptic",
        "noslip_iterations": int(scene.model.opt.noslip_iterations),
        "impedance": IMPEDANCE,
        "friction_sliding": lst(cal["mu"]),
        "friction_torsional_m": lst(cal["mu"] * cal["e"]),
        "stiffness_N_m": lst(cal["K"]),
        "spring_offset_m": lst(cal["x0"]),
        "damping_N_s_m": lst(scene.damping),
        "initial_deformation_m": lst(c.dr),
        "initial_normal_force_N": lst(cal["f0"]),
        "equilibrium_deformation_m": lst(cal["d_eq"]),
        "slip_threshold_m": lst(thresholds),
        "units": _UNITS,
    }
