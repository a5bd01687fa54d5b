"""Model-level tests of jaxgrasp.model._potential (no solver): closed forms, kinematics, derivatives,
invariances and the equivalence of the scaled friction margin with the paper's eq. 9.

Everything is in the model's internal units (mm, N, N/mm^2, mJ).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

import jaxgrasp  # noqa: E402
from jaxgrasp import presets  # noqa: E402
from jaxgrasp.model import _potential as M  # noqa: E402
from jaxgrasp.model._potential import model_params  # noqa: E402

# jitted once per contact count: eager evaluation of these small functions (and above
# all of their Hessians) dispatches op by op and is far slower than compiling them.
rotation_matrix = jax.jit(M.rotation_matrix)
contact_kinematics = jax.jit(M.contact_kinematics)
potential_energy = jax.jit(M.potential_energy)
constraint_margins = jax.jit(M.constraint_margins)
grad_U = jax.jit(jax.grad(M.potential_energy))
hess_U = jax.jit(jax.hessian(M.potential_energy))

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

CUBE_POINTS = [(2e5, 1e-3), (2e5, 5e-3), (6e5, 2e-3), (1e6, 3e-3), (3.7e5, 2.4e-3)]


def cube_params(E=6e5, dr=2e-3, mass=0.0, **kw):
    return model_params(presets.cube(E, dr, mass, **kw))


def four_finger():
    return jaxgrasp.load(EXAMPLES / "four_finger.json")


def random_grasp(rng, n=4, mass=0.2):
    """A generic grasp: random contacts on a ~40 mm sphere, outward-ish normals, unequal tips."""
    c = rng.normal(size=(n, 3))
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    nrm = c + 0.3 * rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return jaxgrasp.Grasp.create(
        positions=0.04 * c,
        normals=nrm,
        initial_deformation=rng.uniform(1e-3, 3e-3, n),
        radius=rng.uniform(0.02, 0.03, n),
        young_modulus=rng.uniform(2e5, 1e6, n),
        friction=rng.uniform(0.3, 0.8, n),
        max_force=rng.uniform(10.0, 20.0, n),
        mass=mass,
        gravity=rng.normal(size=3) * 5.0,
    )


def random_pose(rng, t_scale=0.5, w_scale=0.02):
    return jnp.asarray(np.concatenate([rng.normal(size=3) * t_scale, rng.normal(size=3) * w_scale]))


def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ------------------------------------------------------------------ independent NumPy model
def contact_frame(n):
    """``R_i``: a right-handed frame whose first axis ``e1`` is the contact normal ``n``."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]  # the axis least aligned with n
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    R = np.column_stack([n, t1, t2])
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-15) and np.linalg.det(R) > 0
    return R


def numpy_kinematics(x, g):
    """Eq. 11-16 of the paper, literally, in each contact frame ``R_i`` (internal units).

    Independent of ``jaxgrasp.model._potential``'s vector shortcuts: the displacement and rotation
    are expressed in the contact frame (eq. 11, 12), the deformations read off its axes
    ``e1`` (normal) and ``e2, e3`` (tangential, ``D23``), and the torsion is the ``e1``
    component of the rotation vector of ``R_i^T dR R_i`` (a matrix logarithm by SciPy, not
    ``n . w``). ``dR`` is SciPy's; ``R_o = I`` and ``p_o = 0`` (centre-of-mass frame).
    Returns ``d, cos(phi), dt^2, theta``, one entry per contact.
    """
    x = np.array(x, dtype=np.float64)  # a writable copy (SciPy refuses read-only buffers)
    dp, w = x[:3], x[3:]
    dR = Rotation.from_rotvec(w).as_matrix()
    c = np.asarray(g.positions) * 1e3
    normals = np.asarray(g.normals)
    r = np.asarray(g.radius) * 1e3
    dr = np.asarray(g.initial_deformation) * 1e3
    e1 = np.array([1.0, 0.0, 0.0])
    D23 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    out = []
    for i in range(c.shape[0]):
        Ri = contact_frame(normals[i] / np.linalg.norm(normals[i]))
        p_i = Ri.T @ ((dR - np.eye(3)) @ c[i] + dp)  # eq. 11
        R_i = Ri.T @ dR @ Ri  # eq. 12
        d = r[i] - ((r[i] - dr[i]) * e1 - p_i) @ (R_i @ e1)  # eq. 13
        cphi = e1 @ (R_i @ e1)  # eq. 14 (cos phi; phi itself is never needed)
        dt2 = float(np.sum((D23 @ p_i) ** 2))  # eq. 15, squared
        theta = Rotation.from_matrix(R_i).as_rotvec() @ e1  # eq. 16
        out.append((d, cphi, dt2, theta))
    return tuple(np.array(v) for v in zip(*out))


