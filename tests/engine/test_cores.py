"""One JAX CPU device per core (:mod:`jaxgrasp.engine._devices`): what ``import jaxgrasp`` sets, and
where it leaves the user's choice alone.

JAX fixes its devices when its backends start, so each case imports jaxgrasp in a fresh
subprocess (about 1 s each) and reports ``jax.device_count()``.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from jaxgrasp.engine import _devices as cores

PROBE = "import jax, jaxgrasp; print(jax.device_count())"


def _devices(code: str = PROBE, **env_over) -> int:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES", cores.ENV_VAR)}
    env.update(env_over, JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return int(out.stdout.split()[-1])


@pytest.mark.slow  # a subprocess
def test_one_device_per_usable_core():
    assert _devices() == cores.usable_cores()


@pytest.mark.slow  # a subprocess
def test_environment_variable_sets_the_number():
    assert _devices(JAXGRASP_CPU_DEVICES="3") == 3
    assert _devices(JAXGRASP_CPU_DEVICES="1") == 1


@pytest.mark.slow  # a subprocess
def test_jax_settings_of_the_user_are_kept():
    assert _devices(XLA_FLAGS="--xla_force_host_platform_device_count=3") == 3
    assert _devices(JAX_NUM_CPU_DEVICES="5") == 5
    set_first = "import jax; jax.config.update('jax_num_cpu_devices', 4); " + PROBE
    assert _devices(set_first) == 4


@pytest.mark.slow  # a subprocess
def test_backends_already_running_are_left_alone():
    ran_first = "import jax; jax.numpy.ones(1).block_until_ready(); " + PROBE
    assert _devices(ran_first) == 1  # JAX's own single CPU device; the import does not fail


@pytest.mark.parametrize("text", ["0", "-2", "two", "1.5", ""])
def test_bad_count_is_a_one_line_error(text):
    with pytest.raises(ValueError, match=f"^{cores.ENV_VAR} must be a positive integer"):
        cores.requested_cpu_devices({cores.ENV_VAR: text})


def test_requested_count():
    assert cores.requested_cpu_devices({cores.ENV_VAR: "7"}) == 7
    assert cores.requested_cpu_devices({}) == cores.usable_cores() >= 1
