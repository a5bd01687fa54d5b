"""Starting points of the problems: the equilibrium's lanes and the boundary rays around it."""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp

from jaxgrasp.solver import LaneStatus, SolverResult, kkt_tol, serial_eigh
from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._problems import (
    ProblemData,
    _lane_equalities,
    _num_lanes,
    constraints,
)

__all__ = [
    "LaneStarts",
    "equilibrium_starts",
    "equilibrium_of",
    "boundary_starts",
    "start_frame",
    "FRAME_TIE",
    "FRAME_BITS",
]


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
    model in the compiled executable, to be traced, lowered and compiled: one site instead
    of five (the origin, the grid, the bracket's lower end, the narrowing, a Jacobian).
    """
    num_grid = t_grid.shape[0]
    ts = jnp.concatenate([jnp.zeros(1, t_grid.dtype), t_grid])  # the origin, then the grid
    zero = jnp.zeros((), t_grid.dtype)
    body = partial(_ray_step, gk, z0, v, t_grid, ts)
    init = (zero, t_grid[0], zero, zero, jnp.asarray(0), jnp.asarray(False), zero, zero)
    lo, hi, g_lo, g_hi, _, found, g0, _ = jax.lax.fori_loop(0, 1 + num_grid + crossing_steps, body, init)
    # a secant step can land on the crossing itself (to rounding, on the feasible side):
    # the bracket's other end then closes only by bisection, so the end nearer the
    # boundary is the start
    t = jnp.where(jnp.abs(g_lo) < jnp.abs(g_hi), lo, hi)  # NaN compares false: hi
    return z0 + t * v, found, g0


def _ray_step(gk, z0, v, t_grid, ts, i, c):
    """Iteration ``i`` of `_ray_start`'s loop: ``gk`` at ``ts[i]`` (the origin, then
    the grid) while ``i <= len(t_grid)``, else at the next regula falsi point. The carry
    ``c`` is ``(lo, hi, g_lo, g_hi, side, crossed, g0, g1)``: the bracket ``[lo, hi]``
    along the ray and ``gk``'s (Illinois-halved) values at its ends, the end that moved
    last (``-1`` hi, ``1`` lo), whether the grid has crossed, and ``gk`` at the origin and
    at the first grid point."""
    num_grid = t_grid.shape[0]
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

FRAME_TIE = 1e-6
"""`start_frame` takes eigenvalues of the grasp's stiffness closer than this (relative
to the largest) as one eigenspace, and a reference sum that cancels to within this of its
terms' lengths as none."""

_FRAME_SPAN = 0.3  # a reference vector joins an eigenspace's basis if its residual is longer

FRAME_BITS = 20
"""`start_frame`'s entries are multiples of ``2^-FRAME_BITS`` (about 1e-6)."""


def start_frame(data: ProblemData):
    """``(6, 6)`` orthonormal columns: the frame of the start directions in the scaled pose
    space ``z`` of the grasp ``data``.

    The columns are the eigenvectors of the grasp's stiffness in its initial state
    (`_stiffness`): the object's modes of motion in the grasp, softest first, from
    the grasp's fields alone, so that no derivative of the model is traced (the energy's
    own Hessian at the equilibrium served as well, at the price of the model's second
    derivative in the executable). Their signs, and the basis of an eigenspace of equal
    eigenvalues (within `FRAME_TIE`, as in every symmetric grasp), come from
    reference vectors (`_frame_references`) projected onto the eigenspace and
    orthonormalised in order (`_eigenspace_bases`).

    Rotating or mirroring the world frame maps the pose space by an orthogonal ``T``
    (``dp -> R dp``, ``w -> det(R) R w``), the stiffness to ``T K T^T`` and each reference
    vector to ``T`` times it (``c x n`` and ``w`` are both axial); renumbering the
    contacts changes none of them. So the frame turns with the grasp, and start
    directions written in it ([`EvaluateOptions.directions`][jaxgrasp.EvaluateOptions.directions]) are the same physical
    motions in any world frame and numbering, wherever the references fix the signs and
    the eigenspaces are single. Coordinate axes were not: a mirror image of a 5-finger
    grasp missed its slip boundary's lowest point from every one of the 20 starts
    (``tests/tolerance/test_degenerate.py``, ``sphere_5_mirrored``). A tie or a sign the references
    leave open is settled by the coordinate axes, away from any threshold, so that
    rounding (e.g. a grasp padded with inactive contacts) does not turn the frame.
    """
    k, hmat = _stiffness(data)
    evals, vecs = serial_eigh(hmat / jnp.max(jnp.abs(hmat)))  # one LAPACK call per grasp: jaxgrasp.solver._dense
    refs = _frame_references(data, k)
    basis, rank = _eigenspace_bases(evals, vecs, refs)
    # snapped to a grid of 2^-FRAME_BITS: a rounding-level change of the stiffness (the same
    # grasp padded with inactive contacts) then leaves the starts bit-identical
    return jnp.round(basis[jnp.arange(6), rank].T * 2.0**FRAME_BITS) / 2.0**FRAME_BITS