def numpy_energy(x, g):
    """Eq. 3, 5, 7, 17-19 from :func:`numpy_kinematics` (mJ; gravity along ``g.gravity``)."""
    d, cphi, dt2, theta = numpy_kinematics(x, g)
    E = np.asarray(g.young_modulus) * 1e-6
    r = np.asarray(g.radius) * 1e3
    d = np.maximum(d, 0.0)  # a fingertip that has let go stores no energy
    u_n = np.pi * E * d**3 / (3.0 * cphi**2)  # eq. 3
    u_t = np.pi * E * d * dt2  # eq. 5
    u_tau = np.pi * E * d**2 * (r - d / 3.0) * theta**2  # eq. 7
    u_g = -float(g.mass) * np.asarray(g.gravity) @ np.asarray(x[:3])  # eq. 18 (g = (0, 0, -g) there)
    return float(np.sum(u_n + u_t + u_tau) + u_g)  # eq. 17, 19


def paper_forces(d, cphi, dt2, theta, g):
    """Eq. 4, 6, 8, 10 (internal units): f_n, f_t, tau_n, e_n."""
    r = np.asarray(g.radius) * 1e3
    E = np.asarray(g.young_modulus) * 1e-6
    mu = np.asarray(g.friction)
    f_n = np.pi * E * d**2 / cphi**2  # eq. 4
    f_t = 2.0 * np.pi * E * d * np.sqrt(np.maximum(dt2, 0.0))  # eq. 6
    tau = 2.0 * np.pi * E * d**2 * (r - d / 3.0) * theta  # eq. 8
    with np.errstate(invalid="ignore"):  # e is nan for d < 0 (callers mask those out)
        e = 8.0 / 15.0 * mu * np.sqrt(r**2 - (r - d) ** 2)  # eq. 10
    return f_n, f_t, tau, e


# ------------------------------------------------------------------ closed forms at x = 0
@pytest.mark.parametrize("E, dr", CUBE_POINTS)
def test_cube_zero_pose_energy_and_margins(E, dr):
    p = cube_params(E, dr)
    x0 = jnp.zeros(6)
    E_i, dr_i = E * 1e-6, dr * 1e3  # N/mm^2, mm
    u0 = float(potential_energy(x0, p))
    assert u0 == pytest.approx(2.0 * np.pi * E_i * dr_i**3 / 3.0, rel=1e-14)

    m = np.asarray(constraint_margins(x0, p))
    assert m.shape == (3, 2)
    np.testing.assert_allclose(m[0], 1.0, rtol=1e-14)  # contact: d / dr
    np.testing.assert_allclose(m[1], 1.0, rtol=1e-14)  # slip: (mu dr)^2 / (mu dr)^2
    # force: (sqrt(fmax / (pi E)) cos(phi) - d) / dr with cos(phi) = 1 and d = dr
    force = np.sqrt(15.0 / (np.pi * E_i)) / dr_i - 1.0
    np.testing.assert_allclose(m[2], force, rtol=1e-13, atol=1e-15)
    # the force margin changes sign exactly where pi E dr^2 = fmax
    assert (m[2] >= 0).all() == (np.pi * E_i * dr_i**2 <= 15.0)


def test_zero_pose_kinematics_generic():
    g = random_grasp(np.random.default_rng(1))
    d, cphi, dt2, theta = (np.asarray(a) for a in contact_kinematics(jnp.zeros(6), model_params(g)))
    np.testing.assert_allclose(d, np.asarray(g.initial_deformation) * 1e3, rtol=1e-14)
    np.testing.assert_allclose(cphi, 1.0, rtol=1e-15)  # |n|^2 of a normalised normal
    np.testing.assert_allclose(dt2, 0.0, atol=1e-28)
    np.testing.assert_array_equal(theta, 0.0)


# ------------------------------------------------------------------ torsion closed form
def theta_star(mu, dr, r):
    """Torsion angle at which the slip margin of a pure-torsion contact is zero."""
    return np.sqrt(16.0 * mu**4 * dr * (2 * r - dr) / (225.0 * (r - dr / 3.0) ** 2))


