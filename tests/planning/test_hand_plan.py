"""Planning with a hand (`jaxgrasp.planning._hand_plan`, ``jaxgrasp plan --hand``): the two-finger
MJCF test hand on its 60 mm cube.

What must hold whatever the search finds: every ranked grasp is exactly the grasp its
configuration makes (its value is `jaxgrasp.evaluate` of `Hand.grasp` at its qpos and
wrist, as a hand grasp file loads it), within the joint limits, with its links at most
max_penetration deep in the object and in each other (the two fingers' pairs MuJoCo would
collide, `Hand.self_overlap` recomputed) and at least min_fingertips fingertips in contact; ranked best first
by the objective; a seed gives the same plan (the command's, run with the same seed, is the
library's); ``jaxgrasp evaluate DIR/best.toml`` of the command's output is its first row; bad
arguments are one line before any work.
"""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.model import GraspValueError
from jaxgrasp.surface import Surface

HANDS = Path(__file__).resolve().parents[2] / "examples" / "hands"
HAND = HANDS / "two_finger" / "two_finger.xml"
CUBE = HANDS / "two_finger" / "cube.stl"
TIPS = ["a_tip", "b_tip"]
FIELDS = dict(units="mm", young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)
PLAN = dict(samples=64, top=5, refine=1, seed=3)

pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def hand():
    return jaxgrasp.Hand.from_file(HAND, TIPS)


@pytest.fixture(scope="module")
def planned(hand):
    return jaxgrasp.plan(CUBE, hand=hand, progress=lambda *a: None, **PLAN, **FIELDS)


@pytest.mark.slow
def test_ranked_grasps_are_the_grasps_their_configurations_make(hand, planned):
    res = planned
    assert res.candidates == 64 and len(res.grasps) >= 1, res.summary()
    assert res.status_name == "found", res.summary()  # the cube is easy: a pinch across it holds
    for k, (q, w) in enumerate(zip(res.qpos, res.wrist)):
        hg = hand.grasp(q, CUBE, wrist=w, **FIELDS)
        ev = jaxgrasp.evaluate(hg.grasp)
        assert float(ev.value) == res.values[k] and int(ev.status) == res.statuses[k]
        assert hg.num_active == res.active[k] >= 2
        assert np.all(q >= hand.lower - 1e-12) and np.all(q <= hand.upper + 1e-12)
        deepest = float(np.max(np.asarray(hand.link_depths(q, w, np.zeros(6), Surface.from_trimesh(hg.mesh)))))
        assert deepest == pytest.approx(res.penetration[k], abs=1e-12) and deepest <= 1e-3
        overlap = float(np.max(np.asarray(hand.self_overlap(q))))
        assert overlap == pytest.approx(res.self_overlap[k], abs=1e-12) and overlap <= 1e-3
        assert res.epsilon[k] == pytest.approx(jaxgrasp.epsilon(hg.grasp).value, rel=1e-12)
    stable = res.statuses == 0
    assert np.all(np.diff(stable.astype(int)) <= 0)  # stable grasps first
    assert np.all(np.diff(res.values[stable]) <= 0)  # then by value, best first
    assert res.to_dict()["ranked"][0]["qpos"] == res.qpos[0].tolist()


@pytest.mark.slow
def test_the_command_plans_as_the_library_and_best_toml_evaluates_to_its_first_row(hand, planned, tmp_path, capsys):
    from jaxgrasp import cli

    out = tmp_path / "plan"
    argv = ["plan", CUBE, "--units", "mm", "--hand", HAND, "--fingertips", ",".join(TIPS), "--young-modulus", "6e5",
            "--mass", "0.02", "--samples", "64", "--top", "5", "--refine", "1", "--seed", "3", "--out", out]
    assert cli.main([str(a) for a in argv]) == 0
    ranked = [json.loads(line) for line in (out / "ranked.jsonl").read_text().splitlines()]
    # the same seed: the same plan (the command is the library's plan, written)
    assert [r["qpos"] for r in ranked] == planned.qpos.tolist() and [r["wrist"] for r in ranked] == planned.wrist.tolist()
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["value_J"]) for r in rows] == planned.values.tolist()
    assert [int(r["active"]) for r in rows] == planned.active.tolist()
    assert (out / "best.png").stat().st_size > 10_000 and (out / "hand" / "two_finger.xml").is_file()
    capsys.readouterr()
    assert cli.main(["evaluate", str(out / "best.toml"), "--json"]) == 0  # the file reads its copies alone
    ev = json.loads(capsys.readouterr().out)
    assert ev["value"] == float(rows[0]["value_J"]) and ev["status"] == rows[0]["status"]
    bench = jaxgrasp.hands.read_dexgraspbench(out / "dexgraspbench", hand)  # the same grasps in its format
    assert np.allclose(np.asarray(bench.qpos), planned.qpos, atol=1e-12, rtol=0)
    assert np.allclose(np.asarray(bench.wrist), planned.wrist, atol=1e-12, rtol=0)


