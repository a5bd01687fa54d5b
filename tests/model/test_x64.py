"""``import jaxgrasp`` and JAX's float64 mode: on by default, an explicit choice left alone.

Each case runs in a fresh process (JAX reads ``JAX_ENABLE_X64`` when it starts).
``experiments/startup/x64_scope.py`` measures why the flag is process-wide rather than scoped.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

WORKER = textwrap.dedent(
    r"""
    import json, warnings
    warnings.simplefilter("error")  # a dtype warning would be a failure
    import jax, jax.numpy as jnp
    import jaxgrasp
    out = {"x64": bool(jax.config.jax_enable_x64), "user_zeros": str(jnp.zeros(3).dtype)}
    g = jaxgrasp.presets.cube(6e5, 2e-3)
    out["grasp"] = str(g.young_modulus.dtype)
    if out["x64"] is False:
        r = jaxgrasp.evaluate(g)
        out.update(value=float(r.value), value_dtype=str(r.value.dtype), status=r.status_name)
    print("RESULT " + json.dumps(out))
    """
)
CUBE_VALUE = 2.638202983905735e-4  # J, float64, cube E = 6e5 Pa, dr = 2 mm (test_evaluate)


pytestmark = pytest.mark.slow  # subprocesses


def _run(env_value):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("JAX_ENABLE_X64", None)
    if env_value is not None:
        env["JAX_ENABLE_X64"] = env_value
    proc = subprocess.run([sys.executable, "-c", WORKER], env=env, capture_output=True, text=True, timeout=600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, proc.stderr[-3000:]
    return json.loads(lines[0][len("RESULT ") :])


def test_import_turns_float64_on_for_the_process():
    out = _run(None)
    assert out["x64"] is True
    assert out["grasp"] == "float64"
    assert out["user_zeros"] == "float64"  # the documented side effect on the user's own code


@pytest.mark.parametrize("value", ["1", "true"])
def test_explicit_float64_stays(value):
    assert _run(value)["x64"] is True


def test_explicit_float32_is_left_alone_and_works():
    """JAX_ENABLE_X64=0 keeps JAX in float32: grasps and results are float32 without a
    dtype warning, and the cube's value is within 1e-2 of float64's (test_precision)."""
    out = _run("0")
    assert out["x64"] is False
    assert out["grasp"] == "float32"
    assert out["user_zeros"] == "float32"
    assert out["value_dtype"] == "float32"
    assert out["status"] == "stable"
    assert abs(out["value"] - CUBE_VALUE) / CUBE_VALUE < 1e-2
