"""The Ferrari-Canny epsilon metric (Q1) on a grasp's contacts, beside the energy tolerance.

Convention (``docs/guide/epsilon.md`` states it too). For each active contact ``i`` with position
``p_i`` (m, centre-of-mass frame), unit outward normal ``n_i`` and friction ``mu_i``:

* the fingertip pushes along ``-n_i`` with unit normal force; its friction cone is
  approximated by ``m = cone_edges`` edges
  ``f_ij = -n_i + mu_i (cos(2 pi j / m) t1_i + sin(2 pi j / m) t2_i)``, ``j = 0..m-1``,
  with ``t1_i, t2_i`` an orthonormal basis of the contact's tangent plane
  (`tangent_basis`);
* each edge gives the wrench ``w_ij = (f_ij, (p_i x f_ij) / lam)``, where the torque scale
  ``lam`` (m) is the largest distance of an active contact from the centre of mass;
* with ``torsion=True`` (soft fingers) each contact adds the two wrenches
  ``(-n_i, (p_i x (-n_i) +- mu_i e_i n_i) / lam)``: ``mu_i e_i`` is the torsion the
  fingertip carries per unit normal force with no tangential force (eq. 9), ``e_i`` eq.
  10's eccentricity ``(8/15) mu_i sqrt(r_i^2 - (r_i - dr_i)^2)`` (m) at the initial
  deformation ``dr_i``;
* the value is the signed distance from the origin to the boundary of the convex hull of
  all these wrenches (qhull, ``scipy.spatial.ConvexHull``): the radius of the largest
  ball about the origin inside the hull where the origin is inside (force closure), else
  ``<= 0`` (minus the distance to the farthest facet plane the origin lies beyond). A
  hull that does not span the 6-D wrench space (e.g. two point contacts: no torsion) has
  value 0 and is not force closure.

The metric depends on the contacts' geometry and friction only (and, with torsion, on
the fingertip radius and initial deformation), not on Young's modulus, the squeeze force,
the mass or gravity: that is where it and the energy tolerance part (``docs/guide/epsilon.md``).
Friction is at most `MAX_FRICTION` (1e3, validation):
the wrenches' tangential parts grow as ``mu`` and the torsion as ``mu^2``, and at
``mu = 1e7`` they swamp the unit normal forces that bound the hull, so that qhull's float64
lost the value (1 fell to 0). Up to the bound the value is within round-off of the closed
form of the two-finger cube, which tends to 1 as ``1 - 1.17 / mu^2``.
The finite cone is inscribed in the true one, so the value grows towards its limit as
``cone_edges`` grows; with finite ``cone_edges`` it depends slightly on where the first
edge lies (``t1_i``), so a rotated grasp agrees to about ``1 - cos(pi / cone_edges)``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxgrasp.model import Grasp, GraspValueError, check_batch_inputs, check_grasp_inputs

__all__ = ["epsilon", "EpsilonResult", "wrenches", "tangent_basis", "FORCE_CLOSURE_TOL", "prefetch_qhull"]

FORCE_CLOSURE_TOL = 1e-12
"""A value above this (dimensionless wrench units) is force closure; qhull's facet
offsets carry round-off of about 1e-15 on wrenches of length ~1."""


@dataclasses.dataclass(frozen=True)
class EpsilonResult:
    """The Ferrari-Canny epsilon of one grasp (``()`` arrays) or of a batch (``(B,)``).

    Its ``value`` is the metric, dimensionless, not an energy in J; it has no status
    (``force_closure`` is its yes-or-no outcome).

    Attributes:
        value: signed distance from the origin to the wrench hull's boundary
            (dimensionless: forces per unit normal force, torques divided by ``lam``);
            ``> 0`` inside (force closure), ``<= 0`` otherwise.
        force_closure: ``value > FORCE_CLOSURE_TOL``.
        torque_scale: ``lam``, m: the largest distance of an active contact from the
            centre of mass.
        cone_edges: edges of each friction cone.
        torsion: whether each contact also carries its torsion (soft fingers).
    """

    value: np.ndarray
    force_closure: np.ndarray
    torque_scale: np.ndarray
    cone_edges: int
    torsion: bool

    def summary(self) -> str:
        """One line: force closure or not and the value (one grasp), or how many of a
        batch are force closure and the range of their values."""
        how = f"{self.cone_edges} cone edges, {'soft fingers' if self.torsion else 'point contacts'}"
        value = np.asarray(self.value, dtype=np.float64)
        if value.ndim == 0:
            closure = "force closure" if bool(self.force_closure) else "not force closure"
            return (f"{closure}: epsilon {float(value):.6e} ({how}; torque scale "
                    f"{float(self.torque_scale):.4g} m)")
        if value.size == 0:
            return f"0 grasps ({how})"
        return (f"{value.size} grasps, {int(np.sum(self.force_closure))} force closure: epsilon "
                f"{float(np.min(value)):.6e} to {float(np.max(value)):.6e} ({how})")

    def to_dict(self) -> dict:
        """As plain Python (JSON-ready): ``value`` (dimensionless), ``force_closure`` and
        ``torque_scale`` (m), numbers for one grasp, lists for a batch; ``cone_edges``
        and ``torsion``."""
        return {
            "value": np.asarray(self.value, dtype=np.float64).tolist(),
            "force_closure": np.asarray(self.force_closure, dtype=bool).tolist(),
            "torque_scale": np.asarray(self.torque_scale, dtype=np.float64).tolist(),
            "cone_edges": int(self.cone_edges),
            "torsion": bool(self.torsion),
        }


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(t1, t2)``, each ``(N, 3)``: orthonormal tangent vectors of unit normals ``(N, 3)``,
    with ``(t1, t2, n)`` right-handed; ``t1`` is the coordinate axis least aligned with
    ``n``, made orthogonal to it."""
    n = np.asarray(normal, dtype=np.float64)
    axis = np.eye(3)[np.argmin(np.abs(n), axis=-1)]
    t1 = axis - np.sum(axis * n, axis=-1, keepdims=True) * n
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(n, t1)


