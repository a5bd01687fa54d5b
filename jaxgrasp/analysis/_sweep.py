"""Parameter sweeps: evaluate one grasp over a Cartesian grid of its scalar parameters.

::

    import numpy as np, jaxgrasp
    result = jaxgrasp.sweep(
        jaxgrasp.presets.cube(),
        young_modulus=np.linspace(2e5, 1e6, 9),         # Pa
        initial_deformation=np.linspace(1e-3, 5e-3, 41),  # m, every contact at once
    )
    result.value.shape          # (9, 41), J
    result.to_csv("sweep.csv")  # one row per grid point, SI units in the column names

A sweep is a grid of grasps for the engine's one batch runner
(`run_batch`, shared with [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch]),
a source whose points are made a chunk at a time: the grid points are cut into chunks whose size is a bucket
(1, 4, 16 or 64 points per CPU device; `plan_chunks`), each
evaluated by the compiled pipeline; the last chunk is padded to the same size, so one
sweep compiles once, and a later sweep or batch of grasps with the same number of
contacts and options, in the same bucket, reuses that compilation. Memory is bounded by
the chunk size, not by the grid size: apart from the result arrays (5 numbers per grid
point) nothing grows with the grid, and no device buffer outlives its chunk.

Each chunk is sharded along its batch axis over all ``jax.devices()`` (a 1-D
``jax.sharding.Mesh`` with axis ``'batch'``; the chunk is rounded up to a multiple of the
device count), so one call uses every GPU of a machine, or every device of several hosts
after ``jax.distributed.initialize()``. Results are gathered to the host.

The compiled evaluator is memoised in the process and, where the caches are on
([`jaxgrasp.engine.enable_compilation_cache`][jaxgrasp.engine.enable_compilation_cache]; the CLI turns them on), kept in the executable
store on disk, so that a later process neither traces nor compiles it.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, Callable, Mapping

import jax
import numpy as np

from jaxgrasp import storage
from jaxgrasp.analysis._limits import MAX_GRID_POINTS
from jaxgrasp.engine import RETRY, SweepKeeper, check_chunk_size, plan_source, run_batch
from jaxgrasp.model import (
    FIELD,
    SWEEPABLE,
    BoundaryKind,
    Field,
    Grasp,
    GraspValueError,
    as_float_array,
    check_corners,
    check_grasp_inputs,
    format_value,
)
from jaxgrasp.tolerance import SUMMARY_FIELDS, EvaluateOptions, GraspStatus, SummaryNames

__all__ = [
    "sweep",
    "check_inputs",
    "grid_grasp",
    "SweepResult",
    "PARAMETERS",
    "column_name",
]

PARAMETERS: dict[str, Field] = {name: FIELD[name] for name in SWEEPABLE}
"""Sweepable parameters: name -> its `jaxgrasp.model._fields.Field` (``.unit`` SI unit,
``.per_contact``, ``.rule`` and ``.allows(x)`` its allowed range).

