"""Robust energy tolerance: the evaluation value of a grasp under uncertain friction,
stiffness, squeeze, placement, mass and gravity, by Monte Carlo through the engine.

::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(mass=0.2)
    r = jaxgrasp.robust(grasp, jaxgrasp.analysis.Uncertainty(friction=0.1), samples=64, seed=0)
    r.p_stable, r.p_stable_stderr, r.value_mean, r.quantiles   # -, -, J, (2,) J

Each grasp's ``S`` perturbed copies (`jaxgrasp.analysis._uncertainty`) are stacked
into one batched grasp with those of every other grasp of the same contact count and
evaluated by [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch]: one compiled evaluator for all samples of
all grasps of a contact count, cut into the engine's chunks. The nominal grasps (one
grasp is a list of one: no path of its own) are evaluated by the same runner in a batch
of their own with the samples' chunk, so by their samples' program; that program's
numbers equal [`jaxgrasp.evaluate`][jaxgrasp.evaluate]'s within rounding (the energies to about
``1e-15`` of themselves: ``tests/engine/test_single_vs_batch.py``).

The statistics of a grasp are over its samples whose evaluation settled (status
``stable``, ``unstable`` or ``infeasible``): ``p_stable`` is the fraction of them that
are stable, ``p_stable_stderr`` its binomial standard error ``sqrt(p (1 - p) / n)``,
``value_mean`` and the quantiles are over their values (J, 0 for a sample that is not
stable, eq. 1). A ``not_converged`` sample is left out and counted ([`RobustStatus`][jaxgrasp.analysis.RobustStatus]).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Sequence

import numpy as np

from jaxgrasp.analysis._limits import MAX_ROBUST_SAMPLES, ROBUST_SAMPLES_WHAT
from jaxgrasp.analysis._uncertainty import CLIP_SOURCES, Uncertainty, draw_normals, perturb
from jaxgrasp.base import Coded, json_floats, over_limit
from jaxgrasp.engine import BatchResult, evaluate_batch, evaluate_in_chunks, plan_chunks
from jaxgrasp.model import Grasp, GraspValueError, stack
from jaxgrasp.surface import MeshGrasp, Surface
from jaxgrasp.tolerance import EvaluateOptions, Evaluation, GraspStatus

__all__ = ["robust", "robust_batch", "perturbed", "RobustResult", "RobustBatch", "RobustStatus", "DEFAULT_QUANTILES",
           "quantile_name"]

DEFAULT_QUANTILES = (0.05, 0.5)
"""The quantile levels of the value that [`robust`][jaxgrasp.robust] reports by default (the 0.05 quantile and the median)."""

MESH_FACES = 256
"""A mesh's faces are padded to a power of two times this ([`jaxgrasp.surface.Surface.padded`][jaxgrasp.surface.Surface.padded]),
so that the closest-point search of meshes of similar size is compiled once."""

_SETTLED = (GraspStatus.STABLE, GraspStatus.UNSTABLE, GraspStatus.INFEASIBLE)


class RobustStatus(Coded):
    """What [`jaxgrasp.robust`][jaxgrasp.robust] could estimate for a grasp."""

    ESTIMATED = 0, "every sample's evaluation settled: the statistics are over all samples"
    PARTLY_CONVERGED = 1, (
        "some samples did not converge: the statistics are over the settled ones (see converged)"
    )
    NOT_CONVERGED = 2, "no sample's evaluation settled: no estimate (NaN)"
    INVALID = 3, "the grasp's input is invalid, so it was not evaluated (NaN)"


def quantile_name(level: float) -> str:
    """The name of a quantile's field and column: ``value_q05`` for 0.05, ``value_q50``,
    ``value_q2.5`` for 0.025."""
    pct = round(float(level) * 100.0, 10)
    return f"value_q{int(pct):02d}" if pct == int(pct) else f"value_q{pct:g}"


@dataclasses.dataclass(frozen=True, eq=False)
class RobustResult:
    """The robust evaluation of one grasp ([`jaxgrasp.robust`][jaxgrasp.robust]), SI units.

    Its [`value`][jaxgrasp.analysis.RobustResult.value] is the nominal (unperturbed)
    grasp's value, J, as [`jaxgrasp.evaluate`][jaxgrasp.evaluate] gives it; the statistics
    over the samples have names of their own (``value_mean``, ``quantiles``).

    Attributes:
        status: a [`RobustStatus`][jaxgrasp.analysis.RobustStatus] ([`status_name`][jaxgrasp.analysis.RobustResult.status_name] its name).
        p_stable: fraction of the settled samples that are stable (NaN without any).
        p_stable_stderr: its standard error ``sqrt(p (1 - p) / n)``, ``n`` settled samples.
        value_mean: mean value of the settled samples, J (0 for a sample that is not stable).
        quantile_levels: ``(Q,)`` the levels, default ``(0.05, 0.5)``.
        quantiles: ``(Q,)`` J, the value's quantiles over the settled samples (NumPy's
            linear interpolation).
        values: ``(S,)`` J, each sample's value (eq. 1).
        statuses: ``(S,)`` int, each sample's [`GraspStatus`][jaxgrasp.GraspStatus].
        converged: the settled samples ``n``.
        nominal: the [`Evaluation`][jaxgrasp.Evaluation] of the unperturbed grasp.
        clipped: sampled numbers clipped into their valid range, by field
            (``friction``, ``initial_deformation``, ``mass``).
        uncertainty: the [`Uncertainty`][jaxgrasp.analysis.Uncertainty] sampled.
        samples: ``S``.
        seed: the seed of the draws.
    """

    status: RobustStatus
    p_stable: float
    p_stable_stderr: float
    value_mean: float
    quantile_levels: tuple
    quantiles: np.ndarray
    values: np.ndarray
    statuses: np.ndarray
    converged: int
    nominal: Evaluation
    clipped: dict
    uncertainty: Uncertainty
    samples: int
    seed: int

    @property
    def status_name(self) -> str:
        """The name of `status` (``'estimated'``)."""
        return self.status.label

    @property
    def value(self) -> float:
        """The nominal grasp's evaluation value, J (``nominal.value``; NaN for an invalid
        grasp): the grasp's own value beside the statistics of its perturbed copies."""
        return float(np.asarray(self.nominal.value))

    def summary(self) -> str:
        """Two lines: the status and the nominal value, then the statistics over the
        settled samples (``n/a`` where there are none)."""
        num = lambda x, f: "n/a" if not np.isfinite(x) else format(x, f)  # noqa: E731
        qs = ", ".join(f"{quantile_name(q)[len('value_'):]} {num(v, '.6e')} J"
                       for q, v in zip(self.quantile_levels, self.quantiles))
        return (f"{self.status_name}: nominal value {num(self.value, '.6e')} J; {self.converged} of {self.samples} "
                f"samples settled (seed {self.seed})\n"
                f"p_stable {num(self.p_stable, '.4f')} +- {num(self.p_stable_stderr, '.4f')}, "
                f"value_mean {num(self.value_mean, '.6e')} J" + (f", {qs}" if qs else ""))

    def quantile(self, level: float) -> float:
        """The quantile of one of `quantile_levels`, J."""
        for q, v in zip(self.quantile_levels, self.quantiles):
            if abs(q - float(level)) < 1e-12:
                return float(v)
        raise KeyError(f"level {level} is not one of {self.quantile_levels}")

    def to_dict(self) -> dict[str, Any]:
        """The statistics as plain Python (JSON: NaN as ``None``): ``robust_status``,
        ``p_stable``, ``p_stable_stderr``, ``value_mean``, one ``value_qNN`` per level,
        ``samples``, ``converged``, ``seed``, ``uncertainty`` and ``clipped``; the
        per-sample arrays and the nominal evaluation (and so ``value``) are not in it.
        Its status is ``robust_status``, not ``status``, because ``jaxgrasp evaluate
        --robust --json`` writes these entries beside the nominal evaluation's own
        ``status`` and ``value``."""
        out = {
            "robust_status": self.status_name,
            "p_stable": json_floats(self.p_stable),
            "p_stable_stderr": json_floats(self.p_stable_stderr),
            "value_mean": json_floats(self.value_mean),
        }
        out.update({quantile_name(q): json_floats(v) for q, v in zip(self.quantile_levels, self.quantiles)})
        out.update(samples=self.samples, converged=self.converged, seed=self.seed,
                   uncertainty=self.uncertainty.to_dict(), clipped=dict(self.clipped))
        return out


