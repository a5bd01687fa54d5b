"""The settling policy: whether a grasp's evaluation runs the settling stage
(`settle_stalled`,
`settle_equilibrium`) inline, or runs without it and
again with it only where a problem did not settle.

Both policies give every grasp the same result: the stage changes nothing where every
problem settled (`needs_settling`), and a grasp that
needs it is evaluated with it either way. They differ in cost only. `RETRY` spares
the stage to the grasps that rarely need it (one grasp, the points of a grid); `INLINE`
suits a set of varied grasps, where some need it in nearly every chunk, so evaluating
them again would cost more than the stage inline, and the set compiles once.

The policy is an argument of the runner (`run_batch`) and of
the compiled evaluators' keys, which name what a program computes (``settle``: whether it
has the stage), never who calls it.
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from jaxgrasp.tolerance import needs_settling

__all__ = ["INLINE", "RETRY", "POLICIES", "check_settle", "settle_then_retry"]

INLINE = "inline"
"""Every grasp's evaluation has the settling stage."""

RETRY = "retry"
"""Grasps are evaluated without the settling stage; those that need it again with it."""

POLICIES = (INLINE, RETRY)


def check_settle(settle: str) -> bool:
    """Whether the first program of policy ``settle`` (one of `POLICIES`) has the
    settling stage inline; a ``ValueError`` for another policy."""
    if settle not in POLICIES:
        raise ValueError(f"settle must be one of {', '.join(POLICIES)}, got {settle!r}")
    return settle == INLINE


def settle_then_retry(first: Mapping[str, object], again: Callable[[np.ndarray], Mapping[str, object]],
                      count: int | None = None) -> Mapping[str, object]:
    """`RETRY`'s results: ``first`` (every [`Evaluation`][jaxgrasp.Evaluation] field by
    name, evaluated without the settling stage) with the grasps that
    `needs_settling` taken from ``again``.

    ``first``'s fields have a leading axis of grasps ``(B, ...)`` (of which the first
    ``count``, default all, are real: the rest is a chunk's padding), or none for one
    grasp. ``again(rows)`` evaluates grasps ``rows`` ``(K,)`` with the stage and returns
    their fields with a leading axis of at least ``K`` (its first ``K`` taken; for one
    grasp, the grasp's fields, which replace ``first``). ``first`` is returned as it is
    where no grasp needs the stage (``again`` is not called), else host copies.
    """
    need = np.atleast_1d(needs_settling(first["boundary_status"], first["equilibrium_status"]))
    rows = np.flatnonzero(need[:count])
    if not rows.size:
        return first
    redone = again(rows)
    if np.ndim(first["equilibrium_status"]) == 0:  # one grasp: its evaluation with the stage
        return redone
    out = {f: np.array(a) for f, a in first.items()}  # writable host copies
    for f in out:
        out[f][rows] = np.asarray(redone[f])[: rows.size]
    return out
