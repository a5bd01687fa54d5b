"""The settling policy (:mod:`jaxgrasp.engine._settling`): one settle-then-retry rule for
one grasp and for a chunk, checked on made-up results (no solve)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgrasp.engine._settling import INLINE, RETRY, check_settle, settle_then_retry
from jaxgrasp.solver._status import LaneStatus

NC = LaneStatus.NOT_CONVERGED
OK = LaneStatus.CONVERGED


def _results(boundary, equilibrium, value):
    """Evaluation-like fields: ``boundary_status (B, 2, 1)``, ``equilibrium_status (B,)``, ``value (B,)``."""
    return {"boundary_status": np.asarray(boundary), "equilibrium_status": np.asarray(equilibrium),
            "value": np.asarray(value, dtype=np.float64)}


def test_check_settle_names_the_policies():
    assert check_settle(INLINE) is True and check_settle(RETRY) is False
    with pytest.raises(ValueError, match="settle must be one of inline, retry"):
        check_settle("sweep")


def test_nothing_unsettled_returns_the_first_results_untouched():
    first = _results([[[OK], [OK]]] * 3, [OK] * 3, [1.0, 2.0, 3.0])
    assert settle_then_retry(first, lambda rows: pytest.fail("evaluated again")) is first


def test_only_the_unsettled_real_rows_are_taken_from_the_retry():
    first = _results([[[OK], [OK]], [[NC], [OK]], [[OK], [OK]], [[NC], [OK]]], [OK, OK, NC, OK],
                     [1.0, 2.0, 3.0, 4.0])
    asked = []

    def again(rows):
        asked.append(rows.tolist())
        return _results([[[OK], [OK]]] * (rows.size + 1), [OK] * (rows.size + 1), [10.0 + r for r in rows.tolist()] + [99.0])

    out = settle_then_retry(first, again, count=3)  # row 3 is padding: never retried
    assert asked == [[1, 2]]
    np.testing.assert_array_equal(out["value"], [1.0, 11.0, 12.0, 4.0])
    np.testing.assert_array_equal(out["equilibrium_status"], [OK, OK, OK, OK])
    np.testing.assert_array_equal(first["value"], [1.0, 2.0, 3.0, 4.0])  # the input is not written to


def test_one_grasp_takes_its_retry_whole():
    first = _results([[NC], [OK]], OK, 1.0)
    redone = _results([[OK], [OK]], OK, 5.0)
    assert settle_then_retry(first, lambda rows: redone) is redone