@pytest.mark.parametrize("E, dr", CUBE_POINTS)
def test_cube_torsion_closed_form(E, dr):
    p = cube_params(E, dr)
    dr_i, r_i, mu = dr * 1e3, 25.0, 0.5
    ts = theta_star(mu, dr_i, r_i)
    for th in (0.3 * ts, ts, -ts, 1.7 * ts):
        x = jnp.array([0.0, 0.0, 0.0, th, 0.0, 0.0])  # rotation about the grasp axis (both normals)
        d, cphi, dt2, theta = (np.asarray(a) for a in contact_kinematics(x, p))
        np.testing.assert_allclose(d, dr_i, rtol=1e-14)
        np.testing.assert_allclose(cphi, 1.0, rtol=1e-15)
        np.testing.assert_allclose(dt2, 0.0, atol=1e-24)
        np.testing.assert_allclose(theta, [th, -th], rtol=1e-15)
        # energy: two contacts, each pi E (dr^3/3 + dr^2 (r - dr/3) theta^2)
        E_i = E * 1e-6
        u = 2 * np.pi * E_i * (dr_i**3 / 3.0 + dr_i**2 * (r_i - dr_i / 3.0) * th**2)
        assert float(potential_energy(x, p)) == pytest.approx(u, rel=1e-13)
    slip = lambda th: np.asarray(constraint_margins(jnp.array([0, 0, 0, th, 0, 0.0]), p))[1]  # noqa: E731
    np.testing.assert_allclose(slip(ts), 0.0, atol=1e-12)
    assert (slip(0.999 * ts) > 0).all() and (slip(1.001 * ts) < 0).all()


