"""Hand grasp files on the command line (issue 66): ``evaluate``, ``show``, ``tune`` and
``simulate`` take one wherever they take a grasp file, and number its contacts one way.

**One numbering.** Contact ``k`` is fingertip ``k`` in the order the file lists its
fingertips, touching or not (`jaxgrasp.hands._batch`). The check that tells it from a
renumbering: a grasp whose first fingertip does not touch (``THREE``: the two-finger hand
with its proximal capsule listed first, out of reach) is limited at fingertip 1 by
``jaxgrasp.evaluate`` of the file's grasp; the compacted grasp would call it contact 0.
``evaluate --json``, ``show``'s summary line and GLB, and ``simulate``'s results.json must
all say 1 (named ``a_tip``); on the Shadow hand (fingertips ff, mf, rf, lf, th; ff and th
on a ball) ``explain()`` and ``show`` both say contact 4 (the issue's report: show said 1).

Fixtures are built in ``tmp_path`` from ``examples/hands`` (the two-finger hand's pinch of
a 60 mm cube; the Shadow hand's index finger and thumb on a ball placed between their
tips, a start from ``experiments/tuning/hand_tune.log``).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.hands import load_hand_grasp

pytest.importorskip("mujoco", reason="the hands extra: pip install 'jaxgrasp[hands]'")
trimesh = pytest.importorskip("trimesh")

HANDS = Path(__file__).resolve().parents[2] / "examples" / "hands"
PINCH = HANDS / "two_finger" / "pinch.toml"
SHADOW = HANDS / "shadow" / "shadow_hand.xml"
# The bunny's tuned Shadow configuration of experiments/tuning/hand_tune.log: index finger and thumb pinching.
SHADOW_QPOS = [-0.008907, 0.007548, -0.336287, 0.028614, 1.157035, 1.544184] + [0.0] * 13 + [
    0.841297, 1.000737, -0.208522, 0.504912, -1.562123]


def _two_finger(folder: Path, tips=("a_tip", "b_tip")) -> Path:
    """``folder/grasp.toml``: the pinch, with its hand and cube beside it, fingertips ``tips``."""
    for name in ("two_finger.xml", "cube.stl"):
        shutil.copy(PINCH.parent / name, folder / name)
    text = PINCH.read_text().replace('fingertips = ["a_tip", "b_tip"]', f"fingertips = {json.dumps(list(tips))}")
    (folder / "grasp.toml").write_text(text)
    return folder / "grasp.toml"


@pytest.fixture
def three(tmp_path) -> Path:
    """The pinch with fingertips [a_proximal (out of reach), a_tip, b_tip]: contacts 1 and 2."""
    return _two_finger(tmp_path, ("a_proximal", "a_tip", "b_tip"))


@pytest.fixture
def shadow(tmp_path) -> Path:
    """A Shadow-hand grasp file: ff and th press a ball (1.5 mm at ff), mf, rf, lf off it."""
    tips = [f"robot0:C_{f}distal" for f in ("ff", "mf", "rf", "lf", "th")]
    hand = jaxgrasp.Hand.from_mjcf(SHADOW, fingertips=tips)
    c = np.asarray(hand.fingertip_centers(np.array(SHADOW_QPOS)))
    middle = (c[0] + c[4]) / 2
    radius = np.linalg.norm(c[0] - c[4]) / 2 - hand.radius[0] + 1.5e-3
    trimesh.creation.icosphere(subdivisions=4, radius=radius).export(tmp_path / "ball.stl")
    (tmp_path / "shadow.toml").write_text(
        f'[hand]\nmjcf = {json.dumps(str(SHADOW))}\nfingertips = {json.dumps(tips)}\nqpos = {SHADOW_QPOS}\n\n'
        f'[object]\nmesh = "ball.stl"\npose = {[*middle.tolist(), 0.0, 0.0, 0.0]}\ndensity = 300.0\n\n'
        "[fingertip]\nyoung_modulus = 3e5\nfriction = 0.8\nmax_force = 10.0\n")
    return tmp_path / "shadow.toml"


def _library(path, allow=None) -> dict:
    """``jaxgrasp.evaluate(load_hand_grasp(path).grasp).to_dict()`` as JSON reads it back."""
    hg = load_hand_grasp(path, allow)
    return json.loads(json.dumps(jaxgrasp.evaluate(hg.grasp).to_dict()))


@pytest.mark.parametrize("which", ["pinch", "three"])
def test_evaluate_json_equals_the_library(run_cli, tmp_path, which):
    """Done-when of issue 66: ``evaluate HANDFILE --json`` is ``jaxgrasp.evaluate`` of the
    file's grasp (masked, contact k fingertip k), field by field, plus the hand's fields."""
    path = PINCH if which == "pinch" else _two_finger(tmp_path, ("a_proximal", "a_tip", "b_tip"))
    rc, out, err = run_cli(["evaluate", path, "--json"])
    assert rc == 0, err
    d, lib = json.loads(out), _library(path)
    for key, value in lib.items():
        assert d[key] == value, key
    assert set(d) - set(lib) == {"hand", "epsilon", "force_closure"}
    assert d["hand"]["in_contact"] == ([True, True] if which == "pinch" else [False, True, True])
    assert len(d["boundaries"]) == 2 * len(d["hand"]["fingertips"])  # every fingertip's, touching or not


def test_one_numbering_in_evaluate_show_and_simulate(run_cli, tmp_path, three):
    """The limiting contact of a grasp whose first fingertip does not touch is fingertip 1
    (a_tip) in evaluate's JSON and text, show's summary line, labels and GLB, and simulate's
    results.json (per-contact lists one per fingertip, null where not in contact)."""
    pytest.importorskip("mujoco")
    lib = _library(three)
    assert lib["limiting"]["contact"] == 1, lib["limiting"]  # the compacted grasp would say 0
    rc, out, err = run_cli(["evaluate", three, "--json"])
    assert rc == 0 and json.loads(out)["limiting"] == lib["limiting"], err
    rc, text, err = run_cli(["evaluate", three])
    assert rc == 0, err
    assert f"limiting boundary: {lib['limiting']['kind']} of contact 1 (a_tip)" in text
    assert "0 a_proximal (not in contact)" in text
    assert not re.search(r"^\s+contact 0 ", text, re.M), text  # no boundary lines of a fingertip off the object
    assert re.search(r"^\s+contact 2 slip", text, re.M), text

    rc, line, err = run_cli(["show", three, "--out", tmp_path / "g.png", "--glb", tmp_path / "g.glb"])
    assert rc == 0, err
    assert f"limited by {lib['limiting']['kind']} of contact 1 (a_tip), 2 fingertips in contact" in line, line
    names = set(trimesh.load(tmp_path / "g.glb").geometry)
    assert {"fingertip 1", "fingertip 2", "cone 2", "normal 1"} <= names and "fingertip 0" not in names, names

    rc, line, err = run_cli(["simulate", three, "--out", tmp_path / "sim", "--hold-time", "0.2", "--six-axis-time",
                             "0.2", "--kick-time", "0.1", "--scales", "2", "--random-kicks", "0"])
    assert rc == 0, err
    res = json.loads((tmp_path / "sim" / "results.json").read_text())
    assert res["limiting"] == {**lib["limiting"], "fingertip": "a_tip"}
    assert f"of contact 1 (a_tip)" in line and (tmp_path / "sim" / "trials.png").exists()
    assert res["hand"]["fingertips"] == ["a_proximal", "a_tip", "b_tip"]
    for values in (res["settled_normal_force_N"], res["parameters"]["stiffness_N_m"], res["hold"]["max_sliding_m"]):
        assert len(values) == 3 and values[0] is None and None not in values[1:], values
    assert res["parameters"]["initial_deformation_m"][1:] == pytest.approx(res["hand"]["dr_m"][1:], rel=1e-12)


def test_shadow_explain_and_show_name_one_contact(run_cli, tmp_path, shadow):
    """The issue's report: on a Shadow grasp of ff and th (fingertips 0 and 4), explain()
    named contact 4 and show contact 1; both say 4 (th) now, and show labels 0 and 4."""
    hg = load_hand_grasp(shadow, [str(SHADOW.parent)])
    assert np.asarray(hg.active).tolist() == [True, False, False, False, True]
    ev = jaxgrasp.evaluate(hg.grasp)
    k = int(ev.limiting_contact)
    assert ev.status_name == "stable" and f"of contact {k}." in ev.explain()
    rc, line, err = run_cli(["show", shadow, "--allow-dir", SHADOW.parent, "--out", tmp_path / "s.png",
                             "--glb", tmp_path / "s.glb"])
    assert rc == 0, err
    assert f"of contact {k} ({hg.hand.fingertip_names[k]})" in line, line
    names = set(trimesh.load(tmp_path / "s.glb").geometry)
    assert {"fingertip 0", "fingertip 4"} <= names and "fingertip 1" not in names


def test_show_hand_option_and_file_draw_alike(run_cli, tmp_path):
    """``show FILE`` and ``show --hand FILE`` draw the same scene (the GLB's parts)."""
    rc, a, err = run_cli(["show", PINCH, "--out", tmp_path / "a.png", "--glb", tmp_path / "a.glb"])
    assert rc == 0, err
    rc, b, err = run_cli(["show", "--hand", PINCH, "--out", tmp_path / "b.png", "--glb", tmp_path / "b.glb"])
    assert rc == 0, err
    assert a.split(";")[0].replace(str(PINCH), "--hand " + str(PINCH)) == b.split(";")[0]
    assert set(trimesh.load(tmp_path / "a.glb").geometry) == set(trimesh.load(tmp_path / "b.glb").geometry)
    rc, _, err = run_cli(["show", PINCH, "--hand", PINCH, "--out", tmp_path / "c.png"])
    assert rc == 2 and "not more than one" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow  # compiles tune_hand's value and gradient where run first (about 40 s on 2 cores)
def test_tune_writes_a_hand_grasp_file_that_loads(run_cli, tmp_path):
    """``tune HANDFILE`` tunes the joints as ``tune_hand`` does (the same qpos), writes a hand
    grasp file that loads again (its paths relative to it) and the plot beside it."""
    path = _two_finger(tmp_path)
    out = tmp_path / "tuned.toml"
    rc, line, err = run_cli(["tune", path, "--maxiter", "2", "--out", out, "--quiet"])
    assert rc == 0, err
    hg = load_hand_grasp(path)
    ref = jaxgrasp.tune_hand(hg.hand, hg.mesh, hg.qpos, hg.wrist, maxiter=2, object_pose=[0.0] * 6,
                             young_modulus=6e5, friction=0.8, max_force=15.0, mass=0.02)
    tuned = load_hand_grasp(out)
    np.testing.assert_array_equal(np.asarray(tuned.qpos), ref.qpos)
    assert f"value {ref.start_value:.6e} J -> {ref.value:.6e} J" in line and "deepest link penetration" in line
    assert out.with_suffix(".png").stat().st_size > 5_000
    assert 'model = "two_finger.xml"' in out.read_text() and 'mesh = "cube.stl"' in out.read_text()
    assert float(jaxgrasp.evaluate(tuned.grasp).value) == pytest.approx(ref.value, rel=1e-9)


def test_tune_refuses_an_output_that_would_not_load(run_cli, tmp_path):
    """A tuned file in a folder that holds neither the hand nor the mesh could not be read
    again: refused before tuning (one line, exit 2, nothing written) unless --allow-dir
    allows their folder; a .json output, --param and --bounds are refused likewise."""
    path = _two_finger(tmp_path)
    (tmp_path / "sub").mkdir()
    for extra, words in ((["--out", tmp_path / "sub" / "t.toml"], "could not be read again"),
                         (["--out", tmp_path / "t.json"], "name a .toml file"),
                         (["--param", "initial_deformation", "--out", tmp_path / "t.toml"], "--param: not used"),
                         (["--young-modulus", "1e6", "--out", tmp_path / "t.toml"], "--young-modulus")):
        rc, out, err = run_cli(["tune", path, *extra])
        assert rc == 2 and out == "" and words in err and len(err.strip().splitlines()) == 1, (extra, err)
    assert sorted(p.name for p in tmp_path.rglob("t.*")) == []
    rc, _, err = run_cli(["tune", "--preset", "cube", "--tune-wrist", "--out", tmp_path / "t.toml"])
    assert rc == 2 and "--tune-wrist: only with a hand grasp file" in err


def test_simulation_results_are_renumbered_by_fingertip(three):
    """``by_fingertip``: the simulator's contact i (the i-th fingertip in contact) is fingertip
    ``tips[i]`` in every per-contact entry, a slip included (a trial that slipped at the
    simulator's contact 0 slipped at fingertip 1, a_tip); lists of other lengths untouched."""
    from jaxgrasp.cli._simulate import by_fingertip

    hg = load_hand_grasp(three)
    trial = {"slipped_contact": 0, "max_sliding_m": [1e-3, 2e-3], "time_s": [0.0, 0.1, 0.2]}
    d = {"settled_normal_force_N": [1.0, 2.0], "model_normal_force_N": [3.0, 4.0], "hold": trial, "six_axis": [],
         "kicks": [{**trial, "slipped_contact": 1}], "parameters": {"stiffness_N_m": [5.0, 6.0], "kick_scales": [1, 2]}}
    out = by_fingertip(d, hg, jaxgrasp.evaluate(hg.grasp))
    assert out["hold"]["slipped_contact"] == 1 and out["hold"]["slipped_fingertip"] == "a_tip"
    assert out["kicks"][0]["slipped_contact"] == 2 and out["kicks"][0]["slipped_fingertip"] == "b_tip"
    assert out["hold"]["max_sliding_m"] == [None, 1e-3, 2e-3] and out["hold"]["time_s"] == [0.0, 0.1, 0.2]
    assert out["settled_normal_force_N"] == [None, 1.0, 2.0] and out["parameters"]["stiffness_N_m"] == [None, 5.0, 6.0]
    assert out["parameters"]["kick_scales"] == [1, 2] and out["limiting"]["fingertip"] == "a_tip"
