"""The model's integer codes: boundaries of the equilibrium region and constraint rows."""

from __future__ import annotations

import numpy as np

from jaxgrasp.base import Coded

__all__ = ["BoundaryKind", "Constraint", "NO_BOUNDARY"]


class BoundaryKind(Coded):
    """A boundary of the equilibrium region; the first axis of every ``(2, N)`` array."""

    SLIP = 0, "the contact's friction is at its limit (Howe-Cutkosky with torsion, eq. 20)"
    MAX_FORCE = 1, "the contact's normal force is at its limit (eq. 21)"

    @classmethod
    def names_of(cls, codes) -> np.ndarray:
        """An array of codes as an object array of labels, same shape (``()`` for one
        code); ``-1`` (`NO_BOUNDARY`) is ``'none'``."""
        return np.asarray(np.asarray(cls.labels() + ("none",), dtype=object)[np.asarray(codes)], dtype=object)


NO_BOUNDARY = -1
"""``limiting_kind`` and ``limiting_contact`` where no boundary limits the value."""


class Constraint(Coded):
    """Rows of the ``(3, N)`` constraint margins (`jaxgrasp.model.constraint_margins`),
    ``>= 0`` where satisfied."""

    CONTACT = 0, "the fingertip keeps touching: d / dr >= 0"
    SLIP = 1, "no slip: friction carries the tangential force and torsion (eq. 9)"
    FORCE = 2, "the normal force stays below its limit (eq. 21)"
