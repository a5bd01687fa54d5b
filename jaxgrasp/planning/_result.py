"""What [`jaxgrasp.plan`][jaxgrasp.plan] returns: ranked grasps on a mesh, their values, and how they were found."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxgrasp.base import Coded

__all__ = ["PlanResult", "PlanStatus"]


class PlanStatus(Coded):
    """What a plan found."""

    FOUND = 0, "at least one valid candidate is stable: the ranked grasps start with the best"
    NONE_STABLE = 1, "valid candidates were evaluated, but none is stable (every value is 0)"
    NO_VALID = 2, "no candidate keeps the contact rules: nothing was evaluated (try more samples or a larger flatness)"


@dataclasses.dataclass(frozen=True)
class PlanResult:
    """The ranked grasps of a plan (SI units), best first.

    Its [`value`][jaxgrasp.planning.PlanResult.value] is the best grasp's value, J;
    ``values`` and ``statuses`` are every ranked grasp's.

    Attributes:
        status: a [`PlanStatus`][jaxgrasp.planning.PlanStatus] ([`status_name`][jaxgrasp.planning.PlanResult.status_name]
            its name).
        grasps: ``K`` [`MeshGrasp`][jaxgrasp.MeshGrasp] ranked by value, best first: each one's
            ``grasp`` in the centre-of-mass frame, ``to_mesh_frame`` for the mesh's frame.
            Only settled grasps (status stable, unstable or infeasible) are ranked.
        values: ``(K,)`` J, their evaluation values.
        statuses: ``(K,)`` int [`GraspStatus`][jaxgrasp.GraspStatus] codes.
        limiting_kind: ``(K,)`` int [`BoundaryKind`][jaxgrasp.model.BoundaryKind] of the limiting boundary
            (-1 none); limiting_contact: ``(K,)`` its contact (-1 none).
        epsilon: ``(K,)`` the Ferrari-Canny epsilon of each ([`jaxgrasp.epsilon`][jaxgrasp.epsilon]).
        refined: ``(K,)`` bool, the grasp came out of surface-constrained tuning.
        mesh_positions: ``(K, N, 3)`` m, the contacts in the mesh's frame.
        sampled: geometric candidates drawn; valid: of them, those that kept every rule
            (`jaxgrasp.surface`), all of which were evaluated.
        rule_failures: candidates that broke each rule, by rule name (one candidate may
            break several).
        stable: valid candidates that were stable.
        dropped: candidates whose evaluation did not settle (``not_converged``): left out
            of the ranking.
        refine_tried: candidates tuned; refine_kept: tuned grasps that were better and valid.
        seed: the seed of the random draws; elapsed_s: wall time, s.
        settings: the plan's settings (fingers, fingertip, object, sampler, rules, rank ...).
        robust: where the plan ranked by the robust value, ``(K,)`` arrays by column name
            (``p_stable``, ``p_stable_stderr``, ``value_mean``, ``value_q05``, ``value_q50``;
            [`jaxgrasp.analysis.RobustBatch.columns`][jaxgrasp.analysis.RobustBatch.columns]), in rank order; else ``None``.
    """

    status: PlanStatus
    grasps: tuple
    values: np.ndarray
    statuses: np.ndarray
    limiting_kind: np.ndarray
    limiting_contact: np.ndarray
    epsilon: np.ndarray
    refined: np.ndarray
    mesh_positions: np.ndarray
    sampled: int
    valid: int
    rule_failures: dict
    stable: int
    dropped: int
    refine_tried: int
    refine_kept: int
    seed: int
    elapsed_s: float
    settings: dict = dataclasses.field(default_factory=dict)
    robust: dict | None = None

    @property
    def best(self) -> Any:
        """The best [`MeshGrasp`][jaxgrasp.MeshGrasp], or ``None`` when nothing was ranked."""
        return self.grasps[0] if self.grasps else None

    @property
    def value(self) -> float:
        """The best grasp's value, J (``values[0]``; 0 when nothing was ranked)."""
        return float(self.values[0]) if len(self.values) else 0.0

    @property
    def status_name(self) -> str:
        """The name of ``status`` (``'found'``, ``'none_stable'``, ``'no_valid'``)."""
        return PlanStatus(self.status).label

    def summary(self) -> str:
        """One line: what was found, from how many candidates, in what time."""
        dropped = f", {self.dropped} not settled and left out" if self.dropped else ""
        return (
            f"{self.status.label}: best value {self.value:.6e} J; {self.valid} valid of {self.sampled} candidates "
            f"evaluated, {self.stable} stable{dropped}; {self.refine_kept} of {self.refine_tried} refined by tuning "
            f"improved; {self.elapsed_s:.1f} s"
        )

    def rows(self) -> list[dict]:
        """One dict per ranked grasp: rank (1-based), value_J, status, limiting_kind,
        limiting_contact, epsilon, refined, and where the plan ranked by the robust value
        p_stable, value_mean_J, value_q05_J."""
        from jaxgrasp.model import BoundaryKind
        from jaxgrasp.tolerance import GraspStatus

        out = []
        for i in range(len(self.grasps)):
            kind = int(self.limiting_kind[i])
            out.append({
                "rank": i + 1,
                "value_J": float(self.values[i]),
                "status": GraspStatus(int(self.statuses[i])).label,
                "limiting_kind": str(BoundaryKind.names_of(kind)),
                "limiting_contact": int(self.limiting_contact[i]),
                "epsilon": float(self.epsilon[i]),
                "refined": bool(self.refined[i]),
            })
            if self.robust is not None:
                out[-1].update(p_stable=float(self.robust["p_stable"][i]),
                               value_mean_J=float(self.robust["value_mean"][i]),
                               value_q05_J=float(self.robust["value_q05"][i]))
        return out

    def to_dict(self) -> dict[str, Any]:
        """The plan as plain Python (JSON-ready; ``None`` for a number that is not
        finite): ``status`` by name, ``value`` (the best, J), ``ranked`` (one entry of
        [`rows`][jaxgrasp.planning.PlanResult.rows] per grasp, best first, with its
        ``mesh_positions``, m), the candidate counts, ``rule_failures``, ``seed``,
        ``elapsed_s`` (s) and ``settings``. The grasps themselves are in the command's
        ``ranked.jsonl``."""
        finite = lambda v: None if isinstance(v, float) and not np.isfinite(v) else v  # noqa: E731
        ranked = [{**{k: finite(v) for k, v in row.items()}, "mesh_positions": np.asarray(p, np.float64).tolist()}
                  for row, p in zip(self.rows(), self.mesh_positions)]
        counts = dict(sampled=self.sampled, valid=self.valid, stable=self.stable, dropped=self.dropped,
                      refine_tried=self.refine_tried, refine_kept=self.refine_kept)
        return {"status": self.status_name, "value": self.value, "ranked": ranked,
                **{k: int(v) for k, v in counts.items()},
                "rule_failures": {k: int(v) for k, v in self.rule_failures.items()}, "seed": int(self.seed),
                "elapsed_s": float(self.elapsed_s), "settings": _plain(self.settings)}


def _plain(x):
    """``x`` with NumPy numbers and arrays as Python ones (settings are JSON-ready otherwise)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (np.ndarray, np.generic)):
        return x.tolist()
    return x
