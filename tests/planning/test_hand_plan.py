"""Planning with a hand (`jaxgrasp.planning._hand_plan`): the URDF test gripper on its 60 mm cube.

What must hold whatever the search finds: every ranked grasp is exactly the grasp its
configuration makes (its value is `jaxgrasp.evaluate` of `Hand.grasp` at its qpos and
wrist, as a hand grasp file loads it), within the joint limits, with its links at most
max_penetration deep and at least min_fingertips fingertips in contact; ranked best first
by the objective; a seed gives the same plan; bad arguments are one line before any work.
"""

from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.model import GraspValueError
from jaxgrasp.surface import Surface

GRIPPER = Path(__file__).resolve().parents[2] / "examples" / "hands" / "urdf_gripper"
PAD = {"link": "b_pad", "center": [0.01, 0.0, 0.0], "axis": [1.0, 0.0, 0.0], "radius": 0.01}
TIPS = ["a_tip", PAD]
FIELDS = dict(units="mm", young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)

pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def hand():
    return jaxgrasp.Hand.from_file(GRIPPER / "gripper.urdf", TIPS)


@pytest.fixture(scope="module")
def planned(hand):
    return jaxgrasp.plan(GRIPPER / "cube.stl", hand=hand, samples=64, top=5, refine=1, tune_maxiter=5, seed=3,
                         progress=lambda *a: None, **FIELDS)


@pytest.mark.slow
def test_ranked_grasps_are_the_grasps_their_configurations_make(hand, planned):
    res = planned
    assert res.candidates == 64 and len(res.grasps) >= 1, res.summary()
    assert res.status_name == "found", res.summary()  # the cube is easy: a pinch across it holds
    for k, (q, w) in enumerate(zip(res.qpos, res.wrist)):
        hg = hand.grasp(q, GRIPPER / "cube.stl", wrist=w, **FIELDS)
        ev = jaxgrasp.evaluate(hg.grasp)
        assert float(ev.value) == res.values[k] and int(ev.status) == res.statuses[k]
        assert hg.num_active == res.active[k] >= 2
        assert np.all(q >= hand.lower - 1e-12) and np.all(q <= hand.upper + 1e-12)
        deepest = float(np.max(np.asarray(hand.link_depths(q, w, np.zeros(6), Surface.from_trimesh(hg.mesh)))))
        assert deepest == pytest.approx(res.penetration[k], abs=1e-12) and deepest <= 1e-3
        assert res.epsilon[k] == pytest.approx(jaxgrasp.epsilon(hg.grasp).value, rel=1e-12)
    stable = res.statuses == 0
    assert np.all(np.diff(stable.astype(int)) <= 0)  # stable grasps first
    assert np.all(np.diff(res.values[stable]) <= 0)  # then by value, best first
    assert res.to_dict()["ranked"][0]["qpos"] == res.qpos[0].tolist()


@pytest.mark.slow
def test_a_seed_gives_the_same_plan_and_epsilon_ranks_by_epsilon(hand, planned):
    again = jaxgrasp.plan(GRIPPER / "cube.stl", hand=hand, samples=64, top=5, refine=1, tune_maxiter=5, seed=3,
                          progress=lambda *a: None, **FIELDS)
    assert np.array_equal(again.qpos, planned.qpos) and np.array_equal(again.values, planned.values)
    eps = jaxgrasp.plan(GRIPPER / "cube.stl", hand=hand, samples=64, top=5, refine=1, tune_maxiter=5, seed=3,
                        objective="epsilon", progress=lambda *a: None, **FIELDS)
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
        jaxgrasp.plan(GRIPPER / "cube.stl", hand=hand, progress=lambda *a: None, **{**FIELDS, **kwargs})
    assert "\n" not in str(err.value)


def test_a_hand_file_needs_its_fingertips_and_free_fingertips_need_a_radius():
    with pytest.raises(GraspValueError, match="needs fingertips="):
        jaxgrasp.plan(GRIPPER / "cube.stl", hand=GRIPPER / "gripper.urdf", **FIELDS)
    with pytest.raises(GraspValueError, match=r"radius= \(m, every fingertip's\) is needed without a hand"):
        jaxgrasp.plan(GRIPPER / "cube.stl", **FIELDS)
