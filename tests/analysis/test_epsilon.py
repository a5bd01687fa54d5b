"""Tests of :func:`jaxgrasp.epsilon` (the Ferrari-Canny metric, ``jaxgrasp/ferrari_canny.py``).

Pure NumPy/SciPy: nothing here compiles a JAX program (no ``evaluate``), so the file runs
in a few seconds. Checked independently of the module's qhull computation:

* closed forms for the two-finger cube (derivation in :func:`cube_closed_form`), for any
  number of cone edges, per-contact friction and deformation, any rigid rotation, and
  their ``cone_edges -> infinity`` limit;
* convergence in ``cone_edges`` (nested polygons, the ``1 - cos(pi/m)`` bound);
* invariances (renumbering, rotation within the discretization bound, scaling all
  lengths, Young's modulus / mass / gravity / force limit);
* an LP formulation (``scipy.optimize.linprog``): the radial function at the nearest
  facet's normal, radial and support functions in random directions, and a qhull-free
  recovery of the value as the farthest vertex of the polar polytope;
* batches, padding, one-line errors and grasps that are not force closure.

Discretization bound used below (``d_m``): every point of contact ``i``'s true cone
section (a circle of radius ``mu_i``) lies within ``mu_i (1 - cos(pi/m))`` of the
inscribed ``m``-gon; the wrench map ``f -> (f, p_i x f / lam)`` stretches lengths by at
most ``sqrt(1 + |p_i|^2 / lam^2) <= sqrt 2``. So the hull with exact cones lies within
Hausdorff distance ``d_m = sqrt(2) max_i mu_i (1 - cos(pi/m))`` of the ``m``-edge hull,
which it contains; for force-closure grasps the value (inscribed radius, the minimum of
the support function over unit directions) therefore satisfies
``eps_m <= eps_inf <= eps_m + d_m``. ``eps_inf`` is exactly rotation invariant, hence
``|eps_m(g) - eps_m(Q g)| <= d_m``, and ``0 <= eps_2m - eps_m <= d_m``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

import jaxgrasp
from jaxgrasp.analysis._epsilon import FORCE_CLOSURE_TOL, tangent_basis, wrenches
from jaxgrasp.presets import cube, prism
from jaxgrasp.model._validation import GraspValueError
from grasp_draws import NumpyDraw, build_grasp_fields, random_rotation

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
PER_CONTACT = ("positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force")
LP_TOL = 1e-9
HIGHS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


# ----------------------------------------------------------------------------- helpers
def fields_of(g: jaxgrasp.Grasp) -> dict:
    """A grasp's fields as float64 NumPy arrays, per-contact ones broadcast to ``(N,)``."""
    f = {k: np.asarray(v, dtype=np.float64) for k, v in g.to_numpy().items() if k != "active"}
    n = f["positions"].shape[0]
    for k in PER_CONTACT[2:]:
        f[k] = np.broadcast_to(f[k], (n,)).copy()
    return f


def make(**f) -> jaxgrasp.Grasp:
    return jaxgrasp.Grasp.create(**f)


def eps(g, m=8, torsion=True) -> float:
    return float(jaxgrasp.epsilon(g, cone_edges=m, torsion=torsion).value)


def random_grasps(count=6, seed=11):
    """Seeded grasps of ``tests/grasp_draws.py``'s generator, 2 to 5 contacts."""
    rng = np.random.default_rng(seed)
    return [make(**build_grasp_fields(NumpyDraw(rng), n=2 + i % 4)) for i in range(count)]


def d_bound(g, m) -> float:
    """The discretization bound ``d_m`` of the module doc above."""
    return math.sqrt(2.0) * float(np.max(fields_of(g)["friction"])) * (1.0 - math.cos(math.pi / m))


def cube_grasp(h=0.05, mu=(0.5, 0.5), r=(0.025, 0.025), dr=(0.002, 0.002)):
    return make(
        positions=[[h, 0, 0], [-h, 0, 0]],
        normals=[[1, 0, 0], [-1, 0, 0]],
        initial_deformation=list(dr),
        radius=list(r),
        young_modulus=2e5,
        friction=list(mu),
        max_force=15.0,
    )