@dataclasses.dataclass(frozen=True, eq=False)
class RobustBatch:
    """The robust evaluation of ``G`` grasps ([`jaxgrasp.robust_batch`][jaxgrasp.robust_batch]), in input
    order: the fields of [`RobustResult`][jaxgrasp.analysis.RobustResult] with a leading ``G`` axis; ``rb[i]`` is
    grasp ``i``'s [`RobustResult`][jaxgrasp.analysis.RobustResult].

    Its [`value`][jaxgrasp.analysis.RobustBatch.value] is ``(G,)`` the nominal grasps'
    values, J, as [`RobustResult.value`][jaxgrasp.analysis.RobustResult.value] is one.

    Attributes:
        status: ``(G,)`` [`RobustStatus`][jaxgrasp.analysis.RobustStatus] codes
            ([`status_names`][jaxgrasp.analysis.RobustBatch.status_names] their names).
        p_stable, p_stable_stderr, value_mean: ``(G,)`` (-, -, J).
        quantile_levels: ``(Q,)``; quantiles: ``(G, Q)`` J.
        values: ``(G, S)`` J; statuses: ``(G, S)`` [`GraspStatus`][jaxgrasp.GraspStatus] codes.
        converged: ``(G,)`` settled samples.
        nominal: the [`BatchResult`][jaxgrasp.BatchResult] of the unperturbed grasps.
        clipped: ``(G,)`` counts by field.
        uncertainty, samples, seed: as [`RobustResult`][jaxgrasp.analysis.RobustResult].
    """

    status: np.ndarray
    p_stable: np.ndarray
    p_stable_stderr: np.ndarray
    value_mean: np.ndarray
    quantile_levels: tuple
    quantiles: np.ndarray
    values: np.ndarray
    statuses: np.ndarray
    converged: np.ndarray
    nominal: BatchResult
    clipped: dict
    uncertainty: Uncertainty
    samples: int
    seed: int

    def __len__(self) -> int:
        return len(self.status)

    def __getitem__(self, i: int) -> RobustResult:
        """Grasp ``i``'s [`RobustResult`][jaxgrasp.analysis.RobustResult] (its nominal evaluation's contacts numbered as in the batch)."""
        return RobustResult(
            status=RobustStatus(int(self.status[i])), p_stable=float(self.p_stable[i]),
            p_stable_stderr=float(self.p_stable_stderr[i]), value_mean=float(self.value_mean[i]),
            quantile_levels=self.quantile_levels, quantiles=self.quantiles[i], values=self.values[i],
            statuses=self.statuses[i], converged=int(self.converged[i]), nominal=self.nominal[i],
            clipped={k: int(v[i]) for k, v in self.clipped.items()}, uncertainty=self.uncertainty,
            samples=self.samples, seed=self.seed,
        )

    @property
    def status_names(self) -> np.ndarray:
        """``(G,)`` the names of `status`."""
        return RobustStatus.names_of(self.status)

    @property
    def value(self) -> np.ndarray:
        """``(G,)`` J, the nominal grasps' evaluation values (``nominal.value``; NaN for an
        invalid grasp)."""
        return np.asarray(self.nominal.value)

    def summary(self) -> str:
        """Two lines: the grasps by status, then the best by ``value_mean`` (J) with its
        ``p_stable``."""
        counts = ", ".join(f"{k} {v}" for k, v in RobustStatus.count(self.status).items() if v)
        head = f"{len(self)} grasps x {self.samples} samples (seed {self.seed}): {counts}"
        best = int(self.rank()[0]) if len(self) else None
        if best is None or not np.isfinite(self.value_mean[best]):
            return head + "\nno estimate"
        return (head + f"\nbest by value_mean: grasp {best}, value_mean {float(self.value_mean[best]):.6e} J, "
                f"p_stable {float(self.p_stable[best]):.4f}, nominal value {float(self.value[best]):.6e} J")

    def to_dict(self) -> dict[str, Any]:
        """The statistics as plain Python (JSON: NaN as ``None``), one list entry per
        grasp in input order: ``status`` by name, ``value`` (the nominal values, J), the
        [`columns`][jaxgrasp.analysis.RobustBatch.columns] (``p_stable``,
        ``p_stable_stderr``, ``value_mean``, one ``value_qNN`` per level), ``converged``
        and ``clipped`` by field; then ``samples``, ``seed`` and ``uncertainty``. The
        per-sample arrays are not in it."""
        out: dict[str, Any] = {"status": self.status_names.tolist(), "value": json_floats(self.value)}
        out.update({k: json_floats(v) for k, v in self.columns().items()})
        out.update(converged=np.asarray(self.converged).tolist(),
                   clipped={k: np.asarray(v).tolist() for k, v in self.clipped.items()},
                   samples=self.samples, seed=self.seed, uncertainty=self.uncertainty.to_dict())
        return out

    def columns(self) -> dict[str, np.ndarray]:
        """``(G,)`` arrays by column name: ``p_stable``, ``p_stable_stderr``, ``value_mean``,
        one ``value_qNN`` per quantile level (the ``batch --robust`` columns)."""
        out = {"p_stable": self.p_stable, "p_stable_stderr": self.p_stable_stderr, "value_mean": self.value_mean}
        out.update({quantile_name(q): self.quantiles[:, j] for j, q in enumerate(self.quantile_levels)})
        return out

    def rank(self, by: str = "value_mean") -> np.ndarray:
        """Grasp indices, best first, by a column of [`columns`][jaxgrasp.analysis.RobustBatch.columns] (highest first; ties
        broken by ``value_mean``, then input order; NaN last), e.g. ``"p_stable"`` or
        ``"value_q05"``."""
        cols = self.columns()
        if by not in cols or by == "p_stable_stderr":
            raise GraspValueError(f"rank by must be one of {', '.join(k for k in cols if k != 'p_stable_stderr')}, got {by!r}")
        key = np.nan_to_num(np.asarray(cols[by], dtype=np.float64), nan=-np.inf)
        tie = np.nan_to_num(np.asarray(self.value_mean, dtype=np.float64), nan=-np.inf)
        return np.lexsort((np.arange(len(self)), -tie, -key))

    def __repr__(self) -> str:
        return f"RobustBatch({len(self)} grasps x {self.samples} samples; {self.uncertainty.to_spec()})"


