"""What an evaluation says of a grasp, as a named integer code with a message."""

from __future__ import annotations

from jaxgrasp.base import Coded

__all__ = ["GraspStatus"]


class GraspStatus(Coded):
    """What [`jaxgrasp.evaluate`][jaxgrasp.evaluate] says of a grasp."""

    STABLE = 0, "the equilibrium lies inside the equilibrium region: value > 0"
    UNSTABLE = 1, (
        "the equilibrium lies on a boundary (a fingertip is about to slip or is at its "
        "force limit), or the energy pulls the object out of the equilibrium region from "
        "an initial state inside it: value 0"
    )
    INFEASIBLE = 2, "no pose satisfies every constraint (no stable equilibrium at all): value 0"
    NOT_CONVERGED = 3, "the solver did not settle a problem the value depends on: do not trust the value"
    INVALID = 4, (
        "the grasp's input is invalid, so it was not evaluated (a dataset row; its error "
        "names the field and value): value NaN"
    )
