"""Grasp files: TOML or JSON, SI units.

Format (TOML; JSON is the same structure as one object with keys ``fingertip``,
``object`` and ``contacts``)::

    [fingertip]              # defaults for every contact; may be overridden per contact
    radius = 0.025           # m
    young_modulus = 2e5      # Pa
    friction = 0.5           # static friction coefficient, dimensionless
    max_force = 15.0         # N, upper limit of each normal contact force

    [object]                 # optional
    mass = 0.1               # kg, default 0
    gravity = [0, 0, -9.81]  # m/s^2, object frame, default (0, 0, -9.81)
    # mesh = "part.stl"      # optional: the object's mesh, path relative to this file (inside its folder)
    # units = "mm"           # the mesh's length unit: m (default), cm or mm
    # density = 1200.0       # kg/m^3: mass = density x volume (instead of mass)
    # center_of_mass = [0, 0, 0.01]  # m, mesh frame (default: the watertight mesh's)

    [[contacts]]             # one table per contact, at least 2
    position = [0.05, 0, 0]      # m, object frame, origin at the centre of mass
    normal = [1, 0, 0]           # outward surface normal (any non-zero length)
    initial_deformation = 0.002  # m, in (0, radius)
    # radius / young_modulus / friction / max_force here override [fingertip]

With ``mesh``, contact positions are in metres in the mesh's own frame (its origin and
axes, after the unit conversion), each is snapped to the surface, ``normal`` may be
omitted (the mesh's outward normal there), and the grasp is moved to the centre-of-mass
frame ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh]); ``load(path, keep_mesh=True)`` returns the
[`MeshGrasp`][jaxgrasp.MeshGrasp] with the mesh and that offset.

Each fingertip key must be given in ``[fingertip]`` or in every contact. Unknown keys,
keys given twice in one table (JSON too, not only TOML), wrong types (booleans are not
numbers), malformed files and physically invalid values all raise
[`GraspValueError`][jaxgrasp.GraspValueError] with a one-line message prefixed by the
file name. Files are UTF-8, with or without a byte-order mark.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from jaxgrasp import storage
from jaxgrasp.io._inputs import MAX_GRASP_FILE_BYTES, MAX_MESH_BYTES, read_input
from jaxgrasp.io._mesh import MeshReader, from_mesh, load_mesh
from jaxgrasp.model import FIELD, FIELDS, FINGERTIP, Grasp, GraspValueError, check_grasp_inputs
from jaxgrasp.surface import MeshGrasp

__all__ = ["checked_fields", "dict_to_text", "dict_to_toml", "grasp_from_dict", "grasp_to_dict", "load", "copied_mesh", "mesh_grasp_to_dict", "mesh_reference", "save", "to_text", "to_toml"]

TOP_KEYS = ("fingertip", "object", "contacts")
FINGERTIP_KEYS = tuple(FIELD[name].file_key for name in FINGERTIP)
MESH_KEYS = ("mesh", "units", "density", "center_of_mass")
"""``[object]`` keys of an object given by its mesh ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh])."""
OBJECT_KEYS = tuple(f.file_key for f in FIELDS if f.file_section == "object") + MESH_KEYS
CONTACT_REQUIRED = tuple(f.file_key for f in FIELDS if f.file_section == "contacts")
CONTACT_KEYS = CONTACT_REQUIRED + FINGERTIP_KEYS
_COMMENTS = {f.file_key: f.comment for f in FIELDS}


# ----------------------------------------------------------------------------- parsing


def _show(value: Any, limit: int = 60) -> str:
    """One-line text of a parsed value for error messages (JSON-like, truncated)."""
    try:
        text = json.dumps(value, ensure_ascii=False, allow_nan=True)
    except (TypeError, ValueError, OverflowError, RecursionError):
        text = repr(value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(value: Any, path: str) -> float:
    if not _is_number(value):
        kind = "a boolean" if isinstance(value, bool) else type(value).__name__
        raise GraspValueError(f"{path} = {_show(value)} must be a number (got {kind})")
    try:
        return float(value)
    except OverflowError:
        raise GraspValueError(f"{path} = {_show(value)} is too large to be a finite number") from None


def _vector3(value: Any, path: str) -> list[float]:
    if (
        not isinstance(value, (list, tuple))
        or len(value) != 3
        or not all(_is_number(v) for v in value)
    ):
        raise GraspValueError(f"{path} = {_show(value)} must be a list of 3 numbers")
    return [_number(v, f"{path}[{k}]") for k, v in enumerate(value)]


def _check_keys(table: Mapping, allowed: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise GraspValueError(
                f"unknown key {key!r} {where}; expected one of {', '.join(allowed)}"
            )


def _table(value: Any, path: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise GraspValueError(f"{path} = {_show(value)} must be a table (object)")
    return value


def _value(field, value: Any, path: str):
    """A file value of ``field``: a 3-vector for vector fields, else a number."""
    if field.shape in ("points", "directions", "vector"):
        return _vector3(value, path)
    return _number(value, path)


def _grasp_kwargs(data: Any) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """Turn a parsed file into keyword arguments for [`Grasp.create`][jaxgrasp.Grasp.create], and the mesh
    keys of ``[object]`` (``None`` when it names no mesh)."""
    if not isinstance(data, Mapping):
        raise GraspValueError(
            f"the top level must be a table (object) with keys {', '.join(TOP_KEYS)}, "
            f"got {_show(data)}"
        )
    _check_keys(data, TOP_KEYS, "at top level")
    fingertip = _table(data.get("fingertip", {}), "fingertip")
    _check_keys(fingertip, FINGERTIP_KEYS, "in [fingertip]")
    defaults = {k: _number(v, f"fingertip.{k}") for k, v in fingertip.items()}
    obj = _table(data.get("object", {}), "object")
    _check_keys(obj, OBJECT_KEYS, "in [object]")
    mesh = _mesh_keys(obj)
    kwargs: dict[str, Any] = {}
    for f in FIELDS:
        if f.file_section == "object":
            kwargs[f.name] = _value(f, obj[f.file_key], f"object.{f.file_key}") if f.file_key in obj else f.default
    if mesh is not None and "mass" not in obj:
        kwargs["mass"] = None  # from_mesh: from the density, or the default
    optional = ("normal",) if mesh is not None else ()
    kwargs.update(_contact_kwargs(_contact_tables(data), defaults, optional))
    return kwargs, mesh


def _mesh_keys(obj: Mapping) -> dict[str, Any] | None:
    """The mesh keys of ``[object]`` as [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] arguments, or ``None``."""
    if "mesh" not in obj:
        extra = [k for k in MESH_KEYS if k in obj]
        if extra:
            raise GraspValueError(f"object.{extra[0]} is given without object.mesh (the object's mesh file)")
        return None
    out: dict[str, Any] = {}
    for key in ("mesh", "units"):
        if key in obj and not (isinstance(obj[key], str) and obj[key]):
            raise GraspValueError(f"object.{key} = {_show(obj[key])} must be a non-empty string")
    out["mesh"], out["units"] = obj["mesh"], obj.get("units", "m")
    if "density" in obj:
        out["density"] = _number(obj["density"], "object.density")
    if "center_of_mass" in obj:
        out["center_of_mass"] = _vector3(obj["center_of_mass"], "object.center_of_mass")
    return out


def _contact_tables(data: Mapping) -> list:
    if "contacts" not in data:
        raise GraspValueError("no contacts: give at least 2 [[contacts]] tables")
    contacts = data["contacts"]
    if not isinstance(contacts, (list, tuple)) or not all(isinstance(c, Mapping) for c in contacts):
        raise GraspValueError(
            f"contacts = {_show(contacts)} must be a list of tables ([[contacts]])"
        )
    if len(contacts) == 0:
        raise GraspValueError("contacts is empty: give at least 2 [[contacts]] tables")
    return list(contacts)


def _contact_kwargs(contacts: list, defaults: dict, optional: tuple[str, ...] = ()) -> dict[str, Any]:
    """The per-contact fields of the contact tables, with ``[fingertip]`` ``defaults``;
    a contact key in ``optional`` may be missing (its value is then ``None``)."""
    per_contact = [f for f in FIELDS if f.file_section in ("contacts", "fingertip")]
    values: dict[str, list] = {f.name: [] for f in per_contact}
    overridden = {key: False for key in FINGERTIP_KEYS}
    for i, contact in enumerate(contacts):
        where = f"contacts[{i}]"
        _check_keys(contact, CONTACT_KEYS, f"in {where}")
        for key in CONTACT_REQUIRED:
            if key not in contact and key not in optional:
                raise GraspValueError(f"{where} is missing key {key!r}")
        for f in per_contact:
            key = f.file_key
            if key in contact:
                values[f.name].append(_value(f, contact[key], f"{where}.{key}"))
                if key in overridden:
                    overridden[key] = True
            elif key in defaults:
                values[f.name].append(defaults[key])
            elif key in optional:
                values[f.name].append(None)
            else:
                raise GraspValueError(
                    f"{where} has no {key!r} and [fingertip] does not give one; "
                    f"give {key} in [fingertip] or in every contact"
                )
    # a value taken only from [fingertip] is passed as a scalar, so error messages
    # name it without a contact index
    for f in per_contact:
        if f.file_section == "fingertip" and not overridden[f.file_key]:
            values[f.name] = defaults[f.file_key]
    return values


def grasp_from_dict(data: Mapping, source: str = "<dict>", base=None, *, allowed_dirs=None) -> Grasp:
    """Build a validated [`Grasp`][jaxgrasp.Grasp] from a parsed grasp file (TOML/JSON structure).

    Args:
        data: ``{"fingertip": {...}, "object": {...}, "contacts": [{...}, ...]}``, SI units.
        source: name used as the prefix of error messages (a file name).
        base: the folder of the file the data came from: a relative ``object.mesh`` path
            is taken from it, and the mesh must lie inside it (after symlinks) or inside
            one of ``allowed_dirs``. ``None``: a relative path is taken from the current
            folder and not confined (data built in Python).
        allowed_dirs: folders (paths) outside ``base`` that meshes may be in.

    Raises:
        GraspValueError: anything wrong with the data; message ``"<source>: <problem>"``.
    """
    meshes = None if base is None else MeshReader(base, allowed_dirs, owner="grasp file")
    built = _build(data, source, meshes)
    return built.grasp if isinstance(built, MeshGrasp) else built


def checked_fields(data: Mapping, source: str, meshes) -> dict[str, np.ndarray]:
    """The validated fields of parsed grasp data as float64 NumPy arrays (those of
    `check_grasp_inputs`: per-contact fields ``(N,)``,
    unit normals), without building a [`Grasp`][jaxgrasp.Grasp] of JAX arrays; ``meshes``: the
    `MeshReader` of the data's file.

    Raises:
        GraspValueError: as [`grasp_from_dict`][jaxgrasp.io.grasp_from_dict].
    """
    built = _build(data, source, meshes, as_fields=True)
    if isinstance(built, dict):
        return built
    grasp = built.grasp  # a mesh's grasp, made by from_mesh: its fields as NumPy arrays
    return {f.name: np.asarray(getattr(grasp, f.name), dtype=np.float64) for f in FIELDS}


def _build(data: Mapping, source: str, meshes, as_fields: bool = False):
    """The grasp of parsed file data: a [`MeshGrasp`][jaxgrasp.MeshGrasp] where it names a mesh (read by
    ``meshes``, a `MeshReader`, or ``None``: from the current
    folder); else a [`Grasp`][jaxgrasp.Grasp], or with ``as_fields`` its checked NumPy fields."""
    try:
        kwargs, mesh = _grasp_kwargs(data)
        if mesh is None:
            return check_grasp_inputs(**kwargs) if as_fields else Grasp.create(**kwargs)
        name, units = mesh.pop("mesh"), mesh.pop("units")
        surface, shown = meshes(name, units) if meshes is not None else (load_mesh(name, units), name)
        made = from_mesh(surface, kwargs.pop("positions"), normals=kwargs.pop("normals"), **mesh, **kwargs)
        return made.replace(source=shown, units=units)
    except GraspValueError as exc:
        raise GraspValueError(f"{source}: {exc}") from None
    except RecursionError:
        raise GraspValueError(f"{source}: data nested too deeply") from None


def _format(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise GraspValueError(
            f"{path}: unknown grasp file type {path.suffix!r}; use .toml or .json"
        )
    return suffix[1:]


class _JsonObject(dict):
    """A parsed JSON object that remembers the keys it was given more than once."""

    duplicates: list


def _json_object(pairs) -> _JsonObject:
    """``object_pairs_hook`` of `json.loads`: keep every object's duplicate keys
    (plain ``json`` silently keeps the last value; TOML rejects a repeated key)."""
    obj = _JsonObject()
    obj.duplicates = []
    for key, value in pairs:
        if key in obj and key not in obj.duplicates:
            obj.duplicates.append(key)
        obj[key] = value
    return obj


def _first_duplicate(value: Any, where: str = "") -> str | None:
    """``"key 'k' in fingertip"`` for the first repeated key in document order, or ``None``."""
    if isinstance(value, _JsonObject):
        if value.duplicates:
            return f"key {value.duplicates[0]!r} " + (f"in {where}" if where else "at top level")
        items = ((k, f"{where}.{k}" if where else k) for k, v in value.items())
        children = [(value[k], w) for k, w in items]
    elif isinstance(value, list):
        children = [(v, f"{where}[{i}]") for i, v in enumerate(value)]
    else:
        return None
    for child, w in children:
        found = _first_duplicate(child, w)
        if found:
            return found
    return None


def _parse_json(raw: bytes) -> Any:
    """Parse JSON, rejecting a key given twice in one object (one-line ValueError)."""
    data = json.loads(raw, object_pairs_hook=_json_object)
    dup = _first_duplicate(data)
    if dup:
        raise ValueError(f"{dup} is given more than once; give each key once")
    return data


def load(path: str | os.PathLike, *, keep_mesh: bool = False, allowed_dirs=None) -> Grasp | MeshGrasp:
    """Read a grasp file (``.toml`` or ``.json``, SI units) and return a validated [`Grasp`][jaxgrasp.Grasp].

    UTF-8 text, with or without a byte-order mark. A key given twice in one table is an
    error in both formats. A file whose ``[object]`` names a ``mesh`` (path relative to
    the file) gives the grasp in the centre-of-mass frame ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh]);
    with ``keep_mesh=True`` it gives its [`MeshGrasp`][jaxgrasp.MeshGrasp] instead (the
    grasp, the mesh and the frame offset), for drawing. A file without a mesh gives its
    [`Grasp`][jaxgrasp.Grasp] either way.

    The mesh must lie inside the grasp file's folder after symlinks, or inside one of
    ``allowed_dirs`` (folder paths), and be a mesh format
    (`MESH_SUFFIXES`). The grasp file must be a regular file
    of at most `MAX_GRASP_FILE_BYTES` bytes (not a FIFO or a
    device), checked before it is read.

    Raises:
        GraspValueError: missing/unreadable file, a folder, a special file, a file over
            the size cap, unknown extension, malformed TOML/JSON, invalid content, or a
            mesh outside the allowed folders; the message is one line starting with the
            file name.
    """
    path = Path(path)
    if path.is_dir():
        raise GraspValueError(f"{path}: is a folder, not a grasp file (.toml or .json)")
    fmt = _format(path)
    raw = read_input(path, MAX_GRASP_FILE_BYTES, "grasp file")
    try:
        if fmt == "toml":
            data = tomllib.loads(raw.decode("utf-8-sig"))  # a leading BOM is not TOML syntax
        else:
            data = _parse_json(raw)
    except UnicodeDecodeError as exc:
        raise GraspValueError(f"{path}: not valid UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # TOMLDecodeError, JSONDecodeError, int-too-long
        kind = "TOML" if fmt == "toml" else "JSON"
        raise GraspValueError(f"{path}: malformed {kind}: {exc}") from None
    except RecursionError:
        raise GraspValueError(f"{path}: malformed {fmt.upper()}: nested too deeply") from None
    built = _build(data, str(path), MeshReader(path.parent, allowed_dirs, owner="grasp file"))
    return built.grasp if isinstance(built, MeshGrasp) and not keep_mesh else built


# ----------------------------------------------------------------------------- writing


def _floats(arr: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(arr, dtype=np.float64).reshape(-1)]


def grasp_to_dict(grasp: Grasp) -> dict[str, Any]:
    """The file structure of a single (unbatched) grasp, as plain Python floats.

    Per-fingertip values equal across all contacts go into ``"fingertip"``; the others
    are written per contact. Only active contacts are written ([`Grasp.compact`][jaxgrasp.Grasp.compact]). ``grasp_from_dict(grasp_to_dict(g))`` reproduces ``g``.
    """
    fields = grasp.compact().to_numpy()  # a file lists the contacts the grasp has
    pos = np.asarray(fields["positions"], dtype=np.float64)
    if pos.ndim != 2 or pos.shape[-1] != 3:
        raise GraspValueError(
            f"grasp_to_dict needs a single grasp with positions of shape (N, 3), got {pos.shape}"
        )
    n = pos.shape[0]

    def per_contact(name: str) -> np.ndarray:
        arr = np.asarray(fields[name], dtype=np.float64)
        try:
            return np.broadcast_to(arr, (n,))
        except ValueError:
            raise GraspValueError(
                f"grasp_to_dict needs {name} of shape ({n},), got {arr.shape}"
            ) from None

    normals = np.broadcast_to(np.asarray(fields["normals"], dtype=np.float64), (n, 3))
    dr = per_contact("initial_deformation")
    fingertip: dict[str, float] = {}
    varying: dict[str, np.ndarray] = {}
    for key in FINGERTIP_KEYS:
        arr = per_contact(key)
        if np.array_equal(arr, np.full(n, arr[0])) and n > 0:
            fingertip[key] = float(arr[0])
        else:
            varying[key] = arr
    contacts = []
    for i in range(n):
        c: dict[str, Any] = {
            "position": _floats(pos[i]),
            "normal": _floats(normals[i]),
            "initial_deformation": float(dr[i]),
        }
        for key, arr in varying.items():
            c[key] = float(arr[i])
        contacts.append(c)
    out: dict[str, Any] = {}
    if fingertip:
        out["fingertip"] = fingertip
    out["object"] = {
        "mass": float(np.asarray(fields["mass"], dtype=np.float64)),
        "gravity": _floats(fields["gravity"]),
    }
    out["contacts"] = contacts
    return out


def _toml_float(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))  # repr round-trips exactly and is valid TOML ("1e-05", "0.5")


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, list):
        return "[" + ", ".join(_toml_float(v) for v in value) + "]"
    return _toml_float(value)


def _toml_lines(table: Mapping[str, Any]) -> list[str]:
    lines = []
    for key, value in table.items():
        line = f"{key} = {_toml_value(value)}"
        comment = _COMMENTS.get(key)
        lines.append(f"{line:<44} # {comment}" if comment else line)
    return lines


def mesh_grasp_to_dict(mesh_grasp: MeshGrasp, mesh_name: str, mesh_positions=None) -> dict[str, Any]:
    """The file structure of a grasp of a meshed object: [`grasp_to_dict`][jaxgrasp.io.grasp_to_dict] with
    ``[object] mesh = mesh_name`` (the path as the file will name it), its ``units`` and
    ``center_of_mass`` (m, mesh frame), contact positions in the mesh's frame (m) and each
    contact's normal (so that [`load`][jaxgrasp.load] gives back the same normals, also on an edge).

    ``mesh_positions``: ``(N, 3)`` m, the mesh-frame positions to write, where the caller
    has them (the points the grasp was made from: the file then loads to this very grasp);
    default the grasp's positions moved back into the mesh's frame."""
    d = grasp_to_dict(mesh_grasp.grasp)
    com = np.asarray(mesh_grasp.center_of_mass, dtype=np.float64)
    d["object"] = {"mesh": mesh_name, "units": mesh_grasp.units, "center_of_mass": _floats(com), **d["object"]}
    given = None if mesh_positions is None else np.asarray(mesh_positions, dtype=np.float64)
    for i, contact in enumerate(d["contacts"]):
        contact["position"] = _floats(np.asarray(contact["position"]) + com if given is None else given[i])
    return d


def to_toml(grasp: Grasp | MeshGrasp, mesh_name: str | None = None) -> str:
    """TOML text of a grasp (the fixed grasp-file structure; floats written with ``repr``);
    a [`MeshGrasp`][jaxgrasp.MeshGrasp] names its mesh as ``mesh_name`` (`mesh_grasp_to_dict`)."""
    d = grasp_to_dict(grasp) if mesh_name is None else mesh_grasp_to_dict(grasp, mesh_name)
    return dict_to_toml(d)


def dict_to_toml(d: Mapping[str, Any]) -> str:
    """TOML text of a grasp file's structure ([`grasp_to_dict`][jaxgrasp.io.grasp_to_dict], `mesh_grasp_to_dict`)."""
    mesh = "mesh" in d["object"]
    frame = "positions in the mesh's frame" if mesh else "object frame at the centre of mass"
    lines = [f"# Grasp file (jaxgrasp). SI units: m, Pa, N, kg, m/s^2; {frame}."]
    if "fingertip" in d:
        lines += ["", "[fingertip]"] + _toml_lines(d["fingertip"])
    lines += ["", "[object]"] + _toml_lines(d["object"])
    for contact in d["contacts"]:
        lines += ["", "[[contacts]]"] + _toml_lines(contact)
    return "\n".join(lines) + "\n"


