"""The planner on a real object (pybullet's generated object 000, in mm): every ranked grasp keeps
the contact rules (checked here in NumPy, apart from the JAX rules), ranking and reproducibility,
the antipodal sampler's closed form on a box, and ``jaxgrasp plan``'s files."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

import jaxgrasp
from jaxgrasp.io._mesh import load_mesh
from jaxgrasp.surface import closest_on_triangles
from jaxgrasp.planning import PlanStatus, plan
from jaxgrasp.planning._sampling import antipodal_pairs, first_hits, spread_tuples, surface_points

MESH = Path(__file__).resolve().parents[2] / "examples" / "meshes" / "pybullet_000_mm.obj"
TIP = dict(radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0)
SMALL = dict(units="mm", density=500.0, samples=48, top=5, refine=1, tune_maxiter=6, **TIP)


@pytest.fixture(scope="module")
def planned():
    return plan(MESH, 2, seed=3, **SMALL)


def _numpy_rules(mesh, pos, nrm, dr, r=0.01, flatness_deg=25.0):
    """The five rules of :mod:`jaxgrasp.surface`, brute force in NumPy over every face."""
    tri, fn = np.asarray(mesh.triangles), np.asarray(mesh.face_normals)
    ok = True
    c = pos + (r - dr)[:, None] * nrm
    for i, p in enumerate(pos):
        d = np.linalg.norm(closest_on_triangles(p, tri, xp=np) - p, axis=1)
        on = d.min() < 1e-6 and np.any(fn[d < 1e-6] @ nrm[i] > np.cos(np.radians(2.0)))
        a = np.sqrt(r**2 - (r - dr[i]) ** 2)
        flat = np.all(fn[d <= a] @ nrm[i] >= np.cos(np.radians(flatness_deg)))
        dc = np.linalg.norm(closest_on_triangles(c[i], tri, xp=np) - c[i], axis=1).min()
        alone = dc >= r - dr[i] - 1e-6
        apart = all(np.linalg.norm(c[i] - c[j]) >= 2 * r for j in range(len(pos)) if j != i)
        in_range = 5e-4 <= dr[i] <= min(0.9 * r, np.sqrt(15.0 / (np.pi * 3e5)))
        ok = ok and on and flat and alone and apart and in_range
    return ok


def test_ranked_grasps_keep_every_rule_and_are_sorted(planned):
    res = planned
    assert res.status == PlanStatus.FOUND and res.valid == 48 and res.sampled >= 48
    assert len(res.grasps) == 5 and np.all(np.diff(res.values) <= 0) and res.values[0] > 0
    assert set(res.statuses.tolist()) <= {0, 1, 2}  # settled only
    mesh = load_mesh(MESH, "mm")
    for g, mp in zip(res.grasps, res.mesh_positions):
        np.testing.assert_allclose(g.to_mesh_frame(g.grasp.positions), mp, atol=1e-15)
        assert _numpy_rules(mesh, mp, np.asarray(g.grasp.normals), np.asarray(g.grasp.initial_deformation))
    # the values are those of the grasps as their files load
    assert jaxgrasp.evaluate(res.best.grasp).value == res.values[0]
    assert res.epsilon[0] == pytest.approx(jaxgrasp.epsilon(res.best.grasp).value, rel=1e-12)


def test_same_seed_same_plan_other_seed_other_candidates(planned):
    again = plan(MESH, 2, seed=3, **SMALL)
    np.testing.assert_array_equal(again.values, planned.values)
    np.testing.assert_array_equal(again.mesh_positions, planned.mesh_positions)
    other = plan(MESH, 2, seed=4, **{**SMALL, "refine": 0})
    assert not np.array_equal(other.mesh_positions[0], planned.mesh_positions[0])


def test_antipodal_pairs_on_a_box_are_opposite_face_points():
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.04])
    tri, fn = np.asarray(box.triangles), np.asarray(box.face_normals)
    rng = np.random.default_rng(0)
    p, n = surface_points(tri, fn, 200, rng)
    pos, nrm = antipodal_pairs(tri, fn, p, n, friction=0.5)
    assert len(pos) == 200  # every ray through a box leaves through the opposite face
    np.testing.assert_allclose(nrm[:, 1], -nrm[:, 0], atol=1e-15)
    np.testing.assert_allclose(pos[:, 1] - pos[:, 0], -nrm[:, 0] * np.abs(np.einsum("kd,kd->k", pos[:, 1] - pos[:, 0], nrm[:, 0]))[:, None], atol=1e-12)
    t, face = first_hits(tri, np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert t[0] == pytest.approx(0.05) and fn[face[0]] @ [1, 0, 0] == pytest.approx(1.0)


def test_spread_tuples_on_a_box_carry_the_weight_from_below():
    # on a box no three face normals sum to zero; under gravity -z the best tuples push up
    # from the bottom face (normal -z) and pinch two opposite sides: normals summing to -z
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.04])
    tri, fn = np.asarray(box.triangles), np.asarray(box.face_normals)
    p, n = surface_points(tri, fn, 300, np.random.default_rng(1))
    pos, nrm = spread_tuples(p, n, 3, 40, np.random.default_rng(2), down=np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(nrm.sum(axis=1), np.tile([0.0, 0.0, -1.0], (40, 1)), atol=1e-12)
    _, flat = spread_tuples(p, n, 3, 40, np.random.default_rng(2))  # without a load: any two opposite
    assert np.all(np.linalg.norm(flat.sum(axis=1), axis=1) == pytest.approx(1.0))


def test_plan_rejects_bad_arguments_in_one_line():
    with pytest.raises(jaxgrasp.GraspValueError, match="fingers must be an integer >= 2"):
        plan(MESH, 1, **SMALL)
    with pytest.raises(jaxgrasp.GraspValueError, match="antipodal sampler makes two-finger grasps"):
        plan(MESH, 3, sampler="antipodal", **SMALL)
    with pytest.raises(jaxgrasp.GraspValueError, match="no initial deformation keeps rule 5"):
        plan(MESH, 2, **{**SMALL, "max_force": 0.01})


def test_cli_plan_writes_the_ranked_set(tmp_path, run_cli):
    out = tmp_path / "plan"
    rc, stdout, err = run_cli(["plan", MESH, "--units", "mm", "--fingers", "2", "--samples", "48", "--top", "4",
                               "--refine", "0", "--seed", "3", "--out", out])
    assert rc == 0, err
    assert {p.name for p in out.iterdir()} >= {"ranked.jsonl", "best.toml", "results.csv", "best.png",
                                               MESH.name}
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["rank"] for r in rows] == ["1", "2", "3", "4"]
    assert "found: best value" in stdout and "jaxgrasp: plan:" in err
    rc, js, err = run_cli(["evaluate", out / "best.toml", "--json"])
    assert rc == 0, err
    assert json.loads(js)["value"] == float(rows[0]["value_J"])  # the very same number
    lines = (out / "ranked.jsonl").read_text().splitlines()
    assert len(lines) == 4 and all(json.loads(x)["object"]["mesh"] == MESH.name for x in lines)


def test_no_single_contact_keeps_the_rules_gives_no_valid_not_an_error():
    """An object too small for the fingertip (no point of it is flat over the contact's
    radius) gives the antipodal sampler an empty pool of single contacts every round: the
    plan then says ``no_valid`` (``random_urdfs`` 037 and 086 once raised in the ray cast)."""
    empty = np.zeros((0, 3))
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.04])
    pos, nrm = antipodal_pairs(np.asarray(box.triangles), np.asarray(box.face_normals), empty, empty, friction=0.5)
    assert pos.shape == (0, 2, 3) and nrm.shape == (0, 2, 3)
    tiny = trimesh.creation.icosahedron()
    tiny.apply_scale(0.002)  # m: 2 mm across, under a 10 mm fingertip
    res = plan(tiny, 2, units="m", density=500.0, samples=4, top=2, refine=0, **TIP)
    assert res.status == PlanStatus.NO_VALID
    assert len(res.grasps) == 0 and "contact rules" in res.status.message


# --------------------------------------------------------------------------- input checks


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory):
    """A folder with a 0.1 m box, an open box, a file that is not a mesh and an empty one."""
    folder = tmp_path_factory.mktemp("plan_inputs")
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    box.export(folder / "block.stl")
    trimesh.Trimesh(box.vertices, box.faces[box.face_normals[:, 2] < 0.5]).export(folder / "open.stl")
    (folder / "notmesh.stl").write_text("hello\n")
    (folder / "empty.stl").write_bytes(b"")
    return folder


@pytest.mark.parametrize(
    "mesh, options, message",
    [
        ("nonexist.stl", [], "nonexist.stl': no such file"),
        ("notmesh.stl", [], "notmesh.stl' has no faces"),
        ("empty.stl", [], "empty.stl' has no faces"),
        ("block.stl", ["--fingers", "1"], "fingers must be an integer >= 2, got 1"),
        ("block.stl", ["--fingers", "9"], "--fingers must be at most 8 fingertips, got 9"),
        ("block.stl", ["--samples", "0"], "samples must be an integer >= 1, got 0"),
        ("block.stl", ["--top", "0"], "top must be an integer >= 1, got 0"),
        ("block.stl", ["--refine", "-1"], "refine must be an integer >= 0, got -1"),
        ("block.stl", ["--seed", "-1"], "seed must be an integer >= 0, got -1"),
        ("block.stl", ["--flatness", "-5"], "flatness_deg = -5.0 must be a number of degrees in [0, 90)"),
        ("block.stl", ["--flatness", "nan"], "flatness_deg = nan must be a number of degrees"),
        ("block.stl", ["--sampler", "antipodal", "--fingers", "3"], "antipodal sampler makes two-finger grasps, not 3"),
        ("block.stl", ["--max-force", "0.001"], "no initial deformation keeps rule 5"),
        ("open.stl", [], ("open.stl' is not watertight (not a closed surface), so it has no centre of mass or "
                          "volume of its own: plan needs a closed mesh")),
    ],
    ids=["missing", "not-a-mesh", "empty", "fingers-1", "fingers-9", "samples-0", "top-0", "refine--1", "seed--1",
         "flatness--5", "flatness-nan", "antipodal-3", "rule-5", "open"],
)
def test_cli_plan_bad_input_creates_nothing(bad_inputs, tmp_path, run_cli, mesh, options, message):
    """Every option and the mesh are checked (``check_plan``) before ``--out`` is created and
    before the "compiling first" line: bad input leaves no folder and prints one line. An
    open mesh is not sent to ``center_of_mass``, a grasp-file key ``plan`` has no option for."""
    out = tmp_path / "pz" / "a" / "b"
    rc, stdout, err = run_cli(["plan", bad_inputs / mesh, *options, "--out", out])
    assert rc == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith("jaxgrasp: error: ") and message in err and "give center_of_mass" not in err, err
    assert not (tmp_path / "pz").exists()


def test_plan_and_check_plan_take_the_same_arguments():
    import inspect

    from jaxgrasp.planning import check_hand_plan
    from jaxgrasp.planning._plan import check_plan

    params = dict(inspect.signature(plan).parameters)
    params.pop("progress")
    hand_only = ("hand", "fingertips", "min_fingertips", "objective", "max_penetration")
    # plan's defaults of fingers, radius and samples are None: resolved for free fingertips or a hand
    assert list(inspect.signature(check_plan).parameters) == [n for n in params if n not in hand_only]
    assert set(inspect.signature(check_hand_plan).parameters) <= set(params)


def test_density_zero_is_a_weightless_object(bad_inputs, tmp_path, run_cli, monkeypatch):
    """``--density 0`` was replaced by the default 500 kg/m^3 (``0 or 500``): it now reaches
    :func:`jaxgrasp.plan` as 0, a mass of 0 (the model's default, no weight to carry)."""
    import jaxgrasp.planning

    got = {}

    def stop(mesh, fingers, progress=None, **kwargs):
        got.update(kwargs, mesh=mesh, fingers=fingers)
        raise jaxgrasp.GraspValueError("stopped before planning")

    monkeypatch.setattr(jaxgrasp.planning, "plan", stop)
    rc, _, err = run_cli(["plan", bad_inputs / "block.stl", "--density", "0", "--quiet", "--out", tmp_path / "o"])
    assert rc == 2 and "stopped before planning" in err, err
    assert got["density"] == 0.0

    from jaxgrasp.planning._plan import check_plan

    options = {k: v for k, v in got.items() if k not in ("mesh", "fingers")}
    assert check_plan(got["mesh"], got["fingers"], **options).mass == 0.0
    rc, _, err = run_cli(["plan", bad_inputs / "block.stl", "--density", "-1", "--out", tmp_path / "o2"])
    assert rc == 2 and "--density must be a finite number >= 0, got -1" in err and not (tmp_path / "o2").exists()
    # the default: 500 kg/m^3 of a 0.1 m box (its STL's float32 vertices)
    rc, _, err = run_cli(["plan", bad_inputs / "block.stl", "--quiet", "--out", tmp_path / "o3"])
    options = {k: v for k, v in got.items() if k not in ("mesh", "fingers")}
    assert got["density"] == 500.0 and check_plan(got["mesh"], 2, **options).mass == pytest.approx(0.5, rel=1e-6)