def cube_closed_form(h, mu, r, dr, m=None) -> float:
    """Exact epsilon of two soft contacts at ``(+-h, 0, 0)``, normals ``+-x``; ``m=None``: the
    ``cone_edges -> infinity`` limit.

    Derivation. ``lam = h``. Write ``c_j, s_j = cos, sin(2 pi j/m)``. For contact 1
    (``p = (h,0,0)``, ``n = +x``) the wrench of an edge with tangential part ``(0, fy, fz)``
    is ``(-1, fy, fz, 0, -fz, fy)`` (torque ``p x f / h = (0, -fz, fy)``); for contact 2
    (``p = -h x``, ``n = -x``) it is ``(1, fy, fz, 0, fz, -fy)``. Whatever the tangent
    basis, the tangential parts run over a regular ``m``-gon of circumradius ``mu_i``
    (any rotation / reflection of it). In the orthonormal coordinates
    ``x = fx``, ``tau = tx``, ``U = ((fy + tz), (fz - ty)) / sqrt 2``,
    ``V = ((fy - tz), (fz + ty)) / sqrt 2`` the wrench set is

    * contact 1: ``(x, tau, U, V) = (-1, 0, sqrt2 mu_1 P_j, 0)`` and torsion ``(-1, +-k_1, 0, 0)``;
    * contact 2: ``(+1, 0, 0, sqrt2 mu_2 P'_j)`` and torsion ``(+1, +-k_2, 0, 0)``,

    ``P_j, P'_j`` the unit ``m``-gons, ``k_i = mu_i e_i / h``,
    ``e_i = (8/15) mu_i sqrt(r_i^2 - (r_i - dr_i)^2)``. The origin is interior, so the value
    is the inscribed radius ``min_{|u|=1} h_W(u) = 1 / max{|y| : y in W°}``, ``W°`` the
    polar ``{y : w . y <= 1 for all w}``. With ``y = (a, t, A, B)`` the polar's constraints
    are ``-a + k_1 |t| <= 1``, ``a + k_2 |t| <= 1``, ``sqrt2 mu_1 g(A) <= 1 + a``,
    ``sqrt2 mu_2 g(B) <= 1 - a``, ``g`` the support function of the unit m-gon, whose
    polar (an m-gon of inradius 1) has circumradius ``1 / cos(pi/m)`` (any orientation).
    For fixed ``a in [-1, 1]`` the blocks decouple, so
    ``max |y|^2 = max_a F(a)``,
    ``F(a) = a^2 + min((1+a)/k_1, (1-a)/k_2)^2 + ((1+a)^2/mu_1^2 + (1-a)^2/mu_2^2) / (2 cos^2(pi/m))``.
    ``F`` is convex on each side of the kink ``a* = (k_1 - k_2)/(k_1 + k_2)``, so its
    maximum is at ``a in {-1, a*, 1}`` and ``epsilon = 1 / sqrt(max F)``. For the paper's
    symmetric cube ``a* = 0``: ``epsilon = (1/k^2 + 1/(mu cos(pi/m))^2)^(-1/2)``
    (``a = +-1`` gives ``1 + 2/(mu cos(pi/m))^2``, smaller there), increasing in ``m``
    towards ``(1/k^2 + 1/mu^2)^(-1/2)``. Without torsion every wrench has ``tau = 0``:
    a flat hull, value 0.
    """
    mu1, mu2 = mu
    c2 = 1.0 if m is None else math.cos(math.pi / m) ** 2
    k1, k2 = ((8 / 15) * mu_i**2 * math.sqrt(r_i**2 - (r_i - d_i) ** 2) / h for mu_i, r_i, d_i in zip(mu, r, dr))

    def F(a):
        t = min((1 + a) / k1, (1 - a) / k2)
        return a * a + t * t + ((1 + a) ** 2 / mu1**2 + (1 - a) ** 2 / mu2**2) / (2 * c2)

    return 1.0 / math.sqrt(max(F(-1.0), F((k1 - k2) / (k1 + k2)), F(1.0)))


def radial(W, u) -> float:
    """``rho(u) = max t`` with ``t u in conv(W)`` (LP over convex weights)."""
    K = W.shape[0]
    A_eq = np.zeros((7, K + 1))
    A_eq[:6, :K] = W.T
    A_eq[:6, K] = -u
    A_eq[6, :K] = 1.0
    b_eq = np.zeros(7)
    b_eq[6] = 1.0
    c = np.zeros(K + 1)
    c[K] = -1.0
    res = linprog(c, A_eq=A_eq, b_eq=b_eq, bounds=[(0, None)] * K + [(None, None)], method="highs", options=HIGHS)
    assert res.status == 0, res.message
    return -res.fun


