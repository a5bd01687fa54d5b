"""jaxgrasp.simulate: the grasp in MuJoCo, calibrated to the paper's fingertips (issue 38).

The presets reuse the evaluators compiled for 2 and 3 contacts; the random grasps are
evaluated in one batch (``evaluate_many``) and simulated in one MuJoCo loop. Simulated
times are short: the calibration is checked at the end of a 0.2 s hold started at the
model's equilibrium, long enough for the contact springs (periods of a few ms) to settle.
"""

from __future__ import annotations

import json
import math

import mujoco  # noqa: F401  (the extra jaxgrasp[sim]: CI installs it, so these tests always run there)
import numpy as np
import pytest
from grasp_draws import NumpyDraw, build_grasp

import jaxgrasp
from jaxgrasp.simulation import SimulationStatus, simulate
from jaxgrasp.simulation._scene import Contacts, calibrate

SHORT = dict(hold_time_s=0.2, six_axis_time_s=0.01, kick_scales=(), random_kicks=0)
PRESETS = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(mass=0.1)]
INFEASIBLE = jaxgrasp.presets.cube(young_modulus=1e6, initial_deformation=4e-3)  # pi E dr^2 = 50 N > 15 N


def _random_heavy(count: int):
    rng = np.random.default_rng(3838)
    out = []
    while len(out) < count:
        g = build_grasp(NumpyDraw(rng), n=2 + len(out) % 2)
        if float(g.mass) > 0:
            out.append(g)
    return out


@pytest.fixture(scope="module")
def evaluated(evaluate_many):
    """Every grasp of this module, evaluated in one call: the presets, the infeasible cube,
    60 random grasps with mass (2 and 3 contacts: the evaluators the suite compiles anyway)."""
    pool = _random_heavy(60)
    evs = evaluate_many(PRESETS + [INFEASIBLE] + pool)
    return {"presets": evs[:2], "infeasible": evs[2], "pool": list(zip(pool, evs[3:]))}


def _close(settled, model, rel=0.10):
    settled, model = np.asarray(settled), np.asarray(model)
    return np.all(np.abs(settled - model) <= rel * model), settled / model


def test_calibration_is_eq4_at_both_points():
    """The spring K (x - x0) passes through pi E dr^2 at dr and the model's force at the
    equilibrium deformation (eq. 4), on a pose that changes the deformations."""
    c = Contacts.of(jaxgrasp.presets.prism(mass=0.1))
    cal = calibrate(c, np.array([3e-4, -2e-4, 1e-4]), np.array([0.0, 0.0, 0.01]))
    assert np.allclose(cal["K"] * (c.dr - cal["x0"]), np.pi * c.E * c.dr**2, rtol=1e-12)
    assert np.allclose(cal["K"] * (cal["d_eq"] - cal["x0"]), cal["f_eq"], rtol=1e-12)
    assert not np.allclose(cal["d_eq"], c.dr)


def test_presets_settle_to_the_model_force_and_hold(evaluated):
    """Cube (weightless) and prism (0.1 kg, gravity along its axis): MuJoCo's settled
    normal force is the model's at jaxgrasp's equilibrium within 10 %, and the prism holds
    (< 1 mm); with friction 0.01 the same prism drops."""
    grasps, evs = PRESETS, evaluated["presets"]
    for g, ev in zip(grasps, evs):
        r = simulate(g, evaluation=ev, **SHORT)
        ok, ratio = _close(r.settled_normal_force_N, r.model_normal_force_N)
        assert r.status == SimulationStatus.SIMULATED and ok, ratio
        assert r.hold.success and r.hold.max_displacement_m < 1e-3
    drop = simulate(grasps[1], evaluation=evs[1], friction=0.01, **SHORT)
    assert not drop.hold.success
    assert drop.hold.max_displacement_m > 0.05  # 0.2 s of free fall: 0.196 m, cut at 0.2 m
    assert drop.parameters["friction_sliding"] == [0.01] * 3


