"""Damaged checkpoints (issue 40, item 4): a batch checkpoint's chunk files that are
truncated, not zips, of other arrays, shapes, dtypes or rows are skipped by
``BatchCheckpoint.load`` (so ``--resume`` evaluates their rows again) with a one-line
note; a damaged sweep checkpoint is one ``ValueError`` line. In-process and fast: the
chunks hold made-up numbers in the evaluator's layout, nothing compiles. The command's
resume over a damaged chunk is in ``tests/cli/test_interrupts.py`` (a full disk)."""

from __future__ import annotations

import io
import os
import zipfile

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import storage as outputs
from jaxgrasp.cli import _notes
from jaxgrasp.cli._keepers import BatchCheckpoint
from jaxgrasp.engine._checkpoint import SweepCheckpoint, chunk_layout, rows_digest
from jaxgrasp.tolerance._result import FIELDS

GRASPS, CONTACTS = 6, 3


def _results(rows, n=CONTACTS) -> dict[str, np.ndarray]:
    """Results for ``rows`` in the evaluator's layout, each row's numbers its index."""
    rows = np.asarray(rows)
    return {
        k: np.broadcast_to(rows.reshape(-1, *[1] * len(shape)), (rows.size, *shape)).astype(dtype)
        for k, (shape, dtype) in chunk_layout(n).items()
    }


@pytest.fixture
def checkpoint(tmp_path) -> BatchCheckpoint:
    """A checkpoint of 6 grasps padded to 3 contacts with two good chunks: rows 0-1, 4-5."""
    cp = BatchCheckpoint(tmp_path / "results.partial", "set.jsonl", "0" * 64, GRASPS, CONTACTS)
    cp.open(resume=False)
    _notes.clear_notes()
    cp.save_rows(np.array([0, 1]), _results([0, 1]))
    cp.save_rows(np.array([4, 5]), _results([4, 5]))
    return cp


