"""The field's hand-grasp datasets in and out: DexGraspNet and DexGraspBench (SI units).

Both formats are ``.npy`` files of pickled dicts, read by `jaxgrasp.io.load_npy` (a
restricted unpickler: nothing a file names is run). Either gives a `HandPoses`: joint
positions in the hand's joint order, the wrist and the object pose in jaxgrasp's
convention (translation m, rotation vector rad: `jaxgrasp.hands._kinematics.wrist_transform`),
and the object's scale. The conventions, read in each project's source:

**DexGraspNet** (``PKU-EPIC/DexGraspNet``, ``grasp_generation/tests/visualize_result.py``
and ``utils/hand_model.py``): one file per object, an object array of dicts
``{"scale": s, "qpos": {...}}``. ``qpos`` names the translation ``WRJTx``, ``WRJTy``,
``WRJTz`` (m), the rotation ``WRJRx``, ``WRJRy``, ``WRJRz`` (rad; transforms3d's
``euler2mat(rx, ry, rz)``, static axes ``sxyz``: ``R = Rz(rz) Ry(ry) Rx(rx)``), and each
joint by its MJCF name (rad). A hand point ``p`` in the MJCF's world frame lies at
``R p + t`` in the object's frame (``hand_model.py`` applies ``R`` and ``t`` to
pytorch_kinematics' frames, whose root is the MJCF's world; DexGraspNet's
``shadow_hand_wrist_free.xml`` has its palm there): jaxgrasp's wrist is ``(t,
rotvec(R))``. The object is the normalised mesh scaled by ``s`` about its origin, at the
origin (``object_pose`` zeros).

**DexGraspBench** (``JYChen18/DexGraspBench``, ``src/util/hand_util.py``,
``src/task/vis_obj.py``, ``src/task/convert_format.py``): one file per grasp, a dict with
``obj_path`` (the object's folder, its mesh ``mesh/simplified.obj`` inside), ``obj_scale``,
``obj_pose`` (7: x y z m, quaternion w x y z) and ``pregrasp_qpos``, ``grasp_qpos``,
``squeeze_qpos`` (each 7 + J: the pose of the hand MJCF's world frame, as ``obj_pose``, then
the joints in the MJCF's qpos order, unnamed). The benchmark simulates pregrasp, grasp,
then squeeze; `save_dexgraspbench` writes jaxgrasp's grasps so, with a pregrasp and a
squeeze of its own (`PREGRASP_FACTOR`, `SQUEEZE_FACTOR`) where none is given.
"""

from __future__ import annotations

import dataclasses
import io
import os
import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from jaxgrasp import storage
from jaxgrasp.io import MAX_GRASP_FILE_BYTES, check_path_text, load_npy
from jaxgrasp.model import GraspValueError

__all__ = ["HandPoses", "read_dexgraspnet", "read_dexgraspbench", "save_dexgraspbench",
           "PREGRASP_FACTOR", "SQUEEZE_FACTOR", "DEXGRASPBENCH_MESH"]

MAX_DEXGRASPNET_BYTES = 256 * 2**20
"""Largest DexGraspNet file read, bytes (256 MiB: about 300 000 grasps of the Shadow hand;
its published files hold a few hundred, about 200 KiB)."""

MAX_DEXGRASPBENCH_FILES = 1_000_000
"""Most grasp files read from one folder."""

PREGRASP_FACTOR = 0.9
"""Where `save_dexgraspbench` puts each joint before the grasp, as a factor of its grasp
angle (the hand opened by a tenth), the wrist kept: DexGraspBench's own conversion of
DexGraspNet's grasps (its ``baseline`` branch, ``src/task/convert_format.py``, ``DGN``)."""

SQUEEZE_FACTOR = 1.1
"""Where `save_dexgraspbench` squeezes each joint, as a factor of its grasp angle (closed
by a tenth further), the wrist kept; from the same source as `PREGRASP_FACTOR`."""

DEXGRASPBENCH_MESH = "mesh/simplified.obj"
"""The object's mesh inside a DexGraspBench ``obj_path`` folder (``src/task/vis_obj.py``)."""

