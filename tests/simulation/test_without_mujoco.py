"""Without the extra jaxgrasp[sim]: the package imports, and simulate says what to install.

MuJoCo's absence is simulated by ``sys.modules["mujoco"] = None`` (an import of it then
raises ImportError), with the simulation package imported afresh under it.
"""

from __future__ import annotations

import importlib
import sys

import pytest

import jaxgrasp


def test_without_mujoco_import_works_and_simulate_says_what_to_install(monkeypatch):
    from jaxgrasp import _startup, engine

    # the package's face runs again; its process-wide set-up (the session's executable
    # store, JAX's devices, the command's interrupt handler) stays as the session made it
    for module, name in ((engine, "enable_from_environment"), (engine, "configure_cpu_devices"),
                         (_startup, "install_if_command_line")):
        monkeypatch.setattr(module, name, lambda: None)
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco -> ImportError
    for name in [m for m in sys.modules if m == "jaxgrasp" or m.startswith("jaxgrasp.simulation")]:
        monkeypatch.delitem(sys.modules, name)
    fresh = importlib.import_module("jaxgrasp")  # the package's face, run again without mujoco
    assert "simulate" in fresh.__all__
    with pytest.raises(ImportError) as info:
        fresh.simulate(jaxgrasp.presets.cube())
    assert str(info.value) == 'jaxgrasp.simulate needs MuJoCo: pip install "jaxgrasp[sim]"'


def test_the_command_says_what_to_install(monkeypatch, run_cli, tmp_path):
    monkeypatch.setitem(sys.modules, "mujoco", None)
    code, _, err = run_cli(["simulate", "--preset", "cube", "--out", str(tmp_path / "sim")])
    assert code == 2
    assert err.strip() == 'jaxgrasp: error: jaxgrasp.simulate needs MuJoCo: pip install "jaxgrasp[sim]"'
    assert not (tmp_path / "sim").exists()
