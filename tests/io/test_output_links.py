"""Outputs that never follow a link they did not make, and stale temporary files (issue 40,
item 2): the lock file, the checkpoints (``results.partial``, ``sweep.partial.npz``),
temporary files and result files, each with a link planted at its path to a file
elsewhere, whose bytes must stay as they were. In-process and fast: nothing here
compiles (the commands' computations are replaced by a failure, since each link is
refused before any computation)."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import cli
from jaxgrasp.cli import _batch, _sweep
from jaxgrasp import storage as outputs
from jaxgrasp.cli import _notes
from jaxgrasp.cli._keepers import BatchCheckpoint
from jaxgrasp.engine import _checkpoint
from jaxgrasp.engine._checkpoint import SweepKeeper
from jaxgrasp.storage import _files

SECRET = b"a file of the user's, elsewhere\n"


@pytest.fixture
def target(tmp_path) -> Path:
    """A file outside the output folder that a planted link points at."""
    path = tmp_path / "elsewhere" / "precious.txt"
    path.parent.mkdir()
    path.write_bytes(SECRET)
    return path


@pytest.fixture
def out(tmp_path) -> Path:
    path = tmp_path / "out"
    path.mkdir()
    return path


def _untouched(target: Path) -> bool:
    return target.read_bytes() == SECRET and sorted(os.listdir(target.parent)) == [target.name]


@pytest.fixture
def no_computing(monkeypatch):
    """``jaxgrasp.cli.main`` in-process with every computation replaced by a test failure."""
    # the commands import them from the faces
    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)
    monkeypatch.setattr(jaxgrasp.analysis, "sweep", lambda *a, **k: pytest.fail("computed"))
    monkeypatch.setattr(jaxgrasp.engine, "evaluate_dataset", lambda *a, **k: pytest.fail("computed"))


def test_checkpoint_names_are_the_commands(out):
    """``--out``'s check refuses links at the names the commands use."""
    assert _batch.PARTIAL_NAME == _checkpoint.BATCH_FOLDER and _sweep.PARTIAL_NAME == _checkpoint.SWEEP_FILE


# ----------------------------------------------------------------------------- lock


def test_lock_link_is_refused_and_its_target_kept(out, target):
    """The lock file used to be opened through a link and its target truncated to the pid."""
    (out / outputs.LOCK_NAME).symlink_to(target)
    with pytest.raises(outputs.OutputError, match="is a symbolic link where jaxgrasp keeps") as info:
        outputs.FolderLock(out).acquire()
    assert "\n" not in str(info.value)
    assert _untouched(target) and (out / outputs.LOCK_NAME).is_symlink()


def test_lock_with_a_second_name_is_refused(out, target):
    """A hard link at the lock's path names a file elsewhere too: never truncated."""
    os.link(target, out / outputs.LOCK_NAME)
    with pytest.raises(outputs.OutputError, match="other names"):
        outputs.FolderLock(out).acquire()
    assert _untouched(target)


