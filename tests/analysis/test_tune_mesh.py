"""Tuning positions on a mesh grasp slides the contacts along the surface (issue 36): they stay on
it, their normals are the faces', the value rises, and the tuned grasp file names the mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import jaxgrasp
from jaxgrasp.analysis._tune_spec import face_basis
from jaxgrasp.surface import Surface

RADIUS = 0.02  # m, the icosphere of the issue: 40 mm across


@pytest.fixture(scope="module")
def ball_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ball")
    trimesh.creation.icosphere(subdivisions=3, radius=RADIUS * 1e3).export(folder / "ball.stl")  # in mm
    ang = np.deg2rad([90.0, 210.0, 330.0])
    pts = np.stack([RADIUS * np.cos(ang), RADIUS * np.sin(ang), np.zeros(3)], axis=1)
    mg = jaxgrasp.from_mesh(folder / "ball.stl", pts, units="mm", initial_deformation=2e-3, radius=0.01,
                            young_modulus=3e5, friction=0.8, max_force=15.0, mass=0.05, gravity=(0.0, -9.81, 0.0),
                            tolerance=2e-3)
    jaxgrasp.save(mg, folder / "grasp.toml")
    return folder / "grasp.toml"


@pytest.fixture(scope="module")
def tuned(ball_file):
    mg = jaxgrasp.load(ball_file, keep_mesh=True)
    return mg, jaxgrasp.tune(mg, ["initial_deformation", "positions"], {"positions": 0.01}, maxiter=12)


def _face_angles_deg(surface: Surface, points, normals) -> np.ndarray:
    """Angle between each normal and the normal of the face its point lies on."""
    hit = surface.closest(points)
    cos = np.sum(np.asarray(hit.normal) * np.asarray(normals), axis=1) / np.linalg.norm(normals, axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))), np.asarray(hit.distance)


def test_tuned_contacts_stay_on_the_surface_with_its_normals(tuned):
    start, res = tuned
    surface = Surface.from_trimesh(start.mesh)
    pts = res.mesh_grasp.to_mesh_frame(res.grasp.positions)
    angle, dist = _face_angles_deg(surface, pts, res.grasp.normals)
    moved = np.linalg.norm(pts - start.to_mesh_frame(start.grasp.positions), axis=1)
    assert res.value > res.start_value > 0
    assert moved.max() > 2e-3  # contacts slid by millimetres, across faces of a ~6 mm facet mesh
    assert dist.max() < 1e-6 and angle.max() < 2.0
    # the old way, a move of the same size in the tangent plane, leaves the curved surface
    k = int(np.argmax(moved))
    plane = start.to_mesh_frame(start.grasp.positions)[k] + moved[k] * face_basis(start.grasp.normals)[k, 0]
    old_angle, old_dist = _face_angles_deg(surface, plane[None], start.grasp.normals[k][None])
    assert old_dist[0] > 1e-5 and old_angle[0] > 2.0


def test_tuned_grasp_file_names_the_mesh_and_loads_back(tuned, tmp_path):
    _, res = tuned
    jaxgrasp.save(res.mesh_grasp, tmp_path / "tuned.toml", copy_mesh=True)
    text = (tmp_path / "tuned.toml").read_text()
    assert 'mesh = "ball.stl"' in text and 'units = "mm"' in text and (tmp_path / "ball.stl").is_file()
    back = jaxgrasp.load(tmp_path / "tuned.toml", keep_mesh=True)
    np.testing.assert_allclose(np.asarray(back.grasp.positions), np.asarray(res.grasp.positions), atol=1e-15)
    np.testing.assert_array_equal(np.asarray(back.grasp.normals), np.asarray(res.grasp.normals))
    assert jaxgrasp.evaluate(back.grasp).value == pytest.approx(res.value, rel=1e-12)


def test_cli_tune_of_a_mesh_grasp_writes_a_file_naming_the_mesh(ball_file, tmp_path, run_cli):
    out = tmp_path / "out" / "tuned.toml"
    rc, stdout, err = run_cli(["tune", ball_file, "--param", "initial_deformation", "--param", "positions", "--bounds",
                               "positions=0.01", "--maxiter", "12", "--no-plot", "--quiet", "--out", out])
    assert rc == 0, err
    back = jaxgrasp.load(out, keep_mesh=True)  # the mesh was copied beside it
    assert back.units == "mm" and (out.parent / "ball.stl").is_file()
    surface = Surface.from_trimesh(back.mesh)
    angle, dist = _face_angles_deg(surface, back.to_mesh_frame(back.grasp.positions), back.grasp.normals)
    assert dist.max() < 1e-6 and angle.max() < 2.0
    value = float(stdout.split("-> ")[1].split(" J")[0])
    assert jaxgrasp.evaluate(back.grasp).value == pytest.approx(value, rel=1e-6)
