"""Issue 11, items 5-12 ("Hardening"): inputs, results and the command line's wording.

One test (or a few) per item, each failing on the code before its fix. Cheap by design:
most run no evaluation at all; the few that do reuse the 2-contact cube's compilations
(unbatched ``evaluate`` as in ``test_cli.py``, the shared-deformation tune objective as
in ``test_gradients.py``), so within the suite they add seconds, not compilations.
Item 11 (``JAX_ENABLE_X64=0`` left alone) is covered by ``tests/model/test_x64.py``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import without_compile_reports

import jaxgrasp
from jaxgrasp import presets
from jaxgrasp.io._grasp_file import load
from jaxgrasp.model._validation import GraspValueError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
ROOT = Path(jaxgrasp.__file__).resolve().parent.parent  # the jaxgrasp under test, for subprocesses


def cube_doc(**fingertip) -> dict:
    """The cube preset as a grasp-file dict (2 contacts on opposite faces, outward normals)."""
    return {
        "fingertip": {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15.0, **fingertip},
        "contacts": [
            {"position": [0.05, 0.0, 0.0], "normal": [1.0, 0.0, 0.0], "initial_deformation": 0.002},
            {"position": [-0.05, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "initial_deformation": 0.002},
        ],
    }


@pytest.fixture(scope="module")
def cube_eval():
    """The cube preset's evaluation (NumPy leaves): the compiled evaluator of test_cli.py."""
    return jax.tree_util.tree_map(np.asarray, jaxgrasp.evaluate(presets.cube()))


# ----------------------------------------------------------------------------- item 5


def test_toml_with_byte_order_mark_loads(tmp_path):
    text = (EXAMPLES / "cube.toml").read_text(encoding="utf-8")
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    a, b = load(p).to_numpy(), load(EXAMPLES / "cube.toml").to_numpy()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


# ----------------------------------------------------------------------------- item 6


def test_tune_gain_is_from_the_grasp_as_given(run_cli, tmp_path):
    """A start outside the bounds is clipped into them; the gain and the printed start are
    those of the grasp as given (cube: 8.794e-5 J), and the clipping is said."""
    given = float(jaxgrasp.evaluate(presets.cube()).value)  # 8.794010e-05 J at 2 mm
    res = jaxgrasp.tune(
        presets.cube(), ["initial_deformation:shared"], {"initial_deformation": (3e-3, 4e-3)}, maxiter=1
    )
    assert res.start_value == pytest.approx(given, rel=1e-9)
    assert res.clipped == ("initial_deformation:shared",)
    assert res.initial_value > 3 * given  # the search started at 3 mm (2.946e-4 J)
    assert res.gain == pytest.approx(res.value / given)
    assert "clipped" in res.summary() and f"{given:.6e} J ->" in res.summary()
    rc, out, err = run_cli(
        ["tune", "--preset", "cube", "--param", "initial_deformation:shared", "--bounds",
         "initial_deformation=0.003:0.004", "--maxiter", "1", "--no-plot", "--quiet", "--out", tmp_path / "t.toml"]
    )
    assert rc == 0, err
    assert out.count("\n") == 1 and f"value {given:.6e} J ->" in out, out
    assert "initial_deformation:shared clipped into its bounds" in out, out
    assert not re.search(r"\b1 iterations\b", out), out  # item 12: "1 iterations"


# ----------------------------------------------------------------------------- item 7


@pytest.mark.parametrize(
    "raw, where",
    [
        ('{"fingertip": {"radius": 0.025, "young_modulus": 2e5, "young_modulus": 3e5, "friction": 0.5,'
         ' "max_force": 15}, "contacts": []}', "key 'young_modulus' in fingertip"),
        ('{"contacts": [{"position": [0.05, 0, 0]}, {"normal": [1, 0, 0], "normal": [-1, 0, 0]}]}',
         "key 'normal' in contacts[1]"),
        ('{"object": {}, "object": {}}', "key 'object' at top level"),
    ],
)
def test_json_duplicate_key_is_an_error(tmp_path, raw, where):
    p = tmp_path / "dup.json"
    p.write_text(raw, encoding="utf-8")
    with pytest.raises(GraspValueError) as info:
        load(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}: ") and where in msg and "more than once" in msg and "\n" not in msg, msg


# ----------------------------------------------------------------------------- item 8


