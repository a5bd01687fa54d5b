"""What [`jaxgrasp.plan`][jaxgrasp.plan] with a hand returns: ranked hand configurations, their values, and how they were found."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxgrasp.planning._result import PlanStatus, _plain

__all__ = ["HandPlanResult", "HAND_RESULT_COLUMNS"]

HAND_RESULT_COLUMNS = ("rank", "value_J", "status", "active", "penetration_mm", "self_overlap_mm", "epsilon", "refined")
"""The columns of [`HandPlanResult.rows`][jaxgrasp.planning.HandPlanResult.rows] (``results.csv`` of ``jaxgrasp plan --hand``)."""


@dataclasses.dataclass(frozen=True)
class HandPlanResult:
    """The ranked hand grasps of a plan (SI units), best first.

    Attributes:
        status: a [`PlanStatus`][jaxgrasp.planning.PlanStatus]: ``found`` when the best is stable.
        grasps: ``K`` [`HandGrasp`][jaxgrasp.hands.HandGrasp], best first (by ``objective``), each
            with its ``qpos`` and ``wrist``; only grasps with at least ``min_fingertips``
            fingertips in contact, links at most ``max_penetration`` deep in the object and
            in each other, and a settled
            evaluation are ranked.
        values: ``(K,)`` J, each one's value ([`jaxgrasp.evaluate`][jaxgrasp.evaluate] of its grasp).
        statuses: ``(K,)`` int [`GraspStatus`][jaxgrasp.GraspStatus] codes.
        active: ``(K,)`` fingertips in contact.
        penetration: ``(K,)`` m, the deepest of the hand's other links inside the object
            (negative: clear of it), on the exact surface.
        self_overlap: ``(K,)`` m, the deepest overlap of two of the hand's own links that
            MuJoCo would collide ([`Hand.self_overlap`][jaxgrasp.Hand.self_overlap]; negative: the
            smallest clearance); at most ``max_penetration``.
        epsilon: ``(K,)`` each one's Ferrari-Canny epsilon ([`jaxgrasp.epsilon`][jaxgrasp.epsilon]).
        refined: ``(K,)`` bool, the grasp came out of refinement.
        qpos: ``(K, J)`` rad (m for slides), within the limits and couplings. wrist: ``(K, 6)``
            the hand's model frame in the mesh's (translation m, rotation vector rad).
        candidates: configurations closed onto the object; evaluated: of them, those with
            at least two fingertips in contact (evaluated by the engine's runner);
            eligible: of those, the ones ranked (enough fingertips, links clear, settled);
            stable: eligible and stable.
        refine_tried, refine_kept: candidates refined; refinements that were better and
            still eligible.
        seed: of every random draw. elapsed_s: wall time, s. timings: s per stage.
        settings: the plan's settings (hand, fingertips, objective, fields, object).
    """

    status: PlanStatus
    grasps: tuple
    values: np.ndarray
    statuses: np.ndarray
    active: np.ndarray
    penetration: np.ndarray
    self_overlap: np.ndarray
    epsilon: np.ndarray
    refined: np.ndarray
    qpos: np.ndarray
    wrist: np.ndarray
    candidates: int
    evaluated: int
    eligible: int
    stable: int
    refine_tried: int
    refine_kept: int
    seed: int
    elapsed_s: float
    timings: dict = dataclasses.field(default_factory=dict)
    settings: dict = dataclasses.field(default_factory=dict)

    @property
    def best(self) -> Any:
        """The best [`HandGrasp`][jaxgrasp.hands.HandGrasp], or ``None`` when nothing was ranked."""
        return self.grasps[0] if self.grasps else None

    @property
    def value(self) -> float:
        """The best grasp's value, J (0 when nothing was ranked)."""
        return float(self.values[0]) if len(self.values) else 0.0

    @property
    def status_name(self) -> str:
        """The name of ``status`` (``'found'``, ``'none_stable'``, ``'no_valid'``)."""
        return PlanStatus(self.status).label

    def summary(self) -> str:
        """One line: what was found, from how many candidates, in what time."""
        best = (f"best value {self.value:.6e} J with {int(self.active[0])} fingertips, links "
                f"{max(self.penetration[0], 0.0) * 1e3:.2f} mm deep" if len(self.values) else "nothing ranked")
        return (f"{self.status.label}: {best}; {self.candidates} candidates closed, {self.evaluated} evaluated, "
                f"{self.eligible} eligible, {self.stable} stable; {self.refine_kept} of {self.refine_tried} refined "
                f"improved; {self.elapsed_s:.1f} s")

    def rows(self) -> list[dict]:
        """One dict per ranked grasp with the columns `HAND_RESULT_COLUMNS`: rank (1-based),
        value_J, status (its name), active, penetration_mm (deepest link, mm, negative:
        clear), self_overlap_mm (deepest overlap of the hand's own links, mm, negative:
        clear), epsilon, refined."""
        from jaxgrasp.tolerance import GraspStatus

        return [{"rank": i + 1, "value_J": float(self.values[i]), "status": GraspStatus(int(self.statuses[i])).label,
                 "active": int(self.active[i]), "penetration_mm": float(self.penetration[i]) * 1e3,
                 "self_overlap_mm": float(self.self_overlap[i]) * 1e3,
                 "epsilon": float(self.epsilon[i]), "refined": bool(self.refined[i])} for i in range(len(self.grasps))]

    def to_dict(self) -> dict[str, Any]:
        """The plan as plain Python (JSON-ready; ``None`` for a number that is not finite):
        ``status`` by name, ``value`` (J), ``ranked`` (each row with its ``qpos`` and
        ``wrist``), the counts, ``seed``, ``elapsed_s``, ``timings`` (s) and ``settings``."""
        finite = lambda v: None if isinstance(v, float) and not np.isfinite(v) else v  # noqa: E731
        ranked = [{**{k: finite(v) for k, v in row.items()}, "qpos": np.asarray(q).tolist(),
                   "wrist": np.asarray(w).tolist()} for row, q, w in zip(self.rows(), self.qpos, self.wrist)]
        counts = dict(candidates=self.candidates, evaluated=self.evaluated, eligible=self.eligible, stable=self.stable,
                      refine_tried=self.refine_tried, refine_kept=self.refine_kept)
        return {"status": self.status_name, "value": self.value, "ranked": ranked,
                **{k: int(v) for k, v in counts.items()}, "seed": int(self.seed), "elapsed_s": float(self.elapsed_s),
                "timings": {k: float(v) for k, v in self.timings.items()}, "settings": _plain(self.settings)}
