"""The commands' own input checks and consistency (issues 40 item 4 and 35 item 5).

Absurd inputs (magnifications, grid sizes, names that are not UTF-8) are one line
``jaxgrasp: error: ...``, exit 2, before anything is computed: every in-process run here
has the evaluation, the sweep and the tuning replaced by a function that fails the test
if it is called, so none of them compiles. Two subprocesses time the first line of
``tune`` and ``batch``; they are killed once it is read.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.analysis import TuneStatus
from jaxgrasp.cli import _common, _show, _sweep, _tune, build_parser
from jaxgrasp.storage import csv_cell
from jaxgrasp.presets import PRESETS

ROOT = Path(__file__).resolve().parents[2]
BAD = os.fsdecode(b"out\xff")  # how Python sees a file name of bytes that are not UTF-8


class Computed(Exception):
    """Raised by the stand-ins below: the command got past its input checks."""


@pytest.fixture
def no_compute(monkeypatch):
    """The evaluation, sweep and tuning the commands call, replaced: each records its
    arguments and raises :class:`Computed` (nothing compiles)."""
    calls = []

    def stand_in(*args, **kwargs):
        calls.append((args, kwargs))
        raise Computed

    monkeypatch.setattr("jaxgrasp.engine.evaluate", stand_in)  # the commands import it from the face
    monkeypatch.setattr("jaxgrasp.analysis.sweep", stand_in)
    monkeypatch.setattr("jaxgrasp.analysis.tune", stand_in)
    return calls


def one_line_error(run_cli, argv, *fragments):
    rc, out, err = run_cli(argv)
    assert rc == 2 and out == "", (rc, out, err)
    assert err.count("\n") == 1 and err.startswith("jaxgrasp: error: ") and "Traceback" not in err, err
    for f in fragments:
        assert f in err, err
    return err


# ----------------------------------------------------------------------------- show --magnification


@pytest.mark.parametrize("m", ["1e300", "0", "-2", "nan", "inf", "1e-4", "2e12"])
def test_show_magnification_out_of_range(run_cli, no_compute, tmp_path, m):
    one_line_error(run_cli, ["show", "--preset", "cube", "--magnification", m, "--out", tmp_path / "g.png"],
                   "--magnification must be a number from 0.001 to 1e+12")
    assert no_compute == [] and list(tmp_path.iterdir()) == []


def test_show_magnification_range_is_inclusive(tmp_path):
    for m in _show.MAGNIFICATION_RANGE:
        args = argparse.Namespace(magnification=m, out=str(tmp_path / "g.png"), glb=None)
        assert _show._check_outputs(args) == [tmp_path / "g.png"]


# ----------------------------------------------------------------------------- grid size


def test_sweep_grid_over_the_cap_is_refused_before_allocating(run_cli, no_compute, tmp_path):
    axes = ["--young-modulus", "2e5:1e6:465", "--initial-deformation", "1e-3:5e-3:465", "--mass", "0:1:465"]
    one_line_error(run_cli, ["sweep", *axes, "--out", tmp_path / "o"], "100,544,625 points (465 x 465 x 465)",
                   f"{_sweep.MAX_GRID_POINTS:,}")
    # 5e6 x 5: two axes each under the cap, the grid over it; expanding the first would
    # take 40 MB, so the peak shows that no axis was expanded before the refusal
    tracemalloc.start()
    try:
        one_line_error(run_cli, ["sweep", "--young-modulus", "2e5:1e6:5000000", "--mass", "0:1:5",
                                 "--out", tmp_path / "o"], "25,000,000 points")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10e6, peak
    one_line_error(run_cli, ["sweep", "--mass", "0:1:100000000000", "--out", tmp_path / "o"],
                   "100,000,000,000 points")
    with pytest.raises(_common.UsageError, match="100,000,000,000 points"):  # the spec alone, not expanded
        _sweep.parse_axis_spec("--mass", "0:1:100000000000")
    assert no_compute == [] and not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- names


@pytest.mark.parametrize(
    "argv, option",
    [
        (["sweep", "--preset", "cube", "--out", BAD], "--out"),
        (["show", "--preset", "cube", "--out", BAD + ".png"], "--out"),
        (["show", "--preset", "cube", "--glb", BAD + ".glb"], "--glb"),
        (["tune", "--preset", "cube", "--out", BAD + ".toml"], "--out"),
        (["evaluate", BAD + ".toml"], "the input file name"),
        (["batch", BAD + ".jsonl"], "the input file name"),
    ],
)
def test_names_that_are_not_utf8(run_cli, no_compute, argv, option):
    err = one_line_error(run_cli, argv, option, "out\\xff", "is not valid UTF-8")
    assert "\\udcff" not in err  # the byte as the user's shell shows it


def test_titles_are_drawn_as_written(tmp_path):
    """A file name with ``$`` (``a$\\x$.toml``) in a figure title is text, not mathtext,
    which matplotlib fails to parse only when saving, after all the computing."""
    from jaxgrasp.analysis import SweepResult
    from jaxgrasp.plots import plot_sweep, save_figure

    shape = (2, 3)
    result = SweepResult(
        axes={"young_modulus": np.array([2e5, 6e5]), "initial_deformation": np.array([1e-3, 2e-3, 3e-3])},
        value=np.full(shape, 1e-4), status=np.zeros(shape, np.int32), limiting_kind=np.zeros(shape, np.int32),
        limiting_contact=np.zeros(shape, np.int32), equilibrium_energy=np.full(shape, 1e-5),
    )
    title = "jaxgrasp sweep: a$\\x$b.toml"
    fig = plot_sweep(result, title=title)
    save_figure(fig, io.BytesIO(), format="png")
    shown = fig._suptitle
    assert shown._preprocess_math(shown.get_text()) == (title, False)


# ----------------------------------------------------------------------------- many contacts


def test_large_grasp_says_what_it_evaluates(run_cli, no_compute, tmp_path, capsys):
    """Above LONG_EVALUATION_CONTACTS the command says what it compiles and evaluates
    before it starts (one compiled call without progress of its own); not at or below."""
    n = _common.LONG_EVALUATION_CONTACTS + 1
    v = np.random.default_rng(0).normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    doc = {"fingertip": {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15.0},
           "contacts": [{"position": (0.05 * u).tolist(), "normal": u.tolist(), "initial_deformation": 1e-3}
                        for u in v]}
    path = tmp_path / "many.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(Computed):
        run_cli(["evaluate", path])
    assert len(no_compute) == 1  # the line came before the evaluation
    err = capsys.readouterr().err
    assert err.startswith(f"jaxgrasp: {path} has {n} contacts: compiling and solving its {2 * n} boundary problems"), err
    with pytest.raises(Computed):
        run_cli(["evaluate", "--preset", "prism"])  # 3 contacts: silent
    assert len(no_compute) == 2 and capsys.readouterr().err == ""


def test_announce_large_grasp_threshold(capsys):
    n = _common.LONG_EVALUATION_CONTACTS
    _common.announce_large_grasp(n, "x.toml")
    assert capsys.readouterr().err == ""
    _common.announce_large_grasp(n + 1, "x.toml")
    err = capsys.readouterr().err
    assert err.startswith(f"jaxgrasp: x.toml has {n + 1} contacts: compiling and solving its {2 * n + 2} "), err


# ----------------------------------------------------------------------------- consistency (issue 35)


@pytest.mark.parametrize("name", list(PRESETS))
def test_presets_equal_the_example_files_of_their_name(name):
    given, preset = jaxgrasp.load(ROOT / "examples" / f"{name}.toml").to_numpy(), PRESETS[name]().to_numpy()
    assert given.keys() == preset.keys()
    for k in given:
        np.testing.assert_array_equal(np.broadcast_to(given[k], np.shape(preset[k])), preset[k], err_msg=k)


def test_tune_takes_the_overrides(run_cli, no_compute, tmp_path):
    with pytest.raises(Computed):
        run_cli(["tune", "--preset", "cube", "--young-modulus", "6e5", "--mass", "0.05", "--quiet",
                 "--out", tmp_path / "t.toml"])
    (grasp, *_), _ = no_compute[0]
    np.testing.assert_array_equal(grasp.young_modulus, [6e5, 6e5])
    assert float(grasp.mass) == 0.05
    one_line_error(run_cli, ["tune", "--preset", "cube", "--young-modulus", "-1", "--out", tmp_path / "t.toml"],
                   "--young-modulus -1: young_modulus must be positive")


@pytest.mark.parametrize("status", list(TuneStatus))
def test_every_tune_status_is_explained_in_the_summary(status, tmp_path):
    message = status.message.format(ftol=1e-7, patience=4, maxiter=50)
    res = SimpleNamespace(params={"initial_deformation:shared": 2.5e-3}, start_value=8.8e-5, value=1.2e-4,
                          gain=1.2e-4 / 8.8e-5, iterations=7, status=status, message=message, start_note=lambda: "")
    line = _tune._summary_line(res, "preset cube", tmp_path / "t.toml", False, [])
    assert f", {status}: {message}); " in line and "\n" not in line
    assert "usable" in message  # whether the tuned grasp can be used
    assert f"``{status}``: " in TuneStatus.__doc__  # and in the docs


def test_sweep_axes_follow_the_command_line_order():
    parse = build_parser().parse_args
    for argv, order in [
        (["--mass", "0,0.1", "--young-modulus", "2e5", "--initial-deformation", "1e-3"],
         ["mass", "young_modulus", "initial_deformation"]),
        (["--initial-deformation", "1e-3", "--mass", "0", "--young-modulus", "2e5", "--mass", "0.1"],
         ["initial_deformation", "young_modulus", "mass"]),  # given twice: the last place
    ]:
        axes, paper = _sweep._parse_axes(parse(["sweep", *argv]))
        assert list(axes) == order and not paper
    axes, paper = _sweep._parse_axes(parse(["sweep"]))
    assert list(axes) == ["young_modulus", "initial_deformation"] and paper  # the paper's Fig. 6


@pytest.mark.parametrize(
    "spec, cells",
    [
        ("0.1:0.5:5", ["0.1", "0.2", "0.3", "0.4", "0.5"]),
        ("-0.3:0.3:3", ["-0.3", "0.0", "0.3"]),
        ("2e5:1e6:9", [f"{k}00000.0" for k in range(2, 11)]),
        ("0.0001:0.0002:3", ["0.0001", "0.00015", "0.0002"]),
        ("0:1:4", ["0.0", "0.3333333333333333", "0.6666666666666666", "1.0"]),  # no exact decimal step
    ],
)
def test_grid_values_are_written_as_typed(spec, cells):
    values = _sweep.parse_axis_spec("--x", spec)
    assert [csv_cell(x) for x in values] == cells
    np.testing.assert_allclose(values, np.linspace(float(cells[0]), float(cells[-1]), len(cells)), rtol=1e-15)


def test_paper_grid_is_written_as_typed():
    axes, paper = _sweep._parse_axes(build_parser().parse_args(["sweep"]))
    assert paper
    dr = axes["initial_deformation"]
    assert [csv_cell(x) for x in dr[:4]] == ["0.001", "0.0011", "0.0012", "0.0013"]  # linspace: 0.0012000000000000001
    assert all(len(csv_cell(x)) <= 6 for x in dr), [csv_cell(x) for x in dr]


# ----------------------------------------------------------------------------- the first line


def _first_line_seconds(argv, env, wait: float) -> tuple[float, str]:
    """Seconds from starting ``python -m jaxgrasp ARGV`` to its first stderr line, and the
    line (``""`` where none came within ``wait`` seconds: the process is then killed)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "jaxgrasp", *argv], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    watchdog = threading.Timer(wait, proc.kill)  # a missing line fails the test, not hangs it
    watchdog.start()
    try:
        line = proc.stderr.readline()
        return time.perf_counter() - t0, line
    finally:
        watchdog.cancel()
        proc.kill()
        proc.wait()


