"""``jaxgrasp batch FILE --out DIR`` in-process (issue 12, items 3-5): the files it writes,
invalid rows, ``--strict``, ``--top``, and how it treats an unfinished run's checkpoint.

The dataset mixes 2, 3 and 4 contacts with one invalid grasp and runs with
``--chunk-size 2``: the same compiled program as ``tests/engine/test_batch.py`` (4 contacts,
masked, batch 2), so nothing compiles here when both run. The kill -9 / resume runs are in
``tests/cli/test_interrupts.py`` (subprocesses sharing that module's compiled program).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import BatchResult
from jaxgrasp.engine._checkpoint import BatchCheckpoint
from jaxgrasp.tolerance._result import FIELDS

ROOT = Path(__file__).resolve().parents[2]
BAD_LINE = 2  # the invalid grasp's index (its line is 3)


def _grasps():
    return [
        jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002),
        jaxgrasp.presets.prism(mass=0.1),
        jaxgrasp.load(ROOT / "examples" / "four_finger.json"),
        jaxgrasp.presets.cube(young_modulus=1e6, initial_deformation=4.5e-3),  # infeasible
    ]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A .jsonl of the four grasps with an invalid one (friction -1) as line 3."""
    path = tmp_path_factory.mktemp("batch") / "set.jsonl"
    jaxgrasp.save_dataset(path, _grasps())
    lines = path.read_text().splitlines()
    bad = json.loads(lines[0])
    bad["fingertip"]["friction"] = -1
    lines.insert(BAD_LINE, json.dumps(bad))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def first_run(dataset, tmp_path_factory, cache_dir):
    """One run of the command into a fresh folder; (folder, exit code, stdout, stderr)."""
    import contextlib
    import io
    import os

    from jaxgrasp import cli

    out = tmp_path_factory.mktemp("batch-out") / "out"
    before, os.environ["JAXGRASP_CACHE_DIR"] = os.environ.get("JAXGRASP_CACHE_DIR"), str(cache_dir)
    try:
        o, e = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
            rc = cli.main(["batch", str(dataset), "--out", str(out), "--chunk-size", "2", "--top", "2"])
    finally:
        os.environ.update(JAXGRASP_CACHE_DIR=before) if before is not None else os.environ.pop("JAXGRASP_CACHE_DIR")
    return out, rc, o.getvalue(), e.getvalue()


