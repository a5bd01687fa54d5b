"""The object's collision shape for the hand in MuJoCo: a convex decomposition, computed once per mesh.

MuJoCo collides with the convex hull of each mesh geom, so a non-convex object (a mug, a
bowl) is given as convex pieces: CoACD's approximate convex decomposition (Wei et al.,
SIGGRAPH 2022; the ``coacd`` package, optional extra ``jaxgrasp[sim]``), the pieces
DexGraspBench's objects carry (``urdf/meshes/convex_piece_*.obj``). A mesh that is convex
already (its hull's volume within `CONVEX_TOL` of its own) is its own single piece:
CoACD is not run.

CoACD takes seconds to minutes per mesh, so its pieces are kept on disk, keyed by the
SHA-256 of the mesh's bytes (its vertices in metres, float64, and faces, int64) with CoACD's
version and settings, in the folder ``jaxgrasp-convex`` beside the executable store
(`jaxgrasp.engine.default_dir`, ``JAXGRASP_CACHE_DIR`` moves it and ``off`` switches it
off). A piece file is NumPy's ``.npz`` read without pickles, from a private folder
(`jaxgrasp.storage.read_private`: a file another user could have written is not read),
written atomically (`jaxgrasp.storage.write_file`); a file that cannot be read is
computed again and replaced.
"""

from __future__ import annotations

import hashlib
import io
import logging
from pathlib import Path

import numpy as np

from jaxgrasp.model import GraspValueError

__all__ = ["COACD_THRESHOLD", "CONVEX_TOL", "SUBDIR", "convex_pieces", "mesh_digest"]

COACD_THRESHOLD = 0.05
"""CoACD's concavity threshold (its default; DexGraspBench's objects are decomposed with it)."""

CONVEX_TOL = 1e-6
"""A mesh whose convex hull's volume exceeds its own by at most this fraction is convex."""

SUBDIR = "jaxgrasp-convex"
"""The cache's subfolder of `jaxgrasp.engine.default_dir`."""

_MAX_PIECE_FILE = 256 * 2**20
_LOG = logging.getLogger("jaxgrasp")


def mesh_digest(vertices, faces) -> str:
    """SHA-256 (hex) of a mesh's bytes: ``vertices`` ``(V, 3)`` m as float64, ``faces``
    ``(F, 3)`` as int64, with CoACD's settings (the cache's key)."""
    h = hashlib.sha256()
    h.update(f"coacd threshold={COACD_THRESHOLD};".encode())
    h.update(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def _is_convex(mesh) -> bool:
    vol = float(mesh.volume) if mesh.is_watertight else 0.0
    return vol > 0.0 and float(mesh.convex_hull.volume) <= vol * (1.0 + CONVEX_TOL)


def _folder() -> Path | None:
    from jaxgrasp.engine import default_dir

    base = default_dir()
    return None if base is None else base / SUBDIR


def _read(path: Path) -> list | None:
    from jaxgrasp import storage

    try:
        data = storage.read_private(path, _MAX_PIECE_FILE)
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            v, f, nv, nf = z["vertices"], z["faces"], z["vertex_counts"], z["face_counts"]
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, storage.NotPrivate) as exc:
        _LOG.warning("jaxgrasp: convex pieces %s not read (%s); computing them again", path, exc)
        return None
    cv, cf = np.cumsum(np.r_[0, nv]), np.cumsum(np.r_[0, nf])
    return [(v[cv[k]:cv[k + 1]], f[cf[k]:cf[k + 1]]) for k in range(len(nv))]


def _write(path: Path, pieces) -> None:
    from jaxgrasp import storage

    buf = io.BytesIO()
    np.savez(buf, vertices=np.concatenate([p[0] for p in pieces]), faces=np.concatenate([p[1] for p in pieces]),
             vertex_counts=np.array([len(p[0]) for p in pieces]), face_counts=np.array([len(p[1]) for p in pieces]))
    try:
        if storage.private_folder(path.parent, create=True) is None:
            storage.write_file(path, buf.getvalue(), mode=0o600)
    except (OSError, storage.OutputError) as exc:  # a cache: the pieces are used all the same
        _LOG.warning("jaxgrasp: convex pieces not kept in %s (%s)", path.parent, exc)


def _coacd(vertices, faces) -> list:
    try:
        import coacd
    except ImportError:
        raise GraspValueError('the hand simulation decomposes the object with CoACD: pip install "jaxgrasp[sim]"') from None
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)),
                            threshold=COACD_THRESHOLD, seed=0)
    return [(np.asarray(v, np.float64), np.asarray(f, np.int64)) for v, f in parts]


def convex_pieces(mesh) -> tuple[list, str]:
    """``(pieces, how)``: the convex pieces ``[(vertices (V, 3) m, faces (F, 3)), ...]`` of
    the ``trimesh.Trimesh`` ``mesh`` (mesh frame), and how they were had: ``"convex"`` (the
    mesh itself), ``"cache"`` or ``"coacd"`` (module notes)."""
    vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    if _is_convex(mesh):
        return [(vertices, faces)], "convex"
    folder = _folder()
    path = None if folder is None else folder / f"{mesh_digest(vertices, faces)}.npz"
    pieces = None if path is None else _read(path)
    if pieces is not None:
        return pieces, "cache"
    pieces = _coacd(vertices, faces)
    if path is not None:
        _write(path, pieces)
    return pieces, "coacd"
