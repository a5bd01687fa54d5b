"""Shadow-hand grasps tuned on real objects (issue 37): value before and after, penetration, time.

For each object (``pybullet_data`` meshes scaled so that their largest extent is a
graspable size, mesh frame at the centre of mass, density 300 kg/m^3):

1. **A stable start: a pinch placed on an antipodal pair.** The hand keeps the pose of its
   MJCF (palm up: the palm's ``-y`` side faces the world's ``+z``, gravity pushes the object
   towards the palm); the other fingers straight, the wrist joints at 0. Pairs of the
   object's faces with opposed normals (within 14 degrees) on a line passing within 4 mm
   of the centre of mass are listed, narrowest first (``antipodal_pairs``). For a pair of
   width ``w``, the index finger's and thumb's joints are solved (L-BFGS-B within their
   limits) so that their fingertips face each other along the line joining their cap
   centres, ``w + r_ff + r_th - 2 DR0`` apart (``pinch``); the object is placed with the
   first face's centre under the index fingertip pressed ``DR0`` in and its normal against
   the fingertip's axis (tilt 0, the paper's assumption), turned about that axis in
   ``TURNS`` steps (``place_in_pinch``). Placements where a link sample lies in the object
   are skipped; the others are evaluated (:func:`jaxgrasp.hands.hand_value`) and the first
   pair that gives a stable grasp gives the start (its best turn).
2. **Tuning**: :func:`jaxgrasp.tune_hand` from that start over all 24 joints within their
   limits (the wrist pose fixed), penetration penalty weight 10, at most 1 mm accepted.

Writes ``experiments/tuning/hand_tune_<object>_{start,tuned}.png`` and appends to
``experiments/tuning/hand_tune.log``. Run from the repository root:
``python experiments/tuning/hand_tune.py duck`` (objects: see ``OBJECTS``; one object per run, so
that a run stays short).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize
import trimesh
from scipy.spatial.transform import Rotation

import jaxgrasp
from jaxgrasp.hands import hand_value
from jaxgrasp.plots import plot_hand_grasp
from jaxgrasp.surface import Surface

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402
SHADOW = ROOT / "examples" / "hands" / "shadow" / "shadow_hand.xml"
FIGURES = Path(__file__).resolve().parent  # the study folder
LOG = Path(__file__).resolve().parent / "hand_tune.log"
FINGERS = ("ff", "mf", "rf", "lf", "th")
TIPS = [f"robot0:C_{f}distal" for f in FINGERS]
OBJECTS = {  # name: (file under pybullet_data, largest extent m)
    "bunny": ("bunny.obj", 0.045),
    "r009": ("random_urdfs/009/009.obj", 0.045),
    "r033": ("random_urdfs/033/033.obj", 0.045),
    "r104": ("random_urdfs/104/104.obj", 0.050),
    "r023": ("random_urdfs/023/023.obj", 0.045),
    "duck": ("duck_vhacd.obj", 0.040),
}
FIELDS = dict(young_modulus=3e5, friction=0.8, max_force=10.0, density=300.0)
DR0 = 1.5e-3  # m, the closing fingertips' target initial deformation
TURNS = 8  # turns of the object about the pinch axis tried per face pair
MAX_PAIRS = 6  # face pairs tried per object
MIN_WIDTH = 0.010  # m, the narrowest antipodal pair tried


def load_object(name: str) -> trimesh.Trimesh:
    """The object's mesh, scaled to its graspable size, mesh frame at its centre of mass."""
    import pybullet_data

    rel, size = OBJECTS[name]
    mesh = trimesh.load(os.path.join(pybullet_data.getDataPath(), rel), force="mesh")
    mesh.apply_scale(size / float(np.max(mesh.extents)))
    mesh.apply_translation(-mesh.center_mass)
    return mesh


def joint_mask(hand, fingers) -> np.ndarray:
    """``(J,)`` bool: the joints of ``fingers``."""
    prefixes = tuple(f"robot0:{f.upper()}J" for f in fingers)
    return np.array([n.startswith(prefixes) for n in hand.joint_names])


def pinch_loss(hand):
    """``vg(x, q_base, aperture) -> (loss, grad)``, ``x`` the index finger's and thumb's
    joints: their fingertip axes opposed, on the line joining their centres, the centres
    ``aperture`` m apart (module notes); the other links clear of each other is not checked."""
    free = np.flatnonzero(joint_mask(hand, ("ff", "th")))
    ff, th = FINGERS.index("ff"), FINGERS.index("th")

    def loss(x, q_base, aperture):
        q = q_base.at[free].set(x)
        c, a = hand.fingertip_frames(q)
        gap = c[th] - c[ff]
        return (jnp.sum((gap - aperture * a[ff]) ** 2) / 1e-6 + jnp.sum((gap + aperture * a[th]) ** 2) / 1e-6
                + jnp.sum((a[ff] + a[th]) ** 2) * 10.0)

    return jax.jit(jax.value_and_grad(loss)), free


