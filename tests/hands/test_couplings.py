"""A hand's joint couplings (issue 67): limited fixed tendons and linear joint equalities.

Against MuJoCo's own numbers and against geometry worked out here:

* the Shadow hand's coupling rows are its 44 limited fixed tendons: ``A @ q`` equals
  MuJoCo's ``data.ten_length`` after ``mj_fwdPosition`` for random ``q`` (1e-12 m), the
  names and ranges ``model.tendon_range``, ``T_FFJ1c`` the coefficients written in
  ``shared.xml``;
* a small hand with a linear joint equality (both joints with a reference angle, so
  ``qpos0`` enters), a one-joint equality, an inactive one, an unlimited fixed tendon, a
  limited spatial one and a tendon of a hinge and a slide: its rows' residual ``A @ q -
  lower`` equals MuJoCo's equality residual ``data.efc_pos`` (1e-12), the tendon row
  MuJoCo's length, and nothing else is read; a quadratic ``polycoef`` is refused in one line;
* `Hand.project_joints` of 1000 configurations drawn within the Shadow hand's limits is
  within the limits exactly and the couplings to 1e-9 (as it is on the small hand with its
  equalities, and on a URDF's ``<mimic>`` joint, which MuJoCo makes a joint equality);
  it returns a strictly feasible configuration bit for bit with the identity
  as its Jacobian, and a configuration outside ``T_FFJ1c`` alone is the orthogonal
  projection onto that tendon's bound, Jacobian ``I - a a^T / |a|^2``; a hand without
  couplings is clipped to its limits;
* `tune_hand` refuses a start outside the couplings (the tuned Shadow configuration of
  ``experiments/tuning/hand_tune.log``, which ``T_FFJ1c`` forbids) in one line naming the
  tendon; from a start on ``T_FFJ1c``'s lower bound its search leaves the coupling (the
  iterates in the box) while every configuration it evaluates, and its result, keeps it.

Cost: the Shadow hand's tune_hand compiles once (slow-marked; about 50 s on 2 cores, then
from the executable store); the rest runs in seconds.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.hands._mjcf import read_model
from jaxgrasp.model import GraspValueError

mujoco = pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")

HANDS = Path(__file__).resolve().parents[2] / "examples" / "hands"
SHADOW = HANDS / "shadow" / "shadow_hand.xml"
SHADOW_TIPS = ["robot0:C_ffdistal", "robot0:C_thdistal"]
# The bunny's tuned Shadow configuration of experiments/tuning/hand_tune.log (also in
# tests/cli/test_hand_files.py): T_FFJ1c = 0.00705 FFJ0 - 0.00805 FFJ1 = 1.57 mm, over its 1 mm.
SHADOW_QPOS = np.array([-0.008907, 0.007548, -0.336287, 0.028614, 1.157035, 1.544184] + [0.0] * 13 + [
    0.841297, 1.000737, -0.208522, 0.504912, -1.562123])

COUPLED = """<mujoco model="coupled">
  <compiler angle="radian"/>
  <worldbody>
    <site name="s0" pos="0 0.02 0"/>
    <body name="a">
      <joint name="a" type="hinge" axis="0 0 1" range="-1 1" ref="0.2"/>
      <geom name="a_link" type="capsule" fromto="0 0 0 0.05 0 0" size="0.01"/>
      <body name="b" pos="0.05 0 0">
        <joint name="b" type="hinge" axis="0 0 1" range="-1.2 0.9" ref="-0.3"/>
        <geom name="b_tip" type="capsule" fromto="0 0 0 0.05 0 0" size="0.01"/>
        <body name="c" pos="0.05 0 0">
          <joint name="c" type="slide" axis="1 0 0" range="-0.02 0.02" ref="0.005"/>
          <geom name="c_tip" type="sphere" size="0.01"/>
          <site name="s1" pos="0 0.01 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="unlimited"><joint joint="a" coef="1"/></fixed>
    <spatial name="spatial" limited="true" range="0 0.2"><site site="s0"/><site site="s1"/></spatial>
    <fixed name="ab" limited="true" range="-0.01 0.02">
      <joint joint="a" coef="0.01"/><joint joint="c" coef="0.5"/>
    </fixed>
  </tendon>
  <equality>
    <joint name="b_of_a" joint1="b" joint2="a" polycoef="0.1 0.5 0 0 0"/>
    <joint name="c_fixed" joint1="c" polycoef="0.003 7 0 0 0"/>
    <joint name="off" joint1="a" joint2="c" polycoef="0 2 0 0 0" active="false"/>
  </equality>
