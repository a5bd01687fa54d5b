"""How :func:`jaxgrasp.tune` stopped, as a named string status with a message."""

from __future__ import annotations

import enum

__all__ = ["TuneStatus"]


class TuneStatus(enum.StrEnum):
    """How :func:`jaxgrasp.tune` stopped. A member *is* its string (``== "converged"``).

    ``message`` is a template with ``{ftol}``, ``{patience}`` and ``{maxiter}``.
    """

    def __new__(cls, value: str, message: str):
        obj = str.__new__(cls, value)
        obj._value_ = value
        obj.message = message
        return obj

    CONVERGED = "converged", "the projected gradient vanished"
    STALLED = "stalled", (
        "no relative improvement above {ftol:g} in {patience} iterations "
        "(typically a maximum on a kink, where the limiting boundary switches)"
    )
    MAX_ITERATIONS = "max_iterations", "stopped after maxiter={maxiter} iterations"
    LINE_SEARCH_FAILED = "line_search_failed", "the line search found no better point (a kink of the value, or noise)"

    @property
    def converged(self) -> bool:
        """The search ended at a (local) maximum: converged or stalled."""
        return self in (TuneStatus.CONVERGED, TuneStatus.STALLED)