def interior_lp(W) -> bool:
    """Origin in the interior of conv(W), without qhull: W spans R^6 and the origin is a
    combination of ALL rows with weights >= s > 0 (max s by LP)."""
    if np.linalg.matrix_rank(W, tol=1e-9) < 6:
        return False
    K = W.shape[0]
    A_eq = np.zeros((7, K + 1))
    A_eq[:6, :K] = W.T
    A_eq[6, :K] = 1.0
    b_eq = np.zeros(7)
    b_eq[6] = 1.0
    A_ub = np.zeros((K, K + 1))  # s - lambda_j <= 0
    A_ub[:, :K] = -np.eye(K)
    A_ub[:, K] = 1.0
    c = np.zeros(K + 1)
    c[K] = -1.0
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(K), A_eq=A_eq, b_eq=b_eq, bounds=[(0, None)] * (K + 1), method="highs")
    return res.status == 0 and -res.fun > 1e-9


def polar_value(W, rng, starts=60) -> float:
    """The inscribed radius without qhull: ``1 / max{|y| : W y <= 1}``, the farthest vertex of
    the polar polytope found by ascent (``y <- argmax (y/|y|) . y'`` over the polar, each an
    LP; ``|y|`` never decreases) from random starts. Returns ``1 / |y|`` of the best vertex
    found: an upper bound of the inscribed radius, equal to it when the ascent reaches the
    farthest vertex."""
    best = 0.0
    for _ in range(starts):
        u = rng.normal(size=6)
        u /= np.linalg.norm(u)
        norm = 0.0
        for _ in range(50):
            res = linprog(-u, A_ub=W, b_ub=np.ones(len(W)), bounds=[(None, None)] * 6, method="highs", options=HIGHS)
            assert res.status == 0, res.message  # bounded: the origin is interior
            y = res.x
            if np.linalg.norm(y) <= norm * (1 + 1e-13):
                break
            norm = np.linalg.norm(y)
            u = y / norm
        best = max(best, norm)
    return 1.0 / best


# ----------------------------------------------------------------------------- 1. closed forms
@pytest.mark.parametrize("m", [3, 4, 5, 6, 8, 12, 16, 64])
def test_cube_closed_form(m):
    """The paper's cube (``presets.cube``: mu 0.5, r 25 mm, dr 2 mm, contacts at +-5 cm)
    equals :func:`cube_closed_form` to 1e-12 for every number of cone edges."""
    g = cube()
    exact = cube_closed_form(0.05, (0.5, 0.5), (0.025, 0.025), (0.002, 0.002), m)
    out = jaxgrasp.epsilon(g, cone_edges=m)
    assert abs(float(out.value) - exact) <= 1e-12, (m, float(out.value), exact)
    assert bool(out.force_closure) and float(out.torque_scale) == 0.05
    assert out.cone_edges == m and out.torsion is True
    # the symmetric closed form, written out
    k = (8 / 15) * 0.25 * math.sqrt(0.025**2 - 0.023**2) / 0.05
    assert abs(exact - (1 / k**2 + 1 / (0.5 * math.cos(math.pi / m)) ** 2) ** -0.5) <= 1e-15


@pytest.mark.parametrize(
    "h, mu, r, dr",
    [
        (0.05, (0.5, 0.9), (0.025, 0.02), (0.002, 0.004)),  # kink a* != 0 is the maximum
        (0.03, (0.3, 0.7), (0.03, 0.015), (0.001, 0.005)),
        (0.02, (1.5, 1.5), (0.02, 0.02), (0.019, 0.019)),  # a = +-1 vertex is the maximum
        (0.02, (1.2, 2.0), (0.02, 0.02), (0.018, 0.015)),
    ],
)
@pytest.mark.parametrize("m", [3, 7, 8, 32])
def test_cube_closed_form_general(h, mu, r, dr, m):
    """Per-contact friction, radius and deformation, other half widths, including
    parameters where the polar's farthest vertex is at ``a = +-1`` (strong torsion)."""
    exact = cube_closed_form(h, mu, r, dr, m)
    got = eps(cube_grasp(h, mu, r, dr), m)
    assert abs(got - exact) <= 1e-12, (got, exact)


