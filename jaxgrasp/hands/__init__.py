"""Hands from MJCF or URDF: kinematics in JAX, the grasp a configuration makes, tuning its joints.

[`Hand`][jaxgrasp.Hand] (read by MuJoCo: the optional extra ``jaxgrasp[hands]``; fingertips
as sphere or capsule geoms, or as links with a hemisphere for fingertips that are meshes), the grasp a
configuration makes on a mesh ([`Hand.grasp`][jaxgrasp.Hand.grasp] -> [`HandGrasp`][jaxgrasp.hands.HandGrasp]), its value and
gradient with respect to the joints ([`hand_value`][jaxgrasp.hands.hand_value]), and [`tune_hand`][jaxgrasp.tune_hand], which
maximises the value over the joint angles with the other links kept out of the object.
The field's hand-grasp datasets: [`read_dexgraspnet`][jaxgrasp.hands.read_dexgraspnet],
[`read_dexgraspbench`][jaxgrasp.hands.read_dexgraspbench] (both to [`HandPoses`][jaxgrasp.hands.HandPoses]) and
[`save_dexgraspbench`][jaxgrasp.hands.save_dexgraspbench].

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.hands._batch import HandBatch, hand_batch
    from jaxgrasp.hands._datasets import HandPoses, read_dexgraspbench, read_dexgraspnet, save_dexgraspbench
    from jaxgrasp.hands._file import load_hand_batch, load_hand_grasp
    from jaxgrasp.hands._grasp import DEFAULT_MAX_TILT, HandGrasp
    from jaxgrasp.hands._hand import Hand
    from jaxgrasp.hands._links import link_samples
    from jaxgrasp.hands._mjcf import INSTALL_HINT, KinematicTree
    from jaxgrasp.hands._tune import HandTuneResult, HandValue, hand_value, tune_hand

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.hands._datasets import DEXGRASPBENCH_MESH, PREGRASP_FACTOR, SQUEEZE_FACTOR
    from jaxgrasp.hands._file import hand_grasp_toml, is_hand_grasp_file
    from jaxgrasp.hands._grasp import Material, contact_grasp, material
    from jaxgrasp.hands._mjcf_files import check_mjcf, open_hand_file

__all__ = [
    "Hand",
    "HandGrasp",
    "hand_batch",
    "load_hand_grasp",
    "load_hand_batch",
    "HandBatch",
    "hand_value",
    "HandValue",
    "tune_hand",
    "HandTuneResult",
    "link_samples",
    "KinematicTree",
    "INSTALL_HINT",
    "DEFAULT_MAX_TILT",
    "HandPoses",
    "read_dexgraspnet",
    "read_dexgraspbench",
    "save_dexgraspbench",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
