"""Sharding a sweep over several devices, and the sweep's stored compiled program.

JAX fixes its device count when it starts, so every sweep here runs in a subprocess:
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` gives two CPU devices. Compiling
costs about a minute on a 2-core machine, so the grid is tiny (2 E x 3 dr, 6 points); the
one-device reference is ``evaluate`` of each point in this process (the session's
``evaluate_many``, compiled already).

Checked:

* with 2 devices the sweep's compiled input/output shardings span both devices, the
  result records ``devices == 2``, and the compiled program has no cross-device
  operation (each device runs its own work queue on its half of the batch: with plain
  ``jit(vmap)`` XLA would gather the one queue that ``vmap`` folds the batch into);
* its values, statuses and limiting boundaries equal ``evaluate`` of every grid point on
  one device (statuses exactly, energies to 1e-12 relative);
* a later process with the same cache folders loads the stored compiled program instead
  of tracing and compiling (:mod:`jaxgrasp.engine._store`) and gives bit-identical results; a
  corrupt file falls back to tracing, again with identical results.

Multi-host (``jax.distributed``) is not tested here: it needs several processes with a
coordinator; the code path (``make_array_from_callback``, ``process_allgather``) is only
taken when ``jax.process_count() > 1``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from jaxgrasp.engine._plan import bucket_size

COLLECTIVES = ("all-gather", "all-reduce", "all-to-all", "collective-permute", "reduce-scatter")
"""XLA's cross-device operations: the compiled sweep must contain none (each device runs
its own work queue on its slice of the batch)."""
FIELDS = ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy")
E = (2e5, 1e6)  # Pa: the worker's grid
DR = (1e-3, 3e-3, 4.9e-3)  # m

WORKER = textwrap.dedent(
    r"""
    import json, sys, time
    from pathlib import Path
    import numpy as np
    import jax
    import jaxgrasp
    from jaxgrasp.engine import _compile, _store as cache
    from jaxgrasp.engine._evaluator import compiled_evaluator
    from jaxgrasp.engine._plan import plan_chunks
    from jaxgrasp.tolerance import EvaluateOptions
    cfg = json.loads(sys.argv[1])
    if cfg.get("xla_cache"):
        jax.config.update("jax_compilation_cache_dir", cfg["xla_cache"])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    if cfg.get("executable_dir"):
        cache.set_executable_dir(cfg["executable_dir"])
    E = np.array(%(E)r)
    DR = np.array(%(DR)r)
    out = {"device_count": jax.device_count(), "runs": []}
    for k, step in enumerate(cfg["steps"]):
        if step == "corrupt":
            files = sorted(Path(cfg["executable_dir"]).glob("*.xla"))
            for f in files:
                f.write_bytes(f.read_bytes()[:100] + b"not a program")
            _compile.clear_compiled()
            out["corrupted"] = len(files)
            continue
        before = cache.stats()
        r = jaxgrasp.sweep(jaxgrasp.presets.cube(), young_modulus=E, initial_deformation=DR)
        chunk = plan_chunks(r.size).chunk
        fn, _ = compiled_evaluator(EvaluateOptions(), 2, chunk, settle=False)  # the one the sweep used (memoised)
        shardings = [s for stage in fn.stages.values() for s in jax.tree_util.tree_leaves(stage.input_shardings)
                     + jax.tree_util.tree_leaves(stage.output_shardings)]
        np.savez(cfg["out"] + f"_{k}.npz", **{f: np.asarray(getattr(r, f)) for f in %(fields)r})
        out["runs"].append({
            "devices": r.devices,
            "sharding_devices": sorted({len(s.device_set) for s in shardings}),
            "collectives": sorted({op for op in %(collectives)r for stage in fn.stages.values() if op in stage.as_text()}),
            "compile_seconds": r.compile_seconds,
            "stats": {n: v - before[n] for n, v in cache.stats().items()},
        })
    print("RESULT " + json.dumps(out))
    """
    % {"fields": FIELDS, "E": E, "DR": DR, "collectives": COLLECTIVES}
)


pytestmark = pytest.mark.slow  # subprocesses with two devices


def _start(n_devices: int, cfg: dict) -> subprocess.Popen:
    env = dict(os.environ)
    flags = env.get("XLA_FLAGS", "").replace("--xla_force_host_platform_device_count", "--ignored")
    env["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n_devices}".strip()
    env["JAX_PLATFORMS"] = "cpu"
    return subprocess.Popen(
        [sys.executable, "-c", WORKER, json.dumps(cfg)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _finish(proc: subprocess.Popen) -> dict:
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr[-3000:]
    line = [s for s in stdout.splitlines() if s.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def _load(prefix: str, k: int) -> dict:
    with np.load(f"{prefix}_{k}.npz") as z:
        return {f: np.array(z[f]) for f in FIELDS}


def _assert_same(a: dict, b: dict, rtol: float) -> None:
    for f in ("status", "limiting_kind", "limiting_contact"):
        np.testing.assert_array_equal(a[f], b[f], err_msg=f)
    for f in ("value", "equilibrium_energy"):
        np.testing.assert_allclose(a[f], b[f], rtol=rtol, atol=0, err_msg=f)


def test_batch_size_is_a_multiple_of_the_devices():
    assert bucket_size(4096, 369, 1) == 1024
    assert bucket_size(4096, 369, 2) == 512
    assert bucket_size(62, 369, 2) == 62
    assert bucket_size(61, 369, 4) == 64
    assert bucket_size(4096, 1, 8) == 8


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sharding")
    cache = {"xla_cache": str(tmp / "xla"), "executable_dir": str(tmp / "xla" / "jaxgrasp-executables")}
    # a 2-device sweep that stores its program and fills the caches
    r_two = _finish(_start(2, {"steps": ["sweep"], "out": str(tmp / "two"), **cache}))
    # a later process: loads the stored program, then falls back after corruption
    again = _finish(_start(2, {"steps": ["sweep", "corrupt", "sweep"], "out": str(tmp / "again"), **cache}))
    return {"tmp": tmp, "two": r_two, "again": again}


def test_two_devices_are_used(runs):
    assert runs["two"]["device_count"] == 2
    run = runs["two"]["runs"][0]
    assert run["devices"] == 2
    assert run["sharding_devices"] == [2]  # every input and output spans both devices
    assert run["collectives"] == []  # one queue per device: nothing crosses devices
    assert run["stats"]["traced"] == 1


def test_two_devices_equal_one_device(runs, evaluate_many):
    import jaxgrasp

    grasps = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=d) for e in E for d in DR]
    refs = evaluate_many(grasps)
    one = {f: np.reshape([np.asarray(getattr(r, f)) for r in refs], (len(E), len(DR))) for f in FIELDS}
    _assert_same(_load(str(runs["tmp"] / "two"), 0), one, rtol=1e-12)
    assert len(np.unique(one["status"])) >= 2  # the tiny grid has more than one status


def test_stored_program_is_reused_bit_for_bit(runs):
    tmp = runs["tmp"]
    first = runs["again"]["runs"][0]
    assert first["stats"] == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    assert first["devices"] == 2
    assert first["compile_seconds"] < runs["two"]["runs"][0]["compile_seconds"]
    _assert_same(_load(str(tmp / "again"), 0), _load(str(tmp / "two"), 0), rtol=0)


def test_corrupt_stored_program_falls_back_to_tracing(runs):
    tmp = runs["tmp"]
    assert runs["again"]["corrupted"] == 1
    # step 1 was the corruption; step 2 the sweep after it
    second = runs["again"]["runs"][1]
    assert second["stats"] == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    _assert_same(_load(str(tmp / "again"), 2), _load(str(tmp / "two"), 0), rtol=0)