</mujoco>
"""


@pytest.fixture(scope="module")
def shadow():
    """``(hand, model)``: the Shadow hand (fingertips ff and th) and MuJoCo's model of it."""
    tree, model = read_model(SHADOW)
    return jaxgrasp.Hand.of_tree(tree, SHADOW_TIPS), model


@pytest.fixture(scope="module")
def coupled(tmp_path_factory):
    """``(hand, model)``: the small coupled hand of ``COUPLED``."""
    path = tmp_path_factory.mktemp("coupled") / "coupled.xml"
    path.write_text(COUPLED)
    tree, model = read_model(path)
    return jaxgrasp.Hand.of_tree(tree, ["b_tip", "c_tip"]), model


def draws(hand, n: int, seed: int) -> np.ndarray:
    """``(n, J)`` configurations drawn uniformly within the joint limits."""
    return hand.lower + (hand.upper - hand.lower) * np.random.default_rng(seed).random((n, hand.num_joints))


def name_of(model, kind, i: int) -> str:
    return mujoco.mj_id2name(model, kind, i)


def test_shadow_couplings_are_mujocos_tendon_lengths(shadow):
    hand, model = shadow
    t = hand.tree
    assert model.ntendon == 44 and t.num_couplings == 44  # every tendon of shared.xml is fixed and limited
    assert hand.coupling_names == tuple(name_of(model, mujoco.mjtObj.mjOBJ_TENDON, i) for i in range(44))
    np.testing.assert_array_equal(np.stack([t.coupling_lower, t.coupling_upper], axis=1), model.tendon_range)
    row = t.coupling_matrix[hand.coupling_names.index("robot0:T_FFJ1c")]
    ff0, ff1 = hand.joint_names.index("robot0:FFJ0"), hand.joint_names.index("robot0:FFJ1")
    assert row[ff0] == 0.00705 and row[ff1] == -0.00805 and np.count_nonzero(row) == 2  # shared.xml's coefficients
    data = mujoco.MjData(model)
    q = np.concatenate([draws(hand, 20, 0), np.random.default_rng(1).normal(0.0, 2.0, (20, hand.num_joints))])
    for qpos in q:  # within the limits and far outside them
        data.qpos[:] = qpos
        mujoco.mj_fwdPosition(model, data)
        np.testing.assert_allclose(t.coupling_matrix @ qpos, data.ten_length, rtol=0, atol=1e-12)


