"""Every process starts warm (issue 13): ``JAXGRASP_CACHE_DIR`` turns the caches on at
``import jaxgrasp``, a concrete :func:`jaxgrasp.evaluate` stores its compiled program,
and a later process loads it instead of tracing and compiling.

The ``warm_cache`` fixture (conftest) fills a folder in one cold library process; a
second library process here loads from it, and ``test_cli.py``'s console-script test
runs ``jaxgrasp evaluate examples/cube.toml`` on it (neither tracing nor compiling).
"""

from __future__ import annotations

import shutil

import numpy as np

import jaxgrasp
from jaxgrasp.cache import PROGRAM_SUBDIR
from jaxgrasp.result import FIELDS


def _assert_same_fields(a: dict, b) -> None:
    """``a``: fields as a process printed them; ``b``: an Evaluation. Bit for bit."""
    for f in FIELDS:
        mine = np.asarray(getattr(b, f))
        np.testing.assert_array_equal(np.asarray(a["fields"][f], dtype=mine.dtype), mine, err_msg=f)


def test_variable_turns_the_caches_on(warm_cache):
    assert warm_cache.first["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    files = warm_cache.program_files()
    assert any(f.startswith(PROGRAM_SUBDIR) for f in files), files  # the compiled program
    assert any(f.startswith("jit_evaluate_fields-") for f in files), files  # XLA's cache entry


def test_second_process_loads_the_same_program(warm_cache):
    """Loaded, not traced, and the same numbers bit for bit as the first process and as
    this process's own evaluate (the stored program is the jit path's)."""
    second = warm_cache.evaluate_in_new_process()
    assert second["stats"] == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
    for other in (warm_cache.first, second):
        _assert_same_fields(other, here)


def test_program_from_xla_cache_is_not_stored(warm_cache, tmp_path):
    """Without the stored program but with XLA's cache entry (e.g. a store gone stale), a
    process traces and XLA's cache serves the compilation. Such an executable cannot be
    serialized again on the CPU (the file would load, then fail for missing kernels), so
    it is not stored: the next process traces again and still gets the same numbers.

    XLA's cache key depends on the folder's path, so the folder is the fixture's own, its
    stored programs moved aside meanwhile."""
    programs = warm_cache.folder / PROGRAM_SUBDIR
    aside = tmp_path / "aside"
    shutil.move(programs, aside)
    try:
        here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
        for _ in range(2):
            run = warm_cache.evaluate_in_new_process()
            assert run["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
            assert not programs.exists() or not any(programs.iterdir())
            _assert_same_fields(run, here)
    finally:
        shutil.rmtree(programs, ignore_errors=True)
        shutil.move(aside, programs)
