"""The result of [`jaxgrasp.evaluate`][jaxgrasp.evaluate]: a pytree of named arrays, in SI units."""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np

from jaxgrasp.base import json_floats
from jaxgrasp.model import NO_BOUNDARY, BoundaryKind, Constraint
from jaxgrasp.solver import LaneStatus
from jaxgrasp.tolerance._status import GraspStatus

__all__ = [
    "Evaluation",
    "SummaryNames",
    "SUMMARY_FIELDS",
    "FIELDS",
    "EVALUATION_TREE",
    "STATUS_NAMES",
    "STABLE",
    "UNSTABLE",
    "INFEASIBLE",
    "NOT_CONVERGED",
    "INVALID",
]

STABLE = GraspStatus.STABLE
UNSTABLE = GraspStatus.UNSTABLE
INFEASIBLE = GraspStatus.INFEASIBLE
NOT_CONVERGED = GraspStatus.NOT_CONVERGED
INVALID = GraspStatus.INVALID  # a dataset row that was not evaluated; evaluate() never gives it

STATUS_NAMES = GraspStatus.labels()
"""Grasp status names, indexed by the [`GraspStatus`][jaxgrasp.GraspStatus] codes
(``GraspStatus.labels()``)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Evaluation:
    """Energy-tolerance evaluation of one grasp (SI units; add leading axes under ``vmap``).

    ``N`` is the number of contacts; every ``(2, N, ...)`` array is indexed
    ``[kind, contact]`` by [`BoundaryKind`][jaxgrasp.model.BoundaryKind]: 0 = ``slip`` (eq. 20),
    1 = ``max_force`` (eq. 21).

    Attributes:
        value: ``()`` evaluation value ``Delta U_min`` of eq. 1, J: the least energy that
            brings the object from its equilibrium to a boundary of the equilibrium region.
            0 when ``status`` is unstable or infeasible.
        status: ``()`` int, a [`GraspStatus`][jaxgrasp.GraspStatus] code: ``STABLE``,
            ``UNSTABLE``, ``INFEASIBLE`` or ``NOT_CONVERGED`` (names:
            ``GraspStatus.labels()``, or [`status_name`][jaxgrasp.Evaluation.status_name],
            [`status_names`][jaxgrasp.Evaluation.status_names] under ``vmap``). An integer
            array, not a [`GraspStatus`][jaxgrasp.GraspStatus] member, so that it passes
            through ``jit`` and ``vmap``.
        limiting_kind: ``()`` int, [`BoundaryKind`][jaxgrasp.model.BoundaryKind] of the boundary
            that sets ``value`` (0 slip, 1 max_force), -1 (``NO_BOUNDARY``) when there is none.
        limiting_contact: ``()`` int, 0-based contact of that boundary, -1 when none.
        equilibrium_energy: ``()`` J, ``min U`` over the equilibrium region (energy zero
            at the initial grasping state's gravitational potential).
        equilibrium_translation: ``(3,)`` m, object translation at the equilibrium.
        equilibrium_rotation: ``(3,)`` rad, rotation vector at the equilibrium.
        boundary_energy: ``(2, N)`` J, minimum energy on each boundary; ``+inf`` where the
            boundary cannot be reached (``boundary_status`` infeasible).
        boundary_translation: ``(2, N, 3)`` m, pose of each boundary minimum (the
            equilibrium pose where the boundary cannot be reached).
        boundary_rotation: ``(2, N, 3)`` rad, likewise.
        boundary_status: ``(2, N)`` int, [`LaneStatus`][jaxgrasp.solver.LaneStatus] of each
            boundary problem (converged; infeasible = unreachable; not converged; no start
            because the equilibrium problem did not converge).
        equilibrium_status: ``()`` int, [`LaneStatus`][jaxgrasp.solver.LaneStatus] of the equilibrium
            problem.
        equilibrium_margins: ``(3, N)`` scaled constraint margins at the equilibrium (or,
            for an infeasible grasp, at the least-violating pose found), rows: contact
            kept ``d / dr``, no slip, force below its limit; ``>= 0`` where satisfied
            (`jaxgrasp.model.constraint_margins`).
        kkt: ``(1 + 2N, 3)`` KKT residuals (stationarity, feasibility, complementarity,
            in the solver's scaled units) of the equilibrium problem (row 0) and of the
            kept start of each boundary problem (rows ``1 + kind * N + contact``).
        steps: ``(1 + 2N,)`` solver steps of those same lanes (0 for a boundary the
            equilibrium lies on: its minimiser is the equilibrium, not solved again).
    """

    value: jax.Array | np.ndarray
    status: jax.Array | np.ndarray
    limiting_kind: jax.Array | np.ndarray
    limiting_contact: jax.Array | np.ndarray
    equilibrium_energy: jax.Array | np.ndarray
    equilibrium_translation: jax.Array | np.ndarray
    equilibrium_rotation: jax.Array | np.ndarray
    boundary_energy: jax.Array | np.ndarray
    boundary_translation: jax.Array | np.ndarray
    boundary_rotation: jax.Array | np.ndarray
    boundary_status: jax.Array | np.ndarray
    equilibrium_status: jax.Array | np.ndarray
    equilibrium_margins: jax.Array | np.ndarray
    kkt: jax.Array | np.ndarray
    steps: jax.Array | np.ndarray

    @property
    def status_name(self) -> str:
        """Name of ``status`` (for an unbatched, concrete result): ``'stable'`` etc.

        Raises:
            ValueError: a batched result (``status`` has a shape); its names are
                ``jaxgrasp.GraspStatus.names_of(result.status)``.
        """
        shape = np.shape(self.status)
        if shape != ():
            raise ValueError(
                f"status_name is one grasp's result, but status has shape {shape}: index the "
                "batched result first, or use jaxgrasp.GraspStatus.names_of(result.status)"
            )
        return GraspStatus(int(self.status)).label

    @property
    def status_names(self) -> np.ndarray:
        """``status`` as an array of names (``'stable'``, ...), same shape: a batched
        result's (under ``vmap``) as well as one grasp's (a ``()`` array)."""
        return GraspStatus.names_of(self.status)

    def tolerates(self, kinetic_energy, potential_energy=None):
        """Stable-grasp condition with kinetic energy, eq. 2: ``U + K < min U + value``.

        Args:
            kinetic_energy: the object's kinetic energy ``K``, J, ``>= 0`` and finite
                (a number or an array, broadcast against the result).
            potential_energy: its current potential energy ``U``, J, finite (default: the
                equilibrium energy, i.e. the object passes the equilibrium pose).

        Returns:
            Boolean array: ``True`` where no fingertip can slip or be overloaded.
            Always ``False`` for an unstable, infeasible or not-converged grasp.

        Raises:
            ValueError: a concrete ``kinetic_energy`` that is negative or not finite, or
                a ``potential_energy`` that is not finite (traced values are not checked).
        """
        _check_energy("kinetic_energy", kinetic_energy, nonnegative=True)
        if potential_energy is not None:
            _check_energy("potential_energy", potential_energy, nonnegative=False)
        u = self.equilibrium_energy if potential_energy is None else potential_energy
        ok = (u + kinetic_energy) < (self.equilibrium_energy + self.value)
        return ok & (self.status == STABLE)

    def explain(self, tol: float = 1e-8) -> str:
        """One or two sentences on why the grasp got its status (unbatched, concrete result).

        Uses ``status``, the limiting boundary, ``equilibrium_margins`` (rows: contact kept
        ``d/dr``, no slip, force below its limit; ``>= 0`` where satisfied) and the
        boundary statuses. ``tol`` is the margin at or below which a constraint counts as
        active (the evaluator's ``boundary_tol``). Examples::

            stable: 0.0002638 J must be added to make a fingertip fail; limited by slip of contact 0.
            infeasible: no pose satisfies every constraint; at the least-violating pose found the
            normal force of contact 0 exceeds its limit (force margin -0.023).
        """
        a = jax.tree_util.tree_map(np.asarray, self)
        if a.value.ndim != 0:
            raise ValueError("explain() takes one grasp's result; index a batched result first")
        return _explain(a, tol)

    def summary(self) -> str:
        """Two lines on an unbatched, concrete result: the status, the value (J) and the
        limiting boundary, then [`explain`][jaxgrasp.Evaluation.explain]'s sentence.

        Raises:
            ValueError: a batched result.
        """
        a = jax.tree_util.tree_map(np.asarray, self)
        if a.value.ndim != 0:
            raise ValueError("summary() takes one grasp's result; index a batched result first")
        kind = int(a.limiting_kind)
        limit = (f"limited by {_boundary_phrase(kind, int(a.limiting_contact))}" if kind != NO_BOUNDARY
                 else "no limiting boundary")
        head = f"{GraspStatus(int(a.status)).label}: value {float(a.value):.6e} J; {limit}"
        return head + "\n" + _explain(a, 1e-8)

    def to_dict(self) -> dict:
        """A JSON-ready summary of an unbatched result (``None`` for unreachable boundaries,
        and for the numbers and codes of an ``invalid`` grasp, a batch's row never evaluated).

        Each entry of ``boundaries`` gives the boundary's minimum energy twice, in J:
        ``energy``, absolute (on the scale of ``equilibrium_energy``), and
        ``energy_above_equilibrium``, ``energy - equilibrium_energy``: the energy that
        brings the object from its equilibrium to that boundary, ``>= 0`` (round-off
        below 0 is reported as 0); ``value`` is the least of them (hard minimum).

        Raises:
            ValueError: a batched result.
        """
        a = jax.tree_util.tree_map(np.asarray, self)
        if a.value.ndim != 0:
            raise ValueError("to_dict() takes one grasp's result; index a batched result first")
        n = a.boundary_energy.shape[-1]
        above = _energies_above_equilibrium(a)
        boundaries = []
        for j in range(n):
            for kind in BoundaryKind:
                e = float(a.boundary_energy[kind, j])
                boundaries.append(
                    {
                        "kind": kind.label,
                        "contact": j,
                        "energy": e if math.isfinite(e) else None,
                        "energy_above_equilibrium": float(above[kind, j]) if math.isfinite(e) else None,
                        "status": _lane_label(int(a.boundary_status[kind, j])),
                        "translation": json_floats(a.boundary_translation[kind, j]),
                        "rotation": json_floats(a.boundary_rotation[kind, j]),
                    }
                )
        kind = int(a.limiting_kind)
        return {
            "value": json_floats(a.value),
            "status": GraspStatus(int(a.status)).label,
            "equilibrium_energy": json_floats(a.equilibrium_energy),
            "equilibrium_translation": json_floats(a.equilibrium_translation),
            "equilibrium_rotation": json_floats(a.equilibrium_rotation),
            "limiting": (
                {"kind": BoundaryKind(kind).label, "contact": int(a.limiting_contact)}
                if kind != NO_BOUNDARY
                else None
            ),
            "boundaries": boundaries,
            "explanation": _explain(a, 1e-8),
            "units": {
                "energy": "J",
                "energy_above_equilibrium": "J",
                "translation": "m",
                "rotation": "rad (rotation vector)",
            },
        }


FIELDS = tuple(f.name for f in dataclasses.fields(Evaluation))
"""Every array of an [`Evaluation`][jaxgrasp.Evaluation], in field order."""

EVALUATION_TREE = jax.tree_util.tree_structure(Evaluation(*(0,) * len(FIELDS)))
"""The pytree structure of an [`Evaluation`][jaxgrasp.Evaluation] (it depends on no shape): to rebuild one
from its leaves, or to declare a compiled function's output tree."""

SUMMARY_FIELDS = ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy")
"""The five numbers that summarise a grasp's evaluation (the columns of sweep and batch
tables): value (J), status, limiting kind and contact, equilibrium energy (J)."""


class SummaryNames:
    """Names and counts of the codes of a result with ``status`` and ``limiting_kind``
    arrays of any shape ([`jaxgrasp.analysis.SweepResult`][jaxgrasp.analysis.SweepResult], [`jaxgrasp.BatchResult`][jaxgrasp.BatchResult]),
    and the entries and timing line of its ``to_dict`` and ``summary``."""

    @property
    def status_names(self) -> np.ndarray:
        """``status`` as an array of names (``'stable'``, ..., ``'invalid'``), same shape."""
        return GraspStatus.names_of(self.status)

    @property
    def limiting_kind_names(self) -> np.ndarray:
        """``limiting_kind`` as an array of names (``'slip'``, ``'max_force'``, ``'none'``)."""
        return BoundaryKind.names_of(self.limiting_kind)

    def counts(self) -> dict[str, int]:
        """Number of entries of each status, by name."""
        return GraspStatus.count(self.status)

    def _summary_dict(self) -> dict:
        """The five summary arrays (`SUMMARY_FIELDS`) as nested lists, codes by name and
        floats ``None`` where not finite, then ``counts``, the timings (s) and ``devices``."""
        return {
            "value": json_floats(self.value),
            "status": self.status_names.tolist(),
            "limiting_kind": self.limiting_kind_names.tolist(),
            "limiting_contact": np.asarray(self.limiting_contact).tolist(),
            "equilibrium_energy": json_floats(self.equilibrium_energy),
            "counts": self.counts(),
            "compile_seconds": float(self.compile_seconds),
            "run_seconds": float(self.run_seconds),
            "elapsed_s": self.elapsed_s,
            "devices": int(self.devices),
        }

    def _timing_line(self) -> str:
        """The timings' line of ``summary``: compile, run and elapsed seconds, and the devices."""
        devices = f"{self.devices} device{'s' if self.devices != 1 else ''}"
        return (f"compile {self.compile_seconds:.1f} s, run {self.run_seconds:.1f} s "
                f"(elapsed {self.elapsed_s:.1f} s) on {devices}")


def _lane_label(code: int) -> str | None:
    """A [`LaneStatus`][jaxgrasp.solver.LaneStatus] code's name; ``None`` for -1 (an invalid grasp's)."""
    return LaneStatus(code).label if code >= 0 else None


def _check_energy(name: str, value, nonnegative: bool) -> None:
    """A concrete energy argument, J, must be finite (and ``>= 0`` where asked)."""
    if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value)):
        return
    arr = np.asarray(value, dtype=np.float64)
    bad = ~np.isfinite(arr) | ((arr < 0.0) if nonnegative else False)
    if np.any(bad):
        x = float(arr.reshape(-1)[int(np.flatnonzero(bad)[0])])
        rule = "finite and >= 0 (an energy, J)" if nonnegative else "finite (an energy, J)"
        raise ValueError(f"{name} = {x:g} J must be {rule}")


_ROUND_OFF = 1e-8
"""Relative tolerance (of the result's energy scale) within which a boundary energy below
the equilibrium energy is round-off: the evaluator's default ``boundary_tol``."""


def _energies_above_equilibrium(a) -> np.ndarray:
    """``(2, N)`` ``boundary_energy - equilibrium_energy``, J, of a NumPy-leaved unbatched
    result: ``>= 0``, anything below 0 set to 0, ``nan`` where a boundary is unreachable.

    Below 0 by round-off: a fingertip released at the equilibrium has an energy of
    round-off size. Below 0 by more (`_below_equilibrium`): the equilibrium the
    solver found is a local minimum of the region and a boundary point lies lower, which
    the verdict calls unstable (no energy is needed to reach that boundary) and
    [`Evaluation.explain`][jaxgrasp.Evaluation.explain] says so.
    """
    be = np.asarray(a.boundary_energy, dtype=np.float64)
    finite = np.isfinite(be)
    above = np.where(finite, be - float(a.equilibrium_energy), np.nan)
    return np.where(finite, np.maximum(above, 0.0), np.nan)


def _below_equilibrium(a) -> tuple[int, int, float] | None:
    """``(kind, contact, J below)`` of the reached boundary lying lowest below the
    equilibrium energy by more than round-off, or ``None``.

    The energy scale is the largest magnitude among the equilibrium energy and the
    reachable boundary energies; round-off is `_ROUND_OFF` of it, or ``1e3``
    epsilons of the result's dtype where larger.
    """
    be = np.asarray(a.boundary_energy, dtype=np.float64)
    u0 = float(a.equilibrium_energy)
    finite = np.isfinite(be)
    if not np.any(finite):
        return None
    scale = max([abs(u0)] + [float(x) for x in np.abs(be[finite])])
    eps = float(np.finfo(np.asarray(a.boundary_energy).dtype).eps)
    above = np.where(finite, be - u0, np.inf)
    k, j = np.unravel_index(int(np.argmin(above)), above.shape)
    if above[k, j] >= -max(_ROUND_OFF, 1e3 * eps) * scale:
        return None
    return int(k), int(j), float(-above[k, j])


# ----------------------------------------------------------------------------- explain
_RELEASED = 1e-3
"""A fingertip whose deformation at the equilibrium is below this fraction of its initial
deformation counts as released (no longer pressing) in [`Evaluation.explain`][jaxgrasp.Evaluation.explain]."""


def _boundary_phrase(kind: int, contact: int) -> str:
    if kind == BoundaryKind.SLIP:
        return f"slip of contact {contact}"
    return f"the force limit of contact {contact}"


def _margin_phrase(row: int, contact: int, margin: float) -> str:
    """What a violated (or active) margin means, in words."""
    if row == Constraint.CONTACT:
        return f"contact {contact} is lost (fingertip deformation d/dr = {margin:.3g})"
    if row == Constraint.SLIP:
        return f"contact {contact} slips: friction cannot carry the load (slip margin {margin:.3g})"
    return f"the normal force of contact {contact} exceeds its limit (force margin {margin:.3g})"


def _list(items: list[str]) -> str:
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def _unsettled(a) -> list[tuple[int, int]]:
    """``(kind, contact)`` of every boundary problem that did not settle."""
    bs = np.asarray(a.boundary_status)
    n = bs.shape[-1]
    return [(k, j) for k in BoundaryKind for j in range(n) if int(bs[k, j]) == LaneStatus.NOT_CONVERGED]


def _explain_stable(a, tol: float) -> str:
    k, j = int(a.limiting_kind), int(a.limiting_contact)
    value = float(a.value)
    if not value > 0.0:
        return (
            f"stable, but with value 0 J: the equilibrium is within rounding of "
            f"{_boundary_phrase(k, j)}; treat the grasp as unstable."
        )
    text = (
        f"stable: {value:.4g} J must be added to make a fingertip fail; "
        f"limited by {_boundary_phrase(k, j)}"
    )
    be = np.asarray(a.boundary_energy, dtype=np.float64)
    u0 = float(a.equilibrium_energy)
    ties = [
        _boundary_phrase(kk, jj)
        for kk in BoundaryKind
        for jj in range(be.shape[-1])
        if (kk, jj) != (k, j) and np.isfinite(be[kk, jj]) and abs((be[kk, jj] - u0) - value) <= 1e-6 * value
    ]
    if ties:
        text += f" (tied with {_list(ties)})"
    unsettled = _unsettled(a)
    if unsettled:
        text += (
            f"; the boundary problem of {_list([_boundary_phrase(kk, jj) for kk, jj in unsettled])} "
            "did not settle, but its best feasible point lies more than 10% above the value, "
            "so it does not limit"
        )
    return text + "."


def _explain_unstable(a, tol: float) -> str:
    if int(a.equilibrium_status) == LaneStatus.INFEASIBLE:  # GraspStatus's "pulled out" (verdict)
        return (
            "unstable: the initial grasping state satisfies every constraint, but the energy "
            "pulls the object out through a boundary of the equilibrium region harder than the "
            "solver's largest penalty can hold (fingertips that let go, or a load beyond what "
            "they carry): no equilibrium inside the region; value 0."
        )
    below = _below_equilibrium(a)
    if below is not None:
        k, j, drop = below
        return (
            f"unstable: a point of {_boundary_phrase(k, j)} lies {drop:.3g} J below the "
            "equilibrium the solver found, a local minimum of the equilibrium region: no "
            "energy is needed to reach that boundary; value 0."
        )
    margins = np.asarray(a.equilibrium_margins, dtype=np.float64)
    n = margins.shape[-1]
    lost = [j for j in range(n) if margins[Constraint.CONTACT, j] <= _RELEASED]
    if lost:
        tips = _list([f"contact {j}" for j in lost])
        return (
            f"unstable: at the equilibrium {tips} {'is' if len(lost) == 1 else 'are'} released "
            f"(deformation d/dr = {float(np.max(margins[Constraint.CONTACT, lost])):.2g}, so the "
            "fingertip slips at the slightest load): the fingertips cannot press the object in "
            "place; value 0."
        )
    rows = (Constraint.SLIP, Constraint.FORCE)
    active = [(row, j) for j in range(n) for row in rows if margins[row, j] <= tol]
    if not active:  # on a boundary by less than the evaluator's tolerance
        row, j = np.unravel_index(int(np.argmin(margins[Constraint.SLIP :])), margins[Constraint.SLIP :].shape)
        active = [(int(row) + Constraint.SLIP, int(j))]
    slips = [j for row, j in active if row == Constraint.SLIP]
    forces = [j for row, j in active if row == Constraint.FORCE]
    parts = []
    if slips:
        parts.append(
            f"the slip boundary of {_list([f'contact {j}' for j in slips])}: "
            "friction cannot carry the load with any margin"
        )
    if forces:
        parts.append(
            f"the force limit of {_list([f'contact {j}' for j in forces])}: "
            "the fingertip is already pressed to its normal force limit"
        )
    return "unstable: the equilibrium lies on " + "; and on ".join(parts) + "; value 0."


def _explain_infeasible(a, tol: float) -> str:
    margins = np.asarray(a.equilibrium_margins, dtype=np.float64)
    n = margins.shape[-1]
    flat = margins.reshape(-1)
    order = [int(i) for i in np.argsort(flat) if flat[i] < -tol]
    if not order:
        return (
            "infeasible: no pose satisfies every constraint (the solver could not reach one "
            "from the initial grasping state); value 0."
        )
    worst = [_margin_phrase(i // n, i % n, float(flat[i])) for i in order[:2]]
    more = len(order) - len(worst)
    text = "infeasible: no pose satisfies every constraint; at the least-violating pose found " + _list(worst)
    if more > 0:
        text += f" ({more} more constraint{'s' if more > 1 else ''} violated)"
    return text + "; value 0."


def _explain_not_converged(a, tol: float) -> str:
    if int(a.equilibrium_status) != LaneStatus.CONVERGED:
        return (
            "not converged: the equilibrium problem did not settle "
            f"(solver status {int(a.equilibrium_status)}); the value is not to be trusted."
        )
    unsettled = _unsettled(a)
    if unsettled:
        names = _list([_boundary_phrase(k, j) for k, j in unsettled[:3]])
        if len(unsettled) > 3:
            names += f" and {len(unsettled) - 3} more"
        return (
            f"not converged: the boundary problem{'s' if len(unsettled) > 1 else ''} of {names} "
            f"did not settle; the value {float(a.value):.4g} J is only an upper estimate, not to be trusted."
        )
    return (
        "not converged: no boundary of the equilibrium region could be reached from the "
        "equilibrium (every start search failed); the value is not to be trusted."
    )


def _explain_invalid(a, tol: float) -> str:
    return "invalid: the grasp's input is invalid, so it was not evaluated (its batch's errors say why); value NaN."


_EXPLAIN = {
    GraspStatus.STABLE: _explain_stable,
    GraspStatus.UNSTABLE: _explain_unstable,
    GraspStatus.INFEASIBLE: _explain_infeasible,
    GraspStatus.NOT_CONVERGED: _explain_not_converged,
    GraspStatus.INVALID: _explain_invalid,
}


def _explain(a, tol: float) -> str:
    """The text of [`Evaluation.explain`][jaxgrasp.Evaluation.explain] for a NumPy-leaved, unbatched result."""
    return _EXPLAIN[GraspStatus(int(a.status))](a, tol)