@pytest.mark.slow  # three subprocesses
def test_tune_and_batch_print_a_first_line_within_a_second(tmp_path):
    """``tune`` and a one-chunk ``batch`` say what they do before compiling (which takes
    tens of seconds on a fresh cache): within 1 s of starting, or, on a machine so busy
    that importing JAX alone takes longer, within 0.6 s after that import, measured just
    before each command. Under the suite's own load (load average 3-4 on 2 cores) the
    work after the import once took 0.37 s; on an idle machine the line comes sooner than
    a separate process's import ends (1.4-1.6 s against 1.7-1.8 s)."""
    dataset = tmp_path / "set.jsonl"
    jaxgrasp.save_dataset(dataset, [PRESETS["cube"](), PRESETS["prism"]()])
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    for argv, start in [
        (["tune", "--preset", "cube", "--out", str(tmp_path / "t.toml")], "jaxgrasp: tuning initial_deformation of preset cube"),
        (["batch", str(dataset), "--out", str(tmp_path / "o")], f"jaxgrasp: batch {dataset}: 2 grasps to go;"),
    ]:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import jaxgrasp.cli"], cwd=ROOT, env=env, check=True)
        # the import's own time varies under the suite's load as much as the command's: a margin
        # in proportion to it (a first line after compiling would come 10 s or more late)
        budget = max(1.0, 1.3 * (time.perf_counter() - t0) + 0.6)
        seconds, line = _first_line_seconds(argv, env, wait=budget + 5)
        assert line.startswith(start), line
        assert seconds < budget, (argv[0], seconds, budget)


