"""Objects from meshes (``jaxgrasp.from_mesh``, grasp files with ``[object] mesh``) and
``jaxgrasp show``.

Every grasp evaluated here has 2 contacts, like the paper's cube, so it reuses the
session's compiled ``evaluate`` (no new compilation); the CLI runs in-process.
"""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pytest
import trimesh

import jaxgrasp
from jaxgrasp.io import from_mesh
from jaxgrasp.surface import closest_on_triangles
from jaxgrasp.plots._scene import COLORS

FINGER = dict(initial_deformation=2e-3, radius=0.025, young_modulus=6e5, friction=0.5, max_force=15.0)
POINTS = np.array([[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]])  # m: centres of the +-x faces
OFFSET = np.array([0.013, -0.021, 0.034])  # m: a mesh origin away from the centre of mass

CUBE_FILE = """
[fingertip]
radius = 0.025
young_modulus = 6e5
friction = 0.5
max_force = 15.0

[object]
{object}

[[contacts]]
position = {p0}
initial_deformation = 0.002

[[contacts]]
position = {p1}
initial_deformation = 0.002
"""


def box(size=0.1):
    return trimesh.creation.box(extents=(size, size, size))


def open_box():
    """The cube without its top (+z) face: not watertight."""
    b = box()
    return trimesh.Trimesh(b.vertices, b.faces[b.face_normals[:, 2] < 0.5])


def value(grasp) -> float:
    return float(jaxgrasp.evaluate(grasp).value)


def rel(a, b) -> float:
    return abs(a - b) / abs(b)


def write_grasp(folder, object_lines, points=POINTS, name="g.toml"):
    """A cube grasp file naming a mesh: ``object_lines`` is the body of ``[object]``."""
    text = CUBE_FILE.format(object=object_lines, p0=list(map(float, points[0])), p1=list(map(float, points[1])))
    path = folder / name
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def cube_value():
    """The paper's cube preset at E = 6e5 Pa, dr = 2 mm (J)."""
    v = value(jaxgrasp.presets.cube(6e5, 2e-3))
    assert v > 0
    return v


# --------------------------------------------------------------------------- from_mesh


def test_box_mesh_is_the_papers_cube(cube_value):
    made = from_mesh(box(), POINTS, **FINGER)
    preset = jaxgrasp.presets.cube(6e5, 2e-3)
    for name in jaxgrasp.model._fields.NAMES:
        np.testing.assert_allclose(getattr(made.grasp, name), getattr(preset, name), rtol=0, atol=1e-15)
    # the design: the model pytree is exactly a plain grasp's (no new compilation, no new key)
    assert jax.tree_util.tree_structure(made.grasp) == jax.tree_util.tree_structure(preset)
    assert rel(value(made.grasp), cube_value) < 1e-12


def test_origin_off_the_centre_of_mass(cube_value):
    mesh = box()
    mesh.apply_translation(OFFSET)
    made = from_mesh(mesh, POINTS + OFFSET, **FINGER)
    np.testing.assert_allclose(made.center_of_mass, OFFSET, atol=1e-15)
    np.testing.assert_allclose(made.grasp.positions, POINTS, atol=1e-15)  # centre-of-mass frame
    np.testing.assert_allclose(made.to_mesh_frame(made.grasp.positions), POINTS + OFFSET, atol=1e-15)
    assert rel(value(made.grasp), cube_value) < 1e-12


def test_rotated_mesh_with_gravity_rotated_alike():
    rot = trimesh.transformations.random_rotation_matrix(np.random.default_rng(3).random(3))
    density = 50.0  # kg/m^3: 0.05 kg, so gravity matters
    plain = from_mesh(box(), POINTS, density=density, **FINGER)
    mesh = box()
    mesh.apply_transform(rot)
    turned = from_mesh(mesh, POINTS @ rot[:3, :3].T, density=density, gravity=rot[:3, :3] @ [0, 0, -9.81], **FINGER)
    assert float(plain.grasp.mass) == pytest.approx(density * 1e-3, rel=1e-12)  # density x volume
    v0, v1 = value(plain.grasp), value(turned.grasp)
    assert v0 > 0 and rel(v1, v0) < 1e-9  # the same grasp, written in turned axes