DEXGRASPNET_TRANSLATION = ("WRJTx", "WRJTy", "WRJTz")
DEXGRASPNET_ROTATION = ("WRJRx", "WRJRy", "WRJRz")
BENCH_STAGES = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")
BENCH_KEYS = ("obj_path", "obj_scale", "obj_pose", *BENCH_STAGES)


@dataclasses.dataclass(frozen=True, eq=False)
class HandPoses:
    """``B`` configurations of one hand with ``J`` joints, each on a scaled, placed object
    (NumPy float64, SI units; not a pytree).

    A point ``p`` of the object's mesh lies at ``R_o (scale p) + t_o`` in the world, ``(t_o,
    R_o)`` its ``object_pose``; a point ``x`` of the hand's model (its MJCF world frame) at
    ``R_w x + t_w``, ``(t_w, R_w)`` its ``wrist``.

    Attributes:
        qpos: ``(B, J)`` joint positions, rad (m for slides), in ``joint_names``' order.
        wrist: ``(B, 6)`` the hand's model frame in the world: translation m, rotation vector
            rad (the ``wrist`` of [`Hand.grasp`][jaxgrasp.Hand.grasp]).
        object_pose: ``(B, 6)`` the object's mesh frame in the world, likewise.
        scale: ``(B,)`` the factor the mesh is scaled by about its origin, before it is placed.
        joint_names: ``(J,)`` the hand's joint names.
        objects: ``(B,)`` each grasp's object as its dataset names it: DexGraspNet, the
            file's name without ``.npy`` (the object code); DexGraspBench, ``obj_path``.
        sources: ``(B,)`` where each grasp was read: ``"FILE#i"`` (DexGraspNet, grasp ``i``)
            or the grasp's file (DexGraspBench).
        pregrasp_qpos, squeeze_qpos: ``(B, J)`` rad, or ``None`` (DexGraspNet).
        pregrasp_wrist, squeeze_wrist: ``(B, 6)``, or ``None`` (DexGraspNet).
    """

    qpos: np.ndarray
    wrist: np.ndarray
    object_pose: np.ndarray
    scale: np.ndarray
    joint_names: tuple
    objects: tuple
    sources: tuple
    pregrasp_qpos: np.ndarray | None = None
    pregrasp_wrist: np.ndarray | None = None
    squeeze_qpos: np.ndarray | None = None
    squeeze_wrist: np.ndarray | None = None

    def __post_init__(self):
        b, j = np.shape(self.qpos)[0], len(self.joint_names)
        shapes = {"qpos": (b, j), "wrist": (b, 6), "object_pose": (b, 6), "scale": (b,), "pregrasp_qpos": (b, j),
                  "pregrasp_wrist": (b, 6), "squeeze_qpos": (b, j), "squeeze_wrist": (b, 6)}
        for name, shape in shapes.items():
            value = getattr(self, name)
            if value is not None:
                value = np.array(value, dtype=np.float64)
                if value.shape != shape:
                    raise GraspValueError(f"HandPoses.{name} must have shape {shape}, got {value.shape}")
                object.__setattr__(self, name, value)
        if len(self.objects) != b or len(self.sources) != b:
            raise GraspValueError(f"HandPoses: {b} grasps, but {len(self.objects)} objects and "
                                  f"{len(self.sources)} sources")

    def __len__(self) -> int:
        return int(self.qpos.shape[0])


def _joint_names(hand) -> tuple:
    names = getattr(hand, "joint_names", hand)
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise GraspValueError(f"hand must be a Hand or its joint names, got {type(hand).__name__}")
    return tuple(names)


