"""The result of :func:`jaxgrasp.evaluate`: a pytree of named arrays, in SI units."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import numpy as np

from .model import KINDS
from .status import LaneStatus

__all__ = ["Evaluation", "STATUS_NAMES", "STABLE", "UNSTABLE", "INFEASIBLE", "NOT_CONVERGED"]

STABLE = 0
"""The equilibrium lies inside the equilibrium region: ``value > 0``."""
UNSTABLE = 1
"""The equilibrium lies on a boundary (a fingertip is about to slip or is at its force
limit): ``value = 0``."""
INFEASIBLE = 2
"""No pose satisfies every constraint (no stable equilibrium at all): ``value = 0``."""
NOT_CONVERGED = 3
"""The solver did not settle a problem the value depends on: do not trust ``value``."""

STATUS_NAMES = ("stable", "unstable", "infeasible", "not_converged")
"""Grasp status names, indexed by the integer codes above."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Evaluation:
    """Energy-tolerance evaluation of one grasp (SI units; add leading axes under ``vmap``).

    ``N`` is the number of contacts; every ``(2, N, ...)`` array is indexed
    ``[kind, contact]`` with kind 0 = ``slip`` (eq. 20) and 1 = ``max_force`` (eq. 21).

    Attributes:
        value: ``()`` evaluation value ``Delta U_min`` of eq. 1, J: the least energy that
            brings the object from its equilibrium to a boundary of the equilibrium region.
            0 when ``status`` is unstable or infeasible.
        status: ``()`` int, one of :data:`STABLE`, :data:`UNSTABLE`, :data:`INFEASIBLE`,
            :data:`NOT_CONVERGED` (names in :data:`STATUS_NAMES`).
        limiting_kind: ``()`` int, kind of the boundary that sets ``value`` (0 slip,
            1 max_force), -1 when there is none.
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
        boundary_status: ``(2, N)`` int, solver status of each boundary problem
            (0 converged, 1 infeasible = unreachable, 2 not converged, 3 not started
            because the equilibrium problem did not converge); names in
            :meth:`jaxgrasp.status.LaneStatus.labels`.
        equilibrium_status: ``()`` int, solver status of the equilibrium problem.
        equilibrium_margins: ``(3, N)`` scaled constraint margins at the equilibrium (or,
            for an infeasible grasp, at the least-violating pose found), rows: contact
            kept ``d / dr``, no slip, force below its limit; ``>= 0`` where satisfied
            (:func:`jaxgrasp.model.constraint_margins`).
        kkt: ``(1 + 2N, 3)`` KKT residuals (stationarity, feasibility, complementarity,
            in the solver's scaled units) of the equilibrium problem (row 0) and of the
            kept start of each boundary problem (rows ``1 + kind * N + contact``).
        steps: ``(1 + 2N,)`` solver steps of those same lanes.
    """

    value: Any
    status: Any
    limiting_kind: Any
    limiting_contact: Any
    equilibrium_energy: Any
    equilibrium_translation: Any
    equilibrium_rotation: Any
    boundary_energy: Any
    boundary_translation: Any
    boundary_rotation: Any
    boundary_status: Any
    equilibrium_status: Any
    equilibrium_margins: Any
    kkt: Any
    steps: Any

    @property
    def status_name(self) -> str:
        """Name of ``status`` (for an unbatched, concrete result)."""
        return STATUS_NAMES[int(self.status)]

    def tolerates(self, kinetic_energy, potential_energy=None):
        """Stable-grasp condition with kinetic energy, eq. 2: ``U + K < min U + value``.

        Args:
            kinetic_energy: the object's kinetic energy ``K``, J.
            potential_energy: its current potential energy ``U``, J (default: the
                equilibrium energy, i.e. the object passes the equilibrium pose).

        Returns:
            Boolean array: ``True`` where no fingertip can slip or be overloaded.
            Always ``False`` for an unstable, infeasible or not-converged grasp.
        """
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

    def to_dict(self) -> dict:
        """A JSON-ready summary of an unbatched result (``None`` for unreachable boundaries)."""
        a = jax.tree_util.tree_map(np.asarray, self)
        if a.value.ndim != 0:
            raise ValueError("to_dict() takes one grasp's result; index a batched result first")
        n = a.boundary_energy.shape[-1]
        boundaries = []
        for j in range(n):
            for k, kind in enumerate(KINDS):
                e = float(a.boundary_energy[k, j])
                boundaries.append(
                    {
                        "kind": kind,
                        "contact": j,
                        "energy": e if math.isfinite(e) else None,
                        "status": LaneStatus.labels()[int(a.boundary_status[k, j])],
                        "translation": a.boundary_translation[k, j].tolist(),
                        "rotation": a.boundary_rotation[k, j].tolist(),
                    }
                )
        kind = int(a.limiting_kind)
        return {
            "value": float(a.value),
            "status": STATUS_NAMES[int(a.status)],
            "equilibrium_energy": float(a.equilibrium_energy),
            "equilibrium_translation": a.equilibrium_translation.tolist(),
            "equilibrium_rotation": a.equilibrium_rotation.tolist(),
            "limiting": (
                {"kind": KINDS[kind], "contact": int(a.limiting_contact)} if kind >= 0 else None
            ),
            "boundaries": boundaries,
            "explanation": _explain(a, 1e-8),
            "units": {"energy": "J", "translation": "m", "rotation": "rad (rotation vector)"},
        }


