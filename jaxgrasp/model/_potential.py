"""The potential field of a soft-fingertip grasp (Tsuji et al., eq. 3-21), in pure JAX.

All functions here work in internal units (mm, N, N/mm^2, mJ; see `jaxgrasp.model._units`)
on a `ModelParams`, and take the object's pose change ``x = (dp, w)``:
``dp`` (3,) translation in mm, ``w`` (3,) rotation vector in rad. They are pure,
and compose with ``jit``, ``vmap``, ``grad`` and ``hessian``, including at ``x = 0``.

Constraint margins are returned *scaled* so that each is ~1 in the initial state and
``>= 0`` means satisfied. Positive scale factors do not move the feasible set, the
minimisers or the minimum energies; they only condition the solver. The scale factors
depend on the parameters only through ``stop_gradient`` constants, so derivatives with
respect to the parameters (envelope theorem, `jaxgrasp.tolerance._envelope`) see the
unscaled constraints times a constant, which leaves the value's gradient exact.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from jaxgrasp.model._codes import BoundaryKind
from jaxgrasp.model._grasp import Grasp
from jaxgrasp.model._units import M_TO_MM, PA_TO_MPA
from jaxgrasp.base import contract

__all__ = [
    "ModelParams",
    "model_params",
    "rotation_matrix",
    "rotation_jacobian",
    "rotation_hessian_along",
    "contact_kinematics",
    "potential_energy",
    "constraint_margins",
    "energy_and_margins",
    "elastic_energies",
    "energy_of",
    "margins_of",
    "slip_torsion",
    "contact_gradients",
    "contact_hessians",
    "kinematics_jacobian",
    "kinematics_curvature",
    "energy_scale",
    "KINDS",
]

KINDS = BoundaryKind.labels()
"""Boundary kind names (``"slip"``, ``"max_force"``), indexed by
[`BoundaryKind`][jaxgrasp.model.BoundaryKind]: the order of every ``(2, N)`` array of the library
(``BoundaryKind.labels()``)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ModelParams:
    """A grasp in internal units (mm, N, N/mm^2). Built by `model_params`."""

    c: Any  # (N, 3) contact positions, mm
    n: Any  # (N, 3) unit outward normals
    dr: Any  # (N,) initial deformation, mm
    r: Any  # (N,) fingertip radius, mm
    E: Any  # (N,) Young's modulus, N/mm^2
    mu: Any  # (N,) friction coefficient
    fmax: Any  # (N,) normal force limit, N
    weight: Any  # (3,) m * g_vec, N
    on: Any  # (N,) bool, the active contacts (Grasp.active; all where it is None)


def model_params(grasp: Grasp) -> ModelParams:
    """Convert an SI [`Grasp`][jaxgrasp.Grasp] to internal units, normalising normals."""
    n = jnp.asarray(grasp.normals)
    n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
    on = jnp.ones(n.shape[:-1], bool) if grasp.active is None else jnp.asarray(grasp.active, bool)
    # a per-contact field given as a scalar (e.g. by Grasp.replace) stands for every contact
    each = lambda a: jnp.broadcast_to(a, on.shape) if jnp.ndim(a) == 0 else jnp.asarray(a)
    return ModelParams(
        c=jnp.asarray(grasp.positions) * M_TO_MM,
        n=n,
        dr=each(grasp.initial_deformation) * M_TO_MM,
        r=each(grasp.radius) * M_TO_MM,
        E=each(grasp.young_modulus) * PA_TO_MPA,
        mu=each(grasp.friction),
        fmax=each(grasp.max_force),
        weight=jnp.asarray(grasp.mass)[..., None] * jnp.asarray(grasp.gravity),
        on=on,
    )


_LEVI_CIVITA = tuple(
    tuple(tuple(float((i - j) * (j - k) * (k - i) / 2) for k in range(3)) for j in range(3)) for i in range(3)
)
"""``eps[i][j][k]``, the Levi-Civita symbol: ``skew(w)_ij = -eps_ijk w_k``."""


def rotation_matrix(w):
    """Rodrigues' formula ``R = I + A K + B K^2`` for a rotation vector ``w`` (3,), rad.

    Uses the series of ``A = sin t / t`` and ``B = (1 - cos t) / t^2`` below
    ``t^2 < 1e-6`` with the double-``where`` trick, so that value, gradient and Hessian
    are finite and exact at ``w = 0``.
    """
    a, b = _rotation_coefficients(contract("a,a->", w, w), derivatives=False)
    k = _skew(w)
    return jnp.eye(3, dtype=w.dtype) + a * k + b * contract("ab,bc->ac", k, k)


