"""Hand files built to hurt (issue 65, items 3 and 4): each a one-line error, nothing outside opened.

A hand's MJCF file and what it names are read by jaxgrasp, not MuJoCo
(`jaxgrasp.hands._mjcf_files`). Each hostile hand here is refused in one line by
``Hand.from_mjcf``, by ``load_hand_grasp`` and by ``jaxgrasp show --hand`` (exit 2):

* **Nothing outside the folder is opened.** The files outside are the test's own, in a
  sibling folder ``outside/``: FIFOs nobody writes to (opening one to read blocks for
  ever, so a file opened by jaxgrasp or MuJoCo would hang the call: the test would not
  end; a FIFO jaxgrasp opened itself would be refused as a FIFO, not as outside) and a
  regular file holding a marker, which never appears in a message. Reached through
  ``<include>``, ``meshdir`` (relative and absolute), ``texturedir``, and symlinks inside
  the folder that lead out.
* FIFOs inside the folder (an include, a mesh), over-size files (sparse), DOCTYPE and
  entities, a replicate bomb (1000 x 1000), a flexcomp bomb, deep nesting, a second
  MJCF, plugins, height-field files, a file included twice.
* Hand grasp files: ``qpos`` and ``wrist`` of strings, nested lists or NaN, paths with a
  NUL byte, a path that is not a string.
* What is neutralised rather than refused still loads, at once: a texture bomb, a
  lengthrange simulation, simulation memory of 1000 GB.

The command runs in a new process where a hang is possible (the FIFOs, the bombs): each
must end within 60 s with exit 2 and one line on stderr; the rest run in-process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import jaxgrasp
from jaxgrasp import GraspValueError
from jaxgrasp.hands import _mjcf_files, load_hand_grasp

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")

REPO = Path(__file__).resolve().parents[2]
TWO_FINGER = REPO / "examples" / "hands" / "two_finger"
SHADOW = REPO / "examples" / "hands" / "shadow" / "shadow_hand.xml"
TIPS = ["a_tip", "b_tip"]
MARKER = "jaxgrasp_marker_7f3a91"  # in the outside file marked.xml (an element's name): never in a message
OUTSIDE_RULE = "is outside the hand file's folder"


@pytest.fixture(autouse=True)
def deadline():
    """Each in-process test fails (SIGALRM: an ``open`` blocked on a FIFO is interrupted)
    rather than hangs if a regression lets anything open a FIFO."""
    def expire(signum, frame):
        raise TimeoutError("a hostile hand file took more than 120 s: something blocked or ran away")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(120)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


@pytest.fixture
def dirs(tmp_path):
    """``(hand, outside)``: sibling folders; ``outside`` holds FIFOs and a marked file."""
    hand, outside = tmp_path / "hand", tmp_path / "outside"
    hand.mkdir()
    outside.mkdir()
    (hand / "cube.stl").write_bytes((TWO_FINGER / "cube.stl").read_bytes())
    os.mkfifo(outside / "secret.xml")
    os.mkfifo(outside / "secret.stl")
    (outside / "marked.xml").write_text(f"<mujoco><{MARKER}/></mujoco>")
    return hand, outside


def hand_xml(head: str = "", body: str = "") -> str:
    """The two-finger hand's MJCF with ``head`` after ``<mujoco>`` and ``body`` in its world body."""
    text = (TWO_FINGER / "two_finger.xml").read_text()
    text = text.replace('<mujoco model="two_finger">', '<mujoco model="two_finger">' + head, 1)
    return text.replace("</worldbody>", body + "</worldbody>", 1)


MESH = '<asset><mesh name="m" file="{}"/></asset>'
MESH_GEOM = '<geom type="mesh" mesh="m"/>'