def _number(value, where: str) -> float:
    """A finite real number (not a boolean), as float; a one-line error naming ``where``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GraspValueError(f"{where} must be a number, got {type(value).__name__}")
    if not np.isfinite(value):
        raise GraspValueError(f"{where} = {value} must be finite")
    return float(value)


def _listed(names) -> str:
    shown = ", ".join(repr(n) for n in names[:3])
    return shown + (f" and {len(names) - 3} more" if len(names) > 3 else "")


# ----------------------------------------------------------------------------- DexGraspNet
def _dexgraspnet_row(where: str, item, names: tuple) -> list[float]:
    """``[scale, tx, ty, tz, rx, ry, rz, joints...]`` of one DexGraspNet grasp (a dict)."""
    if not isinstance(item, dict) or "qpos" not in item or "scale" not in item:
        got = sorted(item)[:6] if isinstance(item, dict) else type(item).__name__
        raise GraspValueError(f"{where}: a DexGraspNet grasp is a dict with 'qpos' and 'scale', got {got}")
    qpos = item["qpos"]
    if not isinstance(qpos, dict):
        raise GraspValueError(f"{where}: qpos must be a dict of named joint positions, got {type(qpos).__name__}")
    wrist_keys = DEXGRASPNET_TRANSLATION + DEXGRASPNET_ROTATION
    missing = [k for k in (*wrist_keys, *names) if k not in qpos]
    if missing:
        hint = " (joints of the hand)" if missing[0] in names else ""
        raise GraspValueError(f"{where}: qpos has no {_listed(missing)}{hint}; read the grasps with the hand they were "
                              "made for (DexGraspNet's Shadow hand: mjcf/shadow_hand_wrist_free.xml)")
    unknown = [k for k in qpos if k not in names and k not in wrist_keys]
    if unknown:
        raise GraspValueError(f"{where}: qpos names {_listed(unknown)}, which the hand does not have; "
                              "read the grasps with the hand they were made for")
    scale = _number(item["scale"], f"{where}: scale")
    if scale <= 0.0:
        raise GraspValueError(f"{where}: scale = {scale} must be > 0")
    return [scale, *(_number(qpos[k], f"{where}: qpos[{k!r}]") for k in (*wrist_keys, *names))]


def read_dexgraspnet(path: str | os.PathLike, hand) -> HandPoses:
    """The grasps of a DexGraspNet file (one object; the conventions in the module doc).

    Args:
        path: the ``.npy`` file (an object array of dicts ``{"scale", "qpos"}``; read by a
            restricted unpickler, at most `MAX_DEXGRASPNET_BYTES`).
        hand: the [`Hand`][jaxgrasp.Hand] the grasps were made for, or its joint names.

    Returns:
        [`HandPoses`][jaxgrasp.hands.HandPoses]: each grasp's joints in the hand's order, its
        wrist (``WRJT*`` and the static x-y-z Euler angles ``WRJR*`` as a rotation vector),
        ``object_pose`` zeros, ``scale`` from the file; ``objects`` the file's name
        without ``.npy``, ``sources`` ``"PATH#i"``.

    Raises:
        GraspValueError: one line naming the file (and the grasp): unreadable, refused by the
            restricted loader, not a list of dicts, a joint of the hand missing, a joint the
            hand does not have, a value that is not a finite number, a scale <= 0.
    """
    names, shown = _joint_names(hand), os.fspath(check_path_text(path, "DexGraspNet file"))
    data = load_npy(path, max_bytes=MAX_DEXGRASPNET_BYTES, what="DexGraspNet file")
    if data.dtype != object or data.ndim != 1 or data.size == 0:
        raise GraspValueError(f"{shown}: a DexGraspNet file holds a list of grasps (dicts), "
                              f"got an array of {data.dtype} of shape {data.shape}")
    rows = np.array([_dexgraspnet_row(f"{shown}: grasp {i}", item, names) for i, item in enumerate(data)])
    rotation = Rotation.from_euler("xyz", rows[:, 4:7]).as_rotvec()  # lowercase: static axes, transforms3d's 'sxyz'
    count, stem = len(rows), Path(shown).name.removesuffix(".npy")
    return HandPoses(qpos=rows[:, 7:], wrist=np.concatenate([rows[:, 1:4], rotation], axis=1),
                     object_pose=np.zeros((count, 6)), scale=rows[:, 0], joint_names=names,
                     objects=(stem,) * count, sources=tuple(f"{shown}#{i}" for i in range(count)))


# ----------------------------------------------------------------------------- DexGraspBench
def _pose6(pose7: np.ndarray) -> np.ndarray:
    """``(B, 6)`` translation and rotation vector of ``(B, 7)`` poses (x y z, quaternion w x y z,
    normalised as MuJoCo does; nonzero, `_bench_grasp` checked)."""
    norm = np.linalg.norm(pose7[:, 3:7], axis=1)
    rotvec = Rotation.from_quat(pose7[:, [4, 5, 6, 3]] / norm[:, None]).as_rotvec()
    return np.concatenate([pose7[:, :3], rotvec], axis=1)


def _pose7(pose6: np.ndarray) -> np.ndarray:
    """``(B, 7)`` x y z and unit quaternion w x y z (``w >= 0``) of ``(B, 6)`` poses."""
    xyzw = Rotation.from_rotvec(pose6[:, 3:6]).as_quat()
    xyzw *= np.where(xyzw[:, 3:4] < 0.0, -1.0, 1.0)
    return np.concatenate([pose6[:, :3], xyzw[:, [3, 0, 1, 2]]], axis=1)


def _vector(value, n: int, where: str) -> np.ndarray:
    """A ``(n,)`` float64 vector of finite numbers from an array or a list."""
    try:
        v = np.asarray(value)
    except (TypeError, ValueError):
        v = np.asarray(None)
    if v.dtype.kind not in "iuf" or v.shape != (n,):
        raise GraspValueError(f"{where} must be {n} numbers, got {v.dtype} of shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise GraspValueError(f"{where} must be finite")
    return v.astype(np.float64)


def _bench_grasp(path: str, joints: int) -> tuple:
    """``(obj_path, scale, obj_pose (7,), stages (3, 7 + J))`` of one DexGraspBench file."""
    data = load_npy(path, max_bytes=MAX_GRASP_FILE_BYTES, what="DexGraspBench file")
    item = data.item() if data.dtype == object and data.shape == () else None
    if not isinstance(item, dict):
        raise GraspValueError(f"{path}: a DexGraspBench file holds one dict, "
                              f"got an array of {data.dtype} of shape {data.shape}")
    missing = [k for k in BENCH_KEYS if k not in item]
    if missing:
        raise GraspValueError(f"{path}: no {_listed(missing)}; a DexGraspBench grasp holds {', '.join(BENCH_KEYS)}")
    if not isinstance(item["obj_path"], str):
        raise GraspValueError(f"{path}: obj_path must be a string, got {type(item['obj_path']).__name__}")
    scale = _number(item["obj_scale"], f"{path}: obj_scale")
    if scale <= 0.0:
        raise GraspValueError(f"{path}: obj_scale = {scale} must be > 0")
    n = 7 + joints
    for key in BENCH_STAGES:
        size = np.size(item[key]) if isinstance(item[key], np.ndarray) else None
        if size is not None and np.ndim(item[key]) == 1 and size != n:
            raise GraspValueError(f"{path}: {key} holds {size} numbers, not 7 (the hand's pose) + the hand's {joints} "
                                  "joints (in its MJCF order): read it with the hand the grasps were made for")
    stages = np.stack([_vector(item[k], n, f"{path}: {k}") for k in BENCH_STAGES])
    pose = _vector(item["obj_pose"], 7, f"{path}: obj_pose")
    for key, value in zip(("obj_pose", *BENCH_STAGES), (pose, *stages)):
        if np.linalg.norm(value[3:7]) < 1e-9:
            raise GraspValueError(f"{path}: {key}: its quaternion (numbers 4 to 7, w x y z) is zero")
    return item["obj_path"], scale, pose, stages


def _natural(path: str) -> list:
    """Sort key: digits as numbers (``2.npy`` before ``10.npy``)."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path)]


