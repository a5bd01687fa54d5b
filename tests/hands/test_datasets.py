"""The field's hand-grasp datasets (issue 66, item 3): DexGraspNet and DexGraspBench files
built here in their formats for the Shadow hand of ``examples/`` (as those projects write
them: ``numpy.save`` of pickled dicts), read into ``HandPoses`` with their conventions, and
jaxgrasp's grasps written as DexGraspBench reads them; malformed and hostile files are one
line naming the file.
"""

from __future__ import annotations

import io
import types
from pathlib import Path

import numpy as np
import pytest

from jaxgrasp import GraspValueError
from jaxgrasp.hands import HandPoses, read_dexgraspbench, read_dexgraspnet, save_dexgraspbench
from jaxgrasp.hands._datasets import BENCH_KEYS, PREGRASP_FACTOR, SQUEEZE_FACTOR
from jaxgrasp.io import load_npy

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")

SHADOW = Path(__file__).resolve().parents[2] / "examples" / "hands" / "shadow" / "shadow_hand.xml"
TIPS = ["robot0:C_ffdistal", "robot0:C_mfdistal", "robot0:C_thdistal"]
B = 6


@pytest.fixture(scope="module")
def hand():
    import jaxgrasp

    return jaxgrasp.Hand.from_mjcf(SHADOW, fingertips=TIPS)


@pytest.fixture(scope="module")
def grasps(hand):
    """``(qpos (B, J), translation (B, 3), euler (B, 3), scale (B,))``: random, within limits."""
    rng = np.random.default_rng(66)
    qpos = rng.uniform(hand.lower, hand.upper, size=(B, hand.num_joints))
    return qpos, rng.uniform(-0.2, 0.2, (B, 3)), rng.uniform(-np.pi, np.pi, (B, 3)), rng.choice([0.06, 0.1, 0.15], B)


def dexgraspnet_items(hand, grasps) -> list[dict]:
    qpos, t, euler, scale = grasps
    items = []
    for i in range(B):
        named = {"WRJTx": t[i, 0], "WRJTy": t[i, 1], "WRJTz": t[i, 2],
                 "WRJRx": euler[i, 0], "WRJRy": euler[i, 1], "WRJRz": euler[i, 2]}
        named.update(zip(hand.joint_names, map(float, qpos[i])))
        items.append({"qpos": named, "scale": np.float64(scale[i]), "energy": 1.5})
    return items


def write_dexgraspnet(path: Path, items) -> Path:
    data = np.empty(len(items), dtype=object)
    for i, item in enumerate(items):
        data[i] = item
    np.save(path, data, allow_pickle=True)  # as DexGraspNet's scripts write: an object array of dicts
    return path


def transforms3d_sxyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """transforms3d's ``euler2mat(rx, ry, rz)`` (axes ``'sxyz'``: static x, then y, then z),
    written out: ``Rz(rz) @ Ry(ry) @ Rx(rx)``."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def rotvec_matrix(w) -> np.ndarray:
    """Rodrigues' formula of a rotation vector (rad), in NumPy."""
    angle = np.linalg.norm(w)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / angle
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


# ----------------------------------------------------------------------------- DexGraspNet
def test_dexgraspnet_file_reads_with_its_conventions(tmp_path, hand, grasps):
    path = write_dexgraspnet(tmp_path / "core-mug-123.npy", dexgraspnet_items(hand, grasps))
    poses = read_dexgraspnet(path, hand)
    qpos, t, euler, scale = grasps
    assert isinstance(poses, HandPoses) and len(poses) == B and poses.joint_names == hand.joint_names
    np.testing.assert_array_equal(poses.qpos, qpos)
    np.testing.assert_array_equal(poses.wrist[:, :3], t)
    np.testing.assert_array_equal(poses.scale, scale)
    np.testing.assert_array_equal(poses.object_pose, np.zeros((B, 6)))
    for i in range(B):  # the rotation is transforms3d's euler2mat(rx, ry, rz), written out
        np.testing.assert_allclose(rotvec_matrix(poses.wrist[i, 3:]), transforms3d_sxyz(*euler[i]), atol=1e-12)
    assert poses.objects == ("core-mug-123",) * B and poses.sources[2] == f"{path}#2"