# name -> (files to write in the hand folder {name: text}, the main file's text, the message's part)
CASES = {
    "include_outside": ({}, hand_xml(body='<include file="../outside/secret.xml"/>'), OUTSIDE_RULE),
    "include_absolute": ({}, hand_xml(body='<include file="{outside}/marked.xml"/>'), OUTSIDE_RULE),
    "include_marked": ({}, hand_xml(body='<include file="../outside/marked.xml"/>'), OUTSIDE_RULE),
    "nested_include_outside": ({"inc.xml": '<mujoco><include file="../outside/secret.xml"/></mujoco>'},
                               hand_xml(body='<include file="inc.xml"/>'), OUTSIDE_RULE),
    "meshdir_outside": ({}, hand_xml('<compiler meshdir="../outside"/>' + MESH.format("secret.stl"), MESH_GEOM),
                        OUTSIDE_RULE),
    "meshdir_absolute": ({}, hand_xml('<compiler meshdir="{outside}"/>' + MESH.format("secret.stl"), MESH_GEOM),
                         OUTSIDE_RULE),
    "assetdir_outside": ({}, hand_xml('<compiler assetdir="../outside"/>' + MESH.format("secret.stl"), MESH_GEOM),
                         OUTSIDE_RULE),
    "mesh_file_outside": ({}, hand_xml(MESH.format("../outside/secret.stl"), MESH_GEOM), OUTSIDE_RULE),
    "texturedir_outside": ({}, hand_xml('<compiler texturedir="../outside"/><asset><texture name="t" type="2d" '
                                        'file="secret.png"/></asset>'), OUTSIDE_RULE),
    "include_symlink_out": ({"link.xml": ("symlink", "../outside/secret.xml")},
                            hand_xml(body='<include file="link.xml"/>'), OUTSIDE_RULE),
    "mesh_symlink_out": ({"link.stl": ("symlink", "../outside/secret.stl")},
                         hand_xml(MESH.format("link.stl"), MESH_GEOM), OUTSIDE_RULE),
    "fifo_include": ({"pipe.xml": ("fifo",)}, hand_xml(body='<include file="pipe.xml"/>'), "is a FIFO (named pipe)"),
    "fifo_mesh": ({"pipe.stl": ("fifo",)}, hand_xml(MESH.format("pipe.stl"), MESH_GEOM), "is a FIFO (named pipe)"),
    "replicate_bomb": ({}, hand_xml(body='<replicate count="1000"><replicate count="1000"><body><geom size="0.001"/>'
                                         '</body></replicate></replicate>'), "more than 100000 elements"),
    "replicate_bodies": ({}, hand_xml(body='<replicate count="3000"><body><geom size="0.001"/></body></replicate>'),
                         "more than 2000 bodies"),
    "flexcomp_bomb": ({}, hand_xml(body='<flexcomp name="f" type="grid" count="300 300 1" spacing=".1 .1 .1" '
                                        'dim="2"/>'), "more than 2000 bodies"),
    "deep_nesting": ({}, hand_xml(body="<body>" * 150 + "</body>" * 150), "deeper than 100 levels"),
    "doctype_entities": ({}, '<?xml version="1.0"?><!DOCTYPE m [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>'
                             + hand_xml().replace("two_finger", "&b;", 1), "declares a DOCTYPE or entities"),
    "included_twice": ({"inc.xml": "<mujoco/>"}, hand_xml(body='<include file="inc.xml"/><include file="inc.xml"/>'),
                       "included twice"),
    "self_include": ({}, hand_xml(body='<include file="hand.xml"/>'), "included twice"),
    "second_mjcf": ({"other.xml": "<mujoco/>"}, hand_xml('<asset><model name="o" file="other.xml"/></asset>'),
                    "a <model> asset"),
    "plugin": ({}, hand_xml('<extension><plugin plugin="mujoco.pid"/></extension>'), "a plugin extension"),
    "hfield_file": ({"h.png": "x"}, hand_xml('<asset><hfield name="h" file="h.png" size="1 1 1 1"/></asset>'),
                    "reads a height field from a file"),
    "not_a_mesh_format": ({"m.gltf": "{}"}, hand_xml(MESH.format("m.gltf"), MESH_GEOM), "is not .stl or .obj or .msh"),
    "sdf": ({}, '<sdf version="1.6"><model name="r"/></sdf>', "its root element is <sdf>, not <mujoco>"),
    "missing_include": ({}, hand_xml(body='<include file="nope.xml"/>'), "include 'nope.xml': no such file"),
    "builtin_mesh_bomb": ({}, hand_xml('<asset><mesh name="m" builtin="supersphere" params="3000 1 1"/></asset>',
                                       MESH_GEOM), "a builtin mesh has a parameter above 200"),
    "keyframe_bomb": ({}, hand_xml('<size nkey="100000000"/>'), "<size> nkey is above 1000"),
}