def test_closed_form_branches_are_exercised():
    """The parameter sets above reach each vertex of ``F`` (guards the derivation's cases)."""

    def argmax(h, mu, r, dr):
        k1, k2 = ((8 / 15) * u**2 * math.sqrt(q**2 - (q - d) ** 2) / h for u, q, d in zip(mu, r, dr))
        a = {"-1": -1.0, "kink": (k1 - k2) / (k1 + k2), "+1": 1.0}
        c2 = math.cos(math.pi / 8) ** 2
        F = {
            name: x * x + min((1 + x) / k1, (1 - x) / k2) ** 2 + ((1 + x) ** 2 / mu[0] ** 2 + (1 - x) ** 2 / mu[1] ** 2) / (2 * c2)
            for name, x in a.items()
        }
        return max(F, key=F.get)

    assert argmax(0.05, (0.5, 0.9), (0.025, 0.02), (0.002, 0.004)) == "kink"
    assert argmax(0.02, (1.5, 1.5), (0.02, 0.02), (0.019, 0.019)) in ("-1", "+1")
    assert argmax(0.02, (1.2, 2.0), (0.02, 0.02), (0.018, 0.015)) in ("-1", "+1")


@pytest.mark.parametrize("m", [3, 8, 64])
def test_cube_without_torsion_is_flat(m):
    """Two point contacts: every wrench has zero torque about the contact axis (flat hull):
    value exactly 0, not force closure."""
    out = jaxgrasp.epsilon(cube(), cone_edges=m, torsion=False)
    assert float(out.value) == 0.0 and not bool(out.force_closure) and out.torsion is False
    W, _ = wrenches(fields_of(cube()), cone_edges=m, torsion=False)
    assert np.all(W[:, 3] == 0.0) and not interior_lp(W)


def test_cube_closed_form_any_rotation():
    """The cube's value does not depend on the polygons' orientation (derivation), so a
    rotated cube (new tangent bases) still equals the closed form to 1e-12, at any m."""
    rng = np.random.default_rng(3)
    for m in (3, 8):
        exact = cube_closed_form(0.05, (0.5, 0.5), (0.025, 0.025), (0.002, 0.002), m)
        for _ in range(4):
            Q = random_rotation(NumpyDraw(rng))
            f = fields_of(cube())
            g = make(**{**f, "positions": f["positions"] @ Q.T, "normals": f["normals"] @ Q.T, "gravity": f["gravity"] @ Q.T})
            assert abs(eps(g, m) - exact) <= 1e-12


# ----------------------------------------------------------------------------- 2. convergence
def test_cube_converges_to_its_limit():
    """Monotone in m for every m (closed form increasing in cos(pi/m)); the gap to the
    m -> infinity limit is ``~ C (1 - cos(pi/m))`` with ``C`` the closed form's slope in
    ``cos(pi/m)`` at 1."""
    limit = cube_closed_form(0.05, (0.5, 0.5), (0.025, 0.025), (0.002, 0.002))
    values = {m: eps(cube(), m) for m in (*range(3, 25), 32, 64)}
    ms = sorted(values)
    assert all(values[b] >= values[a] - 1e-15 for a, b in zip(ms, ms[1:]))
    assert all(v < limit for v in values.values())
    ratios = [(limit - values[m]) / (1 - math.cos(math.pi / m)) for m in (16, 32, 64)]
    # d eps / d cos(pi/m) at the limit: A^(-3/2) / mu^2, A = 1/k^2 + 1/mu^2
    k = (8 / 15) * 0.25 * math.sqrt(0.025**2 - 0.023**2) / 0.05
    slope = (1 / k**2 + 1 / 0.25) ** -1.5 / 0.25
    assert ratios[0] > ratios[1] > ratios[2] > slope and ratios[2] / slope < 1.005, (ratios, slope)
    assert limit - values[64] <= 1e-6