# --------------------------------------------------------------------------- the entry points


def robust(grasp, uncertainty: Uncertainty, samples: int = 256, seed: int = 0, *,
           quantiles: Sequence[float] = DEFAULT_QUANTILES, options: EvaluateOptions = EvaluateOptions(),
           chunk_size: int | None = None, progress: Callable[[int, int], Any] | None = None):
    """The robust evaluation of a grasp: its value over ``samples`` perturbed copies.

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] or a [`MeshGrasp`][jaxgrasp.MeshGrasp] (its contact
            moves follow the mesh); or a list of them, or one batched grasp, which is
            [`robust_batch`][jaxgrasp.robust_batch].
        uncertainty: the [`Uncertainty`][jaxgrasp.analysis.Uncertainty] of each source (SI units).
        samples: perturbed copies per grasp, ``>= 2``.
        seed: the seed of the draws (the same seed, the same samples; see
            `jaxgrasp.analysis._uncertainty`).
        quantiles: levels in ``[0, 1]`` of the value's quantiles (default 0.05 and 0.5).
        options, chunk_size, progress: as [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] (of the samples).

    Returns:
        A [`RobustResult`][jaxgrasp.analysis.RobustResult] for one grasp; a [`RobustBatch`][jaxgrasp.analysis.RobustBatch] for a list or a
        batched grasp.

    Raises:
        GraspValueError: a bad grasp, uncertainty, ``samples``, ``seed`` or level; one line.
    """
    one = isinstance(grasp, MeshGrasp) or (isinstance(grasp, Grasp) and np.ndim(grasp.positions) == 2)
    out = robust_batch([grasp] if one else grasp, uncertainty, samples, seed, quantiles=quantiles,
                       options=options, chunk_size=chunk_size, progress=progress)
    return out[0] if one else out