def test_the_wrist_places_the_hand_model_as_dexgraspnet_does(tmp_path, hand, grasps):
    """DexGraspNet's hand point ``p`` (its model frame) lies at ``R p + t``: so do the fingertips
    that jaxgrasp computes with the wrist read from the file."""
    poses = read_dexgraspnet(write_dexgraspnet(tmp_path / "a.npy", dexgraspnet_items(hand, grasps)), hand)
    for i in (0, 3):
        placed = np.asarray(hand.fingertip_centers(poses.qpos[i], poses.wrist[i]))
        model = np.asarray(hand.fingertip_centers(poses.qpos[i]))
        want = model @ transforms3d_sxyz(*grasps[2][i]).T + grasps[1][i]
        np.testing.assert_allclose(placed, want, atol=1e-12)


def one_line(call, *args) -> str:
    with pytest.raises(GraspValueError) as info:
        call(*args)
    text = str(info.value)
    assert "\n" not in text, text
    return text


def test_dexgraspnet_mistakes_are_one_line(tmp_path, hand, grasps):
    items = dexgraspnet_items(hand, grasps)

    def refused(mutate, says):
        broken = [dict(item, qpos=dict(item["qpos"])) for item in items]
        mutate(broken)
        path = write_dexgraspnet(tmp_path / "bad.npy", broken)
        text = one_line(read_dexgraspnet, path, hand)
        assert text.startswith(f"{path}: ") and says in text, text

    refused(lambda b: b[1]["qpos"].pop("robot0:WRJ1"), "grasp 1: qpos has no 'robot0:WRJ1' (joints of the hand)")
    refused(lambda b: b[2]["qpos"].pop("WRJRz"), "grasp 2: qpos has no 'WRJRz'")
    refused(lambda b: b[0]["qpos"].update({"robot0:EXTRA": 0.0}), "grasp 0: qpos names 'robot0:EXTRA', which the hand")
    refused(lambda b: b[3].pop("scale"), "grasp 3: a DexGraspNet grasp is a dict with 'qpos' and 'scale'")
    refused(lambda b: b[3].update({"qpos": [1.0, 2.0]}), "grasp 3: qpos must be a dict")
    refused(lambda b: b[4].update({"scale": -0.1}), "grasp 4: scale = -0.1 must be > 0")
    refused(lambda b: b[0]["qpos"].update({"robot0:FFJ3": float("nan")}), "qpos['robot0:FFJ3'] = nan must be finite")
    refused(lambda b: b[0]["qpos"].update({"WRJTx": "0.1"}), "qpos['WRJTx'] must be a number, got str")
    refused(lambda b: b[0]["qpos"].update({"WRJTx": True}), "qpos['WRJTx'] must be a number, got bool")
    np.save(tmp_path / "numbers.npy", np.zeros((3, 4)))
    text = one_line(read_dexgraspnet, tmp_path / "numbers.npy", hand)
    assert "holds a list of grasps (dicts), got an array of float64" in text
    with pytest.raises(GraspValueError, match="must be a Hand or its joint names"):
        read_dexgraspnet(tmp_path / "numbers.npy", "robot0:FFJ3")


def test_hostile_dexgraspnet_file_runs_nothing(tmp_path, hand):
    marker = tmp_path / "ran"
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "|O", "fortran_order": False, "shape": (1,)})
    header = buf.getvalue()
    path = tmp_path / "evil.npy"
    path.write_bytes(header + b"cos\nsystem\n(S'touch " + str(marker).encode() + b"'\ntR.")
    text = one_line(read_dexgraspnet, path, hand)
    assert text.startswith(f"{path}: the DexGraspNet file refuses pickled global os.system"), text
    assert not marker.exists()
    good = write_dexgraspnet(tmp_path / "good.npy", [{"qpos": {}, "scale": 1.0}] * 3)
    (tmp_path / "cut.npy").write_bytes(good.read_bytes()[:-20])
    assert "malformed or truncated pickle" in one_line(read_dexgraspnet, tmp_path / "cut.npy", hand)


