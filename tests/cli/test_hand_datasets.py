"""``jaxgrasp batch --format dexgraspnet|dexgraspbench`` (issue 66): the field's hand-grasp
datasets through the batch command.

Fixtures are written in each format from the two-finger hand of ``examples/hands/`` (the
formats name or order joints; the readers are checked on the Shadow hand in
``tests/hands/test_datasets.py``). Against `Hand.grasp` of each configuration, its wrist
built here from DexGraspNet's Euler angles by the explicit formula
``R = Rz(rz) Ry(ry) Rx(rx)`` (transforms3d's ``euler2mat``, axes ``sxyz``) and its mesh
scaled by trimesh: ``results.csv`` has one row per grasp in input order, ``dr_k`` equal to
the fingertip's ``dr`` (1e-12 m), empty where it does not touch; both formats give the same
rows for the same grasps; bad command lines and hostile files are one line, exit 2.
"""

from __future__ import annotations

import csv
import pickle
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")
trimesh = pytest.importorskip("trimesh")

HANDS = Path(__file__).resolve().parents[2] / "examples" / "hands" / "two_finger"
FIELDS = ["--young-modulus", "6e5", "--friction", "0.8", "--max-force", "15", "--mass", "0.02"]
Q0 = np.array([0.001, 0.10, 0.05, 0.0005, -0.05, 0.10])
ANGLES = np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.015], [0.0, 0.0, 0.0]])
SCALES = np.array([1.0, 1.0, 0.9])  # the last: a cube of 54 mm, out of reach of finger b


def euler_sxyz(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    return (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
            @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))


@pytest.fixture(scope="module")
def hand():
    return jaxgrasp.Hand.from_file(HANDS / "two_finger.xml", ["a_tip", "b_tip"])


@pytest.fixture()
def dexgraspnet_file(hand, tmp_path):
    grasps = []
    for angles, scale in zip(ANGLES, SCALES):
        qpos = dict(zip(hand.joint_names, Q0.tolist()))
        qpos.update(WRJTx=0.0005, WRJTy=0.0, WRJTz=0.0, WRJRx=angles[0], WRJRy=angles[1], WRJRz=angles[2])
        grasps.append({"scale": np.float64(scale), "qpos": qpos})
    path = tmp_path / "cube.npy"
    np.save(path, np.array(grasps, dtype=object), allow_pickle=True)
    return path