def _stiffness(data: ProblemData):
    """``(k, K)``: ``k`` ``(N,)`` each fingertip's stiffness ``E_i dr_i`` (0 where inactive)
    and ``K`` ``(6, 6)`` the grasp's stiffness in its initial state in the scaled pose
    space ``z``, each fingertip a spring at its contact point:
    ``K = sum_i k_i (A_i^T A_i + a_i b_i b_i^T)``. The elastic energy's second derivative
    in the normal and in the tangential displacement are both ``2 pi E d`` (the common
    ``2 pi`` is left out); ``A_i`` is the ``(3, 6)`` map from ``z`` to the displacement
    ``dp + w x c_i`` of contact ``i``, ``b_i`` the twist ``n_i . w`` about its normal and
    ``a_i = dr_i (r_i - dr_i / 3)`` (mm^2) the torsion's share."""
    p = data.params
    lever = data.lever
    k = jnp.where(p.on, p.E * p.dr, 0.0)  # (N,) stiffness of each fingertip (normal = tangential), / 2 pi
    eye = jnp.broadcast_to(jnp.eye(3, dtype=p.c.dtype), p.c.shape + (3,))
    cross = jnp.cross(p.c[:, None, :], eye)  # (N, 3, 3): cross @ v = v x c
    a = jnp.concatenate([eye, cross / lever], axis=2)  # (N, 3, 6): z -> displacement w x c + dp of the contact
    b = jnp.concatenate([jnp.zeros_like(p.n), p.n / lever], axis=1)  # (N, 6): z -> twist n . w about the normal
    arm = p.dr * (p.r - p.dr / 3.0)  # mm^2: torsion stiffness / k
    return k, jnp.einsum("n,nia,nib->ab", k, a, a) + jnp.einsum("n,na,nb->ab", k * arm, b, b)


def _frame_references(data: ProblemData, k):
    """``(9, 6)`` the reference vectors of `start_frame`, in order: the weight
    ``(m g, 0)``, the sum of the fingertips' normal wrenches ``k_i (n_i, c_i x n_i)`` and
    of their positions ``k_i (c_i, 0)`` (``k`` ``(N,)`` from `_stiffness`; unit
    length, or zero where a sum cancels to within `FRAME_TIE` of its terms' lengths,
    as by symmetry), then the six coordinate axes."""
    p = data.params
    dtype = p.c.dtype
    lever = data.lever
    wrench = jnp.concatenate([p.n, jnp.cross(p.c, p.n) / lever], axis=1)  # (N, 6)
    place = jnp.concatenate([p.c / lever, jnp.zeros_like(p.c)], axis=1)  # (N, 6)
    rows = jnp.stack([k[:, None] * wrench, k[:, None] * place])  # (2, N, 6); inactive: k = 0
    weight = jnp.concatenate([p.weight, jnp.zeros(3, dtype)])
    sums = jnp.concatenate([weight[None], jnp.sum(rows, axis=1)])  # (3, 6)
    norms = jnp.linalg.norm(sums, axis=1, keepdims=True)
    lengths = jnp.concatenate([jnp.linalg.norm(weight)[None], jnp.sum(jnp.linalg.norm(rows, axis=2), axis=1)])
    # a sum that cancels (a symmetric grasp) is rounding noise: no reference
    kept = norms > FRAME_TIE * lengths[:, None]
    return jnp.concatenate([jnp.where(kept, sums / jnp.where(kept, norms, 1.0), 0.0), jnp.eye(6, dtype=dtype)])


def _eigenspace_bases(evals, vecs, refs):
    """``(basis, rank)``: Gram-Schmidt of the reference vectors ``refs`` ``(9, 6)`` in the
    eigenspace of every column of ``vecs`` ``(6, 6)`` (eigenvalues ``evals`` ``(6,)``,
    ascending; runs of gaps within `FRAME_TIE` are one eigenspace). ``basis``
    ``(6, 6, 6)`` ``[column, slot, :]`` is each column's eigenspace basis in the order
    the references filled it, ``rank`` ``(6,)`` the slot of each column in its eigenspace.
    A reference sum joins a basis where its residual is longer than `FRAME_TIE`, a
    coordinate axis where it is longer than 0.3, which completes every basis: six unit
    vectors whose residuals were all at most 0.3 cannot leave an eigenspace dimension
    uncovered."""
    dtype = vecs.dtype
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
    return basis, rank