def robust_batch(grasps, uncertainty: Uncertainty, samples: int = 256, seed: int = 0, *,
                 quantiles: Sequence[float] = DEFAULT_QUANTILES, options: EvaluateOptions = EvaluateOptions(),
                 chunk_size: int | None = None, progress: Callable[[int, int], Any] | None = None,
                 devices=None) -> RobustBatch:
    """The robust evaluation of many grasps: ``samples`` perturbed copies of each, every
    copy of every grasp of a contact count through one compiled evaluator.

    Args:
        grasps: a sequence of [`Grasp`][jaxgrasp.Grasp] or [`MeshGrasp`][jaxgrasp.MeshGrasp]
            (any contact counts), or one batched grasp (leading axis ``G``, a mask allowed,
            e.g. [`jaxgrasp.stack`][jaxgrasp.stack]).
        uncertainty, samples, seed, quantiles, options, chunk_size, progress: as
            [`robust`][jaxgrasp.robust]. Every grasp sees the same draws (common random numbers), so a
            grasp's result does not depend on the others in the list.
        devices: as [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] (default ``jax.devices()``, every
            host's after ``jax.distributed.initialize()``).

    Returns:
        A [`RobustBatch`][jaxgrasp.analysis.RobustBatch], grasps in input order.

    Raises:
        GraspValueError: as [`robust`][jaxgrasp.robust]; an invalid grasp names its index.
    """
    levels = _check_call(uncertainty, samples, seed, quantiles)
    groups, nominal_input = _groups(grasps)
    nominal = _nominal(nominal_input, options, chunk_size, samples, devices)
    g = len(nominal)
    values = np.empty((g, samples))
    statuses = np.empty((g, samples), dtype=np.int64)
    clipped = {name: np.zeros(g, dtype=np.int64) for name in CLIP_SOURCES}
    for rows, fields, project in groups:
        batch, clips = _perturbed(fields, project, uncertainty, samples, seed)
        res = evaluate_batch(batch, options=options, chunk_size=chunk_size, progress=progress, devices=devices)
        values[rows] = np.asarray(res.value).reshape(len(rows), samples)
        statuses[rows] = np.asarray(res.status).reshape(len(rows), samples)
        for name, c in clips.items():
            clipped[name][rows] = c
    return _summarise(values, statuses, levels, nominal, clipped, uncertainty, samples, seed)


