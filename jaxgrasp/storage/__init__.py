"""Storage: files written whole or not at all, folder locks, stale temporary files, and
files of jaxgrasp's own read without following links.

One layer under every writer: output files (:mod:`jaxgrasp.io`, :mod:`jaxgrasp.plots`,
the command line), checkpoints (:mod:`jaxgrasp.engine`) and the executable store
(:mod:`jaxgrasp.engine`, which serialises executables on top of these files). It imports
nothing of jaxgrasp.

* Atomic files (:mod:`._files`): :func:`write_set` (several files, all or none),
  :func:`write_file`, :func:`write_to`; each member a temporary file in its destination
  folder, synced, then renamed into place. :func:`check_writable` before long work,
  :func:`remove_stale_temps` (one age, :data:`STALE_TEMP_SECONDS`), :func:`abandon` on an
  interrupt. Errors: :class:`OutputError`, :class:`DiskFull`, :class:`FolderBusy`,
  :class:`Abandoned`.
* Own files (:mod:`._own`): :class:`FolderLock` (one writer per folder),
  :func:`refuse_link`, :func:`read_own`; private folders and files for what is loaded
  and run (:func:`make_private`, :func:`private_folder`, :func:`read_private`).
* CSV tables (:mod:`._csv`): :func:`csv_content`, :func:`csv_cell`.
"""

from jaxgrasp.storage._csv import csv_cell, csv_content
from jaxgrasp.storage._files import (
    NO_SPACE,
    PUBLISH_LOCK,
    STALE_TEMP_SECONDS,
    TEMP_SUFFIX,
    Abandoned,
    Content,
    DiskFull,
    FolderBusy,
    OutputError,
    abandon,
    check_writable,
    remove_stale_temps,
    write_file,
    write_set,
    write_to,
)
from jaxgrasp.storage._own import (
    LOCK_NAME,
    FolderLock,
    NotPrivate,
    make_private,
    private_folder,
    read_own,
    read_private,
    refuse_link,
)

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
    "abandon",
    "LOCK_NAME",
    "FolderLock",
    "refuse_link",
    "read_own",
    "NotPrivate",
    "make_private",
    "private_folder",
    "read_private",
    "csv_cell",
    "csv_content",
]