def test_normals_are_the_face_normals_and_points_are_snapped():
    mesh = box()
    mesh.apply_translation(OFFSET)
    pts = np.array([[0.0504, 0.01, -0.02], [0.01, -0.0497, 0.03]]) + OFFSET  # 0.4 and 0.3 mm off
    made = from_mesh(mesh, pts, **FINGER)
    np.testing.assert_allclose(made.grasp.normals, [[1, 0, 0], [0, -1, 0]], atol=1e-15)
    np.testing.assert_allclose(made.grasp.positions, [[0.05, 0.01, -0.02], [0.01, -0.05, 0.03]], atol=1e-15)


def test_curved_surface_normal_is_radial():
    """On a tessellated cylinder a point on a seam between facets gets their mean normal."""
    cyl = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=48)
    angles = [0.0, 0.3]  # 0 lies on a seam; 0.3 rad inside a facet
    pts = [[0.03 * math.cos(a), 0.03 * math.sin(a), 0.01] for a in angles]
    made = from_mesh(cyl, pts, **FINGER)
    for a, n in zip(angles, np.asarray(made.grasp.normals)):
        assert math.degrees(math.acos(n @ [math.cos(a), math.sin(a), 0.0])) < 360 / 48 / 2 + 1e-9


def test_center_of_mass_and_mass_of_the_example_block():
    made = jaxgrasp.load("examples/block.toml", keep_mesh=True)
    np.testing.assert_allclose(made.center_of_mass, [0.0, 0.0, 0.02], atol=1e-12)  # 20 mm above its base
    # density x volume, the volume by qhull from the chamfered corners (not by trimesh)
    from scipy.spatial import ConvexHull

    half, cut = np.array([0.06, 0.03, 0.02]), 0.008
    corners = half * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)
    chamfered = np.concatenate([corners - cut * np.sign(corners) * np.eye(3)[k] for k in range(3)])
    assert float(made.grasp.mass) == pytest.approx(700.0 * ConvexHull(chamfered).volume, rel=1e-6)  # STL: float32
    assert made.mesh.is_watertight and made.grasp.num_contacts == 2


def test_closest_point_on_triangles_is_exact():
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 64, 3))
    for p in rng.normal(size=(8, 3)) * 2:
        q = closest_on_triangles(p, np.stack([a, b, c], axis=1), xp=np)  # the NumPy run of the one rule
        # on the triangle: barycentric coordinates in [0, 1]
        m = np.stack([b - a, c - a], axis=-1)
        uv = np.linalg.lstsq(m[0], q[0] - a[0], rcond=None)[0]
        assert uv.min() > -1e-9 and uv.sum() < 1 + 1e-9
        # no sampled point of any triangle is closer
        s = rng.random((4000, 2))
        s[s.sum(1) > 1] = 1 - s[s.sum(1) > 1]
        samples = a[:, None] + s[None, :, :1] * (b - a)[:, None] + s[None, :, 1:] * (c - a)[:, None]
        assert np.all(np.linalg.norm(q - p, axis=1) <= np.linalg.norm(samples - p, axis=2).min(1) + 1e-12)


@pytest.mark.parametrize(
    "make, kwargs, message",
    [
        (box, dict(points=[[0.05, 0, 0], [-0.055, 0.01, 0]]), "contact 1 at (-55, 10, 0) mm is 5 mm from the mesh surface"),
        (open_box, {}, "not watertight"),
        (lambda: trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)), {}, "has no faces"),
        (lambda: trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 1]], process=False), {},
         "encloses no volume"),
        (box, dict(units="inch"), "units = 'inch' is not a length unit; use one of m, cm, mm"),
        (box, dict(mass=1.0, density=1.0), "give mass or density, not both"),
        (box, dict(points=[[0.05, 0.05, 0.0], [-0.05, 0, 0]]), "contact 0 at (50, 50, 0) mm lies on an edge"),
    ],
    ids=["off-surface", "not-watertight", "no-faces", "no-volume", "units", "mass-and-density", "edge"],
)
def test_errors_are_one_line(make, kwargs, message):
    kwargs = {"points": POINTS, **kwargs}
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        from_mesh(make(), kwargs.pop("points"), **kwargs, **FINGER)
    text = str(info.value)
    assert message in text and "\n" not in text


