"""The whole hand and the object as one MuJoCo scene (MJCF), for a protocol such as DexGraspBench's.

The scene is the hand's own MJCF file (read and checked again as `jaxgrasp.Hand` reads it,
`jaxgrasp.hands._mjcf_files`; MJCF hands only: a URDF hand is refused in one line) with:

* the hand's bodies inside one static body at the grasp's wrist pose: the wrist is fixed
  in the world, exactly (DexGraspBench welds a free hand to a mocap body, which yields a
  little under load);
* its keyframes, actuators and sensors removed, its ``<option>`` replaced by the
  protocol's (`jaxgrasp.simulation._protocols`);
* one position actuator per joint (``<general>``, gain and bias set after compiling:
  ``tau = kp (ctrl - q) - kv qdot``, `jaxgrasp.simulation._hand_trials` chooses them);
* the object as a free body at its pose, its collision shape the convex pieces of its
  mesh (`jaxgrasp.simulation._convex`), its mass the grasp's (the protocol's default
  where the grasp has none) and its inertia the mesh's as a uniform solid about the
  grasp's centre of mass;
* the protocol's contact settings: every geom condim 4 with its sliding and torsional
  friction; the hand's geoms the protocol's ``solref``/``solimp``; the object's MuJoCo's
  defaults. The hand's links collide as they are (with the object and each other).

The hand's joints keep their order: the scene's ``qpos`` is the hand's ``(J,)`` then the
object's ``(7,)`` (position, quaternion ``w x y z``).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from jaxgrasp.model import GraspValueError
from jaxgrasp.simulation._scene import load_mujoco, quaternion

__all__ = ["HandScene", "build_hand_scene", "hand_mjcf"]

HAND_BODY = "jaxgrasp_hand"
OBJECT_BODY = "jaxgrasp_object"
_REMOVED = ("keyframe", "actuator", "sensor", "option")
_MUJOCO_SOLREF = "0.02 1"  # MuJoCo's default geom solref and solimp: DexGraspBench leaves the object's so
_MUJOCO_SOLIMP = "0.9 0.95 0.001 0.5 2"
_ALL_BITS = str(2**31 - 1)  # the object's contype and conaffinity: it meets every colliding geom of the hand


@dataclasses.dataclass(frozen=True)
class HandScene:
    """A compiled hand-and-object scene (SI units).

    Attributes:
        model: the ``mujoco.MjModel``.
        num_joints: ``J``, the hand's joints (``qpos[:J]``, one actuator each, in order).
        object_body: the object's body id; ``object_geoms``: its geoms' ids.
        hand_geoms: ``(G,)`` the hand's geom ids.
        fingertip_bodies: ``(F,)`` the scene's body id of each fingertip.
        object_start: ``(7,)`` the object's pose at the start (position m, quaternion).
        mass: the object's mass, kg. pieces: how many convex pieces; ``convex``: how they
            were had (`convex_pieces`).
    """

    model: Any
    num_joints: int
    object_body: int
    object_geoms: np.ndarray
    hand_geoms: np.ndarray
    fingertip_bodies: np.ndarray
    object_start: np.ndarray
    mass: float
    pieces: int
    convex: str


def hand_mjcf(hand, allowed_dirs=None):
    """The checked MJCF source (`jaxgrasp.hands._mjcf_files.HandSource`) of ``hand``'s file;
    a one-line error for a URDF hand (module notes)."""
    from jaxgrasp.hands import check_mjcf, open_hand_file
    from jaxgrasp.io import allowed_folders

    path = hand.tree.source
    root, files = open_hand_file(path, allowed_folders(allowed_dirs))
    if root.tag != "mujoco":
        raise GraspValueError(f"the hand simulation takes MJCF hands only; {path} is <{root.tag}> (URDF): give the "
                              "hand as MJCF (MuJoCo compiles a URDF file to one: mujoco.MjModel.from_xml_path then "
                              "mj_saveLastXML)")
    return check_mjcf(root, files)


def _fmt(a) -> str:
    return " ".join(f"{float(x):.17g}" for x in np.asarray(a).reshape(-1))


def _wrapped(root, wrist) -> ET.Element:
    """``root`` with its removed elements gone and every ``<worldbody>``'s content inside
    one body at the wrist pose (``(6,)`` m, rotation vector rad); the first worldbody."""
    for tag in _REMOVED:
        for el in root.findall(tag):
            root.remove(el)
    worlds = root.findall("worldbody")
    if not worlds:
        worlds = [ET.SubElement(root, "worldbody")]
    wrist = np.asarray(wrist, dtype=np.float64)
    hand = ET.Element("body", name=HAND_BODY, pos=_fmt(wrist[:3]), quat=_fmt(quaternion(wrist[3:])))
    for world in worlds:
        for child in list(world):
            world.remove(child)
            hand.append(child)
    for world in worlds[1:]:
        root.remove(world)
    worlds[0].append(hand)
    return worlds[0]


def _add_object(root, world, pieces, pose, settings, friction) -> None:
    """The object's meshes (inline) and its free body of convex pieces (module notes)."""
    asset = ET.SubElement(root, "asset")
    pose = np.asarray(pose, dtype=np.float64)
    body = ET.SubElement(world, "body", name=OBJECT_BODY, pos=_fmt(pose[:3]), quat=_fmt(quaternion(pose[3:])))
    ET.SubElement(body, "freejoint", name=OBJECT_BODY)
    for k, (v, f) in enumerate(pieces):
        ET.SubElement(asset, "mesh", name=f"{OBJECT_BODY}_{k}", vertex=_fmt(v),
                      face=" ".join(str(int(x)) for x in np.asarray(f).reshape(-1)))
        ET.SubElement(body, "geom", name=f"{OBJECT_BODY}_{k}", type="mesh", mesh=f"{OBJECT_BODY}_{k}",
                      contype=_ALL_BITS, conaffinity=_ALL_BITS, condim=str(settings["condim"]),
                      friction=_fmt([friction[0], friction[1], 1e-4]), solref=_MUJOCO_SOLREF, solimp=_MUJOCO_SOLIMP,
                      margin="0", gap="0", group="0", priority="0", solmix="1", density="1000",
                      rgba="0.62 0.66 0.72 1")