def test_random_grasps_with_mass_settle_to_the_model_force(evaluated):
    """20 stable random grasps with mass: every fingertip's settled force within 10 % of
    the model's (one batch evaluation, then one MuJoCo loop)."""
    stable = [(g, ev) for g, ev in evaluated["pool"] if ev.status_name == "stable"][:20]
    assert len(stable) == 20
    worst = []
    for g, ev in stable:
        r = simulate(g, evaluation=ev, **SHORT)
        _, ratio = _close(r.settled_normal_force_N, r.model_normal_force_N)
        worst.append(float(np.max(np.abs(ratio - 1.0))))
    assert max(worst) <= 0.10, worst


def test_infeasible_grasp_is_reported_not_simulated(evaluated):
    """The initial squeeze above the force limit: infeasible, no trial, the reason given."""
    g, ev = INFEASIBLE, evaluated["infeasible"]
    assert ev.status_name == "infeasible"
    r = simulate(g, evaluation=ev)
    assert r.status_name == "infeasible" and not r.simulated
    assert r.hold is None and r.six_axis == () and r.kicks == ()
    assert "infeasible" in r.reason
    assert np.all(np.isnan(r.settled_normal_force_N))


def test_kick_kinetic_energy_is_s_times_the_value(evaluated):
    """0.5 m |v|^2 + 0.5 w^T I w of each kick's initial velocity (the free joint's angular
    velocity is in body axes) is s times the value to 1e-6."""
    g, ev = PRESETS[1], evaluated["presets"][1]
    r = simulate(g, evaluation=ev, hold_time_s=0.05, six_axis_time_s=0.01, kick_time_s=0.01,
                 kick_scales=(0.5, 2.0), random_kicks=1)
    m = r.parameters["mass_kg"]
    inertia = np.asarray(r.parameters["inertia_kg_m2"])
    assert {k.direction for k in r.kicks} == {"least_energy", "random"} and len(r.kicks) == 4
    for k in r.kicks:
        v = np.asarray(k.initial_velocity)
        ke = 0.5 * m * v[:3] @ v[:3] + 0.5 * v[3:] @ inertia @ v[3:]
        assert ke == pytest.approx(k.scale * float(ev.value), rel=1e-6)


def test_results_json_and_plot(run_cli, tmp_path):
    """``jaxgrasp simulate FILE --out DIR``: every field the issue names, and the plot."""
    out = tmp_path / "sim"
    code, stdout, stderr = run_cli(["simulate", "examples/prism.toml", "--mass", "0.1", "--out", str(out),
                                    "--hold-time", "0.05", "--six-axis-time", "0.02", "--kick-time", "0.01",
                                    "--scales", "0.5,2", "--random-kicks", "1"])
    assert code == 0, stderr
    assert "running MuJoCo" in stderr
    assert "six-axis" in stdout and "results.json" in stdout and "\n" not in stdout.strip()
    data = json.loads((out / "results.json").read_text())
    assert (out / "trials.png").read_bytes()[:4] == b"\x89PNG"
    trials = [data["hold"], *data["six_axis"], *data["kicks"]]
    for t in trials:
        assert {"success", "max_displacement_m", "max_rotation_rad", "slipped_contact"} <= set(t)
        assert isinstance(t["success"], bool) and (t["slipped_contact"] is None or isinstance(t["slipped_contact"], int))
    assert [t["axis"] for t in data["six_axis"]] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert {(k["scale"], k["direction"]) for k in data["kicks"]} == {
        (s, d) for s in (0.5, 2.0) for d in ("least_energy", "random")}
    assert len(data["settled_normal_force_N"]) == len(data["model_normal_force_N"]) == 3
    p = data["parameters"]
    assert p["timestep_s"] > 0 and p["condim"] == 4 and p["cone"] == "elliptic"
    assert p["friction_torsional_m"] == pytest.approx(
        [0.5 * 8 / 15 * 0.5 * math.sqrt(0.025**2 - (0.025 - d) ** 2) for d in p["equilibrium_deformation_m"]])