@pytest.mark.parametrize(
    "size, units, points, message",
    [
        (100.0, "mm", POINTS * 1e3, "when read as millimetres: write them in metres"),
        (10.0, "cm", POINTS * 1e2, "when read as centimetres: write them in metres"),
        # a 4 mm cube read as metres: 4 m, under MAX_OBJECT_SIZE (a larger one is refused on its size)
        (4.0, "m", POINTS * 0.04, 'as if its vertices were in mm: add units = "mm"'),
        (0.1, "m", POINTS + [0.01, 0.0, 0.0], "is it in the mesh's frame and units?"),  # no unit explains it
    ],
    ids=["points-in-mm", "points-in-cm", "mesh-in-mm-read-as-m", "elsewhere"],
)
def test_off_surface_contacts_name_the_unit_mistake(size, units, points, message):
    """Issue 35: contacts typed in mm for a mesh in mm (positions are always metres), or a
    mesh in mm read as metres, are named as such, not as a general question."""
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        from_mesh(box(size), points, units=units, **FINGER)
    text = str(info.value)
    assert "from the mesh surface" in text and message in text and "\n" not in text, text


def test_not_watertight_with_a_center_of_mass_is_fine():
    made = from_mesh(open_box(), POINTS, center_of_mass=[0, 0, 0], mass=0.1, **FINGER)
    np.testing.assert_allclose(made.grasp.normals, [[1, 0, 0], [-1, 0, 0]], atol=1e-15)


# --------------------------------------------------------------------------- grasp files


@pytest.fixture(scope="module")
def mm_files(tmp_path_factory):
    """The cube as an STL in mm whose origin is off the centre of mass, and grasp files."""
    folder = tmp_path_factory.mktemp("mesh")
    mesh = box(100.0)
    mesh.apply_translation(OFFSET * 1e3)
    mesh.export(folder / "cube_mm.stl")
    good = write_grasp(folder, 'mesh = "cube_mm.stl"\nunits = "mm"', POINTS + OFFSET)
    return folder, good


def test_file_in_mm_gives_the_cubes_value(run_cli, mm_files, cube_value):
    _, good = mm_files
    assert rel(value(jaxgrasp.load(good)), cube_value) < 1e-12
    rc, out, err = run_cli(["evaluate", good, "--json"])
    assert rc == 0, err
    assert rel(json.loads(out)["value"], cube_value) < 1e-12


def test_dataset_line_names_a_mesh_relative_to_the_file(mm_files):
    folder, good = mm_files
    import tomllib

    data = tomllib.loads(good.read_text())
    (folder / "set.jsonl").write_text(json.dumps(data) + "\n")
    gset = jaxgrasp.load_dataset(folder / "set.jsonl")
    assert list(gset.errors) == [None]
    np.testing.assert_allclose(gset.grasps[0].positions, POINTS, atol=1e-12)


@pytest.mark.parametrize(
    "object_lines, points, message",
    [
        ('mesh = "cube_mm.stl"\nunits = "mm"', POINTS + OFFSET + [0.005, 0, 0], "contact 0 at (68, -21, 34) mm is 5 mm"),
        ('mesh = "missing.stl"', POINTS, "missing.stl': no such file"),
        ('mesh = "cube_mm.stl"\nunits = "inch"', POINTS, "units = 'inch' is not a length unit"),
        ('density = 700.0', POINTS, "object.density is given without object.mesh"),
        ('mesh = "open.stl"', POINTS, "not watertight"),
    ],
    ids=["off-surface", "missing-mesh", "units", "density-without-mesh", "not-watertight"],
)
def test_file_errors_exit_2_with_one_line(run_cli, mm_files, object_lines, points, message):
    folder, _ = mm_files
    open_box().export(folder / "open.stl")
    path = write_grasp(folder, object_lines, points, name="bad.toml")
    rc, out, err = run_cli(["evaluate", path])
    assert rc == 2 and out == ""
    assert err.startswith(f"jaxgrasp: error: {path}: ") and message in err
    assert err.count("\n") == 1 and "Traceback" not in err


# --------------------------------------------------------------------------- show


def _pixels_near(image, rgb, tol=0.03) -> int:
    return int(np.sum(np.all(np.abs(image[..., :3] - np.asarray(rgb)) < tol, axis=-1)))


def test_show_writes_a_picture_and_a_glb(run_cli, tmp_path):
    import matplotlib.image

    png, glb = tmp_path / "out" / "block.png", tmp_path / "out" / "block.glb"
    rc, out, err = run_cli(["show", "examples/block.toml", "--out", png, "--glb", glb])
    assert rc == 0, err
    assert "stable" in out and "limited by slip of contact 1" in out and "ghost motion x" in out
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 500 and image.shape[1] > 500
    assert np.mean(np.any(image[..., :3] < 0.9, axis=-1)) > 0.05  # not blank
    drawing = image[: int(0.8 * image.shape[0])]  # above the legend, which has every colour
    assert _pixels_near(drawing, COLORS["limiting"][:3]) > 30  # the limiting fingertip is drawn
    assert _pixels_near(drawing, COLORS["fingertip"][:3], tol=0.1) > 30  # and the other one
    scene = trimesh.load(glb)
    names = {"object", "ghost"} | {f"{k} {i}" for k in ("fingertip", "cone", "normal") for i in (0, 1)}
    assert set(scene.geometry) == names


