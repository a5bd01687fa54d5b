"""How [`jaxgrasp.tune`][jaxgrasp.tune] stopped, as a named string status with a message."""

from __future__ import annotations

import enum

__all__ = ["TuneStatus"]


class TuneStatus(enum.StrEnum):
    """How [`jaxgrasp.tune`][jaxgrasp.tune] stopped. A member *is* its string (``== "converged"``).

    ``message`` is a template with ``{ftol}``, ``{patience}`` and ``{maxiter}``: why the
    search stopped, then whether its result is usable. Every status returns the best grasp
    found (its value is never below the start's), so the result is usable in every case
    (unless `message` adds that the best
    iterate's evaluation did not converge); the statuses differ in whether it is a maximum:

    - ``converged``: the projected gradient vanished: a (local) maximum within the bounds.
    - ``stalled``: no further improvement along the gradient, typically at a maximum on a
      kink of the value (where the limiting boundary switches); counts as converged.
    - ``max_iterations``: the iterations ran out before the search converged; more may
      raise the value.
    - ``line_search_failed``: no better point along the search direction (a kink or
      noise); perhaps not a maximum.
    """

    def __new__(cls, value: str, message: str):
        obj = str.__new__(cls, value)
        obj._value_ = value
        obj.message = message
        return obj

    CONVERGED = "converged", "the projected gradient vanished: a (local) maximum within the bounds; the result is usable"
    STALLED = "stalled", (
        "no further improvement along the gradient (relative gain below {ftol:g} in {patience} iterations; "
        "typically a maximum on a kink, where the limiting boundary switches); the result is the best found "
        "and usable"
    )
    MAX_ITERATIONS = "max_iterations", (
        "reached maxiter={maxiter} before the search converged; the result is the best found and usable, "
        "and more iterations may raise it"
    )
    LINE_SEARCH_FAILED = "line_search_failed", (
        "the line search found no better point (a kink of the value, or noise); the result is the best found "
        "and usable, but perhaps not a maximum"
    )

    @property
    def label(self) -> str:
        """The status's name, its string (``'converged'``), as
        [`Coded.label`][jaxgrasp.base.Coded.label] is for the integer codes."""
        return self.value

    @property
    def converged(self) -> bool:
        """The search ended at a (local) maximum: converged or stalled."""
        return self in (TuneStatus.CONVERGED, TuneStatus.STALLED)
