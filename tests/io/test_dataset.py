"""Dataset files (``jaxgrasp.load_dataset`` / ``save_dataset``, issue 12 part 3): round trips
with mixed contact counts, the ``.npz`` broadcasting rules, invalid grasps reported one by
one, and whole-file errors as one line. In-process and fast: nothing here compiles."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import GraspValueError, load_dataset, save_dataset
from jaxgrasp.model._fields import NAMES


def _grasps():
    """Grasps with 2, 3 and 4 contacts and different masses, fingertips and gravity."""
    cube = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002)
    prism = jaxgrasp.presets.prism(mass=0.1)
    four = jaxgrasp.Grasp.create(
        positions=[[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, -0.05, 0.0]],
        normals=[[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]],
        initial_deformation=[0.001, 0.002, 0.0015, 0.0025],
        radius=0.02,
        young_modulus=[2e5, 3e5, 4e5, 5e5],
        friction=0.7,
        max_force=12.0,
        mass=0.05,
        gravity=[0.0, -9.81, 0.0],
    )
    return [cube, prism, four, cube]


def _assert_same(a, b):
    for name in NAMES:
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)), err_msg=name)


@pytest.mark.parametrize("suffix", [".npz", ".jsonl"])
def test_round_trip_mixed_contact_counts(tmp_path, suffix):
    grasps = _grasps()
    path = tmp_path / f"set{suffix}"
    save_dataset(path, grasps)
    got = load_dataset(path)
    assert len(got) == 4 and got.valid.all() and got.errors == (None,) * 4
    assert got.num_contacts.tolist() == [2, 3, 4, 2]
    for a, b in zip(grasps, got.grasps):
        _assert_same(a, b)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary file left


def test_npz_pads_with_active_and_drops_inactive_contacts(tmp_path):
    path = tmp_path / "set.npz"
    save_dataset(path, _grasps())
    with np.load(path) as z:
        assert z["positions"].shape == (4, 4, 3)
        np.testing.assert_array_equal(z["active"].sum(axis=1), [2, 3, 4, 2])
        arrays = {k: np.array(z[k]) for k in z.files}
    # an inactive contact in the middle: the grasp is the one without it
    arrays["active"][2] = [True, False, True, True]
    np.savez(path, **arrays)
    four = load_dataset(path).grasps[2]
    expect = _grasps()[2]
    keep = [0, 2, 3]
    assert four.num_contacts == 3
    np.testing.assert_array_equal(four.positions, np.asarray(expect.positions)[keep])
    np.testing.assert_array_equal(four.young_modulus, np.asarray(expect.young_modulus)[keep])


def test_batched_grasp_round_trip(tmp_path):
    cubes = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=0.002) for e in (2e5, 6e5, 1e6)]
    batch = jaxgrasp.Grasp(**{n: np.stack([np.asarray(getattr(g, n)) for g in cubes]) for n in NAMES})
    save_dataset(tmp_path / "b.npz", batch)
    got = load_dataset(tmp_path / "b.npz")
    with np.load(tmp_path / "b.npz") as z:
        assert "active" not in z.files  # every contact active: no mask written
    for a, b in zip(cubes, got.grasps):
        _assert_same(a, b)


def test_npz_broadcast_shapes_with_b_equal_to_n(tmp_path):
    """B = N = 3: a (B,) friction is one value per grasp, not one per contact; (3,)
    gravity and () radius are every grasp's; a missing mass is 0."""
    prism = jaxgrasp.presets.prism()
    pos = np.stack([np.asarray(prism.positions)] * 3)
    nrm = np.stack([np.asarray(prism.normals)] * 3)
    path = tmp_path / "b.npz"
    np.savez(
        path, positions=pos, normals=nrm, initial_deformation=np.full((3, 3), 0.002), radius=np.float64(0.025),
        young_modulus=np.array([2e5, 4e5, 6e5]), friction=np.array([0.3, 0.5, 0.7]), max_force=15.0,
        gravity=np.array([0.0, 0.0, -9.81]),
    )
    got = load_dataset(path)
    assert got.valid.all()
    for i, g in enumerate(got.grasps):
        np.testing.assert_array_equal(g.friction, np.full(3, [0.3, 0.5, 0.7][i]))
        np.testing.assert_array_equal(g.young_modulus, np.full(3, [2e5, 4e5, 6e5][i]))
        np.testing.assert_array_equal(g.radius, np.full(3, 0.025))
        np.testing.assert_array_equal(g.gravity, [0.0, 0.0, -9.81])
        assert float(g.mass) == 0.0