A per-contact parameter is set to the same value at every contact of a grid point."""

_RESULT_FIELDS = SUMMARY_FIELDS
_RESULT_UNITS = {"value": "J", "equilibrium_energy": "J"}


def column_name(name: str) -> str:
    """CSV column name with its SI unit: ``young_modulus_Pa``, ``mass_kg``, ``value_J``."""
    unit = PARAMETERS[name].unit if name in PARAMETERS else _RESULT_UNITS.get(name, "")
    return f"{name}_{unit}" if unit else name


# --------------------------------------------------------------------------- result


@dataclasses.dataclass(frozen=True, eq=False)
class SweepResult(SummaryNames):
    """Evaluation of a grasp over a parameter grid (SI units); a JAX pytree.

    Every array is shaped like the grid, ``(len(ax1), len(ax2), ...)``, in the order the
    axes were given to [`sweep`][jaxgrasp.sweep].

    Attributes:
        axes: dict parameter name -> 1-D float64 array of its grid values (SI units), in
            the order given.
        value: evaluation value ``Delta U_min``, J (0 where unstable or infeasible).
        status: [`GraspStatus`][jaxgrasp.GraspStatus] codes (``STABLE`` ...
            ``NOT_CONVERGED``; names ``GraspStatus.labels()``).
        limiting_kind: [`BoundaryKind`][jaxgrasp.model.BoundaryKind] codes (0 slip, 1 max_force),
            -1 none (names ``BoundaryKind.labels()``).
        limiting_contact: 0-based contact of the limiting boundary, -1 none.
        equilibrium_energy: ``min U`` over the equilibrium region, J.
        compile_seconds: time spent compiling the batched evaluator in this sweep (0 when
            a compilation was reused), s. Static (not a pytree leaf).
        run_seconds: time spent evaluating the chunks, s. Static (not a pytree leaf).
            Their sum is [`elapsed_s`][jaxgrasp.analysis.SweepResult.elapsed_s].
        devices: number of devices the batch was sharded over. Static (not a pytree leaf).

    As a pytree, the leaves are the axis arrays (in grid order) and the five result
    arrays; the axis names and timings are static.
    """

    axes: dict
    value: np.ndarray
    status: np.ndarray
    limiting_kind: np.ndarray
    limiting_contact: np.ndarray
    equilibrium_energy: np.ndarray
    compile_seconds: float = 0.0
    run_seconds: float = 0.0
    devices: int = 1

    # ---- shape and names
    @property
    def names(self) -> tuple[str, ...]:
        """Axis names, in grid order."""
        return tuple(self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape ``(len(ax1), len(ax2), ...)``."""
        return tuple(len(a) for a in self.axes.values())

    @property
    def size(self) -> int:
        """Number of grid points."""
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def elapsed_s(self) -> float:
        """Wall time of the evaluation, s: ``compile_seconds + run_seconds`` (derived from
        them, so a file that keeps the two keeps it)."""
        return float(self.compile_seconds) + float(self.run_seconds)

    def grid(self) -> dict[str, np.ndarray]:
        """Each axis' value at every grid point: dict name -> array shaped like the grid."""
        mesh = np.meshgrid(*self.axes.values(), indexing="ij") if self.axes else []
        return dict(zip(self.axes, mesh))

    def best(self) -> dict | None:
        """The grid point of highest value among trusted results (not ``not_converged``).

        Returns ``None`` when every point is not_converged, else a dict with ``index``
        (grid index tuple), ``value`` (J), ``status``, ``limiting_kind`` and
        ``limiting_contact`` (names / int) and the point's parameters by name (SI).
        """
        v = np.where(np.asarray(self.status) == GraspStatus.NOT_CONVERGED, -np.inf, np.asarray(self.value))
        if v.size == 0 or not np.any(np.isfinite(v)):
            return None
        idx = np.unravel_index(int(np.argmax(v)), v.shape)
        out = {"index": tuple(int(i) for i in idx), "value": float(self.value[idx])}
        out.update({name: float(ax[i]) for (name, ax), i in zip(self.axes.items(), idx)})
        out["status"] = GraspStatus(int(self.status[idx])).label
        out["limiting_kind"] = str(self.limiting_kind_names[idx])
        out["limiting_contact"] = int(self.limiting_contact[idx])
        return out

    def max_over(self, name: str) -> tuple["SweepResult", np.ndarray]:
        """Maximise the value over one axis (e.g. Fig. 7: best initial deformation per E).

        Not-converged points are skipped unless every point along the axis is one.

        Returns:
            ``(reduced, argmax)``: a [`SweepResult`][jaxgrasp.analysis.SweepResult] without axis ``name`` whose
            entries are those of the maximising grid point, and the maximising value of
            parameter ``name`` at every remaining grid point.
        """
        if name not in self.axes:
            raise KeyError(f"no axis {name!r}; axes: {', '.join(self.axes)}")
        k = list(self.axes).index(name)
        value = np.asarray(self.value)
        trusted = np.where(np.asarray(self.status) == GraspStatus.NOT_CONVERGED, -np.inf, value)
        none_trusted = np.all(np.isneginf(trusted), axis=k, keepdims=True)
        score = np.where(none_trusted, value, trusted)
        arg = np.argmax(score, axis=k)
        take = lambda a: np.take_along_axis(np.asarray(a), np.expand_dims(arg, k), axis=k).squeeze(k)
        axes = {n: a for n, a in self.axes.items() if n != name}
        reduced = SweepResult(
            axes=axes,
            **{f: take(getattr(self, f)) for f in _RESULT_FIELDS},
            compile_seconds=self.compile_seconds,
            run_seconds=self.run_seconds,
            devices=self.devices,
        )
        return reduced, np.asarray(self.axes[name])[arg]

    # ---- text and files
    def summary(self) -> str:
        """Three lines: the grid and its points by status, the best point (value, J, and
        its parameters, SI), then the timings."""
        axes = ", ".join(f"{n} [{len(a)}]" for n, a in self.axes.items()) or "no axes"
        counts = ", ".join(f"{k} {v}" for k, v in self.counts().items() if v) or "none"
        best = self.best()
        if best is None:
            where = "no trusted point"
        else:
            at = ", ".join(f"{n} = {best[n]:.6g}" for n in self.axes)
            where = f"best value {best['value']:.6e} J ({best['status']})" + (f" at {at}" if at else "")
        return f"sweep over {axes}: {self.size} points, {counts}\n{where}\n{self._timing_line()}"

    def to_dict(self) -> dict:
        """The sweep as plain Python (JSON-ready): ``axes`` (name -> list of grid values,
        SI), the five result arrays as nested lists shaped like the grid (``value`` and
        ``equilibrium_energy`` in J, ``status`` and ``limiting_kind`` by name,
        ``limiting_contact``), ``counts`` by status, ``best`` ([`best`][jaxgrasp.analysis.SweepResult.best],
        its ``index`` a list), ``compile_seconds``, ``run_seconds``, ``elapsed_s`` (s) and
        ``devices``."""
        best = self.best()
        if best is not None:
            best = {**best, "index": list(best["index"])}
        axes = {n: np.asarray(a, dtype=np.float64).tolist() for n, a in self.axes.items()}
        return {"axes": axes, **self._summary_dict(), "best": best}

    def to_csv(self, path, extra: Mapping[str, Any] | None = None) -> None:
        """Write a tidy CSV to ``path``: one row per grid point (C order: last axis fastest).

        ``path`` is written atomically (a temporary file renamed into place, see
        `jaxgrasp.storage`): a failure leaves the previous file as it was. A binary
        file object is written to directly.

        Columns: each axis with its SI unit (``young_modulus_Pa``, ``initial_deformation_m``,
        ``mass_kg``, ``friction``, ``max_force_N``, ``radius_m``), then ``value_J``,
        ``status`` (name), ``limiting_kind`` (``slip``/``max_force``/``none``),
        ``limiting_contact`` (-1 for none) and ``equilibrium_energy_J``, then a column per
        ``extra`` entry (name -> grid-shaped array, e.g. ``epsilon``). Floats are written
        with 17 significant digits (they read back exactly).
        """
        extra = {k: np.asarray(v).ravel() for k, v in (extra or {}).items()}
        cols = [column_name(n) for n in self.axes] + [
            column_name("value"),
            "status",
            "limiting_kind",
            "limiting_contact",
            column_name("equilibrium_energy"),
            *extra,
        ]
        flat = [g.ravel() for g in self.grid().values()]
        value = np.asarray(self.value).ravel()
        status = self.status_names.ravel()
        kind = self.limiting_kind_names.ravel()
        contact = np.asarray(self.limiting_contact).ravel()
        energy = np.asarray(self.equilibrium_energy).ravel()
        fmt = storage.csv_cell
        rows = (
            [fmt(g[i]) for g in flat]
            + [fmt(value[i]), status[i], kind[i], int(contact[i]), fmt(energy[i])]
            + [fmt(a[i]) for a in extra.values()]
            for i in range(value.size)
        )
        storage.write_to(path, storage.csv_content(cols, rows))

    def to_npz(self, path, extra: Mapping[str, Any] | None = None) -> None:
        """Write a ``.npz``: ``axis_names``, ``axis_<name>`` (1-D, SI), the grid-shaped
        result arrays, ``status_names``, ``kind_names``, the timings, ``devices`` and the
        ``extra`` arrays by name (e.g. ``epsilon``).

        Read it back with [`from_npz`][jaxgrasp.analysis.SweepResult.from_npz]. No pickled objects (``allow_pickle=False``).
        ``path`` gets the suffix ``.npz`` if it has none (as ``np.savez``) and is written
        atomically (see [`to_csv`][jaxgrasp.analysis.SweepResult.to_csv]); a binary file object is written to directly.
        """
        arrays = {
            "axis_names": np.asarray(self.names, dtype=str),
            "status_names": np.asarray(GraspStatus.labels(), dtype=str),
            "kind_names": np.asarray(BoundaryKind.labels(), dtype=str),
            "compile_seconds": np.float64(self.compile_seconds),
            "run_seconds": np.float64(self.run_seconds),
            "devices": np.int64(self.devices),
        }
        for n, a in self.axes.items():
            arrays[f"axis_{n}"] = np.asarray(a, dtype=np.float64)
        for f in _RESULT_FIELDS:
            arrays[f] = np.asarray(getattr(self, f))
        arrays.update({k: np.asarray(v) for k, v in (extra or {}).items()})
        if not hasattr(path, "write"):
            path = os.fspath(path)
            path = path if path.endswith(".npz") else path + ".npz"
        storage.write_to(path, lambda fh: np.savez(fh, **arrays))

    @classmethod
    def from_npz(cls, path) -> "SweepResult":
        """Read a file written by [`to_npz`][jaxgrasp.analysis.SweepResult.to_npz]."""
        with np.load(path, allow_pickle=False) as z:
            names = [str(n) for n in z["axis_names"]]
            return cls(
                axes={n: np.array(z[f"axis_{n}"]) for n in names},
                **{f: np.array(z[f]) for f in _RESULT_FIELDS},
                compile_seconds=float(z["compile_seconds"]),
                run_seconds=float(z["run_seconds"]),
                devices=int(z["devices"]) if "devices" in z.files else 1,
            )

    def __repr__(self) -> str:
        axes = ", ".join(f"{n}[{len(a)}]" for n, a in self.axes.items())
        counts = ", ".join(f"{k} {v}" for k, v in self.counts().items() if v)
        return f"SweepResult({axes or 'no axes'}; {counts})"


