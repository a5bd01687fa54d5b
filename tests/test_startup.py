"""Issue 64, item 3: ``import jaxgrasp`` turns on float64 and changes nothing else in the
process; the ``jaxgrasp`` command answers ``--version``, ``--help`` (its own and every
sub-command's) and every argument error without loading JAX, and a package face loads
none of its modules until one of its names is used. Item 5: long library calls say what
they do on the ``"jaxgrasp"`` logger, visible by default, quiet by one documented switch.

The import and the command run in fresh subprocesses (what a process imports and writes
is the point); the messages are read in this process with ``caplog``, and once in a
subprocess where nothing configured logging.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import cli

ROOT = Path(__file__).resolve().parent.parent


def _python(args: list[str], env: dict | None = None, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], env=env, cwd=str(cwd), capture_output=True, text=True, timeout=300)


# ----------------------------------------------------------------------------- the import

IMPORT_PROBE = textwrap.dedent(
    """
    import json, signal, sys
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}  # a background job ignores SIGINT
    import jaxgrasp
    import jax
    from jax._src import xla_bridge
    print(json.dumps({
        "sigint_unchanged": signal.getsignal(signal.SIGINT) is before[signal.SIGINT],
        "sigterm_unchanged": signal.getsignal(signal.SIGTERM) is before[signal.SIGTERM],
        "x64": bool(jax.config.jax_enable_x64),
        "cpu_devices_asked": jax.config.jax_num_cpu_devices,
        "backends_started": xla_bridge.backends_are_initialized(),
        "jaxgrasp_modules": sorted(m for m in sys.modules if m.startswith("jaxgrasp")),
        "handlers": len(__import__("logging").getLogger("jaxgrasp").handlers),
    }))
    """
)


def test_import_sets_float64_and_nothing_else(tmp_path):
    """In a fresh process with an empty home folder: no file or folder is created, no
    signal handler installed, JAX's devices neither asked for nor made, no handler on the
    ``"jaxgrasp"`` logger, and nothing of jaxgrasp loaded but the package and its
    start-up module; float64 is on."""
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("JAXGRASP_CACHE_DIR", "XDG_CACHE_HOME", "JAX_ENABLE_X64",
                                                            "JAX_NUM_CPU_DEVICES", "JAXGRASP_CPU_DEVICES")}
    env.update(HOME=str(home), JAX_PLATFORMS="cpu")
    proc = _python(["-c", IMPORT_PROBE], env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.splitlines()[-1])
    assert out == {
        "sigint_unchanged": True,
        "sigterm_unchanged": True,
        "x64": True,
        "cpu_devices_asked": -1,
        "backends_started": False,
        "jaxgrasp_modules": ["jaxgrasp", "jaxgrasp._startup"],
        "handlers": 0,
    }, out
    assert sorted(p.relative_to(home).as_posix() for p in home.rglob("*")) == []
    assert proc.stderr == ""


def test_the_face_loads_a_name_when_first_used():
    """Each name of ``__all__`` and each subpackage is reachable as ``jaxgrasp.<name>``;
    an unknown name is an AttributeError (not an import of everything)."""
    assert jaxgrasp.analysis.SweepResult is jaxgrasp.analysis._sweep.SweepResult
    assert jaxgrasp.evaluate is jaxgrasp.engine.evaluate
    assert set(jaxgrasp.__all__) <= set(dir(jaxgrasp))
    assert jaxgrasp.__version__ == cli.package_version()
    with pytest.raises(AttributeError, match="no attribute 'LaneStatus'"):
        jaxgrasp.LaneStatus  # noqa: B018  moved to jaxgrasp.solver


# ----------------------------------------------------------------------------- the command without JAX


@pytest.mark.parametrize(
    "argv, status, stream, text",
    [
        (["--version"], 0, "stdout", f"jaxgrasp {cli.package_version()}"),
        (["--help"], 0, "stdout", "usage: jaxgrasp [-h] [--version]"),
        ([], 2, "stderr", "jaxgrasp: error: choose a command:"),
        (["bogus"], 2, "stderr", "jaxgrasp: error: argument command: invalid choice: 'bogus'"),
        (["--bogus"], 2, "stderr", "jaxgrasp: error: unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
    ],
)
def test_command_answers_without_jax(argv, status, stream, text):
    """``jaxgrasp --version``, ``--help``, no command, an unknown command or option: the
    answer and its status, and not one module of JAX (or NumPy) imported (``-X importtime``
    names every module a process imports)."""
    proc = _python(["-X", "importtime", "-m", "jaxgrasp", *argv])
    imported = [ln.rsplit("|", 1)[1].strip() for ln in proc.stderr.splitlines() if ln.startswith("import time:")]
    said = {"stdout": proc.stdout, "stderr": "\n".join(ln for ln in proc.stderr.splitlines()
                                                       if not ln.startswith("import time:"))}
    assert proc.returncode == status, proc.stderr[-2000:]
    assert said[stream].startswith(text), said[stream]
    assert "jaxgrasp.cli" in imported
    assert not [m for m in imported if m.split(".")[0] in ("jax", "jaxlib", "numpy")], imported


def test_the_sub_commands_are_commands():
    """``jaxgrasp --help`` lists the sub-commands of ``cli.COMMANDS``, in its order, each with
    its line (written once, there)."""
    parser = cli.build_parser()
    (sub,) = [a for a in parser._actions if a.dest == "command"]
    assert list(sub.choices) == list(cli.COMMANDS)
    assert {a.dest: a.help for a in sub._choices_actions} == cli.COMMANDS
    text = " ".join(parser.format_help().split())
    assert all(f"{name} {line}" in text for name, line in cli.COMMANDS.items())


def _run_as_command(tmp_path: Path, code: str, *args: str) -> dict:
    """Run ``code`` the way the ``jaxgrasp`` console script runs (a file named ``jaxgrasp``:
    `jaxgrasp._startup.is_command_line`, so ``import jaxgrasp`` loads no JAX), with the
    repository first on ``sys.path`` and ``args``; the JSON object it prints last."""
    script = tmp_path / "jaxgrasp"
    script.write_text(f"import sys\nsys.path.insert(0, {str(ROOT)!r})\n" + code)
    proc = _python([str(script), *args])
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.splitlines()[-1])


COMMAND_PROBE = textwrap.dedent(
    """
    import contextlib, io, json
    from jaxgrasp.cli import main

    answers = []
    for argv in json.loads(sys.argv[1]):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(argv)
            except SystemExit as exc:  # --help ends as argparse ends it
                status = exc.code
        heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("jax", "jaxlib", "numpy"))
        answers.append({"status": status, "stdout": out.getvalue(), "stderr": err.getvalue(), "heavy": heavy[:5]})
    print(json.dumps(answers))
    """
)

BAD_ARGUMENTS = {
    # per sub-command: an unknown option, a missing option value, an invalid choice, a value
    # its type= rejects; each answered with one line, as before
    "evaluate": [
        (["--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["--young-modulus"], "argument --young-modulus: expected one argument (see 'jaxgrasp evaluate --help')"),
        (["--preset", "nope"],
         "argument --preset: invalid choice: 'nope' (choose from 'cube', 'prism') (see 'jaxgrasp evaluate --help')"),
        (["--young-modulus", "x"], "argument --young-modulus: invalid float value: 'x' (see 'jaxgrasp evaluate --help')"),
    ],
    "sweep": [
        (["--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["--out"], "argument --out: expected one argument (see 'jaxgrasp sweep --help')"),
        (["--preset", "nope"],
         "argument --preset: invalid choice: 'nope' (choose from 'cube', 'prism') (see 'jaxgrasp sweep --help')"),
        (["--young-modulus", "x"], "--young-modulus: value 'x' is not a number"),  # an axis spec
        (["--mass", "0:1:20000000"],
         "--mass: range '0:1:20000000' has 20,000,000 points, more than a whole grid may have (10,000,000); split the sweep"),
    ],
    "batch": [
        (["set.npz", "--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        ([], "the following arguments are required: file (see 'jaxgrasp batch --help')"),
        (["set.npz", "--top", "x"], "argument --top: invalid int value: 'x' (see 'jaxgrasp batch --help')"),
    ],
    "tune": [
        (["--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["--param"], "argument --param: expected one argument (see 'jaxgrasp tune --help')"),
        (["--method", "nope"], ("argument --method: invalid choice: 'nope' (choose from 'scipy_lbfgsb', "
                                "'jaxopt_lbfgsb', 'projected_gradient') (see 'jaxgrasp tune --help')")),
        (["--maxiter", "x"], "argument --maxiter: invalid int value: 'x' (see 'jaxgrasp tune --help')"),
    ],
    "plan": [
        (["part.stl", "--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["part.stl", "--units"], "argument --units: expected one argument (see 'jaxgrasp plan --help')"),
        (["part.stl", "--sampler", "nope"], ("argument --sampler: invalid choice: 'nope' (choose from 'antipodal', "
                                             "'spread', 'uniform') (see 'jaxgrasp plan --help')")),
        (["part.stl", "--fingers", "x"], "argument --fingers: invalid int value: 'x' (see 'jaxgrasp plan --help')"),
    ],
    "show": [
        (["--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["--glb"], "argument --glb: expected one argument (see 'jaxgrasp show --help')"),
        (["--preset", "nope"],
         "argument --preset: invalid choice: 'nope' (choose from 'cube', 'prism') (see 'jaxgrasp show --help')"),
        (["--magnification", "x"], "argument --magnification: invalid float value: 'x' (see 'jaxgrasp show --help')"),
    ],
    "simulate": [
        (["--bogus"], "unrecognized arguments: --bogus (see 'jaxgrasp --help')"),
        (["--scales"], "argument --scales: expected one argument (see 'jaxgrasp simulate --help')"),
        (["--preset", "nope"],
         "argument --preset: invalid choice: 'nope' (choose from 'cube', 'prism') (see 'jaxgrasp simulate --help')"),
        (["--random-kicks", "x"], "argument --random-kicks: invalid int value: 'x' (see 'jaxgrasp simulate --help')"),
    ],
}
"""Argument errors of each sub-command and the line after ``jaxgrasp: error: `` of each."""


def test_every_sub_command_answers_help_and_argument_errors_without_jax(tmp_path):
    """Each sub-command's ``--help`` (status 0) and its argument errors (one line, status 2),
    through `jaxgrasp.cli.main` in the command's own process: not one module of JAX or
    NumPy loaded, before or after."""
    assert list(BAD_ARGUMENTS) == list(cli.COMMANDS)
    cases = [([name, "--help"], 0, None) for name in cli.COMMANDS]
    cases += [([name, *argv], 2, line) for name, bad in BAD_ARGUMENTS.items() for argv, line in bad]
    answers = _run_as_command(tmp_path, COMMAND_PROBE, json.dumps([argv for argv, _, _ in cases]))
    for (argv, status, line), got in zip(cases, answers, strict=True):
        assert got["heavy"] == [], (argv, got["heavy"])
        assert got["status"] == status, (argv, got)
        if line is None:
            assert got["stdout"].startswith(f"usage: jaxgrasp {argv[0]} [-h]") and got["stderr"] == "", (argv, got)
        else:
            assert got["stderr"] == f"jaxgrasp: error: {line}\n" and got["stdout"] == "", (argv, got)


FACES_PROBE = textwrap.dedent(
    """
    import importlib, json
    faces = json.loads(sys.argv[1])
    for face in faces:
        importlib.import_module(face)
    print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("jaxgrasp", "jax", "jaxlib", "numpy"))))
    """
)


def test_a_package_face_loads_no_module_until_a_name_is_used(tmp_path):
    """Importing every package face (``import jaxgrasp.engine`` ...) loads none of their
    modules: each name is loaded when first used (`jaxgrasp._startup.attach`)."""
    faces = sorted(f"jaxgrasp.{p.parent.name}" for p in (ROOT / "jaxgrasp").glob("*/__init__.py"))
    faces.remove("jaxgrasp.cli")  # it loads its parser, without JAX: the test above
    loaded = _run_as_command(tmp_path, FACES_PROBE, json.dumps(faces))
    assert loaded == sorted(["jaxgrasp", "jaxgrasp._startup", *faces]), loaded


def test_a_sub_command_error_is_still_one_line(capsys):
    """In a process where jaxgrasp is loaded already (a program calling `jaxgrasp.cli.main`),
    an argument error is the same one line."""
    assert cli.main(["evaluate", "--bogus"]) == 2
    assert capsys.readouterr().err == "jaxgrasp: error: unrecognized arguments: --bogus (see 'jaxgrasp --help')\n"


# ----------------------------------------------------------------------------- messages


def _records(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name.startswith("jaxgrasp")]


def test_first_evaluate_and_a_batch_report_on_the_logger(caplog):
    """A fresh evaluator's compilation and a batch's chunks are INFO records on the
    ``"jaxgrasp"`` logger, the lines the command prints; ``setLevel(WARNING)`` on that
    logger silences them."""
    caplog.set_level(logging.INFO, logger="jaxgrasp")
    cube = jaxgrasp.presets.cube(6e5, 0.002)
    fresh = jaxgrasp.EvaluateOptions(seed=640_005)  # no other test builds this evaluator
    jaxgrasp.evaluate(cube, options=fresh)
    said = _records(caplog)
    assert [m for m in said if m.startswith("jaxgrasp: compiling evaluate for 2 contacts")], said

    caplog.clear()
    grasps = jaxgrasp.stack([cube, jaxgrasp.presets.cube(4e5, 0.002), cube])
    first = jaxgrasp.evaluate_batch(grasps, chunk_size=1, devices=jaxgrasp.engine._plan.jax.devices()[:1])
    said = _records(caplog)
    assert said[0].startswith("jaxgrasp: evaluating 3 grasps in 3 chunks of 1"), said
    chunks = [m for m in said if m.startswith("jaxgrasp: chunk ")]
    assert [m.split(",")[0] for m in chunks] == [f"jaxgrasp: chunk {i}/3 ({i}/3 grasps)" for i in (1, 2, 3)], said

    caplog.clear()
    logging.getLogger("jaxgrasp").setLevel(logging.WARNING)  # the documented switch (caplog restores the level)
    again = jaxgrasp.evaluate_batch(grasps, chunk_size=1, devices=jaxgrasp.engine._plan.jax.devices()[:1])
    assert _records(caplog) == []
    np.testing.assert_array_equal(again.value, first.value)


PLAIN_SCRIPT = textwrap.dedent(
    """
    import logging, sys
    import jaxgrasp
    if sys.argv[1] == "quiet":
        logging.getLogger("jaxgrasp").setLevel(logging.WARNING)
    cube = jaxgrasp.presets.cube(6e5, 0.002)
    jaxgrasp.evaluate_batch([cube, cube], chunk_size=1)
    print("done")
    """
)


@pytest.mark.slow  # two subprocesses that load (or compile) a batch evaluator
@pytest.mark.parametrize("mode", ["default", "quiet"])
def test_a_script_that_configures_no_logging_sees_the_messages(mode, tmp_path):
    """A script that configures no logging prints jaxgrasp's chunk lines on stderr, one
    line each, as the command does; the documented switch leaves stderr empty."""
    env = dict(os.environ, JAXGRASP_CPU_DEVICES="1", JAX_PLATFORMS="cpu")
    proc = _python(["-c", PLAIN_SCRIPT, mode], env=env, cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout == "done\n", proc.stderr[-2000:]
    lines = [ln for ln in proc.stderr.splitlines() if not ln.startswith("jaxgrasp: compiling")]
    if mode == "quiet":
        assert proc.stderr == ""
    else:
        assert lines[0] == "jaxgrasp: evaluating 2 grasps in 2 chunks of 1 (the first chunk includes compilation)"
        assert [ln.split(",")[0] for ln in lines[1:]] == ["jaxgrasp: chunk 1/2 (1/2 grasps)",
                                                          "jaxgrasp: chunk 2/2 (2/2 grasps)"], proc.stderr
