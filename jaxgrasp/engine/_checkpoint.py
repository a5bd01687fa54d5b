"""What an interrupted command keeps: a sweep's finished grid points, a batch's finished chunks.

Sweeps: `SweepCheckpoint`, the file ``sweep.partial.npz``. Batches:
`BatchCheckpoint`, the folder ``results.partial`` (one file per finished chunk, so a
checkpoint costs the same at every chunk and survives ``kill -9``).

The sweep's checkpoint ``sweep.partial.npz``:

``jaxgrasp sweep --out DIR`` rewrites ``DIR/sweep.partial.npz`` (atomically, see
`jaxgrasp.storage`) after its chunks, and deletes it once the final
``sweep.npz``/``sweep.csv``/``sweep.png`` are in place; an interrupted sweep leaves it
behind with every point finished before the last checkpoint. Read it with
`SweepCheckpoint.load`.

File format (``np.load(path)``; no pickled objects), ``format`` =
``"jaxgrasp-sweep-partial-1"``:

* ``axis_names`` (str, 1-D) and ``axis_<name>`` (float64, 1-D, SI units): the grid, as
  in ``sweep.npz``; grid points are numbered in C order (last axis fastest).
* ``done`` (bool, grid shape): the points whose results are final.
* ``value`` (J), ``status``, ``limiting_kind``, ``limiting_contact``,
  ``equilibrium_energy`` (J): grid-shaped as in ``sweep.npz``; where ``done`` is False
  the floats are NaN and the integer codes -1.
* ``status_names``, ``kind_names``: the names of the codes.
* ``grasp_<field>`` (float64, SI units): every field of the base
  [`Grasp`][jaxgrasp.Grasp] (``Grasp.to_numpy()``), so that a resumed sweep can check it
  continues the same grasp.
* ``chunk_size`` (int64): the grid points per compiled batch.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
import re
import stat
import threading
import time
import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

from jaxgrasp import storage
from jaxgrasp.model import BoundaryKind
from jaxgrasp.tolerance import SUMMARY_FIELDS as RESULT_FIELDS
from jaxgrasp.tolerance import GraspStatus

__all__ = [
    "SweepCheckpoint",
    "SweepKeeper",
    "BatchCheckpoint",
    "CheckpointBusy",
    "FORMAT",
    "BATCH_FORMAT",
    "RESULT_FIELDS",
    "CHECKPOINT_SHARE",
    "SWEEP_FILE",
    "BATCH_FOLDER",
    "chunk_layout",
    "rows_digest",
    "run_key",
]

SWEEP_FILE = "sweep.partial.npz"
"""Name of a sweep's checkpoint file in ``jaxgrasp sweep``'s ``--out``."""

BATCH_FOLDER = "results.partial"
"""Name of a batch's checkpoint folder in ``jaxgrasp batch``'s ``--out``."""

FORMAT = "jaxgrasp-sweep-partial-1"
"""The ``format`` entry of a checkpoint file (changes when its layout does)."""

@dataclasses.dataclass(frozen=True, eq=False)
class SweepCheckpoint:
    """A sweep's grid with the points finished so far (SI units).

    Attributes:
        axes: parameter name -> 1-D float64 grid values, in grid order.
        done: bool array shaped like the grid; True where the results are final.
        results: result field (`RESULT_FIELDS`) -> grid-shaped array; NaN (floats)
            or -1 (integer codes) where not ``done``.
        grasp: the base grasp's fields (``Grasp.to_numpy()``), float64, SI units.
        chunk_size: grid points per compiled batch.
    """

    axes: dict
    done: np.ndarray
    results: dict
    grasp: dict
    chunk_size: int

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape ``(len(ax1), len(ax2), ...)``."""
        return tuple(len(a) for a in self.axes.values())

    @property
    def total(self) -> int:
        """Number of grid points."""
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def done_count(self) -> int:
        """Number of finished grid points."""
        return int(np.count_nonzero(self.done))

    @classmethod
    def from_flat(
        cls,
        axes: Mapping[str, np.ndarray],
        done: np.ndarray,
        results: Mapping[str, np.ndarray],
        grasp: Mapping[str, np.ndarray],
        chunk_size: int,
    ) -> "SweepCheckpoint":
        """From flat (C-order, ``(total,)``) ``done`` and result arrays, which are copied
        with the entries not ``done`` replaced by NaN / -1."""
        shape = tuple(len(a) for a in axes.values())
        done = np.asarray(done, dtype=bool).reshape(shape)
        out = {}
        for f in RESULT_FIELDS:
            a = np.asarray(results[f]).reshape(shape)
            fill = np.nan if np.issubdtype(a.dtype, np.floating) else -1
            out[f] = np.where(done, a, np.asarray(fill, dtype=a.dtype))
        return cls(
            axes={n: np.asarray(a, dtype=np.float64) for n, a in axes.items()},
            done=done,
            results=out,
            grasp={k: np.asarray(v, dtype=np.float64) for k, v in grasp.items()},
            chunk_size=int(chunk_size),
        )

    def save(self, file) -> None:
        """Write the checkpoint to ``file`` (a path or a binary file object); not atomic
        by itself (the CLI writes it through `jaxgrasp.storage.write_file`)."""
        arrays = {
            "format": np.asarray(FORMAT),
            "axis_names": np.asarray(list(self.axes), dtype=str),
            "done": self.done,
            "status_names": np.asarray(GraspStatus.labels(), dtype=str),
            "kind_names": np.asarray(BoundaryKind.labels(), dtype=str),
            "chunk_size": np.int64(self.chunk_size),
        }
        arrays.update({f"axis_{n}": a for n, a in self.axes.items()})
        arrays.update(self.results)
        arrays.update({f"grasp_{k}": v for k, v in self.grasp.items()})
        np.savez(file, **arrays)

    @classmethod
    def load(cls, path) -> "SweepCheckpoint":
        """Read a checkpoint file (without following a link).

        Raises:
            ValueError: (one line) not a checkpoint of this format, or a damaged one:
                unreadable, an array missing, or shapes that disagree with its grid.
        """
        try:
            data = storage.read_own(path)
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                if "format" not in z.files or str(z["format"]) != FORMAT:
                    raise ValueError(f"{path}: not a jaxgrasp sweep checkpoint ({FORMAT})")
                names = [str(n) for n in z["axis_names"]]
                loaded = cls(
                    axes={n: np.array(z[f"axis_{n}"], dtype=np.float64) for n in names},
                    done=np.array(z["done"]),
                    results={f: np.array(z[f]) for f in RESULT_FIELDS},
                    grasp={k[len("grasp_") :]: np.array(z[k]) for k in z.files if k.startswith("grasp_")},
                    chunk_size=int(z["chunk_size"]),
                )
        except ValueError:
            raise
        except Exception as exc:  # noqa: BLE001 - any damage (BadZipFile, KeyError, ...) is one line
            raise ValueError(f"{path}: a damaged sweep checkpoint ({_reason(exc)})") from None
        return loaded._checked(path)

    def _checked(self, path) -> SweepCheckpoint:
        """``self``, if its arrays fit its grid; else ``ValueError`` (one line)."""
        if self.done.dtype != bool or self.done.shape != self.shape or any(a.ndim != 1 for a in self.axes.values()):
            raise ValueError(f"{path}: a damaged sweep checkpoint (done {self.done.shape}, grid {self.shape})")
        for f, a in self.results.items():
            if a.shape != self.shape:
                raise ValueError(f"{path}: a damaged sweep checkpoint ({f} {a.shape}, grid {self.shape})")
        return self


