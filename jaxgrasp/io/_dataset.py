"""Grasp datasets: many grasps in one file, each validated on its own (SI units).

Two formats, chosen by the file's suffix:

``.npz``
    Arrays named exactly like the [`Grasp`][jaxgrasp.Grasp] fields, with a leading axis
    of ``B`` grasps padded to ``N`` contacts:

    ===========================  ===================================  =========
    array                        shape                                unit
    ===========================  ===================================  =========
    ``positions``                ``(B, N, 3)``                        m
    ``normals``                  ``(B, N, 3)``                        (any length)
    ``initial_deformation``      ``(B, N)``, ``(B,)`` or ``()``       m
    ``radius``                   ``(B, N)``, ``(B,)`` or ``()``       m
    ``young_modulus``            ``(B, N)``, ``(B,)`` or ``()``       Pa
    ``friction``                 ``(B, N)``, ``(B,)`` or ``()``       -
    ``max_force``                ``(B, N)``, ``(B,)`` or ``()``       N
    ``mass`` (optional, 0)       ``(B,)`` or ``()``                   kg
    ``gravity`` (optional)       ``(B, 3)`` or ``(3,)``               m/s^2
    ``active`` (optional)        ``(B, N)`` bool                      -
    ===========================  ===================================  =========

    ``active`` marks the contacts each grasp has (default: all): grasps with fewer than
    ``N`` contacts fill the rest with ``active = False`` (their values are ignored but
    must be numbers). A ``(B,)`` array gives one value per grasp, a ``()`` one the value
    of every grasp. No pickled objects.

``.jsonl``
    One grasp per line, each a JSON object in the grasp-file schema
    ([`jaxgrasp.load`][jaxgrasp.load]: ``fingertip``, ``object``, ``contacts``), any numbers of
    contacts (an ``object.mesh`` path is relative to the dataset file). Lines end at
    ``\n`` only (a U+2028 or U+0085 inside a JSON string is part of its line, so line
    numbers are those of ``wc -l``). Blank lines are skipped; UTF-8, with or without a
    byte-order mark. The file is read line by line, never whole.

A mesh a ``.jsonl`` line names must lie inside the dataset's folder after symlinks, or
inside a folder passed in ``allowed_dirs`` (``--allow-dir``): a line naming one outside
is an invalid grasp. Only mesh formats are read (`MESH_SUFFIXES`).
The dataset must be a regular file of at most `MAX_DATASET_BYTES`
bytes; an ``.npz``'s arrays may declare at most as many bytes uncompressed, checked from
the zip directory and each ``.npy`` header before anything is allocated.

Grasps are held in columns (`GraspColumns`: float64 NumPy arrays with a leading
axis of ``B`` grasps, padded to the largest contact count), about 30 numbers per contact,
so that loading a file costs memory in proportion to its numbers, not a JAX array per
field per grasp. ``GraspSet.grasps[i]`` builds grasp ``i``'s [`Grasp`][jaxgrasp.Grasp]
when asked.

A grasp with an invalid value does not stop the reading: [`load_dataset`][jaxgrasp.load_dataset] returns
every grasp in input order, ``None`` with a one-line error (naming the grasp, field and
value) where one is invalid. A file that cannot be read as a whole (missing, wrong
suffix, a special file, too large, a corrupt or truncated zip, an array declaring more
than the cap, no grasps, a missing or misshapen array, an unknown array) raises
[`GraspValueError`][jaxgrasp.GraspValueError] (one line).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import os
import struct
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from jaxgrasp import storage
from jaxgrasp.io._grasp_file import _parse_json, checked_fields, grasp_to_dict
from jaxgrasp.io._inputs import MAX_DATASET_BYTES, open_input
from jaxgrasp.io._mesh import MeshReader
from jaxgrasp.model import (
    DEFAULT_GRAVITY,
    DEFAULT_MASS,
    FIELD,
    NAMES,
    Grasp,
    GraspValueError,
    check_grasp_inputs,
    stack,
)

__all__ = ["SUFFIXES", "GraspColumns", "GraspRows", "GraspSet", "load_dataset", "load_share", "share_rows", "padded_set",
           "save_dataset"]

SUFFIXES = (".npz", ".jsonl")
"""The dataset formats, by file suffix."""

_OPTIONAL = {"mass": DEFAULT_MASS, "gravity": DEFAULT_GRAVITY}
_ARRAYS = NAMES + ("active",)
_BOM = b"\xef\xbb\xbf"


# ----------------------------------------------------------------------------- columns


@dataclasses.dataclass(frozen=True, eq=False)
class GraspColumns:
    """The grasps of a set as columns: one float64 array per [`Grasp`][jaxgrasp.Grasp] field.

    Attributes:
        fields: every grasp field by name with a leading axis of ``B`` grasps, contacts
            padded to ``N`` (the largest count): ``positions (B, N, 3)`` m, unit
            ``normals (B, N, 3)``, per-contact fields ``(B, N)`` (m, m, Pa, -, N),
            ``mass (B,)`` kg, ``gravity (B, 3)`` m/s^2. A grasp's own contacts come first;
            the padding repeats its last one (valid numbers, inactive). An invalid grasp's
            row repeats the first valid grasp's, with no contact.
        counts: ``(B,)`` int64, each grasp's contacts (0 for an invalid one).
        mask: ``(B, N)`` bool, where a grasp's contacts are not its first ``counts[i]``:
            the contacts it has, in place (a hand's fingertips in contact, so that contact
            ``k`` is fingertip ``k`` in every result); ``None``: the first ``counts[i]``.
    """

    fields: Mapping[str, np.ndarray]
    counts: np.ndarray
    mask: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        """``(B,)`` bool: which grasps are valid (have contacts)."""
        return self.counts > 0

    @property
    def active(self) -> np.ndarray:
        """``(B, N)`` bool: the contacts each grasp has (`mask`, else its first ``counts[i]``)."""
        if self.mask is not None:
            return self.mask
        return np.arange(self.fields["positions"].shape[1]) < self.counts[:, None]

    def grasp(self, i: int) -> Grasp | None:
        """Grasp ``i`` with its own contacts (JAX arrays, float64), ``None`` if invalid."""
        k = int(self.counts[i])
        if k == 0:
            return None
        import jax.numpy as jnp

        own = self.active[i]
        return Grasp(**{n: jnp.asarray(a[i, own] if FIELD[n].per_contact else a[i]) for n, a in self.fields.items()})


class _ColumnBuilder:
    """Fills `GraspColumns` row by row from checked fields
    (`check_grasp_inputs`), growing as rows and contacts
    come (the number of grasps and contacts of a ``.jsonl`` is known only at its end)."""

    def __init__(self, rows: int = 64, contacts: int = 2):
        self._rows, self._contacts = max(rows, 1), max(contacts, 1)
        self._arrays: dict[str, np.ndarray] = {}
        self._counts = np.zeros(self._rows, dtype=np.int64)
        self.size = 0

    def _shape(self, name: str, rows: int, contacts: int) -> tuple[int, ...]:
        shape = FIELD[name].shape
        tail = (3,) if shape in ("points", "directions", "vector") else ()
        return (rows, contacts, *tail) if FIELD[name].per_contact else (rows, *tail)

    def _grow(self, rows: int, contacts: int) -> None:
        """Make room for ``rows`` grasps of ``contacts`` contacts (doubling: amortised)."""
        new_rows = self._rows if rows <= self._rows else max(rows, 2 * self._rows)
        new_contacts = self._contacts if contacts <= self._contacts else max(contacts, 2 * self._contacts)
        if (new_rows, new_contacts) == (self._rows, self._contacts) and self._arrays:
            return
        for name in NAMES:
            grown = np.zeros(self._shape(name, new_rows, new_contacts))
            old = self._arrays.get(name)
            if old is not None and FIELD[name].per_contact:
                grown[: self.size, : self._contacts] = old[: self.size]
            elif old is not None:
                grown[: self.size] = old[: self.size]
            self._arrays[name] = grown
        self._counts = np.concatenate([self._counts[: self.size], np.zeros(new_rows - self.size, dtype=np.int64)])
        self._rows, self._contacts = new_rows, new_contacts

    def add(self, fields: Mapping[str, np.ndarray] | None) -> None:
        """Append one grasp's checked fields, or ``None`` for an invalid grasp."""
        k = 0 if fields is None else len(fields["positions"])
        self._grow(self.size + 1, k)
        if fields is not None:
            for name, a in fields.items():
                if FIELD[name].per_contact:
                    self._arrays[name][self.size, :k] = a
                else:
                    self._arrays[name][self.size] = a
            self._counts[self.size] = k
        self.size += 1

    def finish(self) -> GraspColumns:
        """The columns of the rows added: padded to the largest count (see `GraspColumns`)."""
        self._grow(self.size, 1)
        b, counts = self.size, self._counts[: self.size]
        n = int(counts.max(initial=0))
        valid = np.flatnonzero(counts)
        source = np.where(counts > 0, np.arange(b), valid[0] if valid.size else 0)  # the row each row copies
        own = np.maximum(counts[source], 1)
        pick = np.minimum(np.arange(n), own[:, None] - 1)  # (B, N): padding repeats the last contact
        fields = {}
        for name, a in self._arrays.items():
            if FIELD[name].per_contact:
                fields[name] = a[source[:, None], pick]
            else:
                fields[name] = a[source]
        self._arrays = {}
        return GraspColumns(fields=fields, counts=counts.copy())


