"""A grasp on a triangle mesh: contacts snapped to the surface, the centre of mass, the frame.

`grasp_on_mesh` turns a checked mesh (a ``trimesh.Trimesh`` in metres, as
`jaxgrasp.io.load_mesh` reads it; [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] reads and builds in one
call) and fingertip contact points given in the mesh's own frame into a [`MeshGrasp`][jaxgrasp.MeshGrasp]:

* each point is snapped to the closest point of the surface (`snap_to_surface`: an
  exact closest point over every triangle, by `closest_on_triangles` run in NumPy on the
  faces that the mesh's face tree finds near the point, `jaxgrasp.surface._tree`;
  trimesh's own ``closest_point`` needs the optional ``rtree``); the outward
  normal of the face there is the contact normal;
* the centre of mass is the mesh's (a watertight mesh of uniform density) or the one
  given; the mass is given, or ``density`` times the enclosed volume (`mass_properties`);
* positions are moved into the model's frame (origin at the centre of mass, the mesh's
  axes), and [`MeshGrasp`][jaxgrasp.MeshGrasp] keeps the offset beside the grasp.

Design (the one way the library keeps a grasp's mesh): the [`Grasp`][jaxgrasp.Grasp]
pytree is left exactly as for any other grasp, so ``evaluate``, ``sweep``, ``tune``,
``evaluate_batch`` and their compiled executables and caches see nothing new. The mesh and the
frame offset live beside it in [`MeshGrasp`][jaxgrasp.MeshGrasp], a small frozen object that is not a
pytree and never enters ``jit``: evaluate ``mesh_grasp.grasp``; draw with
``mesh_grasp.mesh`` and ``mesh_grasp.to_mesh_frame``. [`jaxgrasp.load`][jaxgrasp.load] with
``keep_mesh=True`` and ``jaxgrasp show`` use it.

Nothing here imports trimesh: the mesh arrives as an object and is only read.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxgrasp.model import DEFAULT_GRAVITY, DEFAULT_MASS, Grasp, GraspValueError
from jaxgrasp.surface._tree import build_tree, nearest_faces

__all__ = ["MeshGrasp", "grasp_on_mesh", "mass_properties", "snap_to_surface", "DEFAULT_TOLERANCE", "SHARP_EDGE_DEG"]

DEFAULT_TOLERANCE = 1e-3
"""Farthest a contact point may lie from the mesh surface, m."""

SHARP_EDGE_DEG = 30.0
"""A contact where faces meet at more than this angle (degrees) is on a sharp edge or
corner, where the surface has no normal: an error. Below it (a tessellated curved surface)
the normals of the faces meeting there are averaged."""


@dataclasses.dataclass(frozen=True, eq=False)
class MeshGrasp:
    """A grasp made from a mesh, with the mesh and where the model's frame sits in it.

    Not a pytree: pass `grasp` to [`jaxgrasp.evaluate`][jaxgrasp.evaluate] (and the other entry
    points); the rest is for drawing results in the mesh's frame.

    Attributes:
        grasp: the [`Grasp`][jaxgrasp.Grasp], model frame: origin at the centre of mass,
            axes of the mesh (SI units).
        mesh: the ``trimesh.Trimesh`` in metres, in the mesh's own frame, faces outward.
        center_of_mass: ``(3,)`` m, the centre of mass in the mesh's frame: a model-frame
            point ``p`` is ``p + center_of_mass`` in the mesh's frame.
        source: where the mesh came from (a path, or ``"<trimesh>"``).
        units: the length unit of the mesh file's vertices (``"m"``, ``"cm"``, ``"mm"``);
            `mesh` is in metres whatever it is.
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


def grasp_on_mesh(
    mesh, points, *, initial_deformation, radius, young_modulus, friction, max_force,
    mass=None, density=None, center_of_mass=None, gravity=DEFAULT_GRAVITY,
    normals=None, tolerance: float = DEFAULT_TOLERANCE, source: str = "<trimesh>", units: str = "m",
) -> MeshGrasp:
    """The [`MeshGrasp`][jaxgrasp.MeshGrasp] of fingertips touching the checked mesh ``mesh`` at ``points``.

    Args:
        mesh: ``trimesh.Trimesh`` in metres, checked and faces outward, as
            `jaxgrasp.io.load_mesh` returns it.
        source, units: where the mesh came from and the length unit of its file's
            vertices, kept in the [`MeshGrasp`][jaxgrasp.MeshGrasp].
        points, initial_deformation, radius, young_modulus, friction, max_force, mass,
            density, center_of_mass, gravity, normals, tolerance: as in
            [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] (SI units; ``points (N, 3)`` m, the mesh's frame).

    Raises:
        GraspValueError: one line, as [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] says (a point off the
            surface or on a sharp edge, mass and density both given, a mesh that is not
            watertight without ``center_of_mass``, an invalid grasp value).
    """
    pts = _points(points)
    com, mass = mass_properties(mesh, mass, density, center_of_mass)
    snapped, normal = _contacts(mesh, pts, normals, tolerance)
    grasp = Grasp.create(
        positions=snapped - com, normals=normal, initial_deformation=initial_deformation, radius=radius,
        young_modulus=young_modulus, friction=friction, max_force=max_force, mass=mass, gravity=gravity,
    )
    return MeshGrasp(grasp=grasp, mesh=mesh, center_of_mass=com, source=source, units=units)