CHECKPOINT_SHARE = 0.05
"""Checkpoints take at most about this share of a sweep's time (later ones are skipped
while the last one's cost exceeds it); the last chunk's is always written."""


class SweepKeeper:
    """``on_chunk`` of [`jaxgrasp.sweep`][jaxgrasp.sweep] that keeps the finished points in a
    `SweepCheckpoint` file at ``path``, atomically.

    A write is skipped while the previous one cost more than `CHECKPOINT_SHARE`
    of the time since; the skipped write is handed to `deferred` (which a caller
    that can be interrupted keeps, to run `write` before it exits: the command
    line's keeper, `jaxgrasp.cli`), so only a hard kill (``kill -9``) loses the
    points since the last write. The last chunk's is always written. Each write, once in
    place, is passed to `kept`. Both hooks do nothing here.
    """

    def __init__(self, path, grasp, axes: Mapping[str, np.ndarray], chunk: int):
        self.path = Path(path)
        self.grasp = grasp.to_numpy()
        self.axes = axes
        self.chunk = chunk
        self.total = int(np.prod([a.size for a in axes.values()]))
        self.done = np.zeros(self.total, dtype=bool)
        self._results = None  # the sweep's flat result arrays (filled chunk by chunk)
        self._lock = threading.Lock()  # the worker's chunk updates vs an interrupt's write
        self._cost = 0.0  # seconds the last write took
        self._end = 0.0  # when it ended

    def __call__(self, start: int, stop: int, results) -> None:
        with self._lock:
            self.done[start:stop] = True
            self._results = results
        now = time.perf_counter()
        if stop < self.total and self._cost > CHECKPOINT_SHARE * (now - self._end):
            self.deferred(self.write)
            return
        self.write()
        self._end = time.perf_counter()
        self._cost = self._end - now

    def write(self) -> None:
        """Write the points finished so far (the worker's later chunks do not touch them)."""
        self.deferred(None)
        with self._lock:
            partial = SweepCheckpoint.from_flat(self.axes, self.done.copy(), self._results, self.grasp, self.chunk)
        storage.write_set({self.path: partial.save}, on_publish=lambda: self.kept(partial))

    def deferred(self, write) -> None:
        """A write skipped (``write``, to call to make it) or none pending any more
        (``None``). Here: nothing."""

    def kept(self, partial: SweepCheckpoint) -> None:
        """``partial`` is in place at `path` (called under
        `jaxgrasp.storage.PUBLISH_LOCK`). Here: nothing."""


