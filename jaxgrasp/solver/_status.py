"""The solver's own status, [`LaneStatus`][jaxgrasp.solver.LaneStatus]: how one lane ended (a `Coded`
of `jaxgrasp.base`, where the kinds of integer code of jaxgrasp are listed)."""

from __future__ import annotations

from jaxgrasp.base import Coded

__all__ = ["LaneStatus"]


class LaneStatus(Coded):
    """How one lane of `jaxgrasp.solver.solve` (one problem from one start) ended."""

    CONVERGED = 0, "KKT conditions hold within tolerance"
    INFEASIBLE = 1, "the constraint violation stagnated above infeasible_tol: no feasible point"
    NOT_CONVERGED = 2, "the step budget ran out before the lane converged or proved infeasible"
    NO_START = 3, "the lane was not run (no starting point was found, it was inactive, or its problem's first wave of starts settled it)"