def _savez(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _digest(rows) -> np.ndarray:
    """The digest the ``checkpoint`` fixture's chunk of ``rows`` carries (no inputs, no key)."""
    return np.asarray(rows_digest({}, np.asarray(rows, dtype=np.int64), ""))


def _chunk(rows, /, **changes) -> bytes:
    """A chunk file's bytes for ``rows`` (with their digest: good but for ``changes``)
    with arrays replaced (``None``: left out)."""
    arrays = {"rows": np.asarray(rows, dtype=np.int64), "digest": _digest(rows),
              **_results(np.clip(rows, 0, GRASPS - 1))}
    arrays.update(changes)
    return _savez(**{k: v for k, v in arrays.items() if v is not None})


def _compressed_bomb() -> bytes:
    """A zip whose ``value`` array inflates to far more than a chunk may hold."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in {"rows": np.array([2, 3]), **_results([2, 3])}.items():
            with zf.open(f"{k}.npy", "w") as fh:
                np.lib.format.write_array(fh, np.zeros(10**6) if k == "value" else v)
    return buf.getvalue()


DAMAGE = {
    "truncated": lambda: _chunk([2, 3])[:300],
    "not a zip": lambda: b"\x00" * 64,
    "empty file": lambda: b"",
    "array missing": lambda: _chunk([2, 3], kkt=None),
    "array unknown": lambda: _chunk([2, 3], extra=np.zeros(2)),
    "row past the end": lambda: _chunk([2, GRASPS]),
    "negative row": lambda: _chunk([-1, 2]),
    "row twice in the chunk": lambda: _chunk([2, 2]),
    "row of another chunk": lambda: _chunk([1, 2]),
    "no rows": lambda: _chunk([], **_results([])),
    "rows not int64": lambda: _chunk([2, 3], rows=np.array([2, 3], dtype=np.int32)),
    "rows 2-D": lambda: _chunk([2, 3], rows=np.array([[2, 3]])),
    "length of an array": lambda: _chunk([2, 3], value=np.zeros(3)),
    "contact padding": lambda: _chunk([2, 3], boundary_energy=np.zeros((2, 2, CONTACTS + 1))),
    "kkt rows": lambda: _chunk([2, 3], kkt=np.zeros((2, 2 * CONTACTS, 3))),
    "float32 value": lambda: _chunk([2, 3], value=np.zeros(2, np.float32)),
    "int64 status": lambda: _chunk([2, 3], status=np.zeros(2, np.int64)),
    "object array": lambda: _chunk([2, 3], steps=np.array([None, None], dtype=object)),
    "zip bomb": _compressed_bomb,
    "digest missing": lambda: _chunk([2, 3], digest=None),
    "digest of other rows": lambda: _chunk([2, 3], digest=_digest([4, 5])),
    "digest not a string": lambda: _chunk([2, 3], digest=np.zeros(2)),
}


@pytest.mark.parametrize("kind", list(DAMAGE))
def test_a_damaged_chunk_is_skipped_and_its_rows_left_to_compute(kind, checkpoint):
    """Each used to raise BadZipFile, KeyError or IndexError out of ``--resume``, or to
    mix wrong rows or dtypes into the results."""
    (checkpoint.folder / "rows-000000002.npz").write_bytes(DAMAGE[kind]())
    rows, results = checkpoint.load()
    assert rows.tolist() == [0, 1, 4, 5]  # the good chunks, whole
    assert set(results) == set(FIELDS)
    for k, (shape, dtype) in chunk_layout(CONTACTS).items():
        assert results[k].shape == (4, *shape) and results[k].dtype == dtype, k
    np.testing.assert_array_equal(results["value"], [0.0, 1.0, 4.0, 5.0])
    assert len(checkpoint.skipped) == 1 and checkpoint.skipped[0].startswith("rows-000000002.npz: ")
    if kind == "zip bomb":  # refused before it is inflated
        assert "would take more than" in checkpoint.skipped[0] and len(DAMAGE[kind]()) < 20_000, checkpoint.skipped
    note = checkpoint.skipped_note()
    assert "\n" not in note and note.startswith(
        f"jaxgrasp: --resume: skipped 1 damaged chunk file in {checkpoint.folder} (first: rows-000000002.npz: "
    ) and note.endswith("its grasps are evaluated again"), note


def test_good_chunks_are_all_read_and_nothing_skipped(checkpoint):
    """The check has no false alarm: chunks as the command writes them are all kept, and
    so is the tests' own good chunk (each of `DAMAGE` is one defect of it)."""
    checkpoint.save_rows(np.array([2, 3]), _results([2, 3]))
    rows, results = checkpoint.load()
    assert rows.tolist() == [0, 1, 2, 3, 4, 5] and checkpoint.skipped == [] and checkpoint.skipped_note() is None
    np.testing.assert_array_equal(results["steps"][:, 0], rows)
    (checkpoint.folder / "rows-000000002.npz").write_bytes(_chunk([2, 3]))
    assert checkpoint.load()[0].tolist() == [0, 1, 2, 3, 4, 5] and checkpoint.skipped == []


# ----------------------------------------------------------------- another run's chunk (issue 65, item 6)

def _inputs(**changed_rows) -> dict[str, np.ndarray]:
    """A dataset's inputs by row, as ``jaxgrasp batch`` digests them (grasp fields and the
    contact counts); ``young_modulus=(row, value)`` changes one row's modulus."""
    rng = np.random.default_rng(65)
    out = {"positions": rng.normal(size=(GRASPS, CONTACTS, 3)), "young_modulus": np.full((GRASPS, CONTACTS), 2e5),
           "mass": np.zeros(GRASPS), "counts": np.full(GRASPS, CONTACTS)}
    for name, (row, value) in changed_rows.items():
        out[name][row] = value
    return out


def _run(tmp_path, name: str, inputs, key: str = "options") -> BatchCheckpoint:
    """A fresh checkpoint of a run in its own folder ``name``."""
    cp = BatchCheckpoint(tmp_path / name / "results.partial", "set.jsonl", "0" * 64, GRASPS, CONTACTS,
                         inputs=inputs, key=key)
    (tmp_path / name).mkdir()
    cp.open(resume=False)
    return cp


def test_a_chunk_of_another_run_is_skipped_never_merged(tmp_path):
    """A chunk written by another dataset's run (one of its rows differs) or by a run of
    other options, copied into this run's folder, is skipped (its rows evaluated again),
    with the reason; one of the same inputs and options, from any folder, is kept."""
    this = _run(tmp_path, "this", _inputs())
    this.save_rows(np.array([0, 1]), _results([0, 1]))
    other_set = _run(tmp_path, "other-set", _inputs(young_modulus=(3, 6e5)))
    other_set.save_rows(np.array([2, 3]), _results([2, 3]))
    other_options = _run(tmp_path, "other-options", _inputs(), key="other options")
    other_options.save_rows(np.array([4, 5]), _results([4, 5]))
    for cp in (other_set, other_options):
        for f in cp.chunk_files():
            (this.folder / f.name).write_bytes(f.read_bytes())
    rows, results = this.load()
    assert rows.tolist() == [0, 1] and results["value"].tolist() == [0.0, 1.0]
    assert [s.split(":")[0] for s in this.skipped] == ["rows-000000002.npz", "rows-000000004.npz"]
    assert all("another run's chunk: its digest is not that of these rows' inputs and options" in s
               for s in this.skipped), this.skipped
    assert "its grasps are evaluated again" in this.skipped_note() or "their grasps" in this.skipped_note()
    same = _run(tmp_path, "same", _inputs(young_modulus=(5, 9e5)))  # rows 2, 3 as this run's; row 5 not
    same.save_rows(np.array([2, 3]), _results([2, 3]))
    (this.folder / "rows-000000002.npz").write_bytes((same.folder / "rows-000000002.npz").read_bytes())
    assert this.load()[0].tolist() == [0, 1, 2, 3]  # the digest covers exactly its own rows


def test_layout_is_the_evaluators(checkpoint):
    """``chunk_layout`` names every Evaluation field, with the shapes of its docstring."""
    layout = chunk_layout(4)
    assert tuple(layout) == FIELDS
    assert layout["boundary_translation"][0] == (2, 4, 3) and layout["kkt"][0] == (9, 3)


def test_several_damaged_chunks_are_counted(checkpoint):
    (checkpoint.folder / "rows-000000002.npz").write_bytes(b"junk")
    (checkpoint.folder / "rows-000000003.npz").write_bytes(_chunk([3, 4]))  # 4 is the next chunk's
    os.rename(checkpoint.folder / "rows-000000004.npz", checkpoint.folder / "rows-000000000004.npz")
    rows, _ = checkpoint.load()
    # sorted by name: rows-000000000004 (4, 5) comes before rows-000000002/3, so (3, 4) is the duplicate
    assert sorted(rows.tolist()) == [0, 1, 4, 5] and len(checkpoint.skipped) == 2
    assert "skipped 2 damaged chunk files" in checkpoint.skipped_note() and "their grasps" in checkpoint.skipped_note()


def test_a_checkpoint_of_the_format_before_digests_is_refused_in_one_line(tmp_path):
    """Its chunks have no digest: one line saying to remove it, not a silent recomputation."""
    import json

    cp = _run(tmp_path, "old", _inputs())
    manifest = cp.folder / cp.MANIFEST
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "format": "jaxgrasp-batch-partial-1"}))
    with pytest.raises(ValueError, match=r"a checkpoint of another jaxgrasp \(jaxgrasp-batch-partial-1, not "
                                         r"jaxgrasp-batch-partial-2\): remove its folder to start afresh"):
        cp.open(resume=True)


