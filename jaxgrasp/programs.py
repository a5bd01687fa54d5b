"""The 1 + 2N programs of a grasp (eq. 1), their starts, and solving them as solver lanes.

* the *equilibrium* problem ``U0 = min U`` subject to every contact, friction and
  force-limit constraint, solved from the initial grasping state;
* for each contact ``j`` a *slip* problem (friction of ``j`` as an equality) and a
  *max_force* problem (force limit of ``j`` as an equality), each with every other
  constraint kept.

Every program has the same scaled objective and constraints (:func:`objective`,
:func:`constraints`), in the scaled pose ``z = (dp [mm], lever * w [mm])`` so that
rotations and translations move the contacts by comparable amounts, with the energy
divided by the initial elastic energy. A boundary program is one equality row of the
same constraint vector (``eq_mask``), so every program of every grasp runs as a lane of
one :func:`jaxgrasp.lanes.solve_lanes` call.

Boundary problems are non-convex, so each is solved from several starts (the caller
keeps the lowest converged energy): a start is found by walking from the equilibrium
along a direction until the boundary's constraint is crossed, then bisecting onto it,
along the 12 half-axes of the grasp's own frame (its modes of motion, :func:`start_frame`)
plus ``EvaluateOptions.num_random_starts`` seeded random directions in that frame: the
starts turn with the grasp, so a grasp written in a rotated or mirrored world frame, or
with its contacts renumbered, gets the same starts and the same minima.

A lane that stalls at a feasible point (status ``NOT_CONVERGED``: typically a released
fingertip whose slip margin is active at the apex of its friction cone, where no bounded
multiplier exists) is then certified, or left as it is, by a Newton polish of its KKT
equations (:func:`settle_stalled`).
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .dense import eigh as serial_eigh
from .dense import solve as dense_solve
from .gathered import over_rows, put_rows
from .grasp import Grasp
from .lanes import solve_lane_batches
from .model import (
    ModelParams,
    constraint_margins,
    contact_gradients,
    contact_hessians,
    contact_kinematics,
    energy_and_margins,
    energy_of,
    energy_scale,
    kinematics_curvature,
    kinematics_jacobian,
    margins_of,
    model_params,
    potential_energy,
    rotation_matrix,
)
from .options import EvaluateOptions
from .solver import FirstOrder, Problem, SolverOptions, SolverResult, kkt_tol
from .status import LaneStatus

__all__ = [
    "ProgramData",
    "program_data",
    "to_pose",
    "objective",
    "constraints",
    "objective_and_constraints",
    "lane_problem",
    "lagrangian",
    "Programs",
    "programs_treedef",
    "solve_programs",
    "programs_of",
    "programs_of_batch",
    "LaneStarts",
    "batch_data",
    "equilibrium_starts",
    "equilibrium_of",
    "boundary_starts",
    "solve_stage",
    "finish_programs",
    "start_frame",
    "FRAME_TIE",
    "FRAME_BITS",
    "settle_stalled",
    "needs_settling",
    "RELEASED_TOL",
    "MAX_POLISHED",
]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ProgramData:
    """What the programs of one grasp depend on (a pytree; one per lane under ``solve_lanes``).

    Attributes:
        params: the grasp in internal units (:class:`~jaxgrasp.model.ModelParams`).
        lever: ``()`` mm, the length that scales rotations in ``z`` (no gradient).
        scale: ``()`` mJ, the energy scale dividing the objective (no gradient).
    """

    params: ModelParams
    lever: Any
    scale: Any


def program_data(p: ModelParams) -> ProgramData:
    """The scaling of ``p``'s programs: lever = largest contact distance or radius, scale =
    initial elastic energy (active contacts only); both constants (``stop_gradient``)."""
    reach = jnp.where(p.on, jnp.maximum(jnp.linalg.norm(p.c, axis=-1), p.r), 0.0)
    lever = jax.lax.stop_gradient(jnp.max(reach))
    return ProgramData(params=p, lever=lever, scale=energy_scale(p))


def to_pose(z, lever):
    """Scaled pose ``z = (dp [mm], lever * w [mm])`` -> pose change ``x = (dp [mm], w [rad])``."""
    return jnp.concatenate([z[:3], z[3:] / lever])


def objective(z, data: ProgramData):
    """Scaled potential energy ``U(z) / scale`` (dimensionless), ``z`` of shape ``(6,)``."""
    return potential_energy(to_pose(z, data.lever), data.params) / data.scale


def constraints(z, data: ProgramData):
    """Scaled constraint margins ``(3N,)``, rows of :func:`~jaxgrasp.model.constraint_margins`
    flattened (index ``row * N + contact``), ``>= 0`` where satisfied."""
    return constraint_margins(to_pose(z, data.lever), data.params).reshape(-1)


def objective_and_constraints(z, data: ProgramData):
    """``(objective(z, data), constraints(z, data))`` from one evaluation of the contact
    kinematics: the function the solver's lanes run (:func:`~jaxgrasp.solver.solve`'s ``fg``)."""
    energy, margins = energy_and_margins(to_pose(z, data.lever), data.params)
    return energy / data.scale, margins.reshape(-1)


def _pose_scale(data: ProgramData, dtype):
    """``(6,)`` ``dx/dz``: 1 for the translation, ``1 / lever`` for the rotation."""
    one = jnp.ones(3, dtype)
    return jnp.concatenate([one, one / data.lever])


def _first_order(z, data: ProgramData) -> FirstOrder:
    """The program at ``z`` with its gradient and constraint Jacobian, from the contact
    kinematics' Jacobian (:func:`~jaxgrasp.model.kinematics_jacobian`) and each contact's
    derivatives in its own kinematics (:func:`~jaxgrasp.model.contact_gradients`), both
    kept in ``aux`` for :func:`_lagrangian_hessian`."""
    p = data.params
    x = to_pose(z, data.lever)
    q, dq, geometry = kinematics_jacobian(x, p)
    de, dm = contact_gradients(tuple(q.T), p)  # (N, 4), (3, N, 4)
    scale = _pose_scale(data, z.dtype)
    gravity = jnp.concatenate([p.weight, jnp.zeros(3, z.dtype)])
    grad_f = (jnp.einsum("nk,nkj->j", de, dq) - gravity) * scale / data.scale
    # (3, N, 6) products over the 4 kinematic coordinates, written as a product and a sum
    # that XLA fuses into one loop: as an einsum each is a dot of 4-long rows per contact,
    # which XLA's CPU runtime runs one small matrix at a time: this one and the Hessian's
    # H_i dq_i took 9 % of the solver loop's profiled time, and written this way a random
    # batch runs 15 % faster (experiments/BENCHMARK.md)
    jac = jnp.sum(dm[:, :, :, None] * dq[None], axis=2).reshape(-1, 6) * scale
    fx = energy_of(x, tuple(q.T), p) / data.scale
    return FirstOrder(fx, margins_of(tuple(q.T), p).reshape(-1), grad_f, jac, aux=(q, dq, geometry, de, dm))


def _lagrangian_hessian(d: FirstOrder, z, weights, data: ProgramData):
    """``(6, 6)`` Hessian in ``z`` of ``f + weights . g`` (``weights`` ``(3N,)`` fixed), from
    the kinematics' derivatives in ``d.aux``: ``sum_i dq_i^T H_i dq_i + sum_ik
    (d psi / d q_ik) d2q_ik`` with ``psi_i`` contact ``i``'s share of the function of its
    own kinematics, ``H_i`` its ``4 x 4`` Hessian (:func:`~jaxgrasp.model.contact_hessians`,
    written out) and the second sum :func:`~jaxgrasp.model.kinematics_curvature`."""
    p = data.params
    q, dq, geometry, de, dm = d.aux
    w = weights.reshape(3, -1)
    he, hm = contact_hessians(tuple(q.T), p)
    gq = de / data.scale + jnp.einsum("rn,rnk->nk", w, dm)  # (N, 4): d psi_i / dq_i
    hq = he / data.scale + jnp.einsum("rn,rnkl->nkl", w, hm)  # (N, 4, 4)
    hd = jnp.sum(hq[:, :, :, None] * dq[:, None, :, :], axis=2)  # (N, 4, 6): H_i dq_i, fused (see _first_order)
    hx = jnp.einsum("njm,njl->ml", dq, hd) + kinematics_curvature(to_pose(z, data.lever), p, geometry, gq)
    scale = _pose_scale(data, z.dtype)
    return hx * scale[:, None] * scale[None, :]


def lane_problem(data: ProgramData) -> Problem:
    """The solver's view of a program of the grasp ``data``: values, first and second
    derivatives from the contact kinematics (the equality row is the lane's ``eq_mask``)."""
    return Problem(
        fg=lambda z: objective_and_constraints(z, data),
        first_order=lambda z: _first_order(z, data),
        lagrangian_hessian=lambda d, z, w: _lagrangian_hessian(d, z, w, data),
    )


def lagrangian(z, lam, nu, eq_mask, data: ProgramData):
    """``L = f(z) + nu h(z) - lam . g(z)`` of the program with equality row ``eq_mask``."""
    gz = constraints(z, data)
    return objective(z, data) + nu * jnp.sum(eq_mask * gz) - jnp.sum(lam * gz)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Programs:
    """Every program of one grasp as solved, lane by lane (internal, scaled units).

    The pose variable of every program is ``z = (dp [mm], lever * w [mm])``. With ``N``
    contacts and ``D`` starts per boundary problem (``EvaluateOptions.num_starts``):

    Attributes:
        equilibrium: :class:`~jaxgrasp.solver.SolverResult` of the equilibrium problem.
        boundary: :class:`~jaxgrasp.solver.SolverResult` with a leading lane axis
            ``(2N * D,)``: lane ``b * D + s`` is start ``s`` of boundary problem
            ``b = kind * N + contact``.
        start: ``(2N * D, 6)`` starting points of the boundary lanes.
        found: ``(2N * D,)`` whether the start search crossed the boundary (lanes where it
            did not carry status :attr:`~jaxgrasp.status.LaneStatus.NO_START`).
        constraint_index: ``(2N * D,)`` index ``k`` of the equality in the flattened
            ``(3N,)`` constraint vector (``N + b``).
        lever: ``()`` mm, the length that scales rotations.
        scale: ``()`` mJ, the energy scale dividing the objective.
        contact_on: ``(N,)`` bool, the active contacts (an inactive one's boundary
            lanes are never started).
    """

    equilibrium: SolverResult
    boundary: SolverResult
    start: Any
    found: Any
    constraint_index: Any
    lever: Any
    scale: Any
    contact_on: Any


def programs_treedef():
    """The pytree structure of :class:`Programs` (it depends on no shape), to rebuild one
    from its leaves, in ``jax.tree_util`` order."""
    lanes = SolverResult(*(0,) * len(dataclasses.fields(SolverResult)))
    return jax.tree_util.tree_structure(
        Programs(lanes, lanes, *(0,) * (len(dataclasses.fields(Programs)) - 2))
    )


def _ray_start(gk, z0, v, t_grid, crossing_steps):
    """First crossing of ``gk >= 0`` -> ``< 0`` along ``z0 + t v``; returns
    ``(z, found, g0)`` with ``g0 = gk(z0)``, the margin at the ray's origin.

    The crossing is bracketed on ``t_grid``, then narrowed by ``crossing_steps`` steps of
    regula falsi with the Illinois modification (the value at an end kept twice in a row
    is halved, so both ends converge, superlinearly: a dozen steps reach the precision
    that bisection needs some fifty for). A step whose secant point is not finite or not
    strictly inside the bracket (e.g. a ``NaN`` value at an invalid pose) bisects instead.
    The bracket stays a bracket, ``gk(lo) >= 0`` (or not a number) and ``gk(hi) < 0``,
    and the start is whichever end has the smaller ``|gk|``.

    Every value comes from ONE call site of ``gk``, in one loop: the origin, then the grid
    point by point, then the narrowing steps (``1 + len(t_grid) + crossing_steps``
    iterations). ``gk`` is the grasp model, and each call site of it is a copy of the
    model in the compiled program: five sites (the origin, the grid, the bracket's lower
    end, the narrowing, a Jacobian) made the start search a fifth of a sweep's program
    and about 1.4 s of its 6-7 s cold start (trace, lowering and XLA; experiments/BENCHMARK.md).
    """
    num_grid = t_grid.shape[0]
    ts = jnp.concatenate([jnp.zeros(1, t_grid.dtype), t_grid])  # the origin, then the grid
    zero = jnp.zeros((), t_grid.dtype)

    def body(i, c):
        lo, hi, g_lo, g_hi, side, crossed, g0, g1 = c
        scanning = i <= num_grid
        secant = hi - g_hi * (hi - lo) / (g_hi - g_lo)
        inside = jnp.isfinite(secant) & (secant > lo) & (secant < hi)
        t = jnp.where(scanning, ts[jnp.minimum(i, num_grid)], jnp.where(inside, secant, 0.5 * (lo + hi)))
        g_t = gk(z0 + t * v)
        neg = g_t < 0.0  # NaN (invalid pose) never counts as a crossing
        # scanning: the bracket's lower end follows the grid up to the first crossing
        # (the origin's value included), its upper end is that crossing
        first = scanning & (i > 0) & ~crossed & neg
        scan_lo = scanning & ~crossed & ~first
        # narrowing, Illinois: the end that stays for the second time in a row has its
        # value halved
        narrowing = ~scanning
        n_lo = jnp.where(neg, jnp.where(side < 0, 0.5 * g_lo, g_lo), g_t)
        n_hi = jnp.where(neg, g_t, jnp.where(side > 0, 0.5 * g_hi, g_hi))
        lo = jnp.where(scan_lo | (narrowing & ~neg), t, lo)
        g_lo = jnp.where(scan_lo, g_t, jnp.where(narrowing, n_lo, g_lo))
        hi = jnp.where(first | (narrowing & neg), t, hi)
        g_hi = jnp.where(first, g_t, jnp.where(narrowing, n_hi, g_hi))
        side = jnp.where(narrowing, jnp.where(neg, -1, 1), side)
        g0 = jnp.where(i == 0, g_t, g0)
        g1 = jnp.where(i == 1, g_t, g1)
        # no crossing on the grid: the first grid interval, as a bracket that is none
        last = ~crossed & ~first & (i == num_grid)
        lo, g_lo = jnp.where(last, 0.0, lo), jnp.where(last, g0, g_lo)
        hi, g_hi = jnp.where(last, t_grid[0], hi), jnp.where(last, g1, g_hi)
        return lo, hi, g_lo, g_hi, side, crossed | first, g0, g1

    init = (zero, t_grid[0], zero, zero, jnp.asarray(0), jnp.asarray(False), zero, zero)
    lo, hi, g_lo, g_hi, _, found, g0, _ = jax.lax.fori_loop(0, 1 + num_grid + crossing_steps, body, init)
    # a secant step can land on the crossing itself (to rounding, on the feasible side):
    # the bracket's other end then closes only by bisection, so the end nearer the
    # boundary is the start
    t = jnp.where(jnp.abs(g_lo) < jnp.abs(g_hi), lo, hi)  # NaN compares false: hi
    return z0 + t * v, found, g0


def _lane_equalities(n: int, num_starts: int):
    """``(2N * D,)`` the equality row of each boundary lane in the ``(3N,)`` constraints:
    lane ``b * D + s`` (start ``s`` of boundary ``b``) has row ``N + b`` (slip rows, then
    force rows)."""
    return jnp.repeat(n + jnp.arange(2 * n), num_starts)


FRAME_TIE = 1e-6
""":func:`start_frame` takes eigenvalues of the grasp's stiffness closer than this (relative
to the largest) as one eigenspace, and a reference sum that cancels to within this of its
terms' lengths as none."""
_FRAME_SPAN = 0.3  # a reference vector joins an eigenspace's basis if its residual is longer
FRAME_BITS = 20
""":func:`start_frame`'s entries are multiples of ``2^-FRAME_BITS`` (about 1e-6)."""


def start_frame(data: ProgramData):
    """``(6, 6)`` orthonormal columns: the frame of the start directions in the scaled pose
    space ``z`` of the grasp ``data``.

    The columns are the eigenvectors of the grasp's stiffness in its initial state, each
    fingertip a spring at its contact point: ``sum_i k_i (A_i^T A_i + a_i b_i b_i^T)`` with
    ``k_i = E_i dr_i`` (the elastic energy's second derivative in the normal and in the
    tangential displacement are both ``2 pi E d``), ``A_i`` the ``(3, 6)`` map from ``z`` to
    the displacement ``dp + w x c_i`` of contact ``i``, ``b_i`` the twist ``n_i . w``
    about its normal and ``a_i = dr_i (r_i - dr_i / 3)`` the torsion's share; inactive
    contacts have none. These are the object's modes of motion in the grasp, softest
    first, from the grasp's fields alone: no derivative of the model is traced (the
    energy's own Hessian at the equilibrium served as well and made the one-grasp program
    21 % longer). Their signs, and the basis of an eigenspace of equal eigenvalues (within
    :data:`FRAME_TIE`, as in every symmetric grasp), come from reference vectors projected
    onto the eigenspace and orthonormalised in order: first the weight ``(m g, 0)``, the
    sum of the fingertips' normal wrenches ``k_i (n_i, c_i x n_i)`` and of their
    positions ``k_i (c_i, 0)`` (unit length; kept where their residual is longer than
    :data:`FRAME_TIE`, and left out where a sum cancels to within :data:`FRAME_TIE` of its
    terms' lengths, as by symmetry), then the coordinate axes, kept where their residual
    is longer than 0.3 (which completes every basis: six unit vectors whose residuals
    were all at most 0.3 cannot leave an eigenspace dimension uncovered).

    Rotating or mirroring the world frame maps the pose space by an orthogonal ``T``
    (``dp -> R dp``, ``w -> det(R) R w``), the stiffness to ``T K T^T`` and each reference
    vector to ``T`` times it (``c x n`` and ``w`` are both axial); renumbering the
    contacts changes none of them. So the frame turns with the grasp, and start
    directions written in it (:meth:`EvaluateOptions.directions`) are the same physical
    motions in any world frame and numbering, wherever the references fix the signs and
    the eigenspaces are single. Coordinate axes were not: a mirror image of a 5-finger
    grasp missed its slip boundary's lowest point from every one of the 20 starts
    (``tests/test_degenerate.py``, ``sphere_5_mirrored``). A tie or a sign the references
    leave open is settled by the coordinate axes, away from any threshold, so that
    rounding (e.g. a grasp padded with inactive contacts) does not turn the frame.
    """
    p = data.params
    dtype = p.c.dtype
    lever = data.lever
    k = jnp.where(p.on, p.E * p.dr, 0.0)  # (N,) stiffness of each fingertip (normal = tangential), / 2 pi
    eye = jnp.broadcast_to(jnp.eye(3, dtype=dtype), p.c.shape + (3,))
    cross = jnp.cross(p.c[:, None, :], eye)  # (N, 3, 3): cross @ v = v x c
    a = jnp.concatenate([eye, cross / lever], axis=2)  # (N, 3, 6): z -> displacement w x c + dp of the contact
    b = jnp.concatenate([jnp.zeros_like(p.n), p.n / lever], axis=1)  # (N, 6): z -> twist n . w about the normal
    arm = p.dr * (p.r - p.dr / 3.0)  # mm^2: torsion stiffness / k
    hmat = jnp.einsum("n,nia,nib->ab", k, a, a) + jnp.einsum("n,na,nb->ab", k * arm, b, b)
    evals, vecs = serial_eigh(hmat / jnp.max(jnp.abs(hmat)))  # one LAPACK call per grasp: jaxgrasp.dense
    wrench = jnp.concatenate([p.n, jnp.cross(p.c, p.n) / lever], axis=1)  # (N, 6)
    place = jnp.concatenate([p.c / lever, jnp.zeros_like(p.c)], axis=1)  # (N, 6)
    rows = jnp.stack([k[:, None] * wrench, k[:, None] * place])  # (2, N, 6); inactive: k = 0
    weight = jnp.concatenate([p.weight, jnp.zeros(3, dtype)])
    sums = jnp.concatenate([weight[None], jnp.sum(rows, axis=1)])  # (3, 6)
    norms = jnp.linalg.norm(sums, axis=1, keepdims=True)
    lengths = jnp.concatenate([jnp.linalg.norm(weight)[None], jnp.sum(jnp.linalg.norm(rows, axis=2), axis=1)])
    # a sum that cancels (a symmetric grasp) is rounding noise: no reference
    kept = norms > FRAME_TIE * lengths[:, None]
    refs = jnp.concatenate([jnp.where(kept, sums / jnp.where(kept, norms, 1.0), 0.0), jnp.eye(6, dtype=dtype)])
    # eigenspaces: runs of eigenvalues (ascending) with gaps within FRAME_TIE
    tie = jnp.diff(evals) <= FRAME_TIE * jnp.max(jnp.abs(evals))
    label = jnp.cumsum(jnp.concatenate([jnp.zeros(1, jnp.int32), (~tie).astype(jnp.int32)]))
    same = label[:, None] == label[None, :]  # (6, 6): column j in column i's eigenspace
    rank = jnp.sum(same & (jnp.arange(6)[None, :] < jnp.arange(6)[:, None]), axis=1)  # i's place in it
    proj = jnp.einsum("ak,ik,bk->iab", vecs, same.astype(dtype), vecs)  # (6, 6, 6) projectors

    # a reference sum counts wherever it is not rounding; an axis where it is long
    spans = jnp.asarray([FRAME_TIE] * 3 + [_FRAME_SPAN] * 6, dtype)

    def orthonormalise(carry, ref_span):  # Gram-Schmidt in every column's eigenspace at once
        basis, count = carry  # (6, 6, 6): [column, slot, :]; (6,) slots filled
        ref, span = ref_span
        r = proj @ ref
        r = r - jnp.einsum("isa,is->ia", basis, jnp.einsum("isa,ia->is", basis, r))
        length = jnp.linalg.norm(r, axis=1)
        keep = length > span
        unit = r / jnp.where(keep, length, 1.0)[:, None]
        basis = basis + (jax.nn.one_hot(count, 6, dtype=dtype) * keep[:, None])[:, :, None] * unit[:, None, :]
        return (basis, count + keep), None

    init = (jnp.zeros((6, 6, 6), dtype), jnp.zeros(6, jnp.int32))
    (basis, _), _ = jax.lax.scan(orthonormalise, init, (refs, spans))
    # snapped to a grid of 2^-FRAME_BITS: a rounding-level change of the stiffness (the same
    # grasp padded with inactive contacts) then leaves the starts bit-identical
    return jnp.round(basis[jnp.arange(6), rank].T * 2.0**FRAME_BITS) / 2.0**FRAME_BITS


def _lane_rays(data: ProgramData, options: EvaluateOptions):
    """The ray of every boundary lane of the grasp ``data``: ``(k, v, t_grid)``, leading
    axis ``2N * D``: ``k`` the lane's equality row in the ``(3N,)`` constraints (slip rows,
    then force rows), ``v`` ``(6,)`` its direction (:meth:`EvaluateOptions.directions`
    in the :func:`start_frame`), ``t_grid`` ``(ray_points,)`` mm, the points the ray
    brackets its crossing on."""
    n = data.params.c.shape[0]
    dtype = data.params.c.dtype
    dirs = jnp.asarray(options.directions(), dtype) @ start_frame(data).T
    num_dirs = dirs.shape[0]
    # A ray walks until its translation reaches ray_length radii or its rotation reaches
    # ray_length rad, whichever is farther: torsion slip needs a rotation angle that does
    # not shrink with the lever arm (contacts far from the centre of mass).
    rot = jnp.linalg.norm(dirs[:, 3:], axis=1)
    r_max = jnp.max(jnp.where(data.params.on, data.params.r, 0.0))
    t_max = options.ray_length * jnp.maximum(r_max, data.lever * rot)  # (D,) mm
    unit_grid = 2.0 ** (-(options.ray_points - 1 - jnp.arange(options.ray_points, dtype=dtype)) / 4.0)
    return _lane_equalities(n, num_dirs), jnp.tile(dirs, (2 * n, 1)), jnp.tile(t_max[:, None] * unit_grid, (2 * n, 1))


def _contact_data(data: ProgramData, j) -> ProgramData:
    """``data`` with contact ``j`` (a traced index) its only contact: every per-contact
    field of its parameters sliced to ``j``, keeping that axis (length 1). The
    constraints of contact ``j`` are each a function of that contact's kinematics
    alone, so ``constraints(z, _contact_data(data, j))`` is rows ``j, N + j, 2N + j`` of
    ``constraints(z, data)``, to rounding (tested)."""
    p = data.params
    keep = lambda a: jax.lax.dynamic_slice_in_dim(a, j, 1, axis=0)
    per_contact = {f.name: keep(getattr(p, f.name)) for f in dataclasses.fields(p) if f.name != "weight"}
    return dataclasses.replace(data, params=dataclasses.replace(p, **per_contact))


def _ray_lane(data: ProgramData, z_eq, k, v, t_grid, options: EvaluateOptions):
    """Start of one boundary lane (its grasp ``data``, ray ``k, v, t_grid`` from
    :func:`_lane_rays`): ``(z0, found, nu0, g_eq)``: ``z0`` the crossing of constraint
    ``k`` along ``v`` from ``z_eq`` (``z_eq`` itself where the equilibrium is already on
    it), ``nu0`` ``NaN``: the solver starts the equality multiplier at its least-squares
    estimate there (:func:`~jaxgrasp.solver.init`, from its first step's derivatives, so
    that no other copy of them is compiled); ``g_eq`` constraint ``k``'s margin at
    ``z_eq``.

    Row ``k = row * N + j`` of the constraints is contact ``j``'s alone, so the ray
    evaluates that contact's kinematics only (:func:`_contact_data`): of a 7-contact
    grasp, one seventh of the model in each of its steps."""
    n = data.params.c.shape[0]
    one = _contact_data(data, k % n)
    z0, found, g_eq = _ray_start(lambda z: constraints(z, one)[k // n], z_eq, v, t_grid, options.crossing_steps)
    on_boundary = g_eq <= 0.0
    z0 = jnp.where(on_boundary, z_eq, z0)
    return z0, found | on_boundary, jnp.asarray(jnp.nan, z_eq.dtype), g_eq


def _equilibrium_lanes(data: ProgramData, num_lanes: int):
    """The lanes of the equilibrium problem: ``(z0, eq_mask, nu0, active)`` with leading
    axis ``num_lanes``; lane 0 starts from the initial grasping state with no equality,
    the others are inactive. A grasp with no active contact (the batch engine's stand-in
    for an invalid grasp, or padding) has no equilibrium lane either: its energy would be
    the weight's alone, unbounded below, and the lane would run the whole step budget
    while the rest of its batch waits."""
    n = data.params.c.shape[0]
    dtype = data.params.c.dtype
    z0 = jnp.zeros((num_lanes, 6), dtype)
    masks = jnp.zeros((num_lanes, 3 * n), dtype)
    nu0 = jnp.zeros(num_lanes, dtype)
    return z0, masks, nu0, (jnp.arange(num_lanes) == 0) & jnp.any(data.params.on)


def programs_of(p: ModelParams, options: EvaluateOptions, settle: bool = True) -> Programs:
    """Solve every program of the grasp ``p`` (traceable; the solver sees no derivative):
    :func:`programs_of_batch` of a batch of one."""
    one = jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], p)
    return jax.tree_util.tree_map(lambda a: a[0], programs_of_batch(one, options, settle))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class LaneStarts:
    """What the solver's lanes of one stage start from (leading axes ``(B, L)``: grasps,
    then each grasp's ``L = 2N * D`` lanes).

    Attributes:
        x0: ``(B, L, 6)`` starting points (scaled pose ``z``).
        eq_mask: ``(B, L, 3N)`` one-hot equality row of each lane (zeros: no equality).
        nu0: ``(B, L)`` initial equality multipliers (``NaN``: the solver's estimate).
        active: ``(B, L)`` bool, the lanes to solve.
        at_eq: ``(B, L)`` bool, boundary lanes whose problem the equilibrium already
            solves (:func:`_at_equilibrium`; not ``active``).
        g_eq: ``(B, L)`` each lane's equality margin at the equilibrium.
    """

    x0: Any
    eq_mask: Any
    nu0: Any
    active: Any
    at_eq: Any
    g_eq: Any


def batch_data(p: ModelParams) -> ProgramData:
    """:func:`program_data` of a batch of grasps ``p`` (leading axis ``B``), with no
    gradient: the solver sees none."""
    return jax.vmap(program_data)(jax.lax.stop_gradient(p))


def _num_lanes(data: ProgramData, options: EvaluateOptions) -> int:
    return 2 * data.params.c.shape[-2] * options.num_starts


def equilibrium_starts(data: ProgramData, options: EvaluateOptions) -> LaneStarts:
    """Stage 1 of :func:`programs_of_batch`: the lanes of the equilibrium problem of a
    batch ``data`` (:func:`_equilibrium_lanes`: lane 0 of each grasp from its initial
    grasping state, the others inactive)."""
    num_lanes = _num_lanes(data, options)
    z0, masks, nu0, active = jax.vmap(lambda d: _equilibrium_lanes(d, num_lanes))(data)
    no = jnp.zeros(active.shape, bool)
    return LaneStarts(z0, masks, nu0, active, no, jnp.zeros(active.shape, z0.dtype))


def equilibrium_of(lanes: SolverResult) -> SolverResult:
    """Each grasp's equilibrium (leading axis ``B``) from the lanes of the equilibrium
    stage (leading axes ``(B, L)``): lane 0."""
    return jax.tree_util.tree_map(lambda a: a[:, 0], lanes)


def boundary_starts(data: ProgramData, eq: SolverResult, options: EvaluateOptions) -> LaneStarts:
    """Stage 3 of :func:`programs_of_batch`: the lanes of every boundary problem of a
    batch ``data`` from its equilibria ``eq`` (leading axis ``B``): each lane's ray
    (:func:`_lane_rays`) walked to its crossing (:func:`_ray_lane`). Without a converged
    equilibrium there is nothing to start from: every lane is skipped; an inactive
    contact has no boundary problems; an equilibrium on a boundary (to the solver's
    tolerance) is that problem's minimiser: its lanes are ``at_eq``, not solved."""
    n = data.params.c.shape[-2]
    dtype = data.params.c.dtype
    tol = kkt_tol(dtype, options.solver)
    lane_k, lane_v, lane_t = jax.vmap(lambda d: _lane_rays(d, options))(data)  # (B, L, ...)
    b, num_lanes = lane_k.shape
    # one vmap over every lane of every grasp, each with its grasp's data: the ray's loop
    # is then batched once, not for the lanes and again for the grasps
    per_lane = lambda a: jnp.broadcast_to(a[:, None], (b, num_lanes) + a.shape[1:]).reshape((-1,) + a.shape[1:])
    flat = lambda a: a.reshape((-1,) + a.shape[2:])
    z0s, found, nu0s, g_eq = jax.tree_util.tree_map(
        lambda a: a.reshape((b, num_lanes) + a.shape[1:]),
        jax.vmap(lambda d, z, k, v, t: _ray_lane(d, z, k, v, t, options))(
            jax.tree_util.tree_map(per_lane, data), per_lane(eq.x), flat(lane_k), flat(lane_v), flat(lane_t)
        ),
    )
    contact_on = jnp.take_along_axis(data.params.on, (lane_k - n) % n, axis=1)
    found = found & (eq.status == LaneStatus.CONVERGED)[:, None] & contact_on
    at_eq = found & (jnp.abs(g_eq) <= tol)
    return LaneStarts(z0s, jax.nn.one_hot(lane_k, 3 * n, dtype=dtype), nu0s, found & ~at_eq, at_eq, g_eq)


def solve_stage(data: ProgramData, starts: LaneStarts, options: EvaluateOptions) -> SolverResult:
    """Stages 2 and 4 of :func:`programs_of_batch`: the lanes ``starts`` of a batch
    ``data`` solved, every grasp's lanes in one work queue
    (:func:`~jaxgrasp.lanes.solve_lane_batches`); leading axes ``(B, L)``.

    Each lane gets its grasp's data as its theta (not closed over): the queue then runs
    the lanes of all grasps (and, under a caller's vmap, of all batches) together. The
    queue starts the force-limit lanes first: on random grasps they take 46 steps on
    average against 27 for the slip lanes (two thirds of them prove their boundary
    infeasible), so started last they would run on with the other slots idle
    (experiments/BENCHMARK.md). The equilibrium stage has one lane per grasp."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    theta = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a[:, None], (b, num_lanes) + a.shape[1:]), data)
    rank = jnp.where(_lane_equalities(n, options.num_starts) >= 2 * n, 0, 1)
    return solve_lane_batches(lane_problem, theta, starts.x0, starts.eq_mask, starts.nu0, starts.active,
                              options.solver, rank=rank)


def finish_programs(data: ProgramData, eq: SolverResult, lanes: SolverResult, starts: LaneStarts,
                    options: EvaluateOptions, settle: bool = True) -> Programs:
    """Stage 5 of :func:`programs_of_batch`: the :class:`Programs` of a batch ``data``
    from its equilibria ``eq`` (leading axis ``B``), its boundary lanes ``lanes`` as
    solved from ``starts`` (leading axes ``(B, L)``): lanes ``at_eq`` get the
    equilibrium's solution (:func:`_at_equilibrium`), and with ``settle`` (static)
    :func:`settle_stalled` certifies stalled ones."""
    b, n = data.params.c.shape[:2]
    num_lanes = _num_lanes(data, options)
    lane_k = _lane_equalities(n, options.num_starts)
    lanes = jax.vmap(lambda *a: _at_equilibrium(*a, lane_k))(eq, lanes, starts.at_eq, starts.g_eq)
    found = starts.active | starts.at_eq
    if settle:
        lanes = _settle_where_stalled(data, lanes, lane_k, found, options.num_starts, options.solver)
    return Programs(
        equilibrium=eq,
        boundary=lanes,
        start=starts.x0,
        found=found,
        constraint_index=jnp.broadcast_to(lane_k, (b, num_lanes)),
        lever=data.lever,
        scale=data.scale,
        contact_on=data.params.on,
    )


def programs_of_batch(p: ModelParams, options: EvaluateOptions, settle: bool = True) -> Programs:
    """Solve every program of a batch of grasps ``p`` (leading axis ``B`` on every field;
    traceable; the solver sees no derivative). Returns :class:`Programs` with a leading
    ``B``.

    Its stages, each a function of the batch: the equilibrium's lanes
    (:func:`equilibrium_starts`), solved (:func:`solve_stage`); the boundary problems'
    lanes from starts around that equilibrium (:func:`boundary_starts`), solved; the
    :class:`Programs` (:func:`finish_programs`). The batch engine runs them as separate
    compiled programs (:mod:`jaxgrasp.batch_stages`); here they are one program.

    Both solves run through ONE :func:`solve_stage` call site, inside a two-iteration
    loop: iteration 0 solves the equilibrium problem, iteration 1 the boundary problems.
    The solver's loop is then compiled once rather than twice, which halves the program
    the solver contributes; each lane's result is what :func:`~jaxgrasp.solver.solve`
    gives it. Taking the batch itself, rather than being vmapped over grasps, traces the
    queue once: under ``vmap`` it is traced for one grasp and again folded
    (``custom_vmap``), 0.3-0.4 s of a sweep's cold start (experiments/BENCHMARK.md). The
    stage is the loop counter, not batched data, so under a caller's ``vmap`` the
    ``lax.cond`` choosing the lanes stays a branch.

    With ``settle`` (static), :func:`settle_stalled` then certifies stalled boundary
    lanes. Without it the program is smaller and faster, and equal wherever no boundary
    problem ends unsettled (:func:`needs_settling`): the host-level drivers
    (:func:`jaxgrasp.evaluate` of a concrete grasp, the batch engine) run that program
    first and the settling one only on the grasps that need it.
    """
    data = batch_data(p)

    def stage(i, carry):
        eq, _, _ = carry
        starts = jax.lax.cond(
            i == 0,
            lambda eq: equilibrium_starts(data, options),
            lambda eq: boundary_starts(data, eq, options),
            eq,
        )
        res = solve_stage(data, starts, options)
        eq = jax.lax.cond(i == 0, lambda: equilibrium_of(res), lambda: eq)
        return eq, res, starts

    # the carry: each grasp's equilibrium lane, every lane's result (zeros until solved)
    # and the lanes' starts
    starts0 = equilibrium_starts(data, options)
    zero = lambda a, dt=None: jnp.zeros(a.shape, a.dtype if dt is None else dt)
    x0 = starts0.x0
    lanes0 = SolverResult(
        x=zero(x0),
        lam=zero(starts0.eq_mask),
        nu=zero(starts0.nu0),
        objective=zero(starts0.nu0),
        status=zero(starts0.nu0, jnp.int32),
        stationarity=zero(starts0.nu0),
        feasibility=zero(starts0.nu0),
        complementarity=zero(starts0.nu0),
        steps=zero(starts0.nu0, jnp.int32),
    )
    carry0 = (equilibrium_of(lanes0), lanes0, jax.tree_util.tree_map(zero, starts0))
    # The carry's zeros, made to depend on the grasps (jnp.where of a flag computed from
    # every field of their data; the values are the same zeros): under a caller's vmap over
    # grasps, whichever fields it maps, the carry is then batched from the start. Zeros
    # that are not would be batched only after the first stage, and JAX's loop batching
    # would trace the body (the whole solver) once more to find that out: 128 grasps over
    # 2 devices traced in 2.6 s instead of 4.0-4.5 s, with the same results
    # (experiments/BENCHMARK.md).
    dtype = data.params.c.dtype
    per_grasp = jnp.isnan(sum(jnp.sum(jnp.asarray(a, dtype)) for a in jax.tree_util.tree_leaves(data)))
    carry0 = jax.tree_util.tree_map(lambda a: jnp.where(per_grasp, a, a), carry0)
    eq, lanes, starts = jax.lax.fori_loop(0, 2, stage, carry0)
    return finish_programs(data, eq, lanes, starts, options, settle)


def _at_equilibrium(eq: SolverResult, lanes: SolverResult, at_eq, g_eq, lane_k) -> SolverResult:
    """The boundary lanes ``at_eq`` ``(L,)`` (leading axis ``L`` of ``lanes``; ``lane_k``
    their equality rows, ``g_eq`` that row's margin at the equilibrium) given the
    equilibrium's solution ``eq``: an equilibrium whose
    margin of row ``k`` is within the solver's tolerance of 0 is a KKT point of boundary
    problem ``k`` too, with the same residuals (the equality's multiplier
    ``nu = -lam_k``, row ``k``'s ``lam`` 0), and its minimiser, as no point of the
    boundary lies below the minimum of the region that holds it. Such lanes all start at
    the equilibrium (where a degenerate one, several constraints active at once, could
    stall: a grasp of the long property profile settled such a boundary in one
    orientation and not in another), so they are not solved but given this solution."""
    rows = jnp.arange(lanes.lam.shape[-1])
    is_k = rows[None, :] == lane_k[:, None]  # (L, 3N)
    given = SolverResult(
        x=jnp.broadcast_to(eq.x, lanes.x.shape),
        lam=jnp.where(is_k, 0.0, eq.lam[None, :]),
        nu=-jnp.sum(jnp.where(is_k, eq.lam[None, :], 0.0), axis=1),
        objective=jnp.broadcast_to(eq.objective, lanes.objective.shape),
        status=jnp.full(lanes.status.shape, LaneStatus.CONVERGED, lanes.status.dtype),
        stationarity=jnp.broadcast_to(eq.stationarity, lanes.stationarity.shape),
        feasibility=jnp.maximum(eq.feasibility, jnp.abs(g_eq)),
        complementarity=jnp.broadcast_to(eq.complementarity, lanes.complementarity.shape),
        steps=jnp.zeros(lanes.steps.shape, lanes.steps.dtype),
    )
    return jax.tree_util.tree_map(
        lambda a, b: jnp.where(at_eq.reshape((-1,) + (1,) * (a.ndim - 1)), a.astype(b.dtype), b), given, lanes
    )


# ------------------------------------------------------------- stalled-lane polish
# A boundary lane can stall (status NOT_CONVERGED) where a fingertip j is released:
# d_j = 0, and the slip margin (eq. 9) is then active at the apex of its friction cone,
# where its gradient vanishes (it is quadratic in (d_j, dt_j)). No bounded multiplier
# exists (LICQ and MFCQ fail), the augmented Lagrangian's multiplier of that row grows
# without bound and the KKT residuals stall near 1e-5. The point itself is right; what
# is missing is a certificate. In (d_j, t_j) (t_j: tangential displacement, 2 components)
# contact j's three rows require d_j >= 0 and 2 |t_j| <= mu_j d_j / cos^2 phi_j (minus a
# torsion term), inside the circular cone; the three half-spaces
#     P_k = (mu_j d_j / (2 cos^2 phi_j) + t_j . v_k) / dr_j >= 0,   v_k at 0, 120, 240 deg,
# bound a triangular pyramid circumscribing that cone, whose apex is the cone's and
# whose three rows have independent gradients. Replacing contact j's rows by P_0..P_2
# (and dropping the equality where it is j's own slip row) relaxes the program. A point
# that is feasible for the original program and a KKT point of the relaxation (bounded
# multipliers, residuals <= tol) is a KKT point of a program whose feasible set contains
# the original's: whatever certifies it as a minimiser of the relaxation certifies it for
# the original, at the same energy. The polish is a few Newton steps on the relaxation's
# KKT equations with the active set fixed at the stalled point.

_PYRAMID = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)  # face angles, rad
RELEASED_TOL = 1e-6
"""A stalled lane's contact ``j`` is released where its contact and slip margins are
both within this (scaled margins), and the lane's violation too."""
_POLISH_STEPS = 8
MAX_POLISHED = 2
"""Most boundary problems of one grasp that :func:`settle_stalled` polishes."""
SETTLE_BLOCK = 4
"""Grasps per block of the settling stage in a batch (:func:`_settle_where_stalled`)."""


def _tangential(z, data: ProgramData, j):
    """``(3,)`` mm, the displacement of contact ``j`` at scaled pose ``z`` (eq. 11), and
    its normal ``n_j``."""
    x = to_pose(z, data.lever)
    u = (rotation_matrix(x[3:]) - jnp.eye(3, dtype=z.dtype)) @ data.params.c[j] + x[:3]
    return u, data.params.n[j]


def _pyramid_basis(z0, data: ProgramData, j):
    """``(3, 3)`` the pyramid's face directions ``v_k`` for contact ``j``, with ``v_0``
    against the tangential displacement at the stalled point ``z0``: the objective pushes
    the stalled iterate out of the cone there, and a pyramid with a face across that push
    certifies the apex exactly where the circular cone does (the tangential reaction
    ``sum_k lam_k v_k`` may then reach the cone's bound ``2 / (mu / cos^2 phi)`` of the
    normal one). Falls back to a fixed basis where that displacement vanishes."""
    u, n = _tangential(z0, data, j)
    t = u - jnp.dot(n, u) * n
    tn = jnp.linalg.norm(t)
    a = jax.nn.one_hot(jnp.argmin(jnp.abs(n)), 3, dtype=z0.dtype)
    fixed = jnp.cross(n, a)
    e1 = jnp.where(tn > 1e-14, -t / jnp.where(tn > 1e-14, tn, 1.0), fixed / jnp.linalg.norm(fixed))
    e2 = jnp.cross(n, e1)
    angles = jnp.asarray(_PYRAMID, z0.dtype)
    return jnp.cos(angles)[:, None] * e1 + jnp.sin(angles)[:, None] * e2


def _relaxed_program(z, data: ProgramData, j, v, relaxed_rows):
    """``(f, g)`` of the program at scaled pose ``z`` with contact ``j``'s rows replaced,
    where ``relaxed_rows`` ``(3N,)``, by its pyramid rows ``P_k = (mu_j d_j / (2 cos^2
    phi_j) + v_k . u_j) / dr_j`` (``v``: the ``(3, 3)`` face directions; row ``k * N + j``
    holds ``P_k``). One evaluation of the contact kinematics serves every row, so that
    the polish's derivatives are taken once."""
    p = data.params
    n = p.c.shape[0]
    x = to_pose(z, data.lever)
    kinematics = contact_kinematics(x, p)
    f = energy_of(x, kinematics, p) / data.scale
    g = margins_of(kinematics, p).reshape(-1)
    d, cphi = kinematics[0][j], kinematics[1][j]
    u, _ = _tangential(z, data, j)
    pyramid = (p.mu[j] * d / (2.0 * cphi**2) + v @ u) / jax.lax.stop_gradient(p.dr[j])
    return f, jnp.where(relaxed_rows, pyramid[jnp.arange(3 * n) // n], g)


def _polish(data: ProgramData, z0, k, j, released, o: SolverOptions):
    """Newton's method on the KKT equations of boundary program ``k`` (equality row), with
    the active set fixed at the stalled point ``z0``: on the relaxation at contact ``j``
    where ``released``, else on the program itself.

    Returns ``(z, lam_rel, ok, (stat, feas, comp))``: ``lam_rel`` ``(3N,)`` multipliers
    of the (relaxed) program (the equality's included, free in sign); ``ok`` whether ``z``
    is a KKT point of it within tol and feasible for the original program."""
    n = data.params.c.shape[0]
    dtype = z0.dtype
    tol = kkt_tol(dtype, o)
    rows = jnp.arange(3 * n)
    j_rows = (rows % n == j) & released
    has_eq = ~released | (k != n + j)  # j's own slip equality is relaxed away
    is_eq = (rows == k) & has_eq
    v = _pyramid_basis(z0, data, j)
    fg = lambda z: _relaxed_program(z, data, j, v, j_rows)
    active = j_rows | is_eq | (constraints(z0, data) <= RELEASED_TOL)

    def residual(y):  # the KKT equations, and the constraints for the statistics
        z, lam = y[:6], y[6:]
        grad_l = jax.grad(lambda z: (lambda a: a[0] - jnp.dot(lam, a[1]))(fg(z)))(z)
        gz = fg(z)[1]
        r = jnp.concatenate([grad_l, jnp.where(active, gz, lam)])
        return r, (r, gz)

    def newton(i, carry):
        # _POLISH_STEPS Newton steps, then one more pass for the residual at the last point
        y, _, _ = carry
        jac, (r, gz) = jax.jacfwd(residual, has_aux=True)(y)
        step = jnp.where(i < _POLISH_STEPS, dense_solve(jac, r), 0.0)  # no LAPACK: see jaxgrasp.dense
        return y - step, r, gz

    y0 = jnp.concatenate([z0, jnp.zeros(3 * n, dtype)])
    y, r, gz = jax.lax.fori_loop(
        0, _POLISH_STEPS + 1, newton, (y0, jnp.zeros(6 + 3 * n, dtype), jnp.zeros(3 * n, dtype))
    )
    z, lam = y[:6], y[6:]
    stat = jnp.max(jnp.abs(r[:6]))
    feas = jnp.max(jnp.where(is_eq, jnp.abs(gz), jnp.maximum(-gz, 0.0)))
    comp = jnp.max(jnp.where(is_eq, 0.0, jnp.abs(lam * gz)))
    # With torsion (theta_j != 0) the slip margin is d_j (mu_j^2 d_j / cos^4 phi_j - K theta_j^2)
    # - 4 dt_j^2 with K = (225/32) r_j / mu_j^2 at d_j = 0: negative for 0 < d_j < gap below,
    # so near the apex contact j's rows hold exactly where d_j = 0 and t_j = 0, the pyramid
    # rows' common zero: their multipliers are then free in sign.
    p = data.params
    _, cphi, _, theta = contact_kinematics(to_pose(z, data.lever), p)
    gap = (225.0 / 32.0) * p.r[j] * theta[j] ** 2 * cphi[j] ** 4 / p.mu[j] ** 4
    free = is_eq | (j_rows & (gap >= RELEASED_TOL * p.dr[j]))
    dual = jnp.all(free | (lam >= -tol))  # rows held at lam = 0 end at +-1e-30
    lam = jnp.where(free, lam, jnp.maximum(lam, 0.0))
    g_orig = constraints(z, data)
    orig_feas = jnp.max(jnp.where(rows == k, jnp.abs(g_orig), jnp.maximum(-g_orig, 0.0)))
    ok = (stat <= tol) & (feas <= tol) & (comp <= tol) & dual & (orig_feas <= tol) & jnp.all(jnp.isfinite(y))
    return z, lam, ok, (stat, jnp.maximum(feas, orig_feas), comp)


def _polish_candidates(lanes: SolverResult, found, num_starts: int):
    """``(2N, D)`` bool: the lanes :func:`settle_stalled` may polish, those that stalled
    (``NOT_CONVERGED``) at a point feasible within :data:`RELEASED_TOL`, of problems
    that no start settled (a settled problem keeps its answer: a stalled lane of one can
    sit far from the converged ones, e.g. at a large rotation)."""
    stalled = found & (lanes.status == LaneStatus.NOT_CONVERGED) & (lanes.feasibility <= RELEASED_TOL)
    converged = (found & (lanes.status == LaneStatus.CONVERGED)).reshape(-1, num_starts)
    return stalled.reshape(-1, num_starts) & ~jnp.any(converged, axis=1, keepdims=True)


def _settle_where_stalled(data: ProgramData, lanes: SolverResult, lane_k, found, num_starts: int,
                          o: SolverOptions) -> SolverResult:
    """:func:`settle_stalled` of each grasp of a batch (leading axis ``B`` on ``data``,
    ``lanes`` and ``found``) that has a lane to polish, in gathered blocks of
    :data:`SETTLE_BLOCK` grasps (:func:`jaxgrasp.gathered.over_rows`); every other
    grasp's lanes are returned as they are, which is what :func:`settle_stalled` returns
    for them. Under ``vmap`` the stage would cost every grasp its polish; stalls are rare
    (some 5 % of random grasps have one, and grids hardly any), so a batch pays for the
    few that need it (experiments/BENCHMARK.md)."""
    need = jax.vmap(lambda l, f: jnp.any(_polish_candidates(l, f, num_starts)))(lanes, found)

    def update(rows, valid, lanes):
        pick = lambda t: jax.tree_util.tree_map(lambda a: a[rows], t)
        settled = jax.vmap(lambda d, l, f: settle_stalled(d, l, lane_k, f, num_starts, o))(
            pick(data), pick(lanes), found[rows]
        )
        return jax.tree_util.tree_map(lambda a, s: put_rows(a, rows, valid, s), lanes, settled)

    return over_rows(need, SETTLE_BLOCK, update, lanes)


def settle_stalled(data: ProgramData, lanes: SolverResult, lane_k, found, num_starts: int, o: SolverOptions):
    """Certify boundary lanes that stalled at a feasible point (a post-solve stage).

    For each boundary problem that no start settled (at most :data:`MAX_POLISHED` per grasp), the lowest-energy lane that ended
    ``NOT_CONVERGED`` with its violation within :data:`RELEASED_TOL` is polished by
    Newton's method on the KKT equations, its active set (margins within :data:`RELEASED_TOL`, and the equality)
    fixed: on the relaxation above where some contact ``j`` is released (contact and
    slip margins within :data:`RELEASED_TOL`; ``j``'s force row not the equality), else
    on the program itself (bounded multipliers, but an inner solve that stalled, e.g. at
    the largest penalty). Where that gives a KKT point within ``tol`` (inequality
    multipliers ``>= 0``) that is feasible for the original program, the lane becomes
    ``CONVERGED`` there, with the polish's KKT residuals. A relaxation's multipliers are
    mapped back: ``lam`` of ``j``'s contact row carries the pyramid rows' ``d_j`` part
    (clipped at 0; the tangential part has no row of the original program, so the
    envelope derivative of such a boundary misses it), ``nu`` the equality's. Every other
    lane is returned unchanged; a lane that converged is never touched.

    Args:
        data: the grasp's :class:`ProgramData`.
        lanes: the boundary lanes, leading axis ``2N * D``.
        lane_k: ``(2N * D,)`` equality row of each lane.
        found: ``(2N * D,)`` the lanes that were started.
        num_starts: ``D``.
        o: the :class:`~jaxgrasp.solver.SolverOptions` the lanes were solved with.
    """
    n = data.params.c.shape[0]
    g = jax.vmap(lambda z: constraints(z, data))(lanes.x).reshape(-1, 3, n)  # (L, 3, N)
    released = (g[:, 0] <= RELEASED_TOL) & (g[:, 1] <= RELEASED_TOL) & data.params.on  # (L, N)
    released = released & (lane_k[:, None] != 2 * n + jnp.arange(n))
    j = jnp.argmax(released, axis=1)
    released_any = jnp.any(released, axis=1)
    candidate = _polish_candidates(lanes, found, num_starts)  # (2N, D)
    pick = jnp.argmin(jnp.where(candidate, lanes.objective.reshape(-1, num_starts), jnp.inf), axis=1)
    pick = jnp.arange(2 * n) * num_starts + pick  # (2N,) one lane per boundary problem
    # Polish at most MAX_POLISHED problems per grasp, those with a candidate first: under
    # vmap every grasp polishes as many as the one that needs most, and stalls are rare
    # (42 of 8000 programs in the robustness set), so polishing all 2N would cost every
    # grasp ~15% more for nothing.
    has_candidate = jnp.any(candidate, axis=1)
    chosen = jnp.argsort(~has_candidate, stable=True)[: min(MAX_POLISHED, 2 * n)]
    pick = pick[chosen]
    z, lam_rel, ok, (stat, feas, comp) = jax.vmap(
        lambda l: _polish(data, lanes.x[l], lane_k[l], j[l], released_any[l], o)
    )(pick)
    ok = ok & has_candidate[chosen]
    # the relaxation's multipliers in the original rows: the equality's as nu, the pyramid
    # rows' d_j part on j's contact row (d P_k / d d_j = mu_j / (2 cos^2 phi_j) per dr_j)
    jp = j[pick]
    rows = jnp.arange(3 * n)
    is_eq = rows[None, :] == lane_k[pick][:, None]
    j_rows = (rows[None, :] % n == jp[:, None]) & released_any[pick][:, None]
    cphi = jax.vmap(lambda z: contact_kinematics(to_pose(z, data.lever), data.params)[1])(z)  # (2N, N)
    slope = data.params.mu[jp] / (2.0 * jnp.take_along_axis(cphi, jp[:, None], axis=1)[:, 0] ** 2)
    lam_d = jnp.maximum(slope * jnp.sum(jnp.where(j_rows, lam_rel, 0.0), axis=1), 0.0)
    lam = jnp.where(is_eq | j_rows, 0.0, lam_rel) + jnp.where(
        released_any[pick][:, None], jax.nn.one_hot(jp, 3 * n, dtype=lam_rel.dtype) * lam_d[:, None], 0.0
    )
    nu = -jnp.sum(jnp.where(is_eq, lam_rel, 0.0), axis=1)
    new = SolverResult(
        x=z,
        lam=lam,
        nu=nu,
        objective=jax.vmap(lambda z: objective(z, data))(z),
        status=jnp.full(pick.shape, LaneStatus.CONVERGED, jnp.int32),
        stationarity=stat,
        feasibility=feas,
        complementarity=comp,
        steps=lanes.steps[pick] + _POLISH_STEPS,
    )
    old = jax.tree_util.tree_map(lambda a: a[pick], lanes)
    upd = jax.tree_util.tree_map(
        lambda a, b: jnp.where(ok.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), new, old
    )
    return jax.tree_util.tree_map(lambda a, u: a.at[pick].set(u.astype(a.dtype)), lanes, upd)


@partial(jax.jit, static_argnames=("options", "settle"))
def solve_programs(grasp: Grasp, options: EvaluateOptions = EvaluateOptions(), settle: bool = True) -> Programs:
    """Solve every program of ``grasp`` and return them lane by lane (for diagnostics and
    benchmarks; :func:`jaxgrasp.evaluate` is this plus the reduction to one value);
    ``settle`` as in :func:`programs_of`."""
    return programs_of(model_params(grasp), options, settle)


def needs_settling(boundary_status) -> np.ndarray:
    """``(...)`` bool: whether an evaluation with this ``boundary_status`` ``(..., 2, N)``
    (an :class:`~jaxgrasp.Evaluation` field, host-side) has a boundary problem that no
    start settled, the only case in which :func:`settle_stalled` can change anything."""
    return np.any(np.asarray(boundary_status) == LaneStatus.NOT_CONVERGED, axis=(-2, -1))