# ----------------------------------------------------------------------------- DexGraspBench
@pytest.fixture(scope="module")
def poses(hand, grasps):
    rng = np.random.default_rng(7)
    qpos = grasps[0]
    rotvec = rng.normal(size=(B, 3))
    rotvec *= (rng.uniform(0.1, 3.0, B) / np.linalg.norm(rotvec, axis=1))[:, None]  # angles below pi
    object_pose = np.concatenate([rng.uniform(-0.1, 0.1, (B, 3)), rng.normal(size=(B, 3))], axis=1)
    return HandPoses(qpos=qpos, wrist=np.concatenate([grasps[1], rotvec], axis=1), object_pose=object_pose,
                     scale=grasps[3], joint_names=hand.joint_names, sources=("",) * B,
                     objects=tuple(f"assets/object/o{i}" for i in range(B)))


def test_dexgraspbench_round_trip(tmp_path, hand, poses):
    files = save_dexgraspbench(tmp_path / "out", poses, hand=hand)
    assert [f.name for f in files] == [f"{i}.npy" for i in range(B)]
    back = read_dexgraspbench(tmp_path / "out", hand)
    for name in ("qpos", "wrist", "object_pose", "scale"):
        np.testing.assert_allclose(getattr(back, name), getattr(poses, name), rtol=0, atol=1e-12, err_msg=name)
    assert back.objects == poses.objects and back.sources == tuple(map(str, files))
    for got, factor in ((back.pregrasp_qpos, PREGRASP_FACTOR), (back.squeeze_qpos, SQUEEZE_FACTOR)):
        np.testing.assert_allclose(got, np.clip(factor * poses.qpos, hand.lower, hand.upper), atol=1e-15)
    np.testing.assert_allclose(back.pregrasp_wrist, poses.wrist, atol=1e-12)
    again = save_dexgraspbench(tmp_path / "again", back)  # pregrasp and squeeze written as they are
    for a, b in zip(again, files):
        for key in BENCH_KEYS:
            x, y = np.load(a, allow_pickle=True).item()[key], np.load(b, allow_pickle=True).item()[key]
            assert (x == y) if key == "obj_path" else np.allclose(x, y, rtol=0, atol=1e-12), key


