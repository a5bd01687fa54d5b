"""A hand's kinematic tree, read from an MJCF or URDF file by MuJoCo.

jaxgrasp reads the file and every file it names, inside its folder and checked
(`jaxgrasp.hands._mjcf_files`); MuJoCo compiles the checked text, given every file as
bytes, and opens none (defaults, ``euler``/``axisangle`` frames are all resolved by its
compiler); `read_model` copies what the kinematics needs out of
the compiled ``mujoco.MjModel`` into a `KinematicTree` of NumPy arrays: for each
body its parent, its frame in the parent's and its joints; for each joint its type, axis,
anchor, limits and reference angle; for each geom its body, frame, type and size; and the
linear couplings of the joints (`coupling_rows`: limited fixed tendons, joint equalities).
MuJoCo is imported here only, when a hand is read, so ``import jaxgrasp`` does not need it.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from jaxgrasp.model import GraspValueError

__all__ = ["KinematicTree", "collision_pairs", "coupling_rows", "read_model", "read_mjcf", "require_mujoco", "INSTALL_HINT",
           "HINGE", "SLIDE", "SPHERE", "CAPSULE", "BOX", "CYLINDER"]

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
        coupling_matrix: ``(C, J)`` the joints' linear couplings ``A`` (`coupling_rows`):
            a configuration the hand can hold has ``coupling_lower <= A @ qpos <=
            coupling_upper``; m/rad (tendon length per joint angle) for a tendon's row,
            unitless for an equality's.
        coupling_lower: ``(C,)`` each row's lower bound (m for a tendon, rad or m for an equality).
        coupling_upper: ``(C,)`` its upper bound (equal to the lower one for an equality).
        coupling_names: ``(C,)`` the tendon's or equality's name (``"tendon 3"``,
            ``"equality 0"`` where unnamed).
        collision_pairs: ``(P, 2)`` the geom pairs ``(g1 < g2)`` MuJoCo would test for
            contact within the hand (`collision_pairs`).
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
    coupling_matrix: np.ndarray
    coupling_lower: np.ndarray
    coupling_upper: np.ndarray
    coupling_names: tuple
    collision_pairs: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2), dtype=int))
    source: str = ""

    @property
    def num_joints(self) -> int:
        """Number of joints ``J`` (= the length of ``qpos``)."""
        return int(self.jnt_type.shape[0])

    @property
    def num_couplings(self) -> int:
        """Number of coupling rows ``C``."""
        return int(self.coupling_matrix.shape[0])

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
        geom_names=_names(model, mujoco.mjtObj.mjOBJ_GEOM, model.ngeom), **coupling_rows(model, source, kind),
        collision_pairs=collision_pairs(model), source=source,
    )


def collision_pairs(model) -> np.ndarray:
    """``(P, 2)`` the geom pairs ``(g1 < g2)``, sorted, that MuJoCo's collision pipeline
    would test in a compiled ``mujoco.MjModel``: its explicit ``<contact><pair>``s, and the
    pairs whose ``contype``/``conaffinity`` bitmasks match (either way round), whose
    bodies are not welded together, nor parent and child (welded bodies counted as one;
    unless the model disables ``filterparent``; the world's children are not filtered),
    nor a ``<contact><exclude>`` body pair."""
    import mujoco

    pairs = {(min(int(a), int(b)), max(int(a), int(b))) for a, b in zip(model.pair_geom1, model.pair_geom2)}
    excluded = {int(s) for s in model.exclude_signature}
    filterparent = not (int(model.opt.disableflags) & int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT))
    weld, parent = np.asarray(model.body_weldid), np.asarray(model.body_parentid)
    ctype, caff, body = model.geom_contype, model.geom_conaffinity, model.geom_bodyid
    for g1 in range(model.ngeom):
        for g2 in range(g1 + 1, model.ngeom):
            if not (int(ctype[g1]) & int(caff[g2]) or int(ctype[g2]) & int(caff[g1])):
                continue
            w1, w2 = int(weld[body[g1]]), int(weld[body[g2]])
            b1, b2 = sorted((int(body[g1]), int(body[g2])))
            related = w1 == int(weld[parent[w2]]) or w2 == int(weld[parent[w1]])
            if w1 == w2 or (filterparent and w1 != 0 and w2 != 0 and related) or {(b1 << 16) + b2, (b2 << 16) + b1} & excluded:
                continue
            pairs.add((g1, g2))
    return np.array(sorted(pairs), dtype=int).reshape(-1, 2)


def coupling_rows(model, source: str = "<MjModel>", kind: str = "mjcf") -> dict:
    """The linear couplings of a compiled model's joints, as the `KinematicTree` fields
    ``coupling_matrix`` ``(C, J)``, ``coupling_lower``, ``coupling_upper`` ``(C,)`` and
    ``coupling_names``: a configuration the hand can hold has ``lower <= A @ qpos <= upper``.

    The rows are, in the model's order:

    * each limited fixed tendon (every wrap a joint): MuJoCo's tendon length is
      ``sum(coef * qpos[joint])`` over its wraps (``qpos`` itself, not its offset from
      ``qpos0``), limited to ``tendon_range``; the Shadow hand's ``T_FFJ1c`` couples FFJ0
      and FFJ1 so. An unlimited tendon, or a spatial one (through sites and geoms), bounds
      nothing here.
    * then each active joint equality (``<equality><joint>``, active at the start,
      ``eq_active0``): MuJoCo holds ``q1 - q1_0 = c0 + c1 (q2 - q2_0) + c2 (q2 - q2_0)^2 +
      ...`` (``polycoef``, ``q_0`` the joint's ``qpos0``; ``q1 - q1_0 = c0`` without a
      second joint), the row ``q1 - c1 q2 = c0 + q1_0 - c1 q2_0``. Equalities of other kinds
      (connect, weld, tendon, flex) are not read.

    ``qpos`` holds one entry per joint in the joints' order (`tree_of` checks it), so a
    row's columns are the joints' indices.

    Raises:
        GraspValueError: a joint equality whose polynomial is not linear (one line).
    """
    rows = _tendon_rows(model) + _equality_rows(model, source, kind)  # (row (J,), lower, upper, name) each
    return {"coupling_matrix": np.array([r[0] for r in rows], dtype=np.float64).reshape(-1, model.njnt),
            "coupling_lower": np.array([r[1] for r in rows], dtype=np.float64),
            "coupling_upper": np.array([r[2] for r in rows], dtype=np.float64),
            "coupling_names": tuple(r[3] for r in rows)}


def _tendon_rows(model) -> list:
    """``(row (J,), lower, upper, name)`` of each limited fixed tendon (`coupling_rows`)."""
    import mujoco

    out = []
    joint_wrap = int(mujoco.mjtWrap.mjWRAP_JOINT)
    for t in range(model.ntendon):
        wraps = range(int(model.tendon_adr[t]), int(model.tendon_adr[t] + model.tendon_num[t]))
        if not model.tendon_limited[t] or any(int(model.wrap_type[w]) != joint_wrap for w in wraps):
            continue
        row = np.zeros(model.njnt)
        for w in wraps:
            row[int(model.wrap_objid[w])] += float(model.wrap_prm[w])
        out.append((row, float(model.tendon_range[t, 0]), float(model.tendon_range[t, 1]),
                    mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TENDON, t) or f"tendon {t}"))
    return out


def _equality_rows(model, source: str, kind: str) -> list:
    """``(row (J,), value, value, name)`` of each active linear joint equality (`coupling_rows`)."""
    import mujoco

    out = []
    joint_eq = int(mujoco.mjtEq.mjEQ_JOINT)
    for e in range(model.neq):
        if int(model.eq_type[e]) != joint_eq or not model.eq_active0[e]:
            continue
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_EQUALITY, e) or f"equality {e}"
        j1, j2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
        c = np.array(model.eq_data[e, :5], dtype=np.float64)
        row = np.zeros(model.njnt)
        row[j1] = 1.0
        value = c[0] + model.qpos0[j1]
        if j2 >= 0:  # without a second joint MuJoCo uses c0 alone
            if np.any(c[2:] != 0.0):
                degree = 2 + int(np.flatnonzero(c[2:])[-1])
                raise GraspValueError(
                    f"{kind} {source!r}: equality {name!r} couples joint "
                    f"{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j1)!r} to a polynomial of degree {degree} "
                    f"(polycoef {' '.join(f'{x:g}' for x in c)}): only linear couplings are supported")
            row[j2] -= c[1]
            value -= c[1] * model.qpos0[j2]
        out.append((row, float(value), float(value), name))
    return out