def test_doubling_edges_is_monotone_and_bounded():
    """For force-closure grasps, the m-gon's edges are among the 2m-gon's (nested hulls):
    ``0 <= eps_2m - eps_m <= d_m`` (module doc)."""
    grasps = [cube(), prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(8, seed=5)]
    checked = 0
    for g in grasps:
        ms = [4, 8, 16, 32]
        vals = [eps(g, m) for m in ms]
        if vals[0] <= FORCE_CLOSURE_TOL:
            continue
        checked += 1
        for m, a, b in zip(ms, vals, vals[1:]):
            assert -1e-12 <= b - a <= d_bound(g, m) + 1e-12, (m, a, b)
    assert checked >= 6


# ----------------------------------------------------------------------------- 3. invariances
def test_renumbering_contacts():
    rng = np.random.default_rng(7)
    for g in [prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(6)]:
        f = fields_of(g)
        perm = rng.permutation(f["positions"].shape[0])
        h = make(**{k: (v[perm] if k in PER_CONTACT else v) for k, v in f.items()})
        for torsion in (True, False):
            a, b = eps(g, 8, torsion), eps(h, 8, torsion)
            assert abs(a - b) <= 1e-12, (a, b)


def test_rotation_within_discretization_bound():
    """Rotating positions, normals and gravity turns the tangent bases, so each finite
    polygon turns about its normal: ``|eps_m(g) - eps_m(Qg)| <= d_m`` for force-closure
    grasps; a grasp without force closure rotates to a value ``<= d_m``. At m = 64,
    ``d_m <= 1.7e-3 mu_max``; the values here are 1e-2 to 3e-1."""
    rng = np.random.default_rng(2)
    grasps = [prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(8, seed=9)]
    fc = 0
    for i, g in enumerate(grasps):
        Q = random_rotation(NumpyDraw(rng))
        f = fields_of(g)
        h = make(**{**f, "positions": f["positions"] @ Q.T, "normals": f["normals"] @ Q.T, "gravity": f["gravity"] @ Q.T})
        for m in (8, 64) if i == 0 else (8, 16):  # m = 64 hulls cost ~1 s each in 6-D
            a, b = eps(g, m), eps(h, m)
            d = d_bound(g, m)
            if a > FORCE_CLOSURE_TOL and b > FORCE_CLOSURE_TOL:
                fc += 1
                assert abs(a - b) <= d + 1e-12, (m, a, b, d)
            else:
                assert max(a, b) <= d + 1e-12, (m, a, b, d)
    assert fc >= 8


def test_tangent_basis_is_orthonormal_right_handed():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200, 3))
    n[:3] = np.eye(3)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t1, t2 = tangent_basis(n)
    for a, b in ((t1, n), (t2, n), (t1, t2)):
        assert np.max(np.abs(np.sum(a * b, axis=1))) <= 1e-15
    assert np.max(np.abs(np.linalg.norm(t1, axis=1) - 1)) <= 1e-15
    assert np.max(np.abs(np.cross(t1, t2) - n)) <= 1e-15


@pytest.mark.parametrize("s", [0.25, 8.0, 0.37, 3.1])
def test_scaling_lengths(s):
    """Positions, radius and initial deformation times ``s``: lam scales too, so the
    wrenches are the same (bit for bit when ``s`` is a power of 2)."""
    for g in [cube(), prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(4)]:
        f = fields_of(g)
        h = make(**{**f, **{k: f[k] * s for k in ("positions", "radius", "initial_deformation")}})
        a, b = jaxgrasp.epsilon(g), jaxgrasp.epsilon(h)
        assert float(b.torque_scale) == pytest.approx(s * float(a.torque_scale), rel=1e-15)
        if math.log2(s).is_integer():
            assert float(a.value) == float(b.value)
        else:
            assert abs(float(a.value) - float(b.value)) <= 1e-12


def test_independent_of_stiffness_mass_gravity_force_limit():
    for g in [cube(), prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(4)]:
        f = fields_of(g)
        base = eps(g)
        for change in (
            {"young_modulus": f["young_modulus"] * 3.7},
            {"mass": 2.5},
            {"gravity": np.array([3.0, -1.0, 0.5])},
            {"max_force": f["max_force"] * 0.1},
        ):
            assert eps(make(**{**f, **change})) == base, change


# ----------------------------------------------------------------------------- 4. LP formulation
def lp_grasps():
    return [
        ("cube", cube()),
        ("prism", prism()),
        ("four_finger", jaxgrasp.load(EXAMPLES / "four_finger.json")),
        *((f"random{i}", g) for i, g in enumerate(random_grasps(8, seed=1))),
    ]


