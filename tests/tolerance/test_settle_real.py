"""The hardest grasps of real objects (issue 42): every program settles, and the value is Ipopt's.

``tests/data/settle_hard.json`` holds grasps of ``pybullet_data`` meshes drawn by the
planner's own code (``experiments/settle_real.py``) on which, before issue 42's fix, the
equilibrium problem stalled: the weight pulls the object off one fingertip, whose contact
then sits at the apex of its friction cone (``d = 0``, ``dt = 0``), where the slip
margin's gradient vanishes and the augmented Lagrangian crawls at its largest penalty
(status ``not_converged``, or ``unstable`` only through the stalled-equilibrium rule);
and four-finger grasps whose boundary problems stalled after that fix (three force-limit
problems at once, or two fingertips released at their cone apexes); and two-finger
candidates of ``jaxgrasp.plan(sampler="uniform")`` on ``random_urdfs`` 000 whose
equilibrium stalled beside two slip boundaries its Newton steps crossed, until a feasible
lane could walk the deeper step ladder (:mod:`jaxgrasp.solver._line_search`). Beside each
is the status and value of the independent CasADi/Ipopt multi-start reference
(``tests/ipopt_reference.py``, 24 starts; 7-20 s a grasp, so stored, with the note of how:
``experiments/settle_hard_data.py``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.solver._status import LaneStatus

DATA = Path(__file__).resolve().parent.parent / "data" / "settle_hard.json"
REL = 1e-6


def _cases():
    rows = json.loads(DATA.read_text(encoding="utf-8"))["grasps"]
    return [(jaxgrasp.Grasp.create(**row["grasp"]), row) for row in rows]


@pytest.fixture(scope="module")
def evaluated(evaluate_many):
    cases = _cases()
    return cases, evaluate_many([g for g, _ in cases])


def test_the_data_are_the_hard_cases():
    """The stored grasps are the ones that did not settle before the fix."""
    rows = [row for _, row in _cases()]
    assert len(rows) >= 4
    assert all(row["status_before"] in (jaxgrasp.GraspStatus.NOT_CONVERGED, jaxgrasp.GraspStatus.UNSTABLE)
               for row in rows)
    assert any(row["status_before"] == jaxgrasp.GraspStatus.NOT_CONVERGED for row in rows)


def test_every_program_settles(evaluated):
    """Every program that decides the value settles: the equilibrium always (converged, or
    certified to leave the region), and every boundary problem of a stable grasp (an
    unstable grasp's value is 0 from its equilibrium alone; the planner's uniform
    candidates of object 000 leave force-limit problems that no longer matter unsettled
    in ``evaluate``'s path)."""
    for (grasp, row), r in zip(*evaluated):
        # settled: converged, or certified to have no equilibrium inside the region
        assert int(r.equilibrium_status) != LaneStatus.NOT_CONVERGED, (row["object"], r.explain())
        if row["ipopt_status"] == "stable" or not row["object"].startswith("000 (plan"):
            assert not np.any(np.asarray(r.boundary_status) == LaneStatus.NOT_CONVERGED), row["object"]
        assert r.status_name != "not_converged", row["object"]


def test_statuses_and_values_are_ipopts(evaluated):
    for (grasp, row), r in zip(*evaluated):
        assert r.status_name == row["ipopt_status"], (row["object"], r.explain())
        want, got = row["ipopt_value"], float(r.value)
        assert got <= want * (1 + REL) + 1e-15, row["object"]  # never above: stability not overstated
        assert abs(got - want) <= REL * abs(want) + 1e-15, row["object"]


@pytest.mark.slow  # compiles the batch engine's evaluator for two contacts
def test_uniform_plan_candidates_settle_in_the_engine():
    """The planner's uniform candidates stalled in ``evaluate_batch``'s work queue, where
    each lane's Newton step crossed two slip boundaries it did not yet penalise and no
    length of the step ladder lowered its merit: the lane stayed put until its budget ran
    out (``not_converged``). A feasible lane now walks the deeper ladder: the equilibrium
    settles and the status and value are Ipopt's."""
    cases = [(g, row) for g, row in _cases() if row["object"].startswith("000 (plan")]
    assert len(cases) >= 2
    res = jaxgrasp.evaluate_batch([g for g, _ in cases], chunk_size=4)
    for k, (_, row) in enumerate(cases):
        assert int(res.equilibrium_status[k]) == LaneStatus.CONVERGED, row["object"]
        assert jaxgrasp.GraspStatus.labels()[int(res.status[k])] == row["ipopt_status"], row["object"]
        assert abs(float(res.value[k]) - row["ipopt_value"]) <= REL * abs(row["ipopt_value"]) + 1e-15


STALLED = Path(__file__).resolve().parent.parent / "data" / "settle_stalled_points.json"


def _stalled_equilibria():
    """``[(row, ProblemData, SolverResult)]``: each stored stalled equilibrium lane, rebuilt."""
    import jax.numpy as jnp

    from jaxgrasp.model._potential import model_params
    from jaxgrasp.solver._solver import SolverResult
    from jaxgrasp.tolerance._problems import constraints, objective, problem_data

    out = []
    for row in json.loads(STALLED.read_text(encoding="utf-8"))["points"]:
        data = problem_data(model_params(jaxgrasp.Grasp.create(**row["grasp"])))
        z = jnp.asarray(row["z"])
        n3 = 3 * row["fingers"]
        eq = SolverResult(
            x=z, lam=jnp.zeros(n3), nu=jnp.zeros(()), objective=objective(z, data),
            status=jnp.asarray(LaneStatus.NOT_CONVERGED, jnp.int32),
            stationarity=jnp.asarray(row["stationarity"]),
            feasibility=jnp.max(jnp.maximum(-constraints(z, data), 0.0)),
            complementarity=jnp.zeros(()), steps=jnp.asarray(300, jnp.int32),
        )
        out.append((row, data, eq))
    return out


def test_a_stalled_equilibrium_far_from_its_multipliers_is_certified_on_its_boundary():
    """``random_urdfs`` 073 (3 fingers): the augmented Lagrangian stalled beside the slip
    boundaries of contacts 1 and 2 with one slip multiplier at 9.4e3 (the minimum's are
    2e-2 and 4). From multipliers 0 the settling stage's Newton polish wandered off towards
    contact 2's apex; from the active rows' least-squares multipliers it reaches the minimum
    on both slip boundaries, with positive multipliers: the equilibrium lies on the edge of
    the region, so the grasp is unstable, as Ipopt says (value 0)."""
    import jax
    import jax.numpy as jnp

    from jaxgrasp.solver._solver import SolverOptions, kkt_tol
    from jaxgrasp.tolerance import _settle
    from jaxgrasp.tolerance._problems import constraints

    o = SolverOptions()
    tol = kkt_tol(jnp.float64, o)
    for row, data, eq in _stalled_equilibria():
        n = row["fingers"]
        none = jnp.zeros(n, bool)
        cold = _settle._polish(data, eq.x, _settle.NO_EQUALITY, none, jnp.asarray(False), o)
        assert not bool(cold[2]), row["object"]  # the polish from 0 alone: no certificate
        batch = lambda t: jax.tree_util.tree_map(lambda a: a[None], t)  # noqa: E731
        settled = jax.tree_util.tree_map(lambda a: a[0], _settle.settle_equilibrium(batch(data), batch(eq), o))
        assert int(settled.status) == LaneStatus.CONVERGED, row["object"]
        assert max(float(settled.stationarity), float(settled.feasibility), float(settled.complementarity)) <= tol
        g = np.asarray(constraints(settled.x, data)).reshape(3, n)
        lam = np.asarray(settled.lam).reshape(3, n)
        assert np.all(g >= -tol)
        on = np.abs(g[1]) <= tol  # the slip rows held: contacts 1 and 2
        assert on.tolist() == [False, True, True], (row["object"], g)
        assert np.all(lam[1, on] > 0.0)  # friction at its limit: the energy presses on both
        assert np.all(np.abs(lam[0]) <= tol) and np.all(np.abs(lam[2]) <= tol) and abs(lam[1, 0]) <= tol
        # lower than where it stalled: the polish went down to the minimum, not up
        assert float(settled.objective) < float(eq.objective)
        assert row["ipopt_status"] == "unstable" and row["ipopt_value"] == 0.0
