"""Tests of the uncertainty model (``jaxgrasp/analysis/_uncertainty.py``): the spec, the
draws and the perturbed fields. Pure NumPy, nothing is evaluated or compiled.

Each distribution of :class:`jaxgrasp.analysis.Uncertainty`'s docstring is checked on many
samples against its stated moments, each geometric rule exactly (a tangential move keeps
the normal and is orthogonal to it; a tilt keeps gravity's magnitude), and each clip is
counted where the sampled number left its valid range.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.analysis import Uncertainty, parse_spec
from jaxgrasp.analysis._uncertainty import SOURCES, draw_normals, perturb

S = 20000  # samples for the moment checks: a standard error of about 0.7 % of a spread


def _fields(grasp) -> dict:
    return jaxgrasp.stack([grasp]).replace(active=None).to_numpy_batch()


def _perturbed(grasp, u: Uncertainty, samples: int = S, seed: int = 0):
    fields = _fields(grasp)
    z = draw_normals(u, samples, seed, fields["positions"].shape[1])
    return fields, *perturb(fields, u, z, samples)


PRISM = jaxgrasp.presets.prism(mass=0.1, gravity=(0.0, -3.0, -9.0))


def test_zero_spreads_copy_every_field_bit_for_bit():
    fields, out, clipped = _perturbed(PRISM, Uncertainty(), samples=5)
    for k, v in fields.items():
        assert out[k].shape == (5, *v.shape[1:])
        assert np.array_equal(out[k], np.repeat(v, 5, axis=0)), k
    assert all(c.tolist() == [0] for c in clipped.values())


def test_friction_is_one_lognormal_factor_shared_by_the_fingertips():
    fields, out, _ = _perturbed(PRISM, Uncertainty(friction=0.2))
    log = np.log(out["friction"] / fields["friction"])
    assert np.allclose(log, log[:, :1], rtol=0, atol=1e-15)  # one factor per sample
    assert abs(log[:, 0].std() - 0.2) < 0.005 and abs(log[:, 0].mean()) < 0.005
    # the stated stream: contact 0 of source 0 ('friction'), seeded [seed, 0, 0]
    z = np.random.default_rng([0, 0, 0]).standard_normal((S, 1))[:, 0]
    np.testing.assert_allclose(log[:, 0], 0.2 * z, rtol=0, atol=1e-14)


def test_per_fingertip_friction_young_modulus_and_deformation_are_independent_per_contact():
    u = Uncertainty(friction_per_fingertip=0.1, young_modulus=0.3, initial_deformation=2e-4)
    fields, out, clipped = _perturbed(PRISM, u)
    lf = np.log(out["friction"] / fields["friction"])
    le = np.log(out["young_modulus"] / fields["young_modulus"])
    dd = out["initial_deformation"] - fields["initial_deformation"]
    for a, sd in ((lf, 0.1), (le, 0.3), (dd, 2e-4)):
        assert np.all(np.abs(a.std(axis=0) / sd - 1) < 0.03)
        assert abs(np.corrcoef(a[:, 0], a[:, 1])[0, 1]) < 0.05  # independent fingertips
    assert all(c.tolist() == [0] for c in clipped.values())  # 2 mm +- 0.2 mm stays inside (0, 25 mm)


def test_position_moves_in_the_tangent_plane_and_keeps_the_normal():
    fields, out, _ = _perturbed(PRISM, Uncertainty(position=1e-3))
    d = out["positions"] - fields["positions"]
    n = fields["normals"][0]
    assert np.array_equal(out["normals"], np.repeat(fields["normals"], S, axis=0))
    assert np.max(np.abs(np.einsum("sij,ij->si", d, n))) < 1e-17
    r2 = np.sum(d * d, axis=-1)  # two tangential coordinates of std 1e-3 each: E|d|^2 = 2e-6
    assert np.all(np.abs(r2.mean(axis=0) / 2e-6 - 1) < 0.03)


def test_mass_and_gravity_angle():
    fields, out, _ = _perturbed(PRISM, Uncertainty(mass=0.5, gravity_angle=0.1))
    lm = np.log(out["mass"] / fields["mass"])
    assert abs(lm.std() - 0.5) < 0.01
    g0, g = fields["gravity"][0], out["gravity"]
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), np.linalg.norm(g0), rtol=1e-14)
    cos = g @ g0 / np.dot(g0, g0)
    angle = np.arccos(np.clip(cos, -1, 1))  # |v|, v two tilt coordinates of std 0.1: E|v|^2 = 0.02
    assert abs(np.mean(angle**2) / 0.02 - 1) < 0.03


def test_clips_are_counted_and_stay_in_the_valid_range():
    # initial deformation 2 mm +- 5 mm: about a third of the samples fall below r / 1000
    fields, out, clipped = _perturbed(jaxgrasp.presets.cube(), Uncertainty(initial_deformation=5e-3), samples=400)
    dr = out["initial_deformation"]
    moved = fields["initial_deformation"] + 5e-3 * draw_normals(Uncertainty(initial_deformation=1), 400, 0, 2)[
        "initial_deformation"][..., 0]
    outside = int(np.sum((moved < 0.025e-3) | (moved > 0.025 * (1 - 1e-3))))
    assert clipped["initial_deformation"].tolist() == [outside] and outside > 100
    assert dr.min() == pytest.approx(0.025e-3) and np.all(dr < 0.025)
    jaxgrasp.engine._batch.check_batch_inputs(out)  # every sample is a valid grasp
    # friction past MAX_FRICTION (1e3): a friction of 500 doubled
    big = jaxgrasp.Grasp.create([[0.05, 0, 0], [-0.05, 0, 0]], [[1, 0, 0], [-1, 0, 0]], 2e-3, radius=0.025,
                                young_modulus=2e5, friction=500.0, max_force=15.0)
    _, out, clipped = _perturbed(big, Uncertainty(friction=1.0), samples=100)
    assert out["friction"].max() == 1e3 and clipped["friction"][0] == 2 * np.sum(out["friction"][:, 0] == 1e3) > 0
    # a mass whose weight passes 1e4 times the squeeze (pi E dr^2 = 2.5 N per contact)
    heavy = jaxgrasp.presets.cube(mass=4000.0)
    _, out, clipped = _perturbed(heavy, Uncertainty(mass=0.5), samples=100)
    limit = 1e4 * 2 * math.pi * 2e5 * 4e-6 / 9.81
    assert out["mass"].max() <= limit and clipped["mass"][0] == np.sum(out["mass"] > limit * (1 - 1e-9)) > 0


def test_draws_do_not_depend_on_the_contact_count_and_extend_with_more_samples():
    u = Uncertainty(position=1.0, friction=1.0)
    a, b = draw_normals(u, 10, 7, 2), draw_normals(u, 20, 7, 5)
    assert np.array_equal(a["position"], b["position"][:10, :2])
    assert np.array_equal(a["friction"], b["friction"][:10])
    assert not np.array_equal(a["position"], draw_normals(u, 10, 8, 2)["position"])


def test_spec_round_trip_and_one_line_errors():
    u = parse_spec("friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3,mass=0.05,gravity-angle=0.02")
    assert u == Uncertainty(friction=0.1, young_modulus=0.1, initial_deformation=2e-4, position=1e-3, mass=0.05,
                            gravity_angle=0.02)
    assert parse_spec(u.to_spec()) == u and parse_spec("none") == Uncertainty()
    assert set(u.to_dict()) == set(SOURCES)
    bad = {
        "friction": "not name=value",
        "friction=x": "is not a number",
        "fric=0.1": "unknown source 'fric'",
        "friction=0.1,friction=0.2": "given twice",
        "friction=-0.1": "friction = -0.1 must be in [0, 3]",
        "friction=4": "must be in [0, 3]",
        "position=nan": "position = nan m must be >= 0 and finite",
        "gravity_angle=4": "gravity_angle = 4 rad must be in [0, 3.14159]",
        "": "is not name=value",
    }
    for spec, message in bad.items():
        with pytest.raises(jaxgrasp.GraspValueError) as info:
            parse_spec(spec)
        assert message in str(info.value) and "\n" not in str(info.value), (spec, str(info.value))
    with pytest.raises(jaxgrasp.GraspValueError, match="must be a number"):
        Uncertainty(friction="0.1")
