"""The 3-D scene of a grasp and the way it fails: the geometry the picture and the GLB share.

`grasp_scene` builds, in the mesh's frame (m), triangle meshes of

* the object: its mesh, or, for a grasp without one, the convex hull of a disc of the
  fingertip's radius in each contact's tangent plane (a stand-in that shows where the
  surfaces are);
* the *ghost*: the object moved by the least-energy pose of the limiting boundary (the
  motion from the initial grasping state that makes that fingertip slip or overload, at
  the least energy), magnified by a stated factor so that it can be seen;
* each fingertip: a hemisphere of its radius, centre ``(r - dr)`` outside the contact
  along the normal, pressed ``dr`` into the surface as in the initial state (fingertips
  stay where they are; the object moves);
* each friction cone: apex at the contact, half-angle ``atan(mu)``, opening into the
  object (the forces a fingertip can press on it without slipping);
* each normal: an arrow from the contact along the outward normal.

`jaxgrasp.plots.plot_grasp` draws it with matplotlib and
`GraspScene.to_trimesh` exports it (``jaxgrasp show --glb``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from jaxgrasp.plots._drawing import drawing_mesh, feature_edges

__all__ = ["Part", "GraspScene", "grasp_scene", "COLORS", "pose_points", "nice_magnification"]

COLORS = {
    "object": (0.62, 0.66, 0.72, 0.35),
    "ghost": (1.00, 0.50, 0.05, 0.12),
    "fingertip": (0.25, 0.45, 0.80, 0.85),
    "limiting": (0.85, 0.10, 0.10, 0.95),
    "cone": (0.20, 0.65, 0.30, 0.40),
    "normal": (0.10, 0.10, 0.10, 1.00),
}
"""RGBA (0-1) of each kind of part; ``limiting`` is the fingertip whose boundary limits."""

_SEGMENTS = 32  # facets around each surface of revolution


@dataclasses.dataclass(frozen=True, eq=False)
class Part:
    """One coloured mesh of the scene.

    Attributes:
        name: ``"object"``, ``"ghost"``, ``"fingertip 0"``, ``"cone 0"``, ``"normal 0"``, ...
        role: ``"object"``, ``"ghost"``, ``"fingertip"``, ``"cone"`` or ``"normal"``.
        mesh: ``trimesh.Trimesh``, m, mesh frame.
        color: RGBA, 0-1.
        drawn: the mesh a picture draws: ``mesh`` itself, or decimated to at most
            `jaxgrasp.plots._drawing.DRAW_FACES` faces when it has more (default: made
            from ``mesh`` by `jaxgrasp.plots._drawing.drawing_mesh`). For drawing only:
            the GLB and every computation use ``mesh``.
    """

    name: str
    role: str
    mesh: Any
    color: tuple
    drawn: Any = None

    def __post_init__(self):
        if self.drawn is None:
            object.__setattr__(self, "drawn", drawing_mesh(self.mesh))


@dataclasses.dataclass(frozen=True, eq=False)
class GraspScene:
    """A grasp, its evaluation and its limiting motion as geometry, mesh frame, m.

    Attributes:
        parts: the coloured meshes (object, ghost when there is a limiting boundary, then
            per contact: fingertip, cone, normal).
        object_edges: ``(E, 2, 3)`` m, the object's feature edges (faces meeting at more
            than 20 degrees, and open borders) for line drawings, on the mesh a picture
            draws (``Part.drawn``); empty for a smooth closed object.
        ghost_edges: ``(E, 2, 3)`` m, the same edges at the ghost pose (empty without one).
        axes: ``(3, 2, 3)`` m, the object's x, y and z axes (start, end) drawn from its
            centre of mass (length a third of its size): they show a rotation that the
            shape alone hides (a turn of a cylinder about its axis).
        ghost_axes: ``(3, 2, 3)`` m, the same at the ghost pose (empty without one).
        contacts: ``(N, 3)`` m, the points of the grasp's active contacts (all of them
            without a mask); ``normals (N, 3)`` unit outward normals.
        radius: ``(N,)`` m, fingertip radii.
        numbers: ``(N,)`` int, each drawn contact's number in the grasp (its index among
            all of the grasp's contacts, masked ones included: a hand's fingertip number),
            which names its parts (``"fingertip 4"``) and its label.
        names: ``(N,)`` each drawn contact's name (a hand's fingertip), or ``None``.
        limiting_contact: the limiting boundary's contact (its number in the grasp, as
            the evaluation's), -1 when none.
        limiting_kind: ``"slip"`` or ``"max_force"``, ``None`` when none.
        magnification: the factor the ghost's motion is magnified by.
        value: J; status: the status name; has_mesh: whether the object is a mesh.
    """

    parts: tuple
    object_edges: np.ndarray
    ghost_edges: np.ndarray
    axes: np.ndarray
    ghost_axes: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray
    radius: np.ndarray
    numbers: np.ndarray
    names: tuple | None
    limiting_contact: int
    limiting_kind: str | None
    magnification: float
    value: float
    status: str
    has_mesh: bool

    def label(self, number: int) -> str:
        """``"contact 4"``, or with a name ``"contact 4 (robot0:C_thdistal)"``: how the picture
        and its title name the grasp's contact ``number``."""
        i = np.flatnonzero(self.numbers == number)
        name = self.names[int(i[0])] if self.names is not None and i.size else None
        return f"contact {number}" + (f" ({name})" if name else "")

    def part(self, name: str) -> Part | None:
        """The part named ``name``, or ``None``."""
        return next((p for p in self.parts if p.name == name), None)

    def to_trimesh(self):
        """A ``trimesh.Scene`` of every part, each a geometry named like it, coloured
        (RGBA face colours; translucent parts keep their alpha)."""
        import trimesh

        scene = trimesh.Scene()
        for p in self.parts:
            mesh = p.mesh.copy()
            rgba = np.round(np.asarray(p.color) * 255).astype(np.uint8)
            mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=np.tile(rgba, (len(mesh.faces), 1)))
            scene.add_geometry(mesh, geom_name=p.name, node_name=p.name)
        return scene