def _bench_files(paths) -> list[str]:
    """The ``.npy`` files of a file, a folder (searched below, in natural order), or a list of them."""
    items = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    out = []
    for item in items:
        item = os.fspath(check_path_text(item, "DexGraspBench path"))
        if not os.path.isdir(item):
            out.append(item)
            continue
        found = [os.path.join(root, f) for root, _, files in os.walk(item) for f in files if f.endswith(".npy")]
        if len(out) + len(found) > MAX_DEXGRASPBENCH_FILES:
            raise GraspValueError(f"{item}: more than {MAX_DEXGRASPBENCH_FILES} grasp files; read fewer at once")
        out.extend(sorted(found, key=_natural))
    if not out:
        shown = _listed([os.fspath(p) for p in items]) or "no path"
        raise GraspValueError(f"{shown}: no DexGraspBench grasp file (.npy)")
    return out


def read_dexgraspbench(paths, hand) -> HandPoses:
    """The grasps of DexGraspBench files (one grasp each; the conventions in the module doc).

    Args:
        paths: a ``.npy`` file, a folder (every ``.npy`` below it, in natural order:
            ``2.npy`` before ``10.npy``), or a list of files and folders, in that order.
        hand: the [`Hand`][jaxgrasp.Hand] the grasps were made for, or its joint names: the
            files hold the joints unnamed, in the hand's MJCF order.

    Returns:
        [`HandPoses`][jaxgrasp.hands.HandPoses]: ``qpos`` and ``wrist`` from ``grasp_qpos``, the
        pregrasp and squeeze likewise, ``object_pose`` and ``scale`` from ``obj_pose`` and
        ``obj_scale``, ``objects`` the ``obj_path`` (its mesh: ``obj_path/mesh/simplified.obj``,
        relative to where DexGraspBench runs), ``sources`` the files.

    Raises:
        GraspValueError: one line naming the file: unreadable, refused by the restricted
            loader, a key missing, a vector of the wrong length (another hand), a value
            that is not a finite number, a zero quaternion, a scale <= 0.
    """
    names = _joint_names(hand)
    files = _bench_files(paths)
    grasps = [_bench_grasp(f, len(names)) for f in files]
    stages = np.stack([g[3] for g in grasps])  # (B, 3, 7 + J)
    poses = [_pose6(stages[:, s, :7]) for s in range(3)]
    return HandPoses(qpos=stages[:, 1, 7:], wrist=poses[1],
                     object_pose=_pose6(np.stack([g[2] for g in grasps])),
                     scale=np.array([g[1] for g in grasps]), joint_names=names, objects=tuple(g[0] for g in grasps),
                     sources=tuple(files), pregrasp_qpos=stages[:, 0, 7:], pregrasp_wrist=poses[0],
                     squeeze_qpos=stages[:, 2, 7:], squeeze_wrist=poses[2])