def _skew(w):
    """``(3, 3)`` ``skew(w)`` (``skew(w) v = w x v``), exactly: one product per entry."""
    return -contract("ijk,k->ij", jnp.asarray(_LEVI_CIVITA, w.dtype), w)


def _rotation_coefficients(t2, derivatives: bool = True):
    """``(a, b, a1, b1, a2, b2)`` of ``R = I + a K + b K^2`` at ``t2 = |w|^2``: ``a = sin t /
    t``, ``b = (1 - cos t) / t^2`` and their first and second derivatives in ``t2``
    (without ``derivatives``: ``(a, b)`` alone), from the series below ``t2 < 1e-6`` with
    the double-``where`` trick, so that value, gradient and Hessian are finite and exact at
    ``w = 0``, and closed forms above: ``a1 = (cos t - a) / (2 t2)``, ``b1 = (a / 2 - b) /
    t2``, ``a2 = -(a / 2 + 3 a1) / (2 t2)``, ``b2 = (a1 / 2 - 2 b1) / t2``."""
    small = t2 < 1e-6
    s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(s)
    a_big, c_big = jnp.sin(t) / t, jnp.cos(t)
    b_big = (1.0 - c_big) / s
    pick = lambda series, closed: jnp.where(small, series, closed)  # noqa: E731
    a = pick(1.0 - t2 / 6.0 + t2 * t2 / 120.0, a_big)
    b = pick(0.5 - t2 / 24.0 + t2 * t2 / 720.0, b_big)
    if not derivatives:
        return a, b
    a1_big = (c_big - a_big) / (2.0 * s)
    b1_big = (0.5 * a_big - b_big) / s
    a2_big = -(0.5 * a_big + 3.0 * a1_big) / (2.0 * s)
    b2_big = (0.5 * a1_big - 2.0 * b1_big) / s
    return (
        a,
        b,
        pick(-1.0 / 6.0 + t2 / 60.0 - t2 * t2 / 1680.0, a1_big),
        pick(-1.0 / 24.0 + t2 / 360.0 - t2 * t2 / 13440.0, b1_big),
        pick(1.0 / 60.0 - t2 / 840.0, a2_big),
        pick(1.0 / 360.0 - t2 / 6720.0, b2_big),
    )


def rotation_jacobian(w):
    """``(3, 3, 3)`` ``dR / dw_k`` (last axis ``k``) of `rotation_matrix` at ``w`` (3,),
    written out: ``dR/dw_k = 2 w_k (a1 K + b1 K^2) + a dK/dw_k + b (e_k w^T + w e_k^T -
    2 w_k I)`` (``K = skew(w)``; coefficients from `_rotation_coefficients`): a few
    dozen operations where forward-mode autodiff of the matrix takes hundreds."""
    eps = jnp.asarray(_LEVI_CIVITA, w.dtype)
    eye = jnp.eye(3, dtype=w.dtype)
    a, b, a1, b1, _, _ = _rotation_coefficients(contract("a,a->", w, w))
    k = _skew(w)
    inner = a1 * k + b1 * contract("ab,bc->ac", k, k)
    sym = eye[:, None, :] * w[None, :, None] + w[:, None, None] * eye[None, :, :] - 2.0 * eye[:, :, None] * w
    return 2.0 * inner[:, :, None] * w - a * eps + b * sym


def rotation_hessian_along(w, m):
    """``(3, 3)`` Hessian in ``w`` of ``s(w) = sum_ij R(w)_ij m_ij`` (`rotation_matrix`;
    ``m`` ``(3, 3)`` fixed), written out. With ``p = K : m = w . mu`` (``mu_k = dK/dw_k : m``),
    ``q = K^2 : m = w^T m w - t2 tr m``, ``g = grad q = (m + m^T) w - 2 tr(m) w`` and
    ``v = a1 mu + b1 g``: ``H = 2 (a1 p + b1 q) I + 4 (a2 p + b2 q) w w^T + 2 (w v^T + v w^T)
    + b (m + m^T - 2 tr(m) I)``."""
    eps = jnp.asarray(_LEVI_CIVITA, w.dtype)
    eye = jnp.eye(3, dtype=w.dtype)
    t2 = contract("a,a->", w, w)
    _, b, a1, b1, a2, b2 = _rotation_coefficients(t2)
    mu = -contract("ijk,ij->k", eps, m)
    sym = m + m.T
    tr = jnp.trace(m)
    p = contract("a,a->", w, mu)
    q = contract("a,ab,b->", w, m, w) - t2 * tr
    v = a1 * mu + b1 * (contract("ab,b->a", sym, w) - 2.0 * tr * w)
    return (
        2.0 * (a1 * p + b1 * q) * eye
        + 4.0 * (a2 * p + b2 * q) * contract("a,b->ab", w, w)
        + 2.0 * (contract("a,b->ab", w, v) + contract("a,b->ab", v, w))
        + b * (sym - 2.0 * tr * eye)
    )


