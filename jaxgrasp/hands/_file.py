"""Hand grasp files: a hand, its configuration and the object, in TOML (SI units).

::

    [hand]
    model = "shadow/shadow_hand.xml"         # MJCF or URDF, relative to this file (``mjcf = `` too)
    fingertips = ["robot0:C_ffdistal", "robot0:C_thdistal"]
    # or a hemisphere on a link, for fingertips that are meshes (m, the link's frame):
    # fingertips = ["a_tip", {link = "b_distal", center = [0.03, 0, 0], axis = [1, 0, 0], radius = 0.01}]
    qpos = [0.0, ...]                        # (J,) rad (m for slides); or (B, J): B configurations
    wrist = [0, 0, 0, 0, 0, 0]               # optional: translation m, rotation vector rad; or (B, 6)

    [object]
    mesh = "duck.obj"                        # relative to this file
    units = "m"                              # optional
    pose = [0, 0, 0, 0, 0, 0]                # optional: the mesh frame in the world
    mass = 0.05                              # kg (or density, kg/m^3)

    [fingertip]
    young_modulus = 6e5                      # Pa
    friction = 1.0
    max_force = 15.0                         # N

``model`` names the hand's MJCF or URDF file (told apart by its root element, as
[`Hand.from_file`][jaxgrasp.Hand.from_file] reads it); ``mjcf``, its name in earlier files,
is accepted with the same meaning (one of the two). A fingertip is a geom or link name or
an inline table ``{link, center, axis, radius}`` (`jaxgrasp.hands._fingertips`).
The hand file and the mesh must lie inside the file's folder after symlinks, or in one of the
allowed folders (``--allow-dir``), as for grasp files; so must every file the hand file names
(its includes, meshes and textures: `jaxgrasp.hands._mjcf_files`, `jaxgrasp.hands._urdf_files`).
Numbers are checked (``qpos``, ``wrist``, ``pose`` and the fields: one line naming the key).
`load_hand_grasp` gives the [`HandGrasp`][jaxgrasp.hands.HandGrasp] of a file of one configuration;
`load_hand_batch` the [`HandBatch`][jaxgrasp.hands.HandBatch] of a file of one or many (``qpos``
``(B, J)``: the project's own dataset of hand grasps, evaluated by ``jaxgrasp batch``);
`save_hand_grasp` writes one (atomically).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

import numpy as np

from jaxgrasp.io import MAX_GRASP_FILE_BYTES, allowed_folders, check_path_text, confine, read_input
from jaxgrasp.model import GraspValueError

__all__ = ["load_hand_grasp", "load_hand_batch", "is_hand_grasp_file", "save_hand_grasp", "hand_grasp_toml"]

_TABLES = {"hand": ("model", "mjcf", "fingertips", "qpos", "wrist"), "object": ("mesh", "units", "pose", "mass", "density"),
           "fingertip": ("young_modulus", "friction", "max_force")}


def _confined_model(name: str, base: Path, allowed: tuple, where: str, key: str) -> Path:
    """The real path of the hand file ``name`` (relative to ``base``), inside the allowed folders."""
    check_path_text(name, f"{where}: {key}")
    real = os.path.realpath(os.path.join(base, name))
    folders = (os.path.realpath(base), *allowed)
    if not any(os.path.commonpath([real, f]) == f for f in folders):
        raise GraspValueError(f"{where}: {key} {name!r} is outside the file's folder; pass --allow-dir DIR to allow it")
    return Path(real)


def _model_key(path: Path, hand: dict) -> str:
    """``"model"`` or ``"mjcf"``: the [hand] key naming the hand file (exactly one)."""
    keys = [k for k in ("model", "mjcf") if k in hand]
    if len(keys) != 1:
        raise GraspValueError(f"{path}: [hand] needs model = \"HAND.xml or HAND.urdf\" (or its older name mjcf), "
                              f"{'not both' if keys else 'missing'}")
    return keys[0]


def _tables(path: Path) -> dict:
    """The file's tables, checked for unknown tables and keys (one-line errors)."""
    raw = read_input(path, MAX_GRASP_FILE_BYTES, "hand grasp file")
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise GraspValueError(f"{path}: malformed TOML: {' '.join(str(exc).split())}") from None
    for table, value in data.items():
        if table not in _TABLES or not isinstance(value, dict):
            raise GraspValueError(f"{path}: unknown table [{table}]; a hand grasp file has [hand], [object] and [fingertip]")
        unknown = sorted(set(value) - set(_TABLES[table]))
        if unknown:
            raise GraspValueError(f"{path}: unknown key {unknown[0]!r} in [{table}]; its keys: {', '.join(_TABLES[table])}")
    model = _model_key(path, data.get("hand", {}))
    for table, key in (("hand", "fingertips"), ("hand", "qpos"), ("object", "mesh")):
        if key not in data.get(table, {}):
            raise GraspValueError(f"{path}: [{table}] {key} is missing")
    for table, key in (("hand", model), ("object", "mesh"), ("object", "units")):
        if not isinstance(data[table].get(key, ""), str):
            raise GraspValueError(f"{path}: [{table}] {key} must be a string, got {type(data[table][key]).__name__}")
    return data


def _opened(path: Path, allowed_dirs):
    """``(hand, mesh path, object table, fingertip table, hand table)`` of a hand grasp file."""
    from jaxgrasp.hands._hand import Hand

    data = _tables(path)
    allowed = allowed_folders(allowed_dirs)
    hand_t, obj, tip = data["hand"], data["object"], data.get("fingertip", {})
    key = _model_key(path, hand_t)
    hand = Hand.from_file(_confined_model(hand_t[key], path.parent, allowed, str(path), key), hand_t["fingertips"],
                          allowed)
    mesh = confine(obj["mesh"], path.parent, allowed, "hand grasp file")
    missing = [k for k in _TABLES["fingertip"] if k not in tip]
    if missing:
        raise GraspValueError(f"{path}: [fingertip] {missing[0]} is missing")
    return hand, mesh, obj, tip, hand_t


