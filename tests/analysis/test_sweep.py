"""Tests for jaxgrasp.sweep, the ``jaxgrasp sweep`` command and the sweep plots.

Compilation dominates the cost, so every cube sweep here uses batches of 6 grid points
(one compilation of the batched cube evaluator, shared with the CLI test which runs
in-process); the prism needs one more, and the point-by-point check one unbatched.
"""

import jax

jax.config.update("jax_enable_x64", True)

import csv
import subprocess
import sys

import numpy as np
import pytest
from conftest import without_compile_reports

import jaxgrasp
from jaxgrasp import cli
from jaxgrasp.engine._evaluate import evaluate
from jaxgrasp.presets import cube, prism
from jaxgrasp.tolerance._result import INFEASIBLE, STABLE, STATUS_NAMES
from jaxgrasp.analysis._sweep import PARAMETERS, SweepResult, sweep
from jaxgrasp.model._validation import GraspValueError

CHUNK = 6
E_AXIS = np.array([2e5, 1e6])  # Pa
DR_AXIS = np.array([1.0, 2.0, 3.0, 4.0, 4.5, 4.7, 4.85]) * 1e-3  # m; 14 points: 3 chunks, last padded
MAX_FORCE = jaxgrasp.model.BoundaryKind.labels().index("max_force")


@pytest.fixture(scope="module")
def cube_sweep():
    calls = []
    res = sweep(
        cube(),
        young_modulus=E_AXIS,
        initial_deformation=DR_AXIS,
        chunk_size=CHUNK,
        progress=lambda done, total: calls.append((done, total)),
    )
    return res, calls


# ---------------------------------------------------------------- equality and shapes


def test_shapes_axes_and_progress(cube_sweep):
    res, calls = cube_sweep
    assert isinstance(res, SweepResult)
    assert res.names == ("young_modulus", "initial_deformation")
    np.testing.assert_array_equal(res.axes["young_modulus"], E_AXIS)
    np.testing.assert_array_equal(res.axes["initial_deformation"], DR_AXIS)
    for f in ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy"):
        assert np.shape(getattr(res, f)) == (2, 7), f
    assert calls == [(6, 14), (12, 14), (14, 14)]
    assert sum(res.counts().values()) == 14


