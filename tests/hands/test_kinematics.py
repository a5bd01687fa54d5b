"""Hands from MJCF (issue 37): forward kinematics against MuJoCo's own, and the optional extra.

* At random joint angles within limits, ``Hand.fingertip_centers`` of the vendored Shadow
  hand equals MuJoCo's C ``mj_kinematics`` (geom positions plus the end-cap offset along
  the geom's axis) to 1e-9 m, with and without a wrist pose; every geom frame too. The
  two-finger test hand adds slide joints and a hinge anchor off the body's origin.
* Without MuJoCo, ``import jaxgrasp`` works and ``Hand.from_mjcf`` raises one line that
  says what to install.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.model._potential import rotation_matrix

REPO = Path(__file__).resolve().parents[2]
SHADOW = REPO / "examples" / "hands" / "shadow" / "shadow_hand.xml"
TWO_FINGER = REPO / "examples" / "hands" / "two_finger" / "two_finger.xml"
SHADOW_TIPS = [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")]

mujoco = pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")


def mujoco_tips(path, hand, qpos, wrist=None):
    """MuJoCo's fingertip centres: ``mj_kinematics`` body frames plus each fingertip's
    centre in its body's frame, then the wrist applied in NumPy."""
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    xmat = data.xmat.reshape(-1, 3, 3)[hand.fingertip_body]
    tips = data.xpos[hand.fingertip_body] + np.einsum("fij,fj->fi", xmat, hand.fingertip_center)
    geoms = data.geom_xpos.copy()
    if wrist is not None:
        rot = np.asarray(rotation_matrix(np.asarray(wrist[3:])))
        tips, geoms = tips @ rot.T + wrist[:3], geoms @ rot.T + wrist[:3]
    return tips, geoms


@pytest.mark.parametrize("path, tips", [(SHADOW, SHADOW_TIPS), (TWO_FINGER, ["a_tip", "b_tip"])], ids=["shadow", "two_finger"])
def test_fingertip_centers_equal_mujoco(path, tips):
    hand = jaxgrasp.Hand.from_mjcf(path, fingertips=tips)
    rng = np.random.default_rng(7)
    assert np.all(np.isfinite(hand.lower)) and np.all(hand.lower < hand.upper)
    for k in range(4):
        qpos = rng.uniform(hand.lower, hand.upper)
        wrist = None if k == 0 else np.concatenate([rng.normal(0, 0.1, 3), rng.normal(0, 1.0, 3)])
        ref_tips, ref_geoms = mujoco_tips(path, hand, qpos, wrist)
        np.testing.assert_allclose(np.asarray(hand.fingertip_centers(qpos, wrist)), ref_tips, rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(hand.geom_frames(qpos, wrist)[0]), ref_geoms, rtol=0, atol=1e-9)


def test_shadow_fingertips_are_the_distal_caps():
    hand = jaxgrasp.Hand.from_mjcf(SHADOW, fingertips=SHADOW_TIPS)
    np.testing.assert_allclose(hand.radius, [0.00705] * 4 + [0.00918])  # the model's capsule radii, m
    # the +z cap, away from the joint: the geom's centre on the body's z, plus the half-length (0.012 m, 0.013 m)
    np.testing.assert_allclose(hand.fingertip_center, [[0, 0, 0.024]] * 4 + [[0, 0, 0.026]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(hand.fingertip_axis, [[0, 0, 1]] * 5, rtol=0, atol=1e-15)
    assert hand.num_joints == 24 and len(hand.joint_names) == 24


def test_bad_fingertip_names_one_line():
    with pytest.raises(jaxgrasp.GraspValueError, match="no geom or link named 'nope'") as err:
        jaxgrasp.Hand.from_mjcf(TWO_FINGER, fingertips=["a_tip", "nope"])
    assert "\n" not in str(err.value)
    with pytest.raises(jaxgrasp.GraspValueError, match="neither a sphere nor a capsule"):
        jaxgrasp.Hand.from_mjcf(TWO_FINGER, fingertips=["a_tip", "b_palm"])


NO_MUJOCO = """
import sys
sys.modules["mujoco"] = None          # an import of mujoco now raises ImportError
sys.modules["mujoco.mjx"] = None
import jaxgrasp
try:
    jaxgrasp.Hand.from_mjcf({path!r}, fingertips=["a_tip", "b_tip"])
except jaxgrasp.GraspValueError as exc:
    print("ERR", exc)
"""


def test_without_mujoco_import_works_and_hand_says_what_to_install():
    code = NO_MUJOCO.format(path=str(TWO_FINGER))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines == ['ERR jaxgrasp.Hand needs MuJoCo: pip install "jaxgrasp[hands]"']