# ----------------------------------------------------------------------------- grid points and bounds evaluate rejects


@pytest.mark.parametrize(
    "axis, fragment",
    [  # the cube: E 2e5 Pa, dr 2 mm, initial squeeze 5.03 N
        (["--young-modulus", "1e-300"], "sweep grid point (young_modulus = 1e-300 Pa): contact 0: young_modulus"),
        (["--mass", "1e300"], "sweep grid point (mass = 1e+300 kg): mass * |gravity| = 9.81e+300 N is more than 10000"),
        (["--mass", "1e10"], "sweep grid point (mass = 10000000000 kg): mass * |gravity|"),
        (["--friction", "1e6"], "sweep grid point (friction = 1000000): friction = 1000000 must be at most 1000"),
    ],
)
def test_sweep_refuses_grid_points_evaluate_rejects(run_cli, no_compute, tmp_path, axis, fragment):
    """``jaxgrasp sweep`` applies ``evaluate``'s rules (energy scale, load ratio, friction
    limit) to its grid: exit 2, one line naming the axis and value (audit: these ran with
    exit 0 and reported stable, unstable or not_converged)."""
    one_line_error(run_cli, ["sweep", *axis, "--out", tmp_path / "o"], fragment)
    assert no_compute == [] and not (tmp_path / "o").exists()


