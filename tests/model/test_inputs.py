"""Tests for the input side: validation, grasp files, presets and examples."""

import jax

jax.config.update("jax_enable_x64", True)

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxgrasp.model._grasp import Grasp
from jaxgrasp.io._grasp_file import grasp_from_dict, grasp_to_dict, load, save, to_toml
from jaxgrasp.presets import PRESETS, cube, prism
from jaxgrasp.model._validation import GraspValueError, check_grasp_inputs

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
FIELDS = (
    "positions",
    "normals",
    "initial_deformation",
    "radius",
    "young_modulus",
    "friction",
    "max_force",
    "mass",
    "gravity",
)


def assert_grasp_equal(a: Grasp, b: Grasp) -> None:
    """Bit-for-bit equality of every field (shape, dtype and values)."""
    na, nb = a.to_numpy(), b.to_numpy()
    assert set(na) == set(nb) == set(FIELDS)
    for k in FIELDS:
        assert na[k].dtype == np.float64, k
        assert na[k].shape == nb[k].shape, k
        assert np.array_equal(na[k], nb[k]), (k, na[k], nb[k])
        # also sign of zero / exact bits
        assert na[k].tobytes() == nb[k].tobytes(), k


def base_kwargs(**over):
    kw = dict(
        positions=[[0.05, 0, 0], [-0.05, 0, 0]],
        normals=[[1, 0, 0], [-1, 0, 0]],
        initial_deformation=0.002,
        radius=0.025,
        young_modulus=2e5,
        friction=0.5,
        max_force=15.0,
        mass=0.0,
        gravity=(0, 0, -9.81),
    )
    kw.update(over)
    return kw


def base_dict():
    return {
        "fingertip": {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15.0},
        "object": {"mass": 0.1, "gravity": [0, 0, -9.81]},
        "contacts": [
            {"position": [0.05, 0, 0], "normal": [1, 0, 0], "initial_deformation": 0.002},
            {"position": [-0.05, 0, 0], "normal": [-1, 0, 0], "initial_deformation": 0.003},
        ],
    }


def one_line(exc: BaseException) -> str:
    msg = str(exc)
    assert "\n" not in msg and msg.strip() == msg and msg
    return msg


# ----------------------------------------------------------------------------- validation


def test_check_grasp_inputs_broadcasts_and_normalises():
    out = check_grasp_inputs(**base_kwargs(normals=[[2, 0, 0], [0, -3, 4]]))
    assert list(out) == list(FIELDS)
    for k, v in out.items():
        assert isinstance(v, np.ndarray) and v.dtype == np.float64, k
    for k in ("initial_deformation", "radius", "young_modulus", "friction", "max_force"):
        assert out[k].shape == (2,)
    np.testing.assert_allclose(out["normals"], [[1, 0, 0], [0, -0.6, 0.8]], rtol=0, atol=1e-16)
    assert out["mass"].shape == () and out["gravity"].shape == (3,)
    # idempotent: validating the output again changes no bit
    again = check_grasp_inputs(**out)
    for k in FIELDS:
        assert again[k].tobytes() == out[k].tobytes(), k


def test_create_matches_check():
    g = Grasp.create(**base_kwargs(initial_deformation=[0.001, 0.004], young_modulus=[1e5, 3e5]))
    assert g.num_contacts == 2
    np.testing.assert_array_equal(g.initial_deformation, [0.001, 0.004])
    np.testing.assert_array_equal(g.young_modulus, [1e5, 3e5])
    np.testing.assert_array_equal(g.radius, [0.025, 0.025])


def test_unit_normal_renormalised_only_when_needed():
    # a normal off unit length by far more than rounding gets normalised
    out = check_grasp_inputs(**base_kwargs(normals=[[1 + 1e-9, 0, 0], [-1, 0, 0]]))
    assert out["normals"][0, 0] == 1.0
    # huge and short (above the 1e-12 threshold) normals do not overflow
    out = check_grasp_inputs(**base_kwargs(normals=[[1e300, 1e300, 0], [-1e-9, 0, 0]]))
    np.testing.assert_allclose(out["normals"], [[math.sqrt(0.5), math.sqrt(0.5), 0], [-1, 0, 0]])


