"""The result of [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch]: every grasp's evaluation, a ranking, tables.

A [`BatchResult`][jaxgrasp.BatchResult] holds one batched [`Evaluation`][jaxgrasp.Evaluation] (NumPy arrays
with a leading axis of ``B`` grasps, in input order) and what the batch adds: each
grasp's contact count and mask, the one-line error of an invalid grasp, timings.
Every Evaluation field reads directly (``res.value`` is ``res.evaluation.value``);
``res[i]`` is grasp ``i``'s own [`Evaluation`][jaxgrasp.Evaluation].

Files: [`BatchResult.to_csv`][jaxgrasp.BatchResult.to_csv] (one row per grasp: ``index``, ``num_contacts``,
``value_J``, ``status``, ``limiting_kind``, ``limiting_contact``,
``equilibrium_energy_J``, ``error``) and [`BatchResult.to_npz`][jaxgrasp.BatchResult.to_npz] (every array; read
back with [`BatchResult.from_npz`][jaxgrasp.BatchResult.from_npz]).
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Mapping

import jax
import numpy as np

from jaxgrasp import storage
from jaxgrasp.model import BoundaryKind
from jaxgrasp.tolerance import FIELDS, Evaluation, SummaryNames
from jaxgrasp.tolerance import GraspStatus

__all__ = ["BatchResult", "CSV_COLUMNS", "mark_invalid", "assemble"]

CSV_COLUMNS = (
    "index",
    "num_contacts",
    "value_J",
    "status",
    "limiting_kind",
    "limiting_contact",
    "equilibrium_energy_J",
    "error",
)
"""The columns of [`BatchResult.to_csv`][jaxgrasp.BatchResult.to_csv], in order."""

_RANK_GROUP = {GraspStatus.STABLE: 0, GraspStatus.NOT_CONVERGED: 2, GraspStatus.INVALID: 3}  # others: 1


def mark_invalid(results: dict[str, np.ndarray], rows) -> None:
    """Set the rows ``rows`` of [`Evaluation`][jaxgrasp.Evaluation] field arrays (by name, leading
    axis ``B``) to those of grasps that were not evaluated: NaN for floats, -1 for integer
    codes, ``status`` `INVALID`."""
    for a in results.values():
        a[rows] = np.nan if np.issubdtype(a.dtype, np.floating) else -1
    results["status"][rows] = GraspStatus.INVALID

def assemble(parts, total: int, invalid, active: np.ndarray, errors, *, compile_seconds: float = 0.0,
             run_seconds: float = 0.0, devices: int = 1) -> "BatchResult":
    """One [`BatchResult`][jaxgrasp.BatchResult] of ``total`` grasps from ``parts``, ``(rows, results)``
    pairs that together cover every valid row (``results``: each
    [`Evaluation`][jaxgrasp.Evaluation] field for those rows, leading axis ``len(rows)``); the
    rows ``invalid`` (indices or a mask) marked as not evaluated (`mark_invalid`).

    ``active``: ``(B, N)`` each grasp's contacts; ``errors``: each grasp's error or
    ``None``; the timings (s) and device count are those of the evaluation that made the
    newest part. A single part holding every row in order is taken as it is (its arrays
    become the result's, their invalid rows marked in place), so a large batch's
    results are held once.
    """
    arrays = {}
    whole = len(parts) == 1 and np.array_equal(parts[0][0], np.arange(total))
    for f in FIELDS:
        like = parts[0][1][f]
        if whole:  # one part of every row in order: its arrays are the result (no second copy)
            arrays[f] = np.asarray(like)
            continue
        arrays[f] = np.empty((total, *np.shape(like)[1:]), dtype=np.asarray(like).dtype)
        for rows, results in parts:
            arrays[f][rows] = results[f]
    mark_invalid(arrays, invalid)
    return BatchResult(
        evaluation=Evaluation(**arrays),
        num_contacts=active.sum(axis=1),
        active=active,
        errors=tuple(errors),
        compile_seconds=compile_seconds,
        run_seconds=run_seconds,
        devices=devices,
    )



@dataclasses.dataclass(frozen=True, eq=False)
class BatchResult(SummaryNames):
    """The evaluation of ``B`` grasps, in input order (SI units).

    Every [`Evaluation`][jaxgrasp.Evaluation] field is an attribute with a leading ``B`` axis
    (``value (B,)`` J, ``status (B,)``, ``boundary_energy (B, 2, N)`` J, ...; ``N`` is
    the batch's padded contact count, inactive contacts marked as in [`Evaluation`][jaxgrasp.Evaluation]).
    An invalid grasp (not evaluated) has status
    `INVALID`, NaN floats and -1 codes.

    Attributes:
        evaluation: the batched [`Evaluation`][jaxgrasp.Evaluation] (NumPy leaves).
        num_contacts: ``(B,)`` active contacts of each grasp (0 for an invalid one).
        active: ``(B, N)`` bool, the contacts each grasp has (its others are padding).
        errors: ``B`` entries: ``None``, or the one-line reason a grasp is invalid.
        compile_seconds: time spent compiling (0 when a compilation was reused), s.
        run_seconds: time spent evaluating the chunks, s. Their sum is
            [`elapsed_s`][jaxgrasp.BatchResult.elapsed_s].
        devices: number of devices the batch was sharded over.
    """

    evaluation: Evaluation
    num_contacts: np.ndarray
    active: np.ndarray
    errors: tuple
    compile_seconds: float = 0.0
    run_seconds: float = 0.0
    devices: int = 1

    def __getattr__(self, name: str) -> Any:
        if name in FIELDS:  # only reached for names that are not attributes of self
            return getattr(self.__dict__["evaluation"], name)
        raise AttributeError(f"'BatchResult' object has no attribute {name!r}")

    def __len__(self) -> int:
        return len(self.errors)

    @property
    def elapsed_s(self) -> float:
        """Wall time of the evaluation, s: ``compile_seconds + run_seconds`` (derived from
        them, so a file that keeps the two keeps it)."""
        return float(self.compile_seconds) + float(self.run_seconds)

    def __getitem__(self, i: int) -> Evaluation:
        """Grasp ``i``'s [`Evaluation`][jaxgrasp.Evaluation] (contacts numbered as in the batch)."""
        return jax.tree_util.tree_map(lambda a: a[i], self.evaluation)

    # ---- ranking
    def rank(self) -> np.ndarray:
        """Grasp indices, best first: stable grasps by value (highest first), then
        unstable and infeasible ones (value 0), then not_converged ones (untrusted) by
        value, then invalid ones; ties keep input order."""
        status = np.asarray(self.status)
        group = np.select([status == s for s in _RANK_GROUP], list(_RANK_GROUP.values()), default=1)
        value = np.nan_to_num(np.asarray(self.value, dtype=np.float64), nan=-np.inf)
        return np.lexsort((np.arange(len(self)), -value, group))

    # ---- text, tables and files
    def summary(self) -> str:
        """Two lines: the grasps by status and the best one's value (J), then the timings."""
        counts = ", ".join(f"{k} {v}" for k, v in self.counts().items() if v) or "none"
        order = self.rank()
        best = ""
        if len(order) and int(self.status[order[0]]) == GraspStatus.STABLE:
            best = f"; best value {float(self.value[order[0]]):.6e} J (grasp {int(order[0])})"
        return f"{len(self)} grasps: {counts}{best}\n{self._timing_line()}"

    def to_dict(self) -> dict:
        """The batch as plain Python (JSON-ready): per grasp, in input order, ``value`` and
        ``equilibrium_energy`` (J; ``None`` for an invalid grasp), ``status`` and
        ``limiting_kind`` by name, ``limiting_contact``, ``num_contacts`` and ``errors``
        (``None`` for a valid grasp); then ``counts`` by status, ``compile_seconds``,
        ``run_seconds``, ``elapsed_s`` (s) and ``devices``. The columns of
        [`to_csv`][jaxgrasp.BatchResult.to_csv] as lists; the per-boundary arrays are in
        [`to_npz`][jaxgrasp.BatchResult.to_npz]."""
        out = self._summary_dict()
        out.update(num_contacts=np.asarray(self.num_contacts).tolist(), errors=list(self.errors))
        return out

    def rows(self, extra: Mapping[str, Any] | None = None) -> list[list]:
        """The rows of [`to_csv`][jaxgrasp.BatchResult.to_csv] (`CSV_COLUMNS`, then the ``extra`` columns), in
        input order; an invalid grasp's numbers are empty strings."""
        return list(self._rows(extra))

    def _rows(self, extra: Mapping[str, Any] | None = None):
        """The rows of [`rows`][jaxgrasp.BatchResult.rows], one at a time (a table of a million grasps is never
        held as Python objects at once)."""
        value, energy = np.asarray(self.value), np.asarray(self.equilibrium_energy)
        status, kind = self.status_names, self.limiting_kind_names  # object arrays of shared names
        contact, count = np.asarray(self.limiting_contact), np.asarray(self.num_contacts)
        extra = [np.asarray(a) for a in (extra or {}).values()]
        fmt = storage.csv_cell
        for i in range(len(self)):
            yield ([i, int(count[i]), fmt(value[i]), status[i], kind[i], int(contact[i]), fmt(energy[i]),
                    self.errors[i] or ""] + [fmt(a[i]) for a in extra])

    def to_csv(self, path, extra: Mapping[str, Any] | None = None) -> None:
        """Write one row per grasp, in input order (`CSV_COLUMNS`): ``value_J`` and
        ``equilibrium_energy_J`` with 17 significant digits (empty for an invalid grasp),
        ``status`` and ``limiting_kind`` by name, ``limiting_contact`` (-1 none) and
        ``error`` (empty for a valid grasp); then a column per ``extra`` entry (name ->
        ``(B,)`` array, e.g. ``epsilon``). Atomic for a path; a binary file object is
        written to directly."""
        storage.write_to(path, storage.csv_content(CSV_COLUMNS + tuple(extra or ()), self._rows(extra)))

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array of [`to_npz`][jaxgrasp.BatchResult.to_npz], by name."""
        out = {f: np.asarray(getattr(self.evaluation, f)) for f in FIELDS}
        out.update(
            num_contacts=np.asarray(self.num_contacts, dtype=np.int64),
            active=np.asarray(self.active, dtype=bool),
            error=np.asarray([e or "" for e in self.errors], dtype=str),
            status_names=np.asarray(GraspStatus.labels(), dtype=str),
            kind_names=np.asarray(BoundaryKind.labels(), dtype=str),
            compile_seconds=np.float64(self.compile_seconds),
            run_seconds=np.float64(self.run_seconds),
            devices=np.int64(self.devices),
        )
        return out

    def to_npz(self, path, extra: Mapping[str, Any] | None = None) -> None:
        """Write a ``.npz`` with every [`Evaluation`][jaxgrasp.Evaluation] field (leading ``B``),
        ``num_contacts``, ``active``, ``error`` (str, empty for a valid grasp),
        ``status_names``, ``kind_names``, the timings, ``devices`` and the ``extra``
        arrays by name; no pickled objects. Atomic for a path; read it back with
        [`from_npz`][jaxgrasp.BatchResult.from_npz]."""
        arrays = self.arrays() | {k: np.asarray(v) for k, v in (extra or {}).items()}
        storage.write_to(path, lambda fh: np.savez(fh, **arrays))

    @classmethod
    def from_arrays(cls, z: Mapping[str, np.ndarray]) -> "BatchResult":
        """From the arrays of [`arrays`][jaxgrasp.BatchResult.arrays] (e.g. an open ``np.load``)."""
        return cls(
            evaluation=Evaluation(**{f: np.array(z[f]) for f in FIELDS}),
            num_contacts=np.array(z["num_contacts"]),
            active=np.array(z["active"]),
            errors=tuple(str(e) or None for e in z["error"]),
            compile_seconds=float(z["compile_seconds"]),
            run_seconds=float(z["run_seconds"]),
            devices=int(z["devices"]),
        )

    @classmethod
    def from_npz(cls, path: str | os.PathLike) -> "BatchResult":
        """Read a file written by [`to_npz`][jaxgrasp.BatchResult.to_npz]."""
        with np.load(path, allow_pickle=False) as z:
            return cls.from_arrays(z)

    def __repr__(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in self.counts().items() if v)
        return f"BatchResult({len(self)} grasps; {counts})"
