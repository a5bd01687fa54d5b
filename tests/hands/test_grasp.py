"""The grasp a hand configuration makes, its value and gradient, and tuning (issue 37).

A two-finger test hand (``examples/hands/two_finger/two_finger.xml``: a slide, a swing and a curl per finger,
capsule fingertips of radius 10 mm) pinches a 60 mm cube of 20 g. Against references that
share nothing with the code under test but the kinematics (checked against MuJoCo in
``test_kinematics.py``):

* each active contact is the closest surface point to its fingertip centre, found by a
  brute-force NumPy search over every triangle (within 1e-9 m; on the surface within
  1e-6 m), ``dr = r - |c - p|`` to 1e-9 m, the normal the face's; the value equals
  ``jaxgrasp.evaluate`` of the same grasp built by hand with ``Grasp.create``;
* ``jax``'s gradient of the value with respect to ``qpos`` agrees with central
  differences (step 1e-4 relative) to 1e-3 relative on 3 configurations;
* a fingertip out of reach, or touching with its cylinder (tilt past 90 degrees), is
  inactive; ``tune_hand`` raises the value within the joint limits with the other links
  clear, and refuses a start of value 0.

Cost: one compiled value-and-gradient (``hand_value`` and ``tune_hand`` share it), then
one evaluation per finite-difference point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.hands import hand_value
from jaxgrasp.surface import closest_on_triangles

from conftest import json_from_new_process

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")
trimesh = pytest.importorskip("trimesh")

TWO_FINGER = Path(__file__).resolve().parents[2] / "examples" / "hands" / "two_finger" / "two_finger.xml"
FIELDS = dict(young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)
# Asymmetric configurations (no tie between the two fingertips' boundaries, so the value
# is smooth there): slide m, swing rad, curl rad per finger; every contact inside a face.
CONFIGS = np.array([
    [0.001, 0.10, 0.05, 0.0005, -0.05, 0.10],
    [0.0015, -0.08, 0.12, 0.0002, 0.06, -0.04],
    [0.0004, 0.05, -0.10, 0.0012, 0.12, 0.08],
])


@pytest.fixture(scope="module")
def hand():
    return jaxgrasp.Hand.from_mjcf(TWO_FINGER, fingertips=["a_tip", "b_tip"])


@pytest.fixture(scope="module")
def cube():
    return trimesh.creation.box((0.06, 0.06, 0.06))


def brute_closest(mesh, point):
    """``(p, normal)``: the closest point of ``mesh`` to ``point`` over every triangle, NumPy."""
    tri = np.asarray(mesh.triangles)
    q = closest_on_triangles(np.asarray(point), tri, xp=np)
    k = int(np.argmin(np.linalg.norm(q - point, axis=1)))
    return q[k], np.asarray(mesh.face_normals[k])


def grasp_by_hand(hand, qpos, mesh):
    """The grasp of ``qpos`` built with ``Grasp.create`` from the brute-force closest points."""
    centers = np.asarray(hand.fingertip_centers(qpos))
    closest = [brute_closest(mesh, c) for c in centers]
    p = np.array([pc[0] for pc in closest])
    dr = hand.radius - np.linalg.norm(centers - p, axis=1)
    com = np.asarray(mesh.center_mass)
    g = jaxgrasp.Grasp.create(p - com, np.array([pc[1] for pc in closest]), dr, radius=hand.radius, **FIELDS)
    return g, centers, p, dr


@pytest.mark.parametrize("k", range(len(CONFIGS)))
def test_grasp_from_configuration_is_consistent(hand, cube, k):
    qpos = CONFIGS[k]
    hg = hand.grasp(qpos, cube, **FIELDS)
    assert hg.status == "grasp" and hg.num_active == 2
    ref, centers, p, dr = grasp_by_hand(hand, qpos, cube)
    got = hg.grasp.compact()
    com = np.asarray(hg.center_of_mass)
    np.testing.assert_allclose(np.asarray(got.positions) + com, p, rtol=0, atol=1e-9)
    for c in np.asarray(got.positions) + com:  # on the surface
        assert np.linalg.norm(brute_closest(cube, c)[0] - c) < 1e-6
    np.testing.assert_allclose(np.asarray(got.initial_deformation), hand.radius - np.linalg.norm(centers - p, axis=1), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(got.normals), np.asarray(ref.normals), atol=1e-12)
    np.testing.assert_allclose(np.asarray(hg.tilt) < 0.2, True)  # the fingertips point at the faces
    value = hand_value(hand, qpos, cube, **FIELDS).value
    expected = float(jaxgrasp.evaluate(ref).value)
    assert expected > 0.0
    assert value == pytest.approx(expected, rel=1e-9)


def test_value_gradient_matches_central_differences(hand, cube):
    for qpos in CONFIGS:
        hv = hand_value(hand, qpos, cube, **FIELDS)
        assert hv.value > 0.0 and hv.evaluation.status == jaxgrasp.GraspStatus.STABLE
        fd = np.zeros(len(qpos))
        for j in range(len(qpos)):
            h = 1e-4 * abs(qpos[j])
            e = np.zeros(len(qpos))
            e[j] = h
            fd[j] = (hand_value(hand, qpos + e, cube, **FIELDS).value - hand_value(hand, qpos - e, cube, **FIELDS).value) / (2 * h)
        scale = np.max(np.abs(fd))
        np.testing.assert_allclose(hv.grad_qpos, fd, rtol=0, atol=1e-3 * scale)
        assert np.all(np.abs(hv.grad_qpos) > 1e-6 * scale)  # every joint moves the value: none checked at 0


def test_out_of_reach_and_cylinder_contacts_are_inactive(hand, cube):
    far = hand.grasp(np.array([-0.02, 0.0, 0.0, 0.0005, 0.0, 0.0]), cube, **FIELDS)  # finger a pulled back 20 mm
    assert list(np.asarray(far.active)) == [False, True] and far.status == "too_few_contacts"
    # finger a's base slid in 10 mm and its tip curled 0.8 rad: its cap's edge, not its face, meets the cube
    side = hand.grasp(np.array([0.01, 0.0, -0.8, 0.0005, 0.0, 0.0]), cube, **FIELDS)
    tilt = np.asarray(side.tilt)
    assert tilt[1] < 1e-9
    if tilt[0] >= jaxgrasp.hands.DEFAULT_MAX_TILT:
        assert not bool(np.asarray(side.active)[0])


def test_tune_hand_raises_the_value_within_limits(hand, cube):
    res = jaxgrasp.tune_hand(hand, cube, CONFIGS[0], maxiter=3, **FIELDS)
    assert res.value > res.start_value > 0.0
    assert np.all(res.qpos >= hand.lower) and np.all(res.qpos <= hand.upper)
    assert res.deepest <= 1e-3 and res.history[0] == res.start_value
    assert res.value == pytest.approx(float(jaxgrasp.evaluate(res.grasp.grasp).value), rel=1e-9)
    with pytest.raises(jaxgrasp.GraspValueError, match="value 0"):
        jaxgrasp.tune_hand(hand, cube, np.array([-0.02, 0.0, 0.0, 0.0005, 0.0, 0.0]), **FIELDS)
    with pytest.raises(jaxgrasp.GraspValueError, match="the start has 2 fingertips in contact, fewer than min_fingertips = 3"):
        jaxgrasp.tune_hand(hand, cube, CONFIGS[0], maxiter=3, min_fingertips=3, **FIELDS)


def test_hand_digest_follows_the_content_not_the_path(hand, tmp_path):
    """Equal files in two folders give one digest (the stored executable's key); a
    fingertip 1 mm thicker gives another."""
    copy = tmp_path / "copy" / TWO_FINGER.name
    copy.parent.mkdir()
    copy.write_text(TWO_FINGER.read_text())
    same = jaxgrasp.Hand.from_mjcf(copy, fingertips=["a_tip", "b_tip"])
    assert same.tree.source != hand.tree.source and same.digest() == hand.digest()
    thicker = tmp_path / "thicker" / TWO_FINGER.name
    thicker.parent.mkdir()
    text = TWO_FINGER.read_text()
    assert text.count('fromto="0 0 0 0.03 0 0" size="0.01"') >= 1
    thicker.write_text(text.replace('fromto="0 0 0 0.03 0 0" size="0.01"', 'fromto="0 0 0 0.03 0 0" size="0.011"', 1))
    other = jaxgrasp.Hand.from_mjcf(thicker, fingertips=["a_tip", "b_tip"])
    assert other.digest() != hand.digest() and len(hand.digest()) == 64


_TUNE_HAND_IN_A_NEW_PROCESS = """
import json, sys
import numpy as np, trimesh
import jaxgrasp
from jaxgrasp.engine import _store
hand = jaxgrasp.Hand.from_mjcf(sys.argv[1], fingertips=["a_tip", "b_tip"])
res = jaxgrasp.tune_hand(hand, trimesh.creation.box((0.06, 0.06, 0.06)), np.array(json.loads(sys.argv[2])), maxiter=2,
                         **json.loads(sys.argv[3]))
print(json.dumps({"stats": _store.stats(), "history": [float(v) for v in res.history], "qpos": res.qpos.tolist()}))
"""


@pytest.mark.slow  # compiles tune_hand's objective where run alone, then a second process
def test_second_process_loads_tune_hands_objective(hand, cube, tmp_path):
    """``tune_hand``'s value and gradient come from the executable store: a new process
    (the suite's store, ``JAXGRASP_CACHE_DIR``), with the hand read from a copy of its
    file elsewhere, compiles no program and iterates as this process does, bit for bit."""
    import json

    from jaxgrasp.engine import _compile

    res = jaxgrasp.tune_hand(hand, cube, CONFIGS[0], maxiter=2, **FIELDS)
    _compile.wait_for_saves()
    copy = tmp_path / TWO_FINGER.name
    copy.write_text(TWO_FINGER.read_text())
    other = json_from_new_process(_TUNE_HAND_IN_A_NEW_PROCESS, str(copy), json.dumps(CONFIGS[0].tolist()),
                                  json.dumps(FIELDS))
    assert other["stats"]["traced"] == 0 and other["stats"]["deserialized"] >= 1, other["stats"]
    assert other["history"] == [float(v) for v in res.history]
    assert other["qpos"] == res.qpos.tolist()


PINCH = TWO_FINGER.with_name("pinch.toml")


def test_show_hand_draws_links_object_and_failure_pose(run_cli, tmp_path):
    out = tmp_path / "pinch.png"
    rc, stdout, err = run_cli(["show", "--hand", PINCH, "--out", out, "--glb", tmp_path / "pinch.glb"])
    assert rc == 0, err
    assert "stable" in stdout and "2 fingertips in contact" in stdout and out.stat().st_size > 10_000
    scene = trimesh.load(tmp_path / "pinch.glb")
    names = set(scene.geometry)
    assert {"object", "ghost", "link a_tip", "link b_tip", "link a_proximal", "fingertip 0", "fingertip 1"} <= names
    bad = tmp_path / "bad.toml"
    bad.write_text(PINCH.read_text().replace("[fingertip]", "[fingertip]\ncolour = 1"))
    (tmp_path / "two_finger.xml").write_text(TWO_FINGER.read_text())
    rc, _, err = run_cli(["show", "--hand", bad, "--out", tmp_path / "x.png"])
    assert rc == 2 and "unknown key 'colour' in [fingertip]" in err and len(err.strip().splitlines()) == 1
