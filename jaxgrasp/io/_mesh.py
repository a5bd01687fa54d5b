"""Mesh files in: a checked mesh in metres from a file or a ``trimesh.Trimesh``, and
[`from_mesh`][jaxgrasp.from_mesh], which reads one and builds the grasp on it.

`load_mesh` (and `read_mesh`, which also gives the bytes' SHA-256) parses a
mesh file (STL, OBJ, PLY, OFF, GLB) from its bytes as the format its name says, rejects a
degenerate mesh in one line (no faces, NaN, infinite or far vertices, no area, a closed
mesh with no volume or no inside) and turns a closed inward mesh outward;
`MeshReader` reads the meshes a grasp file or a dataset names, confined to its
folder. [`from_mesh`][jaxgrasp.from_mesh] is `load_mesh` then
`jaxgrasp.surface.grasp_on_mesh`: the geometry (snapping contacts to the surface, the
centre of mass, the frame) and [`MeshGrasp`][jaxgrasp.MeshGrasp] live in `jaxgrasp.surface`.

trimesh is imported when a mesh is used, so ``import jaxgrasp`` does not pay for it.
"""

from __future__ import annotations

import collections
import hashlib
import io
import json
import os
import struct

import numpy as np

from jaxgrasp.io._inputs import (
    MAX_MESH_BYTES,
    MAX_MESH_DECLARED_BYTES,
    MAX_MESH_FACES,
    allowed_folders,
    check_mesh_suffix,
    confine,
    read_input,
)
from jaxgrasp.model import (
    COINCIDENT_DISTANCE,
    DEFAULT_GRAVITY,
    LENGTH_UNITS,
    MAX_COORDINATE,
    MAX_OBJECT_SIZE,
    GraspValueError,
)
from jaxgrasp.surface import DEFAULT_TOLERANCE, MeshGrasp, grasp_on_mesh

__all__ = ["MeshReader", "from_mesh", "load_mesh", "read_mesh", "PYTHON_UNITS", "FILE_UNITS"]

PYTHON_UNITS = 'pass units="{}" (in a grasp or hand file: units = "{}" in [object])'
"""How to give a mesh's units, for `load_mesh`'s message of a mesh too large to be
grasped (`MAX_OBJECT_SIZE`): ``PYTHON_UNITS.format(unit, unit)``."""

FILE_UNITS = 'add units = "{}" to [object]'
"""The same for a mesh a grasp file or a dataset names (`MeshReader`)."""


def load_mesh(mesh, units: str = "m", *, how: str = PYTHON_UNITS):
    """A checked ``trimesh.Trimesh`` in metres from a ``Trimesh`` or a mesh file path.

    Args:
        mesh: ``trimesh.Trimesh`` or a path to a mesh file of one of the formats of
            `MESH_SUFFIXES` (STL, OBJ, PLY, OFF, GLB; a scene of
            several parts is joined into one mesh), at most
            `MAX_MESH_BYTES` bytes, a regular file. It is parsed
            from its bytes as the format its name says, so it cannot reach other files.
        units: the length unit of the vertices: ``"m"``, ``"cm"`` or ``"mm"``.
        how: how the caller gives ``units``, for the message of a mesh too large to be
            grasped: a format string of the unit (twice), such as `PYTHON_UNITS`.

    Returns:
        A new mesh, vertices in m (the input is not changed), faces turned outward when
        the mesh is watertight with its faces inward.

    Raises:
        GraspValueError: unknown units, a file that is not a mesh format, too large, not a
            regular file or unreadable, or a degenerate mesh (no faces, NaN or infinite
            vertex coordinates, a coordinate beyond `MAX_COORDINATE`, no area, a
            closed mesh enclosing no volume or with faces not consistently oriented), or
            one more than `MAX_OBJECT_SIZE` across (vertices in mm read as metres: the
            message names the fix, ``how``); one line.
    """
    import trimesh

    _check_units(units)
    if isinstance(mesh, (str, os.PathLike)):
        return read_mesh(mesh, units, how=how)[0]
    if not isinstance(mesh, trimesh.Trimesh):
        raise GraspValueError(f"mesh must be a trimesh.Trimesh or a file path, got {type(mesh).__name__}")
    return _checked(mesh, "mesh", units, how=how)