def perturbed(grasp, uncertainty: Uncertainty, samples: int = 256, seed: int = 0) -> Grasp:
    """The perturbed copies of ``grasp`` that [`robust`][jaxgrasp.robust] evaluates, for a look at them.

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] or [`MeshGrasp`][jaxgrasp.MeshGrasp] (one grasp).
        uncertainty, samples, seed: as [`robust`][jaxgrasp.robust].

    Returns:
        One batched [`Grasp`][jaxgrasp.Grasp] of ``samples`` copies (``positions (S, N, 3)``
        m, model frame), sample ``k`` at index ``k``.
    """
    _check_call(uncertainty, samples, seed, ())
    if not (isinstance(grasp, MeshGrasp) or (isinstance(grasp, Grasp) and np.ndim(grasp.positions) == 2)):
        raise GraspValueError("perturbed needs one jaxgrasp.Grasp or MeshGrasp")
    _, fields, project = _groups([grasp])[0][0]
    return _perturbed(fields, project, uncertainty, samples, seed)[0]


def _perturbed(fields, project, uncertainty, samples, seed) -> tuple[Grasp, dict]:
    """A group's perturbed copies as one batched grasp (grasp-major rows) and the clip counts."""
    z = draw_normals(uncertainty, samples, seed, fields["positions"].shape[1])
    out, clips = perturb(fields, uncertainty, z, samples, project)
    active = out.pop("active", None)
    return Grasp(**out, active=active), clips


def _check_call(uncertainty, samples, seed, quantiles) -> tuple:
    """The quantile levels as a tuple, after checking every argument but the grasps."""
    if not isinstance(uncertainty, Uncertainty):
        raise GraspValueError(f"uncertainty must be a jaxgrasp.analysis.Uncertainty, got {type(uncertainty).__name__}")
    for name, x, low in (("samples", samples, 2), ("seed", seed, 0)):
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < low:
            raise GraspValueError(f"{name} must be an integer >= {low}, got {x!r}")
    problem = over_limit("samples", samples, MAX_ROBUST_SAMPLES, ROBUST_SAMPLES_WHAT)
    if problem:  # before a draw: 1e12 samples asked NumPy for 29 TiB
        raise GraspValueError(problem)
    try:
        levels = tuple(float(q) for q in quantiles)
    except (TypeError, ValueError):
        raise GraspValueError(f"quantiles must be numbers in [0, 1], got {quantiles!r}") from None
    if not all(0.0 <= q <= 1.0 for q in levels):
        raise GraspValueError(f"quantiles must be numbers in [0, 1], got {quantiles!r}")
    return levels


