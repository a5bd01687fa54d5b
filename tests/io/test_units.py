"""Unit mistakes named (issue 65, item 7): a grasp written in mm, a mesh in mm read as
metres, positions and mesh that disagree.

Each is a one-line [`GraspValueError`][jaxgrasp.GraspValueError] naming the field, its
value and the fix, and on the command line one line on stderr with exit status 2, well
within 60 s: everything here stops at reading the input, before anything is compiled
(the command line runs in-process, ``run_cli``). The correct files still load.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import jaxgrasp
from jaxgrasp import GraspValueError, load_dataset
from jaxgrasp.io import grasp_from_dict
from jaxgrasp.model import MAX_CONTACT_DISTANCE, MAX_FINGERTIP_RADIUS, MAX_OBJECT_SIZE, CheckReason
from jaxgrasp.planning import check_plan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
FINGERTIP = {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15.0}
PLAN = dict(radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0, density=700.0)


def cube(radius=0.025, deformation=0.002, half_side=0.05) -> dict:
    """The paper's cube grasp as grasp-file data, its lengths as given."""
    contacts = [
        {"position": [half_side, 0, 0], "normal": [1, 0, 0], "initial_deformation": deformation},
        {"position": [-half_side, 0, 0], "normal": [-1, 0, 0], "initial_deformation": deformation},
    ]
    return {"fingertip": {**FINGERTIP, "radius": radius}, "contacts": contacts}


def one_line(exc_info) -> str:
    text = str(exc_info.value)
    assert "\n" not in text, text
    return text


def cli_error(run_cli, argv) -> str:
    """The one line the command prints (exit status 2, nothing on stdout, within 60 s)."""
    t0 = time.perf_counter()
    rc, out, err = run_cli(argv)
    assert time.perf_counter() - t0 < 60
    assert rc == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, (rc, out, err)
    return err


# --------------------------------------------------------------------------- grasps in mm


def test_a_grasp_file_in_mm_is_one_line_naming_metres(tmp_path, run_cli):
    """The cube with every length in mm ran (exit 0) and said 'infeasible ... force margin
    -0.998', no word about units."""
    path = tmp_path / "cube_mm.json"
    path.write_text(json.dumps(cube(radius=25, deformation=2, half_side=50)))
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.load(path)
    text = one_line(info)
    assert text == (f"{path}: radius = 25 m is larger than any fingertip (at most 1 m): the grasp's lengths look "
                    "like millimetres; write every length in metres (radius = 0.025; positions and "
                    "initial_deformation likewise)"), text
    err = cli_error(run_cli, ["evaluate", path])
    assert err == f"jaxgrasp: error: {text}\n"


def test_positions_in_mm_name_the_contact_and_its_metres():
    fields = dict(positions=[[50.0, 0, 0], [-50.0, 0, 0]], normals=[[1.0, 0, 0], [-1.0, 0, 0]],
                  initial_deformation=0.002, **FINGERTIP)
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.Grasp.create(**fields)
    assert one_line(info) == ("positions[0] = [50, 0, 0] m is 50 m from the centre of mass, farther than a "
                              "fingertip grasp reaches (at most 10 m): the positions look like millimetres; write "
                              "them in metres ([0.05, 0, 0])")


def test_a_deformation_in_mm_says_so():
    with pytest.raises(GraspValueError) as info:
        grasp_from_dict(cube(deformation=2))
    assert one_line(info) == ("<dict>: initial_deformation[0] = 2 m must be in (0, radius = 0.025 m): it looks "
                              "like millimetres; write it in metres (0.002)")
    with pytest.raises(GraspValueError) as info:  # a deformation beyond the radius, in metres: no such hint
        grasp_from_dict(cube(deformation=0.03))
    assert one_line(info).endswith("must be in (0, radius = 0.025 m)")


def test_the_limits_themselves_are_valid():
    """A fingertip of exactly `MAX_FINGERTIP_RADIUS`, contacts exactly
    `MAX_CONTACT_DISTANCE` from the centre of mass: accepted (rules are ``<=``)."""
    g = jaxgrasp.Grasp.create(
        positions=[[MAX_CONTACT_DISTANCE, 0, 0], [0, -MAX_CONTACT_DISTANCE, 0]], normals=[[1.0, 0, 0], [0, -1.0, 0]],
        initial_deformation=0.002, **{**FINGERTIP, "radius": MAX_FINGERTIP_RADIUS},
    )
    assert bool(jaxgrasp.check(g).valid)
    with pytest.raises(GraspValueError, match=r"^radius = 1\.000001 m is larger than any fingertip"):
        jaxgrasp.Grasp.create(**{**g.to_numpy(), "radius": 1.000001})


def test_check_flags_a_grasp_in_mm_as_validation_rejects_it():
    """`jaxgrasp.check` states the same rule (`CheckReason.SIZE`) for traced grasps."""
    g = jaxgrasp.presets.cube(2e5, 0.002)
    for broken in (g.replace(radius=jnp.full(2, 25.0), initial_deformation=jnp.full(2, 2.0)),
                   g.replace(positions=g.positions * 1e3)):
        got = jaxgrasp.check(broken)
        assert int(got.reason) == CheckReason.SIZE and int(got.contact) == 0
        with pytest.raises(GraspValueError, match="millimetres"):
            jaxgrasp.Grasp.create(**broken.to_numpy())


