"""A planned Shadow-hand grasp under DexGraspBench's protocol (issue 68).

The grasp is a planner's best on pybullet's generated object 041 (70 mm, E = 3e5 Pa,
mu = 0.8, f_max = 15 N, 500 kg/m^3; ``tests/data/shadow_041/grasp.json``, kept here so that
reruns of ``experiments/hand_simulation`` do not change the test), four fingertips in contact. Its convex pieces are CoACD's,
computed once and stored beside the mesh (``tests/data/shadow_041``) so that the test does
not run CoACD.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import mujoco  # noqa: F401  (the extra jaxgrasp[sim])
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.simulation import SimulationStatus, simulate

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "shadow_041"
TIPS = [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")]


@pytest.fixture(scope="module")
def planned():
    row = json.loads((DATA / "grasp.json").read_text())
    hand = jaxgrasp.Hand.from_file(ROOT / "examples" / "hands" / "shadow" / "shadow_hand.xml", TIPS)
    hg = hand.grasp(row["qpos"], DATA / "041.stl", wrist=row["wrist"], young_modulus=3e5, friction=0.8,
                    max_force=15.0, density=500.0, units="mm")
    return hg, jaxgrasp.evaluate(hg.grasp)


@pytest.fixture(scope="module")
def pieces_stored(tmp_path_factory):
    with np.load(DATA / "pieces.npz") as z:
        v, f, nv, nf = z["vertices"], z["faces"], z["vertex_counts"], z["face_counts"]
    cv, cf = np.cumsum(np.r_[0, nv]), np.cumsum(np.r_[0, nf])
    folder = tmp_path_factory.mktemp("convex")
    return folder, [(v[cv[k]:cv[k + 1]], f[cf[k]:cf[k + 1]]) for k in range(len(nv))]


def _simulate(planned, pieces_stored, monkeypatch, friction=None):
    from jaxgrasp.simulation import _convex

    hg, evaluation = planned
    folder, pieces = pieces_stored
    monkeypatch.setattr(_convex, "_folder", lambda: folder)
    path = folder / f"{_convex.mesh_digest(hg.mesh.vertices, hg.mesh.faces)}.npz"
    if not path.exists():
        _convex._write(path, pieces)
    return simulate(hg, protocol="dexgraspbench", evaluation=evaluation, friction=friction)


@pytest.mark.slow
def test_a_planned_shadow_grasp_holds_at_06_and_fails_at_001(planned, pieces_stored, monkeypatch):
    """At the protocol's friction the object stays within 2 cm and 10 degrees through all six
    pushes (before the fixes of issue 68 it left the hand before the first); every active
    at least three of its four active fingertips press at the end of the squeeze (the little
    finger is pushed off), none more than twice eq. 4's force (the
    calibration does not reach 10 % on this hand: experiments/hand_simulation/FINDINGS.md).
    At 0.01 the object slides out."""
    hg, _ = planned
    held = _simulate(planned, pieces_stored, monkeypatch)
    assert held.status is SimulationStatus.SIMULATED and held.parameters["convex_from"] == "cache"
    assert held.success is True and len(held.six_axis) == 6
    for t in held.six_axis:
        assert t.max_displacement_m < 0.02 and t.max_rotation_rad < math.radians(10)
    active = np.asarray(hg.active, dtype=bool)
    settled, model = held.settled_normal_force_N[active], held.model_normal_force_N[active]
    assert np.all(np.isfinite(model)) and np.all(model > 0)
    assert np.sum(settled > 0.5) >= 3 and np.all(settled < 2.0 * model)
    assert held.parameters["initial_penetration_m"]["hand_object"] < 0.01
    slid = _simulate(planned, pieces_stored, monkeypatch, friction=0.01)
    assert slid.success is False
    assert all(t.max_displacement_m > 0.05 or t.max_rotation_rad > math.radians(15) for t in slid.six_axis)