def columns_of(grasps: Sequence[Grasp | None]) -> GraspColumns:
    """`GraspColumns` of grasps in memory (``None``: an invalid one), each validated.

    Raises:
        GraspValueError: ``grasp i: ...``, the first grasp that is not valid.
    """
    builder = _ColumnBuilder(len(grasps))
    for i, g in enumerate(grasps):
        if g is None:
            builder.add(None)
            continue
        if not isinstance(g, Grasp):
            raise GraspValueError(f"grasp {i} is {type(g).__name__}, not a jaxgrasp.Grasp")
        try:
            builder.add(check_grasp_inputs(**g.compact().to_numpy()))
        except GraspValueError as exc:
            raise GraspValueError(f"grasp {i}: {exc}") from None
    return builder.finish()


class GraspRows(Sequence):
    """The grasps of `GraspColumns` as a read-only sequence: item ``i`` is grasp
    ``i``'s [`Grasp`][jaxgrasp.Grasp] (built when asked, its own contacts only), ``None``
    where it is invalid."""

    def __init__(self, columns: GraspColumns):
        self.columns = columns

    def __len__(self) -> int:
        return len(self.columns.counts)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return tuple(self[j] for j in range(*i.indices(len(self))))
        i = int(i)
        if not -len(self) <= i < len(self):
            raise IndexError(f"grasp index {i} out of range for {len(self)} grasps")
        return self.columns.grasp(i % len(self))

    def __repr__(self) -> str:
        return f"GraspRows({len(self)} grasps)"