def test_torsion_about_generic_normal():
    """A contact whose position lies on its normal: rotating about that normal is pure torsion."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        n0 = rng.normal(size=3)
        n0 /= np.linalg.norm(n0)
        other = -n0 + 0.2 * rng.normal(size=3)
        g = jaxgrasp.Grasp.create(
            positions=[0.04 * n0, 0.03 * other / np.linalg.norm(other)],
            normals=[n0, other],
            initial_deformation=[1.7e-3, 2.2e-3],
            radius=0.025,
            young_modulus=4e5,
            friction=0.6,
            max_force=15.0,
        )
        p = model_params(g)
        ts = theta_star(0.6, 1.7, 25.0)
        x = jnp.concatenate([jnp.zeros(3), ts * jnp.asarray(n0)])
        d, cphi, dt2, theta = (np.asarray(a) for a in contact_kinematics(x, p))
        assert d[0] == pytest.approx(1.7, rel=1e-13)
        assert cphi[0] == pytest.approx(1.0, rel=1e-15)
        assert dt2[0] == pytest.approx(0.0, abs=1e-20)
        assert theta[0] == pytest.approx(ts, rel=1e-14)
        assert float(constraint_margins(x, p)[1, 0]) == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------ translations
@pytest.mark.parametrize("t", [-1.5, -0.3, 0.01, 0.7, 1.9])
def test_cube_translation_along_normal(t):
    dr_i = 2.0
    p = cube_params(6e5, dr_i * 1e-3)
    x = jnp.array([t, 0.0, 0.0, 0.0, 0.0, 0.0])  # along n_0 = +x, i.e. against n_1
    d, cphi, dt2, theta = (np.asarray(a) for a in contact_kinematics(x, p))
    np.testing.assert_allclose(d, [dr_i + t, dr_i - t], rtol=0, atol=1e-13)
    np.testing.assert_array_equal(cphi, 1.0)
    np.testing.assert_allclose(dt2, 0.0, atol=1e-14)  # |u|^2 - (n.u)^2 rounds at t^2 eps


def test_translation_along_normal_and_tangent_generic():
    """For every contact of generic grasps: normal motion changes d by exactly t, tangential
    motion gives dt^2 = t^2 with d unchanged."""
    rng = np.random.default_rng(3)
    for g in (four_finger(), random_grasp(rng), random_grasp(rng, n=3)):
        p = model_params(g)
        n = np.asarray(p.n)
        dr = np.asarray(p.dr)
        for i in range(n.shape[0]):
            for t in (-0.8, 0.25, 1.3):
                d, cphi, dt2, _ = (np.asarray(a) for a in contact_kinematics(jnp.concatenate([t * p.n[i], jnp.zeros(3)]), p))
                assert d[i] == pytest.approx(dr[i] + t, abs=1e-13)
                assert dt2[i] == pytest.approx(0.0, abs=1e-13)
                assert cphi[i] == pytest.approx(1.0, rel=1e-15)
                tang = np.cross(n[i], rng.normal(size=3))
                tang /= np.linalg.norm(tang)
                x = jnp.concatenate([jnp.asarray(t * tang), jnp.zeros(3)])
                d, cphi, dt2, _ = (np.asarray(a) for a in contact_kinematics(x, p))
                assert d[i] == pytest.approx(dr[i], abs=1e-13)
                assert dt2[i] == pytest.approx(t * t, rel=1e-12, abs=1e-14)


def test_contact_lost_gives_negative_contact_margin():
    p = cube_params(6e5, 2e-3)
    x = jnp.array([2.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # moves 2.5 mm away from fingertip 1
    m = np.asarray(constraint_margins(x, p))
    assert m[0, 1] == pytest.approx(-0.25, rel=1e-13)
    assert m[0, 0] == pytest.approx(2.25, rel=1e-13)
    # the energy treats the lifted fingertip as not touching (max(d, 0))
    assert float(potential_energy(x, p)) == pytest.approx(np.pi * 0.6 * 4.5**3 / 3.0, rel=1e-13)


# ------------------------------------------------------------------ rotation matrix
def _rotvecs():
    rng = np.random.default_rng(0)
    ws = [np.zeros(3), np.array([1e-9, -2e-9, 0.5e-9]), np.array([0.0, 0.0, 1e-12])]
    for s in (1e-9, 1e-6, 0.999e-3, 1.001e-3, 1e-2, 0.3, 1.0, 3.0):
        v = rng.normal(size=3)
        ws.append(s * v / np.linalg.norm(v))
    ws += list(rng.normal(size=(10, 3)))
    return ws


@pytest.mark.parametrize("w", _rotvecs(), ids=lambda w: f"|w|={np.linalg.norm(w):.3g}")
def test_rotation_matrix_against_scipy(w):
    R = np.asarray(rotation_matrix(jnp.asarray(w)))
    w = np.array(w, dtype=np.float64)
    np.testing.assert_allclose(R.T @ R, np.eye(3), rtol=0, atol=2e-15)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=2e-15)
    np.testing.assert_allclose(R, Rotation.from_rotvec(w).as_matrix(), rtol=0, atol=2e-15)


def test_rotation_matrix_derivatives_at_zero():
    # dR/dw_k at 0 is the generator [e_k]_x
    J = np.asarray(jax.jit(jax.jacfwd(M.rotation_matrix))(jnp.zeros(3)))  # (3, 3, 3)
    for k in range(3):
        np.testing.assert_allclose(J[:, :, k], skew(np.eye(3)[k]), atol=1e-15)
    # the reverse mode and second derivatives are finite too, at 0 and at 1e-9
    jacrev = jax.jit(jax.jacrev(M.rotation_matrix))
    hess = jax.jit(jax.hessian(M.rotation_matrix))
    for w in (jnp.zeros(3), jnp.array([1e-9, 0.0, -1e-9])):
        Jr = np.asarray(jacrev(w))
        H = np.asarray(hess(w))
        assert np.isfinite(Jr).all() and np.isfinite(H).all()
        np.testing.assert_allclose(Jr, J, atol=1e-8)


_rotation_jacobian = jax.jit(M.rotation_jacobian)
_rotation_hessian_along = jax.jit(M.rotation_hessian_along)
_auto_rotation_jacobian = jax.jit(jax.jacfwd(M.rotation_matrix))
_auto_rotation_hessian_along = jax.jit(jax.hessian(lambda w, m: jnp.sum(M.rotation_matrix(w) * m)))


@pytest.mark.parametrize("w", _rotvecs() + [np.zeros(3)], ids=lambda w: f"|w|={np.linalg.norm(w):.3g}")
def test_rotation_derivatives_written_out_equal_autodiff(w):
    """The solver's dR/dw and Hessian of R(w) : m, written from the coefficients of
    Rodrigues' formula, equal forward-mode and forward-over-reverse autodiff of
    rotation_matrix, on both sides of the series' switch (|w| = 1e-3) and at 0. The
    tolerance is autodiff's own: both differentiate sin t / t near small t with
    cancellation (relative error ~eps / t^2 in the Hessian's w w^T part)."""
    w = jnp.asarray(w)
    m = jnp.asarray(np.random.default_rng(11).normal(size=(3, 3)))
    J = _rotation_jacobian(w)
    np.testing.assert_allclose(J, _auto_rotation_jacobian(w), rtol=0, atol=1e-13)
    H = _rotation_hessian_along(w, m)
    np.testing.assert_allclose(H, _auto_rotation_hessian_along(w, m), rtol=0, atol=1e-10)
    np.testing.assert_allclose(H, H.T, rtol=0, atol=1e-15 * float(jnp.max(jnp.abs(H))))  # symmetric to rounding


# ------------------------------------------------------------------ derivatives of U
@pytest.mark.parametrize("mass", [0.0, 0.3])
def test_energy_gradient_hessian_at_zero_cube(mass):
    E, dr, r = 6e5, 2e-3, 0.025
    p = cube_params(E, dr, mass)
    x0 = jnp.zeros(6)
    gr = np.asarray(grad_U(x0, p))
    H = np.asarray(hess_U(x0, p))
    assert np.isfinite(gr).all() and np.isfinite(H).all()
    # symmetric grasp: the elastic gradient vanishes; only the weight pulls (N in mm units)
    expected = np.concatenate([-mass * np.array([0.0, 0.0, -9.81]), np.zeros(3)])
    np.testing.assert_allclose(gr, expected, atol=1e-12)
    np.testing.assert_allclose(H, H.T, atol=1e-12)
    # torsional stiffness about the grasp axis: 2 contacts x 2 pi E dr^2 (r - dr/3)
    E_i, dr_i, r_i = E * 1e-6, dr * 1e3, r * 1e3
    assert H[3, 3] == pytest.approx(2 * 2 * np.pi * E_i * dr_i**2 * (r_i - dr_i / 3.0), rel=1e-12)
    # normal stiffness: d/dx (pi E d^2) over both contacts = 2 pi E dr * 2
    assert H[0, 0] == pytest.approx(4 * np.pi * E_i * dr_i, rel=1e-12)
    assert np.linalg.eigvalsh(H).min() > 0


def test_energy_derivatives_at_zero_generic():
    jac_margins = jax.jit(jax.jacfwd(M.constraint_margins))
    for g in (four_finger(), random_grasp(np.random.default_rng(5))):
        p = model_params(g)
        x0 = jnp.zeros(6)
        assert np.isfinite(np.asarray(grad_U(x0, p))).all()
        assert np.isfinite(np.asarray(hess_U(x0, p))).all()
        assert np.isfinite(np.asarray(jac_margins(x0, p))).all()


def test_energy_gradient_matches_finite_differences():
    rng = np.random.default_rng(11)
    for g in (four_finger(), random_grasp(rng), presets.prism(4e5, 2e-3, 0.1)):
        p = model_params(g)
        for _ in range(3):
            x = random_pose(rng, 0.2, 0.01)
            gr = np.asarray(grad_U(x, p))
            fd = np.zeros(6)
            h = 1e-6
            for k in range(6):
                e = jnp.zeros(6).at[k].set(h)
                fd[k] = (float(potential_energy(x + e, p)) - float(potential_energy(x - e, p))) / (2 * h)
            np.testing.assert_allclose(gr, fd, rtol=1e-6, atol=1e-7 * np.abs(gr).max())


# ------------------------------------------------------------------ invariance
def rotate_grasp(g, Q):
    return g.replace(
        positions=jnp.asarray(np.asarray(g.positions) @ Q.T),
        normals=jnp.asarray(np.asarray(g.normals) @ Q.T),
        gravity=jnp.asarray(np.asarray(g.gravity) @ Q.T),
    )


def test_rigid_rotation_invariance():
    rng = np.random.default_rng(2)
    for g in (four_finger(), random_grasp(rng), presets.prism(6e5, 1.5e-3, 0.1)):
        p = model_params(g)
        for _ in range(3):
            Q = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
            pq = model_params(rotate_grasp(g, Q))
            for _ in range(4):
                x = np.asarray(random_pose(rng, 0.6, 0.03))
                xq = jnp.asarray(np.concatenate([Q @ x[:3], Q @ x[3:]]))
                u, uq = float(potential_energy(jnp.asarray(x), p)), float(potential_energy(xq, pq))
                assert uq == pytest.approx(u, rel=1e-12)
                np.testing.assert_allclose(
                    np.asarray(constraint_margins(xq, pq)),
                    np.asarray(constraint_margins(jnp.asarray(x), p)),
                    rtol=1e-10,
                    atol=1e-11,
                )


def test_contact_renumbering_invariance():
    rng = np.random.default_rng(4)
    g = random_grasp(rng, n=4)
    perm = np.array([2, 0, 3, 1])
    gp = g.replace(**{k: jnp.asarray(getattr(g, k))[perm] for k in (
        "positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force")})
    p, pp = model_params(g), model_params(gp)
    for _ in range(5):
        x = random_pose(rng, 0.6, 0.03)
        assert float(potential_energy(x, pp)) == pytest.approx(float(potential_energy(x, p)), rel=1e-13)
        np.testing.assert_allclose(
            np.asarray(constraint_margins(x, pp)), np.asarray(constraint_margins(x, p))[:, perm], rtol=1e-12, atol=1e-13
        )


# ------------------------------------------------------------------ against an independent transcription
def test_kinematics_and_energy_match_numpy_transcription():
    """jaxgrasp.model._potential against eq. 11-19 computed literally in each contact frame, to 1e-12."""
    rng = np.random.default_rng(8)
    checked = 0
    for g in (four_finger(), random_grasp(rng), random_grasp(rng, n=3), presets.cube(6e5, 2e-3, 0.2)):
        p = model_params(g)
        for t_scale, w_scale in ((0.5, 0.05), (0.05, 0.3), (1.5, 0.002)):
            x = random_pose(rng, t_scale, w_scale)
            ref = numpy_kinematics(x, g)
            got = [np.asarray(a) for a in contact_kinematics(x, p)]
            for what, a, b in zip(("d", "cos phi", "dt^2", "theta"), got, ref):
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=what)
            assert float(potential_energy(x, p)) == pytest.approx(numpy_energy(x, g), rel=1e-12)
            checked += 1
            # the pose moves every contact: the comparison is not one of zeros
            d, cphi, dt2, theta = ref
            assert (np.abs(d - np.asarray(g.initial_deformation) * 1e3) > 1e-4).all()
            assert (dt2 > 1e-8).all() and (np.abs(theta) > 1e-6).all() and (cphi < 1.0).all()
    assert checked == 12