@pytest.mark.parametrize(
    "over, fragments",
    [
        (dict(initial_deformation=[0.002, 0.03]), ["initial_deformation[1]", "0.03", "radius", "0.025"]),
        (dict(initial_deformation=0.025), ["initial_deformation", "0.025", "radius"]),
        (dict(initial_deformation=0.0), ["initial_deformation", "= 0 m"]),
        (dict(initial_deformation=-0.001), ["initial_deformation", "-0.001"]),
        (dict(initial_deformation=[0.002, 0.002], radius=[0.025, 0.001]), ["initial_deformation[1]", "radius[1]", "0.001"]),
        (dict(normals=[[0, 0, 0], [-1, 0, 0]]), ["normals[0]", "[0, 0, 0]", "non-zero"]),
        (dict(normals=[[1, 0, 0], [1e-13, 0, 0]]), ["normals[1]", "1e-13", "non-zero"]),
        (dict(young_modulus=-5), ["young_modulus", "-5 Pa", "positive"]),
        (dict(young_modulus=0), ["young_modulus", "= 0 Pa", "positive"]),
        (dict(young_modulus=[2e5, -7.5]), ["young_modulus[1]", "-7.5"]),
        (dict(radius=-0.025), ["radius", "-0.025"]),
        (dict(friction=0.0), ["friction", "0", "positive"]),
        (dict(friction=[0.5, -0.1]), ["friction[1]", "-0.1"]),
        (dict(friction=[0.5, 1e7]), ["friction[1] = 10000000", "at most 1000", "below about 10"]),
        (dict(mass=1e9), ["mass * |gravity| = 9.81e+09 N", "more than 10000 times", "initial squeeze", "= 5.027 N"]),
        (dict(mass=0.1, gravity=[0, 0, -1e12]), ["mass * |gravity| = 1e+11 N", "ill-conditioned"]),
        (dict(max_force=-15), ["max_force", "-15 N"]),
        (dict(mass=-0.1), ["mass", "-0.1 kg", ">= 0"]),
        (dict(mass=float("nan")), ["mass", "nan"]),
        (dict(mass=float("inf")), ["mass", "inf"]),
        (dict(young_modulus=float("inf")), ["young_modulus", "inf"]),
        (dict(positions=[[0.05, 0, 0], [float("nan"), 0, 0]]), ["positions[1]", "nan"]),
        (dict(normals=[[1, 0, 0], [-1, float("inf"), 0]]), ["normals[1]", "inf"]),
        (dict(gravity=[0, float("-inf"), -9.81]), ["gravity", "-inf"]),
        (dict(friction=float("nan")), ["friction", "nan"]),
        (dict(positions=[[0.05, 0, 0]], normals=[[1, 0, 0]]), ["at least 2 contacts", "got 1"]),
        (dict(positions=np.zeros((0, 3)), normals=np.zeros((0, 3))), ["at least 2 contacts", "got 0"]),
        (dict(positions=[[0.05, 0, 0], [0.05, 0, 0]]), ["positions[0]", "positions[1]", "[0.05, 0, 0]", "same position"]),
        (dict(positions=[0.05, 0, 0]), ["positions", "(3,)"]),
        (dict(positions=[[0.05, 0], [-0.05, 0]]), ["positions", "(2, 2)"]),
        (dict(normals=[[1, 0, 0]]), ["normals", "(1, 3)"]),
        (dict(radius=[0.025, 0.025, 0.025]), ["radius", "(3,)"]),
        (dict(mass=[0.1]), ["mass", "(1,)"]),
        (dict(gravity=[0, -9.81]), ["gravity", "(2,)"]),
        (dict(friction="0.5"), ["friction", "'0.5'"]),
        (dict(friction=True), ["friction", "True", "boolean"]),
        (dict(mass=None), ["mass", "None"]),
        (dict(young_modulus=1j), ["young_modulus", "1j"]),
        (dict(positions=[[0.05, 0, 0], [0.05, 0]]), ["positions"]),
    ],
)
def test_validation_rules(over, fragments):
    with pytest.raises(GraspValueError) as info:
        Grasp.create(**base_kwargs(**over))
    msg = one_line(info.value)
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_validation_message_examples_exact():
    with pytest.raises(GraspValueError, match=r"^initial_deformation\[1\] = 0\.03 m must be in \(0, radius = 0\.025 m\)$"):
        check_grasp_inputs(**base_kwargs(initial_deformation=[0.002, 0.03]))
    with pytest.raises(GraspValueError, match=r"^young_modulus = -5 Pa must be positive and finite$"):
        check_grasp_inputs(**base_kwargs(young_modulus=-5))
    with pytest.raises(GraspValueError, match=r"^need at least 2 contacts, got 1$"):
        check_grasp_inputs(**base_kwargs(positions=[[0, 0, 0]], normals=[[1, 0, 0]]))