@dataclasses.dataclass(frozen=True, eq=False)
class GraspSet:
    """The grasps of a dataset file, in input order.

    Attributes:
        grasps: one [`Grasp`][jaxgrasp.Grasp] per input grasp (float64, SI units; only its
            active contacts), ``None`` where the grasp is invalid. A set read from a file
            holds a `GraspRows` (built from its columns when indexed); a set made
            in memory, a tuple.
        errors: ``None`` per valid grasp, the one-line reason per invalid one
            (``"grasp 3: friction = -1 must be positive"``; ``line 4`` for ``.jsonl``).
        source: the file read.
        source_sha256: SHA-256 (hex) of the file's bytes as they were parsed, ``None``
            for a set made in memory.
        mesh_sha256: the real path of every mesh file the rows named and read, to the
            SHA-256 (hex) of its bytes (``jaxgrasp batch --resume`` checks these and
            ``source_sha256``).
    """

    grasps: Sequence
    errors: tuple
    source: str = "<memory>"
    source_sha256: str | None = None
    mesh_sha256: Mapping[str, str] = dataclasses.field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.errors)

    def columns(self) -> GraspColumns:
        """The grasps as `GraspColumns` (a file's own; built and validated for a
        set made in memory)."""
        if isinstance(self.grasps, GraspRows):
            return self.grasps.columns
        return columns_of(tuple(self.grasps))

    @property
    def valid(self) -> np.ndarray:
        """``(B,)`` bool: which grasps are valid."""
        if isinstance(self.grasps, GraspRows):
            return self.grasps.columns.valid
        return np.asarray([g is not None for g in self.grasps], dtype=bool)

    @property
    def num_contacts(self) -> np.ndarray:
        """``(B,)`` int: contacts of each valid grasp, 0 for an invalid one."""
        if isinstance(self.grasps, GraspRows):
            return self.grasps.columns.counts
        return np.asarray([0 if g is None else g.num_contacts for g in self.grasps], dtype=np.int64)

    def raise_if_invalid(self) -> None:
        """Raise [`GraspValueError`][jaxgrasp.GraspValueError] naming the first invalid grasp and how many there are."""
        bad = [e for e in self.errors if e is not None]
        if bad:
            more = f" (and {len(bad) - 1} more invalid grasps)" if len(bad) > 1 else ""
            raise GraspValueError(f"{self.source}: {bad[0]}{more}")


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise GraspValueError(f"{path}: unknown dataset file type {suffix!r}; use .npz or .jsonl")
    return suffix