def test_friction_form_equivalent_to_paper_eq9():
    """Scaled slip margin = (mu^2 f_n^2 - f_t^2 - tau^2/e^2) / (pi E d mu dr)^2 for d > 0."""
    rng = np.random.default_rng(9)
    checked = 0
    signs = set()
    for g in (four_finger(), random_grasp(rng), random_grasp(rng, n=3), presets.cube(3e5, 3e-3)):
        p = model_params(g)
        E = np.asarray(g.young_modulus) * 1e-6
        mu = np.asarray(g.friction)
        dr = np.asarray(g.initial_deformation) * 1e3
        for _ in range(40):
            x = random_pose(rng, rng.choice([0.05, 0.3, 1.0]), rng.choice([0.003, 0.03, 0.1]))
            d, cphi, dt2, theta = numpy_kinematics(x, g)
            ok = d > 0
            if not ok.any():
                continue
            f_n, f_t, tau, e = paper_forces(d, cphi, dt2, theta, g)
            paper = mu**2 * f_n**2 - f_t**2 - tau**2 / e**2
            slip = np.asarray(constraint_margins(x, p))[1]
            scale = (np.pi * E * d * mu * dr) ** 2
            np.testing.assert_allclose(
                slip[ok] * scale[ok], paper[ok], rtol=1e-9, atol=1e-12 * np.max(np.abs(mu**2 * f_n**2))
            )
            clear = ok & (np.abs(paper) > 1e-9 * mu**2 * f_n**2)
            np.testing.assert_array_equal(np.sign(slip[clear]), np.sign(paper[clear]))
            signs.update(np.sign(paper[clear]).tolist())
            checked += int(clear.sum())
    assert checked > 100
    assert signs == {-1.0, 1.0}  # both sides of the boundary were exercised


