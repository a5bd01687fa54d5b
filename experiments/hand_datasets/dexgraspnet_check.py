"""DexGraspNet's published sample through ``jaxgrasp batch --format dexgraspnet``, against an
independent computation of every fingertip's contact and ``dr``.

The sample: DexGraspNet's repository (https://github.com/PKU-EPIC/DexGraspNet, not
copied here: ``git clone`` it and pass its folder), ``data/dataset/*.npy`` (5 objects, 1141
grasps) and ``data/meshdata/<object>/coacd/decomposed.obj``; its Shadow hand
``grasp_generation/mjcf/shadow_hand_wrist_free.xml``, which MuJoCo 3 refuses. This script
copies the hand's folder into a temporary one and makes the edits MuJoCo 3 needs
(`fixed_hand`), runs the unmodified file once to record jaxgrasp's one-line error, then
runs ``jaxgrasp batch`` on every object and compares its ``results.csv`` with:

* MuJoCo's own kinematics (``mj_kinematics``) of the edited hand at each grasp's joints;
* the wrist written out by hand: ``R = Rz(rz) Ry(ry) Rx(rx)`` (transforms3d's
  ``euler2mat`` with its default static x-y-z axes), ``p_world = R p + t``;
* the closest point over every triangle of the scaled mesh (trimesh's point-triangle
  routine, by brute force), the side and the normal of the closest face;
* the rules of ``docs/guide/hands.md``: a fingertip is in contact when ``0 < dr < r`` and its
  tilt is below 90 degrees.

Run: ``python experiments/hand_datasets/dexgraspnet_check.py --dexgraspnet /path/to/DexGraspNet``
(writes ``dexgraspnet_check.log`` here).
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TIPS = [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")]
FIELDS = ["--young-modulus", "3e5", "--friction", "0.8", "--max-force", "15"]


def fixed_hand(src: Path, dst: Path) -> Path:
    """A copy of DexGraspNet's hand folder that MuJoCo 3 compiles: ``apirate`` deleted, the
    actuators and sensors of the wrist joints the file dropped (``robot0:WRJ0``/``WRJ1``)
    deleted, ``meshdir``/``texturedir`` made relative to the file's own folder."""
    shutil.copytree(src, dst)
    path = dst / "shadow_hand_wrist_free.xml"
    text = path.read_text()
    text = text.replace(' apirate="200"', "")
    text = re.sub(r'\s*<general name="robot0:A_WRJ[01]"[^>]*/>', "", text)
    text = re.sub(r'\s*<jointpos joint="robot0:WRJ[01]"[^>]*/>', "", text)
    text = text.replace('meshdir="./mjcf/meshes/"', 'meshdir="meshes/"').replace(
        'texturedir="./mjcf/textures/"', 'texturedir="textures/"')
    path.write_text(text)
    return path


def euler_sxyz(rx, ry, rz) -> np.ndarray:
    """transforms3d's ``euler2mat(rx, ry, rz)`` (axes 'sxyz'): ``Rz(rz) @ Ry(ry) @ Rx(rx)``."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def brute_closest(triangles, normals, points) -> tuple[np.ndarray, np.ndarray]:
    """``(closest point (P, 3), its face's normal (P, 3))`` of each point over every triangle
    (trimesh's point-triangle routine, no spatial index); of faces within 1e-12 m of the
    least distance, the one the point lies farthest in front of or behind."""
    import trimesh

    out_p, out_n = [], []
    for c in points:
        q = trimesh.triangles.closest_point(triangles, np.broadcast_to(c, (len(triangles), 3)))
        d = np.linalg.norm(q - c, axis=1)
        near = np.flatnonzero(d <= d.min() + 1e-12)
        best = near[np.argmax(np.abs(np.einsum("ij,ij->i", c - q[near], normals[near])))]
        out_p.append(q[best])
        out_n.append(normals[best])
    return np.array(out_p), np.array(out_n)


def independent(model, grasps, mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(active (B, 5), dr (B, 5) m)`` of DexGraspNet ``grasps`` on ``mesh`` (module notes)."""
    import mujoco

    data = mujoco.MjData(model)
    geoms = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in TIPS]
    radius = model.geom_size[geoms, 0]
    active, dr = np.zeros((len(grasps), 5), bool), np.full((len(grasps), 5), np.nan)
    for i, g in enumerate(grasps):
        q = g["qpos"]
        for j in range(model.njnt):
            data.qpos[model.jnt_qposadr[j]] = q[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)]
        mujoco.mj_kinematics(model, data)
        rot = euler_sxyz(q["WRJRx"], q["WRJRy"], q["WRJRz"])
        t = np.array([q["WRJTx"], q["WRJTy"], q["WRJTz"]])
        z = data.geom_xmat[geoms].reshape(-1, 3, 3)[:, :, 2]
        cap = data.geom_xpos[geoms] + z * model.geom_size[geoms, 1][:, None]  # the +z end: farther from the joint
        centers, axes = cap @ rot.T + t, z @ rot.T
        p, n = brute_closest(mesh.triangles * float(g["scale"]), mesh.face_normals, centers)
        side = np.sign(np.einsum("ij,ij->i", centers - p, n))
        signed = side * np.linalg.norm(centers - p, axis=1)  # |c - p|, negative on the closest face's inner side
        normal = n
        d = radius - signed
        cos_tilt = -np.sum(axes * normal, axis=1)
        active[i] = (d > 0) & (d < radius) & (cos_tilt > 0.0)
        dr[i] = np.where(active[i], d, np.nan)
    return active, dr


