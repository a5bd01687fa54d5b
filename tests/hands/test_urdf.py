"""Hands from URDF and fingertips on links (issue 66, item 4).

The gripper of ``examples/hands/urdf_gripper/`` (written for these tests: prismatic,
revolute and continuous joints, fixed joints to tip links, a sphere tip named by its
link, a mesh tip named as a ROS ``package://`` path and given as its link plus a
hemisphere):

* its fingertip centres and every body frame equal MuJoCo's own kinematics of the same
  URDF (MuJoCo reading the file and its mesh itself, ``mj_kinematics``; the sphere's
  centre is MuJoCo's geom position, the hemisphere's the link's frame applied to the
  centre the test gives) within 1e-9 m at random configurations, with and without a wrist;
* the mesh-fingertip hand evaluates: at ``qpos = 0`` both tips press 2 mm into the 60 mm
  cube (by construction) and the grasp is stable with a positive value;
* the geoms of a link fingertip are not among the links kept out of the object; visual
  meshes are never read (the gripper's is missing); ``package://`` paths resolve in the
  URDF's folder or an ancestor named as the package, or in allowed folders, and nowhere
  else; relative and ``file://`` paths too;
* a hand grasp file names a URDF with ``model =`` and a hemisphere as an inline table.

The hostile URDF files are in ``test_hostile_hands.py``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import GraspValueError
from jaxgrasp.hands import load_hand_grasp
from jaxgrasp.model._potential import rotation_matrix

mujoco = pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")

GRIPPER = Path(__file__).resolve().parents[2] / "examples" / "hands" / "urdf_gripper"
PAD = {"link": "b_pad", "center": [0.01, 0.0, 0.0], "axis": [1.0, 0.0, 0.0], "radius": 0.01}
TIPS = ["a_tip", PAD]
FIELDS = dict(units="mm", young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)


@pytest.fixture(scope="module")
def hand():
    return jaxgrasp.Hand.from_file(GRIPPER / "gripper.urdf", TIPS)


def mujoco_reference(tmp_path, qpos, wrist):
    """``(tips (2, 3), body xpos (B, 3))`` from MuJoCo reading the gripper's URDF and mesh
    itself (a copy told where the meshes are and to keep fixed links as bodies)."""
    folder = tmp_path / "urdf_gripper"
    if not folder.exists():
        shutil.copytree(GRIPPER, folder)
        text = (folder / "gripper.urdf").read_text()
        (folder / "ref.urdf").write_text(text.replace("</robot>", '<mujoco><compiler meshdir="meshes" strippath="true" fusestatic="false" '
                                                      'discardvisual="true" boundmass="1e-6" boundinertia="1e-12"/>'
                                                      "</mujoco></robot>"))
    model = mujoco.MjModel.from_xml_path(str(folder / "ref.urdf"))
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    body = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i): i for i in range(model.nbody)}
    sphere = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body["a_tip"]]
    pad = body["b_pad"]
    tips = np.stack([data.geom_xpos[sphere[0]], data.xpos[pad] + data.xmat[pad].reshape(3, 3) @ PAD["center"]])
    xpos = data.xpos.copy()
    if wrist is not None:
        rot = np.asarray(rotation_matrix(np.asarray(wrist[3:])))
        tips, xpos = tips @ rot.T + wrist[:3], xpos @ rot.T + wrist[:3]
    return tips, xpos


def test_fingertip_centres_equal_mujoco(hand, tmp_path):
    assert hand.joint_names == ("a_slide", "a_curl", "b_slide", "b_swing", "b_curl")
    assert hand.tree.body_names[1:] == ("palm", "a_base", "a_proximal", "a_tip", "b_base", "b_proximal", "b_distal",
                                        "b_pad")  # fixed links kept, by name
    rng = np.random.default_rng(66)
    low, high = np.where(np.isfinite(hand.lower), hand.lower, -np.pi), np.where(np.isfinite(hand.upper), hand.upper, np.pi)
    for k in range(5):
        qpos = rng.uniform(low, high)
        wrist = None if k == 0 else np.concatenate([rng.normal(0, 0.1, 3), rng.normal(0, 1.0, 3)])
        ref_tips, ref_bodies = mujoco_reference(tmp_path, qpos, wrist)
        np.testing.assert_allclose(np.asarray(hand.fingertip_centers(qpos, wrist)), ref_tips, rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(hand.body_frames(qpos, wrist)[0]), ref_bodies, rtol=0, atol=1e-9)


def test_mesh_fingertip_hand_evaluates(hand, evaluate_many):
    at_rest = hand.grasp(np.zeros(5), GRIPPER / "cube.stl", **FIELDS)
    assert at_rest.status == "grasp" and np.all(np.asarray(at_rest.active))
    np.testing.assert_allclose(np.asarray(at_rest.grasp.initial_deformation), [0.002, 0.002], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(at_rest.tilt), [0.0, 0.0], atol=1e-7)
    hg = hand.grasp(np.array([0.001, 0.05, 0.0005, -0.1, 0.08]), GRIPPER / "cube.stl", **FIELDS)
    assert hg.status == "grasp" and hg.num_active == 2
    (result,) = evaluate_many([hg.grasp])
    assert result.status_name == "stable" and np.isfinite(result.value) and result.value > 0, result.summary()


def test_fingertip_links_are_not_kept_out_of_the_object(hand):
    tree = hand.tree
    kept = {tree.body_names[tree.geom_body[g]] for g in hand.links}
    assert kept == {"palm", "a_proximal", "b_proximal"}  # not a_tip's sphere; b_pad's mesh is no link anyway
    assert [tree.body_names[hand.fingertip_body[i]] for i in range(2)] == ["a_tip", "b_pad"]
    assert hand.fingertip_names == ("a_tip", "b_pad") and list(hand.radius) == [0.01, 0.01]
    np.testing.assert_allclose(hand.fingertip_center, [[0, 0, 0], PAD["center"]], atol=0)
    np.testing.assert_allclose(hand.fingertip_axis, [[0, 0, 1], PAD["axis"]], atol=0)


def test_a_link_names_its_one_sphere_or_capsule():
    with pytest.raises(GraspValueError, match="link 'b_pad' has 0 sphere or capsule geoms, not one; give its fingertip"):
        jaxgrasp.Hand.from_file(GRIPPER / "gripper.urdf", ["a_tip", "b_pad"])
    with pytest.raises(GraspValueError, match="no geom or link named 'b_tip' in .*its links: palm, a_base"):
        jaxgrasp.Hand.from_file(GRIPPER / "gripper.urdf", ["a_tip", "b_tip"])
    with pytest.raises(GraspValueError, match=r"fingertip 'b_pad': axis = \[0.0, 0.0, 0.0\] has no direction"):
        jaxgrasp.Hand.from_file(GRIPPER / "gripper.urdf", ["a_tip", {**PAD, "axis": [0, 0, 0]}])
    with pytest.raises(GraspValueError, match=r"root element is <robot>, not <mujoco>.*read it with Hand.from_file"):
        jaxgrasp.Hand.from_mjcf(GRIPPER / "gripper.urdf", TIPS)


def layout(tmp_path: Path, urdf_at: str, mesh_at: str, filename: str) -> Path:
    """The gripper's URDF written at ``tmp_path/urdf_at`` naming its pad mesh (copied to
    ``tmp_path/mesh_at``) as ``filename``."""
    (tmp_path / mesh_at).parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(GRIPPER / "meshes" / "pad.stl", tmp_path / mesh_at)
    path = tmp_path / urdf_at
    path.parent.mkdir(parents=True, exist_ok=True)
    text = (GRIPPER / "gripper.urdf").read_text()
    path.write_text(text.replace("package://urdf_gripper/meshes/pad.stl", filename.format(tmp=tmp_path)))
    return path


@pytest.mark.parametrize("urdf_at, mesh_at, filename, allow, outcome", [
    ("grip/hand.urdf", "grip/meshes/pad.stl", "package://grip/meshes/pad.stl", None, "ok"),  # the URDF's own folder
    ("grip/urdf/hand.urdf", "grip/meshes/pad.stl", "package://grip/meshes/pad.stl", None, "is outside"),  # ROS layout
    ("grip/urdf/hand.urdf", "grip/meshes/pad.stl", "package://grip/meshes/pad.stl", "grip", "ok"),  # ... allowed
    ("a/hand.urdf", "lib/grip/meshes/pad.stl", "package://grip/meshes/pad.stl", "lib", "ok"),  # a package in an allowed dir
    ("a/hand.urdf", "lib/grip/meshes/pad.stl", "package://grip/meshes/pad.stl", None, "no folder named 'grip'"),
    ("a/hand.urdf", "a/m/pad.stl", "m/pad.stl", None, "ok"),
    ("a/hand.urdf", "b/pad.stl", "file://{tmp}/b/pad.stl", "b", "ok"),
    ("a/hand.urdf", "b/pad.stl", "file://{tmp}/b/pad.stl", None, "is outside"),
    ("a/hand.urdf", "a/pad.stl", "file://pad.stl", None, "a file:// path must be absolute"),
    ("a/hand.urdf", "a/pad.stl", "model://pad.stl", None, "reads package://, file:// or plain paths only"),
])
def test_mesh_paths_resolve_as_ros_does_within_the_allowed_folders(tmp_path, urdf_at, mesh_at, filename, allow, outcome):
    path = layout(tmp_path, urdf_at, mesh_at, filename)
    allowed = [tmp_path / allow] if allow else None
    if outcome == "ok":
        hand = jaxgrasp.Hand.from_file(path, TIPS, allowed_dirs=allowed)
        assert hand.tree.geom_type[-1] == 7  # the pad's mesh, read
        return
    with pytest.raises(GraspValueError, match=outcome) as info:
        jaxgrasp.Hand.from_file(path, TIPS, allowed_dirs=allowed)
    assert "\n" not in str(info.value)


def test_only_collision_meshes_are_read(tmp_path):
    from jaxgrasp.hands._mjcf_files import open_hand_file
    from jaxgrasp.hands._urdf_files import check_urdf

    source = check_urdf(*open_hand_file(GRIPPER / "gripper.urdf"))
    assert list(source.names.values()) == ["package://urdf_gripper/meshes/pad.stl"]  # not pad_visual.dae (missing)
    assert list(source.assets.values()) == [(GRIPPER / "meshes" / "pad.stl").read_bytes()]
    assert "<visual" not in source.xml and 'fusestatic="false"' in source.xml


def test_hand_grasp_file_names_a_urdf_and_a_hemisphere(tmp_path, run_cli):
    folder = tmp_path / "urdf_gripper"
    shutil.copytree(GRIPPER, folder)
    text = (folder / "pinch.toml").read_text()
    assert 'model = "gripper.urdf"' in text and '{link = "b_pad"' in text
    hg = load_hand_grasp(folder / "pinch.toml")
    assert hg.hand.fingertip_names == ("a_tip", "b_pad") and hg.status == "grasp" and hg.num_active == 2
    (folder / "both.toml").write_text(text.replace('model = "gripper.urdf"', 'model = "gripper.urdf"\nmjcf = "x.xml"'))
    rc, out, err = run_cli(["show", "--hand", folder / "both.toml", "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and "[hand] needs model =" in err and "not both" in err, err