def _groups(grasps) -> tuple[list, Any]:
    """``([(rows, fields, project), ...], nominal_input)``: the grasps by contact count
    (a batched grasp is one group, its mask kept), each group's input rows, fields
    ([`to_numpy_batch`][jaxgrasp.Grasp.to_numpy_batch]) and mesh projection (``None`` without a
    mesh grasp); and what [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] takes for the nominal grasps."""
    if isinstance(grasps, Grasp) and np.ndim(grasps.positions) == 3:
        if grasps.active is not None and bool(np.all(grasps.active)):  # every contact there: the unmasked program
            grasps = grasps.replace(active=None)
        return [(np.arange(np.shape(grasps.positions)[0]), grasps.to_numpy_batch(), None)], grasps
    items = list(grasps) if isinstance(grasps, (list, tuple)) else None
    if not items or not all(isinstance(g, (Grasp, MeshGrasp)) for g in items):
        raise GraspValueError("robust needs a jaxgrasp.Grasp, a MeshGrasp, a non-empty list of them or a batched Grasp")
    plain = [g.grasp if isinstance(g, MeshGrasp) else g for g in items]
    plain = [g.compact() for g in plain]
    by_count: dict[int, list[int]] = {}
    for i, g in enumerate(plain):
        by_count.setdefault(g.num_contacts, []).append(i)
    groups = []
    for n, rows in sorted(by_count.items()):
        fields = stack([plain[i] for i in rows]).replace(active=None).to_numpy_batch()
        meshes = [items[i] if isinstance(items[i], MeshGrasp) else None for i in rows]
        project = None if all(m is None for m in meshes) else _mesh_projection(meshes, fields["normals"])
        groups.append((np.asarray(rows), fields, project))
    return groups, plain


def _nominal(grasps, options: EvaluateOptions, chunk_size, samples: int, devices=None) -> BatchResult:
    """The evaluation of the unperturbed grasps (a list or a batched grasp; one grasp is a
    list of one) by the batch runner in the chunks of the samples
    (`evaluate_in_chunks`), so that the nominal batch needs
    no program of its own and each nominal grasp is evaluated by the program of its
    samples (zero uncertainty: the samples' values are the nominal value bit for bit)."""
    g = np.shape(grasps.positions)[0] if isinstance(grasps, Grasp) else len(grasps)
    chunk = plan_chunks(g * samples, chunk_size, devices).chunk
    return evaluate_in_chunks(grasps, chunk, options=options, devices=devices)


def _mesh_projection(meshes: list, normals: np.ndarray) -> Callable:
    """``project(positions (G, S, N, 3)) -> (positions, normals)``: each mesh grasp's moved
    contacts onto its mesh (the closest surface point, the face's outward normal there,
    [`jaxgrasp.surface.Surface`][jaxgrasp.surface.Surface]); a plain grasp's kept, with its normals.
    Each distinct mesh's surface is built once (grasps of one object share it)."""
    surfaces = {id(mg.mesh): Surface.from_trimesh(mg.mesh, pad_to=MESH_FACES) for mg in meshes if mg is not None}

    def project(moved: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = moved.copy()
        nrm = np.broadcast_to(normals[:, None], moved.shape).copy()
        for k, mg in enumerate(meshes):
            if mg is None:
                continue
            hit = surfaces[id(mg.mesh)].closest(mg.to_mesh_frame(moved[k]))
            pos[k] = np.asarray(hit.point) - mg.center_of_mass
            nrm[k] = np.asarray(hit.normal)
        return pos, nrm

    return project


def _summarise(values, statuses, levels, nominal, clipped, uncertainty, samples, seed) -> RobustBatch:
    """The statistics of every grasp's samples (the module's doc), as a [`RobustBatch`][jaxgrasp.analysis.RobustBatch]."""
    g = values.shape[0]
    settled = np.isin(statuses, _SETTLED)
    n = settled.sum(axis=1)
    stable = ((statuses == GraspStatus.STABLE) & settled).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(n > 0, stable / np.maximum(n, 1), np.nan)
        stderr = np.where(n > 0, np.sqrt(p * (1.0 - p) / np.maximum(n, 1)), np.nan)
    mean = np.full(g, np.nan)
    qs = np.full((g, len(levels)), np.nan)
    for i in np.flatnonzero(n > 0):
        v = values[i][settled[i]]
        mean[i] = v.mean()
        qs[i] = np.quantile(v, levels) if levels else qs[i]
    status = np.where(n == samples, RobustStatus.ESTIMATED,
                      np.where(n > 0, RobustStatus.PARTLY_CONVERGED, RobustStatus.NOT_CONVERGED))
    return RobustBatch(
        status=status.astype(np.int64), p_stable=p, p_stable_stderr=stderr, value_mean=mean,
        quantile_levels=levels, quantiles=qs, values=values, statuses=statuses, converged=n,
        nominal=nominal, clipped=clipped, uncertainty=uncertainty, samples=int(samples), seed=int(seed),
    )