def dict_to_text(d: Mapping[str, Any], path: str | os.PathLike) -> str:
    """A grasp file's structure as the text of ``path``'s format (TOML or JSON by extension)."""
    return dict_to_toml(d) if _format(Path(path)) == "toml" else json.dumps(d, indent=2) + "\n"


def to_text(grasp: Grasp | MeshGrasp, path: str | os.PathLike, mesh_name: str | None = None) -> str:
    """The text [`save`][jaxgrasp.save] writes to ``path``: TOML or JSON by its extension."""
    d = grasp_to_dict(grasp) if mesh_name is None else mesh_grasp_to_dict(grasp, mesh_name)
    return dict_to_text(d, path)


def save(grasp: Grasp | MeshGrasp, path: str | os.PathLike, *, copy_mesh: bool = False) -> None:
    """Write a single grasp to ``path`` (``.toml`` or ``.json`` by extension, SI units).

    Floats are written so that [`load`][jaxgrasp.load] reproduces the grasp bit for bit (a mesh grasp:
    to the rounding of moving its positions into the mesh's frame and back). The file is
    written atomically (a temporary file renamed into place, `jaxgrasp.storage`): a
    failure leaves the previous file as it was.

    A [`MeshGrasp`][jaxgrasp.MeshGrasp] is written with ``[object] mesh`` naming its mesh file relative to
    ``path``'s folder ([`load`][jaxgrasp.load] reads meshes inside that folder, or in its
    ``allowed_dirs``). With ``copy_mesh=True`` the mesh is copied into that folder first
    (its file's bytes, or, for a mesh given as a ``trimesh.Trimesh``, an STL in metres)
    unless it is there already, so the folder holds everything the file needs.
    """
    if isinstance(grasp, MeshGrasp):
        name, raw = mesh_reference(grasp, Path(path).parent, copy_mesh)
        if raw is not None:
            storage.write_file(Path(path).parent / name, raw)
        storage.write_file(path, to_text(grasp, path, name).encode("utf-8"))
        return
    storage.write_file(path, to_text(grasp, path).encode("utf-8"))