def _check_units(units: str) -> None:
    if units not in LENGTH_UNITS:
        raise GraspValueError(f"units = {units!r} is not a length unit; use one of {', '.join(LENGTH_UNITS)}")


def read_mesh(path: str | os.PathLike, units: str = "m", *, real: str | os.PathLike | None = None,
              how: str = PYTHON_UNITS):
    """``(mesh, sha256)``: the checked mesh (metres, `load_mesh`) of the file ``path``
    and the SHA-256 (hex) of the bytes it was parsed from.

    ``real``: where to read it from, when the caller has resolved ``path`` already
    (`confine`); messages name ``path``. ``how``: as for `load_mesh`.
    """
    import trimesh

    _check_units(units)
    where = f"mesh {os.fspath(path)!r}"
    fmt = check_mesh_suffix(path)
    source = os.fspath(path if real is None else real)
    try:
        raw = read_input(source, MAX_MESH_BYTES, "mesh")
    except GraspValueError as exc:  # "<source>: no such file" -> "mesh '<path>': no such file"
        raise GraspValueError(f"{where}: {str(exc).removeprefix(source + ': ')}") from None
    _check_declared(raw, fmt, where)
    try:  # processed in _checked, after its vertices are checked: processing drops NaN vertices silently
        # geometry only: materials would decode every texture image (a small GLB can hold gigapixels)
        skip = {"skip_materials": True} if fmt in ("glb", "obj") else {}
        loaded = trimesh.load(io.BytesIO(raw), file_type=fmt, force="mesh", process=False, **skip)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise GraspValueError(f"{where}: cannot read it as a mesh ({' '.join(str(exc).split()) or type(exc).__name__})") from None
    return _checked(loaded, where, units, process=True, how=how), hashlib.sha256(raw).hexdigest()


def _checked(loaded, where: str, units: str, process: bool = False, how: str = PYTHON_UNITS):
    """A copy of ``loaded`` in metres whose vertices passed `_check_vertices` and
    `_check_extent`, and surface `_check_surface`; with ``process``, its duplicate
    vertices merged as ``trimesh.load(..., process=True)`` does (in the file's units, as
    that does)."""
    import trimesh

    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise GraspValueError(f"{where} has no faces (a degenerate mesh)")
    _check_counts(len(loaded.faces), len(loaded.vertices), where)
    _check_vertices(np.asarray(loaded.vertices, dtype=np.float64), where, LENGTH_UNITS[units])
    out = loaded.copy()
    if process:
        out.process()
    out.apply_scale(LENGTH_UNITS[units])
    _check_extent(out, where, units, how)
    _check_surface(out, where)
    return out


def _check_extent(mesh, where: str, units: str, how: str) -> None:
    """Reject a mesh (in metres) more than `MAX_OBJECT_SIZE` across: no fingers grasp it, and
    it is nearly always one whose vertices are in mm read in a larger unit; the message
    names the fix (``how``, formatted with ``"mm"``)."""
    size = float(np.ptp(mesh.vertices, axis=0).max())
    if size <= MAX_OBJECT_SIZE:
        return
    text = f"{where} is {size:.4g} m across, larger than an object fingers grasp (at most {MAX_OBJECT_SIZE:g} m)"
    if units == "mm":
        raise GraspValueError(f"{text}, with its vertices in mm: is it the object, at its size?")
    raise GraspValueError(f"{text}: if its vertices are in mm, {how.format('mm', 'mm')}")


def _check_counts(faces: int, vertices: int, where: str, declared: str = "has") -> None:
    """At most `MAX_MESH_FACES` faces and as many vertices (``declared``: how the
    message says it, ``"has"`` or ``"declares"``)."""
    for n, noun in ((faces, "faces"), (vertices, "vertices")):
        if n > MAX_MESH_FACES:
            raise GraspValueError(f"{where} {declared} {n:,} {noun}, more than the {MAX_MESH_FACES:,} read at most "
                                  "(MAX_MESH_FACES); decimate it")


