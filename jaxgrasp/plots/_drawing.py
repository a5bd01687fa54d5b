"""How a picture draws a mesh: decimated for drawing, its sharp edges, its outline, its shading.

The pictures draw with matplotlib, whose 3-D polygons are sorted and filled one by one in
Python: a scanned or CAD object of a million faces would take minutes. So a picture draws
`drawing_mesh`, the mesh decimated to at most `DRAW_FACES` faces by vertex clustering;
every computation (contacts, closest points, the ghost's pose, the GLB) keeps the mesh
itself. On it, the picture draws

* `feature_edges`: where faces meet at more than 20 degrees, and open borders (a box's
  edges; none on a smooth ball);
* `silhouette_edges`: the outline as the camera sees it, the edges between a face turned
  to the camera and one turned away (a smooth ball's rim, a bottle's sides);
* the faces lit by a light near the camera (`shaded_colors`), both sides alike, so that
  a smooth surface shows its curvature and the result does not depend on the faces'
  winding.
"""

from __future__ import annotations

import numpy as np

__all__ = ["DRAW_FACES", "SOURCE_NORMALS", "drawing_mesh", "feature_edges", "silhouette_edges", "polylines",
           "shaded_colors", "light_direction"]

DRAW_FACES = 20_000
"""The most faces of one mesh (the object, and again its ghost) that a picture hands to
matplotlib: a mesh with more is drawn decimated to at most this many (`drawing_mesh`).
Enough to show a scanned object's shape at the picture's size (about 1000 pixels across),
few enough that drawing takes seconds."""

SOURCE_NORMALS = "source_normals"
"""The face attribute of a mesh decimated by `drawing_mesh`: ``(F, 3)``, the unit normal of
the face of the mesh itself that each face comes from."""

_SHARP_DEG = 20.0  # faces meeting at more than this draw their common edge


def drawing_mesh(mesh, budget: int = DRAW_FACES):
    """``mesh`` itself when it has at most ``budget`` faces, else a new ``trimesh.Trimesh``
    decimated for drawing to at most ``budget`` faces.

    Vertex clustering: the vertices in each cell of a cubic grid merge into one, placed
    where it best keeps the planes of the faces around it (the least-squares point of
    their planes, weighted by area, within the cell; Lindstrom 2000), so that a box's
    edges and corners stay sharp; faces whose corners merged vanish. The cell grows
    until at most ``budget`` faces are left. For drawing only: the shape moves by up to
    a cell's diagonal.
    """
    import trimesh

    faces = np.asarray(mesh.faces)
    if len(faces) <= budget:
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    lo = vertices.min(axis=0)
    extent = float(np.ptp(vertices, axis=0).max())
    cell = np.sqrt(3.0 * float(mesh.area) / budget)  # a closed surface keeps about 3 A / cell^2 faces
    cell = max(cell, 1e-6 * extent) or 1.0  # at most 1e6 cells along an axis: the cells' index fits int64
    while True:
        cells, cluster, kept, source = _cluster(vertices, faces, lo, cell)
        if len(kept) <= budget:
            break
        cell *= 1.05 * np.sqrt(len(kept) / budget)
    points = _placed(vertices, faces, cluster, len(cells), lo + cells * cell, cell)
    normals = np.asarray(mesh.face_normals)[source]
    return trimesh.Trimesh(points, kept, process=False, face_attributes={SOURCE_NORMALS: normals})


def _cluster(vertices, faces, lo, cell):
    """The occupied cells ``(K, 3)`` (integer grid indices), each vertex's cell
    ``(V,)``, the faces left ``(F', 3)`` between cells and the index ``(F',)`` of a face of
    ``faces`` each comes from: no two corners in one cell, and the faces on the same three
    cells counted with their orientation, so that a fold collapsed flat (as many faces one
    way as the other) vanishes and the rest leave one face (the surface stays closed
    where it was)."""
    grid = np.floor((vertices - lo) / cell).astype(np.int64)
    shape = tuple(grid.max(axis=0) + 1)
    keys, cluster = np.unique(np.ravel_multi_index(grid.T, shape), return_inverse=True)
    cells, cluster = np.stack(np.unravel_index(keys, shape), axis=-1), cluster.reshape(-1)
    f = cluster[faces]
    whole = np.flatnonzero((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2]))
    f = f[whole]
    turn = np.where((f < np.roll(f, -1, axis=1)).sum(axis=1) == 2, 1, -1)  # +1: the sorted corners' order
    s, k = np.sort(f, axis=1), np.int64(len(cells))
    key, first, where = np.unique((s[:, 0] * k + s[:, 1]) * k + s[:, 2], return_index=True, return_inverse=True)
    net = np.bincount(where.reshape(-1), weights=turn, minlength=len(key))
    s = s[first]
    s = np.where((net > 0)[:, None], s, s[:, [0, 2, 1]])
    return cells, cluster, s[net != 0], whole[first][net != 0]