def _flatten(r: SweepResult):
    # axes as a tuple (not a dict, whose keys JAX would sort): the order is the grid's
    children = (tuple(r.axes.values()), *(getattr(r, f) for f in _RESULT_FIELDS))
    return children, (tuple(r.axes), r.compile_seconds, r.run_seconds, r.devices)


def _unflatten(aux, children):
    names, compile_seconds, run_seconds, devices = aux
    axes, *arrays = children
    return SweepResult(
        dict(zip(names, axes)),
        *arrays,
        compile_seconds=compile_seconds,
        run_seconds=run_seconds,
        devices=devices,
    )


jax.tree_util.register_pytree_node(SweepResult, _flatten, _unflatten)


# --------------------------------------------------------------------------- validation


def _check_axes(fields: dict[str, np.ndarray], axes: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Validate the axes of a grid over the grasp ``fields`` (SI units); one-line errors.

    Each axis is checked on its own (`_check_axis`); then every grid point must be a
    grasp [`jaxgrasp.evaluate`][jaxgrasp.evaluate] accepts. The rules of
    `check_grasp_inputs` are monotone in each swept
    parameter, so the grid's corners (each axis at its smallest or largest value, at most
    ``2^6 = 64`` grasps) break a rule wherever any grid point does
    (`check_corners` says why); nothing grid-sized is made.
    """
    out = {name: _check_axis(name, values) for name, values in axes.items()}
    ends = {name: (np.min(a), np.max(a)) for name, a in out.items()}
    check_corners(fields, ends, "sweep grid point")
    return out


def _check_axis(name: str, values: Any) -> np.ndarray:
    """One axis as a 1-D float64 array, finite and within its field's range."""
    if name not in PARAMETERS:
        valid = ", ".join(PARAMETERS)
        raise GraspValueError(f"cannot sweep unknown parameter {name!r}; valid parameters: {valid}")
    field = PARAMETERS[name]
    unit = f" {field.unit}" if field.unit else ""
    a = as_float_array(f"sweep axis {name}", values)
    if a.ndim > 1:
        raise GraspValueError(
            f"sweep axis {name} must be a number or a 1-D sequence of numbers, got shape {a.shape}"
        )
    a = np.atleast_1d(a).astype(np.float64)
    if a.size == 0:
        raise GraspValueError(f"sweep axis {name} is empty: give at least one value")
    for rule, ok in (("finite", np.isfinite), (field.rule, field.allows)):
        bad = np.flatnonzero(~ok(a))
        if bad.size:
            i = int(bad[0])
            raise GraspValueError(f"sweep axis {name}[{i}] = {format_value(a[i])}{unit} must be {rule}")
    return a