_GLB_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_GLB_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _check_declared(raw: bytes, fmt: str, where: str) -> None:
    """Refuse, before trimesh decodes anything, a file whose own counts say it is too large:
    an OBJ's face and vertex lines (`_check_counts`), a GLB's accessors (what trimesh
    allocates from them, even without data behind them, at most `MAX_MESH_DECLARED_BYTES`).
    STL, PLY and OFF are bounded by the file's size (trimesh checks their counts against it)."""
    if fmt == "obj":
        _check_counts(raw.count(b"\nf ") + raw.startswith(b"f "), raw.count(b"\nv ") + raw.startswith(b"v "),
                      where, "declares")
    elif fmt == "glb":
        declared = _glb_accessor_bytes(raw)
        if declared > MAX_MESH_DECLARED_BYTES:
            raise GraspValueError(f"{where}: its accessors declare {declared / 2**20:,.0f} MiB of geometry, more than "
                                  f"the {MAX_MESH_DECLARED_BYTES / 2**20:,.0f} MiB read at most")


def _glb_accessor_bytes(raw: bytes) -> int:
    """The bytes a GLB's accessors declare (count x components x component bytes, from its
    JSON chunk); 0 where the JSON cannot be read (trimesh then says why)."""
    if len(raw) < 20 or raw[:4] != b"glTF":
        return 0
    length, kind = struct.unpack_from("<II", raw, 12)
    if kind != 0x4E4F534A:  # "JSON"
        return 0
    try:
        header = json.loads(raw[20:20 + length])
    except (ValueError, RecursionError):
        return 0
    accessors = header.get("accessors") if isinstance(header, dict) else None
    total = 0
    for a in accessors if isinstance(accessors, list) else ():
        count = a.get("count") if isinstance(a, dict) else None
        if isinstance(count, int) and count > 0:
            total += count * _GLB_COMPONENTS.get(a.get("type"), 16) * _GLB_COMPONENT_BYTES.get(a.get("componentType"), 4)
    return total


def _check_vertices(vertices: np.ndarray, where: str, metres_per_unit: float) -> None:
    """Reject NaN or infinite vertex coordinates and coordinates beyond `MAX_COORDINATE`
    (``vertices (V, 3)`` in the mesh's units, ``metres_per_unit`` <= 1)."""
    for bad, what in ((np.isnan(vertices), "NaN"), (np.isinf(vertices), "infinite")):
        if bad.any():
            rows = np.flatnonzero(bad.any(axis=1))
            raise GraspValueError(f"{where} has {what} vertex coordinates ({len(rows)} of its {len(vertices)} "
                                  f"vertices; the first: {_vec(vertices[rows[0]])})")
    if len(vertices) and np.abs(vertices).max() * metres_per_unit > MAX_COORDINATE:
        row = int(np.argmax(np.abs(vertices).max(axis=1)))
        raise GraspValueError(
            f"{where} has a vertex at {_vec(vertices[row] * metres_per_unit)} m, beyond the largest coordinate "
            f"{MAX_COORDINATE:g} m (past it float64 no longer resolves contacts {COINCIDENT_DISTANCE:g} m apart): "
            "is the mesh's units right?"
        )


class MeshReader:
    """Reads the meshes a grasp file or dataset names (``[object] mesh``), confined to its
    folder (`confine`), and remembers what it read.

    A dataset's rows often name the same mesh: the last few meshes read are kept (by real
    path and units, their errors too), so each is parsed once while its rows follow one
    another. `sha256` maps every mesh file read to the SHA-256 of its bytes (the key
    of ``jaxgrasp batch --resume``); a file whose bytes change between two reads is an error.

    Args:
        base: the folder of the naming file; relative mesh paths are taken from it.
        allowed_dirs: more folders meshes may be in (``None``: only ``base``).
        owner: the naming file's kind, for messages (``"dataset"``, ``"grasp file"``).
    """

    KEEP = 8
    """Meshes kept parsed at once."""

    def __init__(self, base, allowed_dirs=None, owner: str = "dataset"):
        self.base = os.fspath(base)
        self.allowed = allowed_folders(allowed_dirs)
        self.owner = owner
        self.sha256: dict[str, str] = {}
        self._kept: collections.OrderedDict = collections.OrderedDict()

    def __call__(self, name: str, units: str = "m"):
        """``(mesh in metres, the path as named from the base)`` of the mesh ``name``."""
        real = confine(name, self.base, self.allowed, self.owner)
        shown = os.path.join(self.base, name)
        key = (str(real), units)
        if key not in self._kept:
            try:
                mesh, sha = read_mesh(shown, units, real=real, how=FILE_UNITS)
                if self.sha256.setdefault(str(real), sha) != sha:
                    raise GraspValueError(f"mesh {shown!r} changed while the {self.owner} was read")
                self._kept[key] = mesh
            except GraspValueError as exc:
                self._kept[key] = exc
            while len(self._kept) > self.KEEP:
                self._kept.popitem(last=False)
        self._kept.move_to_end(key)
        got = self._kept[key]
        if isinstance(got, GraspValueError):
            raise GraspValueError(str(got))
        return got, shown


