"""Objects from triangle meshes: contacts snapped to the surface, the centre of mass, the frame.

:func:`from_mesh` turns a mesh (a ``trimesh.Trimesh`` or a mesh file: STL, OBJ, PLY, OFF, GLB)
and fingertip contact points given in the mesh's own frame into a :class:`MeshGrasp`:

* each point is snapped to the closest point of the surface (an exact closest point over
  every triangle, in NumPy: trimesh's own ``closest_point`` needs the optional ``rtree``);
  the outward normal of the face there is the contact normal;
* the centre of mass is the mesh's (a watertight mesh of uniform density) or the one
  given; the mass is given, or ``density`` times the enclosed volume;
* positions are moved into the model's frame (origin at the centre of mass, the mesh's
  axes), and :class:`MeshGrasp` keeps the offset beside the grasp.

Design (the one way the library keeps a grasp's mesh): the :class:`~jaxgrasp.Grasp`
pytree is left exactly as for any other grasp, so ``evaluate``, ``sweep``, ``tune``,
``evaluate_batch`` and their compiled executables and caches see nothing new. The mesh and the
frame offset live beside it in :class:`MeshGrasp`, a small frozen object that is not a
pytree and never enters ``jit``: evaluate ``mesh_grasp.grasp``; draw with
``mesh_grasp.mesh`` and ``mesh_grasp.to_mesh_frame``. :func:`jaxgrasp.load` with
``keep_mesh=True`` and ``jaxgrasp show`` use it.

trimesh is imported when a mesh is used, so ``import jaxgrasp`` does not pay for it.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import io
import os
from typing import Any

import numpy as np

from jaxgrasp.io._inputs import MAX_MESH_BYTES, allowed_folders, check_mesh_suffix, confine, read_input
from jaxgrasp.model import (
    COINCIDENT_DISTANCE,
    DEFAULT_GRAVITY,
    DEFAULT_MASS,
    LENGTH_UNITS,
    MAX_COORDINATE,
    Grasp,
    GraspValueError,
)

__all__ = ["MeshGrasp", "MeshReader", "from_mesh", "load_mesh", "read_mesh", "snap_to_surface", "closest_on_triangles", "DEFAULT_TOLERANCE", "SHARP_EDGE_DEG"]

DEFAULT_TOLERANCE = 1e-3
"""Farthest a contact point may lie from the mesh surface, m."""

SHARP_EDGE_DEG = 30.0
"""A contact where faces meet at more than this angle (degrees) is on a sharp edge or
corner, where the surface has no normal: an error. Below it (a tessellated curved surface)
the normals of the faces meeting there are averaged."""



@dataclasses.dataclass(frozen=True, eq=False)
class MeshGrasp:
    """A grasp made from a mesh, with the mesh and where the model's frame sits in it.

    Not a pytree: pass :attr:`grasp` to :func:`jaxgrasp.evaluate` (and the other entry
    points); the rest is for drawing results in the mesh's frame.

    Attributes:
        grasp: the :class:`~jaxgrasp.Grasp`, model frame: origin at the centre of mass,
            axes of the mesh (SI units).
        mesh: the ``trimesh.Trimesh`` in metres, in the mesh's own frame, faces outward.
        center_of_mass: ``(3,)`` m, the centre of mass in the mesh's frame: a model-frame
            point ``p`` is ``p + center_of_mass`` in the mesh's frame.
        source: where the mesh came from (a path, or ``"<trimesh>"``).
        units: the length unit of the mesh file's vertices (``"m"``, ``"cm"``, ``"mm"``);
            :attr:`mesh` is in metres whatever it is.
    """

    grasp: Grasp
    mesh: Any
    center_of_mass: np.ndarray
    source: str = "<trimesh>"
    units: str = "m"

    def to_mesh_frame(self, points) -> np.ndarray:
        """Model-frame points ``(..., 3)`` (m) in the mesh's frame (m)."""
        return np.asarray(points, dtype=np.float64) + self.center_of_mass

    def replace(self, **changes) -> "MeshGrasp":
        """A copy with some attributes replaced (e.g. ``grasp`` with other fingertips)."""
        return dataclasses.replace(self, **changes)