def rows_of(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def batch(run_cli, data, out, fmt="dexgraspnet", extra=()):
    return run_cli(["batch", data, "--format", fmt, "--hand", HANDS / "two_finger.xml", "--fingertips", "a_tip,b_tip",
                    "--mesh", HANDS / "cube.stl", "--units", "mm", *FIELDS, "--out", out, "--no-plot", "--quiet",
                    *extra])


def test_dexgraspnet_rows_are_each_configurations_grasp(run_cli, hand, dexgraspnet_file, tmp_path):
    rc, _, err = batch(run_cli, dexgraspnet_file, tmp_path / "out")
    assert rc == 0, err
    rows = rows_of(tmp_path / "out" / "results.csv")
    assert [r["index"] for r in rows] == ["0", "1", "2"]
    cube = trimesh.load(HANDS / "cube.stl")
    cube.apply_scale(1e-3)
    for i, row in enumerate(rows):
        mesh = cube.copy()
        mesh.apply_scale(SCALES[i])
        from scipy.spatial.transform import Rotation

        wrist = np.r_[0.0005, 0.0, 0.0, Rotation.from_matrix(euler_sxyz(*ANGLES[i])).as_rotvec()]
        hg = hand.grasp(Q0, mesh, wrist=wrist, young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)
        for k in range(2):
            if bool(hg.active[k]):
                assert float(row[f"dr_{k}"]) == pytest.approx(float(hg.grasp.initial_deformation[k]), abs=1e-12)
            else:
                assert row[f"dr_{k}"] == ""
        assert row["active"] == str(hg.num_active)
    assert rows[2]["status"] == "invalid" and rows[0]["status"] == "stable"


def test_dexgraspbench_of_the_same_grasps_gives_the_same_rows(run_cli, hand, dexgraspnet_file, tmp_path):
    from jaxgrasp.hands import read_dexgraspnet, save_dexgraspbench

    poses = read_dexgraspnet(dexgraspnet_file, hand)
    save_dexgraspbench(tmp_path / "bench", poses, obj_path="cube")
    rc, _, err = batch(run_cli, dexgraspnet_file, tmp_path / "net")
    assert rc == 0, err
    rc, _, err = batch(run_cli, tmp_path / "bench", tmp_path / "bench_out", fmt="dexgraspbench")
    assert rc == 0, err
    net, bench = rows_of(tmp_path / "net" / "results.csv"), rows_of(tmp_path / "bench_out" / "results.csv")
    for a, b in zip(net, bench, strict=True):
        assert (a["status"], a["active"]) == (b["status"], b["active"])
        for k in range(2):
            assert (a[f"dr_{k}"] == "") == (b[f"dr_{k}"] == "")
            if a[f"dr_{k}"]:
                assert float(a[f"dr_{k}"]) == pytest.approx(float(b[f"dr_{k}"]), abs=1e-12)


class _Stop(Exception):
    pass


def test_an_interrupted_hand_batch_resumes_to_the_uninterrupted_rows(run_cli, dexgraspnet_file, tmp_path,
                                                                      monkeypatch):
    """A hand batch interrupted after its first chunk is kept, and ``--resume`` evaluates
    only the rest: ``results.csv`` equals an uninterrupted run's, hand columns included."""
    from jaxgrasp.engine._checkpoint import BatchCheckpoint

    one_chunk = ["--chunk-size", "1"]
    rc, _, err = batch(run_cli, dexgraspnet_file, tmp_path / "whole", extra=one_chunk)
    assert rc == 0, err
    save_rows, saved = BatchCheckpoint.save_rows, []

    def save_then_stop(self, rows, results):
        save_rows(self, rows, results)
        saved.append(rows)
        raise _Stop  # as a killed run after its first chunk is on disk

    monkeypatch.setattr(BatchCheckpoint, "save_rows", save_then_stop)
    with pytest.raises(_Stop):
        batch(run_cli, dexgraspnet_file, tmp_path / "out", extra=one_chunk)
    monkeypatch.setattr(BatchCheckpoint, "save_rows", save_rows)
    assert len(saved) == 1 and not (tmp_path / "out" / "results.csv").exists()
    rc, _, err = batch(run_cli, dexgraspnet_file, tmp_path / "out", extra=[*one_chunk, "--resume"])
    assert rc == 0, err
    assert "resuming: 2 of 3 grasps were finished" in err, err  # the invalid row and the first chunk
    assert rows_of(tmp_path / "out" / "results.csv") == rows_of(tmp_path / "whole" / "results.csv")


class _Boom:
    def __reduce__(self):
        import os

        return (os.system, ("touch BOOM",))


@pytest.mark.parametrize("case, message", [
    ("no_mesh", "--format dexgraspnet needs --mesh"),
    ("options_without_format", "--hand, --fingertips: only with --format"),
    ("one_fingertip", "--fingertips 'a_tip': give at least 2"),
    ("pickled_call", "refuses"),
])
def test_bad_hand_datasets_are_one_line(run_cli, dexgraspnet_file, tmp_path, monkeypatch, case, message):
    monkeypatch.chdir(tmp_path)
    hand_args = ["--hand", HANDS / "two_finger.xml", "--fingertips", "a_tip,b_tip"]
    argv = {
        "no_mesh": ["batch", dexgraspnet_file, "--format", "dexgraspnet", *hand_args],
        "options_without_format": ["batch", HANDS / "pinch.toml", *hand_args],
        "one_fingertip": ["batch", dexgraspnet_file, "--format", "dexgraspnet", "--hand", HANDS / "two_finger.xml",
                          "--fingertips", "a_tip", "--mesh", HANDS / "cube.stl"],
        "pickled_call": None,
    }[case]
    if argv is None:
        bad = tmp_path / "bad.npy"
        payload = pickle.dumps(np.array([_Boom()], dtype=object), protocol=2)
        header = "{'descr': '|O', 'fortran_order': False, 'shape': (1,), }"
        header = header + " " * (63 - len(header) % 64) + "\n"
        bad.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + payload)
        argv = ["batch", bad, "--format", "dexgraspnet", *hand_args, "--mesh", HANDS / "cube.stl"]
    rc, _, err = run_cli([*argv, "--out", tmp_path / "out"])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], err
    assert not (tmp_path / "BOOM").exists()