def write_case_files(hand: Path, files: dict) -> None:
    """A case's extra files in ``hand``: text, a FIFO (``("fifo",)``) or a symlink (``("symlink", target)``)."""
    for name, content in files.items():
        if isinstance(content, tuple) and content[0] == "fifo":
            os.mkfifo(hand / name)
        elif isinstance(content, tuple):
            (hand / name).symlink_to(content[1])
        else:
            (hand / name).write_text(content)


def build(case: str, hand: Path, outside: Path) -> Path:
    """Write the case's files into ``hand``; the main file."""
    files, main, _ = CASES[case]
    write_case_files(hand, files)
    path = hand / "hand.xml"
    path.write_text(main.replace("{outside}", str(outside)))
    return path


def hand_grasp_file(hand: Path, mjcf: str = '"hand.xml"', **hand_keys) -> Path:
    """A hand grasp file (TOML) in ``hand`` naming ``mjcf`` and ``cube.stl``; ``hand_keys``
    replace lines of its [hand] table (TOML text)."""
    keys = {"qpos": "[0.001, 0.1, 0.05, 0.0005, -0.05, 0.1]", "fingertips": '["a_tip", "b_tip"]', **hand_keys}
    text = "[hand]\n" + f"mjcf = {mjcf}\n" + "".join(f"{k} = {v}\n" for k, v in keys.items())
    text += '[object]\nmesh = "cube.stl"\nunits = "mm"\nmass = 0.02\n'
    text += "[fingertip]\nyoung_modulus = 6e5\nfriction = 0.8\nmax_force = 15.0\n"
    path = hand / "grasp.toml"
    path.write_text(text)
    return path


