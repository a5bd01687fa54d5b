"""Tests of the ``jaxgrasp`` command line (``jaxgrasp.cli``).

Most calls run ``jaxgrasp.cli.main`` in-process (the evaluator compiles once per session);
one test runs the installed console script in a subprocess, on a warm cache.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest
from conftest import assert_same_numbers, without_compile_reports

import jaxgrasp
from jaxgrasp import cli

ROOT = Path(__file__).resolve().parents[2]
CUBE_TOML = ROOT / "examples" / "cube.toml"
PRESET_ARGS = ["evaluate", "--preset", "cube", "--young-modulus", "6e5", "--initial-deformation", "0.002", "--json"]


@pytest.fixture(scope="module")
def expected_cube(preset_json):
    """What the CLI must print for the paper's cube at E = 6e5 Pa, dr = 2 mm (computed
    after the first CLI run, which shares its compiled evaluator)."""
    grasp = jaxgrasp.presets.cube(6e5, 0.002)
    eps = jaxgrasp.epsilon(grasp)  # the Ferrari-Canny metric beside the value (issue 15)
    return jaxgrasp.evaluate(grasp).to_dict() | {"epsilon": float(eps.value), "force_closure": bool(eps.force_closure)}


@pytest.fixture(scope="module")
def preset_json(cache_dir):
    """JSON printed by an in-process ``jaxgrasp evaluate --preset cube ... --json``."""
    mp = pytest.MonkeyPatch()
    mp.setenv("JAXGRASP_CACHE_DIR", str(cache_dir))
    try:
        import io
        from contextlib import redirect_stderr, redirect_stdout

        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            rc = cli.main(PRESET_ARGS)
    finally:
        mp.undo()
    return rc, out.getvalue(), err.getvalue()


def test_evaluate_preset_json(preset_json, expected_cube):
    rc, out, err = preset_json
    assert rc == 0, err
    assert without_compile_reports(err) == ""
    d = json.loads(out)
    for key in ("value", "status", "equilibrium_energy", "limiting", "boundaries"):
        assert key in d
    assert set(d["limiting"]) == {"kind", "contact"}
    assert d["limiting"]["kind"] in jaxgrasp.model.BoundaryKind.labels() and d["limiting"]["contact"] in (0, 1)
    assert len(d["boundaries"]) == 4
    for b in d["boundaries"]:
        assert {"kind", "contact", "energy", "translation", "rotation"} <= set(b)
        assert len(b["translation"]) == 3 and len(b["rotation"]) == 3
    assert {(b["kind"], b["contact"]) for b in d["boundaries"]} == {
        (k, j) for k in jaxgrasp.model.BoundaryKind.labels() for j in (0, 1)
    }
    assert d["status"] == "stable"
    assert d["force_closure"] is True and d["epsilon"] > 0
    # exactly the library's numbers (JSON round-trips floats exactly)
    assert d == expected_cube
    assert d["value"] == expected_cube["value"] and d["value"] > 0


def test_evaluate_file_matches_preset(run_cli, preset_json):
    """``examples/cube.toml`` is ``--preset cube`` (issue 35: a name means one grasp), and
    the overrides reach the grasp: E = 6e5 Pa gives another value than the file's 2e5."""
    rc, out, err = run_cli(["evaluate", CUBE_TOML, "--json"])
    assert rc == 0, err
    rc, preset_out, err = run_cli(["evaluate", "--preset", "cube", "--json"])
    assert rc == 0, err
    assert json.loads(out) == json.loads(preset_out)
    assert json.loads(out)["value"] < json.loads(preset_json[1])["value"]


def test_evaluate_summary_text(run_cli, expected_cube):
    rc, out, err = run_cli(["evaluate", CUBE_TOML, "--young-modulus", "6e5"])  # the file is E = 2e5 Pa
    assert rc == 0, err
    assert "status: stable" in out
    assert f"{expected_cube['value']:.6e}" in out
    lim = expected_cube["limiting"]
    assert f"{lim['kind']} of contact {lim['contact']}" in out
    assert f"epsilon: {expected_cube['epsilon']:.6e}   (Ferrari-Canny, 8 cone edges, soft fingers; force closure)" in out


