"""Files in and out: grasp files, datasets, meshes, and output files written whole or not at all.

Grasp files (TOML, JSON; :func:`load`, :func:`save`), datasets of many grasps (NPZ,
JSONL; :func:`load_dataset`, :func:`save_dataset`), grasps on an object's mesh
(:func:`from_mesh`), and :class:`OutputError` for an output that cannot be written. All
in SI units.
"""

from jaxgrasp.io._dataset import GraspSet, load_dataset, save_dataset
from jaxgrasp.io._grasp_file import grasp_from_dict, grasp_to_dict, load, save
from jaxgrasp.io._mesh import MeshGrasp, from_mesh
from jaxgrasp.io._outputs import OutputError

__all__ = [
    "load",
    "save",
    "grasp_from_dict",
    "grasp_to_dict",
    "GraspSet",
    "load_dataset",
    "save_dataset",
    "MeshGrasp",
    "from_mesh",
    "OutputError",
]
