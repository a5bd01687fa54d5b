"""Files and folders of jaxgrasp's own, never reached through a link: lock files,
checkpoints, and the private folders and files of the executable store.

* `refuse_link`, `read_own`: a file jaxgrasp keeps (a lock file, a
  checkpoint) is opened without following a link and must be a regular file with one
  name (a link there is refused, `OutputError`).
* `FolderLock`: one writer per folder (a lock file ``.jaxgrasp.lock`` held with
  ``flock`` and holding the writer's pid); taking it also removes the stale temporary
  files of killed runs (`remove_stale_temps`).
* `private_folder`, `read_private`: a folder or file that only this user can
  have written (owned by the user, not writable by group or others, not a link), for
  what is loaded and run (the executable store's pickles); `make_private` creates
  folders that are (mode 0700, every level).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from jaxgrasp.storage._files import (
    NOFOLLOW,
    FolderBusy,
    OutputError,
    no_space,
    register_lock,
    release_lock,
    remove_stale_temps,
)

__all__ = [
    "LOCK_NAME",
    "FolderLock",
    "refuse_link",
    "read_own",
    "NotPrivate",
    "make_private",
    "private_folder",
    "read_private",
]

LOCK_NAME = ".jaxgrasp.lock"
"""Name of the lock file `FolderLock` keeps in the folder it guards."""

_LOCK_TRIES = 100  # lock files replaced under us before giving up (each: a holder that just left)


# --------------------------------------------------------------------------- links


def refuse_link(path, what: str = "jaxgrasp's file") -> None:
    """Raise `OutputError` (one line) if ``path`` is a symbolic
    link: jaxgrasp writes ``what`` there and never writes, reads or deletes through a link
    it did not make."""
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
        fd = os.open(path, flags | NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0), 0o666)
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


def _read_fd(fd: int, limit: int | None = None) -> bytes:
    """The bytes of ``fd`` to its end; an ``OSError`` (``EFBIG``) past ``limit`` bytes
    (a file that grew while it was read)."""
    chunks, total = [], 0
    while chunk := os.read(fd, 1 << 20):
        chunks.append(chunk)
        total += len(chunk)
        if limit is not None and total > limit:
            raise OSError(errno.EFBIG, f"it grew past the {limit:,} bytes read at most while it was read")
    return b"".join(chunks)


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
        return _read_fd(fd)
    finally:
        os.close(fd)


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

    Use as a context manager (or `acquire`, which does nothing where the lock is
    already held, and `release`); `acquire` creates ``folder`` if needed and,
    once the lock is held, removes the folder's stale temporary files
    (`remove_stale_temps`).
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
                `DiskFull` where there is no space for it.
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
            raise no_space(exc, self.path) from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError as exc:
            os.close(fd)  # the flock goes with it
            raise no_space(exc, self.path) from None
        self._fd = fd
        register_lock(self)
        remove_stale_temps(self.folder)
        return self

    def _open_locked(self, fcntl) -> int:
        """The lock file's descriptor, ``flock``-ed (see `acquire`)."""
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
        release_lock(self)

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


# --------------------------------------------------------------------------- private folders and files


class NotPrivate(Exception):
    """A file another user could have written (the message says why): not read."""


def make_private(folder: Path) -> None:
    """Create ``folder`` and its missing parents, each with mode 0700 whatever the umask;
    raises ``OSError`` where it cannot. Folders that exist are left as they are."""
    missing = []
    for level in (folder, *folder.parents):
        if os.path.lexists(level):
            break
        missing.append(level)
    for level in reversed(missing):
        try:
            os.mkdir(level, 0o700)
        except FileExistsError:  # made by another process meanwhile: checked as any other
            continue
        os.chmod(level, 0o700)  # the umask may have removed the owner's bits


def _not_private(st: os.stat_result, kind: str) -> str | None:
    """Why a file or folder with status ``st`` (of ``lstat`` or ``fstat``) could hold what
    another user wrote; ``None`` where it is the user's alone. ``kind``: ``"folder"`` or
    ``"file"``."""
    if stat.S_ISLNK(st.st_mode):
        return "it is a symbolic link"
    if not (stat.S_ISDIR if kind == "folder" else stat.S_ISREG)(st.st_mode):
        return f"not a {'folder' if kind == 'folder' else 'regular file'}"
    if st.st_uid != os.geteuid():
        return f"owned by user id {st.st_uid}, not by this user ({os.geteuid()})"
    if st.st_mode & 0o022:
        return f"writable by group or others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def private_folder(folder: Path, create: bool) -> str | None:
    """Why ``folder`` must not hold what is loaded and run; ``None`` where it may. With
    ``create``, a missing folder is created private (`make_private`); without, a
    missing one may be used (nothing to read; it is created when the first file is
    written)."""
    try:
        if create:
            make_private(folder)
        return _not_private(os.lstat(folder), "folder")
    except FileNotFoundError:
        return None if not create else "cannot be created (a parent was removed)"
    except OSError as exc:
        return f"cannot be created ({exc.strerror or exc})"


def read_private(path: Path, limit: int | None = None) -> bytes:
    """The bytes of ``path``, opened without following a link and without blocking (a FIFO
    would wait for a writer), if it is a regular file of the user's that no one else can
    write, of at most ``limit`` bytes (checked on the open file before a byte is read,
    and again while reading).

    Raises:
        FileNotFoundError: it is missing.
        NotPrivate: a link, not a regular file (a FIFO, a device), or a file another user
            owns or can write (nothing is read).
        OSError: it cannot be read; ``EFBIG`` where it holds more than ``limit`` bytes.
    """
    try:
        fd = os.open(path, os.O_RDONLY | NOFOLLOW | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise NotPrivate("it is a symbolic link") from None
        raise
    try:
        st = os.fstat(fd)  # the file opened, not a name
        problem = _not_private(st, "file")
        if problem is not None:
            raise NotPrivate(problem)
        if limit is not None and st.st_size > limit:
            raise OSError(errno.EFBIG, f"it holds {st.st_size:,} bytes, more than the {limit:,} read at most")
        os.set_blocking(fd, True)  # a regular file: read it as any other
        return _read_fd(fd, limit)
    finally:
        os.close(fd)