# ----------------------------------------------------------------------------- explain
_RELEASED = 1e-3
"""A fingertip whose deformation at the equilibrium is below this fraction of its initial
deformation counts as released (no longer pressing) in :meth:`Evaluation.explain`."""


def _boundary_phrase(kind: int, contact: int) -> str:
    return f"slip of contact {contact}" if kind == 0 else f"the force limit of contact {contact}"


def _margin_phrase(row: int, contact: int, margin: float) -> str:
    """What a violated (or active) margin means, in words."""
    if row == 0:
        return f"contact {contact} is lost (fingertip deformation d/dr = {margin:.3g})"
    if row == 1:
        return f"contact {contact} slips: friction cannot carry the load (slip margin {margin:.3g})"
    return f"the normal force of contact {contact} exceeds its limit (force margin {margin:.3g})"


def _list(items: list[str]) -> str:
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def _explain(a, tol: float) -> str:
    """The text of :meth:`Evaluation.explain` for a NumPy-leaved, unbatched result."""
    status = int(a.status)
    margins = np.asarray(a.equilibrium_margins, dtype=np.float64)
    n = margins.shape[-1]
    value = float(a.value)
    be = np.asarray(a.boundary_energy, dtype=np.float64)
    bs = np.asarray(a.boundary_status)
    u0 = float(a.equilibrium_energy)

    if status == STABLE:
        k, j = int(a.limiting_kind), int(a.limiting_contact)
        if not value > 0.0:
            return (
                f"stable, but with value 0 J: the equilibrium is within rounding of "
                f"{_boundary_phrase(k, j)}; treat the grasp as unstable."
            )
        text = (
            f"stable: {value:.4g} J must be added to make a fingertip fail; "
            f"limited by {_boundary_phrase(k, j)}"
        )
        ties = [
            _boundary_phrase(kk, jj)
            for kk in range(2)
            for jj in range(n)
            if (kk, jj) != (k, j) and np.isfinite(be[kk, jj]) and abs((be[kk, jj] - u0) - value) <= 1e-6 * value
        ]
        if ties:
            text += f" (tied with {_list(ties)})"
        unsettled = [(kk, jj) for kk in range(2) for jj in range(n) if int(bs[kk, jj]) == 2]
        if unsettled:
            text += (
                f"; the boundary problem of {_list([_boundary_phrase(kk, jj) for kk, jj in unsettled])} "
                "did not settle, but its best feasible point lies more than 10% above the value, "
                "so it does not limit"
            )
        return text + "."

    if status == UNSTABLE:
        active = []
        lost = []
        for j in range(n):
            if margins[0, j] <= _RELEASED:
                lost.append(j)
                continue
            for row in (1, 2):
                if margins[row, j] <= tol:
                    active.append((row, j))
        if lost:
            tips = _list([f"contact {j}" for j in lost])
            return (
                f"unstable: at the equilibrium {tips} {'is' if len(lost) == 1 else 'are'} released "
                f"(deformation d/dr = {float(np.max(margins[0, lost])):.2g}, so the fingertip slips at "
                "the slightest load): the fingertips cannot press the object in place; value 0."
            )
        if not active:  # on a boundary by less than the evaluator's tolerance
            row, j = np.unravel_index(int(np.argmin(margins[1:])), margins[1:].shape)
            active = [(int(row) + 1, int(j))]
        slips = [j for row, j in active if row == 1]
        forces = [j for row, j in active if row == 2]
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

    if status == INFEASIBLE:
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

    # not converged
    if int(a.equilibrium_status) != 0:
        return (
            "not converged: the equilibrium problem did not settle "
            f"(solver status {int(a.equilibrium_status)}); the value is not to be trusted."
        )
    unsettled = [(k, j) for k in range(2) for j in range(n) if int(bs[k, j]) == 2]
    if unsettled:
        names = _list([_boundary_phrase(k, j) for k, j in unsettled[:3]])
        if len(unsettled) > 3:
            names += f" and {len(unsettled) - 3} more"
        return (
            f"not converged: the boundary problem{'s' if len(unsettled) > 1 else ''} of {names} "
            f"did not settle; the value {value:.4g} J is only an upper estimate, not to be trusted."
        )
    return (
        "not converged: no boundary of the equilibrium region could be reached from the "
        "equilibrium (every start search failed); the value is not to be trusted."
    )
