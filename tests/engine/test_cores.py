"""One JAX CPU device per core (:mod:`jaxgrasp.engine._devices`): what jaxgrasp's first use
or :func:`jaxgrasp.configure` sets, where it leaves the user's choice alone, and that
``import jaxgrasp`` alone sets nothing.

JAX fixes its devices when its backends start, so each case runs in a fresh subprocess
and reports ``jax.device_count()``.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from jaxgrasp.engine import _devices as cores

PROBE = "import jax, jaxgrasp; jaxgrasp.configure(); print(jax.device_count())"
FIRST_USE = "import jax, jaxgrasp; jaxgrasp.engine.plan_chunks(8); print(jax.device_count())"
IMPORT_ONLY = "import jax, jaxgrasp; print(jax.device_count())"


def _devices(code: str = PROBE, **env_over) -> int:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES", cores.ENV_VAR)}
    env.update(env_over, JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return int(out.stdout.split()[-1])


@pytest.mark.slow  # a subprocess
def test_one_device_per_usable_core():
    assert _devices() == cores.usable_cores()
    assert _devices(FIRST_USE) == cores.usable_cores()  # a batch's plan is a first use


@pytest.mark.slow  # a subprocess
def test_the_import_alone_leaves_jax_devices_alone():
    assert _devices(IMPORT_ONLY, JAXGRASP_CPU_DEVICES="3") == 1


@pytest.mark.slow  # a subprocess
def test_configure_sets_the_number():
    assert _devices("import jax, jaxgrasp; print(jaxgrasp.configure(cpu_devices=3)['cpu_devices'], "
                    "jax.device_count())") == 3


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
    assert _devices(ran_first) == 1  # JAX's own single CPU device; configure does not fail


@pytest.mark.slow  # a subprocess
def test_the_first_name_used_chooses_the_devices():
    """A preset grasp is a JAX array, but using ``jaxgrasp.presets`` (a name of the face)
    asked for the devices first: the script's batches run on every core."""
    code = "import jax, jaxgrasp; g = jaxgrasp.presets.cube(6e5, 2e-3); print(jax.device_count())"
    assert _devices(code, JAXGRASP_CPU_DEVICES="3") == 3
    assert _devices("import jax, jaxgrasp; jaxgrasp.load; print(jax.device_count())", JAXGRASP_CPU_DEVICES="3") == 3


@pytest.mark.slow  # a subprocess
def test_a_batch_after_jax_made_its_devices_says_so_once(tmp_path):
    """The program's own JAX array came first: JAX has made one CPU device before the first
    batch, which runs on it and says once, on the ``"jaxgrasp"`` logger, how to get more."""
    code = ("import jax, jaxgrasp; jax.numpy.ones(1).block_until_ready(); g = jaxgrasp.presets.cube(6e5, 2e-3); "
            "jaxgrasp.engine.plan_chunks(8); jaxgrasp.engine.plan_chunks(8); print(jax.device_count())")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES")}
    env.update(JAXGRASP_CPU_DEVICES="3", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.split()[-1] == "1", out.stderr[-2000:]
    assert out.stderr.splitlines() == [
        "jaxgrasp: JAX made its devices before jaxgrasp's first use: batches run on 1 CPU device, not 3; "
        "call jaxgrasp.configure() before the first JAX computation to use 3"], out.stderr


@pytest.mark.parametrize("text", ["0", "-2", "two", "1.5", ""])
def test_bad_count_is_a_one_line_error(text):
    with pytest.raises(ValueError, match=f"^{cores.ENV_VAR} must be a positive integer"):
        cores.requested_cpu_devices({cores.ENV_VAR: text})


def test_requested_count():
    assert cores.requested_cpu_devices({cores.ENV_VAR: "7"}) == 7
    assert cores.requested_cpu_devices({}) == cores.usable_cores() >= 1