# --------------------------------------------------------------------------- sweep


def sweep(
    grasp: Grasp,
    /,
    *,
    options: EvaluateOptions = EvaluateOptions(),
    chunk_size: int | None = None,
    progress: Callable[[int, int], Any] | None = None,
    devices=None,
    on_chunk: Callable[[int, int, Mapping[str, np.ndarray]], Any] | None = None,
    checkpoint: str | os.PathLike | None = None,
    **axes,
) -> SweepResult:
    """Evaluate ``grasp`` at every point of the Cartesian grid of ``axes``.

    Args:
        grasp: the base [`Grasp`][jaxgrasp.Grasp] (SI units); parameters not swept keep
            its values.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] for every evaluation.
        chunk_size, progress, on_chunk, devices: as [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch], for
            the grid points in C order (last axis fastest); ``on_chunk``'s results are
            the `SUMMARY_FIELDS`.
        checkpoint: optional path of a file that keeps the finished points while the
            sweep runs (`SweepCheckpoint`, written
            atomically; ``jaxgrasp sweep`` keeps ``sweep.partial.npz`` in ``--out``).
        **axes: ``name=values`` for any of `PARAMETERS` (``young_modulus`` Pa,
            ``initial_deformation`` m, ``mass`` kg, ``friction``, ``max_force`` N,
            ``radius`` m); ``values`` is a number or a 1-D sequence. Per-contact
            parameters are set at every contact at once. The grid's axes follow the
            keyword order.

    Returns:
        A [`SweepResult`][jaxgrasp.analysis.SweepResult] whose arrays have shape ``(len(ax1), len(ax2), ...)``;
        every entry equals [`jaxgrasp.evaluate`][jaxgrasp.evaluate] of that grid point's grasp.

    Raises:
        GraspValueError: before anything is compiled, for an invalid base grasp, an unknown
            parameter name, an empty, non-numeric, non-finite or out-of-range axis, a grid
            point [`jaxgrasp.evaluate`][jaxgrasp.evaluate] rejects (`check_corners`),
            or a grid of more than `MAX_GRID_POINTS` points; the message is one line.
    """
    base, axes = _check_inputs(grasp, chunk_size, axes)
    grid = _Grid(_own_fields(grasp, base), axes)
    plan = plan_source(grid, chunk_size, devices)
    if checkpoint is not None:
        on_chunk = _also(SweepKeeper(checkpoint, grasp, axes, plan.chunk), on_chunk)
    flat: dict[str, np.ndarray] = {}  # the points' results, filled chunk by chunk (what on_chunk reads)
    reached = None if on_chunk is None else (lambda at, _res: on_chunk(int(at[0]), int(at[-1]) + 1, flat))
    # the points of a grid rarely need the settling stage: RETRY spares them it (engine._settling)
    run = run_batch(grid, plan, options, settle=RETRY, keep=_RESULT_FIELDS, progress=progress, on_chunk=reached,
                    results=flat, verb="sweeping", noun="point")
    return SweepResult(
        axes=dict(axes),
        **{f: flat[f].reshape(grid.shape) for f in _RESULT_FIELDS},
        compile_seconds=run.compile_seconds,
        run_seconds=run.run_seconds,
        devices=run.devices,
    )