def load_mesh(mesh, units: str = "m"):
    """A checked ``trimesh.Trimesh`` in metres from a ``Trimesh`` or a mesh file path.

    Args:
        mesh: ``trimesh.Trimesh`` or a path to a mesh file of one of the formats of
            :data:`~jaxgrasp.io._inputs.MESH_SUFFIXES` (STL, OBJ, PLY, OFF, GLB; a scene of
            several parts is joined into one mesh), at most
            :data:`~jaxgrasp.io._inputs.MAX_MESH_BYTES` bytes, a regular file. It is parsed
            from its bytes as the format its name says, so it cannot reach other files.
        units: the length unit of the vertices: ``"m"``, ``"cm"`` or ``"mm"``.

    Returns:
        A new mesh, vertices in m (the input is not changed), faces turned outward when
        the mesh is watertight with its faces inward.

    Raises:
        GraspValueError: unknown units, a file that is not a mesh format, too large, not a
            regular file or unreadable, or a degenerate mesh (no faces, NaN or infinite
            vertex coordinates, a coordinate beyond :data:`MAX_COORDINATE`, no area, a
            closed mesh enclosing no volume or with faces not consistently oriented); one
            line.
    """
    import trimesh

    _check_units(units)
    if isinstance(mesh, (str, os.PathLike)):
        return read_mesh(mesh, units)[0]
    if not isinstance(mesh, trimesh.Trimesh):
        raise GraspValueError(f"mesh must be a trimesh.Trimesh or a file path, got {type(mesh).__name__}")
    return _checked(mesh, "mesh", units)


def _check_units(units: str) -> None:
    if units not in LENGTH_UNITS:
        raise GraspValueError(f"units = {units!r} is not a length unit; use one of {', '.join(LENGTH_UNITS)}")


def read_mesh(path: str | os.PathLike, units: str = "m", *, real: str | os.PathLike | None = None):
    """``(mesh, sha256)``: the checked mesh (metres, :func:`load_mesh`) of the file ``path``
    and the SHA-256 (hex) of the bytes it was parsed from.

    ``real``: where to read it from, when the caller has resolved ``path`` already
    (:func:`~jaxgrasp.io._inputs.confine`); messages name ``path``.
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
    try:  # processed in _checked, after its vertices are checked: processing drops NaN vertices silently
        loaded = trimesh.load(io.BytesIO(raw), file_type=fmt, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise GraspValueError(f"{where}: cannot read it as a mesh ({' '.join(str(exc).split()) or type(exc).__name__})") from None
    return _checked(loaded, where, units, process=True), hashlib.sha256(raw).hexdigest()


def _checked(loaded, where: str, units: str, process: bool = False):
    """A copy of ``loaded`` in metres whose vertices passed :func:`_check_vertices` and
    surface :func:`_check_surface`; with ``process``, its duplicate vertices merged as
    ``trimesh.load(..., process=True)`` does (in the file's units, as that does)."""
    import trimesh

    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise GraspValueError(f"{where} has no faces (a degenerate mesh)")
    _check_vertices(np.asarray(loaded.vertices, dtype=np.float64), where, LENGTH_UNITS[units])
    out = loaded.copy()
    if process:
        out.process()
    out.apply_scale(LENGTH_UNITS[units])
    _check_surface(out, where)
    return out


def _check_vertices(vertices: np.ndarray, where: str, metres_per_unit: float) -> None:
    """Reject NaN or infinite vertex coordinates and coordinates beyond :data:`MAX_COORDINATE`
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
    folder (:func:`~jaxgrasp.io._inputs.confine`), and remembers what it read.

    A dataset's rows often name the same mesh: the last few meshes read are kept (by real
    path and units, their errors too), so each is parsed once while its rows follow one
    another. :attr:`sha256` maps every mesh file read to the SHA-256 of its bytes (the key
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
                mesh, sha = read_mesh(shown, units, real=real)
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
    Its vertices passed :func:`_check_vertices`, so the powers of ``scale`` below are finite."""
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
            :func:`load_mesh` says); vertices in ``units``.
        points: ``(N, 3)`` fingertip contact points, m, in the mesh's frame (its origin
            and axes, after the unit conversion); each is snapped to the closest surface
            point.
        initial_deformation, radius, young_modulus, friction, max_force: as in
            :meth:`jaxgrasp.Grasp.create` (m, m, Pa, -, N; scalar or ``(N,)``).
        mass: object mass, kg. Give ``mass`` or ``density``, not both (neither: 0).
        density: kg/m^3; mass = density x enclosed volume (watertight meshes only).
        center_of_mass: ``(3,)`` m, mesh frame; default the watertight mesh's own (uniform
            density); required for a mesh that is not watertight.
        gravity: ``(3,)`` m/s^2 in the mesh's axes (the model frame has the same axes).
        units: length unit of the mesh's vertices, ``"m"``, ``"cm"`` or ``"mm"``
            (:data:`jaxgrasp.model._units.LENGTH_UNITS`); ``points`` stay in metres.
        normals: ``None`` (every normal from the mesh) or a length-``N`` sequence whose
            entries are ``None`` (from the mesh) or a 3-vector, mesh axes, that is used as
            given.
        tolerance: farthest a point may lie from the surface, m (default 1 mm).

    Returns:
        A :class:`MeshGrasp`: ``.grasp`` in the model frame, ``.mesh`` (m, mesh frame),
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
    pts = _points(points)
    com, mass = mass_properties(surface, mass, density, center_of_mass)
    snapped, normal = _contacts(surface, pts, normals, tolerance)
    grasp = Grasp.create(
        positions=snapped - com, normals=normal, initial_deformation=initial_deformation, radius=radius,
        young_modulus=young_modulus, friction=friction, max_force=max_force, mass=mass, gravity=gravity,
    )
    return MeshGrasp(grasp=grasp, mesh=surface, center_of_mass=com, source=source, units=units)


