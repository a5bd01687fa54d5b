"""jaxgrasp.simulate: the grasp in MuJoCo, calibrated to the paper's fingertips (issue 38).

The presets reuse the evaluators compiled for 2 and 3 contacts; the random grasps are
evaluated in one batch (``evaluate_many``) and simulated in one MuJoCo loop. Simulated
times are short: the calibration is checked at the end of a 0.2 s hold started at the
model's equilibrium, long enough for the contact springs (periods of a few ms) to settle.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import mujoco  # noqa: F401  (the extra jaxgrasp[sim]: CI installs it, so these tests always run there)
import numpy as np
import pytest
from grasp_draws import NumpyDraw, build_grasp

import jaxgrasp
from jaxgrasp.simulation import SimulationStatus, simulate
from jaxgrasp.simulation._scene import Contacts, calibrate

ROOT = Path(__file__).resolve().parents[2]
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
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
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
    assert data["status"] == "simulated" and "diverged" not in stdout  # ordinary kicks: nothing diverges
    assert all(t["diverged"] is False and t["simulator_warnings"] == {} for t in trials)


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
    (["--scales", "2,1e12,1e20,1e300"], "--scales 1e+12 is too large"),  # issue 65: the kicks reported held
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


# ----------------------------------------------------------------- diverged states (issue 65, item 5)

def test_a_kick_of_1e20_times_the_value_is_refused_before_evaluating(monkeypatch):
    """The issue's kicks (1e20 and 1e300 times the value: 2e10 and 2e150 m/s) were reported
    held: a scale above ``MAX_KICK_SCALE`` is one line naming the limit, before evaluating."""
    from jaxgrasp.simulation._limits import MAX_KICK_SCALE

    _no_evaluation(monkeypatch)
    for scales in [(2.0, 1e20), (1e300,), (MAX_KICK_SCALE * 1.001,)]:
        with pytest.raises(jaxgrasp.GraspValueError) as info:
            simulate(PRESETS[1], kick_scales=scales)
        assert "times the value is beyond what the simulator integrates; at most 1e+06" in str(info.value)
        assert "\n" not in str(info.value)


def test_a_kick_faster_than_a_fingertip_radius_per_step_is_refused_before_any_trial(evaluated, monkeypatch):
    """Below ``MAX_KICK_SCALE`` the speed decides: on the prism at 0.1 kg (automatic
    timestep 0.32 ms) a kick of 1e6 times the value moves the contacts 3.2 cm per step,
    more than the fingertip's 2.5 cm: refused once the scene is built, before the hold, with
    the largest scale that fits."""
    from jaxgrasp.simulation import _trials

    def no_trial(*_, **__):
        raise AssertionError("a trial ran before the kicks were checked")

    monkeypatch.setattr(_trials.Runner, "run", no_trial)
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        simulate(PRESETS[1], evaluation=evaluated["presets"][1], kick_scales=(2.0, 1e6), **{
            k: v for k, v in SHORT.items() if k not in ("kick_scales",)})
    text = str(info.value)
    assert text.startswith("a kick of 1e+06 times the value moves the contacts 0.03") and "\n" not in text, text
    assert "at most 1 fingertip radius (0.025 m) per step: use scales up to 6." in text, text


def test_the_travel_check_counts_rotation_at_the_contacts_reach():
    """``|v| + |w| R`` per timestep against ``MAX_KICK_TRAVEL`` radii: exactly at the limit
    passes, a hair above (by translation or by rotation) is refused."""
    from jaxgrasp.simulation._options import check_kick_travel

    dt, r, reach = 1e-3, 0.02, 0.05
    check_kick_travel([(1.0, [20.0, 0, 0, 0, 0, 0]), (1.0, [0, 0, 0, 0, 0, 400.0])], dt, r, reach)
    for v in ([20.001, 0, 0, 0, 0, 0], [10.0, 0, 0, 200.1, 0, 0], [np.nan, 0, 0, 0, 0, 0]):
        with pytest.raises(jaxgrasp.GraspValueError, match="per step: use scales up to"):
            check_kick_travel([(4.0, v)], dt, r, reach)


def test_the_issues_1e20_kick_is_diverged_never_held(evaluated):
    """The trial itself, past the option checks: MuJoCo resets the issue's 1e20 kick
    (and a 1e12 one, also reported held before) to its start, which looked held (0.13 mm);
    the runner reads MuJoCo's warnings and reports it diverged, never a success."""
    from jaxgrasp.simulation._scene import build_scene
    from jaxgrasp.simulation._simulate import _directions
    from jaxgrasp.simulation._trials import Runner, warnings_recorded

    g, ev = PRESETS[1], evaluated["presets"][1]
    scene = build_scene(g, g, np.asarray(ev.equilibrium_translation), np.asarray(ev.equilibrium_rotation),
                        nominal_mass=0.1, damping_ratio=0.05)
    runner = Runner(scene, 0.5 * scene.contacts.mu * scene.calibration["d_eq"], 0.005)  # simulate's thresholds
    start = runner.start_state()
    value = float(ev.value)
    directions = _directions(ev, 2, 0, scene)  # the command's: least-energy, 2 random
    kicks = [(1e20, kind, d) for kind, d in directions] + [(1e12, kind, d) for kind, d in directions[1:]]
    for scale, kind, direction in kicks:
        with warnings_recorded():  # as simulate runs them: no MUJOCO_LOG.TXT in the working directory
            kick = runner.kick(start, direction, scale * value, 0.05, scale, kind)
        assert kick.diverged and not kick.success, (scale, kind, kick.simulator_warnings)
        assert set(kick.simulator_warnings) & {"mjWARN_BADQACC", "mjWARN_BADQVEL", "mjWARN_BADQPOS"}
        assert kick.label.endswith("(diverged)") and kick.to_dict()["diverged"] is True
    calm = runner.kick(start, directions[1][1], 2.0 * value, 0.05, 2.0, "random")
    assert not calm.diverged and calm.simulator_warnings == {} and calm.success