def load_hand_grasp(path: str | os.PathLike, allowed_dirs=None):
    """The [`HandGrasp`][jaxgrasp.hands.HandGrasp] a hand grasp file describes (module notes).

    Raises:
        GraspValueError: an unreadable or malformed file, a missing or unknown key, a path
            outside the allowed folders, invalid values, or a file of several
            configurations (read those with `load_hand_batch`); one line naming the file.
    """
    path = Path(path)
    hand, mesh, obj, tip, hand_t = _opened(path, allowed_dirs)
    if _stacked(hand_t["qpos"]) and len(hand_t["qpos"]) != 1:
        raise GraspValueError(f"{path}: [hand] qpos holds {len(hand_t['qpos'])} configurations; this reads one "
                              "(evaluate them all with jaxgrasp batch)")
    qpos, wrist = _single(hand_t["qpos"]), _single(hand_t.get("wrist"))
    return hand.grasp(
        qpos, str(mesh), wrist=wrist, object_pose=obj.get("pose"), units=obj.get("units", "m"),
        mass=obj.get("mass"), density=obj.get("density"), **{k: tip[k] for k in _TABLES["fingertip"]},
    )


def _stacked(value) -> bool:
    """Whether ``value`` is a list of lists of one length (several configurations; a ragged
    one is refused by the reader of the values, in its words)."""
    return (isinstance(value, list) and bool(value) and all(isinstance(v, list) for v in value)
            and len({len(v) for v in value}) == 1)


def _single(value):
    """A list of one list (one configuration written as ``(1, n)``) as that list."""
    return value[0] if isinstance(value, list) and len(value) == 1 and isinstance(value[0], list) else value


def load_hand_batch(path: str | os.PathLike, allowed_dirs=None, progress=None):
    """The [`HandBatch`][jaxgrasp.hands.HandBatch] of a hand grasp file whose ``qpos`` is one
    configuration ``(J,)`` or several ``(B, J)`` (``wrist`` then ``(6,)`` or ``(B, 6)``):
    the project's own dataset of hand grasps (module notes; `hand_batch`).

    Raises:
        GraspValueError: as `load_hand_grasp`; one line naming the file.
    """
    import hashlib

    from jaxgrasp.hands._batch import hand_batch

    path = Path(path)
    hand, mesh, obj, tip, hand_t = _opened(path, allowed_dirs)
    qpos = hand_t["qpos"] if _stacked(hand_t["qpos"]) else [hand_t["qpos"]]
    sha = hashlib.sha256(read_input(path, MAX_GRASP_FILE_BYTES, "hand grasp file")).hexdigest()
    return hand_batch(hand, str(mesh), qpos, wrist=hand_t.get("wrist"), object_pose=obj.get("pose"),
                      units=obj.get("units", "m"), mass=obj.get("mass"), density=obj.get("density"),
                      progress=progress, source=str(path), source_sha256=sha,
                      **{k: tip[k] for k in _TABLES["fingertip"]})


def is_hand_grasp_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a hand grasp file: a readable ``.toml`` file with a ``[hand]``
    table (what the commands that take a grasp file look at to read it as a hand's)."""
    path = Path(path)
    if path.suffix.lower() != ".toml":
        return False
    try:
        data = tomllib.loads(read_input(path, MAX_GRASP_FILE_BYTES, "grasp file").decode("utf-8-sig"))
    except (GraspValueError, UnicodeDecodeError, ValueError):
        return False  # the grasp-file reader says what is wrong with it
    return isinstance(data.get("hand"), dict)


def _toml_value(v) -> str:
    if isinstance(v, dict):  # an inline table (a hemisphere fingertip)
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(x) for x in (v.tolist() if isinstance(v, np.ndarray) else v)) + "]"
    return repr(float(v))


def hand_grasp_toml(tables: dict) -> str:
    """TOML text of ``tables`` (``{"hand": {...}, "object": {...}, "fingertip": {...}}``)."""
    lines = []
    for table in _TABLES:
        lines.append(f"[{table}]")
        for key, value in tables.get(table, {}).items():
            if value is not None:
                lines.append(f"{key} = {_toml_value(value)}")
        lines.append("")
    return "\n".join(lines)


def save_hand_grasp(path: str | os.PathLike, *, fingertips, qpos, mesh: str, young_modulus, friction, max_force,
                    model: str | None = None, mjcf: str | None = None, wrist=None, pose=None, mass=None, density=None,
                    units: str = "m") -> None:
    """Write a hand grasp file (atomically); ``model`` (MJCF or URDF; ``mjcf``: its older
    name) and ``mesh`` as they should be written (relative to the file's folder);
    ``fingertips`` names or ``{link, center, axis, radius}`` dicts."""
    from jaxgrasp import storage

    if (model is None) == (mjcf is None):
        raise GraspValueError("save_hand_grasp: give the hand file as model= (or mjcf=), once")
    tips = [{k: np.asarray(t[k]).tolist() if k != "link" else t[k] for k in t} if isinstance(t, dict) else t
            for t in fingertips]
    text = hand_grasp_toml({
        "hand": {"model": model if model is not None else mjcf, "fingertips": tips, "qpos": np.asarray(qpos, float),
                 "wrist": wrist},
        "object": {"mesh": mesh, "units": units, "pose": pose, "mass": mass, "density": density},
        "fingertip": {"young_modulus": young_modulus, "friction": friction, "max_force": max_force},
    })
    storage.write_file(Path(path), text.encode("utf-8"))