def test_overrides_apply(run_cli):
    """--mass etc. reach the grasp: the heavy cube is reported unstable with value 0."""
    rc, out, err = run_cli(["evaluate", "--preset", "cube", "--mass", "1.0", "--json"])
    assert rc == 0, err
    d = json.loads(out)
    assert d["status"] == "unstable" and d["value"] == 0.0 and d["limiting"] is None


@pytest.mark.parametrize(
    "argv, mentions",
    [
        (["evaluate", "/nonexistent/dir/grasp.toml"], "no such file"),
        (["evaluate", "--preset", "cube", "--initial-deformation", "0.025"], "initial_deformation"),
        (["evaluate", "--preset", "cube", "--initial-deformation", "0.03"], "initial_deformation"),
        (["evaluate", "--preset", "cube", "--young-modulus=-2e5"], "young_modulus"),
        (["evaluate", "--preset", "cube", "--young-modulus", "-200000"], "young_modulus"),
        (["evaluate", "--preset", "cube", "--bogus-option"], "--bogus-option"),
        (["evaluate"], "--preset"),
        (["evaluate", CUBE_TOML, "--preset", "cube"], "--preset"),
        (["evaluate", "--preset", "sphere"], "sphere"),
        (["evaluate", "--preset", "cube", "--young-modulus", "stiff"], "stiff"),
        ([], "evaluate"),
    ],
    ids=[
        "missing-file",
        "dr-equals-radius",
        "dr-above-radius",
        "negative-E",
        "negative-E-int",
        "unknown-option",
        "no-source",
        "two-sources",
        "unknown-preset",
        "non-numeric",
        "no-command",
    ],
)
def test_bad_input_exit_2_one_line(run_cli, argv, mentions):
    rc, out, err = run_cli(argv)
    assert rc == 2, (out, err)
    assert out == ""
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxgrasp: error:"), err
    assert mentions in lines[0]


def test_console_script_subprocess(warm_cache, preset_json):
    """The installed entry point (or ``python -m jaxgrasp.cli``) prints the same JSON,
    and starts warm (issue 13): on the program a library process stored (conftest's
    ``warm_cache``) it neither traces nor compiles (no new stored program, no new XLA
    cache entry)."""
    script = Path(sys.executable).with_name("jaxgrasp")
    if script.exists():
        cmd = [str(script)]
    elif shutil.which("jaxgrasp"):
        cmd = [shutil.which("jaxgrasp")]
    else:
        cmd = [sys.executable, "-m", "jaxgrasp.cli"]
    before = warm_cache.program_files()
    proc = warm_cache.run(cmd + [*PRESET_ARGS[:1], str(CUBE_TOML), *PRESET_ARGS[3:]])  # the file, E = 6e5 Pa
    assert "Traceback" not in proc.stderr
    assert_same_numbers(json.loads(proc.stdout), json.loads(preset_json[1]))  # to the last digit on a CPU
    assert warm_cache.program_files() == before


@pytest.mark.parametrize("overrides", [["--young-modulus", "5e6", "--friction", "0.1"],
                                       ["--young-modulus=-5", "--friction", "nan"]], ids=["valid", "invalid"])
def test_show_hand_rejects_overrides(run_cli, tmp_path, overrides):
    """``show --hand FILE``: the hand grasp file sets the fingertips and the object, so the
    overrides are refused (one line naming them, exit 2, nothing drawn), not ignored."""
    out = tmp_path / "hand.png"
    rc, stdout, err = run_cli(["show", "--hand", ROOT / "examples" / "hands" / "two_finger" / "pinch.toml",
                               "--out", out, *overrides])
    assert rc == 2 and stdout == "", err
    assert err.splitlines() == [err.strip()] and err.startswith("jaxgrasp: error: --young-modulus, --friction: "), err
    assert "not used with a hand grasp file" in err and not out.exists()
