"""Tests of jaxgrasp.evaluate: closed forms, the independent Ipopt reference, result
structure, jit/vmap, and the kinematics of the returned boundary poses.

All grasps of this module are declared in ``CASES`` and evaluated together (one compiled
``jit(vmap(evaluate))`` per contact count, see ``conftest.py``); the Ipopt references of
``IPOPT_CASES`` run in a worker process meanwhile.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.model import _potential as M
from jaxgrasp import presets

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
R_TIP, MU, FMAX = 0.025, 0.5, 15.0
G = 9.81


# ----------------------------------------------------------------------------- grasps
def cube(E, dr, mass=0.0, **kw):
    return presets.cube(E, dr, mass, **kw)


def prism(E, dr, mass=0.0, **kw):
    return presets.prism(E, dr, mass, **kw)


def with_max_force(g, fmax):
    return g.replace(max_force=jnp.full_like(g.max_force, fmax))


def wedge2(tilt_deg=15.0, E=4e5, dr=2e-3, mass=0.05):
    """Two fingertips on the slanted faces of a wedge; normals tilted up by ``tilt_deg``."""
    a = math.radians(tilt_deg)
    return jaxgrasp.Grasp.create(
        positions=[[0.03, 0.0, 0.0], [-0.03, 0.0, 0.0]],
        normals=[[math.cos(a), 0.0, math.sin(a)], [-math.cos(a), 0.0, math.sin(a)]],
        initial_deformation=dr,
        radius=R_TIP,
        young_modulus=E,
        friction=MU,
        max_force=FMAX,
        mass=mass,
    )


def slanted_prism(tilt_deg=-12.0, E=3e5, dr=2e-3, mass=0.05):
    """The prism's contacts with normals tilted out of the horizontal plane by ``tilt_deg``."""
    g = presets.prism(E, dr, mass)
    b = math.radians(tilt_deg)
    n = np.asarray(g.normals)
    n = np.concatenate([math.cos(b) * n[:, :2], np.full((3, 1), math.sin(b))], axis=1)
    return jaxgrasp.Grasp.create(
        positions=np.asarray(g.positions),
        normals=n,
        initial_deformation=dr,
        radius=R_TIP,
        young_modulus=E,
        friction=MU,
        max_force=FMAX,
        mass=mass,
    )


def unequal_prism():
    g = presets.prism(4e5, [1.5e-3, 2.0e-3, 2.5e-3], 0.05)
    return g.replace(young_modulus=jnp.array([3e5, 4e5, 5e5]))


def tilted_gravity_prism():
    a = math.radians(20.0)
    return presets.prism(4e5, 2e-3, 0.1, gravity=(G * math.sin(a), 0.0, -G * math.cos(a)))


def tilted_gravity_cube():
    return presets.cube(4e5, 2.5e-3, 0.15, gravity=(3.0, 1.0, -9.2))


def rotate_about_z(g, deg):
    a = math.radians(deg)
    Q = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return g.replace(
        positions=jnp.asarray(np.asarray(g.positions) @ Q.T),
        normals=jnp.asarray(np.asarray(g.normals) @ Q.T),
        gravity=jnp.asarray(np.asarray(g.gravity) @ Q.T),
    )


def permute_contacts(g, perm):
    perm = np.asarray(perm)
    per_contact = ("positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force")
    return g.replace(**{k: jnp.asarray(getattr(g, k))[perm] for k in per_contact})


CUBE_CLOSED_FORM = [(2e5, 1e-3), (2e5, 2e-3), (2e5, 3e-3), (6e5, 2e-3), (1e6, 1e-3), (1e6, 2e-3)]

