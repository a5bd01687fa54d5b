"""Every process starts warm (issues 13, 35 and 64): jaxgrasp's first use turns on the
executable store in the user's cache folder (``import jaxgrasp`` writes nothing), a concrete :func:`jaxgrasp.evaluate` stores
its compiled program (and reports its compilation on the ``jaxgrasp`` logger), and a later
process loads it instead of tracing and compiling.

The ``warm_cache`` fixture (conftest) fills the cache of a fresh home folder in one cold
library process; a second library process here loads from it, and ``test_cli.py``'s
console-script test runs ``jaxgrasp evaluate examples/cube.toml`` on it (neither tracing
nor compiling).
"""

from __future__ import annotations

import stat

import numpy as np
import pytest
from conftest import WarmCache, assert_same_numbers

import jaxgrasp
from jaxgrasp.engine._store import EXECUTABLE_SUBDIR
from jaxgrasp.tolerance._result import FIELDS


def _assert_same_fields(a: dict, b) -> None:
    """``a``: fields as a process printed them; ``b``: an Evaluation. Bit for bit on a CPU
    (:func:`conftest.assert_same_numbers`)."""
    for f in FIELDS:
        mine = np.asarray(getattr(b, f))
        assert_same_numbers(np.asarray(a["fields"][f], dtype=mine.dtype), mine, f)


def test_first_use_turns_the_store_on(warm_cache):
    """With no environment set, the first process stores its compiled program in
    ``~/.cache/jaxgrasp/xla/jaxgrasp-executables``, every folder it made private, and
    says once, on the ``jaxgrasp`` logger, what it compiled, why and where it stores it.
    XLA's own cache is not turned on by the first use: no entry of the program there."""
    first = warm_cache.first
    assert first["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    files = warm_cache.program_files()
    assert any(f.startswith(EXECUTABLE_SUBDIR) for f in files), files  # the compiled program
    assert not any(f.startswith("jit_evaluate_fields-") for f in files), files  # no XLA entry
    for folder in (warm_cache.home / ".cache", warm_cache.folder, warm_cache.folder / EXECUTABLE_SUBDIR):
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700, folder
    reports = [line for line in first["log"].splitlines() if "compiling" in line]
    assert reports == [(
        "jaxgrasp INFO jaxgrasp: compiling evaluate for 2 contacts (no stored executable yet); "
        f"it will be stored in {warm_cache.folder / EXECUTABLE_SUBDIR}"
    )], first["log"]


def test_second_process_loads_the_same_program(warm_cache):
    """Loaded, not traced, and the same numbers bit for bit as the first process and as
    this process's own evaluate (the stored program is the jit path's)."""
    second = warm_cache.evaluate_in_new_process()
    assert second["stats"] == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    assert "compiling" not in second["log"], second["log"]
    here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
    for other in (warm_cache.first, second):
        _assert_same_fields(other, here)


@pytest.mark.slow  # compiles cold against caches of its own
def test_program_from_xla_cache_is_not_stored(tmp_path):
    """A process whose program store is off (XLA's cache on) leaves XLA's cache entry of
    the cube's program. A later process with both on finds no stored program, traces,
    and XLA's cache serves the compilation. Such an executable cannot be serialized again
    on the CPU (the file would load, then fail for missing kernels), so it is not
    stored: the next process traces again and still gets the same numbers."""
    cache = WarmCache(tmp_path, {})
    folder = cache.folder
    programs = folder / EXECUTABLE_SUBDIR
    xla_only = cache.evaluate_in_new_process("xla")
    assert xla_only["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    assert any(p.name.startswith("jit_evaluate_fields-") for p in folder.iterdir())
    assert not programs.exists() or not any(programs.iterdir())
    here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
    for _ in range(2):
        both = cache.evaluate_in_new_process("both")
        assert both["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
        assert not programs.exists() or not any(programs.iterdir())
        _assert_same_fields(both, here)


def test_pipeline_runs_its_driver_and_is_stored(tmp_path):
    """A program built in stages (the batch engine's evaluator is one) runs its driver,
    which may call a stage twice (compiled once), and is stored and loaded whole: the
    loaded program gives the same numbers bit for bit. A stage called on other shapes
    the second time, or a stored program whose stages do not fit the driver, is refused."""
    import jax
    import jax.numpy as jnp

    from jaxgrasp.engine import _compile, _pipeline
    from jaxgrasp.engine import _store as cache

    stages = {
        "step": jax.jit(lambda x, y: (jnp.sin(x) * 2.0 + y, x + 1.0)),
        "total": jax.jit(lambda x, a, b: (a * b - x, jnp.sum(a))),
    }

    def drive(call, x):
        a, b = call("step", x, x)
        a, b = call("step", a, b)  # the same stage again
        return call("total", x, a, b)

    pipeline = _pipeline.Pipeline(stages, drive)
    spec = (jax.ShapeDtypeStruct((5,), jnp.float64),)
    x = jnp.linspace(0.0, 1.0, 5)
    want = drive(lambda name, *xs: stages[name](*xs), x)
    saved = cache.executable_dir()
    cache.set_executable_dir(tmp_path)
    try:
        key = ("test-staged", str(tmp_path))
        before = cache.stats()
        built, _ = _compile.compiled(key, lambda: pipeline, spec, name="staged", store_key=key, n_outputs=2)
        assert isinstance(built, _pipeline.Staged) and list(built.stages) == ["step", "total"]
        _compile.wait_for_saves()  # written in a thread
        stored = list(tmp_path.glob("staged-*.xla"))
        assert len(stored) == 1
        _compile.clear_compiled()
        loaded, _ = _compile.compiled(key, lambda: pipeline, spec, name="staged", store_key=key, n_outputs=2)
        after = cache.stats()
        assert after["traced"] - before["traced"] == 1 and after["deserialized"] - before["deserialized"] == 1
        assert isinstance(loaded, _pipeline.Staged)
        for fn in (built, loaded):
            got = fn(x)
            for g, w in zip(got, want):
                np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
        # a driver that calls "step" again on the scalar "total" returns: refused when
        # lowered; the stored stages (for (5,) arrays) are refused for (3,) arrays
        again = lambda call, x: call("step", *call("total", x, *call("step", x, x))[1:] * 2)
        with pytest.raises(ValueError, match="other shapes"):
            _pipeline.lower_stages(_pipeline.Pipeline(stages, again), spec)
        small = (jax.ShapeDtypeStruct((3,), jnp.float64),)
        entry = cache.executable_entry("staged", (key, 0), spec)
        assert entry.path == stored[0]
        assert cache.load_executable(entry, small, [_compile.default_device()], 2, drive) == (
            None, "its stored file does not load here (a stage takes other shapes)")
        assert cache.stats()["cache_errors"] == after["cache_errors"] + 1
    finally:
        cache.set_executable_dir(saved)
        _compile.clear_compiled()
