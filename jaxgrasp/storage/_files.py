"""Files that are whole or absent: written aside, synced, renamed into place as one set.

Every file jaxgrasp writes (outputs, checkpoints, stored executables) goes through
`write_set` (or `write_file`, a set of one). Each member is first written to
a temporary file in its destination folder (``NAME.<pid>-<token>.tmp``, created
exclusively and never through a link), flushed and ``fsync``-ed; only when every member
is complete are they renamed over their destinations (``os.replace``), all under one
process-wide lock (`PUBLISH_LOCK`). So a reader, or a run that stops half-way,
sees either the previous set or the new one, never a new file beside an old one; a
failure while writing removes the temporary files and leaves the previous set as it was.

The rest serves writers that may be interrupted or killed:

* `check_writable`: can files be created in a folder? Asked before any long
  computation, without creating anything.
* `remove_stale_temps`: the temporary files killed processes left in a folder
  (their process gone, or older than `STALE_TEMP_SECONDS`).
* `abandon`: on an interrupt, wait for a rename phase in progress (at most a
  moment), delete this process's temporary files and the lock files it holds
  (`FolderLock`), and forbid every later write.

A full disk (``ENOSPC``, ``EDQUOT``, ``EFBIG``) while writing is a `DiskFull`
naming the file, its temporary file removed.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import threading
import time
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, Mapping, Union

__all__ = [
    "OutputError",
    "FolderBusy",
    "DiskFull",
    "Abandoned",
    "NO_SPACE",
    "TEMP_SUFFIX",
    "STALE_TEMP_SECONDS",
    "PUBLISH_LOCK",
    "Content",
    "check_writable",
    "write_set",
    "write_file",
    "write_to",
    "remove_stale_temps",
    "register_lock",
    "release_lock",
    "abandon",
]

TEMP_SUFFIX = ".tmp"
"""Suffix of every temporary file (``NAME.<pid>-<token>.tmp`` beside its destination)."""

STALE_TEMP_SECONDS = 3600.0
"""Age (s) after which a temporary file of jaxgrasp's naming is stale even if its process
runs (pids are reused)."""

NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""``errno`` values of a write that failed for want of space: a `DiskFull`."""

NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)  # 0 where the platform lacks it (Windows: no symlinks by default)

_TEMP_NAME = re.compile(r".+\.(?P<pid>\d+)-[0-9a-f]{8}" + re.escape(TEMP_SUFFIX))
"""The name of a temporary file (full match): ``NAME.<pid>-<token>.tmp``."""

_STORE_TEMP_NAMES = (
    re.compile(r"\.[^/]+\.(?P<pid>\d+)\.[0-9a-f]+\.tmp"),  # .NAME.PID.RANDOM.tmp
    re.compile(r"[\w.-]+\.tmp(?P<pid>\d+)"),  # NAME.tmpPID
)
"""Names the executable store's temporary files had in earlier versions (full match)."""

PUBLISH_LOCK = threading.Lock()
"""Held while a set of files is renamed into place (and forever after `abandon`)."""

Content = Union[bytes, Callable[[BinaryIO], object]]
"""What a member of a set holds: its bytes, or ``write(fh)`` writing them to a binary file."""

REGISTRY = threading.Lock()  # guards the registries below
_TEMPS: set[Path] = set()  # temporary files of this process not yet renamed or removed
_LOCKS: set = set()  # folder locks held by this process (FolderLock, released by abandon)
_ABANDONED = False


class OutputError(Exception):
    """An output folder or file that cannot be written (one line)."""


class FolderBusy(OutputError):
    """Another process holds the `FolderLock` of the folder;
    ``.pid`` is its pid (``None`` when its lock file does not say)."""

    def __init__(self, message: str, pid: int | None):
        super().__init__(message)
        self.pid = pid


class Abandoned(OutputError):
    """A write tried after `abandon` stopped every write of the process (an
    interrupt, whose handler says what was kept)."""


class DiskFull(OutputError):
    """A write failed for want of space (``errno`` in `NO_SPACE`); ``.path`` is the
    file being written. Its temporary file is removed; what was published stays."""

    def __init__(self, path, exc: OSError):
        super().__init__(f"{(exc.strerror or 'no space left on device').lower()} writing {path}")
        self.path = Path(path)
        self.errno = exc.errno


def no_space(exc: BaseException, path) -> BaseException:
    """``exc`` as a `DiskFull` of ``path`` where it, or an exception it was raised
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
        ``folder`` as a `Path`.

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
        fd, probe = _create_temp(where / "jaxgrasp-probe", 0o666)
    except OSError as exc:
        what = "folder" if where == folder else f"folder {str(where)!r}, where it would be created,"
        raise OutputError(f"cannot write to {str(folder)!r}: the {what} is not writable ({exc.strerror})") from None
    os.close(fd)
    _discard(probe)
    return folder


# --------------------------------------------------------------------------- temporary files


_TEMP_TRIES = 8  # names tried before giving up: only a name planted by guessing collides


def _create_temp(dest: Path, mode: int) -> tuple[int, Path]:
    """Create and register a new temporary file beside ``dest`` with ``mode`` (less the
    umask); ``(fd, path)``.

    The name has a random token and is created exclusively, never through a link
    (``O_CREAT | O_EXCL | O_NOFOLLOW``): where something has that name already (a link
    planted there too) another token is drawn. Registration and creation happen under
    one lock, so `abandon` removes every temporary file that exists, and none is
    created after it.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    with REGISTRY:
        if _ABANDONED:
            raise Abandoned("output writing was abandoned (interrupted)")
        for _ in range(_TEMP_TRIES):
            tmp = dest.with_name(f"{dest.name}.{os.getpid()}-{secrets.token_hex(4)}{TEMP_SUFFIX}")
            try:
                fd = os.open(tmp, flags, mode)
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(errno.EEXIST, "every temporary file name tried exists", str(dest))
        _TEMPS.add(tmp)
        return fd, tmp


