"""What a command says it keeps: the notes an interrupt prints, what a failed write's
error adds, and the writes an interrupt makes first.

The library writes files and raises errors; the words the ``jaxgrasp`` command prints
about them are chosen here. A command leaves, while it runs:

* notes (`set_note`), which an interrupt prints on its one line
  (``jaxgrasp: interrupted; kept 128 of 369 points in out/sweep.partial.npz``);
* what is kept if a later write fails (`set_keeping`), which a full disk's error
  line adds (`keeping`);
* a last write (`set_last_write`), which an interrupt makes before it stops every
  write (`abandon`), e.g. a sweep's checkpoint that was skipped to save time.

The command's checkpoints leave theirs through `_keepers`.
"""

from __future__ import annotations

import threading
from typing import Callable

from jaxgrasp import storage

__all__ = ["set_note", "set_keeping", "keeping", "set_last_write", "clear_notes", "abandon"]

_LOCK = threading.Lock()  # guards the three below: the command's thread writes, an interrupt reads
_NOTES: dict[str, str] = {}
_KEEPING: dict[str, str] = {}
_LAST_WRITES: dict[str, Callable[[], object]] = {}


def set_note(key: str, text: str) -> None:
    """Leave a note for an interrupt (`abandon` returns them), e.g. where a sweep's
    finished points are; replaces the note of the same ``key``."""
    with _LOCK:
        _NOTES[key] = text


def set_last_write(key: str, write: Callable[[], object] | None) -> None:
    """Leave ``write()`` for an interrupt to run first (`abandon`), e.g. the
    checkpoint of the points a sweep finished since its last one; ``None`` withdraws the
    ``key``'s. It runs in the interrupted thread while the command's worker may still run,
    so it must read only what the worker no longer changes."""
    with _LOCK:
        if write is None:
            _LAST_WRITES.pop(key, None)
        else:
            _LAST_WRITES[key] = write


def set_keeping(key: str, text: str | None) -> None:
    """Say what is kept if a later write fails (`keeping`), e.g. ``finished chunks
    kept in DIR, rerun with --resume``; ``None`` withdraws the ``key``'s."""
    with _LOCK:
        if text is None:
            _KEEPING.pop(key, None)
        else:
            _KEEPING[key] = text


def keeping() -> list[str]:
    """What `set_keeping` said is kept, oldest first (for a failed write's error)."""
    with _LOCK:
        return list(_KEEPING.values())


def clear_notes() -> None:
    """Forget every note, last write and `keeping` (a command's notes end with it)."""
    with _LOCK:
        _NOTES.clear()
        _LAST_WRITES.clear()
        _KEEPING.clear()


def abandon(timeout: float = 0.5) -> list[str]:
    """Stop every write of this process for good, for an exit on an interrupt.

    First runs the last writes left with `set_last_write` (a failing one is
    skipped: its previous file stays), then `jaxgrasp.storage.abandon` (waits at
    most ``timeout`` seconds for a set being renamed into place, removes this process's
    temporary files and lock files, forbids later writes).

    Returns:
        The notes left with `set_note`, oldest first.
    """
    with _LOCK:
        last_writes = list(_LAST_WRITES.values())
        _LAST_WRITES.clear()
    for write in last_writes:
        try:
            write()
        except Exception:  # noqa: BLE001 - an exit is under way; the previous file stays
            pass
    storage.abandon(timeout)
    with _LOCK:
        return list(_NOTES.values())
