"""The grasp as a MuJoCo scene (MJCF), with its contacts calibrated to the paper's fingertips.

The object is a free body whose frame is the model frame (origin at the centre of mass,
the grasp's axes); it starts at jaxgrasp's equilibrium pose. Its shape is its mesh (a
[`MeshGrasp`][jaxgrasp.MeshGrasp], moved into the model frame) or, for a plain grasp, the
convex hull of a disc of the fingertip's radius in each contact's tangent plane (the body
``jaxgrasp show`` draws). MuJoCo collides with a mesh's convex hull; a contact whose
surface there does not lie where the grasp says (a dent of a non-convex mesh, or a disc
the hull swallows) is given a plate: a thin box in the object whose face is the contact's
tangent plane (the paper's planar contact surface, Sec. V), reported per contact.

Each fingertip is a sphere of radius ``r`` fixed in the world at
``c_i = p_i + (r - dr_i) n_i``, overlapping the object by ``dr_i`` (eq. 13 at the
initial state), in its own contact pair: condim 4, elliptic cone, sliding friction ``mu``
and torsional friction ``mu e_i`` (``e_i`` of eq. 10 at the equilibrium deformation, so
that MuJoCo's cone ``f_t^2 / mu^2 + tau^2 / (mu e)^2 <= f_n^2`` is eq. 9).

Normal force. With an impedance ``d`` held constant (``solimp = (d, d, ...)``) and
``solref = (-k, -b)``, MuJoCo's static contact force at penetration ``x`` is
``k (x - x0) / ((1 - d) A)`` where ``A`` is the constraint's inverse inertia
(``body_invweight0``; ``1/m`` for a free body with its centre of mass at the frame
origin) and ``-x0`` the pair's margin. With a small ``d`` each contact behaves as a spring
of stiffness ``K = k / ((1 - d) A)`` and a damper of ``b / A`` on the object's true mass
(a large ``d`` makes the object heavier along the normal by ``1 / (1 - d)``). ``K`` and
``x0`` are set so that the force is eq. 4 at two points: ``pi E dr^2`` at the initial
deformation and ``pi E d*^2 / cos^2 phi*`` at jaxgrasp's equilibrium (the secant of eq. 4,
or its tangent where the two deformations coincide). The small ``d`` makes MuJoCo's
friction soft (it creeps), so MuJoCo's no-slip solver enforces it as a hard constraint.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

__all__ = ["Scene", "build_scene", "calibrate", "load_mujoco", "object_shape", "quaternion", "rotation_matrix"]

IMPEDANCE = 0.01
"""MuJoCo's constraint impedance ``d`` of every contact (``solimp = (d, d, 0.001, 0.5, 2)``)."""

SURFACE_DEPTH_TOL = 0.05
"""A collision surface is the grasp's at a contact if MuJoCo's overlap there is ``dr``
within this fraction of ``dr``, and its normal within `SURFACE_ANGLE_TOL`."""

MAX_TIMESTEP = 1e-3
"""The longest timestep `auto_timestep` gives, s."""

SURFACE_ANGLE_TOL = 0.05
"""rad, see `SURFACE_DEPTH_TOL`."""