def one_line(info) -> str:
    text = str(info.value)
    assert "\n" not in text and MARKER not in text, text
    return text


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_hand_file_is_one_line(case, dirs, run_cli, tmp_path):
    hand, outside = dirs
    path = build(case, hand, outside)
    start = time.monotonic()
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(path, TIPS)
    assert CASES[case][2] in one_line(info)
    with pytest.raises(GraspValueError) as info:
        load_hand_grasp(hand_grasp_file(hand))
    assert CASES[case][2] in one_line(info)
    if "FIFO" in CASES[case][2] or "outside" in CASES[case][2]:
        return  # through the command in a new process: test_the_command_refuses_in_one_line_within_60_s
    rc, out, err = run_cli(["show", "--hand", hand / "grasp.toml", "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and CASES[case][2] in err and MARKER not in err, err
    assert time.monotonic() - start < 60


@pytest.mark.slow  # a new process each (about 7 s)
@pytest.mark.parametrize("case", ["include_outside", "meshdir_outside", "mesh_symlink_out", "fifo_include",
                                  "fifo_mesh", "replicate_bomb"])
def test_the_command_refuses_in_one_line_within_60_s(case, dirs, tmp_path):
    """``python -m jaxgrasp show --hand``: a FIFO opened by anyone, or a bomb compiled,
    would run past the timeout; exit 2, one line naming the rule, the marker never shown."""
    hand, outside = dirs
    build(case, hand, outside)
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "jaxgrasp", "show", "--hand", str(hand_grasp_file(hand)),
                           "--out", str(tmp_path / "x.png")], check=False, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    elapsed = time.monotonic() - start
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr[-2000:]
    assert proc.stderr.count("\n") == 1 and CASES[case][2] in proc.stderr and MARKER not in proc.stderr, proc.stderr
    assert elapsed < 60 and not (tmp_path / "x.png").exists()


def test_allow_dir_allows_a_folder_outside(dirs):
    """A mesh in a folder the user allows is read (and a FIFO there is still refused)."""
    hand, outside = dirs
    shared = outside / "meshes"
    shared.mkdir()
    (shared / "c.stl").write_bytes((TWO_FINGER / "cube.stl").read_bytes())
    path = hand / "hand.xml"
    path.write_text(hand_xml('<compiler meshdir="../outside/meshes"/>' + MESH.format("c.stl"),
                             '<body name="m"><geom type="mesh" mesh="m"/></body>'))
    with pytest.raises(GraspValueError, match=OUTSIDE_RULE):
        jaxgrasp.Hand.from_mjcf(path, TIPS)
    assert jaxgrasp.Hand.from_mjcf(path, TIPS, allowed_dirs=[shared]).tree.geom_type[-1] == 7  # mjGEOM_MESH
    os.mkfifo(shared / "pipe.stl")
    path.write_text(path.read_text().replace('file="c.stl"', 'file="pipe.stl"'))
    with pytest.raises(GraspValueError, match="is a FIFO"):
        jaxgrasp.Hand.from_mjcf(path, TIPS, allowed_dirs=[shared])


def test_over_size_files_are_refused_before_reading(dirs, monkeypatch):
    """Sparse files over the caps (nothing of them is read: the size is the file's)."""
    hand, _ = dirs
    big = hand / "big.xml"
    with open(big, "wb") as fh:
        fh.truncate(_mjcf_files.MAX_MJCF_BYTES + 1)
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(big, TIPS)
    assert "more than the 16 MiB read at most" in one_line(info)
    with open(hand / "big.stl", "wb") as fh:
        fh.truncate(_mjcf_files.MAX_HAND_ASSET_BYTES + 1)
    (hand / "hand.xml").write_text(hand_xml(MESH.format("big.stl"), MESH_GEOM))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(hand / "hand.xml", TIPS)
    assert "more than the 32 MiB read at most" in one_line(info)
    monkeypatch.setattr(_mjcf_files, "MAX_HAND_FILES_BYTES", 40_000)  # the Shadow hand's files: 78 kB
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(SHADOW, ["robot0:C_ffdistal", "robot0:C_thdistal"])
    assert "more than the 0.038147 MiB read at most for one hand (all files together)" in one_line(info)


def test_neutralised_bombs_still_load_at_once(dirs):
    """A texture of 1e5 x 1e5 texels (its file never read), a length-range simulation of
    1e9 steps and 1000 GB of simulation memory: what the kinematics never uses is not
    handed to MuJoCo, so the hand loads within seconds."""
    hand, _ = dirs
    head = ('<size memory="1000G"/><compiler texturedir="tex"><lengthrange mode="all" inttotal="1000000000" '
            'timestep="1e-9"/></compiler><asset><texture name="t" type="2d" builtin="checker" width="100000" '
            'height="100000"/><texture name="f" type="cube" file="cube.png"/><material name="m" texture="t"/></asset>')
    path = hand / "hand.xml"
    body = '<body name="x"><joint name="j" range="-1 1"/><geom size="0.01" material="m"/></body>'
    path.write_text(hand_xml(head, body).replace("</mujoco>", '<actuator><muscle joint="j"/></actuator></mujoco>'))
    start = time.monotonic()
    hand_model = jaxgrasp.Hand.from_mjcf(path, TIPS)
    assert hand_model.num_joints == 7 and time.monotonic() - start < 20


@pytest.mark.parametrize("key, value, message", [
    ("qpos", '["a", "b", "c", "d", "e", "f"]', "qpos = ['a', 'b', 'c', 'd', 'e', 'f'] must be a number"),
    ("qpos", "[[0.0, 0.1], [0.2, 0.3, 0.4, 0.5]]", "qpos must be a number or an array of numbers"),
    ("qpos", "[[[0.0, 0.1, 0.2, 0.3, 0.4, 0.5]]]", "qpos must be 6 joint positions (rad, m for slides), got shape (1, 6)"),
    ("qpos", "[[0.0, 0.1, 0.2, 0.3, 0.4, 0.5], [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]]", "qpos holds 2 configurations"),
    ("qpos", "[0.0, nan, 0.0, 0.0, 0.0, 0.0]", "qpos[1] = nan must be finite"),
    ("qpos", "[0.0, 0.1]", "qpos must be 6 joint positions (rad, m for slides), got shape (2,)"),
    ("qpos", "[true, false, true, false, true, false]", "must be numeric, not boolean"),
    ("wrist", '["0", 0, 0, 0, 0, 0]', "wrist = ['0', 0, 0, 0, 0, 0] must be a number"),
    ("wrist", "[[0, 0, 0], [0, 0, 0]]", "wrist must be 6 finite numbers"),
    ("fingertips", "[1, 2]", "fingertips must be at least 2 geom or link names, or {link, center, axis, radius} tables, "
                             "got [1, 2]"),
    ("fingertips", '["a_tip", "nope"]', "fingertips: no geom or link named 'nope'"),
    ("fingertips", '["a_tip", {link = "b_distal", center = [0, 0], axis = [1, 0, 0], radius = 0.01}]',
     "fingertip 'b_distal': center must be 3 finite numbers"),
    ("mjcf", '"two\\u0000finger.xml"', "holds a NUL byte"),
    ("mjcf", "3", "[hand] mjcf must be a string, got int"),
])
def test_hand_grasp_file_values_are_one_line(dirs, run_cli, tmp_path, key, value, message):
    hand, _ = dirs
    (hand / "hand.xml").write_text(hand_xml())
    path = hand_grasp_file(hand, **({"mjcf": value} if key == "mjcf" else {key: value}))
    with pytest.raises(GraspValueError) as info:
        load_hand_grasp(path)
    assert message in one_line(info)
    rc, out, err = run_cli(["show", "--hand", path, "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and message in err, err


def test_mesh_path_with_a_nul_byte_is_one_line(dirs, run_cli, tmp_path):
    hand, _ = dirs
    (hand / "hand.xml").write_text(hand_xml())
    path = hand_grasp_file(hand)
    path.write_text(path.read_text().replace('mesh = "cube.stl"', 'mesh = "cu\\u0000be.stl"'))
    with pytest.raises(GraspValueError) as info:
        load_hand_grasp(path)
    assert "mesh path 'cu\\x00be.stl' holds a NUL byte" in one_line(info)
    rc, _, err = run_cli(["show", "--hand", path, "--out", tmp_path / "x.png"])
    assert rc == 2 and err.count("\n") == 1 and "holds a NUL byte" in err, err


def test_shadow_hand_loads_with_its_includes_and_mesh(tmp_path):
    """The good path: the vendored Shadow hand (two includes, a mesh by ``meshdir``) loads
    as MuJoCo loads it from its file, array for array; its mesh is given as bytes."""
    import mujoco
    import numpy as np

    hand = jaxgrasp.Hand.from_mjcf(SHADOW, [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")])
    ref = mujoco.MjModel.from_xml_path(str(SHADOW))
    np.testing.assert_array_equal(hand.tree.body_pos, ref.body_pos)
    np.testing.assert_array_equal(hand.tree.geom_size, ref.geom_size)
    np.testing.assert_array_equal(hand.tree.jnt_range, ref.jnt_range)
    xml, assets, names = _mjcf_files.checked_mjcf(SHADOW)
    assert list(names.values()) == ["forearm_electric_cvx.stl"] and "include" not in xml and "meshdir" not in xml
    assert next(iter(assets.values())) == (SHADOW.parent / "forearm_electric_cvx.stl").read_bytes()


# ----------------------------------------------------------------------------- URDF (issue 66)
GRIPPER = REPO / "examples" / "hands" / "urdf_gripper"
PAD_TOML = '{link = "b_pad", center = [0.01, 0, 0], axis = [1, 0, 0], radius = 0.01}'


def gripper_urdf(mesh: str = "package://urdf_gripper/meshes/pad.stl", joint: str = "revolute", head: str = "") -> str:
    """The example gripper's URDF naming its pad mesh ``mesh``, its joint ``a_curl`` of type
    ``joint``, with ``head`` after ``<robot>``."""
    text = (GRIPPER / "gripper.urdf").read_text().replace("package://urdf_gripper/meshes/pad.stl", mesh)
    text = text.replace('<joint name="a_curl" type="revolute">', f'<joint name="a_curl" type="{joint}">')
    return text.replace('<robot name="urdf_gripper">', '<robot name="urdf_gripper">' + head)


# name -> (files to write in the hand folder, the URDF's text, the message's part)
URDF_CASES = {
    "package_escapes": ({}, gripper_urdf("package://hand/../outside/secret.stl"), OUTSIDE_RULE),
    "package_elsewhere": ({}, gripper_urdf("package://outside/secret.stl"), "no folder named 'outside' is the URDF's"),
    "file_url_outside": ({}, gripper_urdf("file://{outside}/secret.stl"), OUTSIDE_RULE),
    "relative_outside": ({}, gripper_urdf("../outside/secret.stl"), OUTSIDE_RULE),
    "mesh_symlink_out": ({"link.stl": ("symlink", "../outside/secret.stl")}, gripper_urdf("link.stl"), OUTSIDE_RULE),
    "fifo_mesh": ({"pipe.stl": ("fifo",)}, gripper_urdf("pipe.stl"), "is a FIFO (named pipe)"),
    "collada_collision": ({"pad.dae": "<COLLADA/>"}, gripper_urdf("pad.dae"), "is not .stl or .obj or .msh"),
    "floating_joint": ({}, gripper_urdf(joint="floating"), "joint 'a_curl' is floating; a hand's joints are"),
    "planar_joint": ({}, gripper_urdf(joint="planar"), "joint 'a_curl' is planar; a hand's joints are"),
    "xacro": ({}, gripper_urdf(head='<xacro:include filename="x.xacro"/>'), "a xacro file; run xacro"),
    "doctype": ({}, '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "b">]>' + gripper_urdf(), "declares a DOCTYPE"),
    "link_bomb": ({}, gripper_urdf(head="<link/>" * 2100), "more than 100000 elements or 2000 links"),
}


def build_urdf(case: str, hand: Path, outside: Path) -> Path:
    files, main, _ = URDF_CASES[case]
    (hand / "meshes").mkdir()
    (hand / "meshes" / "pad.stl").write_bytes((GRIPPER / "meshes" / "pad.stl").read_bytes())
    write_case_files(hand, files)
    path = hand / "hand.urdf"
    path.write_text(main.replace("{outside}", str(outside)))
    return path


def urdf_grasp_file(hand: Path, fingertips: str = f'["a_tip", {PAD_TOML}]') -> Path:
    """A hand grasp file naming ``hand.urdf`` with ``model =``."""
    path = hand_grasp_file(hand, '"hand.urdf"', qpos="[0.001, 0.05, 0.0005, -0.1, 0.08]", fingertips=fingertips)
    path.write_text(path.read_text().replace('mjcf = "hand.urdf"', 'model = "hand.urdf"'))
    return path


@pytest.mark.parametrize("case", sorted(URDF_CASES))
def test_hostile_urdf_is_one_line(case, dirs, run_cli, tmp_path):
    hand, outside = dirs
    path = build_urdf(case, hand, outside)
    start = time.monotonic()
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_file(path, ["a_tip", {"link": "b_pad", "center": [0.01, 0, 0], "axis": [1, 0, 0],
                                                 "radius": 0.01}])
    assert URDF_CASES[case][2] in one_line(info)
    rc, out, err = run_cli(["show", "--hand", urdf_grasp_file(hand), "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and URDF_CASES[case][2] in err and MARKER not in err, err
    assert time.monotonic() - start < 60


def test_urdf_unknown_fingertip_is_one_line(dirs, run_cli, tmp_path):
    hand, _ = dirs
    build_urdf("package_escapes", hand, tmp_path)
    (hand / "hand.urdf").write_text(gripper_urdf("meshes/pad.stl"))
    rc, out, err = run_cli(["show", "--hand", urdf_grasp_file(hand, '["a_tip", "b_tip"]'), "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert "fingertips: no geom or link named 'b_tip'" in err and "its links: palm, a_base, a_proximal, a_tip" in err


@pytest.mark.slow  # a new process (about 7 s)
def test_the_command_refuses_an_escaping_package_path_within_60_s(dirs, tmp_path):
    """The package path leads to a FIFO outside: opened by anyone, the command would hang."""
    hand, outside = dirs
    build_urdf("package_escapes", hand, outside)
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "jaxgrasp", "show", "--hand", str(urdf_grasp_file(hand)),
                           "--out", str(tmp_path / "x.png")], check=False, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 2 and proc.stdout == "" and proc.stderr.count("\n") == 1, proc.stderr[-2000:]
    assert OUTSIDE_RULE in proc.stderr and time.monotonic() - start < 60


# ----------------------------------------------------------------------------- legacy MJCF (issue 66)
LEGACY_TAIL = ('<actuator>\n<general name="A_gone" joint="gone"/>\n<motor joint="a_curl"/>\n</actuator>\n'
               '<sensor>\n<jointpos name="S_gone" joint="gone"/>\n</sensor>\n</mujoco>')


def line_of(text: str, part: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if part in line)


def test_legacy_mjcf_names_the_element_its_line_and_the_fix(dirs, run_cli, tmp_path):
    """MuJoCo 3 refuses a removed attribute and an actuator or sensor of a missing joint
    (DexGraspNet's Shadow hand has both): one line each in jaxgrasp's words, with every
    further element to delete."""
    hand, _ = dirs
    text = hand_xml('\n<option apirate="200" timestep="0.002"/>').replace("</mujoco>", LEGACY_TAIL)
    path = hand / "hand.xml"
    path.write_text(text)
    a, s = line_of(text, 'name="A_gone"'), line_of(text, 'name="S_gone"')
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(path, TIPS)
    assert one_line(info) == (f"mjcf '{path}': <option apirate=\"200\"> (line {line_of(text, 'apirate')}): MuJoCo 3 "
                              f"removed the attribute apirate; delete it; then delete the 2 elements that name joints "
                              f"the model does not have (lines {a}, {s})")
    path.write_text(text.replace(' apirate="200"', ""))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_file(path, TIPS)
    assert one_line(info) == (f"mjcf '{path}': <general name=\"A_gone\"> (line {a}) names joint 'gone', which the model "
                              "does not have; delete the actuator; and the other element that names a joint the model "
                              f"does not have (line {s})")
    rc, out, err = run_cli(["show", "--hand", hand_grasp_file(hand), "--out", tmp_path / "x.png"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and "<general name=\"A_gone\"> (line" in err, err


def test_legacy_mjcf_in_an_include_names_that_file(dirs):
    hand, _ = dirs
    (hand / "acts.xml").write_text('<mujoco>\n<actuator>\n<position name="P" joint="wrist"/>\n</actuator>\n</mujoco>')
    (hand / "hand.xml").write_text(hand_xml(body="").replace("</mujoco>", '<include file="acts.xml"/></mujoco>'))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Hand.from_mjcf(hand / "hand.xml", TIPS)
    assert "<position name=\"P\"> (acts.xml line 3) names joint 'wrist', which the model does not have; delete the " \
           "actuator" in one_line(info)
