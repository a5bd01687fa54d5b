"""What [`jaxgrasp.plan`][jaxgrasp.plan] says while it runs: a record per stage on the ``"jaxgrasp"`` logger."""

from __future__ import annotations

import logging
import time

__all__ = ["PlanProgress", "stage"]

LOGGER = logging.getLogger("jaxgrasp")
"""The logger of every jaxgrasp message (`jaxgrasp.engine._progress`)."""


class PlanProgress:
    """``progress(stage, done, total)`` of [`jaxgrasp.plan`][jaxgrasp.plan]: an INFO record on the
    ``"jaxgrasp"`` logger when a stage starts, then at most one a second (``jaxgrasp: plan:
    12/40 candidates evaluated, elapsed T s``). [`jaxgrasp.plan`][jaxgrasp.plan] uses one where it is
    given no ``progress``; the ``jaxgrasp plan`` command prints the same records.

    Args:
        t0: the `time.perf_counter` its elapsed times count from (default: now).
        show: whether it reports at all (the command's ``--quiet`` clears it).
    """

    WORDS = {"draw": "valid candidates found", "evaluate": "candidates evaluated", "refine": "best refined",
             "robust": "perturbed copies evaluated", "grid": "points of the object's distance grid",
             "close": "hand candidates closed onto the object"}
    """What each stage counts, in words."""

    def __init__(self, t0: float | None = None, show: bool = True):
        self.t0 = time.perf_counter() if t0 is None else t0
        self.show, self.stage, self.last = show, None, 0.0

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.perf_counter()
        if not self.show or (stage == self.stage and now - self.last < 1.0 and done < total):
            return
        self.stage, self.last = stage, now
        LOGGER.info(f"jaxgrasp: plan: {done}/{total} {self.WORDS.get(stage, stage)}, elapsed {now - self.t0:.1f} s")


def stage(progress, name: str):
    """``progress(done, total)`` of one stage ``name`` of a plan's ``progress(stage, done,
    total)``, or ``None``."""
    return None if progress is None else (lambda done, total: progress(name, done, total))