def test_inward_normals_are_named_not_silent(run_cli, tmp_path):
    """Inward normals stay valid input (an inside grip: test_degenerate.py), but the CLI
    says which contacts point towards the centre of mass; no negative energy is printed
    where a boundary lies within round-off of the equilibrium (one normal flipped)."""
    from jaxgrasp.model._validation import inward_contacts

    g = presets.cube()
    assert inward_contacts(g.positions, g.normals) == []
    assert inward_contacts(g.positions, -np.asarray(g.normals)) == [0, 1]
    for grasp in [p() for p in presets.PRESETS.values()] + [load(f) for f in sorted(EXAMPLES.iterdir()) if f.suffix in (".toml", ".json")]:
        assert inward_contacts(grasp.positions, grasp.normals) == []  # no note on the shipped grasps
    # one normal flipped: both tips push the same way and let go (unstable)
    one = cube_doc()
    one["contacts"][1]["normal"] = [1.0, 0.0, 0.0]
    p = tmp_path / "one.json"
    p.write_text(json.dumps(one), encoding="utf-8")
    rc, out, err = run_cli(["evaluate", p])
    assert rc == 0 and without_compile_reports(err) == "", err
    lines = out.splitlines()
    notes = [line for line in lines if line.startswith("note: ")]
    assert len(notes) == 1 and "contact 1 " in notes[0] and "centre of mass" in notes[0], out
    energies = [line for line in lines if line.startswith("  contact ") and " J " in line]
    assert len(energies) == 4 and not any(": -" in line for line in energies), out
    # both flipped: the mirror image of the outside grip (same value), and said so in JSON
    both = cube_doc()
    for c in both["contacts"]:
        c["normal"] = [-x for x in c["normal"]]
    p.write_text(json.dumps(both), encoding="utf-8")
    rc, out, err = run_cli(["evaluate", p, "--json"])
    d = json.loads(out)
    assert rc == 0 and d["status"] == "stable"
    assert len(d["notes"]) == 1 and "contacts 0 and 1" in d["notes"][0]


def test_energy_above_equilibrium_is_never_negative(cube_eval):
    u0 = float(cube_eval.equilibrium_energy)
    be = np.array(cube_eval.boundary_energy)
    be[0, 0] = u0 - 4.46e-18  # round-off below the equilibrium (as with one normal flipped)
    d = dataclasses.replace(cube_eval, boundary_energy=be).to_dict()
    first = d["boundaries"][0]
    assert (first["kind"], first["contact"]) == ("slip", 0)
    assert first["energy_above_equilibrium"] == 0.0 and first["energy"] == be[0, 0]
    from jaxgrasp.cli._evaluate import format_summary

    assert "contact 0 slip     : 0.000000e+00 J" in format_summary(d, "x")
    # far below (issue 40: it raised RuntimeError in `jaxgrasp evaluate`): the equilibrium
    # found is a local minimum and the verdict calls the grasp unstable; reported, not raised
    be[0, 0] = u0 - 1e-4
    unstable = dataclasses.replace(
        cube_eval, boundary_energy=be, status=np.int32(jaxgrasp.GraspStatus.UNSTABLE), value=np.float64(0.0)
    )
    d = unstable.to_dict()
    assert d["boundaries"][0]["energy_above_equilibrium"] == 0.0 and d["status"] == "unstable"
    assert "slip of contact 0 lies 0.0001 J below the equilibrium" in d["explanation"], d["explanation"]


# ----------------------------------------------------------------------------- item 9


def test_evaluate_rejects_a_batched_grasp_in_one_line():
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), presets.cube(), presets.cube(6e5))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.evaluate(batch)
    msg = str(info.value)
    assert "jax.vmap(jaxgrasp.evaluate)" in msg and "(2, 2, 3)" in msg and "\n" not in msg, msg


def test_batched_result_status_name_and_tolerates(cube_eval):
    batched = jax.tree_util.tree_map(lambda *x: np.stack(x), cube_eval, cube_eval)
    with pytest.raises(ValueError, match="one grasp's result"):
        batched.status_name
    assert cube_eval.status_name == "stable"
    v = float(cube_eval.value)
    assert bool(cube_eval.tolerates(0.5 * v)) and not bool(cube_eval.tolerates(2 * v))
    assert bool(cube_eval.tolerates(0.0))
    for bad in (-1.0, -1e-30, math.nan, math.inf, np.array([0.0, -1.0])):
        with pytest.raises(ValueError, match="kinetic_energy"):
            cube_eval.tolerates(bad)


# ----------------------------------------------------------------------------- item 10


def test_create_keeps_float32_when_asked():
    kw = dict(radius=0.025, young_modulus=2e5, friction=0.5, max_force=15.0)
    pos = np.array([[0.05, 0, 0], [-0.05, 0, 0]], np.float32)
    nrm = np.array([[1, 0, 0], [-1, 0, 0]], np.float32)
    g32 = jaxgrasp.Grasp.create(pos, nrm, np.float32(2e-3), dtype=jnp.float32, **kw)
    assert {str(a.dtype) for a in g32.to_numpy().values()} == {"float32"}
    assert float(g32.initial_deformation[0]) == float(np.float32(2e-3))
    g64 = jaxgrasp.Grasp.create(pos, nrm, np.float32(2e-3), **kw)  # the default stays float64
    assert {str(a.dtype) for a in g64.to_numpy().values()} == {"float64"}
    with pytest.raises(GraspValueError, match="dtype"):
        jaxgrasp.Grasp.create(pos, nrm, 2e-3, dtype=jnp.int32, **kw)
    # a preset or a loaded file: astype
    cube32 = presets.cube().astype(jnp.float32)
    assert {str(a.dtype) for a in cube32.to_numpy().values()} == {"float32"}


# ----------------------------------------------------------------------------- item 12