def test_slip_margin_independent_of_young_modulus_and_force_margin_eq21():
    rng = np.random.default_rng(10)
    g = random_grasp(rng, mass=0.0)
    for _ in range(5):
        x = random_pose(rng, 0.4, 0.03)
        m1 = np.asarray(constraint_margins(x, model_params(g)))
        m3 = np.asarray(constraint_margins(x, model_params(g.replace(young_modulus=3 * g.young_modulus))))
        np.testing.assert_allclose(m3[:2], m1[:2], rtol=1e-13, atol=1e-14)
        # force margin >= 0  <=>  pi E d^2 / cos^2(phi) <= f_max  (eq. 21)
        d, cphi, dt2, theta = numpy_kinematics(x, g)
        f_n = np.pi * np.asarray(g.young_modulus) * 1e-6 * d**2 / cphi**2
        assert ((m1[2] >= 0) == (f_n <= np.asarray(g.max_force)))[d > 0].all()


def test_matches_ipopt_reference_model():
    """Energy and margins agree with the independent CasADi transcription."""
    pytest.importorskip("casadi")
    from ipopt_reference import reference_constraints, reference_pose_energy

    rng = np.random.default_rng(12)
    for g in (four_finger(), random_grasp(rng), presets.prism(2e5, 2e-3, 0.1)):
        p = model_params(g)
        for _ in range(4):
            x = np.asarray(random_pose(rng, 0.4, 0.03))
            x_si = np.concatenate([x[:3] * 1e-3, x[3:]])
            assert float(potential_energy(jnp.asarray(x), p)) * 1e-3 == pytest.approx(
                reference_pose_energy(g, x_si), rel=1e-11
            )
            ref = reference_constraints(g, x_si)
            m = np.asarray(constraint_margins(jnp.asarray(x), p))
            # same scaling as the reference where dr >= 1e-3 r
            np.testing.assert_allclose(m[0], ref["contact"], rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(m[1], ref["slip"], rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(m[2], ref["max_force"], rtol=1e-10, atol=1e-12)


# ------------------------------------------- hand-written derivatives used by the solver
def _kinematics_stack(x, p):
    return jnp.stack(M.contact_kinematics(x, p), axis=-1)  # (N, 4)


_kin_jacobian = jax.jit(M.kinematics_jacobian)
_kin_curvature = jax.jit(M.kinematics_curvature)
_auto_jacobian = jax.jit(jax.jacfwd(_kinematics_stack))
_auto_hessian = jax.jit(jax.hessian(_kinematics_stack))


def _derivative_cases():
    """(name, grasp, pose): the cube at rest and moved, generic 3-contact grasps (one
    with a mask) at rotations from exactly zero (the rotation's series branch) to large.
    Two contact counts only: each compiles these small functions once."""
    rng = np.random.default_rng(7)
    cases = [("cube_zero", presets.cube(), jnp.zeros(6))]
    cases.append(("cube_moved", presets.cube(), jnp.asarray([0.3, -0.2, 0.1, 0.02, -0.05, 0.04])))
    for w_scale in (0.0, 1e-4, 0.05, 0.6):
        cases.append((f"generic_w{w_scale:g}", random_grasp(rng, n=3), random_pose(rng, w_scale=w_scale)))
    g = random_grasp(rng, n=3).replace(active=np.array([True, False, True]))
    cases.append(("masked", g, random_pose(rng, w_scale=0.1)))
    return cases


def _close(got, want, rtol=1e-12):
    scale = max(float(jnp.max(jnp.abs(want))), 1e-300)
    np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * scale)


@pytest.mark.parametrize("name, grasp, x", _derivative_cases(), ids=lambda v: v if isinstance(v, str) else "")
def test_kinematics_jacobian_and_curvature_equal_autodiff(name, grasp, x):
    """model.kinematics_jacobian / kinematics_curvature (written from dR/dw and one 3x3
    matrix, for the solver's Newton step) equal jax.jacfwd / jax.hessian of
    contact_kinematics, contracted with random weights, to rounding."""
    p = model_params(grasp)
    q, dq, geometry = _kin_jacobian(x, p)
    _close(q, _kinematics_stack(x, p), 1e-13)
    _close(dq, _auto_jacobian(x, p))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=q.shape))
    got = _kin_curvature(x, p, geometry, weights)
    _close(got, jnp.einsum("nk,nkab->ab", weights, _auto_hessian(x, p)))
    _close(got, got.T, 1e-13)  # a Hessian


