"""Named integer codes: `Coded`, the base of every status and kind code of jaxgrasp.

Arrays carry the integer codes (so they live inside ``jit``/``vmap`` results); these
enums give the codes names and one-line meanings. A member *is* its integer
(``enum.IntEnum``), so ``result.status == jaxgrasp.GraspStatus.STABLE`` works on arrays,
and ``GraspStatus(int(code)).label`` is the name written to files and JSON.

Four kinds of integer code, never to be mixed up (they share some names, not their
numbers), each defined in the package it belongs to:

* [`jaxgrasp.solver.LaneStatus`][jaxgrasp.solver.LaneStatus] (`jaxgrasp.solver`): how one solver lane (one problem
  from one start) ended;
* [`jaxgrasp.GraspStatus`][jaxgrasp.GraspStatus] (`jaxgrasp.tolerance`): what an evaluation says of
  a grasp;
* [`jaxgrasp.model.BoundaryKind`][jaxgrasp.model.BoundaryKind] (`jaxgrasp.model`): which boundary of the
  equilibrium region (eq. 20, 21);
* `jaxgrasp.model.Constraint`: the rows of
  `jaxgrasp.model.constraint_margins`;

and one string status, [`jaxgrasp.analysis.TuneStatus`][jaxgrasp.analysis.TuneStatus]: how [`jaxgrasp.tune`][jaxgrasp.tune] stopped
(a Python loop, not an array, so its members are strings).
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Coded"]


class Coded(enum.IntEnum):
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
        """An array of codes as an object array of labels, same shape (a ``()`` array for
        one code, not a bare ``str``, so that ``names[()]`` and ``.tolist()`` work alike)."""
        return np.asarray(np.asarray(cls.labels(), dtype=object)[np.asarray(codes)], dtype=object)

    @classmethod
    def count(cls, codes) -> dict[str, int]:
        """How many entries of an array of codes carry each member, by label."""
        c = np.asarray(codes)
        return {m.label: int(np.sum(c == m)) for m in cls}