def _no_evaluation(monkeypatch):
    """Make any evaluation fail the test: the options must be checked before it."""
    from jaxgrasp import engine

    def evaluate(*_, **__):
        raise AssertionError("evaluated before the options were checked")

    monkeypatch.setattr(engine, "evaluate", evaluate)  # simulate imports it from the face


@pytest.mark.parametrize("options, mentions", [
    (dict(hold_time_s=-1.0), "hold_time_s must be finite and > 0, got -1"),
    (dict(kick_scales=(-1.0, 2.0)), "kick_scales must be finite and >= 0, got -1"),
    (dict(timestep=10.0), "timestep 10 s is too long: at most 1/100 of the shortest trial (kick_time_s 0.3 s)"),
    (dict(hold_time_s=1e9), "the trials add up to 1e+09 s of simulated time"),
    (dict(timestep=1e-7), "the trials need 1.66e+08 MuJoCo steps (16.6 s at timestep 1e-07 s)"),
], ids=["negative-hold", "negative-scale", "timestep-above-trial", "too-long", "too-many-steps"])
def test_options_are_checked_before_any_evaluation(monkeypatch, options, mentions):
    """Every rule of the options (sign, the timestep against the shortest trial, the caps on
    simulated time and steps) is one line naming the parameter, raised before evaluating."""
    _no_evaluation(monkeypatch)
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        simulate(PRESETS[0], **options)
    assert mentions in str(info.value) and "\n" not in str(info.value)


def test_the_automatic_timestep_is_held_to_the_step_cap():
    """With the automatic timestep the steps are counted once the scene is built; the check
    says the timestep was the automatic one. A timestep of 1/100 of the shortest trial passes."""
    from jaxgrasp.simulation._options import MAX_STEPS, check_options, check_steps

    opts = check_options(kick_scales=(), random_kicks=0, hold_time_s=1.0, six_axis_time_s=1.0)
    check_steps(opts, 8.0 / MAX_STEPS)
    with pytest.raises(jaxgrasp.GraspValueError, match="the automatic timestep 1e-07 s, from the contact stiffness"):
        check_steps(opts, 1e-7)
    assert check_options(kick_scales=(1.0,), random_kicks=0, timestep=0.003)["timestep"] == 0.003


@pytest.mark.parametrize("argv, option", [
    (["--hold-time=-1"], "--hold-time"),
    (["--hold-time", "0"], "--hold-time"),
    (["--kick-time", "0"], "--kick-time"),
    (["--six-axis-time=-2"], "--six-axis-time"),
    (["--scales=-1,2"], "--scales"),
    (["--random-kicks=-1"], "--random-kicks"),
    (["--sim-friction", "0"], "--sim-friction"),
    (["--timestep", "0"], "--timestep"),
    (["--scales", ""], "--scales"),
    (["--scales", "1,,2"], "--scales"),
    (["--timestep", "10"], "--timestep"),
    (["--hold-time", "1e9"], "--hold-time"),
    (["--timestep", "1e-7"], "--timestep"),
])
def test_command_checks_its_options_before_evaluating(monkeypatch, run_cli, tmp_path, argv, option):
    """Bad input: exit 2, one line naming the option (not the library's parameter), before
    the evaluation and MuJoCo, and nothing written."""
    _no_evaluation(monkeypatch)
    out = tmp_path / "sim"
    code, stdout, stderr = run_cli(["simulate", "examples/cube.toml", "--out", str(out), *argv])
    assert code == 2 and stdout == "", stderr
    assert len(stderr.splitlines()) == 1 and stderr.startswith("jaxgrasp: error: "), stderr
    assert option in stderr and "running MuJoCo" not in stderr
    from jaxgrasp.cli._simulate import OPTION_NAMES

    bare = stderr
    for name in OPTION_NAMES.values():
        bare = bare.replace(name, "")
    assert not any(param in bare for param in OPTION_NAMES), stderr  # no hold_time_s, kick_scales ...
    assert not out.exists()