@pytest.mark.parametrize(
    "argv, wanted",
    [
        (["--param", "positions"], "--bounds positions=HALF_WIDTH"),
        (["--param", "friction"], "--bounds friction=LO:HI"),
        (["--bounds", "initial_deformation=0.003"], "initial_deformation=LO:HI"),
        (["--param", "positions", "--bounds", "positions=0.001:0.002"], "positions=HALF_WIDTH"),
        (["--bounds", "mass=0:1"], "--param mass"),
    ],
)
def test_cli_tune_errors_name_the_options(run_cli, tmp_path, argv, wanted):
    rc, out, err = run_cli(["tune", "--preset", "cube", *argv, "--out", tmp_path / "t.toml"])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert wanted in err and "bounds={" not in err and "(lo, hi)" not in err, err


@pytest.mark.parametrize(
    "argv, wanted",
    [
        (["--friction", "-1"], "--friction -1: friction must be positive"),
        (["--max-force", "nan"], "--max-force nan: max_force must be finite"),
        (["--initial-deformation", "0.03"], "--initial-deformation 0.03"),
    ],
)
def test_cli_override_errors_name_the_option(run_cli, argv, wanted):
    rc, out, err = run_cli(["evaluate", "--preset", "cube", *argv])
    assert rc == 2 and err.count("\n") == 1, err
    assert wanted in err and "[0]" not in err, err


def test_cli_help_has_no_markup(capsys):
    from jaxgrasp.cli import main

    for argv in ([], ["evaluate"], ["sweep"], ["tune"], ["show"]):
        with pytest.raises(SystemExit):
            main([*argv, "--help"])
        text = capsys.readouterr().out
        assert "usage:" in text and "`" not in text, text


def test_folder_as_grasp_file(run_cli, tmp_path):
    with pytest.raises(GraspValueError, match="is a folder"):
        load(tmp_path)
    rc, _, err = run_cli(["evaluate", tmp_path])
    assert rc == 2 and "is a folder" in err and "''" not in err, err


def test_boundary_energies_named_unambiguously(cube_eval):
    from jaxgrasp.cli._evaluate import format_summary

    d = cube_eval.to_dict()
    u0 = d["equilibrium_energy"]
    for b in d["boundaries"]:
        if b["energy"] is None:
            assert b["energy_above_equilibrium"] is None
        else:
            assert b["energy_above_equilibrium"] == pytest.approx(b["energy"] - u0, abs=1e-18)
    reached = [b["energy_above_equilibrium"] for b in d["boundaries"] if b["energy"] is not None]
    assert min(reached) == pytest.approx(d["value"], rel=1e-12)
    assert d["units"]["energy_above_equilibrium"] == "J"
    text = format_summary(d, "x")
    assert "boundaries (energy above equilibrium, J):" in text, text


def _fake_sweep(status: str, value: float, size: int):
    best = {"index": (0,), "value": value, "young_modulus": 2e5, "status": status,
            "limiting_kind": "none", "limiting_contact": -1}
    counts = {"stable": 0, "unstable": 0, "infeasible": 0, "not_converged": 0}
    counts[status] = size
    return types.SimpleNamespace(
        best=lambda: best, axes={"young_modulus": np.full(size, 2e5)}, size=size,
        counts=lambda: counts, compile_seconds=0.0, run_seconds=0.0,
    )


def test_sweep_summary_wording():
    from jaxgrasp.cli._sweep import _summary_line

    line = _summary_line(_fake_sweep("infeasible", 0.0, 1), "preset cube", 1.0, Path("o"), ["sweep.npz"])
    assert "1 point " in line and "1 points" not in line, line
    assert "best: none (no stable point)" in line and "0.000000e+00" not in line, line
    line = _summary_line(_fake_sweep("unstable", 0.0, 3), "preset cube", 1.0, Path("o"), ["sweep.npz"])
    assert "3 points " in line and "best: none (no stable point)" in line, line


def _not_writable_folder(tmp_path) -> Path | None:
    """A folder this process cannot write in (root writes anywhere chmod allows: /sys)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    for folder in (ro, Path("/sys/kernel")):
        try:
            (folder / "probe").write_bytes(b"")
            (folder / "probe").unlink()
        except OSError:
            return folder
    return None


@pytest.mark.slow  # a subprocess
def test_read_only_cache_folder_is_quiet(tmp_path):
    folder = _not_writable_folder(tmp_path)
    if folder is None:
        pytest.skip("no folder that this process cannot write")
    code = textwrap.dedent(
        """
        import jax, jax.numpy as jnp
        from jaxgrasp.engine import enable_compilation_cache
        print(enable_compilation_cache())
        print(float(jax.jit(lambda x: jnp.sin(x) * 3.0 + 1.0)(jnp.float64(0.5))))
        print(jax.config.jax_persistent_cache_enable_xla_caches)
        """
    )
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(folder), PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == str(folder)  # still read: a shared, pre-filled cache works
    assert r.stdout.splitlines()[2] == "none"  # XLA's own caches (a GPU's autotuning) not pointed there
    assert r.stderr == "", r.stderr