CASES = {
    # --- 2 contacts
    **{f"cube_E{E:.0e}_dr{dr:.0e}": cube(E, dr) for E, dr in CUBE_CLOSED_FORM},
    "cube_E6e5_dr2.7e-3": cube(6e5, 2.7e-3),  # force margin small: max_force limited
    "cube_E1e6_dr3e-3": cube(1e6, 3e-3),  # pi E dr^2 > fmax and nothing relieves it: infeasible
    "cube_E2e5_dr5e-3": cube(2e5, 5e-3),  # infeasible too (pi E dr^2 = 15.7 N)
    "cube_E6e5_dr2e-3_fmax45": with_max_force(cube(6e5, 2e-3), 45.0),  # 3x of cube_E2e+05_dr2e-03
    "cube_E9e5_dr1.5e-3_fmax45": with_max_force(cube(9e5, 1.5e-3), 45.0),
    "cube_E3e5_dr1.5e-3": cube(3e5, 1.5e-3),
    "cube_unequal_dr": cube(4e5, [1.5e-3, 2.5e-3]),
    "cube_E4e5_dr2e-3": cube(4e5, 2e-3),  # the unequal cube, recentred
    "cube_heavy": cube(2e5, 2e-3, 1.0),  # friction holds at most ~0.26 kg
    "cube_tilted_gravity": tilted_gravity_cube(),
    "wedge2_15deg": wedge2(),
    "cube_E8e5_dr1e-3": cube(8e5, 1e-3),
    # --- 3 contacts
    "prism_E2e5_dr2e-3_m0": prism(2e5, 2e-3, 0.0),
    "prism_E2e5_dr2e-3_m0.1": prism(2e5, 2e-3, 0.1),
    "prism_E6e5_dr1.5e-3_m0": prism(6e5, 1.5e-3, 0.0),
    "prism_E6e5_dr1.5e-3_m0.1": prism(6e5, 1.5e-3, 0.1),
    "prism_unequal": unequal_prism(),
    "prism_slanted_-12deg": slanted_prism(),
    "prism_tilted_gravity": tilted_gravity_prism(),
    "prism_heavy": prism(2e5, 2e-3, 1.0),  # friction holds at most ~0.38 kg
    "prism_m0.1_permuted": permute_contacts(prism(2e5, 2e-3, 0.1), [2, 0, 1]),
    "prism_m0.1_rotated40": rotate_about_z(prism(2e5, 2e-3, 0.1), 40.0),
    # --- 4 contacts
    "four_finger": jaxgrasp.load(EXAMPLES / "four_finger.json"),
    "four_finger_m0": jaxgrasp.load(EXAMPLES / "four_finger.json").replace(mass=jnp.asarray(0.0)),
}

IPOPT_CASES = [
    "cube_E2e+05_dr1e-03",
    "cube_E6e+05_dr2e-03",  # slip limited
    "cube_E1e+06_dr2e-03",  # max_force limited
    "cube_E6e5_dr2.7e-3",
    "cube_E1e6_dr3e-3",  # infeasible
    "cube_E2e5_dr5e-3",  # infeasible
    "cube_unequal_dr",
    "cube_heavy",
    "cube_tilted_gravity",
    "wedge2_15deg",
    "prism_E2e5_dr2e-3_m0",
    "prism_E2e5_dr2e-3_m0.1",
    "prism_E6e5_dr1.5e-3_m0",
    "prism_E6e5_dr1.5e-3_m0.1",
    "prism_unequal",
    "prism_slanted_-12deg",
    "prism_tilted_gravity",
    "prism_heavy",
    "four_finger",
    "four_finger_m0",
]
assert set(IPOPT_CASES) <= set(CASES)


@pytest.fixture(scope="module")
def results(evaluate_many, ipopt_reference):
    if ipopt_reference is not None:  # Ipopt runs in a worker process while JAX compiles
        ipopt_reference.submit([CASES[k] for k in IPOPT_CASES])
    return dict(zip(CASES, evaluate_many(list(CASES.values()))))


@pytest.fixture(scope="module")
def refs(results, ipopt_reference):
    if ipopt_reference is None:
        pytest.skip("casadi (for the Ipopt reference) is not installed")
    return {k: ipopt_reference.get(CASES[k]) for k in IPOPT_CASES}


