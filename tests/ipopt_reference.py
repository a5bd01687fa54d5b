"""Independent reference solver for the energy-tolerance value (CasADi + Ipopt).

Test-only. It deliberately does not import ``jaxgrasp`` or ``jax``: it is what the
library is checked against. Every problem is solved with Ipopt (exact Hessians) from
many starts, and the lowest verified-feasible result is kept.

Model (internal units mm, N, N/mm^2, mJ), unknown ``x = (dp [mm], w [rad])``:

* ``dR = Rodrigues(w)``, ``u_i = (dR - I) c_i + dp``, ``cphi_i = n_i . dR n_i``
* ``d_i = r_i - ((r_i - dr_i) n_i - u_i) . dR n_i``
* ``dt2_i = |u_i|^2 - (n_i . u_i)^2``, ``theta_i = w . n_i`` (``|w| < pi``: the principal
  rotation vector; a solution beyond it is rejected)
* ``U = sum_i pi E_i (d^3/(3 cphi^2) + d dt2 + d^2 (r - d/3) theta^2) - m g . dp``

Constraints, all ``>= 0`` (scaled by positive constants here):

* contact ``d_i / dr_i``
* slip ``(mu^2 d^2/cphi^4 - 4 dt2 - 225/16 d (r - d/3)^2 theta^2 / (mu^2 (2r - d))) / (mu^2 dr^2)``
* force ``(sqrt(fmax/(pi E)) cphi - d) / dr``

(``dr`` in these scale factors is ``max(dr_i, 1e-3 r_i)``; the objective is divided by
``sum_i pi E_i dr_i^3 / 3``, the initial-state energy.)

All three families are handled by ONE Ipopt solver per grasp; the boundary problems
only change the bounds of the constraint vector (slip_j or force_j: ``0 <= g <= 0``).
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

__all__ = [
    "reference_evaluate",
    "reference_pose_energy",
    "reference_constraints",
    "KINDS",
]

KINDS = ("slip", "max_force")

_FIELDS = (
    "positions",
    "normals",
    "initial_deformation",
    "radius",
    "young_modulus",
    "friction",
    "max_force",
    "mass",
    "gravity",
)

FEAS_TOL = 1e-9  # accepted constraint violation, scaled units
ACTIVE_TOL = 1e-9  # slip/force margin below this at the equilibrium -> 'unstable'
N_GIVE_UP = 8  # a boundary problem whose first 8 starts all fail is taken as infeasible
MAX_ITER = 200  # successful solves need ~20 (median) to ~100 (99th pct.) iterations


# ----------------------------------------------------------------------------- input
def _as_dict(grasp) -> dict:
    """Accept a dict or any object with the grasp fields as attributes."""
    if isinstance(grasp, dict):
        src = grasp
    else:
        src = {k: getattr(grasp, k) for k in _FIELDS}
    g = {k: np.asarray(src[k], dtype=np.float64) for k in _FIELDS if k in src}
    g.setdefault("mass", np.float64(0.0))
    g.setdefault("gravity", np.array([0.0, 0.0, -9.81]))
    pos = g["positions"].reshape(-1, 3)
    n = pos.shape[0]
    out = {"positions": pos}
    nrm = g["normals"].reshape(n, 3)
    out["normals"] = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    for k in ("initial_deformation", "radius", "young_modulus", "friction", "max_force"):
        out[k] = np.broadcast_to(g[k], (n,)).astype(np.float64).copy()
    out["mass"] = float(g["mass"])
    out["gravity"] = np.broadcast_to(g["gravity"], (3,)).astype(np.float64).copy()
    return out


def _internal(g: dict) -> dict:
    """SI -> mm, N, N/mm^2."""
    return {
        "c": g["positions"] * 1e3,
        "n": g["normals"],
        "dr": g["initial_deformation"] * 1e3,
        "r": g["radius"] * 1e3,
        "E": g["young_modulus"] * 1e-6,
        "mu": g["friction"],
        "fmax": g["max_force"],
        "mg": g["mass"] * g["gravity"],  # N
    }


def _x_to_internal(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64).reshape(6)
    return np.concatenate([x[:3] * 1e3, x[3:]])


def _x_to_si(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64).reshape(6)
    return np.concatenate([x[:3] * 1e-3, x[3:]])


# ----------------------------------------------------------------------------- model
def _rodrigues(w):
    """Rotation matrix with a series branch near 0 (finite derivatives of any order)."""
    t2 = ca.dot(w, w)
    small = t2 < 1e-6
    t2s = ca.if_else(small, 1.0, t2)  # double-where: the big branch never sees 0
    ts = ca.sqrt(t2s)
    a_big = ca.sin(ts) / ts
    b_big = (1.0 - ca.cos(ts)) / t2s
    a_ser = 1.0 - t2 / 6.0 + t2**2 / 120.0 - t2**3 / 5040.0
    b_ser = 0.5 - t2 / 24.0 + t2**2 / 720.0 - t2**3 / 40320.0
    a = ca.if_else(small, a_ser, a_big)
    b = ca.if_else(small, b_ser, b_big)
    k = ca.skew(w)
    return ca.SX.eye(3) + a * k + b * ca.mtimes(k, k)


class _Model:
    """CasADi expressions, functions and one Ipopt solver for one grasp."""

    def __init__(self, grasp, tol: float = 1e-12):
        self.si = _as_dict(grasp)
        p = _internal(self.si)
        self.p = p
        n_c = p["c"].shape[0]
        self.n = n_c

        x = ca.SX.sym("x", 6)
        dp, w = x[:3], x[3:]
        dR = _rodrigues(w)

        U = -ca.dot(ca.DM(p["mg"]), dp)
        contact, slip, force, cphis, ds = [], [], [], [], []
        for i in range(n_c):
            c = ca.DM(p["c"][i])
            ni = ca.DM(p["n"][i])
            r, dr, E, mu, fmax = (float(p[k][i]) for k in ("r", "dr", "E", "mu", "fmax"))
            drs = max(dr, 1e-3 * r)  # length used only to scale constraints
            u = ca.mtimes(dR - ca.SX.eye(3), c) + dp
            Rn = ca.mtimes(dR, ni)
            cphi = ca.dot(ni, Rn)
            d = r - ca.dot((r - dr) * ni - u, Rn)
            un = ca.dot(ni, u)
            dt2 = ca.dot(u, u) - un**2
            th = ca.dot(w, ni)
            U = U + np.pi * E * (d**3 / (3.0 * cphi**2) + d * dt2 + d**2 * (r - d / 3.0) * th**2)
            contact.append(d / drs)
            slip.append(
                (
                    mu**2 * d**2 / cphi**4
                    - 4.0 * dt2
                    - (225.0 / 16.0) * d * (r - d / 3.0) ** 2 * th**2 / (mu**2 * (2.0 * r - d))
                )
                / (mu**2 * drs**2)
            )
            force.append((np.sqrt(fmax / (np.pi * E)) * cphi - d) / drs)
            cphis.append(cphi)
            ds.append(d)

        # objective scale: the initial-state energy (mJ)
        drs_all = np.maximum(p["dr"], 1e-3 * p["r"])
        self.u_scale = float(np.sum(np.pi * p["E"] * drs_all**3 / 3.0))
        g = ca.vertcat(*contact, *slip, *force)
        self.f_all = ca.Function("f_all", [x], [U, g, ca.vertcat(*ds), ca.vertcat(*cphis)])
        self._nlp = {"x": x, "f": U / self.u_scale, "g": g}
        self._opts = {
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.print_level": 0,
            "ipopt.tol": tol,
            "ipopt.acceptable_tol": 1e-9,
            "ipopt.constr_viol_tol": 1e-11,
            "ipopt.acceptable_constr_viol_tol": 1e-10,
            "ipopt.bound_relax_factor": 0.0,
            "ipopt.max_iter": MAX_ITER,
            "ipopt.mu_strategy": "adaptive",
        }
        self._solver = None
        self.n_solves = 0

    @property
    def solver(self):
        """The Ipopt solver, built on first use (pose evaluations do not need it)."""
        if self._solver is None:
            self._solver = ca.nlpsol("ref", "ipopt", self._nlp, self._opts)
        return self._solver

    # --- bounds ------------------------------------------------------------
    def bounds(self, kind: str | None = None, j: int | None = None):
        lbg = np.zeros(3 * self.n)
        ubg = np.full(3 * self.n, np.inf)
        if kind is not None:
            ubg[self.row(kind, j)] = 0.0
        return lbg, ubg

    def row(self, kind: str, j: int) -> int:
        return {"slip": 1, "max_force": 2}[kind] * self.n + j

    def evaluate(self, x_int):
        U, g, d, cphi = self.f_all(np.asarray(x_int, dtype=np.float64))
        return float(U), np.asarray(g).ravel(), np.asarray(d).ravel(), np.asarray(cphi).ravel()

    def violation(self, g, lbg, ubg) -> float:
        return float(np.max(np.maximum(np.maximum(lbg - g, g - ubg), 0.0)))

    def solve(self, x0, lbg, ubg):
        """One Ipopt solve. Returns (U in mJ, x internal) or None if not verified."""
        self.n_solves += 1
        try:
            sol = self.solver(x0=np.asarray(x0, dtype=np.float64), lbg=lbg, ubg=ubg)
        except RuntimeError:
            return None
        status = self.solver.stats().get("return_status", "")
        if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
            return None
        xs = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(xs)):
            return None
        U, g, d, cphi = self.evaluate(xs)
        if not np.isfinite(U) or self.violation(g, lbg, ubg) > FEAS_TOL:
            return None
        if np.any(cphi <= 0.0):
            return None
        if np.linalg.norm(xs[3:]) >= np.pi:
            # theta_i = w . n_i is the twist about n_i only for the principal rotation
            # vector: beyond |w| = pi the same rotation has a shorter w, and the model's
            # torsion is an artefact (seen: a slip boundary reached at |w| = 6.28 rad, a
            # full turn, which made a grasp's value 26 % too low; random_urdfs 078)
            return None
        return U, xs


# ----------------------------------------------------------------------------- API
def reference_pose_energy(grasp, x) -> float:
    """Elastic + gravitational energy U (J) at pose ``x = (dp [m], w [rad])``."""
    m = _Model(grasp) if not isinstance(grasp, _Model) else grasp
    return m.evaluate(_x_to_internal(x))[0] * 1e-3


def reference_constraints(grasp, x) -> dict:
    """Scaled constraint margins (all must be >= 0) at pose ``x = (dp [m], w [rad])``.

    Keys: 'contact' (d/dr), 'slip', 'max_force' (each (N,)), plus 'd' (normal
    deformation, m) and 'cos_phi'.
    """
    m = _Model(grasp) if not isinstance(grasp, _Model) else grasp
    _, g, d, cphi = m.evaluate(_x_to_internal(x))
    n = m.n
    return {
        "contact": g[:n],
        "slip": g[n : 2 * n],
        "max_force": g[2 * n :],
        "d": d * 1e-3,
        "cos_phi": cphi,
    }


def _boundary_starts(x_eq, n_starts, rng, dr_mean):
    """Equilibrium pose plus multi-scale random perturbations in all 6 coordinates."""
    starts = [x_eq.copy()]
    for k in range(n_starts - 1):
        # log-uniform magnitudes: translations 0.02..3 dr, rotations 0.003..0.3 rad
        t_mag = dr_mean * 10 ** rng.uniform(np.log10(0.02), np.log10(3.0))
        r_mag = 10 ** rng.uniform(np.log10(0.003), np.log10(0.3))
        t_dir = rng.normal(size=3)
        r_dir = rng.normal(size=3)
        mode = k % 4
        if mode == 1:  # pure translation
            r_mag = 0.0
        elif mode == 2:  # pure rotation
            t_mag = 0.0
        dx = np.concatenate(
            [t_mag * t_dir / np.linalg.norm(t_dir), r_mag * r_dir / np.linalg.norm(r_dir)]
        )
        starts.append(x_eq + dx)
    return starts


def reference_evaluate(grasp, n_starts: int = 24, seed: int = 0, tol: float = 1e-12) -> dict:
    """Multi-start Ipopt reference for the energy-tolerance value.

    Returns a dict with (SI units, J / m / rad):
        equilibrium_energy: U0 (J), nan if infeasible.
        equilibrium_pose: (6,) (dp m, w rad), nan if infeasible.
        boundary_energy: (2, N) U_b* in J; row 0 slip, row 1 max_force; inf where no
            start gave a verified feasible solution.
        boundary_pose: (2, N, 6), nan where none.
        value: min_b(U_b*) - U0 (J); 0 if unstable/infeasible.
        status: 'stable' | 'unstable' | 'infeasible'.
        limiting: (kind, contact) of the minimising boundary, or None.
        equilibrium_margins: scaled constraints at the equilibrium (dict).
        n_solves, seconds: bookkeeping.
    """
    t0 = time.perf_counter()
    m = _Model(grasp, tol=tol)
    n = m.n
    rng = np.random.default_rng(seed)
    dr_mean = float(np.mean(np.maximum(m.p["dr"], 1e-3 * m.p["r"])))

    out = {
        "equilibrium_energy": np.nan,
        "equilibrium_pose": np.full(6, np.nan),
        "boundary_energy": np.full((2, n), np.inf),
        "boundary_pose": np.full((2, n, 6), np.nan),
        "value": 0.0,
        "status": "infeasible",
        "limiting": None,
        "equilibrium_margins": None,
    }

    # --- equilibrium ---------------------------------------------------------
    lbg, ubg = m.bounds()
    eq_starts = [np.zeros(6)]
    for _ in range(max(3, n_starts // 6)):
        eq_starts.append(
            np.concatenate([rng.normal(scale=0.1 * dr_mean, size=3), rng.normal(scale=0.01, size=3)])
        )
    best = None
    for x0 in eq_starts:
        res = m.solve(x0, lbg, ubg)
        if res is not None and (best is None or res[0] < best[0]):
            best = res
    if best is None:
        out["n_solves"] = m.n_solves
        out["seconds"] = time.perf_counter() - t0
        return out
    U0, x_eq = best
    out["equilibrium_energy"] = U0 * 1e-3
    out["equilibrium_pose"] = _x_to_si(x_eq)
    _, g_eq, _, _ = m.evaluate(x_eq)
    out["equilibrium_margins"] = {
        "contact": g_eq[:n],
        "slip": g_eq[n : 2 * n],
        "max_force": g_eq[2 * n :],
    }

    # --- boundaries ----------------------------------------------------------
    for kk, kind in enumerate(KINDS):
        for j in range(n):
            lbg, ubg = m.bounds(kind, j)
            starts = _boundary_starts(x_eq, n_starts, rng, dr_mean)
            bb = None
            for k, x0 in enumerate(starts):
                # Early exit: if the first N_GIVE_UP diverse starts all fail, the
                # boundary problem is taken as infeasible (Ipopt's runs on infeasible
                # problems are the slow ones, typically ending at max_iter).
                if bb is None and k >= N_GIVE_UP:
                    break
                res = m.solve(x0, lbg, ubg)
                if res is not None and (bb is None or res[0] < bb[0]):
                    bb = res
            if bb is not None:
                out["boundary_energy"][kk, j] = bb[0] * 1e-3
                out["boundary_pose"][kk, j] = _x_to_si(bb[1])

    active = np.min(g_eq[n:]) < ACTIVE_TOL
    if active:
        out["status"] = "unstable"
    else:
        out["status"] = "stable"
        be = out["boundary_energy"]
        if np.any(np.isfinite(be)):
            kk, j = np.unravel_index(np.argmin(be), be.shape)
            out["value"] = float(be[kk, j] - U0 * 1e-3)
            out["limiting"] = (KINDS[kk], int(j))
        else:
            out["value"] = np.inf
    out["n_solves"] = m.n_solves
    out["seconds"] = time.perf_counter() - t0
    return out