def contact_kinematics(x, p: ModelParams):
    """Fingertip deformations for pose change ``x = (dp [mm], w [rad])``, eq. 11-16.

    Returns ``(d, cphi, dt2, theta)``, each ``(N,)``: normal deformation ``d`` (mm,
    eq. 13), ``cos(phi)`` (eq. 14; ``arccos`` is never taken), squared tangential
    deformation ``dt^2`` (mm^2, eq. 15; the norm is never taken) and torsion angle
    ``theta`` (rad, eq. 16: the rotation vector of ``R_i^T dR R_i`` is ``R_i^T w``, whose
    normal component is ``w . n_i``).
    """
    dp, w = x[:3], x[3:]
    rot = rotation_matrix(w)
    u = contract("nb,ab->na", p.c, rot - jnp.eye(3, dtype=x.dtype)) + dp  # (N, 3) contact displacement
    rn = contract("nb,ab->na", p.n, rot)  # (N, 3) rotated normals
    cphi = jnp.sum(p.n * rn, axis=-1)
    d = p.r - jnp.sum(((p.r - p.dr)[:, None] * p.n - u) * rn, axis=-1)
    un = jnp.sum(p.n * u, axis=-1)
    dt2 = jnp.sum(u * u, axis=-1) - un * un
    theta = contract("na,a->n", p.n, w)
    return d, cphi, dt2, theta


def potential_energy(x, p: ModelParams):
    """Potential energy ``U`` of the grasp system, mJ (eq. 3, 5, 7, 17-19).

    ``U = sum_i pi E_i (d^3 / (3 cos^2 phi) + d dt^2 + d^2 (r - d/3) theta^2) - (m g_vec) . dp``,
    zero gravitational energy at the initial state. For ``d_i < 0`` (outside the
    contact-keeping constraint, where the paper's formulas do not apply) the fingertip is
    taken as not touching: its deformation enters as ``max(d_i, 0)``. This leaves ``U``
    unchanged on the feasible set and bounded below outside it, which the solver needs.
    Inactive contacts (``p.on`` false) contribute nothing.
    """
    return energy_of(x, contact_kinematics(x, p), p)


def energy_of(x, kinematics, p: ModelParams):
    """`potential_energy` ``()`` mJ at ``x`` from the contact kinematics there
    ``(d, cos phi, dt^2, theta)`` (`contact_kinematics`)."""
    return jnp.sum(elastic_energies(kinematics, p)) - contract("a,a->", p.weight, x[:3])


def elastic_energies(kinematics, p: ModelParams):
    """``(N,)`` elastic energy of each fingertip, mJ, from its kinematics ``(d, cos phi,
    dt^2, theta)`` (`contact_kinematics`); 0 for an inactive contact."""
    d, cphi, dt2, theta = kinematics
    dp = jnp.maximum(d, 0.0)
    elastic = jnp.pi * p.E * (
        dp**3 / (3.0 * cphi**2) + dp * dt2 + dp**2 * (p.r - dp / 3.0) * theta**2
    )
    return jnp.where(p.on, elastic, 0.0)


def energy_scale(p: ModelParams):
    """A constant energy scale, mJ: the elastic energy of the initial state (no gradient)."""
    return jax.lax.stop_gradient(jnp.sum(jnp.where(p.on, jnp.pi * p.E * p.dr**3 / 3.0, 0.0)))