def torsion_bound(E, dr, r=R_TIP, mu=MU):
    """Energy to twist the cube about its grasp axis until both tips slip (SI units)."""
    theta2 = 16.0 * mu**4 * dr * (2.0 * r - dr) / (225.0 * (r - dr / 3.0) ** 2)
    return 2.0 * np.pi * E * dr**2 * (r - dr / 3.0) * theta2


def name(res):
    return jaxgrasp.GraspStatus.labels()[int(res.status)]


# ----------------------------------------------------------------------------- dtype
@pytest.mark.slow  # a subprocess
def test_float64_by_default_in_a_fresh_interpreter():
    """Importing jaxgrasp alone turns on 64-bit mode (no conftest, no user configuration)."""
    code = (
        "import jaxgrasp, jax, jax.numpy as jnp\n"
        "from jaxgrasp import model\n"
        "p = model.model_params(jaxgrasp.presets.cube())\n"
        "u = model.potential_energy(jnp.zeros(6), p)\n"
        "print(jax.config.jax_enable_x64, jnp.asarray(1.0).dtype, u.dtype, p.E.dtype)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "float64", "float64", "float64"]


def test_evaluate_returns_float64():
    res = jaxgrasp.evaluate(cube(6e5, 2e-3))
    for leaf in (res.value, res.equilibrium_energy, res.boundary_energy, res.equilibrium_translation):
        assert jnp.asarray(leaf).dtype == jnp.float64


# ----------------------------------------------------------------------------- closed forms
@pytest.mark.parametrize("E, dr", CUBE_CLOSED_FORM)
def test_cube_equilibrium_energy_closed_form(results, E, dr):
    res = results[f"cube_E{E:.0e}_dr{dr:.0e}"]
    assert name(res) == "stable"
    assert float(res.equilibrium_energy) == pytest.approx(2.0 * np.pi * E * dr**3 / 3.0, rel=1e-10)
    np.testing.assert_allclose(res.equilibrium_translation, 0.0, atol=1e-12)
    np.testing.assert_allclose(res.equilibrium_rotation, 0.0, atol=1e-10)


@pytest.mark.parametrize("E, dr", CUBE_CLOSED_FORM)
def test_cube_value_below_torsion_bound(results, E, dr):
    res = results[f"cube_E{E:.0e}_dr{dr:.0e}"]
    assert 0.0 < float(res.value) <= torsion_bound(E, dr) * (1 + 1e-9)


@pytest.mark.parametrize(
    "base, scaled",
    [
        ("cube_E2e+05_dr2e-03", "cube_E6e5_dr2e-3_fmax45"),
        ("cube_E3e5_dr1.5e-3", "cube_E9e5_dr1.5e-3_fmax45"),
    ],
)
def test_value_scales_with_young_modulus_and_force_limit(results, base, scaled):
    """m = 0: U is linear in E and the region is unchanged when E and f_max scale together."""
    a, b = results[base], results[scaled]
    assert name(a) == name(b) == "stable"
    assert float(b.value) == pytest.approx(3.0 * float(a.value), rel=1e-8)
    assert float(b.equilibrium_energy) == pytest.approx(3.0 * float(a.equilibrium_energy), rel=1e-10)
    assert (int(b.limiting_kind), int(b.limiting_contact)) == (int(a.limiting_kind), int(a.limiting_contact))


def test_unequal_deformations_recentre(results):
    """Opposed tips with dr = 1.5 and 2.5 mm: the cube shifts 0.5 mm to even them out, after
    which it is the same system as the 2 mm symmetric cube (same energies, same value)."""
    a, b = results["cube_unequal_dr"], results["cube_E4e5_dr2e-3"]
    assert name(a) == name(b) == "stable"
    np.testing.assert_allclose(a.equilibrium_translation, [5e-4, 0.0, 0.0], atol=1e-12)
    assert float(a.equilibrium_energy) == pytest.approx(2 * np.pi * 4e5 * 2e-3**3 / 3, rel=1e-10)
    assert float(a.value) == pytest.approx(float(b.value), rel=1e-6)


@pytest.mark.parametrize(
    "other", ["prism_m0.1_permuted", "prism_m0.1_rotated40"], ids=["renumbered", "rotated_about_gravity"]
)
def test_value_invariant_under_renumbering_and_rotation_about_gravity(results, other):
    a, b = results["prism_E2e5_dr2e-3_m0.1"], results[other]
    assert name(a) == name(b)
    assert float(b.equilibrium_energy) == pytest.approx(float(a.equilibrium_energy), rel=1e-8)
    assert float(b.value) == pytest.approx(float(a.value), rel=1e-6)


# ----------------------------------------------------------------------------- Ipopt
@pytest.mark.parametrize("case", IPOPT_CASES)
def test_agrees_with_ipopt(results, refs, case):
    res, ref = results[case], refs[case]
    status = name(res)
    jv, iv = float(res.value), float(ref["value"])
    summary = (
        f"{case}: jaxgrasp {status} value={jv!r} limiting=({int(res.limiting_kind)},{int(res.limiting_contact)}) "
        f"U0={float(res.equilibrium_energy)!r} | ipopt {ref['status']} value={iv!r} limiting={ref['limiting']} "
        f"U0={ref['equilibrium_energy']!r}\n  jax boundaries={np.asarray(res.boundary_energy).tolist()}"
        f"\n  ipopt boundaries={np.asarray(ref['boundary_energy']).tolist()}"
    )
    assert status == ref["status"], summary
    if status == "infeasible":
        assert jv == 0.0
        return
    u0_j, u0_i = float(res.equilibrium_energy), float(ref["equilibrium_energy"])
    assert u0_j == pytest.approx(u0_i, rel=1e-8), summary
    if status == "unstable":
        assert jv == 0.0 and iv == 0.0
        return

    # stable: the same value as Ipopt's multi-start reference, whatever boundary either
    # names as limiting (a value far too low on another boundary is as wrong as one too
    # high). Tolerance: 1e-6 relative, plus the rounding of a difference of two energies
    # each known to ~1e-12 relative (1e-9 |U0|, far below every value here).
    tol = 1e-6 * abs(iv) + 1e-9 * abs(u0_i)
    assert abs(jv - iv) <= tol, f"|value - ipopt| = {abs(jv - iv)!r} > {tol!r}: " + summary
    jbe = np.asarray(res.boundary_energy, dtype=float)
    ibe = np.asarray(ref["boundary_energy"], dtype=float)
    # the boundary jaxgrasp names as limiting is at Ipopt's minimum too (or ties with it,
    # e.g. between symmetric contacts)
    k, j = int(res.limiting_kind), int(res.limiting_contact)
    assert ibe[k, j] - u0_i <= iv + tol, f"limiting ({k},{j}) is above Ipopt's minimum: " + summary
    # every boundary that both reach: jaxgrasp's minimum is no higher than Ipopt's
    both = np.isfinite(jbe) & np.isfinite(ibe)
    tol = 1e-6 * np.maximum(ibe - u0_i, iv) + 1e-8 * abs(u0_i)
    worse = both & (jbe > ibe + tol)
    assert not worse.any(), f"boundaries {np.argwhere(worse).tolist()} higher than Ipopt's: " + summary


# ----------------------------------------------------------------------------- structure
@pytest.mark.parametrize("case", list(CASES))
def test_result_structure(results, case):
    res = results[case]
    n = CASES[case].num_contacts
    assert np.shape(res.value) == () and np.shape(res.status) == ()
    assert np.shape(res.boundary_energy) == (2, n)
    assert np.shape(res.boundary_status) == (2, n)
    assert np.shape(res.boundary_translation) == (2, n, 3)
    assert np.shape(res.boundary_rotation) == (2, n, 3)
    assert np.shape(res.equilibrium_translation) == (3,) and np.shape(res.equilibrium_rotation) == (3,)
    assert np.shape(res.kkt) == (1 + 2 * n, 3) and np.shape(res.steps) == (1 + 2 * n,)
    status = int(res.status)
    assert status in (jaxgrasp.GraspStatus.STABLE, jaxgrasp.GraspStatus.UNSTABLE, jaxgrasp.GraspStatus.INFEASIBLE, jaxgrasp.GraspStatus.NOT_CONVERGED)
    be, bs = np.asarray(res.boundary_energy), np.asarray(res.boundary_status)
    # 3 (not started) exactly when the equilibrium problem did not converge
    if int(res.equilibrium_status) == 0:
        assert set(np.unique(bs)) <= {0, 1, 2}
    else:
        assert (bs == 3).all()
    assert np.isfinite(be[bs == 0]).all() and np.isposinf(be[(bs == 1) | (bs == 3)]).all()
    if status in (jaxgrasp.GraspStatus.UNSTABLE, jaxgrasp.GraspStatus.INFEASIBLE):
        assert float(res.value) == 0.0
        assert int(res.limiting_kind) == -1 and int(res.limiting_contact) == -1
        assert not bool(res.tolerates(0.0))
    if status == jaxgrasp.GraspStatus.STABLE:
        v = float(res.value)
        assert v > 0.0 and np.isfinite(v)
        k, j = int(res.limiting_kind), int(res.limiting_contact)
        assert 0 <= k < 2 and 0 <= j < n
        assert bs[k, j] == 0
        assert float(be[k, j]) - float(res.equilibrium_energy) == pytest.approx(v, rel=1e-12)
        assert v == pytest.approx(float(np.min(be)) - float(res.equilibrium_energy), rel=1e-12)
        assert (be[bs == 0] >= float(res.equilibrium_energy) - 1e-12 * abs(float(res.equilibrium_energy))).all()


def test_expected_statuses(results):
    assert name(results["cube_E1e6_dr3e-3"]) == "infeasible"
    assert name(results["cube_E2e5_dr5e-3"]) == "infeasible"
    assert name(results["cube_heavy"]) == "unstable"
    assert name(results["prism_heavy"]) == "unstable"
    for k in ("cube_E1e6_dr3e-3", "cube_heavy", "prism_heavy"):
        assert float(results[k].value) == 0.0
    # paper's cube, E = 1e6 Pa, dr = 2 mm: the force limit binds, not friction
    assert jaxgrasp.model.BoundaryKind.labels()[int(results["cube_E1e+06_dr2e-03"].limiting_kind)] == "max_force"
    assert jaxgrasp.model.BoundaryKind.labels()[int(results["cube_E6e+05_dr2e-03"].limiting_kind)] == "slip"


@pytest.mark.parametrize("case", ["cube_E6e+05_dr2e-03", "prism_E2e5_dr2e-3_m0.1", "four_finger"])
def test_tolerates(results, case):
    res = results[case]
    assert name(res) == "stable"
    v = float(res.value)
    assert bool(res.tolerates(v * (1 - 1e-6)))
    assert not bool(res.tolerates(v * (1 + 1e-6)))
    assert bool(res.tolerates(0.0))
    # with a current potential energy above the equilibrium, less kinetic energy is tolerated
    u = float(res.equilibrium_energy) + 0.5 * v
    assert bool(res.tolerates(0.49 * v, u)) and not bool(res.tolerates(0.51 * v, u))
    # batched kinetic energies
    np.testing.assert_array_equal(np.asarray(res.tolerates(jnp.array([0.0, 0.5 * v, 2 * v]))), [True, True, False])


@pytest.mark.slow  # compiles evaluate under the caller's jit
def test_jit_matches_evaluate():
    """A concrete grasp runs the memoised (or stored) program of ``jaxgrasp.engine._store``, a
    traced one the caller's program: the same numbers to rounding (the two programs differ
    in XLA's view: the caller's bakes the temperature in as a constant, and may be compiled
    with other XLA options, so XLA may fuse and round differently, ~1e-15), same codes."""
    g = cube(6e5, 2e-3)
    a = jaxgrasp.evaluate(g)
    b = jax.jit(jaxgrasp.evaluate)(g)
    for f in dataclasses.fields(a):
        x, y = np.asarray(getattr(a, f.name)), np.asarray(getattr(b, f.name))
        assert x.dtype == y.dtype, f.name
        if f.name == "kkt":  # residuals of converged lanes: round-off itself, ~1e-11
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-12)
        else:
            np.testing.assert_allclose(y, x, rtol=1e-13, atol=1e-20, err_msg=f.name)
    assert int(a.status) == int(b.status) == jaxgrasp.GraspStatus.STABLE


