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
from jaxgrasp.engine._checkpoint import SweepCheckpoint, chunk_layout
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


def _chunk(rows, /, **changes) -> bytes:
    """A chunk file's bytes for ``rows`` with arrays replaced (``None``: left out)."""
    arrays = {"rows": np.asarray(rows, dtype=np.int64), **_results(np.clip(rows, 0, GRASPS - 1))}
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
    """The check has no false alarm: chunks as the command writes them are all kept."""
    checkpoint.save_rows(np.array([2, 3]), _results([2, 3]))
    rows, results = checkpoint.load()
    assert rows.tolist() == [0, 1, 2, 3, 4, 5] and checkpoint.skipped == [] and checkpoint.skipped_note() is None
    np.testing.assert_array_equal(results["steps"][:, 0], rows)


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