def test_a_dataset_row_in_mm_is_an_invalid_row_and_batch_says_why(tmp_path, run_cli):
    path = tmp_path / "set.jsonl"
    path.write_text(json.dumps(cube(radius=25, deformation=2, half_side=50)) + "\n")
    got = load_dataset(path)
    assert got.valid.tolist() == [False]
    assert "radius = 25 m is larger than any fingertip" in got.errors[0] and "(radius = 0.025;" in got.errors[0]
    err = cli_error(run_cli, ["batch", path, "--out", tmp_path / "out"])
    assert "no valid grasp (1 invalid; first: grasp 0 (line 1): radius = 25 m is larger than any fingertip" in err


# --------------------------------------------------------------------------- meshes and their units


@pytest.fixture(scope="module")
def block(tmp_path_factory) -> Path:
    """``examples/block.stl`` (mm) beside ``examples/block.toml`` and its variants."""
    folder = tmp_path_factory.mktemp("block")
    (folder / "block.stl").write_bytes((EXAMPLES / "block.stl").read_bytes())
    text = (EXAMPLES / "block.toml").read_text()
    (folder / "block.toml").write_text(text)
    (folder / "no_units.toml").write_text("".join(line for line in text.splitlines(True)
                                                  if not line.startswith("units")))
    mm = text.replace("[0.01, 0.03, 0.02]", "[10, 30, 20]").replace("[0.01, -0.03, 0.02]", "[10, -30, 20]")
    (folder / "positions_mm.toml").write_text(mm)
    return folder


def test_a_mesh_in_mm_without_its_units_line_names_the_line(block, run_cli):
    """``examples/block.toml`` without ``units = "mm"`` told the user to write positions in
    metres, which they were: the missing line is the fix."""
    path = block / "no_units.toml"
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.load(path)
    text = one_line(info)
    assert text == (f"{path}: mesh '{block}/block.stl' is 120 m across, larger than an object fingers grasp "
                    '(at most 5 m): if its vertices are in mm, add units = "mm" to [object]'), text
    assert "write them in metres" not in text
    assert cli_error(run_cli, ["evaluate", path]) == f"jaxgrasp: error: {text}\n"
    assert cli_error(run_cli, ["show", path, "--out", block / "no.png"]) == f"jaxgrasp: error: {text}\n"


def test_positions_in_mm_on_a_mesh_in_mm_name_metres(block, run_cli):
    path = block / "positions_mm.toml"
    err = cli_error(run_cli, ["evaluate", path])
    assert "the contact positions lie on the surface when read as millimetres: write them in metres" in err, err


def test_the_example_itself_loads(block):
    made = jaxgrasp.load(block / "block.toml", keep_mesh=True)
    assert made.units == "mm" and np.ptp(made.mesh.vertices, axis=0).max() == pytest.approx(0.12)


def test_metres_on_a_small_mesh_in_mm_read_as_metres_name_its_units():
    """A 4 mm cube (vertices in mm) with its origin on its bottom face, read as metres: the
    contacts, in metres, lie on it shrunk 1000 times. Read as mm they all fall within 1 mm
    of the origin, which is on the surface: that used to say 'write them in metres'."""
    mesh = trimesh.creation.box(extents=(4.0, 4.0, 4.0))
    mesh.apply_translation([0, 0, 2.0])  # origin at the centre of the bottom face
    points = [[0.002, 0.0, 0.002], [-0.002, 0.0, 0.002]]  # m: the +-x faces' centres
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.from_mesh(mesh, points, initial_deformation=2e-4, **FINGERTIP)
    text = one_line(info)
    assert 'as if its vertices were in mm: add units = "mm" to [object] (Python: units="mm")' in text, text
    made = jaxgrasp.from_mesh(mesh, points, units="mm", initial_deformation=2e-4, **FINGERTIP)
    np.testing.assert_allclose(made.grasp.normals, [[1, 0, 0], [-1, 0, 0]], atol=1e-12)


def test_plan_of_a_mm_mesh_without_units_names_the_option(block, run_cli, tmp_path):
    """``jaxgrasp plan`` of a mm mesh without ``--units`` failed on the weight (1e9 too
    heavy) after drawing its candidates, not naming ``--units``."""
    mesh = block / "block.stl"
    err = cli_error(run_cli, ["plan", mesh, "--out", tmp_path / "plan", "--quiet"])
    assert err == (f"jaxgrasp: error: mesh '{mesh}' is 120 m across, larger than an object fingers grasp (at most "
                   '5 m): if its vertices are in mm, pass --units mm (Python: units="mm")\n'), err
    assert not (tmp_path / "plan").exists()
    with pytest.raises(GraspValueError, match=r'is 120 m across.*units="mm"'):
        check_plan(mesh, 2, **PLAN)
    checked = check_plan(mesh, 2, units="mm", **PLAN)  # the right units: the block weighs 0.2 kg
    assert checked.mass == pytest.approx(700.0 * 0.12 * 0.06 * 0.04, rel=0.02)


def test_a_mesh_up_to_the_size_limit_loads():
    from jaxgrasp.io import load_mesh

    assert load_mesh(trimesh.creation.box(extents=(MAX_OBJECT_SIZE, 1.0, 1.0))).is_watertight
    with pytest.raises(GraspValueError) as info:
        load_mesh(trimesh.creation.box(extents=(1.01 * MAX_OBJECT_SIZE, 1.0, 1.0)))
    assert one_line(info).startswith("mesh is 5.05 m across, larger than an object fingers grasp (at most 5 m): "
                                     'if its vertices are in mm, pass units="mm"')
