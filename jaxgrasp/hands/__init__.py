"""Hands from MJCF: kinematics in JAX, the grasp a configuration makes, tuning its joints.

:class:`Hand` (read by MuJoCo, the optional extra ``jaxgrasp[hands]``), its grasp on a mesh
(:class:`HandGrasp`), and :func:`tune_hand`, which maximises the evaluation value over the
hand's joint angles.
"""

from jaxgrasp.hands._hand import Hand
from jaxgrasp.hands._mjcf import INSTALL_HINT, KinematicTree

__all__ = ["Hand", "KinematicTree", "INSTALL_HINT"]