TUNE_BOUNDS_EVALUATE_REJECTS = [  # the cube: E 2e5 Pa, dr 2 mm, radius 25 mm, squeeze 5.03 N
    (["young_modulus"], {"young_modulus": (1e-300, 1e6)}, "(young_modulus = [1e-300, 1e-300] Pa): contact 0: "),
    (["friction:shared"], {"friction": (0.1, 1e6)}, "(friction = 1000000): friction = 1000000 must be at most 1000"),
    (["mass"], {"mass": (0.0, 1e10)}, "(mass = 10000000000 kg): mass * |gravity| = 9.81e+10 N is more than 10000"),
    (  # each bound fits the grasp's other fields, not the other tuned parameter's bounds
        ["initial_deformation", "radius"], {"initial_deformation": (1e-3, 4e-3), "radius": (3e-3, 0.03)},
        ("(initial_deformation = [0.004, 0.004] m, radius = [0.003, 0.003] m): initial_deformation[0] = 0.004 m "
         "must be in (0, radius[0] = 0.003 m)"),
    ),
]


@pytest.fixture
def no_tune_compile(monkeypatch):
    """tune's compilation of the value and its gradient, replaced by a :class:`Computed`."""
    def stand_in(*args, **kwargs):
        raise Computed

    monkeypatch.setattr("jaxgrasp.analysis._tune._compiled", stand_in)


@pytest.mark.parametrize("params, bounds, fragment", TUNE_BOUNDS_EVALUATE_REJECTS)
def test_tune_bounds_evaluate_rejects_are_refused_before_compiling(no_tune_compile, params, bounds, fragment):
    """tune's box holds only grasps ``evaluate`` accepts: checked at its corners, one line
    naming the parameters and their bounds (audit: young_modulus=1e-300:1e6 passed)."""
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        jaxgrasp.tune(jaxgrasp.presets.cube(), params, bounds)
    assert str(info.value).startswith("tune: at the bounds' corner ") and fragment in str(info.value), info.value
    assert "\n" not in str(info.value)