@pytest.mark.parametrize("name", [outputs.LOCK_NAME, _checkpoint.BATCH_FOLDER, _checkpoint.SWEEP_FILE])
def test_sweep_refuses_a_link_at_its_files_before_computing(name, out, target, no_computing, capsys):
    (out / name).symlink_to(target.parent if name == _checkpoint.BATCH_FOLDER else target)
    rc = cli.main(["sweep", "--preset", "cube", "--mass", "0,0.1", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err == f"jaxgrasp: error: --out: {str(out / name)!r} is a symbolic link where jaxgrasp keeps " + err.split(
        "keeps ", 1)[1], err
    assert err.count("\n") == 1 and "it is not followed" in err
    assert _untouched(target) and sorted(os.listdir(out)) == [name]


@pytest.mark.parametrize("name", [outputs.LOCK_NAME, _checkpoint.BATCH_FOLDER, _checkpoint.SWEEP_FILE])
def test_sweep_refuses_its_files_of_the_wrong_kind_before_computing(name, out, no_computing, capsys):
    """A folder where the lock file or a sweep's checkpoint belongs (a file where a batch's
    chunks belong) was found only when written, after the whole sweep (exit 1), or named
    the output folder itself as the culprit."""
    if name == _checkpoint.BATCH_FOLDER:
        (out / name).write_bytes(b"")
    else:
        (out / name).mkdir()
    rc = cli.main(["sweep", "--preset", "cube", "--mass", "0,0.1", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    kind = "not a folder" if name == _checkpoint.BATCH_FOLDER else "a folder"
    assert err.startswith(f"jaxgrasp: error: --out: {str(out / name)!r}, where jaxgrasp keeps "), err
    assert f"is {kind}:" in err
    assert err.count("\n") == 1 and sorted(os.listdir(out)) == [name]


@pytest.mark.parametrize("argv", [["sweep", "--preset", "cube", "--out", ""], ["batch", " "],
                                  ["show", "--preset", "cube", "--out", ""]])
def test_an_empty_file_or_folder_name_is_refused(argv, tmp_path, monkeypatch, no_computing, capsys):
    """``Path("")`` is the working folder: an empty --out wrote the sweep's files there."""
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is empty: give a file or folder name" in err, err
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("option, value", [("--young-modulus", "-2e5"), ("--friction", "-.5"), ("--mass", "-1e-3")])
def test_a_negative_value_in_exponent_or_point_form_reaches_its_check(option, value, no_computing, capsys):
    """argparse took ``-2e5`` for an option ("expected one argument"): the check that says
    what is wrong with the value never ran."""
    assert cli.main(["evaluate", "--preset", "cube", option, value]) == 2
    err = capsys.readouterr().err
    assert "expected one argument" not in err and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {option} -") and "must be" in err, err


def test_a_vector_starting_with_a_minus_sign_is_a_value():
    args = cli.build_parser().parse_args(["plan", "block.stl", "--gravity", "-9.81,0,0"])
    assert args.gravity == "-9.81,0,0"


# ----------------------------------------------------------------------------- batch checkpoint


def _dataset(folder: Path) -> Path:
    path = folder / "set.jsonl"
    jaxgrasp.save_dataset(path, [jaxgrasp.presets.cube(), jaxgrasp.presets.cube(young_modulus=6e5)])
    return path


@pytest.mark.parametrize("resume", [False, True])
def test_batch_refuses_a_linked_checkpoint_folder_before_computing(resume, out, target, tmp_path, no_computing, capsys):
    """A ``results.partial`` link used to make the checkpoint write into, and at the end
    delete a file from, the folder it points at."""
    (out / _checkpoint.BATCH_FOLDER).symlink_to(target.parent, target_is_directory=True)
    argv = ["batch", str(_dataset(tmp_path)), "--out", str(out)] + (["--resume"] if resume else [])
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: --out: {str(out / _checkpoint.BATCH_FOLDER)!r} is a symbolic link"), err
    assert _untouched(target)


def test_checkpoint_folder_link_or_file_is_refused_and_never_emptied(out, target):
    """The library class refuses them too, before reading or writing anything, and
    :meth:`files` (what the command deletes at the end) lists nothing behind a link."""
    link = out / _checkpoint.BATCH_FOLDER
    link.symlink_to(target.parent, target_is_directory=True)
    (target.parent / "manifest.json").write_text("{}")  # what the checkpoint would delete
    cp = BatchCheckpoint(link, "set.jsonl", "0" * 64, 2, 2)
    for step in (lambda: cp.open(resume=True), cp.start):
        with pytest.raises(outputs.OutputError, match="is a symbolic link"):
            step()
    assert cp.files() == []
    assert (target.parent / "manifest.json").read_text() == "{}" and target.read_bytes() == SECRET
    link.unlink()
    link.write_text("a file")
    with pytest.raises(outputs.OutputError, match="is not a folder"):
        cp.open(resume=False)


def test_checkpoint_reads_and_deletes_no_link_inside(out, target):
    """A linked manifest is not read (``--resume`` says so in one line), a linked chunk is
    skipped, and only real files are listed for deletion."""
    folder = out / _checkpoint.BATCH_FOLDER
    cp = BatchCheckpoint(folder, "set.jsonl", "0" * 64, 2, 2)
    cp.open(resume=False)
    (folder / "rows-000000001.npz").symlink_to(target)
    assert cp.load()[0].size == 0 and cp.skipped[0].startswith("rows-000000001.npz: OutputError")
    assert sorted(p.name for p in cp.files()) == ["manifest.json"]
    (folder / "manifest.json").unlink()
    (folder / "manifest.json").symlink_to(target)
    with pytest.raises(ValueError, match="not a readable checkpoint .*symbolic link"):
        cp.check()
    assert _untouched(target)


# ----------------------------------------------------------------------------- sweep checkpoint, results


def test_sweep_checkpoint_and_result_links_are_replaced_not_followed(out, target, tmp_path):
    """Written with ``os.replace``, a link at a checkpoint or result path is replaced by
    the new file and its target kept; removing one removes the link alone."""
    keeper = SweepKeeper(out / _checkpoint.SWEEP_FILE, jaxgrasp.presets.cube(), {"mass": np.array([0.0])}, chunk=1)
    (out / _checkpoint.SWEEP_FILE).symlink_to(target)
    results = {"value": np.ones(1), "status": np.zeros(1, np.int32), "limiting_kind": np.zeros(1, np.int32),
               "limiting_contact": np.zeros(1, np.int32), "equilibrium_energy": np.zeros(1)}
    try:
        keeper(0, 1, results)
    finally:
        _notes.clear_notes()
    assert not (out / _checkpoint.SWEEP_FILE).is_symlink()
    assert _checkpoint.SweepCheckpoint.load(out / _checkpoint.SWEEP_FILE).done_count == 1
    (out / "results.csv").symlink_to(target)
    (out / "old.png").symlink_to(target)
    assert outputs.write_set({out / "results.csv": b"new"}, remove=[out / "old.png"]) == [out / "results.csv"]
    assert (out / "results.csv").read_bytes() == b"new" and not os.path.lexists(out / "old.png")
    assert _untouched(target)


def test_sweep_checkpoint_load_refuses_a_link(out, target):
    (out / _checkpoint.SWEEP_FILE).symlink_to(target)
    with pytest.raises(ValueError, match="damaged sweep checkpoint .*symbolic link"):
        _checkpoint.SweepCheckpoint.load(out / _checkpoint.SWEEP_FILE)


# ----------------------------------------------------------------------------- temporary files


def test_temp_name_taken_by_a_link_is_skipped(out, target, monkeypatch):
    """A temporary file's name pre-created as a link used to have its target overwritten.
    Names are random and created exclusively: a taken name is passed over."""
    tokens = iter(["0badc0de", "0badc0de", "5afe5afe"])
    monkeypatch.setattr(_files.secrets, "token_hex", lambda n: next(tokens))
    planted = out / f"results.csv.{os.getpid()}-0badc0de{outputs.TEMP_SUFFIX}"
    planted.symlink_to(target)
    outputs.write_file(out / "results.csv", b"new")
    assert (out / "results.csv").read_bytes() == b"new"
    assert _untouched(target) and planted.is_symlink()
    assert sorted(os.listdir(out)) == ["results.csv", planted.name]  # our own temporary file is gone


def test_failed_write_removes_its_temp_and_full_disk_is_one_line(out):
    (out / "results.csv").write_bytes(b"previous")

    def full(fh):
        fh.write(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(outputs.DiskFull) as info:
        outputs.write_set({out / "results.npz": b"whole", out / "results.csv": full})
    assert str(info.value) == f"no space left on device writing {out / 'results.csv'}"
    assert info.value.__cause__ is None and info.value.__suppress_context__  # no chained traceback
    assert sorted(os.listdir(out)) == ["results.csv"] and (out / "results.csv").read_bytes() == b"previous"
    def cleanup_fails_too(fh):
        try:
            full(fh)
        finally:
            raise ValueError("I/O operation on closed file")  # a writer's own clean-up failing after ENOSPC

    with pytest.raises(outputs.DiskFull, match="^no space left on device writing"):
        outputs.write_file(out / "results.npz", cleanup_fails_too)
    with pytest.raises(OSError, match="Permission"):  # any other error: as it was, temporary file gone
        outputs.write_file(out / "x.csv", lambda fh: (_ for _ in ()).throw(PermissionError("Permission denied")))
    assert sorted(os.listdir(out)) == ["results.csv"]


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temps_are_removed_when_a_command_takes_the_folder(out, target):
    """Temporary files of killed runs used to stay for ever. Taking the folder's lock
    removes those of dead processes and those older than an hour; a live run's, other
    names and links stay."""
    live = os.getppid()
    dead = out / f"results.csv.{_dead_pid()}-0123abcd{outputs.TEMP_SUFFIX}"
    old = out / f"sweep.npz.{live}-89abcdef{outputs.TEMP_SUFFIX}"
    fresh = out / f"sweep.csv.{live}-01234567{outputs.TEMP_SUFFIX}"
    other = out / "notes.tmp"
    link = out / f"a.{_dead_pid()}-fedcba98{outputs.TEMP_SUFFIX}"
    for p in (dead, old, fresh, other):
        p.write_bytes(b"x")
    link.symlink_to(target)
    hours_ago = time.time() - outputs.STALE_TEMP_SECONDS - 60
    os.utime(old, (hours_ago, hours_ago))
    with outputs.FolderLock(out):
        assert sorted(os.listdir(out)) == sorted([fresh.name, other.name, link.name, outputs.LOCK_NAME])
    assert _untouched(target)


def test_stale_temps_in_the_checkpoint_folder_are_removed_on_resume(out):
    folder = out / _checkpoint.BATCH_FOLDER
    cp = BatchCheckpoint(folder, "set.jsonl", "0" * 64, 2, 2)
    cp.open(resume=False)
    stale = folder / f"rows-000000000.npz.{_dead_pid()}-0123abcd{outputs.TEMP_SUFFIX}"
    stale.write_bytes(b"half a chunk")
    try:
        assert cp.open(resume=True)[2] is True
        assert _notes.keeping() == [f"finished chunks kept in {folder}, rerun with --resume"]
    finally:
        _notes.clear_notes()
    assert sorted(os.listdir(folder)) == ["manifest.json"]


def test_only_the_store_sweeps_its_earlier_temp_names(out):
    """The executable store's earlier temporary names (``.NAME.PID.RANDOM.tmp``,
    ``NAME.tmpPID``) are swept in the store's folder only: in an output folder a file so
    named may be the user's, and stays."""
    dead = _dead_pid()
    names = [f".a.xla.{dead}.00ff.tmp", f"b.tmp{dead}"]
    for name in names:
        (out / name).write_bytes(b"x")
    with outputs.FolderLock(out):
        assert sorted(os.listdir(out)) == sorted([*names, outputs.LOCK_NAME])
    assert outputs.remove_stale_temps(out, earlier_store_names=True) == 2 and os.listdir(out) == []
