"""The hand's own collisions (issue 67): which geom pairs, and how deep they overlap, against MuJoCo.

* The pairs ``KinematicTree.collision_pairs`` names for the vendored Shadow hand are the
  ones MuJoCo's own collision pipeline tests: with every margin set to 1 m (boxes made
  spheres, whose collider honours margins), every pair MuJoCo may collide touches, and
  ``data.contact`` lists exactly those pairs.
* At random joint angles within limits, ``Hand.self_overlap`` of every capsule pair equals
  minus MuJoCo's ``mj_geomDistance`` (exact for capsules) to 1e-9 m; a box pair (a box as
  its rounded samples) never overlaps more than MuJoCo's and falls short of it by less
  than the box's smallest half-size. Its gradient matches finite differences.
"""

from __future__ import annotations

import numpy as np
import pytest

import jaxgrasp
from tests.hands.test_kinematics import SHADOW, SHADOW_TIPS

mujoco = pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")
SPHERE, CAPSULE, BOX = 2, 3, 6


@pytest.fixture(scope="module")
def shadow():
    model = mujoco.MjModel.from_xml_path(str(SHADOW))
    return jaxgrasp.Hand.from_mjcf(SHADOW, SHADOW_TIPS), model, mujoco.MjData(model)


def test_collision_pairs_are_the_ones_mujoco_tests(shadow):
    hand = shadow[0]
    model = mujoco.MjModel.from_xml_path(str(SHADOW))
    data = mujoco.MjData(model)
    model.geom_margin[:] = 1.0  # every pair MuJoCo tests is then in contact ...
    model.geom_type[model.geom_type == BOX] = SPHERE  # ... but its box-box collider ignores margins
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_MIDPHASE)  # and its mid-phase tree too
    model.pair_margin[:] = 1.0
    mujoco.mj_forward(model, data)
    seen = {tuple(sorted((int(c.geom1), int(c.geom2)))) for c in data.contact[: data.ncon]}
    assert seen == {tuple(p) for p in hand.tree.collision_pairs.tolist()}
    assert len(seen) > 20  # the explicit finger pairs and the thumb's two bitmask boxes


def test_self_overlap_equals_mujoco_distance(shadow):
    hand, model, data = shadow
    pairs = hand.self_segments[0]
    size = model.geom_size
    rng = np.random.default_rng(7)
    for _ in range(12):
        q = rng.uniform(hand.lower, hand.upper)
        ours = np.asarray(hand.self_overlap(q))
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        for k, (a, b) in enumerate(pairs):
            ref = -mujoco.mj_geomDistance(model, data, int(a), int(b), 1.0, None)
            kinds = {int(model.geom_type[a]), int(model.geom_type[b])}
            if kinds == {CAPSULE}:
                assert ours[k] == pytest.approx(ref, abs=1e-9), (model.geom(a).name, model.geom(b).name)
            else:
                box = a if model.geom_type[a] == BOX else b
                assert ref - np.min(size[box]) <= ours[k] <= ref + 1e-9


def test_self_overlap_gradient_and_overlap_seen(shadow):
    hand, model, data = shadow
    import jax

    rng = np.random.default_rng(3)
    deepest = -1.0
    for _ in range(30):
        q = rng.uniform(hand.lower, hand.upper)
        deepest = max(deepest, float(np.max(hand.self_overlap(q))))
    assert deepest > 1e-3  # random configurations do make fingers overlap: the test can see it
    f = jax.jit(lambda q: jax.numpy.sum(jax.numpy.maximum(hand.self_overlap(q), 0.0) ** 2))
    g = np.asarray(jax.grad(f)(q))
    for j in range(hand.num_joints):
        e = np.zeros(hand.num_joints)
        e[j] = 1e-6
        assert g[j] == pytest.approx((float(f(q + e)) - float(f(q - e))) / 2e-6, abs=1e-7)
