"""A hand's kinematic tree, read from an MJCF or URDF file by MuJoCo.

jaxgrasp reads the file and every file it names, inside its folder and checked
(`jaxgrasp.hands._mjcf_files`); MuJoCo compiles the checked text, given every file as
bytes, and opens none (defaults, ``euler``/``axisangle`` frames are all resolved by its
compiler); `read_model` copies what the kinematics needs out of
the compiled ``mujoco.MjModel`` into a `KinematicTree` of NumPy arrays: for each
body its parent, its frame in the parent's and its joints; for each joint its type, axis,
anchor, limits and reference angle; for each geom its body, frame, type and size. MuJoCo
is imported here only, when a hand is read, so ``import jaxgrasp`` does not need it.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from jaxgrasp.model import GraspValueError

__all__ = ["KinematicTree", "read_model", "read_mjcf", "require_mujoco", "INSTALL_HINT", "HINGE", "SLIDE", "SPHERE", "CAPSULE", "BOX", "CYLINDER"]

INSTALL_HINT = 'jaxgrasp.Hand needs MuJoCo: pip install "jaxgrasp[hands]"'
"""The one line a call without the ``hands`` extra raises."""

HINGE, SLIDE = 3, 2  # mujoco.mjtJoint
SPHERE, CAPSULE, BOX, CYLINDER = 2, 3, 6, 5  # mujoco.mjtGeom


def require_mujoco():
    """The ``mujoco`` module, or a one-line [`GraspValueError`][jaxgrasp.GraspValueError] saying what to install."""
    try:
        import mujoco
    except ImportError:
        raise GraspValueError(INSTALL_HINT) from None
    return mujoco


@dataclasses.dataclass(frozen=True, eq=False)
class KinematicTree:
    """The kinematic tree of a compiled MJCF model (NumPy, SI units: m, rad).

    Bodies are in MuJoCo's order (a parent before its children; body 0 is the world).

    Attributes:
        body_parent: ``(B,)`` parent body index (``-1`` for the world).
        body_pos: ``(B, 3)`` body frame origin in the parent's frame, m.
        body_quat: ``(B, 4)`` body frame orientation in the parent's, ``(w, x, y, z)``.
        body_joints: per body, the indices of its joints in order.
        body_names: ``(B,)`` names.
        jnt_type: ``(J,)`` `HINGE` or `SLIDE`.
        jnt_axis: ``(J, 3)`` axis in the body frame (unit).
        jnt_pos: ``(J, 3)`` anchor in the body frame, m.
        jnt_range: ``(J, 2)`` limits, rad or m (``(-inf, inf)`` for an unlimited joint).
        qpos0: ``(J,)`` the joint's reference position (MuJoCo's ``qpos0``).
        jnt_names: ``(J,)`` names.
        geom_body: ``(G,)`` the body each geom belongs to.
        geom_pos: ``(G, 3)`` geom centre in its body's frame, m.
        geom_quat: ``(G, 4)`` geom orientation in its body's frame.
        geom_type: ``(G,)`` MuJoCo geom type codes.
        geom_size: ``(G, 3)`` MuJoCo geom sizes, m (capsule: radius, half-length).
        geom_names: ``(G,)`` names (``""`` where unnamed).
        source: the file it was read from.
    """

    body_parent: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray
    body_joints: tuple
    body_names: tuple
    jnt_type: np.ndarray
    jnt_axis: np.ndarray
    jnt_pos: np.ndarray
    jnt_range: np.ndarray
    qpos0: np.ndarray
    jnt_names: tuple
    geom_body: np.ndarray
    geom_pos: np.ndarray
    geom_quat: np.ndarray
    geom_type: np.ndarray
    geom_size: np.ndarray
    geom_names: tuple
    source: str = ""

    @property
    def num_joints(self) -> int:
        """Number of joints ``J`` (= the length of ``qpos``)."""
        return int(self.jnt_type.shape[0])

    def geom_index(self, name: str) -> int:
        """The index of the geom called ``name``; a one-line error naming the choices otherwise."""
        if name not in self.geom_names:
            named = ", ".join(n for n in self.geom_names if n)
            raise GraspValueError(f"fingertips: no geom named {name!r} in {self.source}; its geoms: {named}")
        return self.geom_names.index(name)


def read_model(path, allowed_dirs=None, kinds=("mjcf", "urdf")) -> tuple[KinematicTree, object]:
    """``(tree, model)``: the `KinematicTree` of the hand file ``path`` (MJCF or URDF, told
    apart by the root element, among ``kinds``) and the compiled ``mujoco.MjModel`` it came from.

    The file and what it names (includes, meshes) are read by jaxgrasp, inside the file's
    folder or the folders ``allowed_dirs``, and checked (`jaxgrasp.hands._mjcf_files`,
    `jaxgrasp.hands._urdf_files`); MuJoCo gets their checked content and opens no file.

    Raises:
        GraspValueError: MuJoCo is not installed, a file outside the allowed folders, not a
            regular file or over its cap, a model over the size caps, the file cannot be
            compiled (legacy MJCF: the element and the fix, `jaxgrasp.hands._legacy`), or a
            joint is neither a hinge nor a slide (free and ball joints are not supported:
            give the hand's pose as the wrist instead), or a joint has a ``qpos`` of other
            size; one line.
    """
    from jaxgrasp.hands._mjcf_files import check_mjcf, open_hand_file
    from jaxgrasp.hands._urdf_files import check_urdf
    from jaxgrasp.io import allowed_folders

    mujoco = require_mujoco()
    where = os.fspath(path)
    root, files = open_hand_file(where, allowed_folders(allowed_dirs))
    roots = {"mjcf": "mujoco", "urdf": "robot"}
    if root.tag not in [roots[k] for k in kinds]:
        hint = " (a URDF file: read it with Hand.from_file)" if root.tag == "robot" else ""
        files.refuse(f"its root element is <{root.tag}>, not {' or '.join(f'<{roots[k]}>' for k in kinds)}: a hand "
                     f"file is {' or '.join(k.upper() for k in kinds)}{hint}")
    source = check_urdf(root, files) if root.tag == "robot" else check_mjcf(root, files)
    try:
        model = mujoco.MjModel.from_xml_string(source.xml, source.assets)
    except Exception as exc:  # MuJoCo raises ValueError with a multi-line message
        raise GraspValueError(f"{source.kind} {where!r}: {_refusal(str(exc), source, mujoco.__version__)}") from None
    return tree_of(model, where, source.kind), model


def read_mjcf(path, allowed_dirs=None) -> tuple[KinematicTree, object]:
    """`read_model` of an MJCF file (a URDF file is refused)."""
    return read_model(path, allowed_dirs, kinds=("mjcf",))


def _refusal(message: str, source, version: str) -> str:
    """MuJoCo's refusal in jaxgrasp's words where `jaxgrasp.hands._legacy` knows it, else
    in MuJoCo's, on one line with the hand file's own names for its assets."""
    from jaxgrasp.hands._legacy import explain

    text = " ".join(message.split())
    ours = explain(text, source, version)
    if ours is not None:
        return ours
    for vfs, name in source.names.items():  # the names written in the file, not the ones MuJoCo was given
        text = text.replace(vfs, name)
    return f"MuJoCo cannot compile it ({text})"


def _names(model, kind, count: int) -> tuple:
    import mujoco

    return tuple(mujoco.mj_id2name(model, kind, i) or "" for i in range(count))


def tree_of(model, source: str = "<MjModel>", kind: str = "mjcf") -> KinematicTree:
    """The `KinematicTree` of a compiled ``mujoco.MjModel`` (read from the ``kind`` file ``source``)."""
    import mujoco

    bad = [i for i, t in enumerate(model.jnt_type) if int(t) not in (HINGE, SLIDE)]
    if bad:
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, bad[0])
        raise GraspValueError(f"{kind} {source!r}: joint {name!r} is a free or ball joint; a hand needs hinge and slide joints only")
    if model.nq != model.njnt or np.any(model.jnt_qposadr != np.arange(model.njnt)):
        raise GraspValueError(f"{kind} {source!r}: qpos does not hold one entry per joint in order")
    limited = np.asarray(model.jnt_limited, dtype=bool)
    rng = np.where(limited[:, None], model.jnt_range, [-np.inf, np.inf])
    joints = [[] for _ in range(model.nbody)]
    for j, b in enumerate(model.jnt_bodyid):
        joints[int(b)].append(j)
    f = lambda a: np.array(a, dtype=np.float64)  # noqa: E731  (a copy, detached from the model)
    return KinematicTree(
        body_parent=np.where(np.arange(model.nbody) == 0, -1, model.body_parentid).astype(int),
        body_pos=f(model.body_pos), body_quat=f(model.body_quat),
        body_joints=tuple(tuple(j) for j in joints), body_names=_names(model, mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        jnt_type=np.array(model.jnt_type, dtype=int), jnt_axis=f(model.jnt_axis), jnt_pos=f(model.jnt_pos),
        jnt_range=f(rng), qpos0=f(model.qpos0), jnt_names=_names(model, mujoco.mjtObj.mjOBJ_JOINT, model.njnt),
        geom_body=np.array(model.geom_bodyid, dtype=int), geom_pos=f(model.geom_pos), geom_quat=f(model.geom_quat),
        geom_type=np.array(model.geom_type, dtype=int), geom_size=f(model.geom_size),
        geom_names=_names(model, mujoco.mjtObj.mjOBJ_GEOM, model.ngeom), source=source,
    )