def test_show_without_a_mesh_draws_the_contacts_hull(tmp_path, cube_value):
    from jaxgrasp.plots._plots import plot_grasp
    from jaxgrasp.plots._scene import grasp_scene

    grasp = jaxgrasp.presets.cube(6e5, 2e-3)
    result = jaxgrasp.evaluate(grasp)
    scene = grasp_scene(grasp, result)
    assert not scene.has_mesh and scene.limiting_contact in (0, 1) and scene.magnification >= 1
    hull = scene.part("object").mesh
    assert hull.is_watertight and np.allclose(np.ptp(hull.vertices, axis=0)[0], 0.1)
    # the ghost is the object at the limiting pose times the magnification
    k, i = int(result.limiting_kind), int(result.limiting_contact)
    m = scene.magnification
    rot = np.asarray(jaxgrasp.model._potential.rotation_matrix(m * np.asarray(result.boundary_rotation[k, i])))
    expect = hull.vertices @ rot.T + m * np.asarray(result.boundary_translation[k, i])
    np.testing.assert_allclose(scene.part("ghost").mesh.vertices, expect, atol=1e-12)
    fig = plot_grasp(grasp, tmp_path / "cube.png", result=result)
    assert "x" + f"{m:g}" in fig._suptitle.get_text() and (tmp_path / "cube.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--out", "g.jpg2"], "--out 'g.jpg2': the file must end in .png or .pdf or .svg"),
        (["--glb", "g.obj"], "--glb 'g.obj': the file must end in .glb"),
        (["--magnification", "-1"], "--magnification must be a number from 0.001 to 1e+12"),
    ],
)
def test_show_option_errors(run_cli, argv, message):
    rc, out, err = run_cli(["show", "--preset", "cube", *argv])
    assert rc == 2 and err.startswith(f"jaxgrasp: error: {message}") and err.count("\n") == 1


# --------------------------------------------------------------------------- coordinates


def _tetra_obj(path, coordinate: str):
    """A tetrahedron OBJ with vertices at 0 and at ``coordinate`` on each axis."""
    c = coordinate
    path.write_text(f"v 0 0 0\nv {c} 0 0\nv 0 {c} 0\nv 0 0 {c}\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return path


@pytest.mark.parametrize(
    "coordinate, units, message",
    [
        ("1e300", "m", "has a vertex at (1e+300, 0, 0) m, beyond the largest coordinate 1000 m"),
        ("2e6", "mm", "has a vertex at (2000, 0, 0) m, beyond the largest coordinate 1000 m"),  # after units
        ("inf", "m", "has infinite vertex coordinates (3 of its 4 vertices; the first: (inf, 0, 0))"),
        ("nan", "m", "has NaN vertex coordinates (3 of its 4 vertices; the first: (nan, 0, 0))"),
    ],
    ids=["1e300", "2e6-mm", "inf", "nan"],
)
def test_huge_or_not_finite_vertices_are_one_line(tmp_path, coordinate, units, message):
    """A tetrahedron at 1e300 m overflowed a Python float in the area check (a traceback);
    NaN vertices were dropped by trimesh's processing and the rest reported as not watertight."""
    path = _tetra_obj(tmp_path / "t.obj", coordinate)
    with pytest.raises(jaxgrasp.GraspValueError) as info:
        jaxgrasp.io._mesh.load_mesh(path, units)
    text = str(info.value)
    assert text.startswith(f"mesh {str(path)!r} {message}") and "\n" not in text, text


def test_coordinates_up_to_the_limit_are_read():
    from jaxgrasp.io._mesh import load_mesh
    from jaxgrasp.model._validation import MAX_COORDINATE

    near = box()
    near.apply_translation([MAX_COORDINATE - 1.0, 0.0, 0.0])
    assert load_mesh(near).is_watertight
    far = box()
    far.apply_translation([MAX_COORDINATE + 1.0, 0.0, 0.0])
    with pytest.raises(jaxgrasp.GraspValueError, match=r"beyond the largest coordinate 1000 m"):
        load_mesh(far)