def run_batch(data: Path, hand: Path, mesh: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "jaxgrasp", "batch", str(data), "--format", "dexgraspnet", "--hand", str(hand),
           "--fingertips", ",".join(TIPS), "--mesh", str(mesh), *FIELDS, "--out", str(out), "--no-plot", "--quiet",
           "--allow-dir", str(hand.parent), *extra]
    return subprocess.run(cmd, capture_output=True, text=True)


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dexgraspnet", required=True, type=Path, help="a clone of DexGraspNet's repository")
    ap.add_argument("--log", type=Path, default=HERE / "dexgraspnet_check.log")
    args = ap.parse_args()
    import mujoco
    import trimesh

    lines = [f"# DexGraspNet sample check, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
             f"load {os.getloadavg()[0]:.2f}"]

    def log(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    src = args.dexgraspnet / "grasp_generation" / "mjcf"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        hand = fixed_hand(src, tmp / "hand")
        model = mujoco.MjModel.from_xml_path(str(hand))
        files = sorted((args.dexgraspnet / "data" / "dataset").glob("*.npy"))
        first_mesh = args.dexgraspnet / "data" / "meshdata" / files[0].stem / "coacd" / "decomposed.obj"
        bad = run_batch(files[0], src / "shadow_hand_wrist_free.xml", first_mesh, tmp / "bad")
        log(f"the hand file as published: exit {bad.returncode}, {len(bad.stderr.strip().splitlines())} line(s): "
            f"{bad.stderr.strip()}")
        only_paths = tmp / "paths_fixed"
        shutil.copytree(src, only_paths)
        xml = only_paths / "shadow_hand_wrist_free.xml"
        xml.write_text(xml.read_text().replace('meshdir="./mjcf/meshes/"', 'meshdir="meshes/"'))
        bad = run_batch(files[0], xml, first_mesh, tmp / "bad2")
        log(f"the same with its meshdir relative to its folder: exit {bad.returncode}, "
            f"{len(bad.stderr.strip().splitlines())} line(s): {bad.stderr.strip()}")
        totals = dict(grasps=0, two=0, three=0, mismatched=0, stable_mass0=0, stable_density=0)
        worst = 0.0
        for f in files:
            mesh_path = args.dexgraspnet / "data" / "meshdata" / f.stem / "coacd" / "decomposed.obj"
            grasps = list(np.load(f, allow_pickle=True))  # the reference side reads it as DexGraspNet does
            t0 = time.perf_counter()
            ran = run_batch(f, hand, mesh_path, tmp / f.stem)
            wall = time.perf_counter() - t0
            if ran.returncode != 0:
                log(f"{f.stem}: jaxgrasp batch failed: {ran.stderr.strip()}")
                return 1
            rows = read_csv(tmp / f.stem / "results.csv")
            assert [int(r["index"]) for r in rows] == list(range(len(grasps))), "rows out of input order"
            got_active = np.array([[r[f"dr_{k}"] != "" for k in range(5)] for r in rows])
            got_dr = np.array([[float(r[f"dr_{k}"]) if r[f"dr_{k}"] else np.nan for k in range(5)] for r in rows])
            ref_active, ref_dr = independent(model, grasps, trimesh.load(mesh_path, force="mesh"))
            same = got_active == ref_active
            both = got_active & ref_active
            diff = float(np.max(np.abs(got_dr[both] - ref_dr[both]), initial=0.0))
            worst = max(worst, diff)
            dense = run_batch(f, hand, mesh_path, tmp / (f.stem + "_density"), "--density", "500")
            assert dense.returncode == 0, dense.stderr
            stable_density = sum(r["status"] == "stable" for r in read_csv(tmp / (f.stem + "_density") / "results.csv"))
            counts = got_active.sum(axis=1)
            stable = sum(r["status"] == "stable" for r in rows)
            log(f"{f.stem}: {len(rows)} grasps, batch {wall:.1f} s; fingertips in contact "
                f"{np.bincount(counts, minlength=6).tolist()} (0..5); contact decisions equal {int(same.sum())}/"
                f"{same.size}; max |dr - dr_ref| {diff:.2e} m; stable {stable} (mass 0), {stable_density} "
                f"(density 500 kg/m^3)")
            totals["grasps"] += len(rows)
            totals["two"] += int((counts >= 2).sum())
            totals["three"] += int((counts >= 3).sum())
            totals["mismatched"] += int((~same).sum())
            totals["stable_mass0"] += stable
            totals["stable_density"] += stable_density
        log(f"all: {totals['grasps']} grasps; {totals['two']} with 2 or more fingertips in contact, {totals['three']} "
            f"with 3 or more; contact decisions that differ: {totals['mismatched']}; max |dr - dr_ref| {worst:.2e} m; "
            f"stable: {totals['stable_mass0']} without weight, {totals['stable_density']} at 500 kg/m^3")
    args.log.write_text("\n".join(lines) + "\n")
    return 0 if worst <= 1e-6 and totals["mismatched"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