@dataclasses.dataclass(frozen=True)
class _Grid:
    """The points of a grid as a `GraspSource`: point ``k``
    (C order, last axis fastest) is the grasp ``own`` (its own fields, SI units) with each
    axis of ``axes`` at its value there."""

    own: dict
    axes: dict

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.size for a in self.axes.values())

    @property
    def size(self) -> int:
        return int(math.prod(self.shape))

    @property
    def width(self) -> int:
        return int(self.own["positions"].shape[0])

    def counts(self) -> np.ndarray:
        return np.full(self.size, self.width)

    def gather(self, at: np.ndarray) -> dict[str, np.ndarray]:
        return _point_fields(self.own, self.axes, at)


def _also(first: Callable, then: Callable | None) -> Callable:
    """``on_chunk`` calling ``first``, then ``then`` (where given)."""
    if then is None:
        return first

    def both(start, stop, results):
        first(start, stop, results)
        then(start, stop, results)

    return both


def grid_grasp(grasp: Grasp, /, **axes) -> Grasp:
    """Every grid point of ``sweep(grasp, **axes)`` as one batched [`Grasp`][jaxgrasp.Grasp] (leading
    axis: the points in C order, last axis fastest), e.g. to compute another metric on the
    same grid (``jaxgrasp.epsilon(grid_grasp(...))``).

    Raises:
        GraspValueError: as [`sweep`][jaxgrasp.sweep] (one line).
    """
    base, checked = _check_inputs(grasp, None, axes)
    total = int(math.prod(a.size for a in checked.values()))
    return Grasp(**_point_fields(_own_fields(grasp, base), checked, np.arange(total)))