def _autodiff_per_contact(fn, q):
    """``(..., N, 4)``: ``fn`` (contact by contact, ``(N, 4) -> (..., N)``) differentiated by
    ``jax.jacfwd`` in all of ``q`` and reduced to each contact's own block."""
    full = jax.jacfwd(fn)(q)  # (..., N, N, 4)
    return jnp.einsum("...iik->...ik", full)


@pytest.mark.slow  # compiles autodiff of the model
@pytest.mark.parametrize("name, grasp, x", _derivative_cases()[::3], ids=lambda v: v if isinstance(v, str) else "")
def test_contact_derivatives_written_out_equal_autodiff(name, grasp, x):
    """model.contact_gradients / contact_hessians (each contact's energy and margins in its
    own kinematics q = (d, cos phi, dt^2, theta), written out for the solver) equal
    autodiff of elastic_energies and margins_of: at the grasp's own kinematics and with d
    moved to a released contact (d < 0), to exactly 0 (where d max(d, 0)/dd is 1/2, as
    autodiff takes it) and deep into the fingertip, torsion and tangential terms on."""
    p = model_params(grasp)
    q0 = jnp.stack(M.contact_kinematics(x, p), axis=-1)
    energies = lambda q: M.elastic_energies(tuple(q.T), p)  # noqa: E731
    margins = lambda q: M.margins_of(tuple(q.T), p)  # noqa: E731
    for d in (None, -0.3, 0.0, 2.5):
        q = q0 if d is None else q0.at[:, 0].set(d).at[:, 2].add(0.05).at[:, 3].add(0.02)
        de, dm = M.contact_gradients(tuple(q.T), p)
        he, hm = M.contact_hessians(tuple(q.T), p)
        _close(de, _autodiff_per_contact(energies, q))
        _close(dm, _autodiff_per_contact(margins, q))
        hess = lambda fn: jnp.einsum("...iikil->...ikl", jax.jacfwd(jax.jacfwd(fn))(q))  # noqa: E731
        _close(he, hess(energies))
        _close(hm, hess(margins))


