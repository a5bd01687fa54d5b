"""Hand grasps per second against contact-point grasps of the same contact counts, one run.

The grasps: DexGraspNet's published sample (5 objects, 1141 Shadow-hand grasps; not copied
here: pass a clone of https://github.com/PKU-EPIC/DexGraspNet), its hand edited for MuJoCo 3
as ``dexgraspnet_check.py`` does. Two ways to the same evaluations, alternated in one process
after one warm-up of each (so both load or compile their programs first):

* **hand**: `jaxgrasp.hands.read_dexgraspnet`, `hand_batch` (the fingertips placed by the
  kinematics and the closest points, one compiled function per chunk) and
  `jaxgrasp.evaluate_batch` of its set: what ``jaxgrasp batch --format dexgraspnet`` does;
* **contacts**: the same grasps as plain contact-point grasps (each with only its fingertips
  in contact, no mask, no hand), through `jaxgrasp.evaluate_batch`.

Both rates count the grasps with 2 or more fingertips in contact (the ones evaluated), per
second of wall time of the whole path. Prints the rates, their ratio, whether the statuses
and values agree, and the load average before and after.

Run: ``python experiments/hand_datasets/benchmark.py --dexgraspnet /path/to/DexGraspNet``
(writes ``benchmark.log`` here).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import jaxgrasp
from jaxgrasp.hands import hand_batch, read_dexgraspnet

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from dexgraspnet_check import FIELDS, TIPS, fixed_hand  # noqa: E402  (the same hand, edited the same way)

MATERIAL = dict(zip(("young_modulus", "friction", "max_force"), map(float, FIELDS[1::2])))


def hand_path(hand, data) -> tuple[list, float]:
    """Every object's `HandBatch` and evaluation, and the wall time of both, s."""
    t0 = time.perf_counter()
    out = []
    for npy, mesh in data:
        poses = read_dexgraspnet(npy, hand)
        hb = hand_batch(hand, mesh, poses.qpos, wrist=poses.wrist, object_pose=poses.object_pose, scale=poses.scale,
                        **MATERIAL)
        out.append((hb, jaxgrasp.evaluate_batch(hb.grasps)))
    return out, time.perf_counter() - t0


def contact_path(sets) -> tuple[list, float]:
    """The evaluation of each set's valid grasps as plain contact-point grasps, and its wall time, s."""
    t0 = time.perf_counter()
    out = [jaxgrasp.evaluate_batch(grasps) for grasps in sets]
    return out, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dexgraspnet", required=True, type=Path, help="a clone of DexGraspNet's repository")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--log", type=Path, default=HERE / "benchmark.log")
    args = ap.parse_args()
    lines = []

    def log(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    log(f"# hand batches against contact-point grasps, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"{os.cpu_count()} CPUs, JAX {jax.__version__}, float64")
    log(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        xml = fixed_hand(args.dexgraspnet / "grasp_generation" / "mjcf", Path(tmp) / "hand")
        hand = jaxgrasp.Hand.from_mjcf(xml, TIPS)
        files = sorted((args.dexgraspnet / "data" / "dataset").glob("*.npy"))
        data = [(f, args.dexgraspnet / "data" / "meshdata" / f.stem / "coacd" / "decomposed.obj") for f in files]
        ran, _ = hand_path(hand, data)  # warm-up: compiles (or loads) every program both paths use
        sets = [[hb.grasps.grasps[i] for i in np.flatnonzero(hb.grasps.valid)] for hb, _ in ran]
        contact_path(sets)
        n = sum(len(s) for s in sets)
        counts = np.concatenate([hb.active[hb.grasps.valid].sum(axis=1) for hb, _ in ran])
        log(f"grasps: {sum(len(hb) for hb, _ in ran)} configurations, {n} with 2 or more fingertips in contact "
            f"(by count 2..5: {np.bincount(counts, minlength=6)[2:].tolist()})")
        hand_s, contact_s = [], []
        for r in range(args.repeats):
            ran, t_hand = hand_path(hand, data)
            plain, t_contact = contact_path(sets)
            hand_s.append(t_hand)
            contact_s.append(t_contact)
            log(f"repeat {r}: hand {n / t_hand:.1f} grasps/s ({t_hand:.2f} s), contacts {n / t_contact:.1f} grasps/s "
                f"({t_contact:.2f} s), ratio {t_contact / t_hand:.3f}")
        agree, worst = True, 0.0
        for (hb, res), res_c in zip(ran, plain):
            valid = np.flatnonzero(hb.grasps.valid)
            agree &= bool(np.array_equal(res.status[valid], res_c.status))
            v, vc = np.asarray(res.value)[valid], np.asarray(res_c.value)
            worst = max(worst, float(np.max(np.abs(v - vc) / np.maximum(np.abs(vc), 1e-300), initial=0.0)))
        h, c = float(np.median(hand_s)), float(np.median(contact_s))
        log(f"median: hand {n / h:.1f} grasps/s, contacts {n / c:.1f} grasps/s; hand / contacts = {c / h:.3f} "
            f"(at least 0.5 asked); statuses equal: {agree}; largest value difference {worst:.1e} relative")
    log(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    args.log.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
