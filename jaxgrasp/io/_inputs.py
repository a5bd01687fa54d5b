"""Reading input files that may be hostile: size caps, no special files, meshes kept in their folder.

Every file jaxgrasp reads on a user's behalf (a grasp file, a dataset, a mesh one of them
names) is opened through `open_input`, which refuses, in one line and before reading
a byte:

* what is not a regular file after symlinks (a FIFO, a socket, a device such as
  ``/dev/zero``, which would otherwise be read without end); the file is opened
  non-blocking, so that opening a FIFO cannot hang;
* a file larger than its kind's cap (`MAX_GRASP_FILE_BYTES`,
  `MAX_DATASET_BYTES`, `MAX_MESH_BYTES`), checked on the open file and again
  while reading (a file that grows while it is read is caught too).

A mesh path written in a dataset or grasp file must resolve (`os.path.realpath`,
after every symlink) inside the folder of the file that names it, or inside a folder the
user allowed explicitly (``allowed_dirs=`` in Python, ``--allow-dir DIR`` on the command
line): `confine`. Only single-mesh formats are read (`MESH_SUFFIXES`, checked
by suffix before trimesh sees the file): trimesh also unpacks archives (zip, tar) and
follows a glTF's references to other files, and a small zip can expand to gigabytes.
"""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO

from jaxgrasp.model import GraspValueError

__all__ = [
    "MAX_DATASET_BYTES",
    "MAX_GRASP_FILE_BYTES",
    "MAX_MESH_BYTES",
    "MAX_MESH_DECLARED_BYTES",
    "MAX_MESH_FACES",
    "MESH_SUFFIXES",
    "allowed_folders",
    "check_mesh_suffix",
    "check_path_text",
    "confine",
    "file_sha256",
    "open_input",
    "read_input",
]

MAX_GRASP_FILE_BYTES = 16 * 2**20
"""Largest grasp file (``.toml``/``.json``) read, bytes (16 MiB: a grasp file with a
hundred thousand contacts is a few MiB)."""

MAX_DATASET_BYTES = 2**30
"""Largest dataset file (``.npz``/``.jsonl``) read, bytes (1 GiB); for ``.npz`` also the
most its arrays may declare, together, once uncompressed."""

MAX_MESH_BYTES = 256 * 2**20
"""Largest mesh file read, bytes (256 MiB: a binary STL of about 5 million triangles)."""

MAX_MESH_FACES = 5_000_000
"""The most faces, and the most vertices, of a mesh read (`jaxgrasp.io._mesh.read_mesh`;
an OBJ's counted from its lines before it is parsed): five times the million faces of the
largest scanned objects, and about what a binary STL of `MAX_MESH_BYTES` holds. Decimate
a finer mesh (its pictures are decimated anyway, its contacts need no finer surface)."""

MAX_MESH_DECLARED_BYTES = 4 * MAX_MESH_BYTES
"""The most bytes of geometry a GLB's accessors may declare (1 GiB): trimesh allocates an
accessor's count even where no data stands behind it, so a small file could ask for any
amount. A GLB's textures are never decoded (materials are skipped)."""

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb")
"""The mesh formats read, by suffix: single-file formats of one surface. Not read: archives
(``.zip``, ``.tar.*``, ``.7z``, ...), which trimesh would unpack; ``.gltf``, whose buffers
are other files; point clouds and drawings (``.xyz``, ``.dxf``)."""

_READ_BLOCK = 1 << 20  # bytes per read while hashing or reading a capped file


def _kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "not a regular file"


def _mib(n: int) -> str:
    return f"{n / 2**20:.4g} MiB"


def check_path_text(name, what: str = "file name") -> str:
    """``name`` as text (``os.fspath``), refused in one line if it holds a NUL byte, which no
    file name can hold (Python's own error, ``embedded null byte``, would be a traceback).

    Raises:
        GraspValueError: ``name`` holds a NUL byte (``what`` names it in the message).
    """
    text = os.fspath(name)
    if ("\0" if isinstance(text, str) else b"\0") in text:
        raise GraspValueError(f"{what} {_shown(text)} holds a NUL byte, which no file name can hold; remove it")
    return text


