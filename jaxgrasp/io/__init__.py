"""Files in and out: grasp files, datasets, meshes, and output files written whole or not at all.

Grasp files (TOML, JSON; :func:`load`, :func:`save`), datasets of many grasps (NPZ,
JSONL; :func:`load_dataset`, :func:`save_dataset`), mesh files and the grasp on an
object's mesh (:func:`from_mesh`: the file read here, the :class:`~jaxgrasp.MeshGrasp` and
its geometry in :mod:`jaxgrasp.surface`), and :class:`OutputError` for an output that cannot be written. All
in SI units.

Inputs are treated as untrusted: every file is read only if it is a regular file under
its kind's size cap (special files such as FIFOs and ``/dev/zero`` are refused in one
line), and a mesh named by a grasp file or a dataset line must be a mesh format (STL,
OBJ, PLY, OFF, GLB; no archives) inside that file's folder after symlinks, unless the
caller allows more folders (``allowed_dirs=``, ``--allow-dir``); see
:mod:`jaxgrasp.io._inputs`.

``__all__`` lists the names promised to users. The names imported below the comment
"For jaxgrasp's other packages" are what the library's other packages use from here
(they import from this face, never from its private modules); they are not in
``__all__`` and not promised to users.
"""

from jaxgrasp.io._dataset import GraspSet, load_dataset, save_dataset
from jaxgrasp.io._grasp_file import grasp_from_dict, grasp_to_dict, load, save
from jaxgrasp.io._mesh import from_mesh
from jaxgrasp.io._outputs import OutputError

# For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
from jaxgrasp.io._dataset import load_share, padded_set, share_rows
from jaxgrasp.io._grasp_file import dict_to_toml, mesh_grasp_to_dict, mesh_reference, to_text
from jaxgrasp.io._inputs import MAX_GRASP_FILE_BYTES, allowed_folders, confine, read_input
from jaxgrasp.io._mesh import load_mesh
from jaxgrasp.io._outputs import (
    LOCK_NAME,
    NO_SPACE,
    TEMP_SUFFIX,
    Abandoned,
    DiskFull,
    FolderLock,
    abandon,
    check_writable,
    clear_notes,
    csv_cell,
    csv_content,
    keeping,
    read_own,
    refuse_link,
    remove_stale_temps,
    set_keeping,
    set_last_write,
    set_note,
    write_file,
    write_set,
    write_to,
)

__all__ = [
    "load",
    "save",
    "grasp_from_dict",
    "grasp_to_dict",
    "GraspSet",
    "load_dataset",
    "save_dataset",
    "from_mesh",
    "OutputError",
]
