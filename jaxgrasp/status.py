"""Every status and kind code of jaxgrasp, as named integer enums with a message each.

Arrays carry the integer codes (so they live inside ``jit``/``vmap`` results); these
enums give the codes names and one-line meanings. A member *is* its integer
(``enum.IntEnum``), so ``result.status == GraspStatus.STABLE`` works on arrays, and
``GraspStatus(int(code)).label`` is the name written to files and JSON.

Four kinds of integer code, never to be mixed up (they share some names, not their numbers):

* :class:`LaneStatus`: how one solver lane (one program from one start) ended;
* :class:`GraspStatus`: what an evaluation says of a grasp;
* :class:`BoundaryKind`: which boundary of the equilibrium region (eq. 20, 21);
* :class:`Constraint`: the rows of :func:`jaxgrasp.model.constraint_margins`.

and one string status, :class:`TuneStatus`: how :func:`jaxgrasp.tune` stopped (a Python
loop, not an array, so its members are strings).
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["LaneStatus", "GraspStatus", "BoundaryKind", "Constraint", "NO_BOUNDARY", "TuneStatus"]


class _Coded(enum.IntEnum):
    """An integer code with a lower-case ``label`` and a one-line ``message``."""

    def __new__(cls, value: int, message: str):
        obj = int.__new__(cls, value)
        obj._value_ = value
        obj.message = message
        return obj

    @property
    def label(self) -> str:
        """The name used in files, JSON and messages (``'not_converged'``)."""
        return self.name.lower()

    @classmethod
    def labels(cls) -> tuple[str, ...]:
        """Every label, indexed by code (codes are ``0, 1, 2, ...``)."""
        return tuple(m.label for m in cls)

    @classmethod
    def names_of(cls, codes) -> np.ndarray:
        """An array of codes as an object array of labels, same shape."""
        return np.asarray(cls.labels(), dtype=object)[np.asarray(codes)]

    @classmethod
    def count(cls, codes) -> dict[str, int]:
        """How many entries of an array of codes carry each member, by label."""
        c = np.asarray(codes)
        return {m.label: int(np.sum(c == m)) for m in cls}


class LaneStatus(_Coded):
    """How one lane of :func:`jaxgrasp.solver.solve` ended."""

    CONVERGED = 0, "KKT conditions hold within tolerance"
    INFEASIBLE = 1, "the constraint violation stagnated above infeasible_tol: no feasible point"
    NOT_CONVERGED = 2, "the step budget ran out before the lane converged or proved infeasible"
    NO_START = 3, "the lane was not run (no starting point was found, or it was inactive)"


class GraspStatus(_Coded):
    """What :func:`jaxgrasp.evaluate` says of a grasp."""

    STABLE = 0, "the equilibrium lies inside the equilibrium region: value > 0"
    UNSTABLE = 1, (
        "the equilibrium lies on a boundary (a fingertip is about to slip or is at its "
        "force limit): value 0"
    )
    INFEASIBLE = 2, "no pose satisfies every constraint (no stable equilibrium at all): value 0"
    NOT_CONVERGED = 3, "the solver did not settle a problem the value depends on: do not trust the value"
    INVALID = 4, (
        "the grasp's input is invalid, so it was not evaluated (a dataset row; its error "
        "names the field and value): value NaN"
    )


class BoundaryKind(_Coded):
    """A boundary of the equilibrium region; the first axis of every ``(2, N)`` array."""

    SLIP = 0, "the contact's friction is at its limit (Howe-Cutkosky with torsion, eq. 20)"
    MAX_FORCE = 1, "the contact's normal force is at its limit (eq. 21)"

    @classmethod
    def names_of(cls, codes) -> np.ndarray:
        """An array of codes as an object array of labels, same shape; ``-1``
        (:data:`NO_BOUNDARY`) is ``'none'``."""
        return np.asarray(cls.labels() + ("none",), dtype=object)[np.asarray(codes)]


NO_BOUNDARY = -1
"""``limiting_kind`` and ``limiting_contact`` where no boundary limits the value."""


class Constraint(_Coded):
    """Rows of the ``(3, N)`` constraint margins, ``>= 0`` where satisfied."""

    CONTACT = 0, "the fingertip keeps touching: d / dr >= 0"
    SLIP = 1, "no slip: friction carries the tangential force and torsion (eq. 9)"
    FORCE = 2, "the normal force stays below its limit (eq. 21)"


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
