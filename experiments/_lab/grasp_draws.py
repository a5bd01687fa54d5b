"""``tests/grasp_draws.py``: the test suite's seeded, physically sensible random grasps, for the studies.

One implementation, shared with the tests so that the experiments measure what the tests
check: ``from _lab.grasp_draws import ...`` is that module, run under the name
``_lab.grasp_draws`` (so that worker processes find it by that name).
"""

from _lab import _from_tests

_from_tests("grasp_draws", __name__)  # replaces this module in sys.modules
