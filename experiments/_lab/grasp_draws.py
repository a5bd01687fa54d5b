"""``tests/grasp_draws.py``: the test suite's seeded, physically sensible random grasps, for the studies.

One implementation, shared with the tests so that the experiments measure what the tests
check: ``from _lab.grasp_draws import ...`` is that module (loaded once under its own name,
``grasp_draws``, so that worker processes unpickle its objects).
"""

import sys

from _lab import _from_tests

sys.modules[__name__] = _from_tests("grasp_draws")