def wrenches(fields: dict, *, cone_edges: int = 8, torsion: bool = True) -> tuple[np.ndarray, float]:
    """The wrenches of one grasp's active contacts (see the module doc) and ``lam`` (m).

    Args:
        fields: one grasp's fields ([`Grasp.to_numpy`][jaxgrasp.Grasp.to_numpy], SI units; ``active`` optional).

    Returns:
        ``(W, lam)``: ``W`` of shape ``(K, 6)``, ``K = n_active * (cone_edges + 2 * torsion)``,
        rows ``(force, torque / lam)``.
    """
    on = np.ones(len(fields["positions"]), bool) if fields.get("active") is None else np.asarray(fields["active"])
    p = np.asarray(fields["positions"], dtype=np.float64)[on]
    n = np.asarray(fields["normals"], dtype=np.float64)[on]
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    mu = np.broadcast_to(np.asarray(fields["friction"], dtype=np.float64), on.shape)[on]
    lam = float(np.max(np.linalg.norm(p, axis=-1)))
    t1, t2 = tangent_basis(n)
    angle = 2.0 * np.pi * np.arange(cone_edges) / cone_edges
    f = -n[:, None, :] + mu[:, None, None] * (
        np.cos(angle)[None, :, None] * t1[:, None, :] + np.sin(angle)[None, :, None] * t2[:, None, :]
    )  # (N, m, 3)
    tau = np.cross(p[:, None, :], f)
    rows = [np.concatenate([f, tau / lam], axis=-1).reshape(-1, 6)]
    if torsion:
        r = np.broadcast_to(np.asarray(fields["radius"], dtype=np.float64), on.shape)[on]
        dr = np.broadcast_to(np.asarray(fields["initial_deformation"], dtype=np.float64), on.shape)[on]
        e = (8.0 / 15.0) * mu * np.sqrt(r**2 - (r - dr) ** 2)  # eq. 10, m
        base = np.cross(p, -n)
        for sign in (1.0, -1.0):
            rows.append(np.concatenate([-n, (base + sign * (mu * e)[:, None] * n) / lam], axis=-1))
    return np.concatenate(rows, axis=0), lam