def open_input(path: str | os.PathLike, cap: int, what: str = "file") -> BinaryIO:
    """Open an input file for reading in binary, after the checks of the module doc.

    Args:
        path: the file (symlinks are followed: what matters is what they lead to).
        cap: the most bytes the file may hold.
        what: the kind of file, for messages (``"grasp file"``, ``"dataset"``, ``"mesh"``).

    Returns:
        A binary file object positioned at the start (the caller closes it).

    Raises:
        GraspValueError: one line starting with the path: no such file, unreadable, not a
            regular file (naming what it is), or larger than ``cap``.
    """
    path = check_path_text(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise GraspValueError(f"{path}: no such file") from None
    except OSError as exc:
        raise GraspValueError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise GraspValueError(f"{path}: is {_kind(st.st_mode)}, not a regular {what}; refusing to read it")
        if st.st_size > cap:
            raise GraspValueError(f"{path}: the {what} holds {_mib(st.st_size)}, more than the {_mib(cap)} read at most")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _check_growth(path, total: int, cap: int, what: str) -> None:
    if total > cap:
        raise GraspValueError(f"{path}: the {what} grew past the {_mib(cap)} read at most while it was read")


def read_input(path: str | os.PathLike, cap: int, what: str = "file") -> bytes:
    """The bytes of an input file (`open_input`'s checks), at most ``cap`` of them.

    Raises:
        GraspValueError: as `open_input`, or the file grew past ``cap`` while read.
    """
    with open_input(path, cap, what) as fh:
        try:
            raw = fh.read(cap + 1)
        except OSError as exc:
            raise GraspValueError(f"{os.fspath(path)}: cannot read file ({exc.strerror or exc})") from None
    _check_growth(os.fspath(path), len(raw), cap, what)
    return raw


def file_sha256(fh: BinaryIO, path, cap: int, what: str = "file") -> str:
    """SHA-256 (hex) of an open file's bytes from its start, read in blocks (no more than
    ``cap`` bytes held or read); the file is left at its start again."""
    digest, total = hashlib.sha256(), 0
    fh.seek(0)
    for block in iter(lambda: fh.read(_READ_BLOCK), b""):
        total += len(block)
        _check_growth(path, total, cap, what)
        digest.update(block)
    fh.seek(0)
    return digest.hexdigest()


def allowed_folders(allowed_dirs: Iterable[str | os.PathLike] | None) -> tuple[str, ...]:
    """The real paths of the folders a user allowed meshes in (``allowed_dirs``), checked.

    Raises:
        GraspValueError: an allowed folder that does not exist or is not a folder.
    """
    if allowed_dirs is None:
        return ()
    if isinstance(allowed_dirs, (str, os.PathLike)):
        allowed_dirs = [allowed_dirs]
    out = []
    for d in allowed_dirs:
        real = os.path.realpath(check_path_text(d, "allowed folder"))
        if not os.path.isdir(real):
            raise GraspValueError(f"allowed folder {os.fspath(d)!r} is not a folder")
        out.append(real)
    return tuple(out)


def _shown(name) -> str:
    """A path for a one-line message: its repr, NUL and other control bytes escaped, at
    most 200 characters."""
    text = repr(os.fspath(name))
    return text if len(text) <= 200 else text[:197] + "..."


def _inside(path: str, folder: str) -> bool:
    return os.path.commonpath([path, folder]) == folder


def check_mesh_suffix(name: str | os.PathLike) -> str:
    """The mesh format of ``name`` by its suffix (``"stl"``), which is what the file is
    parsed as whatever a symlink leads to.

    Raises:
        GraspValueError: not one of `MESH_SUFFIXES`.
    """
    if not isinstance(name, (str, os.PathLike)):
        raise GraspValueError(f"mesh path must be a string, got {type(name).__name__}")
    check_path_text(name, "mesh path")
    suffix = Path(name).suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise GraspValueError(
            f"mesh path {os.fspath(name)!r} is not a mesh file: the formats read are "
            f"{', '.join(MESH_SUFFIXES)} (no archives)"
        )
    return suffix[1:]


def confine(name: str, base: str | os.PathLike, allowed: tuple[str, ...], owner: str) -> Path:
    """The real path of the mesh ``name`` written in a file whose folder is ``base``.

    Args:
        name: the mesh path as written (relative to ``base``, or absolute).
        base: the folder of the file that names it.
        allowed: more folders meshes may be in (`allowed_folders`).
        owner: the naming file's kind in words, for messages (``"dataset"``, ``"grasp file"``).

    Raises:
        GraspValueError: the path (after symlinks) leaves ``base`` and every allowed
            folder, or its name does not end in a mesh suffix (`check_mesh_suffix`).
    """
    check_mesh_suffix(name)  # a NUL byte too
    real = os.path.realpath(os.path.join(os.fspath(base), name))
    folder = os.path.realpath(os.fspath(base))
    if not any(_inside(real, f) for f in (folder, *allowed)):
        raise GraspValueError(
            f"mesh path {name!r} is outside the {owner}'s folder {folder!r} (it leads to {real!r}); "
            "pass --allow-dir DIR (Python: allowed_dirs=) to allow it"
        )
    return Path(real)