def grasp_scene(grasp, result, *, magnification: float | None = None, names=None) -> GraspScene:
    """The scene of ``grasp`` (a [`Grasp`][jaxgrasp.Grasp] or [`MeshGrasp`][jaxgrasp.MeshGrasp])
    and its [`Evaluation`][jaxgrasp.Evaluation] ``result`` (of that grasp, mask and all): its active
    contacts, each under its number in the grasp (`GraspScene.numbers`), never renumbered.

    Args:
        names: one name per contact of the grasp (masked ones too), e.g. a hand's fingertips.
        magnification: factor applied to the limiting pose (translation and rotation
            vector) for the ghost; default: a round number (1, 2 or 5 times a power of
            ten, at least 1) that moves the object's farthest point by about 0.15 of its
            size (`nice_magnification`).
    """
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.model import KINDS

    com = grasp.center_of_mass if isinstance(grasp, MeshGrasp) else np.zeros(3)
    numbers, per = _active_contacts(grasp.grasp if isinstance(grasp, MeshGrasp) else grasp, names)
    contacts = per["positions"] + com
    normals = per["normals"] / np.linalg.norm(per["normals"], axis=1, keepdims=True)
    body = grasp.mesh if isinstance(grasp, MeshGrasp) else _contact_hull(contacts, normals, per["radius"])
    kind, contact = int(np.asarray(result.limiting_kind)), int(np.asarray(result.limiting_contact))
    parts = [Part("object", "object", body, COLORS["object"])]
    object_edges = feature_edges(parts[0].drawn)
    ghost_edges = ghost_axes = np.zeros((0, 2, 3))
    axes = com + np.stack([np.zeros((3, 3)), np.eye(3) * float(np.ptp(body.vertices, axis=0).max()) / 3], axis=1)
    factor = 1.0
    if kind >= 0 and contact >= 0:
        dp = np.asarray(result.boundary_translation, dtype=np.float64)[kind, contact]
        w = np.asarray(result.boundary_rotation, dtype=np.float64)[kind, contact]
        factor = magnification or nice_magnification(body.vertices, com, dp, w)
        ghost, drawn = body.copy(), parts[0].drawn.copy()
        ghost.vertices = pose_points(body.vertices, com, factor * dp, factor * w)
        drawn.vertices = pose_points(drawn.vertices, com, factor * dp, factor * w)
        parts.append(Part("ghost", "ghost", ghost, COLORS["ghost"], drawn))
        ghost_edges = pose_points(object_edges, com, factor * dp, factor * w)
        ghost_axes = pose_points(axes, com, factor * dp, factor * w)
    for i, k in enumerate(numbers):
        c, nv, r, dr = contacts[i], normals[i], per["radius"][i], per["initial_deformation"][i]
        color = COLORS["limiting"] if k == contact else COLORS["fingertip"]
        parts.append(Part(f"fingertip {k}", "fingertip", _hemisphere(c + (r - dr) * nv, -nv, r), color))
        parts.append(Part(f"cone {k}", "cone", _cone(c, -nv, 0.8 * r, math.atan(per["friction"][i])), COLORS["cone"]))
        parts.append(Part(f"normal {k}", "normal", _arrow(c, nv, 2.4 * r, 0.04 * r), COLORS["normal"]))
    return GraspScene(
        parts=tuple(parts),
        object_edges=object_edges,
        ghost_edges=ghost_edges,
        axes=axes,
        ghost_axes=ghost_axes,
        contacts=contacts,
        normals=normals,
        radius=np.asarray(per["radius"]),
        numbers=numbers,
        names=None if names is None else tuple(str(names[k]) for k in numbers),
        limiting_contact=contact,
        limiting_kind=KINDS[kind] if kind >= 0 else None,
        magnification=float(factor),
        value=float(np.asarray(result.value)),
        status=result.status_name,
        has_mesh=isinstance(grasp, MeshGrasp),
    )


