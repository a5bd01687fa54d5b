"""Grasp datasets: many grasps in one file, each validated on its own (SI units).

Two formats, chosen by the file's suffix:

``.npz``
    Arrays named exactly like the :class:`~jaxgrasp.Grasp` fields, with a leading axis
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
    (:func:`jaxgrasp.load`: ``fingertip``, ``object``, ``contacts``), any numbers of
    contacts (an ``object.mesh`` path is relative to the dataset file). Blank lines are
    skipped; UTF-8, with or without a byte-order mark.

A grasp with an invalid value does not stop the reading: :func:`load_dataset` returns
every grasp in input order, ``None`` with a one-line error (naming the grasp, field and
value) where one is invalid. A file that cannot be read as a whole (missing, wrong
suffix, a missing or misshapen array, an unknown array) raises
:class:`~jaxgrasp.GraspValueError`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from jaxgrasp.io import _outputs as outputs
from jaxgrasp.io._grasp_file import _parse_json, grasp_from_dict, grasp_to_dict, read_input
from jaxgrasp.model._fields import DEFAULT_GRAVITY, DEFAULT_MASS, FIELD, NAMES
from jaxgrasp.model._grasp import Grasp, stack
from jaxgrasp.model._validation import GraspValueError

__all__ = ["GraspSet", "load_dataset", "save_dataset", "SUFFIXES"]

SUFFIXES = (".npz", ".jsonl")
"""The dataset formats, by file suffix."""

_OPTIONAL = {"mass": DEFAULT_MASS, "gravity": DEFAULT_GRAVITY}
_ARRAYS = NAMES + ("active",)


@dataclasses.dataclass(frozen=True)
class GraspSet:
    """The grasps of a dataset file, in input order.

    Attributes:
        grasps: one :class:`~jaxgrasp.Grasp` per input grasp (float64, SI units; only its
            active contacts), ``None`` where the grasp is invalid.
        errors: ``None`` per valid grasp, the one-line reason per invalid one
            (``"grasp 3: friction = -1 must be positive"``; ``line 4`` for ``.jsonl``).
        source: the file read.
        source_sha256: SHA-256 (hex) of the file's bytes as they were parsed, ``None``
            for a set made in memory (``jaxgrasp batch --resume`` checks it).
    """

    grasps: tuple
    errors: tuple
    source: str = "<memory>"
    source_sha256: str | None = None

    def __len__(self) -> int:
        return len(self.grasps)

    @property
    def valid(self) -> np.ndarray:
        """``(B,)`` bool: which grasps are valid."""
        return np.asarray([g is not None for g in self.grasps], dtype=bool)

    @property
    def num_contacts(self) -> np.ndarray:
        """``(B,)`` int: contacts of each valid grasp, 0 for an invalid one."""
        return np.asarray([0 if g is None else g.num_contacts for g in self.grasps], dtype=np.int64)

    def raise_if_invalid(self) -> None:
        """Raise :class:`GraspValueError` naming the first invalid grasp and how many there are."""
        bad = [e for e in self.errors if e is not None]
        if bad:
            more = f" (and {len(bad) - 1} more invalid grasps)" if len(bad) > 1 else ""
            raise GraspValueError(f"{self.source}: {bad[0]}{more}")


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise GraspValueError(f"{path}: unknown dataset file type {suffix!r}; use .npz or .jsonl")
    return suffix


def load_dataset(path: str | os.PathLike) -> GraspSet:
    """Read a dataset file (``.npz`` or ``.jsonl``, see the module doc); every grasp validated.

    Returns:
        A :class:`GraspSet`: the grasps in input order, ``None`` and a one-line error
        where a grasp is invalid.

    Raises:
        GraspValueError: the file as a whole cannot be read (one line, starting with
            the file name).
    """
    path = Path(path)
    suffix = _suffix(path)
    if path.is_dir():
        raise GraspValueError(f"{path}: is a folder, not a dataset file (.npz or .jsonl)")
    raw = read_input(path)
    grasps, errors = (_read_npz if suffix == ".npz" else _read_jsonl)(raw, path)
    return GraspSet(
        grasps=tuple(grasps), errors=tuple(errors), source=str(path), source_sha256=hashlib.sha256(raw).hexdigest()
    )


# ----------------------------------------------------------------------------- .npz


def _npz_arrays(raw: bytes, path: Path) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file, checked for names (one-line errors)."""
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except (ValueError, OSError, EOFError) as exc:  # not a zip, pickled objects, truncated
        raise GraspValueError(f"{path}: not a readable .npz file ({exc})") from None
    unknown = sorted(set(arrays) - set(_ARRAYS))
    if unknown:
        raise GraspValueError(f"{path}: unknown array {unknown[0]!r}; arrays are named {', '.join(_ARRAYS)}")
    missing = [n for n in NAMES if n not in arrays and n not in _OPTIONAL]
    if missing:
        raise GraspValueError(f"{path}: missing array {missing[0]!r} (every grasp field but mass and gravity is required)")
    return arrays


def _npz_shapes(arrays: dict[str, np.ndarray], path: Path) -> tuple[int, int]:
    """``(B, N)`` from ``positions``; every other array checked against them."""
    pos = arrays["positions"]
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise GraspValueError(f"{path}: positions must have shape (B, N, 3), got {pos.shape}")
    b, n, _ = pos.shape
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
    """The keyword arguments of :meth:`Grasp.create` for grasp ``i`` (its active contacts).

    Shapes were checked by :func:`_npz_shapes`: a leading ``B`` axis is there when an
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


def _read_npz(raw: bytes, path: Path) -> tuple[list, list]:
    arrays = _npz_arrays(raw, path)
    b, n = _npz_shapes(arrays, path)
    grasps, errors = [], []
    for i in range(b):
        try:
            grasps.append(Grasp.create(**_npz_grasp(arrays, i, n)))
            errors.append(None)
        except GraspValueError as exc:
            grasps.append(None)
            errors.append(f"grasp {i}: {exc}")
    return grasps, errors


# ----------------------------------------------------------------------------- .jsonl


def _read_jsonl(raw: bytes, path: Path) -> tuple[list, list]:
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise GraspValueError(f"{path}: not valid UTF-8 text ({exc.reason} at byte {exc.start})") from None
    grasps, errors = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        where = f"grasp {len(grasps)} (line {lineno})"
        try:
            data = _parse_json(line.encode())
        except ValueError as exc:
            grasps.append(None)
            errors.append(f"{where}: malformed JSON: {exc}")
            continue
        except RecursionError:
            grasps.append(None)
            errors.append(f"{where}: malformed JSON: nested too deeply")
            continue
        try:
            grasps.append(grasp_from_dict(data, source=where, base=path.parent))  # a mesh path is relative to the file
            errors.append(None)
        except GraspValueError as exc:
            grasps.append(None)
            errors.append(str(exc))
    if not grasps:
        raise GraspValueError(f"{path}: no grasps (every line is blank)")
    return grasps, errors


# ----------------------------------------------------------------------------- writing


def _as_list(grasps) -> list[Grasp]:
    """A sequence of grasps, or one batched grasp (leading axis ``B``, e.g. from
    :func:`jaxgrasp.stack`), as a list."""
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
    """The ``.npz`` of ``grasps``, padded by :func:`jaxgrasp.stack` to the largest contact
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
    """Write grasps (a sequence of :class:`~jaxgrasp.Grasp` with any contact counts, or one
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
    outputs.write_file(path, content)