def _own_fields(grasp: Grasp, base: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The grasp's own values (not the validated copies, whose normals are re-normalised),
    so that every grid point is exactly the grasp evaluate() would see."""
    raw = grasp.to_numpy()
    return {k: np.broadcast_to(np.asarray(raw[k], dtype=np.float64), v.shape) for k, v in base.items()}


def check_inputs(grasp: Grasp, /, *, chunk_size: int | None = None, **axes) -> None:
    """Raise what [`sweep`][jaxgrasp.sweep] would raise for these arguments, computing nothing.

    For a caller that must reject bad input before it prepares anything else (the
    ``jaxgrasp sweep`` command checks its output folder only after this).

    Raises:
        GraspValueError: as [`sweep`][jaxgrasp.sweep] (one line).
    """
    _check_inputs(grasp, chunk_size, axes)


def _check_inputs(grasp, chunk_size, axes) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The validated base grasp's fields and the validated axes; one-line errors."""
    check_chunk_size(chunk_size)
    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"sweep needs a jaxgrasp.Grasp, got {type(grasp).__name__}")
    if grasp.active is not None:
        raise GraspValueError(
            "sweep needs a grasp without inactive contacts: sweep grasp.compact() (its active "
            "contacts, renumbered from 0)"
        )
    fields = grasp.to_numpy()
    try:
        base = check_grasp_inputs(**fields)
    except GraspValueError as exc:
        raise GraspValueError(f"base grasp: {exc}") from None
    checked = _check_axes(fields, axes)
    total = math.prod(a.size for a in checked.values())
    if total > MAX_GRID_POINTS:
        shape = " x ".join(f"{a.size:,}" for a in checked.values())
        raise GraspValueError(
            f"the sweep grid has {total:,} points ({shape}), more than MAX_GRID_POINTS = {MAX_GRID_POINTS:,} "
            "(its results must fit in memory); use fewer points per axis or split the sweep"
        )
    return base, checked


def _point_fields(own: dict, axes: dict, idx: np.ndarray) -> dict[str, np.ndarray]:
    """The [`Grasp`][jaxgrasp.Grasp] fields of grid points ``idx`` ``(K,)`` (C order), each with a
    leading axis ``K``."""
    shape = tuple(a.size for a in axes.values())
    n_contacts = own["positions"].shape[0]
    fields = {k: np.broadcast_to(v, (idx.size, *v.shape)) for k, v in own.items()}
    grid_idx = np.unravel_index(idx, shape) if axes else ()
    for (name, values), i_ax in zip(axes.items(), grid_idx):
        v = values[i_ax]
        if PARAMETERS[name].per_contact:
            v = np.broadcast_to(v[:, None], (idx.size, n_contacts))
        fields[name] = v
    return fields