def test_sweep_equals_point_by_point_evaluate(cube_sweep):
    res, _ = cube_sweep
    for i, E in enumerate(E_AXIS):
        for j, dr in enumerate(DR_AXIS[:3]):
            ev = evaluate(cube(young_modulus=E, initial_deformation=dr))
            # Batched and single-grasp XLA kernels round differently; the solver stops at
            # a 1e-10 KKT tolerance, so agreement is ~1e-11 relative, not bit for bit.
            np.testing.assert_allclose(res.value[i, j], float(ev.value), rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(
                res.equilibrium_energy[i, j], float(ev.equilibrium_energy), rtol=1e-9, atol=1e-15
            )
            assert res.status[i, j] == int(ev.status)
            assert res.limiting_kind[i, j] == int(ev.limiting_kind)
            assert res.limiting_contact[i, j] == int(ev.limiting_contact)


def test_shape_follows_axis_order(cube_sweep):
    res, _ = cube_sweep
    swapped = sweep(cube(), initial_deformation=DR_AXIS[:3], young_modulus=E_AXIS, chunk_size=CHUNK)
    assert swapped.names == ("initial_deformation", "young_modulus")
    assert swapped.value.shape == (3, 2)
    np.testing.assert_allclose(swapped.value, res.value[:, :3].T, rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(swapped.status, res.status[:, :3].T)
    np.testing.assert_array_equal(swapped.limiting_kind, res.limiting_kind[:, :3].T)


# ---------------------------------------------------------------- files


def test_csv_one_row_per_point_with_units(cube_sweep, tmp_path):
    res, _ = cube_sweep
    path = tmp_path / "s.csv"
    res.to_csv(path)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == [
        "young_modulus_Pa",
        "initial_deformation_m",
        "value_J",
        "status",
        "limiting_kind",
        "limiting_contact",
        "equilibrium_energy_J",
    ]
    assert len(rows) == res.size == 14
    # C order: last axis fastest; values read back exactly
    k = 0
    for i, E in enumerate(E_AXIS):
        for j, dr in enumerate(DR_AXIS):
            row = rows[k]
            assert float(row["young_modulus_Pa"]) == E
            assert float(row["initial_deformation_m"]) == dr
            assert float(row["value_J"]) == res.value[i, j]
            assert row["status"] == STATUS_NAMES[res.status[i, j]]
            assert row["limiting_kind"] in ("slip", "max_force", "none")
            assert int(row["limiting_contact"]) == res.limiting_contact[i, j]
            k += 1


def test_npz_round_trip_and_plot(cube_sweep, tmp_path):
    res, _ = cube_sweep
    res.to_npz(tmp_path / "s.npz")
    back = SweepResult.from_npz(tmp_path / "s.npz")
    assert back.names == res.names
    for f in ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy"):
        np.testing.assert_array_equal(getattr(back, f), getattr(res, f))
    from jaxgrasp.plots._plots import plot_max_over, plot_sweep

    plot_sweep(res, tmp_path / "s.png")
    plot_max_over(res, tmp_path / "m.png")
    assert (tmp_path / "s.png").stat().st_size > 1000
    assert (tmp_path / "m.png").stat().st_size > 1000


def test_pytree_keeps_axis_order(cube_sweep):
    res, _ = cube_sweep
    leaves, tree = jax.tree_util.tree_flatten(res)
    back = jax.tree_util.tree_unflatten(tree, leaves)
    assert back.names == res.names


# ---------------------------------------------------------------- the paper's findings


def test_cube_value_rises_with_dr_at_soft_fingertips(cube_sweep):
    res, _ = cube_sweep
    i = 0  # E = 2e5 Pa
    assert np.all(res.status[i, :3] == STABLE)
    v = res.value[i, :3]  # dr = 1, 2, 3 mm
    assert v[0] < v[1] < v[2]


def test_cube_value_falls_after_maximum_because_of_force_limit(cube_sweep):
    res, _ = cube_sweep
    for i in range(len(E_AXIS)):
        v = res.value[i]
        k = int(np.argmax(v))
        assert k < len(DR_AXIS) - 1, "the maximum must not be at the largest dr"
        after = slice(k + 1, None)
        assert np.all(v[after] < v[k])
        limited = (res.status[i, after] == STABLE) & (res.limiting_kind[i, after] == MAX_FORCE)
        infeasible = res.status[i, after] == INFEASIBLE
        assert np.all(limited | infeasible), (res.status[i], res.limiting_kind[i])
    # at E = 2e5 Pa the fall is a force-limited one before infeasibility
    assert np.any((res.status[0] == STABLE) & (res.limiting_kind[0] == MAX_FORCE))


def test_cube_max_value_falls_as_E_grows(cube_sweep):
    res, _ = cube_sweep
    reduced, best_dr = res.max_over("initial_deformation")
    assert reduced.names == ("young_modulus",)
    assert reduced.value[0] > reduced.value[1] > 0
    assert best_dr[0] > best_dr[1]


@pytest.mark.slow  # compiles a sweep of its own
def test_prism_heavier_object_lower_value():
    res = sweep(prism(), mass=[0.0, 0.2], young_modulus=2e5, initial_deformation=3e-3)
    assert res.value.shape == (2, 1, 1)
    assert np.all(res.status == STABLE)
    assert res.value[1, 0, 0] < res.value[0, 0, 0]


# ---------------------------------------------------------------- validation (no compilation)


@pytest.mark.parametrize(
    "axes, match",
    [
        ({"stiffness": [1.0]}, "unknown parameter 'stiffness'.*young_modulus, initial_deformation, mass"),
        ({"young_modulus": []}, "young_modulus is empty"),
        ({"young_modulus": [2e5, np.nan]}, r"young_modulus\[1\] = nan Pa must be finite"),
        ({"young_modulus": [2e5, np.inf]}, r"young_modulus\[1\] = inf Pa must be finite"),
        ({"young_modulus": [-2e5]}, "must be positive"),
        ({"friction": [0.0, 0.5]}, r"friction\[0\] = 0 must be positive"),
        ({"max_force": 0}, "must be positive"),
        ({"mass": [0.0, -0.1]}, r"mass\[1\] = -0.1 kg must be >= 0"),
        ({"initial_deformation": [1e-3, 0.025]},
         r"grid point \(initial_deformation = 0.025 m\): initial_deformation = 0.025 m must be in \(0, radius"),
        ({"radius": [0.0015]}, r"grid point \(radius = 0.0015 m\): initial_deformation\[0\] = 0.002 m must be in"),
        ({"initial_deformation": [0.0]}, "must be positive"),
        ({"young_modulus": "abc"}, "must be a number"),
        ({"young_modulus": [[1e5, 2e5]]}, "1-D"),
        (  # three axes of 465 points: refused before any grid-sized array is made
            {"young_modulus": np.linspace(2e5, 1e6, 465), "initial_deformation": np.linspace(1e-3, 5e-3, 465),
             "mass": np.linspace(0.0, 1.0, 465)},
            r"100,544,625 points \(465 x 465 x 465\), more than MAX_GRID_POINTS = 10,000,000",
        ),
    ],
)
def test_bad_axes_raise_one_line(axes, match):
    with pytest.raises(GraspValueError, match=match) as info:
        sweep(cube(), **axes)
    assert "\n" not in str(info.value)


def _must_not_compile(*args, **kwargs):
    raise AssertionError("the sweep got past its input checks and compiled")


@pytest.mark.parametrize(
    "axes, match",
    [  # grid points jaxgrasp.evaluate rejects: the base grasp is the cube (E 2e5 Pa, dr 2 mm, squeeze 5.03 N)
        ({"young_modulus": 1e-300}, r"grid point \(young_modulus = 1e-300 Pa\): contact 0: .* below 1e-150 J"),
        ({"mass": 1e300}, r"grid point \(mass = 1e\+300 kg\): mass \* \|gravity\| = 9.81e\+300 N is more than 10000"),
        ({"mass": [0.0, 1e10]}, r"grid point \(mass = 10000000000 kg\): mass \* \|gravity\| .* more than 10000 times"),
        ({"friction": [0.5, 1e6]}, r"grid point \(friction = 1000000\): friction = 1000000 must be at most 1000"),
        (  # each axis alone is fine; the corner of least squeeze and most weight is not
            {"young_modulus": [1e6, 2e5], "initial_deformation": [4e-3, 1e-3], "mass": [0.0, 2000.0]},
            (r"grid point \(young_modulus = 200000 Pa, initial_deformation = 0.001 m, mass = 2000 kg\): "
             r"mass \* \|gravity\| = 1.962e\+04 N is more than 10000 times"),
        ),
    ],
)
def test_grid_points_evaluate_rejects_are_refused_before_compiling(monkeypatch, axes, match):
    """The rules of jaxgrasp.evaluate's validation (energy scale, friction limit, load
    ratio) hold at every grid point: a sweep that breaks one is refused in one line naming
    the grid point's axes and values, before anything is compiled (audit: ``sweep --mass
    1e10`` ran, ``--young-modulus 1e-300`` reported stable)."""
    monkeypatch.setattr("jaxgrasp.analysis._sweep.run_batch", _must_not_compile)
    with pytest.raises(GraspValueError, match=match) as info:
        sweep(cube(), **axes)
    assert "\n" not in str(info.value)


def test_grid_check_agrees_with_every_grid_point():
    """The grid is checked at its corners only; on random grids near every rule's limit
    that rejects a grid exactly where check_grasp_inputs (evaluate's validation) rejects
    one of its points (per-axis range errors aside, which both raise)."""
    from jaxgrasp.analysis._sweep import check_inputs
    from jaxgrasp.model._validation import check_grasp_inputs

    near = {  # SI; each straddles a rule's limit on the cube
        "young_modulus": [1e-143, 1e-141, 1e3, 2e5, 5e5, 1e6],  # Pa; E dr^3 >= 1e-150 J
        "initial_deformation": [2e-4, 1e-3, 2e-3, 3e-3, 0.02, 0.03],  # m; < radius
        "mass": [0.0, 0.1, 10.0, 3000.0, 1e5],  # kg; weight <= 1e4 x squeeze
        "friction": [0.5, 1.0, 999.0, 1e3, 1001.0],  # <= 1e3
        "radius": [1.5e-3, 0.01, 0.025, 0.05],  # m
    }
    rng = np.random.default_rng(0)
    base = cube().to_numpy()
    verdicts = []
    for _ in range(60):
        names = rng.choice(list(near), size=rng.integers(1, 4), replace=False)
        axes = {str(n): rng.choice(near[n], size=rng.integers(1, 4), replace=False) for n in names}
        rejected = False
        for point in np.array(np.meshgrid(*axes.values(), indexing="ij")).reshape(len(axes), -1).T:
            try:
                check_grasp_inputs(**{**base, **dict(zip(axes, point))})
            except GraspValueError:
                rejected = True
                break
        try:
            check_inputs(cube(), **axes)
            verdicts.append(False)
        except GraspValueError:
            verdicts.append(True)
        assert verdicts[-1] == rejected, axes
    assert 15 <= sum(verdicts) <= 45, sum(verdicts)  # both kinds of grid were drawn


def test_bad_chunk_size():
    with pytest.raises(GraspValueError, match="chunk_size"):
        sweep(cube(), mass=[0.0], chunk_size=0)


def test_parameters_have_units():
    assert PARAMETERS["young_modulus"].unit == "Pa"
    assert PARAMETERS["initial_deformation"].unit == "m"
    assert PARAMETERS["mass"].unit == "kg"


# ---------------------------------------------------------------- CLI


@pytest.fixture
def run_cli(monkeypatch, capsys):
    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)  # no global side effect

    def run(*argv):
        rc = cli.main(list(argv))
        out, err = capsys.readouterr()
        return rc, out, err

    return run


def test_cli_sweep_writes_files(run_cli, tmp_path, cube_sweep):
    out = tmp_path / "out"
    rc, stdout, stderr = run_cli(
        "sweep", "--preset", "cube", "--young-modulus", "2e5,6e5", "--initial-deformation", "1e-3:3e-3:3",
        "--out", str(out), "--chunk-size", str(CHUNK),  # the module's compiled program
    )
    assert rc == 0, stderr
    # one chunk: no chunk lines, only the first line saying what is about to happen
    assert without_compile_reports(stderr) == (
        "jaxgrasp: sweep preset cube: 6 points to go; compiling the evaluator (or loading it from the cache) first\n"
    )
    for name in ("sweep.npz", "sweep.csv", "sweep.png"):
        assert (out / name).stat().st_size > 0, name
    lines = stdout.strip().splitlines()
    assert len(lines) == 1 and "6 points" in lines[0] and "stable" in lines[0] and "best" in lines[0]
    res = SweepResult.from_npz(out / "sweep.npz")
    assert res.value.shape == (2, 3)
    np.testing.assert_allclose(res.axes["initial_deformation"], [1e-3, 2e-3, 3e-3])
    with open(out / "sweep.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 6
    # same points as the library sweep
    np.testing.assert_allclose(res.value[0], cube_sweep[0].value[0, :3], rtol=1e-12, atol=1e-18)


def test_cli_sweep_epsilon_column(run_cli, tmp_path, cube_sweep):
    """``--epsilon`` (issue 15): the Ferrari-Canny value of every grid point, which does not
    change with Young's modulus (the energy tolerance does) and, with torsion, grows with the
    initial deformation through the eccentricity (eq. 10)."""
    out = tmp_path / "out"
    rc, _, stderr = run_cli(
        "sweep", "--preset", "cube", "--young-modulus", "2e5,6e5", "--initial-deformation", "1e-3:3e-3:3",
        "--out", str(out), "--chunk-size", str(CHUNK), "--epsilon", "--no-plot",
    )
    assert rc == 0, stderr
    with np.load(out / "sweep.npz") as z:
        eps, closure, value = z["epsilon"], z["force_closure"], z["value"]
    assert eps.shape == (2, 3) and closure.all()
    np.testing.assert_array_equal(eps[0], eps[1])  # independent of E
    assert np.all(np.diff(eps[0]) > 0) and value[0, 0] != value[1, 0]
    g = cube().replace(young_modulus=np.full(2, 6e5), initial_deformation=np.full(2, 2e-3))
    assert eps[1, 1] == float(jaxgrasp.epsilon(g).value)
    with open(out / "sweep.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["epsilon"]) for r in rows] == eps.ravel().tolist()


@pytest.mark.parametrize(
    "spec",
    [
        ["--young-modulus", "1:2:0"],
        ["--young-modulus", "abc"],
        ["--young-modulus=-2e5"],
        ["--mass=-1"],
        ["--initial-deformation", "1e-3:5e-3"],
        ["--initial-deformation", "0.03"],
        ["--friction", "nan"],
        ["--max-force", "1,,2"],
        ["--stiffness", "1"],
        ["--young-modulus", "1:2:2.5"],
    ],
)
def test_cli_bad_spec_exits_2_with_one_line(run_cli, tmp_path, spec):
    rc, stdout, stderr = run_cli("sweep", "--preset", "cube", *spec, "--out", str(tmp_path / "o"))
    assert rc == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxgrasp: error: "), stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # a subprocess
def test_cli_bad_spec_subprocess(tmp_path):
    p = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from jaxgrasp.cli import main; sys.exit(main())",
            "sweep",
            "--young-modulus",
            "1:2:0",
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 2
    assert p.stderr.count("\n") == 1 and p.stderr.startswith("jaxgrasp: error: ")


def test_parse_axis_spec():
    from jaxgrasp.cli._sweep import parse_axis_spec

    np.testing.assert_allclose(parse_axis_spec("--x", "1e-3:5e-3:5"), [1e-3, 2e-3, 3e-3, 4e-3, 5e-3])
    np.testing.assert_array_equal(parse_axis_spec("--x", "0,0.1, 0.2"), [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(parse_axis_spec("--x", "2e5"), [2e5])
    with pytest.raises(cli.UsageError, match="empty"):
        parse_axis_spec("--x", "1:2:0")