def mesh_reference(mesh_grasp: MeshGrasp, folder, copy: bool) -> tuple[str, bytes | None]:
    """``(name, bytes)``: how a grasp file in ``folder`` names ``mesh_grasp``'s mesh, and
    the bytes of a copy to write there as ``folder / name`` (``None``: nothing to write).

    Without ``copy`` the name is the mesh file's path relative to ``folder``. With it, a
    mesh already in ``folder`` (or an identical copy there) is named as it is; otherwise the
    copy is the mesh file's bytes under its own name, or an STL in metres for a mesh given
    as a ``trimesh.Trimesh``.
    """
    folder, source = Path(folder), mesh_grasp.source
    if source == "<trimesh>":
        if not copy:
            raise GraspValueError("save: this grasp's mesh was given as a trimesh.Trimesh, not a file: use copy_mesh=True")
        import trimesh.exchange.stl

        name, raw = "mesh.stl", trimesh.exchange.stl.export_stl(mesh_grasp.mesh)
    elif not copy:
        return os.path.relpath(os.path.abspath(source), os.path.abspath(folder)), None
    else:
        return copied_mesh(source, folder)
    dest = folder / name
    if dest.is_file() and dest.read_bytes() == raw:
        return name, None
    return name, raw


def copied_mesh(source: str | os.PathLike, folder) -> tuple[str, bytes | None]:
    """``(name, bytes)``: the mesh file ``source`` as a file in ``folder`` names it (its own
    name), and the bytes of the copy to write there as ``folder / name`` (``None``: the file,
    or an identical copy, is there already)."""
    folder = Path(folder)
    if Path(source).resolve().parent == folder.resolve():
        return Path(source).name, None
    name, raw = Path(source).name, read_input(source, MAX_MESH_BYTES, "mesh")
    dest = folder / name
    if dest.is_file() and dest.read_bytes() == raw:
        return name, None
    return name, raw
