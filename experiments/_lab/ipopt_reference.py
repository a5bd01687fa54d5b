"""``tests/ipopt_reference.py``: the test suite's independent CasADi + Ipopt reference solver (it does not use jaxgrasp), for the studies.

One implementation, shared with the tests so that the experiments measure what the tests
check: ``from _lab.ipopt_reference import ...`` is that module, run under the name
``_lab.ipopt_reference`` (so that worker processes find it by that name).
"""

from _lab import _from_tests

_from_tests("ipopt_reference", __name__)  # replaces this module in sys.modules
