"""What long library calls say while they run: Python's ``logging``, logger ``"jaxgrasp"``.

One mechanism serves the library and the ``jaxgrasp`` command: the engine's compilation
reports (`jaxgrasp.engine._compile.compiled`), the chunk lines of a batch or a sweep
(`ChunkProgress`) and the stage lines of a plan
(`jaxgrasp.planning.PlanProgress`) are records at INFO level on `LOGGER` or
its children; warnings (a refused cache folder) at WARNING. The command prints each record
as one line on stderr (`jaxgrasp.engine._store.log_lines_on_stderr`).

A library user sees the same lines by default: at jaxgrasp's first use
(`show_by_default`), where the program has configured no logging (no handler on
the root logger, none on ``"jaxgrasp"``), jaxgrasp gives its logger a handler that prints
each record as one line on stderr, and level INFO unless a level was set. Where the
program configured logging, its configuration decides. Quiet::

    import logging
    logging.getLogger("jaxgrasp").setLevel(logging.WARNING)

before or after jaxgrasp's first use (the level set is kept).
"""

from __future__ import annotations

import logging
import math
import time

from jaxgrasp.engine._store import LOGGER, _StderrLines

__all__ = ["LOGGER", "ChunkProgress", "chunk_progress", "show_by_default"]

_DEFAULT_HANDLER = _StderrLines(logging.INFO)
"""The handler `show_by_default` gives `LOGGER` (once)."""


def show_by_default() -> bool:
    """Where the program has configured no logging (no handler on the root logger or on
    `LOGGER`), print jaxgrasp's records on stderr, one line each, from INFO up
    (unless the program set `LOGGER`'s level); whether the handler was added."""
    if logging.getLogger().handlers or LOGGER.handlers:
        return False
    LOGGER.addHandler(_DEFAULT_HANDLER)
    if LOGGER.level == logging.NOTSET:
        LOGGER.setLevel(logging.INFO)
    return True


class ChunkProgress:
    """``progress`` of the engine's batches and sweeps: a record before the first chunk and
    one per chunk on `LOGGER` at INFO (``jaxgrasp: chunk 2/8 (6/24 points), elapsed
    T s, about S s left``); the time left is estimated from the chunks after the first,
    which includes the compilation. Silent unless ``show`` and the run has more than one
    chunk (a run of one chunk says what it compiles, if it does).

    Args:
        verb, noun: the words of its lines (``"evaluating"``, ``"grasp"``).
        show: whether it reports at all (the command's ``--quiet`` clears it).
    """

    def __init__(self, verb: str = "evaluating", noun: str = "grasp", show: bool = True):
        self.verb, self.noun, self.show = verb, noun, show
        self.chunk = self.nchunks = 1
        self.calls = 0  # chunks reported
        self.t_start = time.perf_counter()
        self._first: tuple[int, float] | None = None  # (done, time) after the first chunk

    def start(self, plan) -> None:
        """The record before the first chunk (how many items, chunks and devices), from the
        engine's `ChunkPlan` or
        `SegmentPlan` (whose programs by contact count it
        names: the first chunk of each includes its compilation)."""
        self.chunk, self.nchunks, self.calls = plan.chunk, plan.n_chunks, 0
        self.show = self.show and plan.n_chunks > 1
        self.t_start = time.perf_counter()
        if self.show:
            on = f" on {plan.n_devices} devices" if plan.n_devices > 1 else ""
            segments = getattr(plan, "segments", ())
            if len(segments) > 1:
                LOGGER.info(f"jaxgrasp: {self.verb} {plan.total} {self.noun}s in {plan.n_chunks} chunks of up to "
                            f"{plan.chunk}{on}, {len(segments)} programs by contact count ({plan.describe()}; "
                            "the first chunk of each includes its compilation)")
            else:
                LOGGER.info(f"jaxgrasp: {self.verb} {plan.total} {self.noun}s in {plan.n_chunks} chunks of "
                            f"{plan.chunk}{on} (the first chunk includes compilation)")

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        self.calls += 1
        if self._first is None:
            self._first = (done, now)
            left = "time left known after the next chunk" if done < total else "done"
        elif done < total:
            rate = (done - self._first[0]) / max(now - self._first[1], 1e-9)
            left = f"about {math.ceil((total - done) / rate)} s left"
        else:
            left = "done"
        if self.show:
            LOGGER.info(f"jaxgrasp: chunk {self.calls}/{self.nchunks} ({done}/{total} {self.noun}s), "
                        f"elapsed {now - self.t_start:.1f} s, {left}")


def chunk_progress(progress, verb: str = "evaluating", noun: str = "grasp"):
    """``progress`` as given, or where it is ``None`` a `ChunkProgress` of ``verb``
    and ``noun``: a library call reports its chunks on `LOGGER` unless the caller
    passes a ``progress`` of its own."""
    return ChunkProgress(verb, noun) if progress is None else progress