def test_writes_the_table_in_input_order(first_run):
    """Each row is its grasp's: the engine's own result for the same grasps in input order
    (``evaluate_batch`` with the same chunk: the program the command ran, loaded, not
    compiled again; that it equals ``evaluate`` grasp by grasp is
    ``tests/engine/test_batch.py``'s and ``tests/engine/test_padding.py``'s)."""
    out, rc, stdout, stderr = first_run
    assert rc == 0, stderr
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "results.npz", "results.png"]  # no checkpoint
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["index", "num_contacts", "value_J", "status", "limiting_kind",
                             "limiting_contact", "equilibrium_energy_J", "error"]
    res = jaxgrasp.evaluate_batch(_grasps(), chunk_size=2)
    refs = [res[i] for i in range(len(res))]
    valid_rows = [r for r in rows if r["status"] != "invalid"]
    assert [int(r["index"]) for r in rows] == [0, 1, 2, 3, 4]
    assert [int(r["num_contacts"]) for r in rows] == [2, 3, 0, 4, 2]
    for row, ref in zip(valid_rows, refs):
        assert row["status"] == ref.status_name
        np.testing.assert_allclose(float(row["value_J"]), float(ref.value), rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(float(row["equilibrium_energy_J"]), float(ref.equilibrium_energy), rtol=1e-12)
        assert int(row["limiting_contact"]) == int(ref.limiting_contact)
    bad = rows[BAD_LINE]
    assert bad["status"] == "invalid" and bad["value_J"] == ""
    assert bad["error"] == "grasp 2 (line 3): friction = -1 must be positive and finite"


def test_npz_holds_every_field_and_png_is_an_image(first_run):
    out, _, _, _ = first_run
    res = BatchResult.from_npz(out / "results.npz")
    assert len(res) == 5 and res.status_names[BAD_LINE] == "invalid"
    for f in FIELDS:
        assert getattr(res, f).shape[0] == 5, f
    assert res.boundary_energy.shape == (5, 2, 4)  # padded to the largest contact count
    assert res.active.sum(axis=1).tolist() == [2, 3, 0, 4, 2]
    with open(out / "results.csv", newline="") as fh:
        csv_values = [r["value_J"] for r in csv.DictReader(fh)]
    assert csv_values == [row[2] for row in res.rows()]
    assert (out / "results.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_summary_lists_the_best_and_the_invalid(first_run):
    _, _, stdout, stderr = first_run
    lines = stdout.splitlines()
    assert lines[0].startswith("batch ") and "stable 3" in lines[0] and "invalid 1" in lines[0], stdout
    assert lines[1] == "top 2:"
    assert lines[2].startswith("  #1 grasp 0: 2.638") and "limited by slip of contact 0" in lines[2], stdout
    assert lines[3].startswith("  #2 grasp 1: ")
    assert lines[4].startswith("note: 1 invalid grasp not evaluated (first: grasp 2 (line 3): friction"), stdout
    assert "chunk 2/2 (4/4 grasps)" in stderr, stderr  # progress, over the valid grasps


def test_strict_fails_before_computing(dataset, run_cli, tmp_path):
    rc, out, err = run_cli(["batch", dataset, "--out", tmp_path / "o", "--strict"])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {dataset}: grasp 2 (line 3): friction = -1"), err
    assert not (tmp_path / "o").exists()


def test_unfinished_run_is_never_overwritten_without_resume(dataset, run_cli, tmp_path):
    out = tmp_path / "o"
    (out / "results.partial").mkdir(parents=True)
    BatchCheckpoint(out / "results.partial", "other.jsonl", "0" * 64, 5, 4).start()
    rc, _, err = run_cli(["batch", dataset, "--out", out])
    assert rc == 2 and "holds an unfinished run: add --resume" in err and err.count("\n") == 1, err
    rc, _, err = run_cli(["batch", dataset, "--out", out, "--resume"])  # another input's checkpoint
    assert rc == 2 and "was made from other input (other.jsonl" in err and err.count("\n") == 1, err
    assert sorted(p.name for p in (out / "results.partial").iterdir()) == ["manifest.json"]


def _checkpoint_of(path: Path, out: Path):
    """The checkpoint ``jaxgrasp batch path --out out`` keeps (the command's own digest
    of rows and options), started: what a run of it leaves after its first chunks."""
    import jax

    from jaxgrasp.cli._batch import batch_checkpoint
    from jaxgrasp.engine import grasps_by_count, plan_widths

    gset = jaxgrasp.load_dataset(path)
    widths = plan_widths(grasps_by_count(gset.num_contacts), jax.devices()[0].platform)
    cp = batch_checkpoint(out, str(path), gset, widths)
    out.mkdir(parents=True)
    cp.start()
    return cp


def test_resume_of_a_finished_checkpoint_computes_nothing(dataset, first_run, run_cli, tmp_path):
    """A run killed after its last chunk's checkpoint, before the final files: --resume
    writes them from the checkpoint alone (no compilation, no chunk): chunks whose digest
    is this run's are reused."""
    out0, _, _, _ = first_run
    whole = BatchResult.from_npz(out0 / "results.npz")
    out = tmp_path / "o"
    cp = _checkpoint_of(dataset, out)
    for rows in ([0, 1], [3, 4]):
        cp.save_rows(np.array(rows), {f: getattr(whole, f)[rows] for f in FIELDS})
    rc, stdout, err = run_cli(["batch", dataset, "--out", out, "--resume"])
    assert rc == 0, err
    assert "resuming: 4 of 5 grasps were finished" in err and "evaluating" not in err, err
    assert "no chunk left to evaluate; 4 resumed from the checkpoint" in stdout, stdout
    back = BatchResult.from_npz(out / "results.npz")
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(back, f), getattr(whole, f), err_msg=f)
    assert not (out / "results.partial").exists()


def test_a_chunk_of_another_dataset_is_evaluated_again_not_merged(dataset, first_run, run_cli, tmp_path):
    """Issue 65, item 6: a chunk of another dataset's run (its row 0 a stiffer cube),
    copied into this run's checkpoint, was accepted by --resume and its rows ended up in
    results.csv. Now it is skipped with one line naming it, its rows are evaluated again
    (2 grasps to go: rows 0 and 1; rows 3 and 4 come from this run's own chunk, not
    evaluated), and results.csv is the uninterrupted run's, byte for byte."""
    out0, _, _, _ = first_run
    other = tmp_path / "other.jsonl"
    lines = dataset.read_text().splitlines()
    row0 = json.loads(lines[0])
    row0["fingertip"]["young_modulus"] = 8e5
    other.write_text("\n".join([json.dumps(row0), *lines[1:]]) + "\n")
    rc, _, err = run_cli(["batch", other, "--out", tmp_path / "other", "--chunk-size", "2"])  # the other run, whole
    assert rc == 0, err
    theirs = BatchResult.from_npz(tmp_path / "other" / "results.npz")
    ours = BatchResult.from_npz(out0 / "results.npz")
    assert theirs.value[0] != ours.value[0]  # the chunk would change results.csv
    their_cp = _checkpoint_of(other, tmp_path / "other-partial")
    their_cp.save_rows(np.array([0, 1]), {f: getattr(theirs, f)[[0, 1]] for f in FIELDS})
    out = tmp_path / "o"
    cp = _checkpoint_of(dataset, out)
    cp.save_rows(np.array([3, 4]), {f: getattr(ours, f)[[3, 4]] for f in FIELDS})
    (cp.folder / "rows-000000000.npz").write_bytes((their_cp.folder / "rows-000000000.npz").read_bytes())
    rc, stdout, err = run_cli(["batch", dataset, "--out", out, "--resume", "--chunk-size", "2", "--top", "2"])
    assert rc == 0, err
    assert "resuming: 2 of 5 grasps were finished" in err and "2 grasps to go" in err, err
    assert (f"jaxgrasp: --resume: skipped 1 damaged chunk file in {cp.folder} (first: rows-000000000.npz: "
            "ValueError: another run's chunk") in err, err
    assert "2 resumed from the checkpoint" in stdout, stdout
    assert (out / "results.csv").read_bytes() == (out0 / "results.csv").read_bytes()

@pytest.mark.parametrize(
    "argv, message",
    [
        (["--chunk-size", "0"], "--chunk-size must be >= 1, got 0"),
        (["--top", "-1"], "--top must be >= 0, got -1"),
    ],
)
def test_bad_options_are_one_line(dataset, run_cli, tmp_path, argv, message):
    rc, out, err = run_cli(["batch", dataset, "--out", tmp_path / "o", *argv])
    assert rc == 2 and err == f"jaxgrasp: error: {message}\n", err


def test_a_file_of_invalid_grasps_is_one_line(run_cli, tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text('{"contacts": []}\n')
    rc, _, err = run_cli(["batch", path, "--out", tmp_path / "o"])
    assert rc == 2 and err.count("\n") == 1 and "no valid grasp (1 invalid; first: grasp 0 (line 1)" in err, err


def test_epsilon_columns(dataset, run_cli, tmp_path):
    """``--epsilon`` appends ``epsilon`` and ``force_closure`` (issue 15): jaxgrasp.epsilon of
    each valid grasp, empty and False for the invalid one."""
    out = tmp_path / "o"
    rc, _, err = run_cli(["batch", dataset, "--out", out, "--chunk-size", "2", "--epsilon", "--no-plot", "--quiet"])
    assert rc == 0, err
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[-3:] == ["error", "epsilon", "force_closure"]
    grasps = _grasps()
    for row, g in zip([r for r in rows if r["status"] != "invalid"], grasps):
        eps = jaxgrasp.epsilon(g)
        assert float(row["epsilon"]) == float(eps.value)
        assert row["force_closure"] == str(bool(eps.force_closure))
    assert rows[BAD_LINE]["epsilon"] == "" and rows[BAD_LINE]["force_closure"] == "False"
    assert rows[4]["status"] == "infeasible" and rows[4]["force_closure"] == "True"  # closure, yet no equilibrium
    with np.load(out / "results.npz") as z:
        assert np.isnan(z["epsilon"][BAD_LINE]) and z["force_closure"].tolist() == [r["force_closure"] == "True" for r in rows]