def pinch(hand, aperture: float, vg_free) -> tuple[np.ndarray, float]:
    """``(qpos, residual)``: index finger and thumb tips facing each other ``aperture`` m apart."""
    vg, free = vg_free
    q_base = np.zeros(hand.num_joints)
    x0 = np.array([0.0, 0.4, 0.6, 0.6, 1.0, 1.1, 0.0, 0.3, -0.4])  # FFJ3..FFJ0, THJ4..THJ0: a loose pinch
    fun = lambda x: tuple(np.asarray(v, dtype=np.float64) for v in vg(jnp.asarray(x), jnp.asarray(q_base), aperture))  # noqa: E731
    out = scipy.optimize.minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=list(zip(hand.lower[free], hand.upper[free])))
    q = q_base.copy()
    q[free] = out.x
    return q, float(out.fun)


def antipodal_pairs(mesh, max_offset: float = 0.006, min_cos: float = 0.95):
    """``[(width m, i, j)]``: pairs of faces with opposed normals (``n_i . n_j < -min_cos``)
    whose centres lie on a line along ``n_i`` passing within ``max_offset`` m of the centre
    of mass (the mesh frame's origin), narrowest first."""
    centres, normals = np.asarray(mesh.triangles_center), np.asarray(mesh.face_normals)
    out = []
    for i in range(len(centres)):
        d = centres - centres[i]
        width = -(d @ normals[i])
        off = np.linalg.norm(d + width[:, None] * normals[i], axis=1)
        line = np.linalg.norm(np.cross(centres[i], normals[i]))  # the com's distance from the line along n_i
        ok = (normals @ normals[i] < -min_cos) & (width > 0) & (off < 2e-3) & (line < max_offset)
        out += [(float(width[j]), i, int(j)) for j in np.flatnonzero(ok)]
    return sorted(out)


def place_in_pinch(hand, mesh, q, i: int, turn: float) -> np.ndarray:
    """The object's pose ``(6,)`` with face ``i``'s centre under the index fingertip pressed
    ``DR0`` in, its normal against the fingertip's axis, turned by ``turn`` about that axis."""
    c, a = (np.asarray(v) for v in hand.fingertip_frames(q))
    ff = FINGERS.index("ff")
    n_world = -a[ff]
    n_mesh = np.array(mesh.face_normals[i], dtype=np.float64)
    rot = Rotation.from_rotvec(turn * n_world) * Rotation.align_vectors([n_world], [n_mesh])[0]
    p_world = c[ff] + (hand.radius[ff] - DR0) * a[ff]
    t = p_world - rot.apply(np.array(mesh.triangles_center[i], dtype=np.float64))
    return np.concatenate([t, rot.as_rotvec()])


def centred(hand, q, pose, surface) -> np.ndarray:
    """``pose`` moved along the pinch axis so that the index fingertip and the thumb are
    pressed equally deep (their mean depth kept)."""
    ff, th = FINGERS.index("ff"), FINGERS.index("th")
    c, a = (np.asarray(v) for v in hand.fingertip_frames(q))
    rot = Rotation.from_rotvec(pose[3:])
    d = np.asarray(surface.closest(rot.inv().apply(c[[ff, th]] - pose[:3])).signed_distance)
    dr = hand.radius[[ff, th]] - d
    shift = 0.5 * (dr[0] - dr[1])  # move towards the thumb by this: the index tip's dr falls, the thumb's rises
    return np.concatenate([pose[:3] - shift * a[ff], pose[3:]])


