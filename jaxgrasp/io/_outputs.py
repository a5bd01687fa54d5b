"""Output files that are whole or absent: checked first, written aside, renamed as one set.

Every file jaxgrasp writes goes through :func:`write_set` (or :func:`write_file`, a set of
one). Each member is first written to a temporary file in its destination folder
(``NAME.<pid>-<token>.tmp``), flushed and ``fsync``-ed; only when every member is complete
are they renamed over their destinations (``os.replace``), all under one process-wide lock
(:data:`PUBLISH_LOCK`). So a reader, or a run that stops half-way, sees either the
previous set or the new one, never a new file beside an old one; a failure while writing
removes the temporary files and leaves the previous set as it was.

The rest is for commands that may be interrupted (``jaxgrasp.cli``):

* :func:`check_writable`: can files be created in a folder? Asked before any
  computation, without creating anything.
* :class:`FolderLock`: one writer per output folder (a lock file ``.jaxgrasp.lock`` held
  with ``flock`` and holding the writer's pid); taking it also removes the stale temporary
  files of killed runs (:func:`remove_stale_temps`).
* :func:`abandon`: on an interrupt, wait for a rename phase in progress (at most a
  moment), delete this process's temporary files and lock files, and forbid every later
  write; it returns the notes commands left for that moment (:func:`set_note`), e.g.
  where a sweep kept its finished points.

Links are never followed where jaxgrasp writes: temporary files are created with
``O_CREAT | O_EXCL | O_NOFOLLOW`` under a random name, the lock file is opened with
``O_NOFOLLOW`` (a link there is refused, :class:`OutputError`), and ``os.replace`` and
``os.unlink`` act on a link itself, never on its target (:func:`read_own` reads a file of
jaxgrasp's own without following one). A full disk (``ENOSPC``, ``EDQUOT``, ``EFBIG``)
while writing is a :class:`DiskFull` naming the file, its temporary file removed.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import stat
import threading
import time
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable, Mapping, Sequence, Union

import numpy as np

__all__ = [
    "OutputError",
    "FolderBusy",
    "DiskFull",
    "Abandoned",
    "NO_SPACE",
    "TEMP_SUFFIX",
    "LOCK_NAME",
    "PUBLISH_LOCK",
    "check_writable",
    "write_file",
    "write_to",
    "csv_content",
    "csv_cell",
    "write_set",
    "FolderLock",
    "refuse_link",
    "read_own",
    "remove_stale_temps",
    "STALE_TEMP_SECONDS",
    "set_note",
    "set_keeping",
    "keeping",
    "set_last_write",
    "clear_notes",
    "abandon",
]

TEMP_SUFFIX = ".tmp"
"""Suffix of every temporary file (``NAME.<pid>-<token>.tmp`` beside its destination)."""

LOCK_NAME = ".jaxgrasp.lock"
"""Name of the lock file :class:`FolderLock` keeps in the folder it guards."""

STALE_TEMP_SECONDS = 3600.0
"""A temporary file of jaxgrasp's naming older than this (s) is stale even if its pid runs
(pids are reused)."""

NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""``errno`` values of a write that failed for want of space: a :class:`DiskFull`."""

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)  # 0 where the platform lacks it (Windows: no symlinks by default)
_TEMP_NAME = re.compile(r".+\.(\d+)-[0-9a-f]{8}" + re.escape(TEMP_SUFFIX))  # NAME.<pid>-<token>.tmp, fullmatch

PUBLISH_LOCK = threading.Lock()
"""Held while a set of files is renamed into place (and forever after :func:`abandon`)."""

Content = Union[bytes, Callable[[BinaryIO], object]]
"""What a member of a set holds: its bytes, or ``write(fh)`` writing them to a binary file."""

_REGISTRY = threading.Lock()  # guards the three below
_TEMPS: set[Path] = set()  # temporary files of this process not yet renamed or removed
_LOCKS: set["FolderLock"] = set()  # folder locks held by this process
_LAST_WRITES: dict[str, Callable[[], object]] = {}  # run by abandon() before it stops writing
_ABANDONED = False
_NOTES: dict[str, str] = {}
_KEEPING: dict[str, str] = {}  # what a failed write leaves, for its one-line error (set_keeping)


class OutputError(Exception):
    """An output folder or file that cannot be written (one line)."""