@pytest.mark.parametrize(
    "young_modulus, initial_deformation, contact",
    [
        (0.5, 1e-50, 0),  # 5e-151 J, just below the threshold
        ([2e5, 1e4], [0.002, 1e-52], 1),  # 1e-152 J at contact 1 only
        (2e5, 1e-300, 0),  # dr^3 underflows to 0
        (5e-324, 0.002, 0),  # the smallest positive float64 modulus
    ],
)
def test_energy_scale_below_1e_150_joule_is_rejected(young_modulus, initial_deformation, contact):
    """``young_modulus * initial_deformation^3`` below 1e-150 J (the solver's energy scale
    would underflow) is one line naming the contact and the threshold."""
    with pytest.raises(GraspValueError) as info:
        Grasp.create(**base_kwargs(young_modulus=young_modulus, initial_deformation=initial_deformation))
    msg = one_line(info.value)
    assert msg.startswith(f"contact {contact}: young_modulus * initial_deformation^3 = "), msg
    assert msg.endswith("is below 1e-150 J, too small to evaluate in floating point"), msg


def test_energy_scale_just_above_1e_150_joule_is_accepted():
    g = Grasp.create(**base_kwargs(young_modulus=2.0, initial_deformation=1e-50))  # 2e-150 J
    assert float(np.min(np.asarray(g.young_modulus) * np.asarray(g.initial_deformation) ** 3)) >= 1e-150


def test_friction_and_weight_at_their_bounds_are_accepted():
    """The bounds themselves are valid input (issue 40: friction <= 1e3, weight <= 1e4
    times the initial squeeze), so the rules above reject only what lies beyond them."""
    from jaxgrasp.model._validation import MAX_FRICTION, MAX_LOAD_RATIO

    squeeze = 2 * math.pi * 2e5 * 0.002**2  # N, base_kwargs' two fingertips
    g = Grasp.create(**base_kwargs(friction=MAX_FRICTION, mass=0.999 * MAX_LOAD_RATIO * squeeze / 9.81))
    assert float(np.max(np.asarray(g.friction))) == MAX_FRICTION


def test_grasp_value_error_is_value_error():
    assert issubclass(GraspValueError, ValueError)
    assert str(GraspValueError("a\nb  c")) == "a b c"


def test_tracer_rejected_with_hint():
    def f(e):
        return Grasp.create(**base_kwargs(young_modulus=e)).young_modulus

    with pytest.raises(GraspValueError) as info:
        jax.jit(f)(2e5)
    msg = one_line(info.value)
    assert "young_modulus" in msg and "concrete" in msg and "replace" in msg

    with pytest.raises(GraspValueError, match="positions"):
        jax.grad(lambda x: Grasp.create(**base_kwargs(positions=[[x, 0.0, 0.0], [-0.05, 0.0, 0.0]])).mass)(0.05)


def test_jax_arrays_accepted():
    import jax.numpy as jnp

    g = Grasp.create(**base_kwargs(young_modulus=jnp.asarray(3e5), positions=jnp.asarray([[0.05, 0, 0], [-0.05, 0, 0]])))
    assert float(g.young_modulus[1]) == 3e5