def _as_poses(grasps, obj_path) -> HandPoses:
    """A `HandPoses` of ``grasps``: itself, or one or several [`HandGrasp`][jaxgrasp.hands.HandGrasp]
    (scale 1, their objects ``obj_path``)."""
    if isinstance(grasps, HandPoses):
        return grasps
    items = list(grasps) if isinstance(grasps, (list, tuple)) else [grasps]
    if not items or not all(hasattr(g, "qpos") and hasattr(g, "wrist") and hasattr(g, "hand") for g in items):
        raise GraspValueError("save_dexgraspbench takes a HandPoses, a HandGrasp or a list of HandGrasps")
    if obj_path is None:
        raise GraspValueError("save_dexgraspbench: a HandGrasp does not say its object's folder: pass obj_path=")
    stacked = {k: np.stack([np.asarray(getattr(g, k)) for g in items]) for k in ("qpos", "wrist", "object_pose")}
    blank = ("",) * len(items)
    return HandPoses(**stacked, scale=np.ones(len(items)), joint_names=tuple(items[0].hand.joint_names),
                     objects=blank, sources=blank)


def _stage(poses: HandPoses, name: str, factor: float, hand) -> np.ndarray:
    """``(B, 7 + J)`` DexGraspBench vectors of a stage: the poses' own, else the grasp's wrist
    with every joint at ``factor`` times its angle (within ``hand``'s limits, if given)."""
    qpos, wrist = getattr(poses, f"{name}_qpos", None), getattr(poses, f"{name}_wrist", None)
    if qpos is None:
        qpos = factor * poses.qpos
        if hand is not None:
            qpos = np.clip(qpos, hand.lower, hand.upper)
    return np.concatenate([_pose7(poses.wrist if wrist is None else wrist), qpos], axis=1)