class FolderBusy(OutputError):
    """Another process holds the :class:`FolderLock` of the folder; ``.pid`` is its pid
    (``None`` when its lock file does not say)."""

    def __init__(self, message: str, pid: int | None):
        super().__init__(message)
        self.pid = pid


class Abandoned(OutputError):
    """A write the command tried after an interrupt abandoned output writing
    (:func:`abandon`): the interrupt's own handler says what was kept, in the process's
    last line, so the command ends without a line of its own."""


class DiskFull(OutputError):
    """A write failed for want of space (``errno`` in :data:`NO_SPACE`); ``.path`` is the
    file being written. Its temporary file is removed; what was published stays."""

    def __init__(self, path, exc: OSError):
        super().__init__(f"{(exc.strerror or 'no space left on device').lower()} writing {path}")
        self.path = Path(path)
        self.errno = exc.errno


def _no_space(exc: BaseException, path) -> BaseException:
    """``exc`` as a :class:`DiskFull` of ``path`` where it, or an exception it was raised
    from or while handling (a writer's clean-up failing in turn), is a want of space;
    else ``exc`` itself."""
    cause: BaseException | None = exc
    for _ in range(8):  # a short chain; never a cycle
        if cause is None or isinstance(cause, OutputError):
            break
        if isinstance(cause, OSError) and cause.errno in NO_SPACE:
            return DiskFull(path, cause)
        cause = cause.__cause__ or cause.__context__
    return exc


# --------------------------------------------------------------------------- checks


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (``lexists``: a path under a regular
    file does not exist)."""
    p = path
    while not os.path.lexists(p) and p.parent != p:
        p = p.parent
    return p


def check_writable(folder) -> Path:
    """Check that files can be created in ``folder`` without creating anything there.

    ``folder`` need not exist; then its nearest existing ancestor must be a folder in
    which ``folder`` can be created. A probe file is created and removed in the folder
    (or that ancestor), so read-only folders and file systems are caught, not just
    permission bits.

    Returns:
        ``folder`` as a :class:`~pathlib.Path`.

    Raises:
        OutputError: (one line) ``folder`` or an ancestor is a regular file, or no file
            can be created there.
    """
    folder = Path(folder)
    where = _nearest_existing(folder)
    if not where.is_dir():
        if where == folder:
            raise OutputError(f"{str(folder)!r} exists and is not a folder")
        raise OutputError(f"cannot create folder {str(folder)!r}: {str(where)!r} is a file, not a folder")
    try:
        fd, probe = _create_temp(where / "jaxgrasp-probe")
    except OSError as exc:
        what = "folder" if where == folder else f"folder {str(where)!r}, where it would be created,"
        raise OutputError(f"cannot write to {str(folder)!r}: the {what} is not writable ({exc.strerror})") from None
    os.close(fd)
    _discard(probe)
    return folder


# --------------------------------------------------------------------------- temporary files


_LOCK_TRIES = 100  # lock files replaced under us before giving up (each: a holder that just left)
_TEMP_TRIES = 8  # names tried before giving up: only a name planted by guessing collides


def _create_temp(dest: Path) -> tuple[int, Path]:
    """Create and register a new temporary file beside ``dest``; ``(fd, path)``.

    The name has a random token and is created exclusively, never through a link
    (``O_CREAT | O_EXCL | O_NOFOLLOW``): where something has that name already (a link
    planted there too) another token is drawn. Registration and creation happen under
    one lock, so :func:`abandon` removes every temporary file that exists, and none is
    created after it.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    with _REGISTRY:
        if _ABANDONED:
            raise Abandoned("output writing was abandoned (interrupted)")
        for _ in range(_TEMP_TRIES):
            tmp = dest.with_name(f"{dest.name}.{os.getpid()}-{secrets.token_hex(4)}{TEMP_SUFFIX}")
            try:
                fd = os.open(tmp, flags, 0o666)  # the umask applies
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(errno.EEXIST, "every temporary file name tried exists", str(dest))
        _TEMPS.add(tmp)
        return fd, tmp


def _discard(tmp: Path) -> None:
    """Remove a temporary file of this process (nothing if it was renamed or removed)."""
    with _REGISTRY:
        if tmp in _TEMPS:
            _TEMPS.discard(tmp)
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass


def _stage(dest: Path, content: Content) -> Path:
    """Write ``content`` to a new temporary file beside ``dest``, on disk (``fsync``); its path.

    Raises:
        DiskFull: no space for it (the temporary file is removed, as on any failure).
    """
    try:
        fd, tmp = _create_temp(dest)
    except OSError as exc:
        raise _no_space(exc, dest) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            if isinstance(content, (bytes, bytearray, memoryview)):
                fh.write(content)
            else:
                content(fh)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException as exc:
        _discard(tmp)
        full = _no_space(exc, dest)
        if full is exc:
            raise
        raise full from None  # one line: the OSError's context says nothing more
    return tmp


def _fsync_folder(folder: Path) -> None:
    """Make the renames in ``folder`` durable (where the platform allows it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- sets


def write_set(
    members: Mapping[object, Content],
    *,
    remove: Iterable = (),
    on_publish: Callable[[], object] | None = None,
) -> list[Path]:
    """Write several files as one set: all of them, or none (the previous ones stay).

    Args:
        members: destination path -> its bytes, or ``write(fh)`` that writes them to a
            binary file object. The destination folders must exist.
        remove: paths deleted in the same rename phase (e.g. a member of the previous
            set that the new set no longer has); missing ones are ignored.
        on_publish: called once the set is in place, still under :data:`PUBLISH_LOCK`
            (so an interrupt sees the state before or after both).

    Returns:
        The destinations that replaced an existing file.

    Raises:
        DiskFull: no space for a member (an :class:`OutputError` naming it); nothing was
            replaced, and every temporary file is gone.
        OSError or whatever a ``write`` raises: likewise.
        OutputError: writing was abandoned (:func:`abandon`).
    """
    staged: list[tuple[Path, Path]] = []
    try:
        for dest, content in members.items():
            dest = Path(dest)
            staged.append((_stage(dest, content), dest))
        return _publish(staged, [Path(p) for p in remove], on_publish)
    finally:
        for tmp, _ in staged:
            _discard(tmp)  # nothing left when they were renamed


def _publish(staged, remove, on_publish) -> list[Path]:
    """Rename the staged files over their destinations and delete ``remove``, under the lock."""
    with PUBLISH_LOCK:
        replaced = [dest for _, dest in staged if os.path.lexists(dest)]
        for tmp, dest in staged:
            try:
                os.replace(tmp, dest)  # a link at dest is replaced itself, its target untouched
            except OSError as exc:  # a folder that must grow for the new name
                raise _no_space(exc, dest) from None
            with _REGISTRY:
                _TEMPS.discard(tmp)
        for path in remove:
            try:
                os.unlink(path)  # a link is removed, not its target
            except FileNotFoundError:
                pass
        for folder in {dest.parent for _, dest in staged} | {p.parent for p in remove}:
            _fsync_folder(folder)
        if on_publish is not None:
            on_publish()
    return replaced


def write_file(path, content: Content) -> bool:
    """Write one file atomically (:func:`write_set` of one member).

    Returns:
        Whether it replaced an existing file.
    """
    return bool(write_set({path: content}))


def write_to(target, content: Content) -> None:
    """Write ``content`` (bytes, or ``write(fh)``) into ``target``: a binary file object
    directly, or the file at path ``target`` atomically (:func:`write_file`)."""
    if hasattr(target, "write"):
        target.write(content) if isinstance(content, bytes) else content(target)
    else:
        write_file(target, content)


def csv_cell(x) -> str:
    """A number as a CSV cell: floats with 17 significant digits (they read back exactly;
    NaN as an empty cell), booleans ``True``/``False``, integers as they are."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return "" if np.isnan(x) else repr(float(x))