def test_vmap_over_young_modulus_matches_pointwise(results):
    """The batched evaluations (jit of vmap, see conftest) equal unbatched evaluate per point."""
    for E, dr in [(2e5, 2e-3), (6e5, 2e-3), (1e6, 2e-3)]:
        batched = results[f"cube_E{E:.0e}_dr{dr:.0e}"]
        single = jaxgrasp.evaluate(cube(E, dr))
        assert int(batched.status) == int(single.status)
        for name_, x, y in zip(
            [f.name for f in dataclasses.fields(single)],
            jax.tree_util.tree_leaves(single),
            jax.tree_util.tree_leaves(batched),
        ):
            if name_ in ("steps", "kkt"):
                continue
            np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=1e-9, atol=1e-15, err_msg=name_)


# ----------------------------------------------------------------------------- kinematics of poses
margins_fn = jax.jit(M.constraint_margins)


def _margins(g, translation, rotation):
    x = jnp.concatenate([jnp.asarray(translation) * 1e3, jnp.asarray(rotation)])
    return np.asarray(margins_fn(x, M.model_params(g)))


@pytest.mark.parametrize("case", list(CASES))
def test_boundary_poses_lie_on_their_boundary(results, case):
    g, res = CASES[case], results[case]
    n = g.num_contacts
    if int(res.equilibrium_status) == 0:
        assert _margins(g, res.equilibrium_translation, res.equilibrium_rotation).min() >= -1e-8
    checked = 0
    for k in range(2):
        for j in range(n):
            if int(res.boundary_status[k, j]) != 0:
                continue
            m = _margins(g, res.boundary_translation[k, j], res.boundary_rotation[k, j])
            assert abs(m[1 + k, j]) <= 1e-8, (case, jaxgrasp.model.BoundaryKind.labels()[k], j, m[1 + k, j])
            assert m.min() >= -1e-8, (case, jaxgrasp.model.BoundaryKind.labels()[k], j, m)
            checked += 1
    if int(res.status) == jaxgrasp.GraspStatus.STABLE:
        assert checked >= 1
        k, j = int(res.limiting_kind), int(res.limiting_contact)
        m = _margins(g, res.boundary_translation[k, j], res.boundary_rotation[k, j])
        assert abs(m[1 + k, j]) <= 1e-8


@pytest.mark.parametrize(
    "objective, reached, expected",
    [
        ([1.0 + 1e-12, 1.0, 2.0], [True, True, True], 0),  # a tie (1e-12 of the value 0.5): the first
        ([1.0 + 1e-6, 1.0, 2.0], [True, True, True], 1),  # 2e-6 of the value apart: the least
        ([0.9, 1.0 + 1e-12, 1.0], [False, True, True], 1),  # unreached boundaries never limit
        ([3.0, 2.0], [False, False], 0),  # none reached
    ],
)
def test_limiting_index_breaks_ties_by_order(objective, reached, expected):
    """The limiting boundary is the least reached one; boundaries within TIE_TOL of the
    value of each other go to the first, so that rounding does not pick among symmetric
    contacts (with a plain argmin the first case gives 1)."""
    from jaxgrasp.tolerance._verdict import limiting_index

    got = limiting_index(jnp.asarray(objective), jnp.asarray(reached), jnp.asarray(0.5))
    assert int(got) == expected
