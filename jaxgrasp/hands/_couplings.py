"""A hand's joint couplings in JAX: how far a configuration lies outside them, and a
configuration within them and the joint limits.

The couplings are the rows ``lower <= A @ qpos <= upper`` of the `KinematicTree`
(`jaxgrasp.hands._mjcf.coupling_rows`: the limited fixed tendons and the linear joint
equalities MuJoCo holds). [`project_joints`][jaxgrasp.Hand.project_joints] reaches them
by alternating projections (von Neumann's, cyclic over convex sets: it converges to a
point of their intersection, not necessarily the nearest one): each sweep projects onto
every row's slab ``{q : lower <= a . q <= upper}`` in turn, ``q += a (clip(a . q) - a . q)
/ |a|^2``, then clips to the joint limits, so the limits hold exactly and the couplings to
the tolerance the sweeps reach (`PROJECTION_SWEEPS`). Rows that share no joint commute,
so they are projected together: the rows are grouped into layers of disjoint joints
(`coupling_layers`), one matrix product per layer, the same result as one row at a time.
A configuration already within every row and limit is returned as it is (each correction
is exactly 0), and so is its derivative (the clips' ``where`` takes the inside branch on a
bound), so a feasible configuration evaluates and differentiates as if there were no
projection.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["COUPLING_TOLERANCE", "PROJECTION_SWEEPS", "coupling_layers", "coupling_violation", "project_joints"]

PROJECTION_SWEEPS = 32
"""Sweeps of `project_joints`. On the Shadow hand (``examples/hands/shadow``: 44 rows, 3
layers) the largest coupling violation left from 100 000 configurations drawn uniformly
within the joint limits (up to 11.5 mm outside a tendon's range) was 8.9e-10 m after 16
sweeps, 1.1e-12 m after 24 and 1.4e-15 m after 32 (the same from the limits' corners): it
shrinks about 2.3 times a sweep, so 32 leave six orders below `COUPLING_TOLERANCE`. A hand
whose coupled rows meet its limits at smaller angles converges more slowly:
[`coupling_violation`][jaxgrasp.Hand.coupling_violation] tells."""

COUPLING_TOLERANCE = 1e-9
"""m or rad: the coupling violation a configuration may have and still count as one the
hand can hold ([`tune_hand`][jaxgrasp.tune_hand]'s start)."""


def coupling_layers(tree) -> list:
    """The coupling rows grouped into layers whose rows share no joint, greedily in the
    rows' order: ``[(A (r, J), lower (r,), upper (r,), 1 / |a|^2 (r,))]`` (NumPy). A row of
    zeros (a tendon whose coefficients cancel) moves nothing and is left out."""
    a = np.asarray(tree.coupling_matrix)
    used, members = [], []
    for c in range(a.shape[0]):
        support = set(np.flatnonzero(a[c]).tolist())
        if not support:
            continue
        for k, joints in enumerate(used):
            if not joints & support:
                joints |= support
                members[k].append(c)
                break
        else:
            used.append(set(support))
            members.append([c])
    return [(a[m], tree.coupling_lower[m], tree.coupling_upper[m], 1.0 / np.sum(a[m] ** 2, axis=1)) for m in members]


def coupling_violation(tree, qpos):
    """``(..., C)`` m or rad: how far ``A @ qpos`` lies outside each coupling's range (0
    within it), ``qpos`` ``(..., J)``. Traceable."""
    s = jnp.asarray(qpos) @ jnp.asarray(tree.coupling_matrix).T
    return jnp.maximum(tree.coupling_lower - s, 0.0) + jnp.maximum(s - tree.coupling_upper, 0.0)


def _clip(x, lo, hi):
    """``clip(x, lo, hi)`` whose derivative on a bound is 1 (the inside's), not ``jnp.clip``'s 1/2."""
    return jnp.where(x < lo, lo, jnp.where(x > hi, hi, x))


def project_joints(tree, qpos, sweeps: int = PROJECTION_SWEEPS):
    """``(..., J)``: ``qpos`` ``(..., J)`` moved within the joint limits and (to the
    tolerance ``sweeps`` reach) the couplings, by ``sweeps`` sweeps of alternating
    projections (module notes); without couplings, the clip to the limits. Traceable,
    differentiable almost everywhere; ``qpos`` itself where it is within both."""
    lo, hi = tree.jnt_range[:, 0], tree.jnt_range[:, 1]
    q = _clip(jnp.asarray(qpos), lo, hi)
    layers = coupling_layers(tree)
    if not layers or sweeps <= 0:
        return q

    def sweep(_, q):
        for a, lower, upper, inv in layers:
            s = q @ a.T
            q = q + ((_clip(s, lower, upper) - s) * inv) @ a
        return _clip(q, lo, hi)

    return jax.lax.fori_loop(0, int(sweeps), sweep, q)
