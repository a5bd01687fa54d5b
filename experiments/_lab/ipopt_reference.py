"""``tests/ipopt_reference.py``: the test suite's independent CasADi + Ipopt reference solver (it does not use jaxgrasp), for the studies.

One implementation, shared with the tests so that the experiments measure what the tests
check: ``from _lab.ipopt_reference import ...`` is that module (loaded once under its own name,
``ipopt_reference``, so that worker processes unpickle its objects).
"""

import sys

from _lab import _from_tests

sys.modules[__name__] = _from_tests("ipopt_reference")