def constraint_margins(x, p: ModelParams):
    """Scaled constraint margins ``(3, N)``, ``>= 0`` where satisfied.

    Rows (`Constraint`), for each contact ``i``:

    0. contact kept: ``d_i / dr_i``;
    1. no slip (Howe-Cutkosky with torsion, eq. 9 divided by ``(pi E d)^2`` and by
       ``(mu dr)^2``): ``(mu^2 d^2 / cos^4 phi - 4 dt^2
       - (225/16) d (r - d/3)^2 theta^2 / (mu^2 (2r - d))) / (mu dr)^2``. This form is
       independent of ``E`` and has no ``1/e^2`` singularity at ``d -> 0``;
    2. normal force below its limit (eq. 21): ``(sqrt(f_max / (pi E)) cos phi - d) / dr``.

    An inactive contact's margins are the constant 1 (always satisfied, no gradient).
    """
    return margins_of(contact_kinematics(x, p), p)


def margins_of(kinematics, p: ModelParams):
    """`constraint_margins` ``(3, N)`` from the contact kinematics ``(d, cos phi,
    dt^2, theta)`` (`contact_kinematics`)."""
    d, cphi, dt2, theta = kinematics
    dr = jax.lax.stop_gradient(p.dr)
    mu_dr2 = jax.lax.stop_gradient((p.mu * p.dr) ** 2)
    contact = d / dr
    slip = (p.mu**2 * d**2 / cphi**4 - 4.0 * dt2 - slip_torsion(d, theta, p)) / mu_dr2
    force = (jnp.sqrt(p.fmax / (jnp.pi * p.E)) * cphi - d) / dr
    return jnp.where(p.on, jnp.stack([contact, slip, force]), 1.0)


def slip_torsion(d, theta, p: ModelParams):
    """``(N,)`` mm^2, the torsion term of the slip margin (`margins_of`, eq. 9),
    ``(225/16) d (r - d/3)^2 theta^2 / (mu^2 (2r - d))`` for deformation ``d`` (mm) and
    torsion angle ``theta`` (rad)."""
    return (225.0 / 16.0) * d * (p.r - d / 3.0) ** 2 * theta**2 / (p.mu**2 * (2.0 * p.r - d))


def _contact_terms(kinematics, p: ModelParams):
    """Shared pieces of `contact_gradients` and `contact_hessians`."""
    d, cphi, dt2, theta = kinematics
    dp = jnp.maximum(d, 0.0)
    ddp = jnp.where(d > 0, 1.0, jnp.where(d < 0, 0.0, 0.5))  # d max(d, 0) / dd, as autodiff takes it
    dr = jax.lax.stop_gradient(p.dr)
    mu_dr2 = jax.lax.stop_gradient((p.mu * p.dr) ** 2)
    u = p.r - d / 3.0
    v = 2.0 * p.r - d
    k = (225.0 / 16.0) / p.mu**2
    f = d * u**2 / v  # the slip margin's torsion term is -k f theta^2
    f1 = u**2 / v - (2.0 / 3.0) * d * u / v + d * u**2 / v**2
    return d, cphi, dt2, theta, dp, ddp, dr, mu_dr2, k, f, f1, u, v


def contact_gradients(kinematics, p: ModelParams):
    """Derivatives of each contact's `elastic_energies` and `margins_of` with
    respect to its own kinematics ``q = (d, cos phi, dt^2, theta)``, written out: ``(de,
    dm)``, ``de`` ``(N, 4)`` mJ per unit of ``q``, ``dm`` ``(3, N, 4)`` (rows as
    `margins_of`); zero for an inactive contact. ``d max(d, 0) / dd`` at ``d = 0`` is
    1/2, as JAX's autodiff takes it."""
    d, c, s, th, dp, ddp, dr, mu_dr2, k, f, f1, _, _ = _contact_terms(kinematics, p)
    a = jnp.pi * p.E
    zero = jnp.zeros_like(d)
    de = a[:, None] * jnp.stack(
        [
            (dp**2 / c**2 + s + (2.0 * dp * p.r - dp**2) * th**2) * ddp,
            -2.0 * dp**3 / (3.0 * c**3),
            dp,
            2.0 * dp**2 * (p.r - dp / 3.0) * th,
        ],
        axis=-1,
    )
    mu2 = p.mu**2
    slip = jnp.stack([2.0 * mu2 * d / c**4 - k * f1 * th**2, -4.0 * mu2 * d**2 / c**5, -4.0 + zero, -2.0 * k * f * th], -1)
    force_c = jnp.sqrt(p.fmax / (jnp.pi * p.E))
    dm = jnp.stack(
        [
            jnp.stack([1.0 / dr, zero, zero, zero], -1),
            slip / mu_dr2[:, None],
            jnp.stack([-1.0 / dr, force_c / dr, zero, zero], -1),
        ]
    )
    on = p.on[:, None]
    return jnp.where(on, de, 0.0), jnp.where(on, dm, 0.0)


