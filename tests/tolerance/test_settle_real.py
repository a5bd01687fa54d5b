"""The hardest grasps of real objects (issue 42): every program settles, and the value is Ipopt's.

``tests/data/settle_hard.json`` holds grasps of ``pybullet_data`` meshes drawn by the
planner's own code (``experiments/settling/settle_real.py``) on which, before issue 42's fix, the
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
``experiments/settling/settle_hard_data.py``).
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
        if "equality_row" in row:  # a boundary problem's lane
            continue
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
        cold = _settle._polish(data, eq.x, _settle.NO_EQUALITY, none, jnp.asarray(False), jnp.asarray(False), o)
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


def test_a_fingertip_on_its_cone_beside_one_at_its_apex_is_certified_in_cone_form():
    """``random_urdfs`` 015 (4 fingers): the force-limit problem of contact 0 stalled with
    contacts 1 and 3 both released (``d = 0``, squared slip margins -1.6e-8 and -1.3e-8,
    slip multipliers 5e3). Its minimum, Ipopt's, has contact 3 at its apex and contact 1 on
    its cone a few tenths of a micrometre deep, where the squared slip margin's gradient is
    of the order of ``d``: the polish in the squared form does not reach ``tol`` from any of
    its starts, nor pinned at both apexes. With the slip rows in cone form (and contact 3
    relaxed) it certifies the point: on contact 1's cone with a positive multiplier, contact
    3 at its apex, on the force limit, at Ipopt's energy."""
    import jax
    import jax.numpy as jnp

    from jaxgrasp.model._potential import contact_kinematics, model_params
    from jaxgrasp.solver._solver import SolverOptions, kkt_tol
    from jaxgrasp.tolerance import _settle
    from jaxgrasp.tolerance._problems import constraints, objective, problem_data, to_pose

    row = next(r for r in json.loads(STALLED.read_text(encoding="utf-8"))["points"] if r["object"] == "015")
    n, k = row["fingers"], row["equality_row"]
    data = problem_data(model_params(jaxgrasp.Grasp.create(**row["grasp"])))
    z0 = jnp.asarray(row["z"])
    o = SolverOptions()
    tol = kkt_tol(jnp.float64, o)
    released = _settle._released_contacts(data, z0, k)
    assert np.asarray(released).tolist() == [False, True, False, True]
    first = jnp.asarray([False, True, False, False])
    masks, warm = jnp.stack([first, released, first, released]), jnp.asarray([False, False, True, True])
    squared = jax.jit(jax.vmap(lambda m, w: _settle._polish(data, z0, k, m, w, jnp.asarray(False), o)))(masks, warm)
    assert not np.any(np.asarray(squared[2]))  # the squared form: no certificate, cold or warm

    polish = jax.jit(lambda z0, released: _settle._polish_released(data, z0, k, released, o))
    z, lam_rel, ok, (stat, feas, comp), relaxed, cone = polish(z0, released)
    assert bool(ok) and bool(cone)
    assert np.asarray(relaxed).tolist() == [False, False, False, True]  # contact 3 pinned at its apex
    assert max(float(stat), float(feas), float(comp)) <= tol
    g = np.asarray(constraints(z, data)).reshape(3, n)
    assert np.all(g >= -tol) and abs(g[2, 0]) <= tol  # feasible, on contact 0's force limit
    assert abs(g[1, 1]) <= tol and g[0, 1] > 1e-5  # contact 1 on its cone, pressed (d > 0)
    assert abs(g[0, 3]) <= tol and abs(g[1, 3]) <= tol  # contact 3 at its apex
    lam, nu = _settle._original_multipliers(data, z[None], lam_rel[None], jnp.asarray([k]), relaxed[None], cone[None])
    lam = np.asarray(lam[0]).reshape(3, n)
    assert lam[1, 1] > 0.0 and float(nu[0]) != 0.0

    # the cone row's multiplier mapped to the squared row's: the same force on the pose
    def cone_row(z):  # contact 1's slip row in cone form
        u = jax.vmap(lambda j: _settle._tangential(z, data, j)[0])(jnp.arange(n))
        return _settle._cone_margins(contact_kinematics(to_pose(z, data.lever), data.params), u, data.params)[1]

    def squared_row(z):
        return constraints(z, data)[n + 1]

    force_cone = float(lam_rel[n + 1]) * np.asarray(jax.grad(cone_row)(z))
    force_squared = lam[1, 1] * np.asarray(jax.grad(squared_row)(z))
    np.testing.assert_allclose(force_squared, force_cone, rtol=1e-6, atol=1e-9 * np.max(np.abs(force_cone)))
    energy = float(objective(z, data)) * float(data.scale) * 1e-3  # J
    assert abs(energy - row["ipopt_boundary_energy"]) <= 1e-6 * row["ipopt_boundary_energy"]
    assert objective(z, data) > objective(z0, data)  # the stalled point was outside the cones
