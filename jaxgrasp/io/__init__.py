"""Files in and out: grasp files (TOML, JSON), datasets (JSONL, NPZ), meshes, and output
files that are written whole or not at all.
"""

from jaxgrasp.io._grasp_file import load, save, grasp_from_dict, grasp_to_dict
from jaxgrasp.io._dataset import GraspSet, load_dataset, save_dataset
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