@pytest.mark.slow
def test_a_second_object_of_one_padded_size_lowers_no_new_program(hand, planned, tmp_path):
    """Many objects planned in one process: once a plan has run, another object whose surface
    pads to the same size reuses every program. Functions jitted anew inside a plan, or
    shapes that follow the mesh, lowered new programs for every object, and the Shadow-hand
    study ran out of memory maps at its 50th object."""
    import jax
    import trimesh

    mesh = trimesh.load(CUBE, force="mesh")
    mesh.apply_scale(1.1)  # 66 mm: another object, the same 12 faces
    path = tmp_path / "cube66.stl"
    mesh.export(path)
    lowered = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/jaxpr_to_mlir_module_duration":  # one per program lowered
            lowered.append(kwargs.get("fun_name", "?"))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        res = jaxgrasp.plan(path, hand=hand, progress=lambda *a: None, **PLAN, **FIELDS)
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert len(res.grasps) >= 1, res.summary()
    assert lowered == []


@pytest.mark.slow
def test_epsilon_ranks_by_epsilon(hand):
    eps = jaxgrasp.plan(CUBE, hand=hand, objective="epsilon", tune_maxiter=5, progress=lambda *a: None, **PLAN,
                        **FIELDS)
    assert len(eps.grasps) >= 1 and eps.settings["objective"] == "epsilon"
    assert np.all(np.diff(eps.epsilon) <= 0) or np.any(eps.active < 3)  # by epsilon (fingertip preference aside)


@pytest.mark.parametrize("kwargs, words", [
    (dict(samples=0), "samples must be an integer >= 1"),
    (dict(min_fingertips=3), "more than the hand's 2 fingertips"),
    (dict(objective="size"), "objective must be one of value, epsilon"),
    (dict(radius=0.01), "radius= is for free fingertips"),
    (dict(fingers=3), "fingers= is for free fingertips"),
    (dict(max_penetration=-1.0), "max_penetration = -1.0 must be a finite number >= 0"),
])
def test_bad_arguments_are_one_line_before_any_work(hand, kwargs, words):
    with pytest.raises(GraspValueError, match=words.replace("(", r"\(").replace(")", r"\)")) as err:
        jaxgrasp.plan(CUBE, hand=hand, progress=lambda *a: None, **{**FIELDS, **kwargs})
    assert "\n" not in str(err.value)


def test_a_hand_file_needs_its_fingertips_and_free_fingertips_need_a_radius():
    with pytest.raises(GraspValueError, match="needs fingertips="):
        jaxgrasp.plan(CUBE, hand=HAND, **FIELDS)
    with pytest.raises(GraspValueError, match=r"radius= \(m, every fingertip's\) is needed without a hand"):
        jaxgrasp.plan(CUBE, **FIELDS)


@pytest.mark.parametrize("extra, words", [
    (["--hand", HAND], "--hand needs --fingertips A,B,C"),
    (["--hand", HAND, "--fingertips", "a_tip,b_tip", "--fingers", "3", "--radius", "0.01"],
     "--fingers, --radius: not used with --hand"),
    (["--hand", HAND, "--fingertips", "a_tip,b_tip", "--gravity", "0,0,9.81"], "a hand grasp file records no gravity"),
    (["--hand", HAND, "--fingertips", "a_tip"], "name at least two"),
    (["--hand", HAND, "--fingertips", "a_tip,b_tip", "--min-fingertips", "3"], "more than the hand's 2 fingertips"),
    (["--fingertips", "a_tip,b_tip"], "--fingertips: for a plan with a hand"),
])
def test_the_command_refuses_bad_hand_options_in_one_line_creating_nothing(extra, words, tmp_path, capsys):
    from jaxgrasp import cli

    out = tmp_path / "plan"
    assert cli.main([str(a) for a in ["plan", CUBE, "--units", "mm", *extra, "--out", out]]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and not out.exists()


def test_two_fingertips_on_one_point_are_never_ranked_not_a_crash():
    # near a mesh corner several fingertip centres share the corner as their closest point: the model refuses
    # such a grasp (two contacts at one position); the planner gives it epsilon 0 and no evaluation
    import dataclasses

    from jaxgrasp.planning._hand_plan import _epsilon, _evaluated

    g = jaxgrasp.presets.cube(6e5, 0.002)
    assert _epsilon(g) > 0
    one_point = dataclasses.replace(g, positions=g.positions.at[1].set(g.positions[0]))
    assert _epsilon(one_point) == 0.0 and _evaluated(one_point) is None