def _contacts(surface, pts, normals, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """``(positions (N, 3) m, normals (N, 3))`` of the contacts, mesh frame: ``pts`` snapped
    to the surface (`snap_to_surface`), each normal the one given in ``normals``
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
        lies on; where it lies on faces meeting at less than `SHARP_EDGE_DEG`
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
    tree = build_tree(tri, face_normals)
    pts = np.asarray(points, dtype=np.float64)
    query, face, point, dist = nearest_faces(tree, pts, margin=1e-9 * scale, scale=scale)  # sorted by query, face
    starts = np.searchsorted(query, np.arange(len(pts) + 1))
    closest, normals = [], []
    for i, p in enumerate(pts):
        mine = slice(starts[i], starts[i + 1])
        best = float(dist[mine].min())
        if best > tolerance:
            raise GraspValueError(
                f"contact {i} at {_vec_mm(p)} mm is {best * 1e3:.3g} mm from the mesh surface "
                f"(tolerance {tolerance * 1e3:.3g} mm): " + _unit_hint(tree, points, tolerance)
            )
        ns = face_normals[face[mine]]  # every face within 1e-9 scale of the closest distance
        angle = np.degrees(np.arccos(np.clip(ns @ ns.T, -1.0, 1.0))).max()
        if angle > SHARP_EDGE_DEG and (need_normal is None or need_normal[i]):
            raise GraspValueError(
                f"contact {i} at {_vec_mm(p)} mm lies on an edge or corner where faces meet at "
                f"{angle:.0f} degrees, so it has no one normal: move it onto a face or give its normal"
            )
        n = ns.mean(axis=0)
        closest.append(point[mine][int(np.argmin(dist[mine]))])
        normals.append(n / np.linalg.norm(n))
    return np.array(closest), np.array(normals)


_METRES = " (units sets the mesh's vertices only; positions are always in metres)"
_UNIT_MISTAKES = (
    (1e-3, "the contact positions lie on the surface when read as millimetres: write them in metres"
           + _METRES),
    (1e-2, "the contact positions lie on the surface when read as centimetres: write them in metres"
           + _METRES),
    (1e3, 'the contacts lie on the mesh shrunk 1000 times, as if its vertices were in mm: '
          'add units = "mm" to [object] (Python: units="mm"); positions stay in metres'),
    (1e2, 'the contacts lie on the mesh shrunk 100 times, as if its vertices were in cm: '
          'add units = "cm" to [object] (Python: units="cm"); positions stay in metres'),
)
"""Unit mistakes `snap_to_surface` recognises: ``(factor, what to say)`` where every
contact point times ``factor`` lies on the surface (points typed in mm or cm; a mesh whose
``units`` do not match its vertices, which scales the mesh instead), the scaled points
spread out (`_shrunk`)."""


def _unit_hint(tree, points, tolerance: float) -> str:
    """What to say of contacts off the surface: the unit mistake that would put every one
    of them on it (`_UNIT_MISTAKES`), or the general question (``tree``: the mesh's
    `jaxgrasp.surface._tree.FaceTree`)."""
    pts = np.asarray(points, dtype=np.float64)
    for factor, text in _UNIT_MISTAKES:
        if _shrunk(pts * factor, tolerance * max(factor, 1.0)):
            continue
        near = nearest_faces(tree, pts * factor)[3]  # each point's closest distance (its tied faces, once each)
        if max(near) <= tolerance * max(factor, 1.0):
            return text
    return "is it in the mesh's frame and units?"


def _shrunk(scaled: np.ndarray, tolerance: float) -> bool:
    """Whether the scaled points ``(N, 3)`` lie within ``tolerance`` of each other along each
    axis, so that they tell nothing of a unit: points in
    metres read as mm all fall near the origin, and an origin on the surface (a mesh's
    bottom face, as in ``examples/block.stl``) would then say that positions already in
    metres are in mm. Only points that stay apart tell a unit."""
    return bool(np.ptp(scaled, axis=0).max() <= tolerance)


def _vec_mm(p) -> str:
    return _vec(np.asarray(p) * 1e3)


def _vec(p) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in p) + ")"