def csv_content(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Callable[[BinaryIO], None]:
    """``write(fh)`` writing a UTF-8 CSV table (``header``, then ``rows``) to a binary file."""
    import csv
    import io

    def write(binary: BinaryIO) -> None:
        fh = io.TextIOWrapper(binary, encoding="utf-8", newline="")
        try:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(rows)
        finally:
            fh.detach()  # flushed; the binary file stays open for its owner

    return write


# --------------------------------------------------------------------------- folder lock


class FolderLock:
    """One writer per folder: the lock file ``folder/.jaxgrasp.lock``, held with ``flock``.

    The file holds the pid of the process that holds it, for the message of a second
    writer. The kernel releases the ``flock`` when its process ends in any way, so a lock
    file left by a killed process (a *stale* lock) is simply taken over; its pid is
    never trusted (pids are reused). On platforms without ``fcntl`` (Windows) the lock
    does nothing.

    The lock file is opened without following a link (``O_NOFOLLOW``): a link, or
    anything but a file with one name (a hard link could name a file elsewhere), at its
    path is refused, since taking the lock truncates the file.

    Use as a context manager (or :meth:`acquire`, which does nothing where the lock is
    already held, and :meth:`release`); :meth:`acquire` creates ``folder`` if needed and,
    once the lock is held, removes the folder's stale temporary files
    (:func:`remove_stale_temps`).
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self._fd: int | None = None

    def acquire(self) -> "FolderLock":
        """Take the lock now or fail at once.

        Raises:
            FolderBusy: another process (or another lock of this one) holds it.
            OutputError: a link or other non-file at the lock file's path (one line);
                :class:`DiskFull` where there is no space for it.
            OSError: the folder or the lock file cannot be created.
        """
        if self._fd is not None:
            return self
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX
            return self
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            fd = self._open_locked(fcntl)
        except OSError as exc:
            raise _no_space(exc, self.path) from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError as exc:
            os.close(fd)  # the flock goes with it
            raise _no_space(exc, self.path) from None
        self._fd = fd
        with _REGISTRY:
            _LOCKS.add(self)
        remove_stale_temps(self.folder)
        return self

    def _open_locked(self, fcntl) -> int:
        """The lock file's descriptor, ``flock``-ed (see :meth:`acquire`)."""
        for _ in range(_LOCK_TRIES):
            fd = _open_own(self.path, os.O_RDWR | os.O_CREAT)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = _read_pid(fd)
                os.close(fd)
                who = f"pid {pid}" if pid is not None else "pid unknown"
                raise FolderBusy(
                    f"{str(self.folder)!r} is being written by another jaxgrasp process ({who}); "
                    "wait for it or choose another folder",
                    pid,
                ) from None
            if _same_file(fd, self.path):  # not a file its last holder removed meanwhile
                return fd
            os.close(fd)
        raise OutputError(f"{str(self.path)!r} keeps being replaced while jaxgrasp takes it: is another program there?")

    def release(self) -> None:
        """Remove the lock file and release the lock (nothing if not held)."""
        with _REGISTRY:
            _LOCKS.discard(self)
            self._drop()

    def _drop(self) -> None:
        # removed while still locked: a waiting process then finds it gone and retries
        if self._fd is None:
            return
        try:
            os.unlink(self.path)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        return int(text) if text else None
    except (OSError, ValueError):
        return None


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.lstat(path))
    except FileNotFoundError:
        return False


# --------------------------------------------------------------------------- links


def refuse_link(path, what: str = "jaxgrasp's file") -> None:
    """Raise :class:`OutputError` (one line) if ``path`` is a symbolic link: jaxgrasp writes
    ``what`` there and never writes, reads or deletes through a link it did not make."""
    if os.path.islink(path):
        raise OutputError(
            f"{str(path)!r} is a symbolic link where jaxgrasp keeps {what}; it is not followed: "
            "remove the link or choose another --out"
        )


def _open_own(path: Path, flags: int) -> int:
    """Open a file of jaxgrasp's own (lock, checkpoint) without following a link; it must
    be a regular file with one name. The descriptor.

    Raises:
        OutputError: a link or anything else at ``path`` (one line).
        OSError: as ``os.open`` (``FileNotFoundError`` where it is missing).
    """
    try:
        fd = os.open(path, flags | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.EMLINK) or os.path.islink(path):  # ELOOP: O_NOFOLLOW met a link
            refuse_link(path)
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        kind = "a file with other names (hard links)" if stat.S_ISREG(st.st_mode) else "not a regular file"
        raise OutputError(f"{str(path)!r} is {kind}; jaxgrasp keeps its own file there: remove it")
    return fd