def _add_options_and_actuators(root, joints, settings) -> None:
    option = ET.SubElement(root, "option", timestep=f"{settings['timestep_s']:.17g}", integrator=settings["integrator"],
                           cone=settings["cone"], impratio=f"{settings['impratio']:.17g}",
                           noslip_iterations=str(settings["noslip_iterations"]))
    ET.SubElement(option, "flag", gravity="enable" if settings["gravity"] else "disable")
    act = ET.SubElement(root, "actuator")
    for name in joints:
        ET.SubElement(act, "general", name=f"jaxgrasp_{name}", joint=name, gaintype="fixed", biastype="affine",
                      dyntype="none", gainprm="1", biasprm="0 -1 0", gear="1", ctrllimited="false",
                      forcelimited="false", actlimited="false")


def _scene_xml(source, hand, wrist, object_pose, pieces, settings, friction) -> str:
    unnamed = [j for j, n in enumerate(hand.joint_names) if not n]
    if unnamed:
        raise GraspValueError(f"{hand.tree.source}: joint {unnamed[0]} has no name; the hand simulation holds each "
                              "joint by an actuator named after it")
    root = ET.fromstring(source.xml)
    world = _wrapped(root, wrist)
    _add_object(root, world, pieces, object_pose, settings, friction)
    _add_options_and_actuators(root, hand.joint_names, settings)
    return ET.tostring(root, encoding="unicode")