def test_the_run_key_names_what_results_depend_on():
    """Other options, another width for a count, another platform: another key (so the
    chunks are evaluated again); the same run: the same key (so they are reused)."""
    from jaxgrasp.engine import run_key
    from jaxgrasp.tolerance import EvaluateOptions

    base = run_key(EvaluateOptions(), {2: 4, 4: 4}, "cpu")
    assert base == run_key(EvaluateOptions(), {4: 4, 2: 4}, "cpu")
    others = [run_key(EvaluateOptions(seed=1), {2: 4, 4: 4}, "cpu"), run_key(EvaluateOptions(), {2: 2, 4: 4}, "cpu"),
              run_key(EvaluateOptions(), {2: 4, 4: 4}, "gpu")]
    assert len({base, *others}) == 4


# ----------------------------------------------------------------------------- sweep


@pytest.fixture
def sweep_file(tmp_path):
    axes = {"mass": np.array([0.0, 0.1, 0.2])}
    flat = {"value": np.arange(3.0), "status": np.zeros(3, np.int32), "limiting_kind": np.zeros(3, np.int32),
            "limiting_contact": np.zeros(3, np.int32), "equilibrium_energy": np.zeros(3)}
    cp = SweepCheckpoint.from_flat(axes, np.array([1, 1, 0], bool), flat, jaxgrasp.presets.cube().to_numpy(), 1)
    path = tmp_path / "sweep.partial.npz"
    outputs.write_file(path, cp.save)
    return path


@pytest.mark.parametrize("damage", ["truncated", "array missing", "done of another shape"])
def test_a_damaged_sweep_checkpoint_is_one_value_error(damage, sweep_file):
    with np.load(sweep_file) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    if damage == "truncated":
        data = sweep_file.read_bytes()[:500]
    elif damage == "array missing":
        data = _savez(**{k: v for k, v in arrays.items() if k != "value"})
    else:
        data = _savez(**{**arrays, "done": np.ones(4, bool)})
    sweep_file.write_bytes(data)
    with pytest.raises(ValueError, match=f"^{sweep_file}: a damaged sweep checkpoint") as info:
        SweepCheckpoint.load(sweep_file)
    assert "\n" not in str(info.value)
