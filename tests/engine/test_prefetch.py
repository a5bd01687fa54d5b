"""jaxgrasp.engine._prefetch: a module imported in a background thread, a failing one ignored."""

from __future__ import annotations

import sys
import time

from jaxgrasp.engine._prefetch import prefetch


def _wait_for(name: str, seconds: float = 10.0) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if name in sys.modules:
            return True
        time.sleep(0.01)
    return False


def test_prefetch_imports_the_module_in_the_background():
    name = "xml.dom.minidom"  # stdlib, imported by nothing in jaxgrasp
    sys.modules.pop(name, None)  # a leaf module: imported afresh below
    prefetch(name)
    assert _wait_for(name)


def test_prefetch_of_a_missing_module_raises_nothing():
    prefetch("jaxgrasp_no_such_module")  # the thread's ImportError is left to a later import
    time.sleep(0.2)
    assert "jaxgrasp_no_such_module" not in sys.modules
