"""Every process starts warm (issue 13): ``JAXGRASP_CACHE_DIR`` turns the caches on at
``import jaxgrasp``, a concrete :func:`jaxgrasp.evaluate` stores its traced program, and
a later process, the library's or the ``jaxgrasp`` command's, loads it instead of
tracing and compiling.

Three short subprocesses on the cube share one empty cache folder: the first traces and
compiles (about 10 s on 2 cores), the other two load (about 2 s each).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.cache import ENV_VAR, EXPORT_SUBDIR
from jaxgrasp.result import FIELDS

ROOT = Path(__file__).resolve().parent.parent
CUBE_TOML = ROOT / "examples" / "cube.toml"  # the same grasp as CUBE below

LIBRARY_RUN = f"""
import json
import numpy as np
import jaxgrasp
r = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
fields = {{f: np.asarray(getattr(r, f)).tolist() for f in {FIELDS!r}}}
print(json.dumps({{"stats": jaxgrasp.cache.stats(), "fields": fields}}))
"""


def _run(argv, cache_dir: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, **{ENV_VAR: str(cache_dir)})
    proc = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=str(ROOT), timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def _program_files(cache_dir: Path) -> set[str]:
    """The stored evaluator's files: its exported programs and its XLA executables."""
    exported = {f"{EXPORT_SUBDIR}/{p.name}" for p in (cache_dir / EXPORT_SUBDIR).glob("evaluate-*")}
    return exported | {p.name for p in cache_dir.glob("jit_evaluate_stored-*")}


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory):
    """A cache folder filled by a library process that only set ``JAXGRASP_CACHE_DIR``;
    ``(folder, that process's output)``."""
    folder = tmp_path_factory.mktemp("warm") / "cache"  # not there yet: jaxgrasp creates it
    proc = _run([sys.executable, "-c", LIBRARY_RUN], folder)
    return folder, json.loads(proc.stdout)


def test_variable_turns_the_caches_on(warm_cache):
    folder, first = warm_cache
    assert first["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    files = _program_files(folder)
    assert any(f.startswith(EXPORT_SUBDIR) for f in files), files  # the traced program
    assert any(f.startswith("jit_evaluate_stored-") for f in files), files  # its XLA executable


def test_second_process_loads_the_same_program(warm_cache):
    """Deserialized, not traced, and the same numbers bit for bit as the first process
    and as this process's own evaluate (the stored program is the jit path's)."""
    folder, first = warm_cache
    second = json.loads(_run([sys.executable, "-c", LIBRARY_RUN], folder).stdout)
    assert second["stats"] == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    here = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
    for f in FIELDS:
        mine = np.asarray(getattr(here, f))
        for other in (first, second):
            np.testing.assert_array_equal(np.asarray(other["fields"][f], dtype=mine.dtype), mine, err_msg=f)


def test_command_runs_warm(warm_cache):
    """``jaxgrasp evaluate examples/cube.toml`` finds the library's stored program: it
    neither traces (no new exported program) nor compiles (no new XLA executable)."""
    folder, first = warm_cache
    before = _program_files(folder)
    proc = _run([sys.executable, "-m", "jaxgrasp", "evaluate", str(CUBE_TOML), "--json"], folder)
    assert _program_files(folder) == before
    assert json.loads(proc.stdout)["value"] == first["fields"]["value"]