def test_dexgraspbench_files_are_what_the_benchmark_loads(tmp_path, hand, poses):
    """``numpy.load(..).item()`` as DexGraspBench does: the six keys, a string, float64
    arrays of 7 and 7 + J; the pose a unit quaternion w x y z with w >= 0, the wrist the
    model frame's (R p + t)."""
    save_dexgraspbench(tmp_path, poses)
    data = np.load(tmp_path / "1.npy", allow_pickle=True).item()
    assert sorted(data) == sorted(BENCH_KEYS) and data["obj_path"] == "assets/object/o1"
    assert data["grasp_qpos"].dtype == np.float64 and data["grasp_qpos"].shape == (7 + hand.num_joints,)
    quat = data["grasp_qpos"][3:7]
    assert abs(np.linalg.norm(quat) - 1) < 1e-15 and quat[0] >= 0
    w, x, y, z = quat  # the quaternion's matrix, written out, is the wrist's rotation
    from_quat = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                          [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                          [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(from_quat, rotvec_matrix(poses.wrist[1, 3:]), atol=1e-12)
    np.testing.assert_array_equal(data["grasp_qpos"][7:], poses.qpos[1])
    assert load_npy(tmp_path / "1.npy", max_bytes=2**20).item().keys() == data.keys()


def test_dexgraspbench_as_the_benchmark_writes_it(tmp_path, hand):
    """float32 vectors, a NumPy scalar scale, extra keys, files ``2.npy`` and ``10.npy`` read
    in natural order; the quaternion is normalised as MuJoCo does."""
    n = 7 + hand.num_joints
    for i in (10, 2):
        grasp = np.zeros(n, dtype=np.float32)
        grasp[3:7] = (2.0, 0.0, 0.0, 0.0)  # w = 2: not unit
        grasp[7:] = i / 100
        np.save(tmp_path / f"{i}.npy", {"obj_path": "assets/o", "obj_scale": np.float64(0.08), "scene_path": "s.npy",
                                        "obj_pose": np.array([0, 0, 0.1, 1, 0, 0, 0]), "pregrasp_qpos": grasp,
                                        "grasp_qpos": grasp, "squeeze_qpos": grasp})
    back = read_dexgraspbench([tmp_path], hand)
    assert back.sources == (str(tmp_path / "2.npy"), str(tmp_path / "10.npy"))
    np.testing.assert_allclose(back.qpos[:, 0], [0.02, 0.1], rtol=1e-6)
    np.testing.assert_array_equal(back.wrist, np.zeros((2, 6)))
    np.testing.assert_array_equal(back.object_pose[0], [0, 0, 0.1, 0, 0, 0])


def test_dexgraspbench_mistakes_are_one_line(tmp_path, hand):
    n = 7 + hand.num_joints
    good = {"obj_path": "o", "obj_scale": 0.1, "obj_pose": np.array([0, 0, 0, 1.0, 0, 0, 0]),
            "pregrasp_qpos": np.eye(n)[3], "grasp_qpos": np.eye(n)[3], "squeeze_qpos": np.eye(n)[3]}

    def refused(says, **change):
        path = tmp_path / "g.npy"
        np.save(path, {k: v for k, v in {**good, **change}.items() if v is not None}, allow_pickle=True)
        text = one_line(read_dexgraspbench, path, hand)
        assert text.startswith(f"{path}: ") and says in text, text

    refused("no 'squeeze_qpos'; a DexGraspBench grasp holds obj_path, obj_scale", squeeze_qpos=None)
    refused(f"grasp_qpos holds 29 numbers, not 7 (the hand's pose) + the hand's {hand.num_joints} joints",
            grasp_qpos=np.eye(29)[3])
    refused("obj_pose: its quaternion (numbers 4 to 7, w x y z) is zero", obj_pose=np.zeros(7))
    refused("obj_path must be a string, got int", obj_path=3)
    refused("obj_scale = 0.0 must be > 0", obj_scale=0.0)
    refused(f"pregrasp_qpos must be {n} numbers, got object", pregrasp_qpos=[{"a": 1}] * n)
    refused("grasp_qpos must be finite", grasp_qpos=np.full(n, np.inf))
    np.save(tmp_path / "g.npy", np.zeros(3))
    assert "holds one dict, got an array of float64" in one_line(read_dexgraspbench, tmp_path / "g.npy", hand)
    (tmp_path / "empty").mkdir()
    assert "no DexGraspBench grasp file" in one_line(read_dexgraspbench, tmp_path / "empty", hand)


def test_save_dexgraspbench_takes_hand_grasps_and_refuses_what_it_cannot_write(tmp_path, hand, poses):
    grasp = types.SimpleNamespace(qpos=poses.qpos[0], wrist=poses.wrist[0], object_pose=poses.object_pose[0], hand=hand)
    assert "pass obj_path=" in one_line(save_dexgraspbench, tmp_path, grasp)
    save_dexgraspbench(tmp_path, [grasp, grasp], obj_path="assets/object/cube", pregrasp_factor=0.5)
    back = read_dexgraspbench([tmp_path / "0.npy", tmp_path / "1.npy"], hand)
    assert back.objects == ("assets/object/cube",) * 2 and np.all(back.scale == 1.0)
    np.testing.assert_allclose(back.pregrasp_qpos[0], 0.5 * poses.qpos[0], atol=1e-15)
    with pytest.raises(GraspValueError, match="obj_path must be a folder name, or 6 of them"):
        save_dexgraspbench(tmp_path, poses, obj_path=["a", "b"])
    with pytest.raises(GraspValueError, match="HandPoses.scale must have shape"):
        HandPoses(poses.qpos, poses.wrist, poses.object_pose, np.ones(2), poses.joint_names, poses.objects,
                  poses.sources)
