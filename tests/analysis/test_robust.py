"""Tests of :func:`jaxgrasp.robust` and :func:`jaxgrasp.robust_batch` (issue 39).

Cheap by construction: every evaluation is of 2-contact grasps through the two programs
the suite compiles anyway, :func:`jaxgrasp.evaluate` for 2 contacts (the friction
threshold's bisection) and :func:`jaxgrasp.evaluate_batch` for 2 contacts in chunks of 4
(the samples and the nominal grasps, one grasp too; ``tests/tolerance/test_degenerate.py``
uses it too).

The friction test has a closed answer: on the cube with a mass the grasp is stable
exactly where the friction exceeds a threshold ``mu*`` (found here by bisection with
``evaluate``; the weight ``m g`` shared by two friction forces ``mu pi E dr^2`` gives
nearly the same number), and ``Uncertainty(friction=s)`` multiplies the friction by
``exp(s z)``, so ``p_stable`` must be ``Phi(ln(mu / mu*) / s)``; and each sample's status
must be that of its own friction against ``mu*``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.analysis import RobustStatus, Uncertainty

ROOT = Path(__file__).resolve().parents[2]
CHUNK = 4  # the samples' chunk: the 2-contact batch program of chunks of 4
MASS = 0.2306  # kg: the cube's friction threshold near 0.45, below its friction 0.5
SPREAD = 0.2
EVERYTHING = Uncertainty(friction=0.05, friction_per_fingertip=0.05, young_modulus=0.1,
                         initial_deformation=1e-4, position=1e-3, mass=0.1, gravity_angle=0.1)


def _cube(mu: float = 0.5, mass: float = MASS):
    return jaxgrasp.presets.cube(mass=mass).replace(friction=np.full(2, mu))


@pytest.fixture(scope="module")
def threshold() -> float:
    """``mu*``: the cube (mass ``MASS``) is stable above it, by bisection on ``ln mu``."""
    lo, hi = 0.3, 0.6
    assert jaxgrasp.evaluate(_cube(hi)).status_name == "stable" != jaxgrasp.evaluate(_cube(lo)).status_name
    for _ in range(13):  # to 2e-4 relative
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if jaxgrasp.evaluate(_cube(mid)).status_name == "stable" else (mid, hi)
    return math.sqrt(lo * hi)


@pytest.fixture(scope="module")
def friction_runs():
    u = Uncertainty(friction=SPREAD)
    return {s: jaxgrasp.robust(_cube(), u, samples=s, seed=0, chunk_size=CHUNK) for s in (32, 64)}


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_the_threshold_is_the_weight_over_the_squeeze(threshold):
    closed = MASS * 9.81 / (2 * math.pi * 2e5 * 2e-3**2)  # m g = 2 mu pi E dr^2 (eq. 4)
    assert threshold == pytest.approx(closed, rel=2e-3)


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_friction_uncertainty_gives_the_normal_probability(threshold, friction_runs):
    r = friction_runs[64]
    expected = 0.5 * math.erfc(-math.log(0.5 / threshold) / SPREAD / math.sqrt(2))  # Phi(ln(mu/mu*)/s)
    assert r.status == RobustStatus.ESTIMATED and r.converged == 64
    assert abs(r.p_stable - expected) <= 3 * r.p_stable_stderr, (r.p_stable, expected, r.p_stable_stderr)
    # sample by sample: the documented draw (stream [seed, 0, 0]) against the threshold
    mu = 0.5 * np.exp(SPREAD * np.random.default_rng([0, 0, 0]).standard_normal(64))
    clear = np.abs(np.log(mu / threshold)) > 1e-3
    assert np.array_equal((r.statuses == jaxgrasp.GraspStatus.STABLE)[clear], (mu > threshold)[clear])
    assert np.all(r.values[r.statuses != 0] == 0) and np.all(r.values[r.statuses == 0] > 0)
    assert r.value_mean == pytest.approx(r.values.mean(), rel=1e-12)
    np.testing.assert_allclose(r.quantiles, np.quantile(r.values, [0.05, 0.5]), rtol=1e-12)


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_doubling_the_samples_shrinks_the_standard_error_by_sqrt2(friction_runs):
    a, b = friction_runs[32], friction_runs[64]
    assert np.array_equal(a.values, b.values[:32])  # the same first samples
    for r in (a, b):
        assert r.p_stable_stderr == pytest.approx(math.sqrt(r.p_stable * (1 - r.p_stable) / r.samples), rel=1e-12)
    assert a.p_stable_stderr / b.p_stable_stderr == pytest.approx(math.sqrt(2), rel=0.15)


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_zero_uncertainty_gives_the_nominal_evaluation():
    # the samples are the nominal grasp bit for bit, and the nominal grasp (one grasp is a
    # list of one) runs in its samples' program: the same numbers. evaluate's program may
    # round apart from the batch's: the energies by about 1e-15 of themselves, the value
    # (their difference, here a few thousandths of the equilibrium energy) by that much
    # of the energy
    r = jaxgrasp.robust(_cube(), Uncertainty(), samples=4, seed=5, chunk_size=CHUNK)
    nominal = jaxgrasp.evaluate(_cube())
    rounding = 1e-13 * float(nominal.equilibrium_energy)
    assert r.nominal.status_name == nominal.status_name == "stable"
    assert np.all(r.values == float(r.nominal.value)) and np.all(r.statuses == int(nominal.status))
    np.testing.assert_allclose(r.values, float(nominal.value), rtol=0, atol=rounding)
    assert r.p_stable == 1.0 and r.p_stable_stderr == 0.0
    assert r.value_mean == float(r.nominal.value)
    assert float(r.nominal.value) == pytest.approx(float(nominal.value), rel=0, abs=rounding)


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_reproducible_for_a_seed_and_independent_of_the_chunking():
    """Four grasps in one call (their samples share chunks of 4: grasp 1's three samples
    start mid-chunk) give each what it gives alone; a stacked batch gives the same; the same
    seed again gives the same numbers, another seed others. (Four grasps: their nominal
    batch has the samples' chunk, so nothing new is compiled.)"""
    grasps = [_cube(), jaxgrasp.presets.cube(young_modulus=3e5, mass=0.1), _cube(0.6), _cube(0.45, mass=0.1)]
    both = jaxgrasp.robust_batch(grasps, EVERYTHING, samples=3, seed=3, chunk_size=CHUNK)
    stacked = jaxgrasp.robust_batch(jaxgrasp.stack(grasps), EVERYTHING, samples=3, seed=3, chunk_size=CHUNK)
    for i in (0, 1):
        one = jaxgrasp.robust(grasps[i], EVERYTHING, samples=3, seed=3, chunk_size=CHUNK)
        for other in (both[i], stacked[i]):
            assert np.array_equal(other.statuses, one.statuses)
            np.testing.assert_allclose(other.values, one.values, rtol=1e-12, atol=1e-18)
            assert other.p_stable == one.p_stable and other.clipped == one.clipped
    again = jaxgrasp.robust_batch(grasps, EVERYTHING, samples=3, seed=3, chunk_size=CHUNK)
    assert np.array_equal(again.values, both.values) and np.array_equal(again.statuses, both.statuses)
    other_seed = jaxgrasp.robust_batch(grasps, EVERYTHING, samples=3, seed=4, chunk_size=CHUNK)
    assert not np.array_equal(other_seed.values, both.values)
    assert list(both.rank("value_mean")) == list(np.argsort(-both.value_mean, kind="stable"))
    assert set(both.columns()) == {"p_stable", "p_stable_stderr", "value_mean", "value_q05", "value_q50"}


def test_bad_calls_are_one_line_errors():
    cases = [
        ((_cube(), "friction=0.1"), "must be a jaxgrasp.analysis.Uncertainty"),
        ((_cube(), Uncertainty(), 1), "samples must be an integer >= 2"),
        ((_cube(), Uncertainty(), 4, -1), "seed must be an integer >= 0"),
        (([], Uncertainty()), "non-empty list"),
    ]
    for args, message in cases:
        with pytest.raises(jaxgrasp.GraspValueError, match=message):
            jaxgrasp.robust(*args)
    with pytest.raises(jaxgrasp.GraspValueError, match="quantiles must be numbers in"):
        jaxgrasp.robust(_cube(), Uncertainty(), quantiles=(0.5, 1.5))


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_mesh_contacts_move_along_the_mesh():
    """The block of ``examples/block.toml`` (a chamfered box mesh, 2 contacts): each moved
    contact lies in a face of the mesh (in its plane, barycentric coordinates in [0, 1],
    checked face by face in NumPy) and carries that face's outward normal; the robust
    value evaluates such copies."""
    mg = jaxgrasp.load(ROOT / "examples" / "block.toml", keep_mesh=True)
    u = Uncertainty(position=3e-3)
    copies = jaxgrasp.analysis.perturbed(mg, u, samples=16, seed=1)
    pos = mg.to_mesh_frame(np.asarray(copies.positions).reshape(-1, 3))
    tri = np.asarray(mg.mesh.triangles)  # (F, 3, 3)
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = pos[:, None, :] - a[None]  # (P, F, 3)
    plane = np.abs(np.einsum("pfk,fk->pf", d, n))
    g = np.stack([np.einsum("fk,fk->f", e1, e1), np.einsum("fk,fk->f", e1, e2), np.einsum("fk,fk->f", e2, e2)])
    b1, b2 = np.einsum("pfk,fk->pf", d, e1), np.einsum("pfk,fk->pf", d, e2)
    det = g[0] * g[2] - g[1] ** 2
    s, t = (g[2] * b1 - g[1] * b2) / det, (g[0] * b2 - g[1] * b1) / det
    inside = (plane < 1e-12) & (s > -1e-9) & (t > -1e-9) & (s + t < 1 + 1e-9)
    assert inside.any(axis=1).all()
    normals = np.asarray(copies.normals).reshape(-1, 3)
    for k in range(len(pos)):  # the normal of a face the point lies in
        assert np.min(np.linalg.norm(n[inside[k]] - normals[k], axis=1)) < 1e-12, k
    moved = np.linalg.norm(np.asarray(copies.positions) - np.asarray(mg.grasp.positions), axis=-1)
    assert 1e-3 < np.median(moved) < 1e-2  # a 2-D move of 3 mm per coordinate: median 3.5 mm
    r = jaxgrasp.robust(mg, u, samples=4, seed=1, chunk_size=CHUNK)
    assert r.status == RobustStatus.ESTIMATED and r.nominal.status_name == jaxgrasp.evaluate(mg.grasp).status_name
