"""Hand batches (issue 66): many configurations of a hand as one dataset of grasps.

Against `Hand.grasp` and `jaxgrasp.evaluate` of each configuration alone (checked against
brute force and MuJoCo in ``test_grasp.py`` and ``test_kinematics.py``):

* every row of `hand_batch` (joints, wrist and object pose per row) is the grasp
  `Hand.grasp` makes, field for field (1e-12), its ``dr`` and tilt included;
* a row's ``scale`` equals `Hand.grasp` on the mesh scaled by trimesh (1e-12 m), and a mass
  given by density scales as ``s^3``;
* `jaxgrasp.evaluate_batch` of the set gives each grasp's status, limiting contact and
  value (1e-9 relative) with contact ``k`` = fingertip ``k``, also where the fingertips in
  contact are not the first ones;
* a row with fewer than 2 fingertips in contact is invalid with a one-line error;
* ``jaxgrasp batch`` of a hand grasp file of several configurations writes one row per
  configuration in input order with the fingertips' columns.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.hands import hand_batch
from jaxgrasp.model import GraspValueError

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")
trimesh = pytest.importorskip("trimesh")

HANDS = Path(__file__).resolve().parents[2] / "examples" / "hands" / "two_finger"
FIELDS = dict(young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)
Q0 = np.array([0.001, 0.10, 0.05, 0.0005, -0.05, 0.10])
GRASP_FIELDS = ("positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force",
                "mass", "gravity")


@pytest.fixture(scope="module")
def hand():
    # a_proximal's cap never reaches the cube: contacts 1 and 2 touch, contact 0 does not
    return jaxgrasp.Hand.from_mjcf(HANDS / "two_finger.xml", fingertips=["a_proximal", "a_tip", "b_tip"])


@pytest.fixture(scope="module")
def cube():
    return trimesh.creation.box((0.06, 0.06, 0.06))


@pytest.fixture(scope="module")
def configs():
    rng = np.random.default_rng(7)
    q = Q0 + rng.normal(0.0, 1.0, (12, 6)) * [3e-4, 0.02, 0.02, 3e-4, 0.02, 0.02]
    q[3, 0] = -0.01  # finger a pulled back: one fingertip in contact
    wrist = rng.normal(0.0, 1.0, (12, 6)) * [4e-4, 4e-4, 4e-4, 0.01, 0.01, 0.01]
    pose = rng.normal(0.0, 1.0, (12, 6)) * [4e-4, 4e-4, 4e-4, 0.01, 0.01, 0.01]
    return q, wrist, pose


def test_rows_are_the_grasps_each_configuration_makes(hand, cube, configs):
    q, wrist, pose = configs
    hb = hand_batch(hand, cube, q, wrist=wrist, object_pose=pose, **FIELDS)
    columns = hb.grasps.columns()
    for i in range(len(q)):
        hg = hand.grasp(q[i], cube, wrist=wrist[i], object_pose=pose[i], **FIELDS)
        np.testing.assert_array_equal(hb.active[i], np.asarray(hg.active))
        np.testing.assert_allclose(hb.tilt[i], np.asarray(hg.tilt), atol=1e-12)
        for name in GRASP_FIELDS:
            np.testing.assert_allclose(columns.fields[name][i], np.asarray(getattr(hg.grasp, name)), atol=1e-12,
                                       err_msg=f"row {i} {name}")
        on = np.asarray(hg.active)
        np.testing.assert_allclose(hb.dr[i][on], np.asarray(hg.grasp.initial_deformation)[on], atol=1e-15)
        assert np.all(np.isnan(hb.dr[i][~on]))
    assert not hb.active[:, 0].any() and hb.active[:, 1:].sum() > 12  # contact 0 never, the tips mostly


def test_scale_is_the_scaled_mesh_and_density_mass_scales_as_its_cube(hand, cube):
    q = np.stack([Q0, Q0])
    # the fingertips stay put; a cube of 60 mm scaled by 1.05 reaches 1.5 mm further
    hb = hand_batch(hand, cube, q, scale=[1.0, 1.05], density=500.0,
                    **{k: v for k, v in FIELDS.items() if k != "mass"})
    big = cube.copy()
    big.apply_scale(1.05)
    hg = hand.grasp(Q0, big, density=500.0, **{k: v for k, v in FIELDS.items() if k != "mass"})
    on = np.asarray(hg.active)
    np.testing.assert_allclose(hb.dr[1][on], np.asarray(hg.grasp.initial_deformation)[on], atol=1e-12)
    assert hb.dr[1][2] == pytest.approx(hb.dr[0][2] + 0.0015, abs=1e-12)
    mass = hb.grasps.columns().fields["mass"]
    assert mass[1] == pytest.approx(mass[0] * 1.05**3, rel=1e-12)
    assert mass[0] == pytest.approx(500.0 * 0.06**3, rel=1e-12)


def test_batch_evaluation_numbers_contacts_by_fingertip(hand, cube, configs):
    q, wrist, pose = configs
    hb = hand_batch(hand, cube, q, wrist=wrist, object_pose=pose, **FIELDS)
    res = jaxgrasp.evaluate_batch(hb.grasps)
    assert res.status_names[3] == "invalid" and "1 fingertip(s) in contact (b_tip)" in res.errors[3]
    assert "\n" not in res.errors[3]
    checked = 0
    for i in np.flatnonzero(hb.grasps.valid)[:5]:
        one = jaxgrasp.evaluate(hand.grasp(q[i], cube, wrist=wrist[i], object_pose=pose[i], **FIELDS).grasp)
        assert res.status_names[i] == one.status_name
        assert int(res.limiting_contact[i]) == int(one.limiting_contact)
        if one.status_name == "stable":
            assert int(res.limiting_contact[i]) in (1, 2)  # fingertips 1 and 2 touch; numbered as given
            assert float(res.value[i]) == pytest.approx(float(one.value), rel=1e-9)
            checked += 1
    assert checked >= 2


def test_bad_rows_are_one_line(hand, cube):
    with pytest.raises(GraspValueError, match=r"qpos must be \(2, 6\) or \(6,\)"):
        hand_batch(hand, cube, np.zeros((2, 5)), **FIELDS)
    with pytest.raises(GraspValueError, match=r"scale\[1\] = -1.0 must be > 0"):
        hand_batch(hand, cube, np.stack([Q0, Q0]), scale=[1.0, -1.0], **FIELDS)
    with pytest.raises(GraspValueError, match=r"wrist\[0\] = nan must be finite"):
        hand_batch(hand, cube, np.stack([Q0, Q0]), wrist=[np.nan, 0, 0, 0, 0, 0], **FIELDS)


def test_batch_command_takes_a_hand_grasp_file_of_many_configurations(run_cli, tmp_path):
    q = np.stack([Q0, Q0 + [0, 0.02, 0, 0, 0, 0], Q0 - [0.01, 0, 0, 0, 0, 0]])
    text = (HANDS / "pinch.toml").read_text()
    start = text.index("qpos = ")
    text = text[:start] + f"qpos = {q.tolist()}" + text[text.index("\n", start):]
    for name in ("two_finger.xml", "cube.stl"):
        (tmp_path / name).write_bytes((HANDS / name).read_bytes())
    (tmp_path / "many.toml").write_text(text)
    rc, out, err = run_cli(["batch", tmp_path / "many.toml", "--out", tmp_path / "out", "--no-plot", "--quiet"])
    assert rc == 0, err
    assert re.search(r"#1 grasp \d: .* of contact \d \((a_tip|b_tip)\)", out), out  # the fingertip named
    rows = list(csv.DictReader(open(tmp_path / "out" / "results.csv", newline="")))
    assert [r["index"] for r in rows] == ["0", "1", "2"]
    assert [r["active"] for r in rows] == ["2", "2", "1"] and rows[2]["status"] == "invalid"
    hand2 = jaxgrasp.Hand.from_mjcf(HANDS / "two_finger.xml", fingertips=["a_tip", "b_tip"])
    for i in (0, 1):
        hg = hand2.grasp(q[i], HANDS / "cube.stl", units="mm", **FIELDS)
        assert float(rows[i]["dr_0"]) == pytest.approx(float(hg.grasp.initial_deformation[0]), abs=1e-12)
        assert float(rows[i]["value_J"]) == pytest.approx(float(jaxgrasp.evaluate(hg.grasp).value), rel=1e-9)
    assert rows[2]["dr_0"] == "" and rows[2]["in_contact"] == "b_tip"


def test_rows_on_several_meshes_are_each_meshs_grasps(hand, cube):
    long = trimesh.creation.box((0.064, 0.06, 0.06))  # 2 mm nearer each fingertip along x
    q = np.stack([Q0, Q0, Q0])
    hb = hand_batch(hand, [cube, long], q, objects=[1, 0, 1], **FIELDS)
    one = hand_batch(hand, cube, Q0[None], **FIELDS)
    np.testing.assert_allclose(hb.dr[1], one.dr[0], atol=1e-15)
    np.testing.assert_allclose(hb.dr[[0, 2]][:, 1:], one.dr[[0, 0]][:, 1:] + 0.002, atol=1e-12)
    with pytest.raises(GraspValueError, match=r"objects must be \(3,\) indices into the 2 meshes"):
        hand_batch(hand, [cube, long], q, objects=[0, 1, 2], **FIELDS)