def test_joint_equality_row_is_mujocos_residual(coupled):
    hand, model = coupled
    t = hand.tree
    assert hand.coupling_names == ("ab", "b_of_a", "c_fixed")  # not the unlimited, spatial or inactive ones
    a, b, c = (hand.joint_names.index(n) for n in "abc")
    np.testing.assert_array_equal(t.coupling_matrix[0], [0.01, 0.0, 0.5])  # a hinge and a slide
    np.testing.assert_array_equal(t.coupling_matrix[1, [a, b, c]], [-0.5, 1.0, 0.0])
    np.testing.assert_array_equal(t.coupling_matrix[2, [a, b, c]], [0.0, 0.0, 1.0])  # one joint: c1 unused (MuJoCo)
    assert np.all(t.coupling_lower[1:] == t.coupling_upper[1:])
    assert model.qpos0[a] == 0.2 and model.qpos0[b] == -0.3  # the references are in the rows' constants
    data = mujoco.MjData(model)
    eq_rows = {"b_of_a": 1, "c_fixed": 2}
    for qpos in np.random.default_rng(2).uniform(-1.0, 1.0, (30, 3)) * [1.0, 1.0, 0.02]:
        data.qpos[:] = qpos
        mujoco.mj_fwdPosition(model, data)
        assert t.coupling_matrix[0] @ qpos == pytest.approx(data.ten_length[2], abs=1e-12)
        eq = np.flatnonzero(data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
        assert len(eq) == 2
        for i in eq:
            k = eq_rows[name_of(model, mujoco.mjtObj.mjOBJ_EQUALITY, int(data.efc_id[i]))]
            assert t.coupling_matrix[k] @ qpos - t.coupling_lower[k] == pytest.approx(data.efc_pos[i], abs=1e-12)
    p = np.asarray(hand.project_joints(draws(hand, 200, 3)))
    assert np.all(p >= hand.lower) and np.all(p <= hand.upper)
    assert np.max(np.asarray(hand.coupling_violation(p))) < 1e-9


MIMIC = """<robot name="mimic">
  <link name="base"><collision><geometry><sphere radius="0.01"/></geometry></collision></link>
  <link name="a"><collision><geometry><sphere radius="0.01"/></geometry></collision></link>
  <link name="b"><collision><geometry><sphere radius="0.01"/></geometry></collision></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="jb" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0.05 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="ja" multiplier="0.5" offset="0.1"/></joint>
</robot>
"""


def test_a_urdf_mimic_joint_is_a_coupling(tmp_path):
    """URDF's ``jb = 0.5 ja + 0.1`` (MuJoCo's joint equality) is the row ``jb - 0.5 ja = 0.1``."""
    path = tmp_path / "mimic.urdf"
    path.write_text(MIMIC)
    tree, _ = read_model(path)
    hand = jaxgrasp.Hand.of_tree(tree, ["a", "b"])
    np.testing.assert_array_equal(tree.coupling_matrix, [[-0.5, 1.0]])
    assert tree.coupling_lower[0] == tree.coupling_upper[0] == pytest.approx(0.1, abs=1e-15)
    p = np.asarray(hand.project_joints(draws(hand, 50, 6)))
    np.testing.assert_allclose(p[:, 1], 0.5 * p[:, 0] + 0.1, rtol=0, atol=1e-9)


def test_a_quadratic_polycoef_is_one_line(tmp_path):
    path = tmp_path / "quadratic.xml"
    path.write_text(COUPLED.replace('polycoef="0.1 0.5 0 0 0"', 'polycoef="0.1 0.5 0.2 0 0"'))
    with pytest.raises(GraspValueError) as info:
        read_model(path)
    text = str(info.value)
    assert "'b_of_a'" in text and "degree 2" in text and "only linear couplings are supported" in text
    assert "\n" not in text


def test_project_joints_reaches_limits_and_couplings_and_keeps_feasible_ones(shadow):
    hand, _ = shadow
    t = hand.tree
    q = draws(hand, 1000, 4)
    assert np.max(np.asarray(hand.coupling_violation(q))) > 1e-3  # most draws are outside T_XXJ1c
    project = jax.jit(hand.project_joints)
    p = np.asarray(project(q))
    assert np.all(p >= hand.lower) and np.all(p <= hand.upper)
    assert np.max(np.asarray(hand.coupling_violation(p))) < 1e-9
    np.testing.assert_allclose(np.asarray(project(p)), p, rtol=0, atol=1e-12)  # the projected ones stay

    # Strictly feasible: between the projections and the middle of the limits, itself
    # within every coupling with room (checked).
    mid = (hand.lower + hand.upper) / 2
    s = t.coupling_matrix @ mid
    assert np.min(np.minimum(s - t.coupling_lower, t.coupling_upper - s)) > 1e-4
    inside = mid + 0.9 * (p - mid)
    assert np.max(np.asarray(hand.coupling_violation(inside))) == 0.0
    np.testing.assert_array_equal(np.asarray(project(inside)), inside)
    np.testing.assert_array_equal(np.asarray(jax.jacobian(hand.project_joints)(inside[0])), np.eye(hand.num_joints))

    # Outside T_FFJ1c alone (every other row and limit with room): the orthogonal projection
    # onto its upper bound, and its Jacobian that projection's matrix.
    k = hand.coupling_names.index("robot0:T_FFJ1c")
    a = t.coupling_matrix[k]
    ff0, ff1 = hand.joint_names.index("robot0:FFJ0"), hand.joint_names.index("robot0:FFJ1")
    out = mid.copy()
    out[ff0], out[ff1] = 1.3, 0.9  # 0.00705 * 1.3 - 0.00805 * 0.9 = 1.92 mm
    over = a @ out - t.coupling_upper[k]
    assert over > 0.0 and np.count_nonzero(np.asarray(hand.coupling_violation(out))) == 1
    expected = out - a * over / (a @ a)
    np.testing.assert_allclose(np.asarray(hand.project_joints(out)), expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(jax.jacobian(hand.project_joints)(out)),
                               np.eye(hand.num_joints) - np.outer(a, a) / (a @ a), rtol=0, atol=1e-12)


def test_a_hand_without_couplings_is_clipped_to_its_limits():
    hand = jaxgrasp.Hand.from_mjcf(HANDS / "two_finger" / "two_finger.xml", fingertips=["a_tip", "b_tip"])
    assert hand.tree.num_couplings == 0 and hand.tree.coupling_matrix.shape == (0, hand.num_joints)
    q = np.random.default_rng(5).normal(0.0, 1.0, (50, hand.num_joints))
    np.testing.assert_array_equal(np.asarray(hand.project_joints(q)), np.clip(q, hand.lower, hand.upper))
    assert np.asarray(hand.coupling_violation(q)).shape == (50, 0)


def test_the_digest_follows_the_couplings(tmp_path):
    """Two hands that differ in one tendon's range only have two digests (tune_hand's key)."""
    one, two = tmp_path / "one.xml", tmp_path / "two.xml"
    one.write_text(COUPLED)
    two.write_text(COUPLED.replace('range="-0.01 0.02"', 'range="-0.01 0.021"'))
    hands = [jaxgrasp.Hand.from_mjcf(p, ["b_tip", "c_tip"]) for p in (one, two)]
    assert hands[0].digest() != hands[1].digest()


def ball_between_tips(hand, qpos, squeeze: float = 1.5e-3):
    """``(ball, pose)``: a sphere between the two fingertips at ``qpos``, pressed ``squeeze`` m at each."""
    trimesh = pytest.importorskip("trimesh")
    c = np.asarray(hand.fingertip_centers(qpos))
    radius = np.linalg.norm(c[0] - c[1]) / 2 - hand.radius[0] + squeeze
    return trimesh.creation.icosphere(subdivisions=3, radius=radius), [*((c[0] + c[1]) / 2).tolist(), 0.0, 0.0, 0.0]


FIELDS = {"young_modulus": 3e5, "friction": 0.8, "max_force": 10.0, "density": 300.0}


def test_tune_hand_refuses_a_start_the_hand_cannot_hold(shadow):
    hand, _ = shadow
    ball, pose = ball_between_tips(hand, SHADOW_QPOS)
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.tune_hand(hand, ball, SHADOW_QPOS, object_pose=pose, **FIELDS)
    text = str(info.value)
    assert "cannot hold" in text and "'robot0:T_FFJ1c' is 0.00157237" in text and "[-0.001, 0.001]" in text
    assert "\n" not in text


@pytest.mark.slow  # compiles the Shadow hand's tune_hand value and gradient where run first (about 50 s on 2 cores)
def test_tune_hand_keeps_the_shadow_hands_couplings(shadow):
    hand, _ = shadow
    t = hand.tree
    k = hand.coupling_names.index("robot0:T_FFJ1c")
    start = SHADOW_QPOS.copy()
    start[2] = 0.0  # FFJ3 (abduction) at -0.336 rad puts the index 12.7 mm inside the middle finger (MuJoCo agrees)
    start[5] = 1.0  # FFJ0: T_FFJ1c = 0.00705 - 0.00805 * 1.157 = -2.3 mm, projected onto its lower bound
    q0 = np.asarray(hand.project_joints(start))
    assert t.coupling_matrix[k] @ q0 == pytest.approx(t.coupling_lower[k], abs=1e-15)
    ball, pose = ball_between_tips(hand, q0)
    lo, hi = hand.lower, hand.upper  # every Shadow joint is limited: the search's box
    searched = []

    def record(iteration, value, u):
        searched.append(np.max(np.asarray(hand.coupling_violation(lo + (hi - lo) * np.asarray(u)[: hand.num_joints]))))

    res = jaxgrasp.tune_hand(hand, ball, q0, object_pose=pose, maxiter=8, callback=record, **FIELDS)
    assert res.value > res.start_value > 0.0
    assert max(searched) > 1e-7, searched  # the search's own iterates leave T_FFJ1c ...
    assert np.all(res.qpos >= lo) and np.all(res.qpos <= hi)
    assert np.max(np.asarray(hand.coupling_violation(res.qpos))) < 1e-9  # ... the configurations evaluated do not
    assert t.coupling_matrix[k] @ res.qpos == pytest.approx(t.coupling_lower[k], abs=1e-9)  # it holds on the bound
    assert res.value == pytest.approx(float(jaxgrasp.evaluate(res.grasp.grasp).value), rel=1e-9)
    assert jaxgrasp.hands.hand_value(hand, res.qpos, ball, object_pose=pose, **FIELDS).value == pytest.approx(
        res.value, rel=1e-9)