def _discard(tmp: Path) -> None:
    """Remove a temporary file of this process (nothing if it was renamed or removed)."""
    with REGISTRY:
        if tmp in _TEMPS:
            _TEMPS.discard(tmp)
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass


def _stage(dest: Path, content: Content, mode: int) -> Path:
    """Write ``content`` to a new temporary file beside ``dest``, on disk (``fsync``); its path.

    Raises:
        DiskFull: no space for it (the temporary file is removed, as on any failure).
    """
    try:
        fd, tmp = _create_temp(dest, mode)
    except OSError as exc:
        raise no_space(exc, dest) from None
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
        full = no_space(exc, dest)
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
    mode: int = 0o666,
) -> list[Path]:
    """Write several files as one set: all of them, or none (the previous ones stay).

    Args:
        members: destination path -> its bytes, or ``write(fh)`` that writes them to a
            binary file object. The destination folders must exist.
        remove: paths deleted in the same rename phase (e.g. a member of the previous
            set that the new set no longer has); missing ones are ignored.
        on_publish: called once the set is in place, still under `PUBLISH_LOCK`
            (so an interrupt sees the state before or after both).
        mode: the new files' permission bits, less the umask (``0o600``: the user's alone).

    Returns:
        The destinations that replaced an existing file.

    Raises:
        DiskFull: no space for a member (an `OutputError` naming it); nothing was
            replaced, and every temporary file is gone.
        OSError or whatever a ``write`` raises: likewise.
        Abandoned: writing was abandoned (`abandon`).
    """
    staged: list[tuple[Path, Path]] = []
    try:
        for dest, content in members.items():
            dest = Path(dest)
            staged.append((_stage(dest, content, mode), dest))
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
                raise no_space(exc, dest) from None
            with REGISTRY:
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


def write_file(path, content: Content, *, mode: int = 0o666) -> bool:
    """Write one file atomically (`write_set` of one member).

    Returns:
        Whether it replaced an existing file.
    """
    return bool(write_set({path: content}, mode=mode))


def write_to(target, content: Content) -> None:
    """Write ``content`` (bytes, or ``write(fh)``) into ``target``: a binary file object
    directly, or the file at path ``target`` atomically (`write_file`)."""
    if hasattr(target, "write"):
        target.write(content) if isinstance(content, bytes) else content(target)
    else:
        write_file(target, content)


# --------------------------------------------------------------------------- stale temporary files


def remove_stale_temps(folder, *, earlier_store_names: bool = False) -> int:
    """Remove the temporary files killed runs left in ``folder``; how many.

    A temporary file is stale where its name has jaxgrasp's pattern (``NAME.<pid>-<token>.tmp``)
    and its process no longer runs or it is older than `STALE_TEMP_SECONDS`; this
    process's own temporary files are never stale. With ``earlier_store_names`` (a folder
    of the executable store) the names its temporary files had in earlier versions
    (``.NAME.PID.RANDOM.tmp``, ``NAME.tmpPID``) count too; elsewhere they could be the
    user's. Only regular files are removed (a link is left alone), and nothing that
    cannot be removed stops the caller.
    """
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    with REGISTRY:
        mine = set(_TEMPS)
    patterns = (_TEMP_NAME, *_STORE_TEMP_NAMES) if earlier_store_names else (_TEMP_NAME,)
    for entry in entries:
        match = next((m for p in patterns if (m := p.fullmatch(entry.name))), None)
        try:
            if match is None or not entry.is_file(follow_symlinks=False) or Path(entry.path) in mine:
                continue
            age = time.time() - entry.stat(follow_symlinks=False).st_mtime
            if _pid_runs(int(match["pid"])) and age < STALE_TEMP_SECONDS:
                continue
            os.unlink(entry.path)
            removed += 1
        except OSError:
            continue
    return removed


def _pid_runs(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine (this one included)."""
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


def register_lock(lock) -> None:
    """Record that this process holds ``lock`` (an object whose ``_drop()`` removes its
    lock file and releases it), so that `abandon` releases it."""
    with REGISTRY:
        _LOCKS.add(lock)


def release_lock(lock) -> None:
    """Release ``lock`` (``lock._drop()``) and forget it, under the registry's lock, so
    that `abandon` never releases it a second time."""
    with REGISTRY:
        _LOCKS.discard(lock)
        lock._drop()


def abandon(timeout: float = 0.5) -> None:
    """Stop every write of this process for good, for an exit on an interrupt.

    Waits at most ``timeout`` seconds for a rename phase in progress (so a set is never
    published half), then keeps `PUBLISH_LOCK` (nothing is published after this),
    deletes every temporary file and lock file of this process and makes later writes
    raise `Abandoned`. Meant to be followed by ``os._exit``.
    """
    global _ABANDONED
    PUBLISH_LOCK.acquire(timeout=timeout)  # never released
    with REGISTRY:
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