def test_lp_radial_and_support_functions():
    """For every force-closure grasp: the radial function (LP) along qhull's nearest facet
    normal equals the value to 1e-9; along 60 random directions it is not smaller; the
    support function ``h(u) = max_j u . w_j`` (no qhull) is ``>= value`` in 20000 random
    directions and equals it at the facet normal; qhull's facets support the wrenches."""
    rng = np.random.default_rng(4)
    seen = 0
    for name, g in lp_grasps():
        value = eps(g)
        W, _ = wrenches(fields_of(g), cone_edges=8, torsion=True)
        assert (value > FORCE_CLOSURE_TOL) == interior_lp(W), name
        if value <= FORCE_CLOSURE_TOL:
            continue
        seen += 1
        hull = ConvexHull(W)
        normals, offsets = hull.equations[:, :6], hull.equations[:, 6]
        # every facet plane supports the wrench set: max_j n . w_j = -offset
        assert np.max(np.abs(np.max(W @ normals.T, axis=0) + offsets)) <= 1e-12
        u_star = normals[np.argmin(-offsets)]
        assert abs(radial(W, u_star) - value) <= LP_TOL, name
        assert abs(np.max(W @ u_star) - value) <= 1e-12
        U = rng.normal(size=(60, 6))
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        assert min(radial(W, u) for u in U) >= value - LP_TOL, name
        U = rng.normal(size=(20000, 6))
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        assert np.min(np.max(U @ W.T, axis=1)) >= value - 1e-12, name
    assert seen >= 6


def test_lp_polar_vertex_recovers_value():
    """No qhull at all: the farthest vertex of the polar polytope ``{y : W y <= 1}``
    (ascent over LP vertices) gives ``1 / |y| = value`` to 1e-9."""
    rng = np.random.default_rng(8)
    seen = 0
    for name, g in lp_grasps():
        value = eps(g)
        if value <= FORCE_CLOSURE_TOL:
            continue
        seen += 1
        W, _ = wrenches(fields_of(g), cone_edges=8, torsion=True)
        assert abs(polar_value(W, rng) - value) <= LP_TOL, name
    assert seen >= 6


# ----------------------------------------------------------------------------- 5. batches, padding, errors
def test_batch_equals_one_by_one():
    grasps = [cube(), prism(), jaxgrasp.load(EXAMPLES / "four_finger.json"), *random_grasps(5)]
    out = jaxgrasp.epsilon(jaxgrasp.stack(grasps), cone_edges=6)
    one = [jaxgrasp.epsilon(g, cone_edges=6) for g in grasps]
    assert out.value.shape == (len(grasps),) and out.force_closure.shape == (len(grasps),)
    assert out.value.tolist() == [float(o.value) for o in one]
    assert out.force_closure.tolist() == [bool(o.force_closure) for o in one]
    assert out.torque_scale.tolist() == [float(o.torque_scale) for o in one]


def test_inactive_contacts_are_ignored():
    """A padded grasp (extra contacts, one far away so that it would change lam) equals
    the compact one exactly."""
    for g in [cube(), prism(), *random_grasps(3)]:
        f = fields_of(g)
        n = f["positions"].shape[0]
        extra = {
            "positions": np.array([[0.5, 0.2, -0.1], [0.0, 0.0, 0.03]]),
            "normals": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        }
        padded = {
            k: (np.concatenate([v, extra[k]]) if k in extra else np.concatenate([v, v[:2]]) if k in PER_CONTACT else v)
            for k, v in f.items()
        }
        active = np.arange(n + 2) < n
        p = make(**padded, active=active)
        for torsion in (True, False):
            a = jaxgrasp.epsilon(g, torsion=torsion)
            b = jaxgrasp.epsilon(p, torsion=torsion)
            assert float(a.value) == float(b.value) and float(a.torque_scale) == float(b.torque_scale)
        assert eps(make(**padded)) != eps(g)  # the extra contacts would matter if active


@pytest.mark.parametrize("m", [2, 0, -4, 2.5, 8.0, True, "8", None])
def test_bad_cone_edges(m):
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.epsilon(cube(), cone_edges=m)
    assert "\n" not in str(info.value) and "cone_edges" in str(info.value)