def _lane_rays(data: ProblemData, options: EvaluateOptions):
    """The ray of every boundary lane of the grasp ``data``: ``(k, v, t_grid)``, leading
    axis ``2N * D``: ``k`` the lane's equality row in the ``(3N,)`` constraints (slip rows,
    then force rows), ``v`` ``(6,)`` its direction ([`EvaluateOptions.directions`][jaxgrasp.EvaluateOptions.directions]
    in the `start_frame`), ``t_grid`` ``(ray_points,)`` mm, the points the ray
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


def _contact_data(data: ProblemData, j) -> ProblemData:
    """``data`` with contact ``j`` (a traced index) its only contact: every per-contact
    field of its parameters sliced to ``j``, keeping that axis (length 1). The
    constraints of contact ``j`` are each a function of that contact's kinematics
    alone, so ``constraints(z, _contact_data(data, j))`` is rows ``j, N + j, 2N + j`` of
    ``constraints(z, data)``, to rounding (tested)."""
    p = data.params
    keep = lambda a: jax.lax.dynamic_slice_in_dim(a, j, 1, axis=0)
    per_contact = {f.name: keep(getattr(p, f.name)) for f in dataclasses.fields(p) if f.name != "weight"}
    return dataclasses.replace(data, params=dataclasses.replace(p, **per_contact))


def _ray_lane(data: ProblemData, z_eq, k, v, t_grid, options: EvaluateOptions):
    """Start of one boundary lane (its grasp ``data``, ray ``k, v, t_grid`` from
    `_lane_rays`): ``(z0, found, nu0, g_eq)``: ``z0`` the crossing of constraint
    ``k`` along ``v`` from ``z_eq`` (``z_eq`` itself where the equilibrium is already on
    it), ``nu0`` ``NaN``: the solver starts the equality multiplier at its least-squares
    estimate there (`init`, from its first step's derivatives, so
    that no other copy of them is compiled); ``g_eq`` constraint ``k``'s margin at
    ``z_eq``.

    Row ``k = row * N + j`` of the constraints is contact ``j``'s alone, so the ray
    evaluates that contact's kinematics only (`_contact_data`): of a 7-contact
    grasp, one seventh of the model in each of its steps."""
    n = data.params.c.shape[0]
    one = _contact_data(data, k % n)
    z0, found, g_eq = _ray_start(lambda z: constraints(z, one)[k // n], z_eq, v, t_grid, options.crossing_steps)
    on_boundary = g_eq <= 0.0
    z0 = jnp.where(on_boundary, z_eq, z0)
    return z0, found | on_boundary, jnp.asarray(jnp.nan, z_eq.dtype), g_eq


def _equilibrium_lanes(data: ProblemData, num_lanes: int):
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
            solves (`_at_equilibrium`; not ``active``).
        g_eq: ``(B, L)`` each lane's equality margin at the equilibrium.
        u0: ``(B,)`` the equilibrium's energy (scaled; 0 in the equilibrium stage): the
            first wave of starts measures boundary energies above it
            (`jaxgrasp.tolerance._stages.rest_needed`).
    """

    x0: Any
    eq_mask: Any
    nu0: Any
    active: Any
    at_eq: Any
    g_eq: Any
    u0: Any


def equilibrium_starts(data: ProblemData, options: EvaluateOptions) -> LaneStarts:
    """The equilibrium stage of `jaxgrasp.engine.PIPELINE`: the lanes of the equilibrium problem of a
    batch ``data`` (`_equilibrium_lanes`: lane 0 of each grasp from its initial
    grasping state, the others inactive)."""
    num_lanes = _num_lanes(data, options)
    z0, masks, nu0, active = jax.vmap(lambda d: _equilibrium_lanes(d, num_lanes))(data)
    no = jnp.zeros(active.shape, bool)
    zero = jnp.zeros(active.shape, z0.dtype)
    return LaneStarts(z0, masks, nu0, active, no, zero, zero[:, 0])


def equilibrium_of(lanes: SolverResult) -> SolverResult:
    """Each grasp's equilibrium (leading axis ``B``) from the lanes of the equilibrium
    stage (leading axes ``(B, L)``): lane 0."""
    return jax.tree_util.tree_map(lambda a: a[:, 0], lanes)


def boundary_starts(data: ProblemData, eq: SolverResult, options: EvaluateOptions) -> LaneStarts:
    """The starts stage of `jaxgrasp.engine.PIPELINE`: the lanes of every boundary problem of a
    batch ``data`` from its equilibria ``eq`` (leading axis ``B``): each lane's ray
    (`_lane_rays`) walked to its crossing (`_ray_lane`). Without a converged
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
    return LaneStarts(z0s, jax.nn.one_hot(lane_k, 3 * n, dtype=dtype), nu0s, found & ~at_eq, at_eq, g_eq,
                      eq.objective.astype(dtype))
