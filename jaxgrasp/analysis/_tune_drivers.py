"""The optimisers of [`jaxgrasp.tune`][jaxgrasp.tune] and the record of their iterates.

Every driver minimises a compiled ``vg(u, data) -> ((objective, Evaluation), grad)`` over
the box ``[0, 1]^k`` and adds each iterate to a `SearchRecord`; they
know nothing of grasps beyond the evaluation's value and status.
"""

from __future__ import annotations

import math
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.analysis._tune_status import TuneStatus
from jaxgrasp.model import GraspValueError
from jaxgrasp.tolerance import GraspStatus

__all__ = ["SearchRecord", "run_search"]


class SearchRecord:
    """The value and status of every iterate, and the best trusted one."""

    def __init__(self, v0: float, u0, ev0):
        self.history = [v0]
        self.statuses = [int(ev0.status)]
        self.best = (v0, np.asarray(u0), ev0)

    @property
    def initial_value(self) -> float:
        return self.history[0]

    @classmethod
    def start(cls, vg, box, data) -> "SearchRecord":
        """Evaluate the start ``box.u0`` (a `ParamBox`);
        a start without a positive value is an error."""
        (_, ev0), _ = vg(jnp.asarray(box.u0), data)
        v0 = float(ev0.value)
        if not (v0 > 0.0 and math.isfinite(v0)):
            where = f" after clipping {', '.join(box.clipped)} to its bounds" if box.clipped else ""
            raise GraspValueError(
                f"tune: the starting grasp{where} has value {v0:g} J "
                f"(status {GraspStatus(int(ev0.status)).label}): "
                "its gradient is 0, so there is nothing to follow; start from a stable grasp"
            )
        return cls(v0, box.u0, ev0)

    def add(self, u, ev) -> float:
        """Record an iterate; returns its value, J."""
        v = float(ev.value)
        s = int(ev.status)
        self.history.append(v)
        self.statuses.append(s)
        if s in (GraspStatus.STABLE, GraspStatus.NOT_CONVERGED) and v > self.best[0]:
            self.best = (v, np.asarray(u), ev)
        return v


def run_search(method: str, vg, u0, data, rec: SearchRecord, **stop):
    """Run the optimiser ``method`` (one of `jaxgrasp.analysis._limits.METHODS`) on ``vg`` from ``u0``;
    ``stop`` holds ``maxiter``, ``tol``, ``ftol``, ``patience`` and ``callback``
    ([`jaxgrasp.tune`][jaxgrasp.tune]). Returns ``(status, iterations, evaluations)``."""
    if method == "scipy_lbfgsb":
        return _run_scipy(vg, u0, data, rec, **stop)
    return _run_jaxopt(_jaxopt_solver(vg, method), u0, data, rec, **stop)


def _run_jaxopt(solver, u0, data, rec: SearchRecord, *, maxiter, tol, ftol, patience, callback):
    """A jaxopt solver's iterations, one record each; ``(status, iterations, evaluations)``."""
    box = (jnp.zeros_like(jnp.asarray(u0)), jnp.ones_like(jnp.asarray(u0)))
    u = jnp.asarray(u0)
    state = solver.init_state(u, box, data)
    status, iters, stall = TuneStatus.MAX_ITERATIONS, 0, 0
    for it in range(1, maxiter + 1):
        u_prev = u
        prev_best = rec.best[0]
        u, state = solver.update(u, state, box, data)
        iters = it
        v = rec.add(u, state.aux)
        if callback is not None:
            callback(it, v, np.asarray(u))
        stall = stall + 1 if rec.best[0] <= prev_best * (1.0 + ftol) else 0
        if float(state.error) <= tol:
            status = TuneStatus.CONVERGED
            break
        if bool(getattr(state, "failed_linesearch", False)) and np.array_equal(np.asarray(u), np.asarray(u_prev)):
            status = TuneStatus.LINE_SEARCH_FAILED
            break
        if stall >= patience:
            status = TuneStatus.STALLED
            break
    return status, iters, int(getattr(state, "num_fun_eval", iters + 1))


@lru_cache(maxsize=32)
def _jaxopt_solver(vg, method: str):
    """A jaxopt solver of ``vg``.

    ``ProjectedGradient`` runs its steps in Python (``jit=False``) around the compiled
    ``vg``: its steps are a few array operations around each call of ``vg``, and compiled
    by jaxopt its ``init_state`` and ``update`` would each compile the evaluation's
    gradient again, per process, never reaching the executable store. ``LBFGSB`` stays
    compiled by jaxopt (run in Python, two of its steps on the cube took three times as
    long as compiling it), and calls the compiled ``vg`` from there as a host callback
    (`_host_callback`)."""
    import jaxopt

    if method == "jaxopt_lbfgsb":
        return jaxopt.LBFGSB(fun=_host_callback(vg), value_and_grad=True, has_aux=True, maxiter=10**6, tol=0.0)
    from jaxopt.projection import projection_box

    return jaxopt.ProjectedGradient(
        fun=vg, projection=projection_box, value_and_grad=True, has_aux=True, maxiter=10**6, tol=0.0, jit=False
    )


def _host_callback(vg):
    """``vg`` (compiled, with compiler options: not callable inside another ``jit``) as a
    function jaxopt's compiled steps call back on the host (`jax.pure_callback`):
    traced inline, the evaluation and its gradient were compiled into ``init_state`` and
    again into ``update`` (its line search), per process, none of it from the executable
    store."""
    inline = getattr(vg, "__wrapped__", vg)

    def fun(u, data):
        shapes = jax.eval_shape(inline, u, data)
        return jax.pure_callback(lambda u, data: jax.device_get(vg(u, data)), shapes, u, data)

    return fun


def _run_scipy(vg, u0, data, rec: SearchRecord, *, maxiter, tol, ftol, patience, callback):
    """SciPy's L-BFGS-B on the compiled value and gradient in ``[0, 1]^k``, one record per
    iteration; ``(status, iterations, evaluations)``. (``patience`` is jaxopt's: SciPy
    stops on ``ftol`` itself.)"""
    import scipy.optimize

    last = {}
    count = {"it": 0, "evals": 0}

    def fun(u):
        count["evals"] += 1
        (f, ev), g = vg(jnp.asarray(u), data)
        last["u"], last["ev"] = np.array(u), ev
        return float(f), np.asarray(g, dtype=np.float64)

    def cb(intermediate_result):
        xk = np.asarray(intermediate_result.x)
        count["it"] += 1
        if "u" in last and np.array_equal(last["u"], xk):
            ev = last["ev"]  # the line search's last point is the accepted iterate
        else:
            count["evals"] += 1
            (_, ev), _ = vg(jnp.asarray(xk), data)
        v = rec.add(xk, ev)
        if callback is not None:
            callback(count["it"], v, xk)

    out = scipy.optimize.minimize(
        fun,
        np.asarray(u0, dtype=np.float64),
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, 1.0)] * len(u0),
        callback=cb,
        options={"maxiter": maxiter, "gtol": tol, "ftol": ftol},
    )
    return _scipy_status(out, count["it"], maxiter), count["it"], count["evals"]


def _scipy_status(out, iterations: int, maxiter: int) -> TuneStatus:
    """How SciPy's L-BFGS-B run ``out`` stopped, as a [`TuneStatus`][jaxgrasp.analysis.TuneStatus]."""
    if out.success:
        return TuneStatus.CONVERGED if "PROJ" in str(out.message).upper() else TuneStatus.STALLED
    if iterations >= maxiter:
        return TuneStatus.MAX_ITERATIONS
    return TuneStatus.LINE_SEARCH_FAILED