@jax.jit
def _program_derivatives(data, z, weights, gauss_newton):
    """(fx, gx, grad f, jac, Lagrangian Hessian with the Gauss-Newton term of weights
    ``gauss_newton``) from the grasp programs' Problem, and the same from the solver's
    autodiff default for the same fg."""
    from jaxgrasp.tolerance import _problems as P
    from jaxgrasp.solver import _solver as S

    def both(problem):
        d = S.first_order(problem, z)
        return d.fx, d.gx, d.grad_f, d.jac, S.lagrangian_hessian(problem, d, z, weights, gauss_newton)

    return both(P.lane_problem(data)), both(S.Problem(lambda z: P.objective_and_constraints(z, data)))


@pytest.mark.slow  # compiles autodiff of the model
@pytest.mark.parametrize("name, grasp, x", _derivative_cases()[1::2], ids=lambda v: v if isinstance(v, str) else "")
def test_program_derivatives_equal_autodiff(name, grasp, x):
    """The grasp programs' Problem (first order and Lagrangian Hessian written from the
    kinematics) gives what the solver's autodiff default gives for the same fg."""
    from jaxgrasp.tolerance import _problems as P

    data = P.problem_data(model_params(grasp))
    z = jnp.concatenate([x[:3], x[3:] * data.lever])
    rng = np.random.default_rng(5)
    m = 3 * grasp.num_contacts
    weights = jnp.asarray(rng.normal(size=m))
    # some rows without the term, as phi's mask leaves them
    gauss_newton = jnp.asarray(rng.uniform(0.0, 10.0, size=m) * (rng.random(m) < 0.6))
    got, want = _program_derivatives(data, z, weights, gauss_newton)
    for g, w in zip(got, want):
        _close(g, w)


@jax.jit
def _phi_hessians(data, z, lam, nu, rho, eq_mask):
    """The solver's Hessian of phi for the grasp programs' Problem, and ``jax.hessian`` of
    phi itself (:func:`jaxgrasp.solver._solver.augmented_lagrangian`)."""
    from jaxgrasp.tolerance import _problems as P
    from jaxgrasp.solver import _solver as S

    problem = P.lane_problem(data)
    s = S.init(z, eq_mask, nu, True, S.SolverOptions())
    s = dataclasses.replace(s, lam=lam, rho=rho)
    phi = lambda z: S.augmented_lagrangian(problem.fg, z, lam, nu, rho, eq_mask)  # noqa: E731
    return S.phi_hessian(problem, s, S.first_order(problem, z)), jax.hessian(phi)(z)


@pytest.mark.slow  # compiles autodiff of the model
@pytest.mark.parametrize("name, grasp, x", _derivative_cases()[1::2], ids=lambda v: v if isinstance(v, str) else "")
def test_phi_hessian_equals_autodiff_of_phi(name, grasp, x):
    """The Newton step's Hessian of the augmented Lagrangian phi (the Lagrangian's, with
    the penalty's Gauss-Newton term folded into each contact's 4 x 4 block) equals
    jax.hessian of phi, with an equality row, inequality rows on both sides of their
    kink (shifted multiplier positive and zero) and a large penalty."""
    from jaxgrasp.tolerance import _problems as P

    data = P.problem_data(model_params(grasp))
    z = jnp.concatenate([x[:3], x[3:] * data.lever])
    m = 3 * grasp.num_contacts
    gx = P.objective_and_constraints(z, data)[1]
    rng = np.random.default_rng(11)
    rho = 30.0
    # lam - rho g > 0 on about half of the rows, clearly negative on the rest
    lam = jnp.where(jnp.asarray(rng.random(m) < 0.5), rho * gx + rng.uniform(0.5, 2.0, m), 0.0)
    eq_mask = jnp.zeros(m).at[grasp.num_contacts + 1].set(1.0)
    got, want = _phi_hessians(data, z, lam, 0.7, rho, eq_mask)
    _close(got, want, 1e-11)
