"""Every process starts warm (issue 13): ``JAXGRASP_CACHE_DIR`` turns the caches on at
``import jaxgrasp``, a concrete :func:`jaxgrasp.evaluate` stores its traced program, and
a later process loads it instead of tracing and compiling.

The ``warm_cache`` fixture (conftest) fills a folder in one cold library process; a
second library process here loads from it, and ``test_cli.py``'s console-script test
runs ``jaxgrasp evaluate examples/cube.toml`` on it (neither tracing nor compiling).
"""

from __future__ import annotations

import numpy as np

import jaxgrasp
from jaxgrasp.cache import EXPORT_SUBDIR
from jaxgrasp.result import FIELDS


def test_variable_turns_the_caches_on(warm_cache):
    assert warm_cache.first["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    files = warm_cache.program_files()
    assert any(f.startswith(EXPORT_SUBDIR) for f in files), files  # the traced program
    assert any(f.startswith("jit_evaluate_stored-") for f in files), files  # its XLA executable


def test_second_process_loads_the_same_program(warm_cache):
    """Deserialized, not traced, and the same numbers bit for bit as the first process
    and as this process's own evaluate (the stored program is the jit path's)."""
    second = warm_cache.evaluate_in_new_process()
    assert second["stats"] == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
    for f in FIELDS:
        mine = np.asarray(getattr(here, f))
        for other in (warm_cache.first, second):
            np.testing.assert_array_equal(np.asarray(other["fields"][f], dtype=mine.dtype), mine, err_msg=f)