def contact_hessians(kinematics, p: ModelParams):
    """Second derivatives of each contact's `elastic_energies` and `margins_of`
    with respect to its own kinematics ``q``, written out: ``(he, hm)``, ``he`` ``(N, 4,
    4)``, ``hm`` ``(3, N, 4, 4)`` (contact and force rows are linear in ``q``: zero);
    zero for an inactive contact."""
    d, c, s, th, dp, ddp, dr, mu_dr2, k, f, f1, u, v = _contact_terms(kinematics, p)
    a = jnp.pi * p.E
    zero = jnp.zeros_like(d)
    e_dd = (2.0 * dp / c**2 + (2.0 * p.r - 2.0 * dp) * th**2) * ddp**2
    e_dc = -2.0 * dp**2 / c**3 * ddp
    e_ds = ddp
    e_dt = 2.0 * (2.0 * dp * p.r - dp**2) * th * ddp
    e_cc = 2.0 * dp**3 / c**4
    e_tt = 2.0 * dp**2 * (p.r - dp / 3.0)
    he = a[:, None, None] * jnp.stack(
        [
            jnp.stack([e_dd, e_dc, e_ds, e_dt], -1),
            jnp.stack([e_dc, e_cc, zero, zero], -1),
            jnp.stack([e_ds, zero, zero, zero], -1),
            jnp.stack([e_dt, zero, zero, e_tt], -1),
        ],
        axis=-2,
    )
    mu2 = p.mu**2
    f2 = -4.0 * u / (3.0 * v) + 2.0 * u**2 / v**2 + 2.0 * d / (9.0 * v) - (4.0 / 3.0) * d * u / v**2 + 2.0 * d * u**2 / v**3
    s_dd = 2.0 * mu2 / c**4 - k * f2 * th**2
    s_dc = -8.0 * mu2 * d / c**5
    s_dt = -2.0 * k * f1 * th
    s_cc = 20.0 * mu2 * d**2 / c**6
    s_tt = -2.0 * k * f
    slip = jnp.stack(
        [
            jnp.stack([s_dd, s_dc, zero, s_dt], -1),
            jnp.stack([s_dc, s_cc, zero, zero], -1),
            jnp.stack([zero, zero, zero, zero], -1),
            jnp.stack([s_dt, zero, zero, s_tt], -1),
        ],
        axis=-2,
    ) / mu_dr2[:, None, None]
    linear = jnp.zeros_like(slip)
    hm = jnp.stack([linear, slip, linear])
    on = p.on[:, None, None]
    return jnp.where(on, he, 0.0), jnp.where(on, hm, 0.0)


def energy_and_margins(x, p: ModelParams):
    """``(potential_energy(x, p), constraint_margins(x, p))`` from one evaluation of the
    contact kinematics (the solver's problems need both at every point; sharing the
    kinematics also shares their derivatives)."""
    kinematics = contact_kinematics(x, p)
    return energy_of(x, kinematics, p), margins_of(kinematics, p)