def _placed(vertices, faces, cluster, count, cell_lo, cell):
    """``(K, 3)``: each cluster's point, the least-squares point of the planes of the faces
    at its vertices (``A x = -b`` with ``A = sum w n n^T``, ``b = sum w d n``, ``w`` the
    area), solved about the vertices' mean with small eigenvalues dropped (a flat patch
    fixes only the normal direction) and kept inside the cell."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    twice = np.linalg.norm(cross, axis=1)
    n = cross / np.where(twice > 0, twice, 1.0)[:, None]
    w = 0.5 * twice
    d = -np.einsum("fi,fi->f", n, tri[:, 0])
    owner = cluster[faces].reshape(-1)  # each face counts at the cluster of each corner
    per = lambda x: np.bincount(owner, weights=np.repeat(x, 3), minlength=count)
    a = np.stack([np.stack([per(w * n[:, i] * n[:, j]) for j in range(3)], -1) for i in range(3)], -2)
    b = np.stack([per(w * d * n[:, i]) for i in range(3)], -1)
    counts = np.bincount(cluster, minlength=count)[:, None]
    mean = np.stack([np.bincount(cluster, weights=vertices[:, i], minlength=count) for i in range(3)], -1) / counts
    val, vec = np.linalg.eigh(a)
    inv = np.where(val > 1e-3 * val[:, -1:], 1.0 / np.where(val > 0, val, 1.0), 0.0)
    rhs = -b - np.einsum("kij,kj->ki", a, mean)
    step = np.einsum("kij,kj->ki", vec, inv * np.einsum("kji,kj->ki", vec, rhs))  # V diag(1/val) V^T rhs
    return np.clip(mean + step, cell_lo, cell_lo + cell)


def _normals(mesh) -> np.ndarray:
    """``(F, 3)``: the faces' unit normals, those of the faces they come from for a mesh
    decimated by `drawing_mesh` (clustering leaves some faces tilted across the surface)."""
    source = mesh.face_attributes.get(SOURCE_NORMALS)
    return np.asarray(mesh.face_normals if source is None else source)


def feature_edges(mesh, angle_deg: float = _SHARP_DEG) -> np.ndarray:
    """``(E, 2, 3)`` m: the edges where faces meet at more than ``angle_deg``, and open
    borders (empty for a closed smooth mesh). For a mesh decimated by `drawing_mesh`, the
    angle is that of the faces each drawn face comes from: a sharp edge of the object,
    not a sliver the decimation tilted."""
    import trimesh

    n, pairs = _normals(mesh), mesh.face_adjacency
    cos = np.einsum("ij,ij->i", n[pairs[:, 0]], n[pairs[:, 1]])
    sharp = mesh.face_adjacency_edges[cos < np.cos(np.radians(angle_deg))]
    border = mesh.edges_sorted[trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)]
    edges = np.concatenate([sharp.reshape(-1, 2), border.reshape(-1, 2)]).astype(int)
    return np.asarray(mesh.vertices)[edges].reshape(-1, 2, 3)


def silhouette_edges(mesh, projection) -> np.ndarray:
    """``(E, 2, 3)`` m: the outline of ``mesh`` seen through ``projection`` (a matplotlib 3-D
    axes' ``get_proj()``, ``(4, 4)``): the edges whose two faces lie on the same side of
    the edge on the screen (one faces the camera, the other away). Independent of the
    faces' winding."""
    from mpl_toolkits.mplot3d import proj3d

    v = np.asarray(mesh.vertices)
    xs, ys, _ = proj3d.proj_transform(v[:, 0], v[:, 1], v[:, 2], projection)
    p = np.stack([xs, ys], axis=-1)
    edge, other = mesh.face_adjacency_edges, mesh.face_adjacency_unshared
    a, ab = p[edge[:, 0]], p[edge[:, 1]] - p[edge[:, 0]]
    side = [ab[:, 0] * (p[other[:, k], 1] - a[:, 1]) - ab[:, 1] * (p[other[:, k], 0] - a[:, 0]) for k in (0, 1)]
    return v[edge[side[0] * side[1] > 0]].reshape(-1, 2, 3)


def polylines(segments) -> list:
    """``segments (E, 2, 3)`` joined end to end where they meet two by two: a list of
    ``(k, 3)`` polylines, so that a dashed outline of many short edges keeps its dashes
    (matplotlib starts the pattern afresh on each line)."""
    segments = np.asarray(segments).reshape(-1, 2, 3)
    points, ends = np.unique(segments.reshape(-1, 3), axis=0, return_inverse=True)
    ends = np.unique(np.sort(ends.reshape(-1, 2), axis=1), axis=0)  # an edge both sharp and outline: once
    at = [[] for _ in points]  # the segments at each point
    for e, (a, b) in enumerate(ends.tolist()):
        at[a].append(e)
        at[b].append(e)
    used, lines = np.zeros(len(ends), dtype=bool), []
    for start in sorted(range(len(points)), key=lambda v: len(at[v]) == 2):  # open chains first, then loops
        for e in at[start]:
            if used[e]:
                continue
            path, v = [start], start
            while e is not None:
                used[e] = True
                v = int(ends[e, 1] if ends[e, 0] == v else ends[e, 0])
                path.append(v)
                e = next((x for x in at[v] if not used[x]), None) if len(at[v]) == 2 else None
            lines.append(points[path])
    return lines


def light_direction(elevation: float, azimuth: float) -> np.ndarray:
    """``(3,)`` unit vector towards the light: from the camera at ``(elevation, azimuth)``
    (degrees, matplotlib's view) turned 30 degrees up and 30 to the side, so that faces
    square to the camera are not all equally bright."""
    e, a = np.radians(elevation + 30.0), np.radians(azimuth - 30.0)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def shaded_colors(mesh, rgba, light) -> np.ndarray:
    """``(F, 4)``: ``rgba`` per face, its colour scaled by ``0.55 + 0.45 |n . light|``
    (``n`` the face's unit normal, as `feature_edges` takes it: both sides lit alike);
    alpha kept."""
    k = 0.55 + 0.45 * np.abs(_normals(mesh) @ np.asarray(light))
    out = np.tile(np.asarray(rgba, dtype=np.float64), (len(k), 1))
    out[:, :3] *= k[:, None]
    return out
