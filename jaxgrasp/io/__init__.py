"""Files in and out: grasp files, datasets and meshes.

Grasp files (TOML, JSON; [`load`][jaxgrasp.load], [`save`][jaxgrasp.save]), datasets of many grasps (NPZ,
JSONL; [`load_dataset`][jaxgrasp.load_dataset], [`save_dataset`][jaxgrasp.save_dataset]), grasps on an object's mesh
([`from_mesh`][jaxgrasp.from_mesh]), and `OutputError` for an output that cannot be written. All
in SI units. Every file is written whole or not at all (`jaxgrasp.storage`).

Inputs are treated as untrusted: every file is read only if it is a regular file under
its kind's size cap (special files such as FIFOs and ``/dev/zero`` are refused in one
line), and a mesh named by a grasp file or a dataset line must be a mesh format (STL,
OBJ, PLY, OFF, GLB; no archives) inside that file's folder after symlinks, unless the
caller allows more folders (``allowed_dirs=``, ``--allow-dir``); see
`jaxgrasp.io._inputs`. A ``.npy`` file that pickles objects (the field's grasp datasets)
is read by a restricted unpickler that runs none of its code (`jaxgrasp.io._safe_npy`).

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.io._dataset import GraspSet, load_dataset, save_dataset
    from jaxgrasp.io._grasp_file import grasp_from_dict, grasp_to_dict, load, save
    from jaxgrasp.io._mesh import from_mesh
    from jaxgrasp.storage import OutputError

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.io._dataset import GraspColumns, GraspRows, load_share, padded_set, share_rows
    from jaxgrasp.io._grasp_file import copied_mesh, dict_to_toml, mesh_grasp_to_dict, mesh_reference, to_text
    from jaxgrasp.io._inputs import MAX_GRASP_FILE_BYTES, allowed_folders, check_path_text, confine, read_input
    from jaxgrasp.io._mesh import load_mesh
    from jaxgrasp.io._safe_npy import load_npy

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

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