def load_dataset(path: str | os.PathLike, *, allowed_dirs=None) -> GraspSet:
    """Read a dataset file (``.npz`` or ``.jsonl``, see the module doc); every grasp validated.

    Args:
        path: the dataset file: a regular file of at most
            `MAX_DATASET_BYTES` bytes.
        allowed_dirs: folders (paths) besides the dataset's own that the meshes its
            ``.jsonl`` lines name may be in (after symlinks); default none.

    Returns:
        A [`GraspSet`][jaxgrasp.GraspSet]: the grasps in input order (as columns), ``None`` and a
        one-line error where a grasp is invalid (a mesh outside the allowed folders too).

    Raises:
        GraspValueError: the file as a whole cannot be read (one line, starting with
            the file name).
    """
    return load_share(path, 0, 1, allowed_dirs=allowed_dirs)[0]


def share_rows(total: int, index: int, count: int) -> np.ndarray:
    """The input rows of share ``index`` of ``count`` of a dataset of ``total`` grasps:
    every ``count``-th grasp from grasp ``index`` (strided, so that neighbouring grasps,
    often alike, are spread over the shares), in input order; ``(rows,)`` int64."""
    return np.arange(index, total, count, dtype=np.int64)


def load_share(path: str | os.PathLike, index: int, count: int, *, allowed_dirs=None) -> tuple[GraspSet, int]:
    """Read and validate share ``index`` of ``count`` of a dataset file: the grasps
    `share_rows` names (of one process of several, ``jaxgrasp batch
    --num-processes``); ``(its set, the file's number of grasps)``.

    Every line of a ``.jsonl`` is still read (to number the grasps and hash the bytes),
    but only the share's lines are parsed and validated and only the meshes they name are
    read; an ``.npz``'s arrays are read whole and the share's rows validated. Errors name
    each grasp by its input index and line, as [`load_dataset`][jaxgrasp.load_dataset] does (which is share
    0 of 1). ``source_sha256`` is the whole file's.

    Raises:
        GraspValueError: the file as a whole cannot be read, as [`load_dataset`][jaxgrasp.load_dataset].
    """
    path = Path(path)
    suffix = _suffix(path)
    if path.is_dir():
        raise GraspValueError(f"{path}: is a folder, not a dataset file (.npz or .jsonl)")
    meshes = MeshReader(path.parent, allowed_dirs, owner="dataset")
    keep = (int(index), int(count))
    with open_input(path, MAX_DATASET_BYTES, "dataset") as fh:
        try:
            if suffix == ".npz":
                columns, errors, sha, total = _read_npz(fh, path, keep)
            else:
                columns, errors, sha, total = _read_jsonl(fh, path, meshes, keep)
        except OSError as exc:
            raise GraspValueError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    gset = GraspSet(grasps=GraspRows(columns), errors=tuple(errors), source=str(path), source_sha256=sha,
                    mesh_sha256=dict(meshes.sha256))
    return gset, total


