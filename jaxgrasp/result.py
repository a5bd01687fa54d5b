"""The result of :func:`jaxgrasp.evaluate`: a pytree of named arrays, in SI units."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .model import KINDS
from .solver import LANE_STATUS_NAMES

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
            (0 converged, 1 infeasible = unreachable, 2 not converged).
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
                        "status": LANE_STATUS_NAMES[int(a.boundary_status[k, j])],
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
            "units": {"energy": "J", "translation": "m", "rotation": "rad (rotation vector)"},
        }