def _npy_bytes(grasp: dict) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.array(grasp, dtype=object), allow_pickle=True)
    return buf.getvalue()


def save_dexgraspbench(folder: str | os.PathLike, grasps, *, obj_path=None, hand=None,
                       pregrasp_factor: float = PREGRASP_FACTOR, squeeze_factor: float = SQUEEZE_FACTOR) -> list[Path]:
    """Write grasps as DexGraspBench's input: ``folder/0.npy``, ``folder/1.npy``, ... (module doc).

    Each file is ``numpy.save`` of a dict of a string and float64 arrays (``obj_path``,
    ``obj_scale``, ``obj_pose``, ``pregrasp_qpos``, ``grasp_qpos``, ``squeeze_qpos``), readable
    by ``numpy.load(allow_pickle=True)`` and by [`read_dexgraspbench`][jaxgrasp.hands.read_dexgraspbench],
    which gives the same numbers back. The files are written as one set, all or none.
    Where the grasps carry no pregrasp or squeeze (all but those read from DexGraspBench),
    the pregrasp is the grasp's wrist with every joint at ``pregrasp_factor`` times its
    angle (0.9: opened by a tenth), the squeeze likewise at ``squeeze_factor`` (1.1),
    within ``hand``'s joint limits when it is given: DexGraspBench's own conversion of
    DexGraspNet's grasps, which carry none either. Run the benchmark with the MJCF of the
    hand the grasps were made with: the joints are written in its order, unnamed.

    Args:
        folder: where the files go (made if missing).
        grasps: [`HandPoses`][jaxgrasp.hands.HandPoses], or a [`HandGrasp`][jaxgrasp.hands.HandGrasp]
            or a list of them (written with ``obj_scale`` 1).
        obj_path: each grasp's object folder as DexGraspBench expects it (its mesh at
            ``obj_path/mesh/simplified.obj``): one string for all, or one per grasp;
            default ``grasps.objects``.
        hand: the [`Hand`][jaxgrasp.Hand], to keep the pregrasp and squeeze within its limits
            (its joint names must be the grasps').
        pregrasp_factor, squeeze_factor: as above.

    Returns:
        The files written, in the grasps' order.

    Raises:
        GraspValueError: not grasps, no ``obj_path`` for a `HandGrasp`, as many paths as
            grasps not given, another hand's joints.
        OutputError: the files cannot be written (none is).
    """
    poses = _as_poses(grasps, obj_path)
    paths = poses.objects if obj_path is None else obj_path
    paths = (paths,) * len(poses) if isinstance(paths, str) else tuple(paths)
    if len(paths) != len(poses) or not all(isinstance(p, str) and p for p in paths):
        raise GraspValueError(f"obj_path must be a folder name, or {len(poses)} of them (one per grasp)")
    if hand is not None and tuple(hand.joint_names) != poses.joint_names:
        raise GraspValueError("save_dexgraspbench: the hand's joints are not the grasps' (another hand)")
    stages = [_stage(poses, "pregrasp", pregrasp_factor, hand), _stage(poses, "grasp", 1.0, None),
              _stage(poses, "squeeze", squeeze_factor, hand)]
    object_pose = _pose7(poses.object_pose)
    folder = Path(check_path_text(folder, "output folder"))
    folder.mkdir(parents=True, exist_ok=True)
    members = {folder / f"{i}.npy": _npy_bytes({
        "obj_path": paths[i], "obj_scale": np.float64(poses.scale[i]), "obj_pose": object_pose[i],
        **{key: stage[i] for key, stage in zip(BENCH_STAGES, stages)}}) for i in range(len(poses))}
    storage.write_set(members)
    return list(members)