def test_bad_grasps():
    for bad in ({"positions": [[1, 0, 0]]}, None, np.zeros((2, 3))):
        with pytest.raises(GraspValueError) as info:
            jaxgrasp.epsilon(bad)
        assert "\n" not in str(info.value)
    f = fields_of(prism())
    broken = cube().replace(friction=np.array([0.5, -0.5]))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.epsilon(broken)
    assert "\n" not in str(info.value) and "friction" in str(info.value)
    batch = jaxgrasp.stack([cube(), cube()])
    batch = batch.replace(initial_deformation=np.array([[0.002, 0.002], [0.002, 0.03]]))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.epsilon(batch)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("grasp 1:"), msg
    assert f  # prism fields were valid


def test_contacts_on_one_side_are_not_force_closure():
    """All normals with ``n_x >= 0.8`` and friction 0.3: every force has ``f_x <= -0.8 + 0.3 *
    0.6 < 0``, the plane ``f_x = -0.62`` separates the origin from the hull:
    value < 0, no force closure (LP agrees). Also a flat case: all normals exactly ``+x``."""
    rng = np.random.default_rng(12)
    tilted = []
    for _ in range(4):
        v = rng.normal(size=3)
        v[0] = 0.0
        v *= 0.6 / np.linalg.norm(v)
        v[0] = 0.8
        tilted.append(v)
    g = make(
        positions=[[0.03, 0.01, 0.0], [0.02, -0.02, 0.01], [0.04, 0.0, -0.02], [0.03, 0.02, 0.02]],
        normals=tilted,
        initial_deformation=0.002,
        radius=0.02,
        young_modulus=3e5,
        friction=0.3,
        max_force=10.0,
    )
    W, _ = wrenches(fields_of(g), cone_edges=8, torsion=True)
    assert np.max(W[:, 0]) < 0
    for m in (3, 8, 32):
        out = jaxgrasp.epsilon(g, cone_edges=m)
        assert float(out.value) < 0 and not bool(out.force_closure)
    assert not interior_lp(W)
    flat = g.replace(normals=np.tile([1.0, 0.0, 0.0], (4, 1)))
    out = jaxgrasp.epsilon(flat)
    assert float(out.value) <= 0 and not bool(out.force_closure)


def test_many_edges_full_dimensional_hull_is_not_flat():
    """Regression: with 64 edges qhull's default options fail on this seeded grasp (QH6271
    "wide merge due to dupridge") although its wrenches span R^6; that failure was once
    reported as a flat hull (value 0). The value must stay between the 32-edge value and
    it plus ``d_32`` (nested polygons; joggled hull, so 1e-9 slack)."""
    g = random_grasps(8, seed=5)[5]
    v32, v64 = eps(g, 32), eps(g, 64)
    assert v32 > 0.1
    assert v32 - 1e-9 <= v64 <= v32 + d_bound(g, 32) + 1e-9, (v32, v64)


@pytest.mark.parametrize("mu", [10.0, 100.0, 1e3])
def test_large_friction_up_to_the_bound_matches_the_closed_form(mu):
    """Issue 40: epsilon fell from 1 to 0 at friction 1e7 (cone edges of length ``mu`` and
    torsion ``mu^2`` swamped the unit normal forces in qhull). Friction is now bounded
    (``MAX_FRICTION``), and up to the bound the value is the closed form's, which tends to
    its large-friction limit 1 (the normal forces alone bound the hull along ``x``)."""
    from jaxgrasp.model._validation import MAX_FRICTION

    assert mu <= MAX_FRICTION
    got = eps(cube_grasp(0.05, (mu, mu), (0.025, 0.025), (0.002, 0.002)))
    exact = cube_closed_form(0.05, (mu, mu), (0.025, 0.025), (0.002, 0.002), 8)
    assert abs(got - exact) <= 1e-9 * max(1.0, mu), (got, exact)
    assert 1.0 - 2.0 / mu**2 <= got <= 1.0  # 1 - 1.17 / mu^2 here


def test_friction_beyond_the_bound_is_one_line():
    with pytest.raises(GraspValueError, match=r"^friction\[0\] = 10000000 must be at most 1000 "):
        jaxgrasp.epsilon(cube().replace(friction=np.array([1e7, 1e7])))
