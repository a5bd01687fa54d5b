"""The first wave of starts (``EvaluateOptions.first_wave``): which boundary problems it
settles, and that what it leaves out would not have changed their answers.

``rest_needed``'s rule is checked here on hand-made lanes, one rule per problem. On real
lanes, ``tests/tolerance/test_starts.py`` (which solves every start once, with the
compilation it needs anyway): every problem the rule settles from its first six starts
has its lowest energy, and its infeasibility, among them, and the default evaluation
gives the full run's values.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.solver._status import LaneStatus
from jaxgrasp.tolerance._stages import SAME_POINT, VALUE_MARGIN, first_wave_lanes, rest_needed

D = jaxgrasp.EvaluateOptions().num_starts
C, I, S, X = (int(LaneStatus.CONVERGED), int(LaneStatus.INFEASIBLE), int(LaneStatus.NOT_CONVERGED),
              int(LaneStatus.NO_START))


def _lanes(rows):
    """``(status, energy)``, each ``(1, len(rows) * D)``: problem ``b`` has the first-wave
    lanes ``rows[b]`` (``(status, energy)`` each, starts 0, 1, ...) and every other lane
    ``NO_START``."""
    status = np.full((len(rows), D), X, np.int32)
    energy = np.zeros((len(rows), D))
    for b, row in enumerate(rows):
        for s, (st, e) in enumerate(row):
            status[b, s], energy[b, s] = st, e
    return jnp.asarray(status.reshape(1, -1)), jnp.asarray(energy.reshape(1, -1))


# one problem per rule; N = 5 contacts make 10 problems. With U0 = 0.9 the least
# first-wave minimum above U0 is 0.1 (problem 0): it, and every problem within
# VALUE_MARGIN times it, runs all its starts.
U0 = 0.9
NEAR = U0 + 0.5 * VALUE_MARGIN * 0.1
FAR = U0 + 2.0 * VALUE_MARGIN * 0.1
RULES = [
    ("the least minimum", [(C, 1.0), (C, 1.0)], True),
    ("a minimum near the value", [(C, NEAR), (C, NEAR), (X, 0.0)], True),
    ("two at one minimum", [(C, FAR), (C, FAR * (1 + 1e-10)), (X, 0.0)], False),
    ("six at one minimum", [(C, FAR)] * 6, False),
    ("two minima", [(C, FAR), (C, FAR * 1.001)], True),
    ("one converged", [(C, FAR), (X, 0.0), (X, 0.0)], True),
    ("converged and infeasible", [(C, FAR), (C, FAR), (I, 3.0)], True),
    ("a stalled lane", [(C, FAR), (C, FAR), (S, 0.9)], True),
    ("three infeasible", [(I, 5.0), (I, 7.0), (I, 6.0), (X, 0.0)], False),
    ("one infeasible", [(I, 5.0)], True),
]


def test_rest_needed_rules():
    """Each problem's other starts run unless its first wave agrees, from two lanes, on a
    minimum far above the value."""
    need = np.asarray(rest_needed(*_lanes([r for _, r, _ in RULES]), _first(len(RULES)), D, jnp.asarray([U0])))
    need = need.reshape(len(RULES), D)
    for b, (name, _, expected) in enumerate(RULES):
        assert np.all(need[b] == expected), name


def test_same_point_is_relative_to_the_energy():
    """Energies of one minimum agree to ``SAME_POINT`` of their size (at least 1). Each
    case: the least minimum, at ``U0`` (value 0: it runs all its starts, and no other
    problem is near it), then two lanes at one point, then two ``2 SAME_POINT`` apart."""
    near, far = 0.5 * SAME_POINT, 2.0 * SAME_POINT
    for e in (1e3, 1e-3):
        rows = [[(C, 0.0), (C, 0.0)], [(C, e), (C, e + max(e, 1.0) * near)], [(C, e), (C, e + max(e, 1.0) * far)]]
        need = np.asarray(rest_needed(*_lanes(rows), _first(len(rows)), D, jnp.asarray([0.0])))
        assert need.reshape(len(rows), D)[:, 0].tolist() == [True, False, True], e


def _first(problems: int):
    """The first-wave lanes of ``problems`` boundary problems (default options)."""
    return jnp.asarray(np.tile(np.arange(D) < jaxgrasp.EvaluateOptions().first_wave, problems))


def test_first_wave_lanes():
    """The first ``first_wave`` starts of every problem; ``None`` where all run at once."""
    o = jaxgrasp.EvaluateOptions()
    first = np.asarray(first_wave_lanes(3, o)).reshape(6, D)
    assert np.all(first[:, : o.first_wave]) and not np.any(first[:, o.first_wave :])
    assert first_wave_lanes(3, dataclasses.replace(o, first_wave=None)) is None
    assert first_wave_lanes(3, dataclasses.replace(o, first_wave=D)) is None


@pytest.mark.parametrize("bad", [0, 1, -3, 2.5, True, "6"])
def test_first_wave_rejects(bad):
    with pytest.raises(ValueError, match="first_wave"):
        jaxgrasp.EvaluateOptions(first_wave=bad)


def test_a_boundary_through_the_equilibrium_sets_the_value():
    """A problem the equilibrium solves (its lanes ``at_eq``, not run) has its minimum at
    ``U0``: the value is 0, so a problem whose first wave agrees far above ``U0`` is
    settled; without it that problem would be the least and run every start."""
    rows = [[], [(C, 1.0), (C, 1.0)]]
    at_eq = np.zeros((1, 2 * D), bool)
    at_eq[0, :3] = True
    u0 = jnp.asarray([0.9])
    with_eq = np.asarray(rest_needed(*_lanes(rows), _first(2), D, u0, jnp.asarray(at_eq))).reshape(2, D)
    without = np.asarray(rest_needed(*_lanes(rows), _first(2), D, u0)).reshape(2, D)
    assert not np.any(with_eq[1]) and np.all(without[1])