def test_npz_invalid_grasp_is_reported_not_fatal(tmp_path):
    path = tmp_path / "set.npz"
    save_dataset(path, _grasps())
    with np.load(path) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    arrays["friction"][1, 0] = -1.0
    arrays["initial_deformation"][3, 1] = 0.5  # beyond the radius
    np.savez(path, **arrays)
    got = load_dataset(path)
    assert got.valid.tolist() == [True, False, True, False]
    assert got.num_contacts.tolist() == [2, 0, 4, 0]
    assert got.errors[1].startswith("grasp 1: friction") and "-1" in got.errors[1] and "\n" not in got.errors[1]
    assert got.errors[3].startswith("grasp 3: initial_deformation"), got.errors[3]
    with pytest.raises(GraspValueError, match=r"set\.npz: grasp 1: friction.*\(and 1 more invalid grasps\)"):
        got.raise_if_invalid()


def test_jsonl_rows_reported_one_by_one(tmp_path):
    cube, prism = _grasps()[:2]
    good = json.dumps(jaxgrasp.io.grasp_to_dict(cube))
    bad_value = jaxgrasp.io.grasp_to_dict(prism)
    bad_value["fingertip"]["friction"] = 0.0
    dup = good.replace('"radius":', '"radius": 0.02, "radius":', 1)
    lines = [good, "", "{not json", json.dumps(bad_value), dup, "   ", json.dumps(jaxgrasp.io.grasp_to_dict(prism))]
    path = tmp_path / "set.jsonl"
    path.write_bytes(b"\xef\xbb\xbf" + "\n".join(lines).encode())  # a byte-order mark too
    got = load_dataset(path)
    assert got.valid.tolist() == [True, False, False, False, True]  # blank lines skipped
    assert got.errors[1].startswith("grasp 1 (line 3): malformed JSON")
    assert got.errors[2].startswith("grasp 2 (line 4): ") and "friction" in got.errors[2]
    assert got.errors[3].startswith("grasp 3 (line 5): ") and "'radius'" in got.errors[3] and "more than once" in got.errors[3]
    _assert_same(got.grasps[0], cube)
    _assert_same(got.grasps[4], prism)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p, a: p.with_suffix(".csv").write_text("x"), r"unknown dataset file type '\.csv'"),
        (lambda p, a: None, r"no such file"),
        (lambda p, a: p.mkdir(), r"is a folder"),
        (lambda p, a: p.write_bytes(b"not a zip"), r"not a readable \.npz file"),
        (lambda p, a: np.savez(p, **a, mass_kg=np.zeros(4)), r"unknown array 'mass_kg'"),
        (lambda p, a: np.savez(p, **{k: v for k, v in a.items() if k != "friction"}), r"missing array 'friction'"),
        (lambda p, a: np.savez(p, **{**a, "positions": a["positions"][:, :, :2]}), r"positions must have shape \(B, N, 3\)"),
        (lambda p, a: np.savez(p, **{**a, "radius": np.zeros((4, 5))}), r"radius must have shape \(4, 4\) or \(4,\) or \(\)"),
        (lambda p, a: np.savez(p, **{**a, "active": a["active"].astype(int)}), r"active must be a bool array"),
        (lambda p, a: np.savez(p, **{**a, "mass": np.array(["a"] * 4)}), r"mass must hold numbers"),
    ],
)
def test_whole_file_errors_are_one_line(tmp_path, make, message):
    src = tmp_path / "src.npz"
    save_dataset(src, _grasps())
    with np.load(src) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    path = tmp_path / "bad.npz"
    make(path, arrays)
    target = path.with_suffix(".csv") if "csv" in message else path
    with pytest.raises(GraspValueError) as info:
        load_dataset(target)
    text = str(info.value)
    assert "\n" not in text and text.startswith(str(target)), text
    assert re.search(message, text), text


def test_save_batch_rejects_what_is_not_a_grasp(tmp_path):
    with pytest.raises(GraspValueError, match="item 1 is dict"):
        save_dataset(tmp_path / "x.jsonl", [jaxgrasp.presets.cube(), {}])
    with pytest.raises(GraspValueError, match="no grasps"):
        save_dataset(tmp_path / "x.jsonl", [])
    with pytest.raises(GraspValueError, match="unknown dataset file type"):
        save_dataset(tmp_path / "x.json", [jaxgrasp.presets.cube()])
    assert list(tmp_path.iterdir()) == []