def test_tune_command_refuses_bounds_evaluate_rejects(run_cli, no_tune_compile, tmp_path):
    one_line_error(run_cli, ["tune", "--preset", "cube", "--param", "young_modulus", "--bounds",
                             "young_modulus=1e-300:1e6", "--quiet", "--out", tmp_path / "t.toml"],
                   "tune: at the bounds' corner (young_modulus = [1e-300, 1e-300] Pa)", "below 1e-150 J")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- every count bounded (issue 65)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["plan", "part.stl", "--samples", "1e12"], "--samples must be at most 100,000 candidates per plan"),
        (["plan", "part.stl", "--robust-samples", "1000000000000"],
         "--robust-samples must be at most 100,000 perturbed copies per grasp"),
        (["plan", "part.stl", "--refine", "1e6"], "--refine must be at most 1,000 refined candidates"),
        (["plan", "part.stl", "--top", "1e12"], "--top must be at most 100,000 candidates per plan"),
        (["plan", "part.stl", "--fingers", "9"], "--fingers must be at most 8 fingertips, got 9"),
        (["evaluate", "--preset", "cube", "--robust", "friction=0.1", "--samples", "1e12"],
         "--samples must be at most 100,000 perturbed copies per grasp"),
        (["batch", "set.npz", "--robust", "friction=0.1", "--samples", "1e12"], "--samples must be at most 100,000"),
        (["batch", "set.npz", "--chunk-size", "1e9"], "--chunk-size must be at most 65,536 grasps per compiled call"),
        (["batch", "set.npz", "--top", "1e12"], "--top must be at most 1,000 best grasps listed"),
        (["sweep", "--chunk-size", "1e9"], "--chunk-size must be at most 65,536"),
        (["evaluate", "--preset", "cube", "--chunk-size", "100000"], "--chunk-size must be at most 65,536"),
        (["tune", "--preset", "cube", "--maxiter", "1e9"], "--maxiter must be at most 10,000 iterations"),
    ],
)
def test_counts_over_their_cap_are_one_line_before_anything_is_loaded(run_cli, no_compute, argv, fragment):
    """Each count is refused by the parser (no file is read: ``part.stl`` and ``set.npz``
    do not exist), in one line naming the option, its cap and the value."""
    t0 = time.perf_counter()
    err = one_line_error(run_cli, argv, fragment)
    assert f"{fragment.split()[0]} 1e12" not in err and ", got " in err, err
    assert no_compute == [] and time.perf_counter() - t0 < 60


def test_counts_may_be_written_as_whole_floats():
    from jaxgrasp.cli._arguments import Count

    count = Count("--samples", 100, "samples")
    assert count("1e2") == 100 and count(" 64 ") == 64 and count("2000.0e-2") == 20
    for bad in ("1.5", "nan", "inf", "ten", ""):
        with pytest.raises(ValueError):
            count(bad)


def test_library_counts_over_their_cap_raise_the_same_line(tmp_path):
    """The API refuses the same counts in one line, before reading a mesh (``plan``: the
    mesh does not exist) or drawing a sample (``robust``: 1e12 samples once asked NumPy
    for 29 TiB)."""
    from jaxgrasp.analysis import Uncertainty, perturbed
    from jaxgrasp.presets import cube

    tip = dict(radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0)
    cases = [
        (lambda: jaxgrasp.plan(tmp_path / "absent.stl", samples=10**12, **tip),
         "plan: samples must be at most 100,000 candidates per plan"),
        (lambda: jaxgrasp.plan(tmp_path / "absent.stl", robust_samples=10**12, **tip),
         "plan: robust_samples must be at most 100,000 perturbed copies per grasp"),
        (lambda: jaxgrasp.plan(tmp_path / "absent.stl", refine=10**6, **tip), "plan: refine must be at most 1,000"),
        (lambda: jaxgrasp.plan(tmp_path / "absent.stl", tune_maxiter=10**9, **tip),
         "plan: tune_maxiter must be at most 10,000"),
        (lambda: jaxgrasp.robust(cube(), Uncertainty(friction=0.1), samples=10**12),
         "samples must be at most 100,000 perturbed copies per grasp"),
        (lambda: perturbed(cube(), Uncertainty(friction=0.1), samples=10**12), "samples must be at most 100,000"),
        (lambda: jaxgrasp.tune(cube(), ["initial_deformation:shared"], {"initial_deformation": (1e-3, 5e-3)},
                               maxiter=10**9), "tune: maxiter must be at most 10,000 iterations"),
        (lambda: jaxgrasp.evaluate_batch([cube(), cube()], chunk_size=10**9),
         "chunk_size must be at most 65,536 grasps per compiled call"),
    ]
    for call, fragment in cases:
        tracemalloc.start()
        try:
            with pytest.raises(jaxgrasp.GraspValueError) as info:
                call()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        text = str(info.value)
        assert "\n" not in text and text.startswith(fragment), text
        assert peak < 64 * 2**20, (fragment, peak)  # refused before anything large was allocated
