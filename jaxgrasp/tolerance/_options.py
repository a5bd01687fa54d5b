"""The static settings of one evaluation: solver, start search and reduction."""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxgrasp.solver import SolverOptions

__all__ = ["EvaluateOptions"]


@dataclasses.dataclass(frozen=True)
class EvaluateOptions:
    """Static settings of [`jaxgrasp.evaluate`][jaxgrasp.evaluate] (hashable, so it can be a ``jit`` static argument).

    Attributes:
        solver: settings of the augmented-Lagrangian solver ([`jaxgrasp.SolverOptions`][jaxgrasp.SolverOptions]).
        num_random_starts: random start directions per boundary problem, on top of the 12
            half-axes of the start frame (`jaxgrasp.tolerance._starts.start_frame`: the
            grasp's modes of motion, so that the starts do not depend on the world
            frame or the contact numbering the grasp is written in).
        seed: seed of those random directions (fixed, so results are reproducible).
        ray_length: how far a start search walks from the equilibrium: translations up to
            ``ray_length`` fingertip radii, rotations up to ``ray_length`` rad or that
            many radii of arc at the grasp's lever arm, whichever is larger.
        ray_points: points of the geometric grid on which the crossing is looked for.
        crossing_steps: steps of safeguarded regula falsi (Illinois) from the bracketing
            ray points onto the boundary.
        boundary_tol: a slip or force-limit margin (scaled) at most this at the
            equilibrium, or a boundary energy at most this (relative to the energy
            scale) above ``U0``, means the equilibrium is on a boundary: status unstable.
            Also the feasibility a stalled lane must reach for its energy to count as an
            estimate.
        first_wave: how many starts of each boundary problem run first (its starts
            ``0 .. first_wave - 1``: the first half-axes of the start frame); the others
            run only where those leave the problem open
            (`jaxgrasp.tolerance._stages.rest_needed`): every other start runs too
            unless at least two of the first converged to one minimum and none ended
            otherwise, or at least two proved the boundary infeasible and none ended
            otherwise, and in any case where the problem's first minimum is within
            ``VALUE_MARGIN`` (30) times the grasp's least (the boundaries that could set
            the value). Lanes left out carry ``LaneStatus.NO_START``. ``None`` runs
            every start at once. Measured on the benchmark's mixed set in
            ``experiments/first_wave/first_wave.py``.
        smooth_min_temperature: ``None`` (default) for the paper's hard minimum over
            boundaries. A temperature ``T > 0`` in J replaces it by the soft minimum

                ``value = max(0, -T log sum_b exp(-(U_b - U0) / T))``

            over the reachable boundaries ``b`` (computed stably, relative to the hard
            minimum; unreachable boundaries are left out). Its gradient is the
            softmin-weighted mean of the boundaries' gradients, so it is continuous where
            the limiting boundary switches (useful for gradient-based tuning). It is
            biased low: with ``K`` reachable boundaries,
            ``hard - T log K <= value <= hard``, where ``hard`` is the value without
            smoothing (equality on the right when one boundary dominates by many ``T``).
            Choose ``T`` well below the values of interest (e.g. a hundredth of them).
            ``Evaluation.value`` is then the smoothed value; ``limiting_kind`` and
            ``limiting_contact`` still name the hard minimiser and every other field is
            unchanged.
    """

    solver: SolverOptions = SolverOptions()
    num_random_starts: int = 8
    seed: int = 0
    ray_length: float = 1.0
    ray_points: int = 48
    crossing_steps: int = 12
    boundary_tol: float = 1e-8
    first_wave: int | None = 6
    smooth_min_temperature: float | None = None

    def __post_init__(self):
        w = self.first_wave
        if w is not None and (isinstance(w, bool) or not isinstance(w, (int, np.integer)) or w < 2):
            raise ValueError(f"first_wave must be None or an int >= 2 (starts per boundary problem), got {w!r}")
        t = self.smooth_min_temperature
        if t is not None:
            try:
                ok = float(t) > 0.0 and np.isfinite(float(t)) and not isinstance(t, bool)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(
                    f"smooth_min_temperature must be None or a finite number > 0 (J), got {t!r}"
                )

    def __repr__(self) -> str:
        """Only the settings that differ from their defaults (``EvaluateOptions()`` for the
        defaults), so that ``help(jaxgrasp.evaluate)`` shows a short signature; two options
        with the same repr are equal."""
        return _changed_fields(self)

    def directions(self) -> np.ndarray:
        """``(12 + num_random_starts, 6)`` unit start directions: coefficients in the start
        frame (`jaxgrasp.tolerance._starts.start_frame`) of the scaled pose space, its 12
        half-axes first, then the seeded random ones."""
        axes = np.concatenate([np.eye(6), -np.eye(6)])
        rng = np.random.default_rng(self.seed)
        rand = rng.standard_normal((self.num_random_starts, 6))
        rand /= np.linalg.norm(rand, axis=1, keepdims=True)
        return np.concatenate([axes, rand])

    @property
    def num_starts(self) -> int:
        """Starts per boundary problem, ``D = 12 + num_random_starts``."""
        return 12 + self.num_random_starts


def _changed_fields(obj) -> str:
    """``Name(field=value, ...)`` of a dataclass instance, listing only the fields that
    differ from their defaults (a nested dataclass the same way)."""
    parts = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.default is not dataclasses.MISSING and value == f.default and type(value) is type(f.default):
            continue
        text = _changed_fields(value) if dataclasses.is_dataclass(value) else repr(value)
        parts.append(f"{f.name}={text}")
    return f"{type(obj).__name__}({', '.join(parts)})"