def find_start(hand, mesh, log):
    """``(qpos, pose, label, HandValue)``: the best stable pinch over antipodal pairs and turns."""
    surface = Surface.from_trimesh(mesh)
    vg_free = pinch_loss(hand)
    best = None
    pairs = antipodal_pairs(mesh)
    log(f"  {len(pairs)} antipodal face pairs through the centre of mass; trying up to {MAX_PAIRS}")
    pairs = [p for p in pairs if p[0] >= MIN_WIDTH]
    for width, i, j in pairs[:: max(1, len(pairs) // MAX_PAIRS)][:MAX_PAIRS]:
        aperture = width + hand.radius[FINGERS.index("ff")] + hand.radius[FINGERS.index("th")] - 2 * DR0
        q, residual = pinch(hand, aperture, vg_free)
        for turn in np.linspace(0.0, 2 * np.pi, TURNS, endpoint=False):
            pose = centred(hand, q, place_in_pinch(hand, mesh, q, i, turn), surface)
            deepest = float(np.max(np.asarray(hand.link_depths(q, None, pose, surface))))
            if deepest > 0.0:
                continue
            hv = hand_value(hand, q, mesh, object_pose=pose, **FIELDS)
            label = f"faces {i}-{j} ({width * 1e3:.1f} mm apart), turn {np.degrees(turn):.0f} deg"
            log(f"  start candidate {label}: pinch residual {residual:.2e}, value {hv.value:.4e} J "
                f"({jaxgrasp.GraspStatus(int(hv.evaluation.status)).label}), deepest link {hv.deepest * 1e3:+.2f} mm, "
                f"tilt {np.round(np.degrees(hv.tilt)).astype(int).tolist()} deg")
            if hv.value > 0 and (best is None or hv.value > best[3].value):
                best = (q, pose, label, hv)
        if best is not None:
            break
    return best


def picture(hand_grasp, result, path: Path, title: str) -> None:
    """The hand grasp's picture (its links, the object, the failure pose)."""
    plot_hand_grasp(hand_grasp, path, result=result, title=title)


def run(name: str, maxiter: int, log) -> None:
    """Find a start on the object ``name``, tune it, write its pictures and log lines."""
    hand = jaxgrasp.Hand.from_mjcf(SHADOW, fingertips=TIPS)
    mesh = load_object(name)
    log(f"{name}: {OBJECTS[name][0]} scaled to {OBJECTS[name][1] * 1e3:.0f} mm, {len(mesh.faces)} faces, "
        f"mass {FIELDS['density'] * mesh.volume * 1e3:.1f} g; E {FIELDS['young_modulus']:g} Pa, mu {FIELDS['friction']}, "
        f"f_max {FIELDS['max_force']} N")
    t0 = time.perf_counter()
    start = find_start(hand, mesh, log)
    t_start = time.perf_counter() - t0
    if start is None:
        log(f"{name}: no stable start with clear links in {t_start:.1f} s")
        return
    q0, pose, label, hv0 = start
    log(f"{name}: start {label}: value {hv0.value:.6e} J, deepest link {hv0.deepest * 1e3:+.3f} mm ({t_start:.1f} s)")
    t1 = time.perf_counter()
    res = jaxgrasp.tune_hand(hand, mesh, q0, object_pose=pose, maxiter=maxiter, **FIELDS)
    t_tune = time.perf_counter() - t1
    log(f"{name}: {res.summary()}")
    log(f"{name}: value {res.start_value:.6e} -> {res.value:.6e} J (x{res.gain:.3f}); deepest link penetration "
        f"{res.start_deepest * 1e3:+.3f} -> {res.deepest * 1e3:+.3f} mm; {res.grasp.num_active} fingertips in contact, "
        f"tilt {np.round(np.degrees(np.asarray(res.grasp.tilt))).astype(int).tolist()} deg; start search {t_start:.1f} s, "
        f"tuning {t_tune:.1f} s ({res.iterations} iterations, {res.evaluations} evaluations)")
    log(f"{name}: tuned qpos {np.round(res.qpos, 6).tolist()}; object pose {np.round(pose, 6).tolist()}")
    start_grasp = hand.grasp(q0, mesh, object_pose=pose, **FIELDS)
    for tag, hg in (("start", start_grasp), ("tuned", res.grasp)):
        ev = jaxgrasp.evaluate(hg.grasp.compact())
        picture(hg, ev, FIGURES / f"hand_tune_{name}_{tag}.png", f"Shadow hand on the {name} ({tag}): {ev.status_name}, "
                f"value {float(ev.value) * 1e3:.4g} mJ")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("objects", nargs="+", choices=list(OBJECTS))
    p.add_argument("--maxiter", type=int, default=30)
    p.add_argument("--no-log", action="store_true", help="print only; do not append to experiments/tuning/hand_tune.log")
    args = p.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)

    def log(line: str) -> None:
        print(line, flush=True)
        if not args.no_log:
            with open(LOG, "a", encoding="utf-8") as fh:
                fh.write(line + "\n")

    log(f"# {time.strftime('%Y-%m-%d %H:%M:%S')} jaxgrasp {jaxgrasp.__version__}, jax {jax.__version__}, "
        f"{os.cpu_count()} CPUs (shared), objects {' '.join(args.objects)}")
    for name in args.objects:
        run(name, args.maxiter, log)
    return 0


if __name__ == "__main__":
    sys.exit(main())