# --------------------------------------------------------------------------- batches

class CheckpointBusy(Exception):
    """A batch checkpoint holds an unfinished run that was not asked to resume."""

    def __init__(self, folder):
        super().__init__(str(folder))
        self.folder = Path(folder)


BATCH_FORMAT = "jaxgrasp-batch-partial-2"
"""The ``format`` of a batch checkpoint's ``manifest.json`` (changes when its layout does)."""


def chunk_layout(num_contacts: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Each [`Evaluation`][jaxgrasp.Evaluation] field's shape per grasp and dtype, for grasps
    padded to ``num_contacts`` (``N``) contacts: what a batch checkpoint's chunk must hold
    (the evaluator's output: float64 and int32 arrays, see [`Evaluation`][jaxgrasp.Evaluation])."""
    n, f8, i4 = int(num_contacts), np.dtype(np.float64), np.dtype(np.int32)
    return {
        "value": ((), f8),
        "status": ((), i4),
        "limiting_kind": ((), i4),
        "limiting_contact": ((), i4),
        "equilibrium_energy": ((), f8),
        "equilibrium_translation": ((3,), f8),
        "equilibrium_rotation": ((3,), f8),
        "boundary_energy": ((2, n), f8),
        "boundary_translation": ((2, n, 3), f8),
        "boundary_rotation": ((2, n, 3), f8),
        "boundary_status": ((2, n), i4),
        "equilibrium_status": ((), i4),
        "equilibrium_margins": ((3, n), f8),
        "kkt": ((1 + 2 * n, 3), f8),
        "steps": ((1 + 2 * n,), i4),
    }


_CHUNK_NAME = re.compile(r"rows-\d+\.npz")  # rows-<first row, 9 digits>.npz, fullmatch
_NPY_HEADER_BYTES = 4096  # at most, per array of a chunk file (NumPy's header, padded)
_DIGEST_BYTES = 64 * 4  # a chunk's digest: 64 hex digits as a NumPy unicode scalar


def run_key(options, widths: Mapping[int, int], platform: str) -> str:
    """What a batch's results depend on besides each grasp's own fields, as the text a
    chunk's digest (`rows_digest`) starts from: the
    [`EvaluateOptions`][jaxgrasp.EvaluateOptions] ``options``, the width each contact count
    runs at (``widths``, `plan_widths`: a grasp's value can differ with the width by
    rounding), the devices' ``platform`` (another program), jaxgrasp's source
    (`source_digest`: an editable install keeps its version while its code changes) and
    the JAX and jaxlib versions. The processor is left out: a run resumed on another
    machine of the same platform reuses its chunks."""
    import jax
    import jaxlib

    from jaxgrasp.engine._store import source_digest

    parts = [repr(options), repr(sorted((int(c), int(w)) for c, w in dict(widths).items())), str(platform),
             source_digest(), jax.__version__, jaxlib.__version__]
    return "\n".join(parts)


def rows_digest(inputs: Mapping[str, np.ndarray], rows: np.ndarray, key: str) -> str:
    """SHA-256 (hex) of ``key`` (`run_key`), the row numbers ``rows`` and, for each array
    of ``inputs`` (name -> ``(B, ...)``, the dataset's grasp fields by row), its name,
    dtype, and the bytes of exactly those rows: what a chunk's results were computed
    from. A chunk whose digest is not its rows' digest in this run is another run's."""
    rows = np.asarray(rows, dtype=np.int64)
    h = hashlib.sha256(key.encode("utf-8", "surrogateescape"))
    h.update(b"\nrows\n" + rows.astype("<i8").tobytes())
    for name in sorted(inputs):
        a = np.ascontiguousarray(np.asarray(inputs[name])[rows])
        h.update(f"\n{name} {a.dtype.str} {a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _reason(exc: BaseException) -> str:
    """An exception as a short, one-line reason."""
    text = str(exc).strip().splitlines()
    line = text[0] if text else ""
    return f"{type(exc).__name__}: {line[:200]}" if line else type(exc).__name__


class BatchCheckpoint:
    """The finished chunks of ``jaxgrasp batch FILE --out DIR``: the folder
    ``DIR/results.partial``, which ``--resume`` continues.

    Layout (no pickled objects):

    * ``manifest.json``: ``format`` (`BATCH_FORMAT`), ``source`` (the input file),
      ``source_sha256`` (its bytes' SHA-256: a resumed run must read the same file),
      ``grasps`` (``B``) and ``num_contacts`` (``N``, the padded contact count);
    * ``rows-<first>.npz``, one per finished chunk, each written atomically once its
      chunk is done: ``rows`` (int64, the input indices of its grasps), ``digest`` (str,
      `rows_digest` of those rows' inputs and the run's `run_key`) and every
      [`Evaluation`][jaxgrasp.Evaluation] field for them (leading axis ``len(rows)``, contacts
      padded to ``N``; `chunk_layout`).

    A chunk file is complete or absent, so a run killed at any moment (even ``kill -9``)
    keeps every chunk finished before it. A damaged chunk file (truncated, arrays missing
    or of other shapes or dtypes, rows out of range or held by another chunk) is skipped
    by `load` and its rows are evaluated again (`skipped` says which); so is another
    run's chunk, one whose digest is not that of its rows' inputs and options in this
    run (a chunk copied from another dataset's or another version's checkpoint): it is
    recomputed, never merged. Recomputing, not refusing the resume: the run still ends
    with the results an uninterrupted one writes, and a stray file costs its chunk's time,
    not the rest of the run.

    ``inputs`` (name -> ``(B, ...)`` array, the dataset's grasp fields by row) and ``key``
    (`run_key`) are what the digest covers; ``jaxgrasp batch`` gives both
    (`jaxgrasp.cli._batch.batch_checkpoint`). Without ``inputs`` a digest covers the row
    numbers and ``key`` alone.

    No link is followed: the folder, its manifest and its chunks must be real folders and
    files (a link at the folder's path is refused, `OutputError`;
    a linked chunk is skipped), and only real files in it are ever deleted.
    """

    MANIFEST = "manifest.json"
    MANIFEST_LIMIT = 1 << 20
    """The most bytes a manifest may hold, read back."""

    def __init__(self, folder, source: str, source_sha256: str, grasps: int, num_contacts: int, *,
                 inputs: Mapping[str, np.ndarray] | None = None, key: str = ""):
        self.folder = Path(folder)
        self.inputs = dict(inputs or {})
        self.key = key
        self.manifest = {
            "format": BATCH_FORMAT,
            "source": str(source),
            "source_sha256": source_sha256,
            "grasps": int(grasps),
            "num_contacts": int(num_contacts),
        }
        self.skipped: list[str] = []
        """The chunk files the last `load` skipped, each ``NAME: reason``."""

    def check_folder(self) -> None:
        """Raise `OutputError` (one line) unless the folder is absent
        or a real folder (not a link, not a file)."""
        storage.refuse_link(self.folder, "a batch's finished chunks")
        if os.path.lexists(self.folder) and not self.folder.is_dir():
            raise storage.OutputError(
                f"{str(self.folder)!r} is not a folder; jaxgrasp keeps a batch's finished chunks there: remove it"
            )

    def exists(self) -> bool:
        """Whether the folder holds a checkpoint (its manifest, a real file)."""
        try:
            return stat.S_ISREG(os.lstat(self.folder / self.MANIFEST).st_mode)
        except OSError:
            return False

    def start(self) -> None:
        """Create the folder and its manifest (a fresh run)."""
        self.check_folder()
        self.folder.mkdir(exist_ok=True)
        self.check_folder()  # nothing put a link there meanwhile
        text = json.dumps(self.manifest, indent=1) + "\n"
        storage.write_file(self.folder / self.MANIFEST, text.encode())

    def check(self) -> None:
        """Raise ``ValueError`` (one line) unless the checkpoint on disk is of this run:
        same format, input bytes, number of grasps and padded contact count."""
        path = self.folder / self.MANIFEST
        try:
            have = json.loads(storage.read_own(path, self.MANIFEST_LIMIT).decode("utf-8"))
        except (OSError, ValueError, storage.OutputError) as exc:
            raise ValueError(f"{path}: not a readable checkpoint ({exc})") from None
        if not isinstance(have, dict) or have.get("format") != BATCH_FORMAT:
            if isinstance(have, dict) and str(have.get("format")).startswith("jaxgrasp-batch-partial-"):
                raise ValueError(f"{path}: a checkpoint of another jaxgrasp ({have['format']}, not {BATCH_FORMAT}): "
                                 "remove its folder to start afresh")
            raise ValueError(f"{path}: not a jaxgrasp batch checkpoint ({BATCH_FORMAT})")
        if have.get("source_sha256") != self.manifest["source_sha256"]:
            raise ValueError(
                f"{self.folder} was made from other input ({have.get('source')}, whose contents "
                f"differ from {self.manifest['source']}): remove it to start afresh"
            )
        for key in ("grasps", "num_contacts"):
            if have.get(key) != self.manifest[key]:
                raise ValueError(f"{path}: {key} {have.get(key)} differs from this run's {self.manifest[key]}")

    def open(self, resume: bool) -> tuple[np.ndarray, dict[str, np.ndarray], bool]:
        """``(rows, results, resumed)``: with ``resume`` and a checkpoint on disk, the rows
        it holds and their results (after `check`, whose ``ValueError`` it raises;
        damaged chunks skipped, `skipped`); otherwise a fresh checkpoint
        (`start`) and no rows. Stale temporary files of killed runs in the folder are
        removed first.

        Raises:
            CheckpointBusy: the folder holds an unfinished run and ``resume`` is false (an
                unfinished run's checkpoint is never overwritten silently).
            OutputError: the folder's path holds a link or a file (before anything is read).
        """
        self.check_folder()
        if self.folder.is_dir():
            storage.remove_stale_temps(self.folder)
        if self.exists():
            if not resume:
                raise CheckpointBusy(self.folder)
            self.check()
            return (*self.load(), True)
        self.start()
        return np.zeros(0, dtype=np.int64), {}, False

    def keeper(self, before: int, total: int):
        """``on_chunk_rows(rows, results)`` for
        `evaluate_dataset`: each finished chunk saved at once
        (`save_rows`), then `kept` told how many rows are kept (``before``
        from an earlier run, of ``total`` in the dataset)."""
        count = [before]

        def keep(rows: np.ndarray, results: Mapping[str, np.ndarray]) -> None:
            self.save_rows(rows, results)
            count[0] += len(rows)
            self.kept(count[0], total)

        return keep

    def kept(self, rows: int, total: int) -> None:
        """``rows`` of the dataset's ``total`` are kept in the folder. Here: nothing."""

    def chunk_files(self) -> list[Path]:
        """Every entry named like a chunk file (``rows-<first>.npz``), in order of its
        first row; links among them too (which `load` skips)."""
        try:
            names = [e.name for e in os.scandir(self.folder) if _CHUNK_NAME.fullmatch(e.name)]
        except OSError:
            return []
        return [self.folder / n for n in sorted(names)]

    def load(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Every finished row: ``(rows, results)``, ``rows`` the input indices (int64) and
        ``results`` each [`Evaluation`][jaxgrasp.Evaluation] field for them (empty when no
        chunk is finished).

        A chunk file that is damaged in any way (unreadable, a link, not a zip, arrays
        missing or unknown, shapes or dtypes other than `chunk_layout`'s for the
        manifest's contact count, rows out of range or held by an earlier chunk) or is
        another run's (its digest is not `rows_digest` of its rows here) is skipped, so
        its rows are evaluated again; `skipped` lists them with the reason.
        """
        seen = np.zeros(self.manifest["grasps"], dtype=bool)
        rows, parts, self.skipped = [], [], []
        for path in self.chunk_files():
            try:
                r, part = self._read_chunk(path, seen)
            except Exception as exc:  # noqa: BLE001 - any damage: skipped, its rows recomputed
                self.skipped.append(f"{path.name}: {_reason(exc)}")
                continue
            seen[r] = True
            rows.append(r)
            parts.append(part)
        if not rows:
            return np.zeros(0, dtype=np.int64), {}
        return np.concatenate(rows), {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def _read_chunk(self, path: Path, seen: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """A chunk file's ``(rows, results)``, checked against the manifest (``seen``: rows
        of earlier chunks); ``ValueError`` (or whatever reading raises) where damaged."""
        layout = chunk_layout(self.manifest["num_contacts"])
        total = self.manifest["grasps"]
        row_bytes = 8 + sum(int(np.prod(shape)) * dt.itemsize for shape, dt in layout.values())
        limit = total * row_bytes + _DIGEST_BYTES + (len(layout) + 2) * _NPY_HEADER_BYTES
        data = storage.read_own(path, limit)
        with zipfile.ZipFile(io.BytesIO(data)) as zf:  # compressed members: bound what they inflate to
            if sum(i.file_size for i in zf.infolist()) > limit:
                raise ValueError(f"its arrays would take more than {limit} bytes")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if set(z.files) != {"rows", "digest", *layout}:
                raise ValueError(f"arrays {sorted(set(z.files) ^ {'rows', 'digest', *layout})} missing or unknown")
            rows = np.asarray(z["rows"])
            digest = np.asarray(z["digest"])
            part = {k: np.asarray(z[k]) for k in layout}
        if rows.dtype != np.int64 or rows.ndim != 1 or rows.size == 0:
            raise ValueError(f"rows {rows.dtype} {rows.shape}, not a 1-D int64 list")
        if rows.min() < 0 or rows.max() >= total:
            raise ValueError(f"rows {rows.min()}..{rows.max()} outside 0..{total - 1}")
        if np.unique(rows).size != rows.size or seen[rows].any():
            raise ValueError("rows held twice")
        for k, (shape, dtype) in layout.items():
            if part[k].shape != (rows.size, *shape) or part[k].dtype != dtype:
                raise ValueError(f"{k} {part[k].dtype} {part[k].shape}, not {dtype} {(rows.size, *shape)}")
        if digest.shape != () or digest.dtype.kind != "U" or str(digest) != rows_digest(self.inputs, rows, self.key):
            raise ValueError("another run's chunk: its digest is not that of these rows' inputs and options "
                             "in this run")
        return rows, part

    def save_rows(self, rows: np.ndarray, results: Mapping[str, np.ndarray]) -> None:
        """Keep one finished chunk: input ``rows``, their ``results`` (by field) and the
        digest of what they were computed from (`rows_digest`), atomically."""
        rows = np.asarray(rows, dtype=np.int64)
        arrays = {"rows": rows, "digest": np.asarray(rows_digest(self.inputs, rows, self.key)),
                  **{k: np.asarray(v) for k, v in results.items()}}
        storage.write_file(self.folder / f"rows-{int(arrays['rows'][0]):09d}.npz", lambda fh: np.savez(fh, **arrays))

    def files(self) -> list[Path]:
        """Every file of the checkpoint, to remove once the final results are written: its
        chunk files and manifest, with the temporary files a killed run may have left
        (``*.tmp``: never complete). Real files only, and none where the folder is not a
        real folder: a link is never followed to delete what it points at."""
        try:
            self.check_folder()
        except storage.OutputError:
            return []
        found = self.chunk_files() + [self.folder / self.MANIFEST] + sorted(self.folder.glob("*" + storage.TEMP_SUFFIX))
        return [p for p in found if _is_real_file(p)]


def _is_real_file(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False