def padded_set(gset: GraspSet, n_contacts: int) -> GraspSet:
    """``gset`` (read from a file) with its columns padded to ``n_contacts`` contacts (at
    least its own), the padding repeating each grasp's last contact, as a file whose
    largest grasp has ``n_contacts`` contacts is read: so that the shares of one dataset
    are evaluated at one contact count. A set without a valid grasp (no contact to
    repeat) is padded with zeros, which are never evaluated."""
    columns = gset.columns()
    n = columns.fields["positions"].shape[1]
    if n_contacts <= n:
        return gset
    pick = np.minimum(np.arange(n_contacts), max(n - 1, 0))
    fields = {k: (a[:, pick] if n else np.zeros((a.shape[0], n_contacts, *a.shape[2:]))) if FIELD[k].per_contact
              else a for k, a in columns.fields.items()}
    mask = None if columns.mask is None else np.concatenate(
        [columns.mask, np.zeros((len(columns.mask), n_contacts - n), bool)], axis=1)  # the padding is never a contact
    return dataclasses.replace(gset, grasps=GraspRows(GraspColumns(fields=fields, counts=columns.counts, mask=mask)))


# ----------------------------------------------------------------------------- .npz


def _npz_arrays(fh: BinaryIO, path: Path) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file (`_npz_members`), checked for names (one-line errors)."""
    try:
        arrays = _npz_members(fh, path)
    except GraspValueError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, ValueError, OSError, EOFError,
            NotImplementedError, KeyError, RuntimeError) as exc:  # not a zip, truncated, a bad member, compression unknown
        raise GraspValueError(f"{path}: not a readable .npz file ({' '.join(str(exc).split())})") from None
    unknown = sorted(set(arrays) - set(_ARRAYS))
    if unknown:
        raise GraspValueError(f"{path}: unknown array {unknown[0]!r}; arrays are named {', '.join(_ARRAYS)}")
    missing = [n for n in NAMES if n not in arrays and n not in _OPTIONAL]
    if missing:
        raise GraspValueError(f"{path}: missing array {missing[0]!r} (every grasp field but mass and gravity is required)")
    return arrays


def _size(n: float) -> str:
    return f"{n / 2**40:.3g} TiB" if n >= 2**40 else f"{n / 2**20:.4g} MiB"


def _npz_members(fh: BinaryIO, path: Path) -> dict[str, np.ndarray]:
    """Every ``NAME.npy`` member of the zip ``fh`` as an array, its size checked first: the
    sizes the zip directory declares, then each ``.npy`` header's shape times item size,
    against `MAX_DATASET_BYTES`, before a byte is allocated."""
    arrays = {}
    _check_member_count(fh, path)
    with zipfile.ZipFile(fh) as zf:
        infos = zf.infolist()
        declared = sum(info.file_size for info in infos)
        if declared > MAX_DATASET_BYTES:
            raise GraspValueError(
                f"{path}: its arrays declare {_size(declared)} uncompressed, more than the "
                f"{_size(MAX_DATASET_BYTES)} read at most"
            )
        _check_members(infos, path)
        for info in infos:
            name = info.filename.removesuffix(".npy")
            with zf.open(info) as member:
                arrays[name] = _npy_member(member, info.file_size, name, path)
    return arrays


_MAX_MEMBERS = 64
"""The most members an ``.npz``'s zip may list (its arrays are at most one per name of
`_ARRAYS`; a few more get the one line that names the first unknown one)."""

_EOCD = struct.Struct("<4s4H2LH")
"""The zip's end-of-central-directory record: signature, disk numbers, entries on this disk
and in all, the directory's size and offset, the comment's length."""


def _check_member_count(fh: BinaryIO, path: Path) -> None:
    """At most `_MAX_MEMBERS` members, read from the zip's last record before ``zipfile``
    builds an object per member of its directory (a 1 GiB file could list 20 million
    members). A file without that record is left to ``zipfile`` (not a zip)."""
    size = fh.seek(0, os.SEEK_END)
    fh.seek(max(0, size - _EOCD.size - 0xFFFF))  # the record, then a comment of at most 64 KiB
    tail = fh.read()
    fh.seek(0)
    at = tail.rfind(b"PK\x05\x06", 0, max(0, len(tail) - _EOCD.size + 4))  # the whole record fits
    if at < 0:
        return
    entries = _EOCD.unpack_from(tail, at)[4]  # in the whole zip
    if entries > _MAX_MEMBERS:
        raise GraspValueError(f"{path}: the zip lists {entries:,} members; a dataset .npz holds at most "
                              f"{len(_ARRAYS)} arrays, one per name ({', '.join(_ARRAYS)})")


def _check_members(infos: list, path: Path) -> None:
    """Every member a ``NAME.npy`` of a known array name, not encrypted, before one is
    decompressed (one-line errors)."""
    for info in infos:
        name = info.filename.removesuffix(".npy")
        if info.flag_bits & 0x1:  # zip flag bit 0: encrypted, a password would be needed
            raise GraspValueError(f"{path}: array {name!r} is encrypted; save the dataset with numpy.savez, "
                                  "without a password")
        if name not in _ARRAYS:
            raise GraspValueError(f"{path}: unknown array {name!r}; arrays are named {', '.join(_ARRAYS)}")


def _npy_member(member: BinaryIO, size: int, name: str, path: Path) -> np.ndarray:
    """One ``.npy`` member: header read and checked, then exactly its data (no pickles)."""
    fmt = np.lib.format
    version = fmt.read_magic(member)
    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
    shape, fortran, dtype = read_header(member)
    if dtype.hasobject:
        raise GraspValueError(f"{path}: array {name!r} holds Python objects, which are not read (no pickles)")
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes > MAX_DATASET_BYTES or nbytes > size:
        raise GraspValueError(
            f"{path}: array {name!r} claims shape {shape} of {dtype} ({_size(nbytes)}), more than its "
            f"{_size(size)} in the file" + (f" and the {_size(MAX_DATASET_BYTES)} read at most" if nbytes > size else "")
        )
    data = member.read(nbytes)
    if len(data) != nbytes:
        raise GraspValueError(f"{path}: array {name!r} is truncated ({len(data)} of {nbytes} bytes)")
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")


def _npz_shapes(arrays: dict[str, np.ndarray], path: Path) -> tuple[int, int]:
    """``(B, N)`` from ``positions``; every other array checked against them."""
    pos = arrays["positions"]
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise GraspValueError(f"{path}: positions must have shape (B, N, 3), got {pos.shape}")
    b, n, _ = pos.shape
    if b == 0:
        raise GraspValueError(f"{path}: no grasps (positions has shape {pos.shape})")
    for name, a in arrays.items():
        allowed = _allowed_shapes(name, b, n)
        if a.shape not in allowed:
            shown = " or ".join(str(s) for s in allowed)
            raise GraspValueError(f"{path}: {name} must have shape {shown} (B={b}, N={n}), got {a.shape}")
        if name == "active" and a.dtype != np.bool_:
            raise GraspValueError(f"{path}: active must be a bool array, got {a.dtype}")
        if name != "active" and not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise GraspValueError(f"{path}: {name} must hold numbers, got dtype {a.dtype}")
    return b, n


def _allowed_shapes(name: str, b: int, n: int) -> tuple[tuple[int, ...], ...]:
    if name == "active":
        return ((b, n),)
    shape = FIELD[name].shape
    if shape in ("points", "directions"):
        return ((b, n, 3),)
    if shape == "per_contact":
        return ((b, n), (b,), ())
    if shape == "vector":
        return ((b, 3), (3,))
    return ((b,), ())  # scalar: mass


def _npz_grasp(arrays: dict[str, np.ndarray], i: int, n: int) -> dict[str, Any]:
    """The keyword arguments of [`Grasp.create`][jaxgrasp.Grasp.create] for grasp ``i`` (its active contacts).

    Shapes were checked by `_npz_shapes`: a leading ``B`` axis is there when an
    array has more axes than the field of one grasp, except that a per-contact ``(B,)``
    array holds one value per grasp."""
    keep = arrays["active"][i] if "active" in arrays else np.ones(n, dtype=bool)
    kwargs: dict[str, Any] = {}
    for name in NAMES:
        if name not in arrays:
            kwargs[name] = _OPTIONAL[name]
            continue
        a, field = arrays[name], FIELD[name]
        if field.per_contact:
            row = a if a.ndim == 0 else a[i]
            kwargs[name] = row[keep] if a.ndim >= 2 else row
        else:
            kwargs[name] = a[i] if a.ndim > field.ndim else a
    return kwargs


def _read_npz(fh: BinaryIO, path: Path, keep: tuple[int, int] = (0, 1)) -> tuple[GraspColumns, list, str, int]:
    """``(columns, errors, sha256, B)`` of the rows of an ``.npz`` dataset that share
    ``keep = (index, count)`` names (`share_rows`)."""
    digest = hashlib.sha256()
    for block in iter(lambda: fh.read(1 << 20), b""):  # the size was capped when it was opened
        digest.update(block)
    fh.seek(0)
    arrays = _npz_arrays(fh, path)
    b, n = _npz_shapes(arrays, path)
    builder, errors = _ColumnBuilder(-(-b // keep[1]), n), []
    for i in share_rows(b, *keep).tolist():
        try:
            builder.add(check_grasp_inputs(**_npz_grasp(arrays, i, n)))
            errors.append(None)
        except GraspValueError as exc:
            builder.add(None)
            errors.append(f"grasp {i}: {exc}")
    return builder.finish(), errors, digest.hexdigest(), b


# ----------------------------------------------------------------------------- .jsonl


def _jsonl_row(line: bytes, where: str, meshes: MeshReader) -> dict[str, np.ndarray]:
    """The checked fields of one ``.jsonl`` line (UTF-8 already checked); one-line errors."""
    try:
        data = _parse_json(line)
    except ValueError as exc:
        raise GraspValueError(f"{where}: malformed JSON: {exc}") from None
    except RecursionError:
        raise GraspValueError(f"{where}: malformed JSON: nested too deeply") from None
    return checked_fields(data, where, meshes)  # a mesh path is relative to the file


def _read_jsonl(fh: BinaryIO, path: Path, meshes: MeshReader, keep: tuple[int, int] = (0, 1)
                ) -> tuple[GraspColumns, list, str, int]:
    """``(columns, errors, sha256, B)`` of the grasps of a ``.jsonl`` dataset that share
    ``keep = (index, count)`` names (`share_rows`; the others' lines are counted,
    not parsed), read one line at a time.

    Lines end at ``b"\\n"`` only: a binary file's lines, unlike ``str.splitlines``, which
    also breaks at U+2028, U+0085 and others that JSON strings may hold raw."""
    digest, total, builder, errors, grasps = hashlib.sha256(), 0, _ColumnBuilder(), [], 0
    for lineno in range(1, 2**63):
        line = fh.readline(MAX_DATASET_BYTES + 1 - total)  # never more than the cap in all
        if not line:
            break
        total += len(line)
        if total > MAX_DATASET_BYTES:
            raise GraspValueError(f"{path}: the dataset grew past the {_size(MAX_DATASET_BYTES)} read at most")
        digest.update(line)
        start = total - len(line)
        if lineno == 1 and line.startswith(_BOM):
            line, start = line[len(_BOM):], start + len(_BOM)
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise GraspValueError(f"{path}: not valid UTF-8 text ({exc.reason} at byte {start + exc.start})") from None
        if not text.strip():
            continue
        grasps += 1
        if (grasps - 1) % keep[1] != keep[0]:
            continue
        where = f"grasp {grasps - 1} (line {lineno})"
        try:
            builder.add(_jsonl_row(line, where, meshes))
            errors.append(None)
        except GraspValueError as exc:
            builder.add(None)
            errors.append(str(exc))
    if not grasps:
        raise GraspValueError(f"{path}: no grasps (every line is blank)")
    return builder.finish(), errors, digest.hexdigest(), grasps


# ----------------------------------------------------------------------------- writing


def _as_list(grasps) -> list[Grasp]:
    """A sequence of grasps, or one batched grasp (leading axis ``B``, e.g. from
    [`jaxgrasp.stack`][jaxgrasp.stack]), as a list."""
    if isinstance(grasps, Grasp):
        pos = np.asarray(grasps.positions)
        if pos.ndim == 2:
            return [grasps]
        if pos.ndim != 3:
            raise GraspValueError(f"save_dataset needs grasps with positions (N, 3) or a batch (B, N, 3), got {pos.shape}")
        fields = grasps.to_numpy_batch()
        return [Grasp(**{k: v[i] for k, v in fields.items()}) for i in range(pos.shape[0])]
    out = list(grasps)
    for i, g in enumerate(out):
        if not isinstance(g, Grasp):
            raise GraspValueError(f"save_dataset: item {i} is {type(g).__name__}, not a jaxgrasp.Grasp")
    if not out:
        raise GraspValueError("save_dataset: no grasps to write")
    return out


def _npz_bytes(grasps: Sequence[Grasp]) -> bytes:
    """The ``.npz`` of ``grasps``, padded by [`jaxgrasp.stack`][jaxgrasp.stack] to the largest contact
    count (``active`` marks the real contacts, written only where some are padding)."""
    arrays = stack(grasps).to_numpy()
    active = arrays.pop("active")
    arrays = {name: np.asarray(a, dtype=np.float64) for name, a in arrays.items()}
    if not active.all():
        arrays["active"] = active
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _jsonl_bytes(grasps: Sequence[Grasp]) -> bytes:
    lines = [json.dumps(grasp_to_dict(g), allow_nan=False, separators=(",", ":")) for g in grasps]
    return ("\n".join(lines) + "\n").encode("utf-8")


def save_dataset(path: str | os.PathLike, grasps) -> None:
    """Write grasps (a sequence of [`Grasp`][jaxgrasp.Grasp] with any contact counts, or one
    batched grasp) to a dataset file, ``.npz`` or ``.jsonl`` (see the module doc), atomically.

    ``load_dataset(path)`` gives the same grasps back (float64, exactly).

    Raises:
        GraspValueError: unknown suffix, no grasps, or an item that is not a grasp.
        OSError: the file cannot be written (the previous file, if any, stays).
    """
    path = Path(path)
    suffix = _suffix(path)
    items = _as_list(grasps)
    content = _npz_bytes(items) if suffix == ".npz" else _jsonl_bytes(items)
    storage.write_file(path, content)