def _contacts(surface, pts, normals, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """``(positions (N, 3) m, normals (N, 3))`` of the contacts, mesh frame: ``pts`` snapped
    to the surface (:func:`snap_to_surface`), each normal the one given in ``normals``
    (``None`` or a length-``N`` sequence of ``None`` or 3-vectors) or else the surface's."""
    given = [None] * len(pts) if normals is None else list(normals)
    if len(given) != len(pts):
        raise GraspValueError(f"normals has {len(given)} entries for {len(pts)} points")
    snapped, found = snap_to_surface(surface, pts, tolerance, need_normal=[g is None for g in given])
    normal = np.array([found[i] if g is None else np.asarray(g, dtype=np.float64) for i, g in enumerate(given)])
    return snapped, normal


def _points(points) -> np.ndarray:
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise GraspValueError("points must be an (N, 3) array of numbers, m") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise GraspValueError(f"points must be an (N, 3) array of finite numbers, m; got shape {pts.shape}")
    return pts


def mass_properties(surface, mass, density, center_of_mass) -> tuple[np.ndarray, float]:
    """``(centre of mass (3,) m, mass kg)`` of the object: given, or from its closed surface."""
    closed = surface.is_watertight
    if mass is not None and density is not None:
        raise GraspValueError("give mass or density, not both")
    if center_of_mass is None:
        if not closed:
            raise GraspValueError(
                "the mesh is not watertight, so it has no centre of mass of its own: give center_of_mass (m, mesh frame)"
            )
        com = np.asarray(surface.center_mass, dtype=np.float64)
    else:
        com = np.asarray(center_of_mass, dtype=np.float64)
        if com.shape != (3,) or not np.all(np.isfinite(com)):
            raise GraspValueError(f"center_of_mass must be 3 finite numbers, m; got {center_of_mass!r}")
    if density is None:
        return com, DEFAULT_MASS if mass is None else mass
    density = float(density)
    if not closed:
        raise GraspValueError("density needs a watertight mesh (its volume); give mass instead")
    if not (np.isfinite(density) and density >= 0):
        raise GraspValueError(f"density = {density:g} must be >= 0 (kg/m^3)")
    return com, density * float(surface.volume)


def snap_to_surface(surface, points, tolerance: float = DEFAULT_TOLERANCE, need_normal=None) -> tuple[np.ndarray, np.ndarray]:
    """The closest surface point and the outward unit normal there, for each point.

    Args:
        surface: ``trimesh.Trimesh`` (m).
        points: ``(N, 3)`` m, the mesh's frame.
        tolerance: farthest a point may lie from the surface, m.
        need_normal: ``None`` (every point) or ``(N,)`` bools: the points whose normal is
            taken from the surface; a point whose normal is given may lie on a sharp edge.

    Returns:
        ``(closest (N, 3) m, normals (N, 3))``: the normal of the face the closest point
        lies on; where it lies on faces meeting at less than :data:`SHARP_EDGE_DEG`
        (a tessellated curved surface), their mean normal.

    Raises:
        GraspValueError: a point farther than ``tolerance`` (naming the contact, the
            distance in mm and a unit mistake that would explain every point, if one does)
            or on a sharp edge or corner.
    """
    keep = surface.area_faces > 0
    tri = np.asarray(surface.triangles, dtype=np.float64)[keep]
    face_normals = np.asarray(surface.face_normals, dtype=np.float64)[keep]
    scale = float(np.ptp(surface.vertices, axis=0).max())
    closest, normals = [], []
    for i, p in enumerate(points):
        q = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
        dist = np.linalg.norm(q - p, axis=1)
        best = float(dist.min())
        if best > tolerance:
            raise GraspValueError(
                f"contact {i} at {_vec_mm(p)} mm is {best * 1e3:.3g} mm from the mesh surface "
                f"(tolerance {tolerance * 1e3:.3g} mm): " + _unit_hint(tri, points, tolerance)
            )
        near = dist <= best + 1e-9 * scale
        ns = face_normals[near]
        angle = np.degrees(np.arccos(np.clip(ns @ ns.T, -1.0, 1.0))).max()
        if angle > SHARP_EDGE_DEG and (need_normal is None or need_normal[i]):
            raise GraspValueError(
                f"contact {i} at {_vec_mm(p)} mm lies on an edge or corner where faces meet at "
                f"{angle:.0f} degrees, so it has no one normal: move it onto a face or give its normal"
            )
        n = ns.mean(axis=0)
        closest.append(q[int(np.argmin(dist))])
        normals.append(n / np.linalg.norm(n))
    return np.array(closest), np.array(normals)


_METRES = " (units sets the mesh's vertices only; positions are always in metres)"
_UNIT_MISTAKES = (
    (1e-3, "the contact positions lie on the surface when read as millimetres: write them in metres"
           + _METRES),
    (1e-2, "the contact positions lie on the surface when read as centimetres: write them in metres"
           + _METRES),
    (1e3, 'the contacts lie on the mesh 1000 times larger, as if its vertices were in mm: set units = "mm"'),
    (1e2, 'the contacts lie on the mesh 100 times larger, as if its vertices were in cm: set units = "cm"'),
)
"""Unit mistakes :func:`snap_to_surface` recognises: ``(factor, what to say)`` where every
contact point times ``factor`` lies on the surface (points typed in mm or cm; a mesh whose
``units`` do not match its vertices, which scales the mesh instead)."""


def _unit_hint(tri: np.ndarray, points, tolerance: float) -> str:
    """What to say of contacts off the surface: the unit mistake that would put every one
    of them on it (:data:`_UNIT_MISTAKES`), or the general question."""
    pts = np.asarray(points, dtype=np.float64)
    for factor, text in _UNIT_MISTAKES:
        near = [
            np.linalg.norm(closest_on_triangles(p * factor, tri[:, 0], tri[:, 1], tri[:, 2]) - p * factor, axis=1).min()
            for p in pts
        ]
        if max(near) <= tolerance * max(factor, 1.0):
            return text
    return "is it in the mesh's frame and units?"


def _vec_mm(p) -> str:
    return _vec(np.asarray(p) * 1e3)


def _vec(p) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in p) + ")"