def prefetch_qhull() -> None:
    """Start importing SciPy's qhull in a background thread (returns at once;
    `jaxgrasp.engine._prefetch.prefetch`): a caller that will need [`epsilon`][jaxgrasp.epsilon]
    after a compile or the load of a stored executable has ``scipy.spatial`` imported
    during that wait rather than after it."""
    from jaxgrasp.engine import prefetch

    prefetch("scipy.spatial")


def _hull_distance(w: np.ndarray) -> float:
    """Signed distance from the origin to the boundary of ``conv(w)``; 0 where the hull is
    flat (does not span the space).

    Flatness is decided by the rank of the points' differences, not by a qhull error: in
    6-D, qhull's default (``Qx``, exact pre-merges) can fail on full-dimensional wrench
    sets with many cone edges (QH6271 "wide merge due to dupridge", e.g. 64 edges), and
    such a grasp is not flat. Those are retried with joggled input (``QJ``: a simplicial
    hull of inputs perturbed by about 1e-11, so the value moves by about that much)."""
    from scipy.spatial import ConvexHull, QhullError

    w = np.asarray(w, dtype=np.float64)
    dim = w.shape[1]
    if w.shape[0] <= dim or np.linalg.matrix_rank(w[1:] - w[0], tol=1e-12 * max(1.0, float(np.max(np.abs(w))))) < dim:
        return 0.0
    try:
        hull = ConvexHull(w)
    except QhullError:
        hull = ConvexHull(w, qhull_options="QJ")
    return float(np.min(-hull.equations[:, -1]))  # rows: unit normal . x + offset <= 0 inside


def epsilon(grasp: Grasp, /, *, cone_edges: int = 8, torsion: bool = True) -> EpsilonResult:
    """The Ferrari-Canny epsilon (Q1) of a grasp or of a batch of grasps (leading axis
    ``B``, e.g. [`jaxgrasp.stack`][jaxgrasp.stack]), with the convention of the module doc.

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] (SI units); its inactive contacts are left out.
        cone_edges: edges of the polygon inscribed in each friction cone (>= 3).
        torsion: add each soft fingertip's torsion about its normal (eq. 9, 10).

    Returns:
        An [`EpsilonResult`][jaxgrasp.analysis.EpsilonResult], ``()`` arrays for one grasp, ``(B,)`` for a batch.

    Raises:
        GraspValueError: an invalid grasp (one line, naming the grasp of a batch) or
            ``cone_edges`` < 3.
    """
    if isinstance(cone_edges, bool) or not isinstance(cone_edges, (int, np.integer)) or cone_edges < 3:
        raise GraspValueError(f"cone_edges must be an integer >= 3, got {cone_edges!r}")
    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"epsilon needs a jaxgrasp.Grasp, got {type(grasp).__name__}")
    ndim = np.ndim(grasp.positions)
    if ndim not in (2, 3):
        raise GraspValueError(f"epsilon needs positions (N, 3) or a batch (B, N, 3), got {np.shape(grasp.positions)}")
    if ndim == 3:
        batch = grasp.to_numpy_batch()
        check_batch_inputs(batch)
    else:
        batch = {k: v[None] for k, v in grasp.to_numpy().items()}
        check_grasp_inputs(**grasp.to_numpy())
    values, lams = [], []
    for i in range(batch["positions"].shape[0]):
        w, lam = wrenches({k: v[i] for k, v in batch.items()}, cone_edges=int(cone_edges), torsion=bool(torsion))
        values.append(_hull_distance(w))
        lams.append(lam)
    value = np.asarray(values) if ndim == 3 else np.asarray(values[0])
    lam = np.asarray(lams) if ndim == 3 else np.asarray(lams[0])
    return EpsilonResult(
        value=value,
        force_closure=value > FORCE_CLOSURE_TOL,
        torque_scale=lam,
        cone_edges=int(cone_edges),
        torsion=bool(torsion),
    )