def read_own(path, limit: int | None = None) -> bytes:
    """The bytes of a file of jaxgrasp's own (a checkpoint's) at ``path``, read without
    following a link.

    Args:
        limit: the most bytes it may hold (a larger file is refused: nothing is read).

    Raises:
        OutputError: a link, not a regular file, or larger than ``limit`` (one line).
        OSError: it cannot be read (``FileNotFoundError`` where it is missing).
    """
    fd = _open_own(Path(path), os.O_RDONLY)
    try:
        size = os.fstat(fd).st_size
        if limit is not None and size > limit:
            raise OutputError(f"{str(path)!r} holds {size} bytes, more than the {limit} it may")
        chunks = []
        while chunk := os.read(fd, 1 << 20):
            chunks.append(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def remove_stale_temps(folder) -> int:
    """Remove the temporary files killed runs left in ``folder``; how many.

    A temporary file is stale where its name has jaxgrasp's pattern
    (``NAME.<pid>-<token>.tmp``) and its process no longer runs, it is older than
    :data:`STALE_TEMP_SECONDS`, or its pid is this process's but it is not one of this
    process's (a pid reused). Only regular files are removed (a link is left alone), and
    nothing that cannot be removed stops the caller.
    """
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    with _REGISTRY:
        mine = set(_TEMPS)
    for entry in entries:
        m = _TEMP_NAME.fullmatch(entry.name)
        try:
            if m is None or not entry.is_file(follow_symlinks=False) or Path(entry.path) in mine:
                continue
            if _pid_runs(int(m[1])) and time.time() - entry.stat(follow_symlinks=False).st_mtime < STALE_TEMP_SECONDS:
                continue
            os.unlink(entry.path)
            removed += 1
        except OSError:
            continue
    return removed


def _pid_runs(pid: int) -> bool:
    """Whether a process ``pid`` runs (other than this one: its temporary files are known)."""
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    except (OSError, OverflowError, ValueError):
        return False
    return True


# --------------------------------------------------------------------------- interrupts


def set_note(key: str, text: str) -> None:
    """Leave a note for an interrupt (:func:`abandon` returns them), e.g. where a sweep's
    finished points are; replaces the note of the same ``key``."""
    with _REGISTRY:
        _NOTES[key] = text


def set_last_write(key: str, write: Callable[[], object] | None) -> None:
    """Leave ``write()`` for an interrupt to run first (:func:`abandon`), e.g. the
    checkpoint of the points a sweep finished since its last one; ``None`` withdraws the
    ``key``'s. It runs in the interrupted thread while the command's worker may still run,
    so it must read only what the worker no longer changes."""
    with _REGISTRY:
        if write is None:
            _LAST_WRITES.pop(key, None)
        else:
            _LAST_WRITES[key] = write


def set_keeping(key: str, text: str | None) -> None:
    """Say what is kept if a later write fails (:func:`keeping`), e.g. ``finished chunks
    kept in DIR, rerun with --resume``; ``None`` withdraws the ``key``'s."""
    with _REGISTRY:
        if text is None:
            _KEEPING.pop(key, None)
        else:
            _KEEPING[key] = text


def keeping() -> list[str]:
    """What :func:`set_keeping` said is kept, oldest first (for a failed write's error)."""
    with _REGISTRY:
        return list(_KEEPING.values())


def clear_notes() -> None:
    """Forget every note, last write and :func:`keeping` (a command's notes end with it)."""
    with _REGISTRY:
        _NOTES.clear()
        _LAST_WRITES.clear()
        _KEEPING.clear()


def abandon(timeout: float = 0.5) -> list[str]:
    """Stop every write of this process for good, for an exit on an interrupt.

    First runs the last writes left with :func:`set_last_write` (a failing one is
    skipped: its previous file stays). Then waits at most ``timeout`` seconds for a
    rename phase in progress (so a set is never published half), then keeps
    :data:`PUBLISH_LOCK` (nothing is published after this), deletes every temporary file
    and lock file of this process and makes later writes raise :class:`OutputError`.
    Meant to be followed by ``os._exit``.

    Returns:
        The notes left with :func:`set_note`, oldest first.
    """
    global _ABANDONED
    with _REGISTRY:
        last_writes = list(_LAST_WRITES.values())
        _LAST_WRITES.clear()
    for write in last_writes:
        try:
            write()
        except Exception:  # noqa: BLE001 - an exit is under way; the previous file stays
            pass
    PUBLISH_LOCK.acquire(timeout=timeout)  # never released
    with _REGISTRY:
        _ABANDONED = True
        for tmp in list(_TEMPS):
            try:
                os.unlink(tmp)
            except OSError:
                pass
        _TEMPS.clear()
        for lock in list(_LOCKS):
            lock._drop()
        _LOCKS.clear()
        return list(_NOTES.values())