# ----------------------------------------------------------------------------- presets


def test_cube_preset_geometry():
    g = cube()
    n = g.to_numpy()
    np.testing.assert_array_equal(n["positions"], [[0.05, 0, 0], [-0.05, 0, 0]])
    np.testing.assert_array_equal(n["normals"], [[1, 0, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(n["radius"], [0.025] * 2)
    np.testing.assert_array_equal(n["friction"], [0.5] * 2)
    np.testing.assert_array_equal(n["max_force"], [15.0] * 2)
    np.testing.assert_array_equal(n["young_modulus"], [2e5] * 2)
    np.testing.assert_array_equal(n["initial_deformation"], [2e-3] * 2)
    assert n["mass"] == 0.0
    np.testing.assert_array_equal(n["gravity"], [0, 0, -9.81])
    g2 = cube(6e5, 3e-3, 0.2, gravity=(0, 0, -1.0)).to_numpy()
    assert g2["young_modulus"][0] == 6e5 and g2["initial_deformation"][1] == 3e-3
    assert g2["mass"] == 0.2 and g2["gravity"][2] == -1.0


def test_prism_preset_geometry():
    n = prism().to_numpy()
    pos, nrm = n["positions"], n["normals"]
    a = 0.1 / (2 * math.sqrt(3))
    for i, ang in enumerate((0.0, 120.0, 240.0)):
        t = math.radians(ang)
        np.testing.assert_allclose(pos[i], [a * math.cos(t), a * math.sin(t), 0], atol=1e-15)
        np.testing.assert_allclose(nrm[i], [math.cos(t), math.sin(t), 0], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-15)
    # each contact is the centre of a face of an equilateral triangle of side 0.1:
    # neighbouring face centres are side/2 apart, and the normals sum to zero
    for i in range(3):
        assert abs(np.linalg.norm(pos[i] - pos[(i + 1) % 3]) - 0.05) < 1e-15
    np.testing.assert_allclose(nrm.sum(axis=0), 0, atol=1e-15)
    np.testing.assert_allclose(pos.sum(axis=0), 0, atol=1e-15)  # centroid on the axis
    np.testing.assert_array_equal(n["gravity"], [0, 0, -9.81])
    assert np.all(pos[:, 2] == 0)
    assert set(PRESETS) == {"cube", "prism"} and PRESETS["prism"] is prism


# ----------------------------------------------------------------------------- examples


@pytest.mark.parametrize(
    "name, expected",
    [
        ("cube.toml", lambda: cube(young_modulus=2e5, initial_deformation=0.002, mass=0.0)),
        ("prism.toml", lambda: prism(young_modulus=2e5, initial_deformation=0.002, mass=0.0)),
    ],
)
def test_examples_equal_presets(name, expected):
    assert_grasp_equal(load(EXAMPLES / name), expected())


def test_four_finger_example():
    g = load(EXAMPLES / "four_finger.json")
    n = g.to_numpy()
    assert g.num_contacts == 4
    assert n["mass"] == 0.15
    np.testing.assert_array_equal(n["gravity"], [0.5, 0, -9.8])
    dr = n["initial_deformation"]
    assert len(set(dr.tolist())) > 1 and dr.min() >= 1.5e-3 and dr.max() <= 2.5e-3
    # every contact lies on the surface of the 0.08 x 0.06 x 0.05 m box, normal = face normal
    half = np.array([0.04, 0.03, 0.025])
    for p, nv in zip(n["positions"], n["normals"]):
        axis = int(np.argmax(np.abs(nv)))
        assert abs(nv[axis]) == 1.0
        assert p[axis] == np.sign(nv[axis]) * half[axis]
        assert np.all(np.abs(p) <= half)
    off_centre = [p for p, nv in zip(n["positions"], n["normals"]) if np.count_nonzero(p) > 1]
    assert off_centre, "one contact should be off the centre of its face"
    # the per-contact friction override is honoured
    assert len(set(n["friction"].tolist())) == 2


# ----------------------------------------------------------------------------- round trips


def _irregular_grasp():
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(5, 3)) * 0.05
    nrm = rng.normal(size=(5, 3))
    return Grasp.create(
        pos,
        nrm,
        rng.uniform(1e-3, 4e-3, 5),
        radius=rng.uniform(0.02, 0.03, 5),
        young_modulus=2e5,
        friction=[0.5, 0.5, 0.3, 0.5, 0.5],
        max_force=np.pi,
        mass=1 / 3,
        gravity=(0.1, -0.2, -9.80665),
    )


@pytest.mark.parametrize("ext", [".toml", ".json", ".TOML"])
@pytest.mark.parametrize("make", [cube, prism, _irregular_grasp, lambda: prism(3.3e5, [1e-3, 2e-3, 3e-3], 0.25)])
def test_save_load_round_trip(tmp_path, ext, make):
    g = make()
    path = tmp_path / f"grasp{ext}"
    save(g, path)
    g2 = load(path)
    assert_grasp_equal(g, g2)
    # and a second round trip writes the identical file
    path2 = tmp_path / f"again{ext}"
    save(g2, path2)
    assert path.read_text() == path2.read_text()


def test_grasp_to_dict_structure():
    d = grasp_to_dict(_irregular_grasp())
    assert set(d) == {"fingertip", "object", "contacts"}
    # equal per-fingertip values are shared, unequal ones go per contact
    assert set(d["fingertip"]) == {"young_modulus", "max_force"}
    assert d["fingertip"]["max_force"] == np.pi
    for c in d["contacts"]:
        assert set(c) == {"position", "normal", "initial_deformation", "radius", "friction"}
    assert [c["friction"] for c in d["contacts"]] == [0.5, 0.5, 0.3, 0.5, 0.5]
    json.dumps(d)  # plain Python types only
    assert_grasp_equal(grasp_from_dict(d), _irregular_grasp())


def test_toml_text_is_commented_and_parseable():
    import tomllib

    text = to_toml(cube())
    assert "# m" in text and "# Pa" in text and "# N" in text and "# kg" in text
    data = tomllib.loads(text)
    assert data["fingertip"]["radius"] == 0.025


# ----------------------------------------------------------------------------- file content errors


def test_per_contact_override():
    d = base_dict()
    d["contacts"][1]["young_modulus"] = 5e5
    d["contacts"][0]["radius"] = 0.03
    g = grasp_from_dict(d).to_numpy()
    np.testing.assert_array_equal(g["young_modulus"], [2e5, 5e5])
    np.testing.assert_array_equal(g["radius"], [0.03, 0.025])
    np.testing.assert_array_equal(g["friction"], [0.5, 0.5])


def test_fingertip_keys_only_per_contact():
    d = base_dict()
    del d["fingertip"]
    for i, c in enumerate(d["contacts"]):
        c.update(radius=0.025, young_modulus=2e5 + i, friction=0.5, max_force=15.0)
    g = grasp_from_dict(d).to_numpy()
    np.testing.assert_array_equal(g["young_modulus"], [2e5, 2e5 + 1])


def test_missing_fingertip_key_names_contact_and_key():
    d = base_dict()
    del d["fingertip"]["friction"]
    d["contacts"][0]["friction"] = 0.4  # given in contact 0 but not in contact 1
    with pytest.raises(GraspValueError) as info:
        grasp_from_dict(d, source="g.toml")
    msg = one_line(info.value)
    assert msg.startswith("g.toml: ") and "contacts[1]" in msg and "'friction'" in msg


def test_object_table_optional_defaults():
    d = base_dict()
    del d["object"]
    n = grasp_from_dict(d).to_numpy()
    assert n["mass"] == 0.0
    np.testing.assert_array_equal(n["gravity"], [0, 0, -9.81])


def _set(d, path, value):
    *head, last = path
    for k in head:
        d = d[k]
    d[last] = value


def _delete(d, path):
    *head, last = path
    for k in head:
        d = d[k]
    del d[last]


@pytest.mark.parametrize(
    "path, value, fragments",
    [
        (("fingertip", "youngs_modulus"), 2e5, ["unknown key 'youngs_modulus' in [fingertip]", "young_modulus"]),
        (("object", "weight"), 1.0, ["'weight'", "[object]", "mass, gravity"]),
        (("contacts", 1, "pos"), [0, 0, 0], ["'pos'", "contacts[1]", "position"]),
        (("extra",), {}, ["'extra'", "top level"]),
        (("contacts", 1, "position"), "abc", ['contacts[1].position = "abc" must be a list of 3 numbers']),
        (("contacts", 0, "position"), [0.05, 0], ["contacts[0].position", "[0.05, 0]", "3 numbers"]),
        (("contacts", 0, "normal"), [1, 0, True], ["contacts[0].normal", "true", "3 numbers"]),
        (("contacts", 0, "initial_deformation"), True, ["contacts[0].initial_deformation", "true", "boolean"]),
        (("contacts", 0, "initial_deformation"), "0.002", ["contacts[0].initial_deformation", '"0.002"', "number"]),
        (("contacts", 0, "initial_deformation"), None, ["contacts[0].initial_deformation", "null"]),
        (("contacts", 1, "friction"), [0.5], ["contacts[1].friction", "[0.5]", "number"]),
        (("fingertip", "radius"), False, ["fingertip.radius", "false", "boolean"]),
        (("fingertip", "max_force"), {"a": 1}, ["fingertip.max_force", "number"]),
        (("object", "mass"), True, ["object.mass", "boolean"]),
        (("object", "gravity"), [0, 0], ["object.gravity", "3 numbers"]),
        (("object", "mass"), 10**400, ["object.mass", "too large"]),
        (("object",), [1, 2], ["object", "table"]),
        (("fingertip",), 3, ["fingertip", "table"]),
        (("contacts",), [], ["contacts", "at least 2"]),
        (("contacts",), {"position": [0, 0, 0]}, ["contacts", "list of tables"]),
        (("contacts",), [1, 2], ["contacts", "list of tables"]),
        # physically invalid values from a file are reported with the file name
        (("object", "mass"), -1, ["mass = -1 kg must be >= 0"]),
        (("fingertip", "young_modulus"), -5, ["young_modulus = -5 Pa must be positive"]),
        (("contacts", 1, "initial_deformation"), 0.03, ["initial_deformation[1] = 0.03 m", "radius = 0.025 m"]),
    ],
)
def test_file_content_errors(path, value, fragments):
    d = base_dict()
    _set(d, path, value)
    with pytest.raises(GraspValueError) as info:
        grasp_from_dict(d, source="bad.toml")
    msg = one_line(info.value)
    assert msg.startswith("bad.toml: ")
    for frag in fragments:
        assert frag in msg, (frag, msg)


@pytest.mark.parametrize(
    "path, fragments",
    [
        (("contacts",), ["contacts"]),
        (("contacts", 0, "normal"), ["contacts[0]", "'normal'"]),
        (("contacts", 1, "position"), ["contacts[1]", "'position'"]),
        (("contacts", 1, "initial_deformation"), ["contacts[1]", "'initial_deformation'"]),
        (("fingertip", "radius"), ["contacts[0]", "'radius'", "[fingertip]"]),
    ],
)
def test_missing_keys(path, fragments):
    d = base_dict()
    _delete(d, path)
    with pytest.raises(GraspValueError) as info:
        grasp_from_dict(d)
    msg = one_line(info.value)
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_top_level_must_be_table():
    for data in ([1, 2], "x", None, 3.0):
        with pytest.raises(GraspValueError, match="top level"):
            grasp_from_dict(data)


# ----------------------------------------------------------------------------- file errors


def test_malformed_toml(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[fingertip]\nradius = \n")
    with pytest.raises(GraspValueError) as info:
        load(p)
    msg = one_line(info.value)
    assert str(p) in msg and "TOML" in msg and "line 2" in msg


def test_malformed_json(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text('{"contacts": [1, 2,\n\n')
    with pytest.raises(GraspValueError) as info:
        load(p)
    msg = one_line(info.value)
    assert str(p) in msg and "JSON" in msg


def test_invalid_utf8(tmp_path):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(GraspValueError, match="UTF-8"):
        load(p)


def test_missing_file(tmp_path):
    p = tmp_path / "nope.toml"
    with pytest.raises(GraspValueError) as info:
        load(p)
    msg = one_line(info.value)
    assert str(p) in msg and "no such file" in msg


def test_directory_instead_of_file(tmp_path):
    p = tmp_path / "dir.json"
    p.mkdir()
    with pytest.raises(GraspValueError, match="dir.json"):
        load(p)


@pytest.mark.parametrize("name", ["grasp.yaml", "grasp", "grasp.toml.bak"])
def test_bad_extension(tmp_path, name):
    p = tmp_path / name
    p.write_text("{}")
    with pytest.raises(GraspValueError, match="toml or .json"):
        load(p)
    with pytest.raises(GraspValueError):
        save(cube(), p)


def test_json_nan_is_rejected_as_value(tmp_path):
    d = base_dict()
    d["object"]["mass"] = float("nan")
    p = tmp_path / "nan.json"
    p.write_text(json.dumps(d))
    with pytest.raises(GraspValueError, match=r"mass = nan"):
        load(p)


def test_toml_per_contact_override_file(tmp_path):
    p = tmp_path / "o.toml"
    p.write_text(
        """
[fingertip]
radius = 0.025
young_modulus = 2e5
friction = 0.5
max_force = 15

[[contacts]]
position = [0.05, 0, 0]
normal = [1, 0, 0]
initial_deformation = 0.002
max_force = 20

[[contacts]]
position = [-0.05, 0, 0]
normal = [-1, 0, 0]
initial_deformation = 0.002
"""
    )
    n = load(p).to_numpy()
    np.testing.assert_array_equal(n["max_force"], [20.0, 15.0])
    assert n["mass"] == 0.0


# ----------------------------------------------------------------------------- fuzzing

_json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**30), max_value=10**30)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
)
_keys = st.sampled_from(
    ["fingertip", "object", "contacts", "radius", "young_modulus", "friction", "max_force",
     "mass", "gravity", "position", "normal", "initial_deformation"]
) | st.text(max_size=6)
garbage = st.recursive(
    _json_scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(_keys, children, max_size=4),
    max_leaves=20,
)


def _leaf_paths(obj, prefix=()):
    if isinstance(obj, dict):
        yield prefix
        for k, v in obj.items():
            yield from _leaf_paths(v, prefix + (k,))
    elif isinstance(obj, list):
        yield prefix
        for i, v in enumerate(obj):
            yield from _leaf_paths(v, prefix + (i,))
    else:
        yield prefix


_BASE_PATHS = [p for p in _leaf_paths(base_dict()) if p]


def _accepts_or_grasp_error(data):
    try:
        g = grasp_from_dict(data)
    except GraspValueError as exc:
        one_line(exc)
    else:
        assert isinstance(g, Grasp)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(garbage)
def test_fuzz_garbage_dict(data):
    _accepts_or_grasp_error(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(_BASE_PATHS), garbage, st.booleans())
def test_fuzz_mutated_valid_dict(path, value, delete):
    d = base_dict()
    if delete:
        _delete(d, path)
    else:
        _set(d, path, value)
    _accepts_or_grasp_error(d)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=200) | st.text(max_size=200).map(str.encode), st.sampled_from([".toml", ".json"]))
def test_fuzz_random_file_bytes(tmp_path, raw, ext):
    p = tmp_path / f"fuzz{ext}"
    p.write_bytes(raw)
    try:
        g = load(p)
    except GraspValueError as exc:
        msg = one_line(exc)
        assert str(p) in msg
    else:
        assert isinstance(g, Grasp)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(list(FIELDS)), garbage)
def test_fuzz_create_fields(field, value):
    try:
        g = Grasp.create(**base_kwargs(**{field: value}))
    except GraspValueError as exc:
        one_line(exc)
    else:
        assert isinstance(g, Grasp)