def _active_contacts(g, names) -> tuple[np.ndarray, dict]:
    """``(numbers (N,), fields)``: the numbers of the grasp ``g``'s active contacts (all of
    them without a mask) and their fields (``positions``, ``normals`` ``(N, 3)``;
    ``initial_deformation``, ``radius``, ``friction`` ``(N,)``), float64; ``names`` (one
    per contact of ``g``, or ``None``) checked against the contact count."""
    f = {k: np.asarray(v, dtype=np.float64) for k, v in g.replace(active=None).to_numpy().items()}
    total = f["positions"].shape[0]
    if names is not None and len(names) != total:
        raise ValueError(f"names: {len(names)} given for a grasp of {total} contacts")
    numbers = np.arange(total) if g.active is None else np.flatnonzero(np.asarray(g.active, dtype=bool))
    per = {k: np.broadcast_to(f[k], (total,))[numbers] for k in ("initial_deformation", "radius", "friction")}
    return numbers, {**per, "positions": f["positions"][numbers], "normals": f["normals"][numbers]}


def pose_points(points, com, translation, rotation) -> np.ndarray:
    """Mesh-frame points ``(..., 3)`` m of the object moved by the pose change
    ``(translation (3,) m, rotation (3,) rad rotation vector)`` about its centre of mass
    ``com (3,)``: ``com + R (p - com) + translation``, with ``R`` from
    `jaxgrasp.model._potential.rotation_matrix` (the model's own convention)."""
    import jax.numpy as jnp

    from jaxgrasp.model import rotation_matrix

    rot = np.asarray(rotation_matrix(jnp.asarray(rotation, dtype=jnp.float64)))
    return com + (np.asarray(points) - com) @ rot.T + np.asarray(translation)


def nice_magnification(points, com, translation, rotation, share: float = 0.15) -> float:
    """A round factor (1, 2 or 5 times a power of ten, >= 1) that moves the farthest of
    ``points (M, 3)`` by about ``share`` of their extent under the magnified pose."""
    pts = np.asarray(points)
    moved = pose_points(pts, com, translation, rotation)
    reach = float(np.linalg.norm(moved - pts, axis=1).max())
    size = float(np.ptp(pts, axis=0).max())
    if not reach > 0 or not size > 0:
        return 1.0
    raw = share * size / reach
    if raw <= 1:
        return 1.0
    power = 10.0 ** math.floor(math.log10(raw))
    return max(m * power for m in (1, 2, 5) if m * power <= raw)


# --------------------------------------------------------------------------- shapes


def _frame(axis) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``axis`` and to each other."""
    a = np.asarray(axis, dtype=np.float64)
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    u = np.cross(a, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def _revolve(origin, axis, profile):
    """The surface swept by ``profile`` (``(K, 2)`` of (distance along ``axis``, radius),
    m) around ``axis`` through ``origin``: a ``trimesh.Trimesh`` (``_SEGMENTS`` facets)."""
    import trimesh

    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    u, v = _frame(axis)
    phi = np.linspace(0.0, 2 * np.pi, _SEGMENTS, endpoint=False)
    ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v  # (S, 3)
    prof = np.asarray(profile, dtype=np.float64)
    verts = origin + prof[:, :1, None] * axis + prof[:, 1:, None] * ring  # (K, S, 3)
    k, s = len(prof), _SEGMENTS
    idx = np.arange(k * s).reshape(k, s)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)
    c, d = idx[1:], np.roll(idx[1:], -1, axis=1)
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return trimesh.Trimesh(verts.reshape(-1, 3), faces, process=False)


def _hemisphere(centre, axis, r):
    """A hemisphere of radius ``r`` whose dome points along ``axis`` from ``centre``, closed by its base."""
    t = np.linspace(0.0, np.pi / 2, 9)
    profile = np.concatenate([np.stack([r * np.cos(t), r * np.sin(t)], -1), [[0.0, 0.0]]])
    return _revolve(centre, axis, profile)


def _cone(apex, axis, height, half_angle):
    """A closed cone, apex at ``apex``, opening along ``axis``."""
    rim = height * math.tan(half_angle)
    return _revolve(apex, axis, [[0.0, 0.0], [height, rim], [height, 0.0]])


def _arrow(start, direction, length, width):
    """A closed arrow (shaft and head) from ``start`` along ``direction``."""
    head = 0.25 * length
    return _revolve(start, direction, [[0.0, 0.0], [0.0, width], [length - head, width],
                                       [length - head, 3 * width], [length, 0.0]])


def _contact_hull(contacts, normals, radius):
    """The convex hull of a disc of radius ``radius[i]`` in each contact's tangent plane."""
    import trimesh

    phi = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    pts = []
    for c, nv, r in zip(contacts, normals, radius):
        u, v = _frame(nv)
        pts.append(c + r * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v))
    return trimesh.convex.convex_hull(np.concatenate(pts))
