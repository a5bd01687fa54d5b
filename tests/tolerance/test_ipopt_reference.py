"""Checks of the independent CasADi/Ipopt reference solver against closed forms.

These test the reference itself (``tests/ipopt_reference.py``), not the library.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

try:  # works whether or not tests/ is a package
    from tests.ipopt_reference import (
        reference_constraints,
        reference_evaluate,
        reference_pose_energy,
    )
except ImportError:  # pragma: no cover
    from ipopt_reference import (  # type: ignore[no-redef]
        reference_constraints,
        reference_evaluate,
        reference_pose_energy,
    )

R_TIP = 0.025
MU = 0.5
FMAX = 15.0


pytestmark = pytest.mark.slow  # checks the Ipopt oracle, not the library; runs Ipopt


def cube(young=2e5, dr=2e-3, mu=MU, fmax=FMAX):
    """Two fingertips at the centres of opposite faces of a 100 mm cube, m = 0."""
    return {
        "positions": np.array([[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]]),
        "normals": np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]),
        "initial_deformation": np.full(2, dr),
        "radius": np.full(2, R_TIP),
        "young_modulus": np.full(2, young),
        "friction": np.full(2, mu),
        "max_force": np.full(2, fmax),
        "mass": np.array(0.0),
        "gravity": np.array([0.0, 0.0, -9.81]),
    }


def torsion_bound(young, dr, r=R_TIP, mu=MU):
    """Pure rotation about the grasp axis: d = dr, cos(phi) = 1, dt = 0 (SI units)."""
    theta2 = 16.0 * mu**4 * dr * (2.0 * r - dr) / (225.0 * (r - dr / 3.0) ** 2)
    dU = 2.0 * np.pi * young * dr**2 * (r - dr / 3.0) * theta2
    return np.sqrt(theta2), dU


@pytest.fixture(scope="module")
def cube_results():
    return {E: reference_evaluate(cube(young=E)) for E in (2e5, 6e5)}


@pytest.mark.parametrize("young", [2e5, 6e5])
def test_cube_equilibrium_closed_form(cube_results, young):
    res = cube_results[young]
    dr = 2e-3
    u0 = 2.0 * np.pi * young * dr**3 / 3.0
    assert res["status"] == "stable"
    assert res["equilibrium_energy"] == pytest.approx(u0, rel=1e-10)
    np.testing.assert_allclose(res["equilibrium_pose"], 0.0, atol=1e-9)
    # the closed-form pose energy agrees with the solver's optimum
    assert reference_pose_energy(cube(young=young), np.zeros(6)) == pytest.approx(u0, rel=1e-13)


@pytest.mark.parametrize("young", [2e5, 6e5])
def test_cube_torsion_bound(cube_results, young):
    res = cube_results[young]
    dr = 2e-3
    theta, dU = torsion_bound(young, dr)
    x = np.array([0.0, 0.0, 0.0, theta, 0.0, 0.0])
    g = cube(young=young)

    # the pure-torsion pose lies on the slip boundary of both contacts ...
    cons = reference_constraints(g, x)
    np.testing.assert_allclose(cons["slip"], 0.0, atol=1e-12)
    assert np.all(cons["max_force"] > 0) and np.all(cons["contact"] > 0)
    np.testing.assert_allclose(cons["d"], dr, rtol=1e-12)
    np.testing.assert_allclose(cons["cos_phi"], 1.0, rtol=0, atol=1e-15)
    # ... and its energy above the equilibrium is the closed form
    u_theta = reference_pose_energy(g, x)
    assert u_theta - res["equilibrium_energy"] == pytest.approx(dU, rel=1e-12)

    # the minimum over the boundary cannot exceed a feasible boundary point
    assert res["value"] <= dU * (1 + 1e-12)
    assert res["value"] > 0
    assert res["limiting"][0] == "slip"


def test_cube_symmetry_and_scaling(cube_results):
    # both contacts of the symmetric cube have the same slip boundary energy
    be = cube_results[2e5]["boundary_energy"]
    assert be[0, 0] == pytest.approx(be[0, 1], rel=1e-9)
    # with m = 0 and the max-force boundaries not limiting, the value is linear in E
    v2, v6 = cube_results[2e5]["value"], cube_results[6e5]["value"]
    assert v6 == pytest.approx(3.0 * v2, rel=1e-8)
    # 2 dr < sqrt(fmax / (pi E)) at E = 2e5: the max-force boundary is unreachable
    assert np.all(np.isinf(cube_results[2e5]["boundary_energy"][1]))


def test_cube_boundary_pose_is_on_boundary(cube_results):
    res = cube_results[2e5]
    kind, j = res["limiting"]
    x = res["boundary_pose"][0 if kind == "slip" else 1, j]
    cons = reference_constraints(cube(), x)
    assert abs(cons[kind][j]) < 1e-9
    for k in ("contact", "slip", "max_force"):
        assert np.all(cons[k] > -1e-9)
    assert reference_pose_energy(cube(), x) == pytest.approx(
        res["value"] + res["equilibrium_energy"], rel=1e-12
    )


def test_cube_infeasible():
    # dr = 3 mm > sqrt(fmax / (pi E)) = 2.19 mm at E = 1e6 Pa
    res = reference_evaluate(cube(young=1e6, dr=3e-3), n_starts=8)
    assert res["status"] == "infeasible"
    assert res["value"] == 0.0
    assert res["limiting"] is None


def test_cube_with_gravity_closed_form():
    # Gravity along z, perpendicular to the grasp axis: the object sinks by
    # dz = -m g / (4 pi E dr) (tangential stiffness 2 pi E dr per contact), d and the
    # rotation stay put, and U0 = 2 pi E dr^3 / 3 - (m g)^2 / (8 pi E dr).
    young, dr, mass, grav = 2e5, 2e-3, 0.25, 9.81
    g = cube(young=young, dr=dr)
    g["mass"] = np.array(mass)
    res = reference_evaluate(g, n_starts=8)
    dz = -mass * grav / (4 * np.pi * young * dr)
    u0 = 2 * np.pi * young * dr**3 / 3 - (mass * grav) ** 2 / (8 * np.pi * young * dr)
    assert res["status"] == "stable"
    assert res["equilibrium_energy"] == pytest.approx(u0, rel=1e-10)
    np.testing.assert_allclose(res["equilibrium_pose"], [0, 0, dz, 0, 0, 0], atol=1e-10)
    slip = res["equilibrium_margins"]["slip"]
    np.testing.assert_allclose(slip, 1 - 4 * dz**2 / (MU**2 * dr**2), rtol=1e-8)
    assert 0 < res["value"] < torsion_bound(young, dr)[1]


def test_cube_too_heavy_is_unstable():
    # friction can carry at most 2 mu pi E dr^2 = 2.51 N < 9.81 N: the energy minimum
    # over the equilibrium region sits on the slip boundary
    g = cube()
    g["mass"] = np.array(1.0)
    res = reference_evaluate(g, n_starts=4)
    assert res["status"] == "unstable"
    assert res["value"] == 0.0 and res["limiting"] is None
    assert np.min(res["equilibrium_margins"]["slip"]) < 1e-9


# random_urdfs 078 (mm mesh scaled by 15, density 500 kg/m^3), two fingertips drawn by
# experiments/settling/settle_real.py (part 0/2, two-finger candidate 1304): without the
# reference's |w| < pi rule, Ipopt reached contact 0's slip boundary at |w| = 6.28 rad
# (a full turn, whose torsion w . n is an artefact) and gave a value of 1.847e-3 J.
GRASP_078 = {
    "positions": np.array([[0.0011919498886308244, -0.005654839139072439, -0.015263397982208967],
                           [-0.002449276448282287, -0.0038687466328001666, 0.015773816016580552]]),
    "normals": np.array([[0.11632911381573946, -0.05706169854735303, -0.991570219317692],
                         [-0.09077959821073214, -0.06329945572926872, 0.9938572550688939]]),
    "initial_deformation": np.full(2, 0.0033337698869064015),
    "radius": np.full(2, 0.01),
    "young_modulus": np.full(2, 3e5),
    "friction": np.full(2, 0.8),
    "max_force": np.full(2, 15.0),
    "mass": 0.038359128808497456,
    "gravity": np.array([0.0, 0.0, -9.81]),
}


def test_rotations_stay_principal():
    """Every pose the reference keeps has a principal rotation vector (``|w| < pi``), and
    on the grasp where Ipopt found a full-turn image its value is jaxgrasp's (2.4841e-3 J,
    ``jaxgrasp.evaluate`` on commit 3c24a8c: force limit of contact 0)."""
    ref = reference_evaluate(GRASP_078, n_starts=24, seed=0)
    poses = np.asarray(ref["boundary_pose"]).reshape(-1, 6)
    finite = np.all(np.isfinite(poses), axis=1)
    assert finite.any() and np.all(np.linalg.norm(poses[finite, 3:], axis=1) < np.pi), poses
    assert ref["status"] == "stable" and ref["limiting"] == ("max_force", 0), ref["limiting"]
    assert abs(ref["value"] - 2.4840955081887e-3) <= 1e-6 * 2.4840955081887e-3, ref["value"]
