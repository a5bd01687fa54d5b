"""The command's words are the command's (issue 64, item 2): the engine's checkpoints
write files and leave no line for the command to print; the command's keepers
(``jaxgrasp.cli._keepers``) leave them. In-process and fast: nothing compiles."""

from __future__ import annotations

import numpy as np

import jaxgrasp
from jaxgrasp.cli import _keepers, _notes
from jaxgrasp.engine import _checkpoint

FLAT = {"value": np.arange(2.0), "status": np.zeros(2, np.int32), "limiting_kind": np.zeros(2, np.int32),
        "limiting_contact": np.zeros(2, np.int32), "equilibrium_energy": np.zeros(2)}


def test_engine_keepers_write_files_and_no_words(tmp_path):
    _notes.clear_notes()
    path = tmp_path / _checkpoint.SWEEP_FILE
    keeper = _checkpoint.SweepKeeper(path, jaxgrasp.presets.cube(), {"mass": np.array([0.0, 0.1])}, chunk=1)
    keeper(0, 1, FLAT)
    batch = _checkpoint.BatchCheckpoint(tmp_path / _checkpoint.BATCH_FOLDER, "set.jsonl", "0" * 64, 2, 2)
    batch.open(resume=False)
    assert _checkpoint.SweepCheckpoint.load(path).done_count == 1 and batch.exists()
    assert _notes.keeping() == []  # the library said nothing a command would print
    assert not hasattr(batch, "skipped_note")


def test_command_keepers_say_what_is_kept(tmp_path):
    _notes.clear_notes()
    path = tmp_path / _checkpoint.SWEEP_FILE
    try:
        keeper = _keepers.SweepKeeper(path, jaxgrasp.presets.cube(), {"mass": np.array([0.0, 0.1])}, chunk=1)
        keeper(0, 1, FLAT)
        batch = _keepers.BatchCheckpoint(tmp_path / _checkpoint.BATCH_FOLDER, "set.jsonl", "0" * 64, 2, 2)
        batch.open(resume=False)
        assert _notes.keeping() == [f"1 of 2 finished points kept in {path}",
                                    f"finished chunks kept in {batch.folder}, rerun with --resume"]
    finally:
        _notes.clear_notes()
    assert _notes.keeping() == []
