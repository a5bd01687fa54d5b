"""Ctrl-C and SIGTERM for the ``jaxgrasp`` command: exit within a second, one line, no crash.

A Python signal handler runs only in the main thread and only between bytecodes, so
while the main thread is inside XLA's compiler (C++, seconds at a time) a Ctrl-C waits
for it; and
an interrupt that unwinds the interpreter while XLA's threads still run ends in a
segfault at teardown, or, inside an import, in a fatal error. Therefore
`run_interruptibly` runs the command in a worker thread (a daemon) while the main
thread only waits, a short timeout at a time, so that its handlers run at once; the
worker blocks both signals for itself and the threads it starts (XLA's), so they reach
the main thread only. On SIGINT or SIGTERM the main thread:

1. ignores further signals (a second Ctrl-C cannot cut the clean-up short);
2. calls `jaxgrasp.cli._notes.abandon`: waits at most `PUBLISH_WAIT_SECONDS`
   for a set of output files being renamed into place, removes this run's temporary
   files and lock files, and forbids later writes; then waits as long again at most
   for a compiled executable being written to the executable store
   (`jaxgrasp.engine._compile.wait_for_saves`);
3. flushes stdout and stderr and prints one line ``jaxgrasp: interrupted``
   (``terminated`` for SIGTERM) with the notes commands left, e.g. ``; kept 128 of 369
   points in out/sweep.partial.npz``, as the process's last output;
4. ends the process with ``os._exit`` (status 130, or 143 for SIGTERM), skipping the
   interpreter teardown that crashes while XLA works.

Exceptions of the command (errors, ``SystemExit``) are raised again in the calling
thread, so the command behaves as if it ran there.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Callable

from jaxgrasp._startup import EXIT
from jaxgrasp.cli import _notes
from jaxgrasp.engine import wait_for_saves

__all__ = ["run_interruptibly", "Interrupted", "EXIT_STATUS", "POLL_SECONDS", "PUBLISH_WAIT_SECONDS"]

EXIT_STATUS = {signum: status for signum, (status, _) in EXIT.items()}
"""Exit status on each signal handled: 128 + the signal number, as a shell reports it."""

_WORDS = {signum: word for signum, (_, word) in EXIT.items()}

POLL_SECONDS = 0.05
"""The main thread's longest wait between two chances to run a signal handler, s."""

PUBLISH_WAIT_SECONDS = 0.5
"""The longest wait, on an interrupt, for a set of files being renamed into place, s."""

_exit = os._exit  # replaced by tests that exercise the exit path in-process


class Interrupted(BaseException):
    """Raised in the main thread by the signal handlers; ``.signum`` is the signal."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum, _frame):
    raise Interrupted(signum)


def run_interruptibly(func: Callable[[], int], *, end_process: bool = False) -> int:
    """``func()`` in a worker thread, the main thread handling SIGINT and SIGTERM; its result.

    With ``end_process`` (the ``jaxgrasp`` command itself), once ``func`` has returned
    the process ends at once with ``os._exit(result)`` after flushing stdout and stderr:
    a Ctrl-C can then never land in the interpreter's teardown (where Python's
    handlers are gone and it killed the process without a word, exit -2, in 5 of 12
    tries), and XLA's threads never see a teardown. Called from another thread than the
    main one (where signals cannot be handled), just ``func()``. Exceptions of ``func``
    are raised again here.
    """
    if threading.current_thread() is not threading.main_thread():
        return func()
    previous = {s: signal.signal(s, _raise_interrupted) for s in EXIT_STATUS}
    try:
        try:
            result = _run_in_worker(func)
            if end_process:
                _flush(sys.stdout)
                _flush(sys.stderr)
                _exit(int(result))
            return result
        except Interrupted as exc:
            return _exit_interrupted(exc.signum)
        except KeyboardInterrupt:  # pragma: no cover - a handler replaced ours meanwhile
            return _exit_interrupted(signal.SIGINT)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _run_in_worker(func: Callable[[], int]) -> int:
    """Run ``func`` in a daemon thread; wait for it interruptibly; its result or exception."""
    box: dict = {}

    def work():
        _block_signals()
        try:
            box["result"] = func()
        except BaseException as exc:  # SystemExit too: raised again in the main thread
            box["error"] = exc

    worker = threading.Thread(target=work, name="jaxgrasp-command", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(POLL_SECONDS)
    if "error" in box:
        error = box.pop("error")
        try:
            raise error
        finally:
            del error
    return box["result"]


def _block_signals() -> None:
    """Block SIGINT and SIGTERM in this thread and in every thread it starts (XLA's
    compiler and thread pools), so that the main thread always takes them.

    Linux already prefers the main thread for a signal sent to the process; this makes
    it certain (no signal interrupts a system call inside XLA). When the main thread
    itself was inside XLA's compiler (the old, single-threaded command), Ctrl-C made the
    compilation end early and the process segfault soon after (exit -11).
    """
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, set(EXIT_STATUS))


def _exit_interrupted(signum: int) -> int:
    """Clean up, print the one line and end the process (see the module's docstring)."""
    for s in EXIT_STATUS:
        signal.signal(s, signal.SIG_IGN)
    notes = _notes.abandon(PUBLISH_WAIT_SECONDS)
    wait_for_saves(PUBLISH_WAIT_SECONDS)  # an executable being stored: no temporary file left
    _say_last(f"jaxgrasp: {_WORDS.get(signum, 'interrupted')}" + "".join(f"; {n}" for n in notes))
    status = EXIT_STATUS.get(signum, 130)
    _exit(status)
    return status  # only where _exit was replaced


def _say_last(line: str) -> None:
    """Print ``line`` on stderr as the process's last output.

    Where stderr is file descriptor 2, descriptors 1 and 2 are first pointed to
    ``os.devnull`` (the line goes to a copy of 2), so nothing the worker thread or XLA
    still prints can follow it.
    """
    _flush(sys.stdout)
    _flush(sys.stderr)
    try:
        if sys.stderr.fileno() != 2:
            raise OSError("stderr is not file descriptor 2")
        err = os.dup(2)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os.write(err, (line + "\n").encode("utf-8", "replace"))
    except (OSError, ValueError, AttributeError):  # captured or closed stderr: print
        try:
            print(line, file=sys.stderr)
        except Exception:  # pragma: no cover - stderr gone: the status still tells
            pass
        _flush(sys.stderr)


def _flush(stream) -> None:
    try:
        stream.flush()
    except Exception:  # pragma: no cover - a closed or broken pipe
        pass