def closest_on_triangles(p, a, b, c) -> np.ndarray:
    """The closest point to ``p (3,)`` on each triangle ``(a, b, c)``, each ``(F, 3)``.

    Exact, by the triangle's Voronoi regions (Ericson, *Real-Time Collision Detection*,
    Sec. 5.1.5). Triangles must have non-zero area. Returns ``(F, 3)``.
    """
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c

    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2

    def ratio(num, den):
        return (num / np.where(den == 0, 1.0, den))[:, None]

    inside = 1.0 / np.where(va + vb + vc == 0, 1.0, va + vb + vc)
    regions = [  # (condition, point), in Ericson's order: the first that holds applies
        (((d1 <= 0) & (d2 <= 0)), a),
        (((d3 >= 0) & (d4 <= d3)), b),
        (((vc <= 0) & (d1 >= 0) & (d3 <= 0)), a + ratio(d1, d1 - d3) * ab),
        (((d6 >= 0) & (d5 <= d6)), c),
        (((vb <= 0) & (d2 >= 0) & (d6 <= 0)), a + ratio(d2, d2 - d6) * ac),
        (((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)), b + ratio(d4 - d3, (d4 - d3) + (d5 - d6)) * (c - b)),
    ]
    out = a + ab * (vb * inside)[:, None] + ac * (vc * inside)[:, None]
    for cond, point in reversed(regions):
        out = np.where(cond[:, None], point, out)
    return out