def _check_surface(mesh, where: str) -> None:
    """Reject a mesh that has no usable surface; turn a closed inward mesh outward (in place).
    Its vertices passed `_check_vertices`, so the powers of ``scale`` below are finite."""
    scale = float(np.ptp(mesh.vertices, axis=0).max())
    if not scale > 0 or not mesh.area > 1e-12 * scale**2:
        raise GraspValueError(f"{where} has no surface area (a degenerate mesh)")
    if mesh.is_watertight:
        with np.errstate(invalid="ignore", divide="ignore"):  # trimesh divides by a zero volume
            volume = float(mesh.volume)
        if not mesh.is_winding_consistent:
            raise GraspValueError(f"{where}: its faces are not consistently oriented, so it has no inside")
        if not abs(volume) > 1e-9 * scale**3:
            raise GraspValueError(f"{where} encloses no volume (a degenerate mesh)")
        if volume < 0:
            mesh.invert()  # faces inward: turn them outward


def from_mesh(
    mesh, points, *, initial_deformation, radius, young_modulus, friction, max_force,
    mass=None, density=None, center_of_mass=None, gravity=DEFAULT_GRAVITY, units: str = "m",
    normals=None, tolerance: float = DEFAULT_TOLERANCE,
) -> MeshGrasp:
    """A grasp of a meshed object by fingertips touching it at ``points``.

    Args:
        mesh: ``trimesh.Trimesh`` or mesh file path (STL, OBJ, PLY, OFF or GLB, read as
            `load_mesh` says); vertices in ``units``.
        points: ``(N, 3)`` fingertip contact points, m, in the mesh's frame (its origin
            and axes, after the unit conversion); each is snapped to the closest surface
            point.
        initial_deformation, radius, young_modulus, friction, max_force: as in
            [`jaxgrasp.Grasp.create`][jaxgrasp.Grasp.create] (m, m, Pa, -, N; scalar or ``(N,)``).
        mass: object mass, kg. Give ``mass`` or ``density``, not both (neither: 0).
        density: kg/m^3; mass = density x enclosed volume (watertight meshes only).
        center_of_mass: ``(3,)`` m, mesh frame; default the watertight mesh's own (uniform
            density); required for a mesh that is not watertight.
        gravity: ``(3,)`` m/s^2 in the mesh's axes (the model frame has the same axes).
        units: length unit of the mesh's vertices, ``"m"``, ``"cm"`` or ``"mm"``
            (`jaxgrasp.model._units.LENGTH_UNITS`); ``points`` stay in metres.
        normals: ``None`` (every normal from the mesh) or a length-``N`` sequence whose
            entries are ``None`` (from the mesh) or a 3-vector, mesh axes, that is used as
            given.
        tolerance: farthest a point may lie from the surface, m (default 1 mm).

    Returns:
        A [`MeshGrasp`][jaxgrasp.MeshGrasp]: ``.grasp`` in the model frame, ``.mesh`` (m, mesh frame),
        ``.center_of_mass`` (the offset).

    Raises:
        GraspValueError: one line: a point farther than ``tolerance`` from the surface
            (naming the contact, its distance and, where one explains every point, the
            unit mistake: points typed in mm or cm, or a mesh's ``units`` not those of its
            vertices) or on a sharp edge, a mesh that is not
            watertight without ``center_of_mass`` (or with ``density``), a degenerate
            mesh, unknown units, or an invalid grasp value.
    """
    surface = load_mesh(mesh, units)
    source = os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else "<trimesh>"
    return grasp_on_mesh(
        surface, points, initial_deformation=initial_deformation, radius=radius, young_modulus=young_modulus,
        friction=friction, max_force=max_force, mass=mass, density=density, center_of_mass=center_of_mass,
        gravity=gravity, normals=normals, tolerance=tolerance, source=source, units=units,
    )


def _vec(p) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in p) + ")"