def _set_object_inertia(mujoco, model, body: int, mass: float, com, inertia) -> None:
    """The object's mass, kg, centre of mass ``(3,)`` m (body frame) and inertia ``(3, 3)``
    kg m^2 about it, whatever the hand file's compiler settings made of its geoms."""
    evals, evecs = np.linalg.eigh(np.asarray(inertia, dtype=np.float64))
    if np.linalg.det(evecs) < 0:
        evecs[:, 2] *= -1.0
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, evecs.reshape(-1))
    model.body_mass[body] = mass
    model.body_ipos[body] = np.asarray(com, dtype=np.float64)
    model.body_iquat[body] = quat
    model.body_inertia[body] = np.maximum(evals, 1e-12)


def _set_contacts(model, hand_geoms, settings, friction) -> None:
    """The protocol's contact settings on the hand's geoms (the object's are in its XML)."""
    for g in hand_geoms:
        model.geom_condim[g] = settings["condim"]
        model.geom_friction[g, :2] = friction
        model.geom_solref[g, :2] = settings["hand_solref"]
        model.geom_solimp[g, :3] = settings["hand_solimp"]


def _inertia_about_com(mesh, mass: float) -> np.ndarray:
    """``(3, 3)`` kg m^2: a uniform solid of ``mass`` bounded by ``mesh``, about its centre of
    mass (a ball of the mesh's bounding radius where it encloses no volume)."""
    vol = float(mesh.volume) if mesh.is_watertight else 0.0
    if not (vol > 0.0 and np.isfinite(vol)):
        rad = float(np.max(np.linalg.norm(np.asarray(mesh.vertices) - np.mean(mesh.vertices, axis=0), axis=1)))
        return 0.4 * mass * rad**2 * np.eye(3)
    return np.asarray(mesh.moment_inertia) * mass / vol


def build_hand_scene(hand_grasp, settings, friction, allowed_dirs=None) -> HandScene:
    """Compile the scene of the [`HandGrasp`][jaxgrasp.hands.HandGrasp] ``hand_grasp`` under a
    protocol's ``settings`` (`DEXGRASPBENCH`) with ``friction`` ``(sliding, torsional m)``
    (module notes). The object's inertia is about the mesh's own centre of mass as a
    uniform solid, moved to the grasp's centre of mass (parallel axes).

    Raises:
        GraspValueError: a URDF hand, a joint without a name, or a file MuJoCo refuses; one line.
    """
    from jaxgrasp.simulation._convex import convex_pieces

    mujoco = load_mujoco()
    hg = hand_grasp
    source = hand_mjcf(hg.hand, allowed_dirs)
    pieces, how = convex_pieces(hg.mesh)
    mass = float(np.asarray(hg.grasp.mass)) or settings["default_object_mass_kg"]
    xml = _scene_xml(source, hg.hand, np.asarray(hg.wrist), np.asarray(hg.object_pose), pieces, settings, friction)
    try:
        model = mujoco.MjModel.from_xml_string(xml, source.assets)
    except Exception as exc:  # MuJoCo raises ValueError with a multi-line message
        raise GraspValueError(f"the hand's scene does not compile: {' '.join(str(exc).split())}") from None
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
    com = np.asarray(hg.center_of_mass, dtype=np.float64)
    i_cm = _inertia_about_com(hg.mesh, mass)
    offset = com - np.asarray(hg.mesh.center_mass if hg.mesh.is_watertight else com)
    i_com = i_cm + mass * (np.dot(offset, offset) * np.eye(3) - np.outer(offset, offset))
    _set_object_inertia(mujoco, model, body, mass, com, i_com)
    geoms = np.arange(model.ngeom)
    hand_geoms = geoms[np.asarray(model.geom_bodyid) != body]
    _set_contacts(model, hand_geoms, settings, friction)
    mujoco.mj_setConst(model, mujoco.MjData(model))
    q = np.asarray(hg.object_pose, dtype=np.float64)
    return HandScene(model, hg.hand.num_joints, body, geoms[np.asarray(model.geom_bodyid) == body], hand_geoms,
                     np.asarray(hg.hand.fingertip_body) + 1, np.concatenate([q[:3], quaternion(q[3:])]), mass,
                     len(pieces), how)
