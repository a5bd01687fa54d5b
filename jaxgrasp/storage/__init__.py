"""Storage: files written whole or not at all, folder locks, stale temporary files, and
files of jaxgrasp's own read without following links.

One layer under every writer: output files (`jaxgrasp.io`, `jaxgrasp.plots`,
the command line), checkpoints (`jaxgrasp.engine`) and the executable store
(`jaxgrasp.engine`, which serialises executables on top of these files). It imports
nothing of jaxgrasp.

* Atomic files (`_files`): `write_set` (several files, all or none),
  `write_file`, `write_to`; each member a temporary file in its destination
  folder, synced, then renamed into place. `check_writable` before long work,
  `remove_stale_temps` (one age, `STALE_TEMP_SECONDS`), `abandon` on an
  interrupt. Errors: `OutputError`, `DiskFull`, `FolderBusy`,
  `Abandoned`.
* Own files (`_own`): `FolderLock` (one writer per folder),
  `refuse_link`, `read_own`; private folders and files for what is loaded
  and run (`make_private`, `private_folder`, `read_private`).
* CSV tables (`_csv`): `csv_content`, `csv_cell`.
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
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

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