def kinematics_jacobian(x, p: ModelParams):
    """The contact kinematics and their Jacobian in the pose change, written from the
    rotation's derivatives.

    Returns ``(q, dq, geometry)``: `contact_kinematics` ``q = (d, cos phi, dt^2,
    theta)`` of every contact as ``(N, 4)``, the Jacobian ``dq`` ``(N, 4, 6)`` with respect
    to ``x = (dp [mm], w [rad])``, and the per-contact vectors
    `kinematics_curvature` reuses. Every quantity is a polynomial of degree at most
    two in ``u = (R - I) c + dp`` and ``R n``, so its derivatives follow from
    ``dR/dw_k`` (``3 x 3`` each, `rotation_jacobian`, once per pose rather than once
    per contact and tangent).
    """
    dtype = x.dtype
    dp, w = x[:3], x[3:]
    rot = rotation_matrix(w)
    d_rot = rotation_jacobian(w)  # (3, 3, k)
    c, n = p.c, p.n
    num = c.shape[0]
    u = contract("nb,ab->na", c, rot - jnp.eye(3, dtype=dtype)) + dp  # (N, 3)
    rn = contract("nb,ab->na", n, rot)  # (N, 3): R n
    a_c = contract("abk,nb->nka", d_rot, c)  # (N, k, 3): dR/dw_k c
    a_n = contract("abk,nb->nka", d_rot, n)  # dR/dw_k n
    arm = (p.r - p.dr)[:, None]  # (N, 1)

    cphi = jnp.sum(n * rn, axis=-1)
    d = p.r - jnp.sum((arm * n - u) * rn, axis=-1)
    un = jnp.sum(n * u, axis=-1)
    dt2 = jnp.sum(u * u, axis=-1) - un * un
    theta = contract("na,a->n", n, w)

    zeros3 = jnp.zeros((num, 3), dtype)
    # rows of dq, (N, 6) each: [d/d dp | d/d w]
    n_a_n = contract("na,nka->nk", n, a_n)
    dcphi = jnp.concatenate([zeros3, n_a_n], axis=-1)
    dd_w = -arm * n_a_n + contract("nka,na->nk", a_c, rn) + contract("na,nka->nk", u, a_n)
    dd = jnp.concatenate([rn, dd_w], axis=-1)
    pu = u - un[:, None] * n  # (N, 3): the tangential part of u
    ddt2 = 2.0 * jnp.concatenate([pu, contract("nka,na->nk", a_c, pu)], axis=-1)
    dtheta = jnp.concatenate([zeros3, n], axis=-1)
    dq = jnp.stack([dd, dcphi, ddt2, dtheta], axis=1)  # (N, 4, 6)
    q = jnp.stack([d, cphi, dt2, theta], axis=-1)
    return q, dq, (u, rn, pu, a_c, a_n)


def kinematics_curvature(x, p: ModelParams, geometry, weights):
    """``(6, 6)`` ``sum_ik weights_ik d2 q_ik / dx^2``: the kinematics' second derivatives
    weighted by ``weights`` ``(N, 4)`` (one per contact and quantity of ``q``), summed
    over contacts as they are formed, so that no per-contact ``6 x 6`` Hessian is ever
    built (``geometry`` from `kinematics_jacobian` at the same ``x``).

    With ``A_k = dR/dw_k`` and ``B_kl = d2R/dw_k dw_l``: ``theta`` is linear; ``cos phi =
    n.Rn`` and the ``B`` terms of ``d`` and ``dt^2`` add up to ``sum B_kl : M`` for one
    ``3 x 3`` matrix ``M`` (the Hessian of ``w -> R(w) : M``, `rotation_hessian_along`); the rest are products of
    the per-contact vectors ``A_k c``, ``A_k n``.
    """
    dtype = x.dtype
    u, rn, pu, a_c, a_n = geometry
    c, n = p.c, p.n
    arm = p.r - p.dr
    gd, gc, gt = weights[:, 0], weights[:, 1], weights[:, 2]
    outer = lambda s, a, b: contract("n,na,nb->ab", s, a, b)
    # every B_kl term: d (-arm n.Bn + Bc.Rn + u.Bn), cos phi (n.Bn), dt^2 (2 Pu.Bc)
    m = outer(gd, rn, c) + outer(gd, u, n) + outer(gc - gd * arm, n, n) + outer(2.0 * gt, pu, c)
    b_part = rotation_hessian_along(x[3:], m)
    # d: (A_k c).(A_l n) + (A_l c).(A_k n), and the dp-w cross term A_k n
    a_cn = contract("n,nka,nla->kl", gd, a_c, a_n)
    ww = b_part + a_cn + a_cn.T
    pw = contract("n,nka->ak", gd, a_n)
    # dt^2 = |P u|^2: 2 (du)^T P (du), du = [I | A_k c]
    s_c = contract("na,nka->nk", n, a_c)  # n . A_k c
    ww = ww + 2.0 * (contract("n,nka,nla->kl", gt, a_c, a_c) - contract("n,nk,nl->kl", gt, s_c, s_c))
    pw = pw + 2.0 * (contract("n,nka->ak", gt, a_c) - contract("n,na,nk->ak", gt, n, s_c))
    pp = 2.0 * (jnp.sum(gt) * jnp.eye(3, dtype=dtype) - outer(gt, n, n))
    return jnp.block([[pp, pw], [pw.T, ww]])
