"""The grid points a sweep has finished so far: the checkpoint ``sweep.partial.npz``.

``jaxgrasp sweep --out DIR`` rewrites ``DIR/sweep.partial.npz`` (atomically, see
:mod:`jaxgrasp.outputs`) after its chunks, and deletes it once the final
``sweep.npz``/``sweep.csv``/``sweep.png`` are in place; an interrupted sweep leaves it
behind with every point finished before the last checkpoint. Read it with
:meth:`PartialSweep.load`.

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
  :class:`~jaxgrasp.Grasp` (``Grasp.to_numpy()``), so that a resumed sweep can check it
  continues the same grasp.
* ``chunk_size`` (int64): the grid points per compiled batch.
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

import numpy as np

from .status import BoundaryKind, GraspStatus

__all__ = ["PartialSweep", "FORMAT", "RESULT_FIELDS"]

FORMAT = "jaxgrasp-sweep-partial-1"
"""The ``format`` entry of a checkpoint file (changes when its layout does)."""

RESULT_FIELDS = ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy")
"""The per-point result arrays, as in :class:`jaxgrasp.SweepResult`."""


@dataclasses.dataclass(frozen=True, eq=False)
class PartialSweep:
    """A sweep's grid with the points finished so far (SI units).

    Attributes:
        axes: parameter name -> 1-D float64 grid values, in grid order.
        done: bool array shaped like the grid; True where the results are final.
        results: result field (:data:`RESULT_FIELDS`) -> grid-shaped array; NaN (floats)
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
    ) -> "PartialSweep":
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
        by itself (the CLI writes it through :func:`jaxgrasp.outputs.write_file`)."""
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
    def load(cls, path) -> "PartialSweep":
        """Read a checkpoint file.

        Raises:
            ValueError: not a checkpoint of this format.
        """
        with np.load(path, allow_pickle=False) as z:
            if "format" not in z.files or str(z["format"]) != FORMAT:
                raise ValueError(f"{path}: not a jaxgrasp sweep checkpoint ({FORMAT})")
            names = [str(n) for n in z["axis_names"]]
            return cls(
                axes={n: np.array(z[f"axis_{n}"]) for n in names},
                done=np.array(z["done"]),
                results={f: np.array(z[f]) for f in RESULT_FIELDS},
                grasp={k[len("grasp_") :]: np.array(z[k]) for k in z.files if k.startswith("grasp_")},
                chunk_size=int(z["chunk_size"]),
            )