def load_mujoco():
    """The ``mujoco`` module, or one line saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise ImportError('jaxgrasp.simulate needs MuJoCo: pip install "jaxgrasp[sim]"') from None
    return mujoco


def rotation_matrix(w) -> np.ndarray:
    """``(3, 3)`` rotation matrix of a rotation vector ``w`` (3,), rad (Rodrigues)."""
    w = np.asarray(w, dtype=np.float64)
    t = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if t < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + math.sin(t) / t * k + (1.0 - math.cos(t)) / t**2 * (k @ k)


def quaternion(w) -> np.ndarray:
    """``(4,)`` unit quaternion ``(w, x, y, z)`` (MuJoCo's order) of a rotation vector, rad."""
    w = np.asarray(w, dtype=np.float64)
    t = float(np.linalg.norm(w))
    if t < 1e-12:
        return np.array([1.0, *(0.5 * w)]) / math.sqrt(1.0 + 0.25 * t * t)
    return np.array([math.cos(t / 2), *(math.sin(t / 2) * w / t)])


@dataclasses.dataclass(frozen=True)
class Contacts:
    """The grasp's contacts in NumPy (SI units, model frame), ``(N, ...)``."""

    p: Any  # positions, m
    n: Any  # unit outward normals
    dr: Any  # initial deformation, m
    r: Any  # fingertip radius, m
    E: Any  # Young's modulus, Pa
    mu: Any  # friction coefficient
    mass: float  # kg
    gravity: Any  # (3,) m/s^2

    @classmethod
    def of(cls, grasp) -> Contacts:
        f = {k: np.asarray(v, dtype=np.float64) for k, v in grasp.compact().to_numpy().items()}
        n = f["positions"].shape[0]
        per = lambda k: np.broadcast_to(f[k], (n,)).copy()
        nv = f["normals"] / np.linalg.norm(f["normals"], axis=1, keepdims=True)
        return cls(f["positions"], nv, per("initial_deformation"), per("radius"), per("young_modulus"),
                   per("friction"), float(f["mass"]), f["gravity"])


def model_forces(c: Contacts, dp, w) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(d, cos phi, f_n)``, each ``(N,)``, at the pose change ``(dp, w)`` (m, rad): the
    normal deformation (eq. 13, m), ``cos phi`` (eq. 14) and the normal force
    ``pi E d^2 / cos^2 phi`` (eq. 4, N; 0 where ``d <= 0``)."""
    rot = rotation_matrix(w)
    u = c.p @ (rot - np.eye(3)).T + np.asarray(dp)
    rn = c.n @ rot.T
    cphi = np.sum(c.n * rn, axis=1)
    d = c.r - np.sum(((c.r - c.dr)[:, None] * c.n - u) * rn, axis=1)
    f = np.pi * c.E * np.maximum(d, 0.0) ** 2 / cphi**2
    return d, cphi, f


def calibrate(c: Contacts, dp, w) -> dict:
    """Per-contact spring ``F(x) = K (x - x0)`` through eq. 4 at ``dr`` and at the
    equilibrium pose ``(dp, w)``; the eccentricity ``e`` (eq. 10) there.

    Returns:
        ``{"d_eq", "f_eq", "f0", "K", "x0", "e"}``: m, N, N, N/m, m, m; each ``(N,)``.
    """
    d, _, f_eq = model_forces(c, dp, w)
    f0 = np.pi * c.E * c.dr**2
    tangent = 2.0 * np.pi * c.E * c.dr
    gap = d - c.dr
    close = np.abs(gap) < 1e-3 * c.dr
    K = np.where(close, tangent, (f_eq - f0) / np.where(close, 1.0, gap))
    K = np.where(K > 0.1 * tangent, K, tangent)  # a secant that is not rising: the tangent at dr
    x0 = c.dr - f0 / K
    dd = np.clip(d, 0.0, c.r)
    e = 8.0 / 15.0 * c.mu * np.sqrt(np.maximum(c.r**2 - (c.r - dd) ** 2, 0.0))
    return {"d_eq": d, "f_eq": f_eq, "f0": f0, "K": K, "x0": x0, "e": e}


def object_shape(grasp_like) -> tuple[np.ndarray, np.ndarray, str]:
    """``(vertices (V, 3) m model frame, faces (F, 3), kind)`` of the object: the
    [`MeshGrasp`][jaxgrasp.MeshGrasp]'s mesh moved to the centre of mass (``"mesh"``), or the
    convex hull of a disc of the fingertip's radius in each contact's tangent plane (``"hull"``)."""
    import trimesh

    from jaxgrasp.surface import MeshGrasp

    if isinstance(grasp_like, MeshGrasp):
        mesh = grasp_like.mesh
        return np.asarray(mesh.vertices) - grasp_like.center_of_mass, np.asarray(mesh.faces), "mesh"
    c = Contacts.of(grasp_like)
    phi = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    pts = []
    for p, nv, r in zip(c.p, c.n, c.r):
        u = np.cross(nv, [1.0, 0.0, 0.0] if abs(nv[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(nv, u)
        pts.append(p + r * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v))
    hull = trimesh.convex.convex_hull(np.concatenate(pts))
    return np.asarray(hull.vertices), np.asarray(hull.faces), "hull"


def inertia_about_origin(vertices, faces, mass: float) -> np.ndarray:
    """``(3, 3)`` inertia tensor, kg m^2, of a uniform solid of ``mass`` bounded by the
    mesh, about the model frame's origin (the centre of mass the grasp states); a uniform
    ball of the mesh's bounding radius where the mesh encloses no volume."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    vol = float(mesh.volume) if mesh.is_watertight else 0.0
    if not (vol > 0.0 and math.isfinite(vol)):
        rad = float(np.max(np.linalg.norm(vertices, axis=1)))
        return 0.4 * mass * rad**2 * np.eye(3)
    com = np.asarray(mesh.center_mass)
    i_cm = np.asarray(mesh.moment_inertia) * mass / vol
    return i_cm + mass * (np.dot(com, com) * np.eye(3) - np.outer(com, com))


@dataclasses.dataclass(frozen=True)
class Scene:
    """A compiled scene: the MuJoCo model, where the object starts, and the calibration."""

    model: Any
    contacts: Contacts
    calibration: dict
    start_qpos: Any  # (7,)
    surfaces: tuple  # per contact: "mesh", "hull" or "plane"
    sim_mass: float  # kg, the object's mass in the simulator
    sim_gravity: Any  # (3,) m/s^2
    inertia: Any  # (3, 3) kg m^2
    damping: Any  # (N,) N s/m
    timestep: float  # s


def _fmt(a) -> str:
    return " ".join(f"{float(x):.17g}" for x in np.asarray(a).reshape(-1))


def _pair(i: int, geom: str, c: Contacts, cal: dict, mu, k_mj, b_mj) -> str:
    return (
        f'<pair name="pair{i}" geom1="tip{i}" geom2="{geom}" condim="4" '
        f'friction="{_fmt([mu[i], mu[i], mu[i] * cal["e"][i], 0.0, 0.0])}" '
        f'solref="{-k_mj[i]:.17g} {-b_mj[i]:.17g}" solimp="{IMPEDANCE} {IMPEDANCE} 0.001 0.5 2" '
        f'margin="{-cal["x0"][i]:.17g}" gap="0"/>'
    )


def scene_xml(c: Contacts, cal: dict, shape, planes, *, mass, gravity, inertia, mu, damping_ratio, timestep) -> str:
    """The MJCF text of the scene (see the module doc); ``planes``: contacts given a plate."""
    verts, faces = shape
    inv_mass = 1.0 / mass
    k_mj = cal["K"] * (1.0 - IMPEDANCE) * inv_mass
    b_mj = 2.0 * damping_ratio * np.sqrt(cal["K"] * inv_mass)
    tips = "".join(
        f'<geom name="tip{i}" type="sphere" size="{c.r[i]:.17g}" pos="{_fmt(c.p[i] + (c.r[i] - c.dr[i]) * c.n[i])}" '
        'contype="0" conaffinity="0" rgba="0.25 0.45 0.8 0.6"/>'
        for i in range(len(c.r))
    )
    plates = "".join(
        f'<geom name="plate{i}" type="box" size="{c.r[i]:.17g} {c.r[i]:.17g} {c.r[i] / 4:.17g}" '
        f'pos="{_fmt(c.p[i] - c.r[i] / 4 * c.n[i])}" zaxis="{_fmt(c.n[i])}" contype="0" conaffinity="0" '
        'rgba="0.9 0.6 0.2 0.3"/>'
        for i in planes
    )
    pairs = "".join(_pair(i, f"plate{i}" if i in planes else "object", c, cal, mu, k_mj, b_mj) for i in range(len(c.r)))
    ii = np.asarray(inertia)
    full = [ii[0, 0], ii[1, 1], ii[2, 2], ii[0, 1], ii[0, 2], ii[1, 2]]
    return f"""<mujoco model="jaxgrasp">
  <compiler inertiafromgeom="false"/>
  <option timestep="{timestep:.17g}" gravity="{_fmt(gravity)}" cone="elliptic" noslip_iterations="30"
          noslip_tolerance="1e-10" iterations="200" tolerance="1e-12"/>
  <asset><mesh name="shape" vertex="{_fmt(verts)}" face="{' '.join(str(int(x)) for x in np.asarray(faces).reshape(-1))}"/></asset>
  <worldbody>{tips}
    <body name="object"><freejoint name="object"/>
      <inertial pos="0 0 0" mass="{mass:.17g}" fullinertia="{_fmt(full)}"/>
      <geom name="object" type="mesh" mesh="shape" contype="0" conaffinity="0" rgba="0.62 0.66 0.72 0.5"/>{plates}
    </body>
  </worldbody>
  <contact>{pairs}</contact>
</mujoco>"""


def _surfaces_off(mujoco, model, c: Contacts, qpos) -> list[int]:
    """The contacts whose collision surface in ``model`` (every pair with the object's
    geom) is not the grasp's: no contact, or overlap or normal off by more than the
    tolerances (`SURFACE_DEPTH_TOL`, `SURFACE_ANGLE_TOL`)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    found = {}
    for j in range(data.ncon):
        con = data.contact[j]
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(con.geom1))
        found[int(name[3:])] = (float(con.dist), np.asarray(con.frame[:3]))
    off = []
    rot = rotation_matrix_of_quat(qpos[3:])
    for i in range(len(c.r)):
        if i not in found:
            off.append(i)
            continue
        dist, normal = found[i]
        want = rot @ c.n[i]
        depth_ok = abs(-dist - float(model_d(c, i, qpos))) <= SURFACE_DEPTH_TOL * c.dr[i]
        angle_ok = abs(float(np.dot(normal, want))) >= math.cos(SURFACE_ANGLE_TOL)
        if not (depth_ok and angle_ok):
            off.append(i)
    return off


def rotation_matrix_of_quat(q) -> np.ndarray:
    """``(3, 3)`` rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = np.asarray(q, dtype=np.float64)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def model_d(c: Contacts, i: int, qpos) -> float:
    """The plane overlap (eq. 13) of contact ``i`` with the object at ``qpos``, m."""
    rot = rotation_matrix_of_quat(qpos[3:])
    ci = c.p[i] + (c.r[i] - c.dr[i]) * c.n[i]
    return float(c.r[i] - np.dot(ci - (rot @ c.p[i] + qpos[:3]), rot @ c.n[i]))


def auto_timestep(K, mass: float, inertia, c: Contacts, damping_ratio: float) -> float:
    """A timestep, s, that resolves the fastest contact mode and keeps the contact dampers
    stable: the least of ``0.08 / omega``, ``0.5 d / b_max`` and `MAX_TIMESTEP`. ``omega^2`` is the
    largest eigenvalue of ``M^-1 H`` (``H = sum K_i J_i^T J_i``, ``J_i = (n_i, p_i x n_i)``,
    ``M = diag(m, m, m, I)``); ``b_max`` the largest ``b_i = 2 zeta sqrt(K_i / m)`` of
    ``solref`` and ``d`` the impedance (`IMPEDANCE`): with a small ``d`` MuJoCo's
    step is stable only for ``b dt`` below about ``d``, beyond which the object chatters
    at the step's own frequency (found by halving the step on random grasps)."""
    jac = np.concatenate([c.n, np.cross(c.p, c.n)], axis=1)  # (N, 6)
    mm = np.zeros((6, 6))
    mm[:3, :3] = mass * np.eye(3)
    mm[3:, 3:] = np.asarray(inertia)
    inv = np.linalg.inv(np.linalg.cholesky(mm))
    k = np.asarray(K, dtype=np.float64)
    omega = math.sqrt(max(float(np.max(np.linalg.eigvalsh(inv @ (jac.T @ (k[:, None] * jac)) @ inv.T))), 1e-30))
    b_max = 2.0 * damping_ratio * math.sqrt(float(np.max(k)) / mass)
    return min(MAX_TIMESTEP, 0.08 / omega, 0.5 * IMPEDANCE / b_max if b_max > 0 else 1.0)


def _set_springs(model, cal: dict, damping_ratio: float) -> None:
    """Set each pair's ``solref = (-k, -b)`` from MuJoCo's own inverse inertia ``A`` of the
    object (``body_invweight0``): ``k = K (1 - d) A``, ``b = 2 zeta sqrt(K A)``."""
    a = float(model.body_invweight0[1, 0])
    for i, stiff in enumerate(cal["K"]):
        model.pair_solref[i] = (-stiff * (1.0 - IMPEDANCE) * a, -2.0 * damping_ratio * math.sqrt(stiff * a))


def build_scene(grasp_like, grasp, dp, w, *, friction=None, nominal_mass=0.1, damping_ratio=0.05, timestep=None) -> Scene:
    """Compile the scene of ``grasp`` (its shape from ``grasp_like``) with the object at
    the equilibrium pose change ``(dp, w)`` (m, rad).

    ``friction`` overrides the simulator's friction coefficient (default the grasp's);
    a weightless grasp (mass 0) is simulated with ``nominal_mass`` kg and no gravity.
    """
    mujoco = load_mujoco()
    c = Contacts.of(grasp)
    cal = calibrate(c, dp, w)
    mu = c.mu if friction is None else np.full_like(c.mu, float(friction))
    mass = c.mass if c.mass > 0 else float(nominal_mass)
    gravity = c.gravity if c.mass > 0 else np.zeros(3)
    verts, faces, kind = object_shape(grasp_like)
    inertia = inertia_about_origin(verts, faces, mass)
    dt = auto_timestep(cal["K"], mass, inertia, c, damping_ratio) if timestep is None else float(timestep)
    qpos = np.concatenate([np.asarray(dp, dtype=np.float64), quaternion(w)])
    kw = dict(mass=mass, gravity=gravity, inertia=inertia, mu=mu, damping_ratio=damping_ratio, timestep=dt)
    model = mujoco.MjModel.from_xml_string(scene_xml(c, cal, (verts, faces), [], **kw))
    planes = _surfaces_off(mujoco, model, c, qpos)
    if planes:
        model = mujoco.MjModel.from_xml_string(scene_xml(c, cal, (verts, faces), planes, **kw))
    _set_springs(model, cal, damping_ratio)
    surfaces = tuple("plane" if i in planes else kind for i in range(len(c.r)))
    damping = 2.0 * damping_ratio * np.sqrt(cal["K"] * mass)
    return Scene(model, c, {**cal, "mu": mu}, qpos, surfaces, mass, gravity, inertia, damping, dt)