BLOWS_UP = dict(hold_time_s=0.3, six_axis_time_s=0.3, kick_time_s=0.3, kick_scales=(1e-9,), random_kicks=0,
                timestep=3e-3)
"""A 1 ug prism on its calibrated springs with a 3 ms step (omega dt ~ 300): the springs'
integration blows up in the hold, at a kick far below both kick limits."""


def test_a_state_that_blows_up_below_the_limits_is_reported_diverged():
    """Every option within its limits and the kick tiny, yet MuJoCo meets accelerations
    beyond its limits (its warning) and resets the state: the hold is diverged, not held,
    the result's status is ``diverged`` with the reason, and no trial starts from the
    reset state."""
    g = jaxgrasp.presets.prism(mass=1e-9)
    r = simulate(g, **BLOWS_UP)
    assert r.status == SimulationStatus.DIVERGED and r.status_name == "diverged" and r.simulated
    assert r.hold.diverged and not r.hold.success and "mjWARN_BADQACC" in r.hold.simulator_warnings
    assert r.six_axis == () and r.kicks == () and r.diverged == (r.hold,)
    assert np.all(np.isnan(r.settled_normal_force_N))
    assert r.reason.startswith("MuJoCo diverged in 1 of 1 trials (first: hold, mjWARN_BADQACC x"), r.reason
    assert "hold: diverged" in r.summary()
    d = r.to_dict()
    assert d["status"] == "diverged" and d["hold"]["diverged"] is True and d["hold"]["success"] is False


def test_the_command_says_diverged(run_cli, tmp_path, monkeypatch):
    """``jaxgrasp simulate`` of the same: results.json's status ``diverged``, the summary
    line says so (never 'held'), the picture is drawn; MuJoCo's own handler (which prints
    and appends to ``MUJOCO_LOG.TXT`` in the working directory) is kept out."""
    out = tmp_path / "sim"
    monkeypatch.chdir(tmp_path)  # where MuJoCo's own handler would write its log
    code, stdout, stderr = run_cli(["simulate", ROOT / "examples/prism.toml", "--mass", "1e-9", "--out", str(out),
                                    "--hold-time", "0.3", "--six-axis-time", "0.3", "--kick-time", "0.3",
                                    "--scales", "1e-9", "--random-kicks", "0", "--timestep", "3e-3"])
    assert code == 0, stderr
    assert "; hold diverged (" in stdout and "; diverged: MuJoCo diverged in 1 of 1 trials" in stdout, stdout
    assert "held" not in stdout.replace("not held", ""), stdout
    data = json.loads((out / "results.json").read_text())
    assert data["status"] == "diverged" and data["hold"]["diverged"] and not data["hold"]["success"]
    assert (out / "trials.png").read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
