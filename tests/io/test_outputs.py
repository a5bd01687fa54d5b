"""Atomic output files, sets, the folder lock and the writability check (``jaxgrasp.storage``),
and the library writers that use them (``SweepResult.to_csv``/``to_npz``, ``jaxgrasp.save``,
the plots). In-process and fast: nothing here compiles."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import storage as outputs
from jaxgrasp.cli import _notes
from jaxgrasp.engine._checkpoint import SweepCheckpoint
from jaxgrasp.storage import _files
from jaxgrasp.analysis._sweep import SweepResult


def _tmp_files(folder) -> list[str]:
    return [n for n in os.listdir(folder) if n.endswith(outputs.TEMP_SUFFIX)]


def _result(contact=(0, 1)) -> SweepResult:
    """A 2-point sweep result; a NaN ``limiting_contact`` makes its CSV fail at row 2."""
    return SweepResult(
        axes={"mass": np.array([0.0, 0.1])},
        value=np.array([1e-4, 2e-4]),
        status=np.array([0, 0]),
        limiting_kind=np.array([0, 1]),
        limiting_contact=np.array(contact, dtype=float),
        equilibrium_energy=np.array([1e-3, 2e-3]),
    )


# ----------------------------------------------------------------------------- sets


def test_write_set_replaces_all_members_and_reports_them(tmp_path):
    a, b, gone = tmp_path / "a.txt", tmp_path / "b.bin", tmp_path / "stale.png"
    a.write_bytes(b"old a")
    gone.write_bytes(b"old png")
    published = []
    replaced = outputs.write_set(
        {a: b"new a", b: lambda fh: fh.write(b"new b")}, remove=[gone], on_publish=lambda: published.append(1)
    )
    assert replaced == [a]
    assert a.read_bytes() == b"new a" and b.read_bytes() == b"new b"
    assert not gone.exists() and published == [1]
    assert _tmp_files(tmp_path) == []


def test_write_set_failing_member_replaces_nothing(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_bytes(b"old a")
    b.write_bytes(b"old b")

    def half_then_fail(fh):
        fh.write(b"half of b")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        outputs.write_set({a: b"new a", b: half_then_fail})
    assert a.read_bytes() == b"old a" and b.read_bytes() == b"old b"
    assert _tmp_files(tmp_path) == []


def test_to_csv_failure_keeps_previous_file(tmp_path):
    """``SweepResult.to_csv`` used to truncate the file and leave it half written."""
    path = tmp_path / "sweep.csv"
    _result().to_csv(path)
    good = path.read_text()
    assert good.count("\n") == 3
    with pytest.raises(ValueError):
        _result(contact=(0, np.nan)).to_csv(path)  # int(nan) fails after the first row
    assert path.read_text() == good
    assert _tmp_files(tmp_path) == []


def test_to_npz_adds_suffix_and_accepts_a_file_object(tmp_path):
    r = _result()
    r.to_npz(tmp_path / "s")  # np.savez's rule: the suffix is added
    assert SweepResult.from_npz(tmp_path / "s.npz").value.tolist() == [1e-4, 2e-4]
    with open(tmp_path / "f.npz", "wb") as fh:
        r.to_npz(fh)
    assert SweepResult.from_npz(tmp_path / "f.npz").limiting_contact.tolist() == [0, 1]


def test_save_grasp_and_figure_write_a_new_file(tmp_path):
    """``jaxgrasp.save`` and the plots write a temporary file and rename it into place
    (a new inode), never rewrite the previous file in place (the old inode kept)."""
    g = jaxgrasp.presets.cube()
    path = tmp_path / "g.toml"
    path.write_text("previous")
    ino = path.stat().st_ino
    jaxgrasp.save(g, path)
    assert path.stat().st_ino != ino
    assert jaxgrasp.load(path).young_modulus.tolist() == [2e5, 2e5]

    from jaxgrasp.plots._plots import new_figure, save_figure

    fig = new_figure(figsize=(1, 1))
    (tmp_path / "f.png").write_text("previous")
    ino = (tmp_path / "f.png").stat().st_ino
    save_figure(fig, tmp_path / "f")  # no suffix: matplotlib's default format, suffix added
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "f.png").stat().st_ino != ino
    assert _tmp_files(tmp_path) == []


# ----------------------------------------------------------------------------- checks


def test_check_writable_creates_nothing_and_names_the_file(tmp_path):
    target = tmp_path / "new" / "deeper"
    assert outputs.check_writable(target) == target
    assert os.listdir(tmp_path) == []  # no folder, no probe left
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(outputs.OutputError, match="is a file, not a folder"):
        outputs.check_writable(blocker / "out")
    with pytest.raises(outputs.OutputError, match="exists and is not a folder"):
        outputs.check_writable(blocker)


READ_ONLY_CHECK = """
import sys
from jaxgrasp import storage as outputs
for path in sys.argv[1:]:
    try:
        outputs.check_writable(path)
        print("writable", path)
    except outputs.OutputError as exc:
        print("error", exc)
"""


@pytest.mark.slow  # a subprocess
def test_check_writable_read_only_folder(tmp_path):
    """A read-only folder, and a folder to be made under it, are refused. Run in a
    subprocess that, as root, drops root's override of permission bits (setpriv), so the
    folder is read-only to it as to any user."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    prefix = []
    if os.geteuid() == 0:
        import shutil

        assert shutil.which("setpriv"), "running as root: setpriv (util-linux) is needed to drop CAP_DAC_OVERRIDE"
        prefix = [shutil.which("setpriv"), "--bounding-set", "-dac_override"]
    try:
        p = subprocess.run(
            prefix + [sys.executable, "-c", READ_ONLY_CHECK, str(ro), str(ro / "sub"), str(tmp_path)],
            capture_output=True, text=True, timeout=120,
        )
    finally:
        ro.chmod(0o755)
    lines = p.stdout.splitlines()
    assert p.returncode == 0 and len(lines) == 3, p.stdout + p.stderr
    assert lines[0].startswith("error") and "not writable" in lines[0], lines
    assert lines[1].startswith("error") and "not writable" in lines[1], lines
    assert lines[2] == f"writable {tmp_path}", lines  # the check can also say yes
    assert os.listdir(ro) == []


# ----------------------------------------------------------------------------- lock


def test_folder_lock_excludes_a_second_holder_and_cleans_up(tmp_path):
    folder = tmp_path / "out"
    with outputs.FolderLock(folder) as lock:
        assert (folder / outputs.LOCK_NAME).read_text().strip() == str(os.getpid())
        with pytest.raises(outputs.FolderBusy, match=f"pid {os.getpid()}") as info:
            outputs.FolderLock(folder).acquire()  # flock: a second open file is excluded
        assert info.value.pid == os.getpid()
        assert lock.acquire() is lock  # held already: nothing to do
    assert os.listdir(folder) == []


def test_folder_lock_takes_over_a_stale_lock(tmp_path):
    """A lock file left by a killed process (no flock held) is taken over; its pid is
    never trusted (here: a pid that exists, ours' parent)."""
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / outputs.LOCK_NAME).write_text(f"{os.getppid()}\n")
    with outputs.FolderLock(folder):
        assert (folder / outputs.LOCK_NAME).read_text().strip() == str(os.getpid())
    assert not (folder / outputs.LOCK_NAME).exists()


@pytest.mark.slow  # a subprocess
def test_folder_lock_held_by_another_process(tmp_path):
    code = (
        "import sys, time; from jaxgrasp.storage import FolderLock; "
        "l = FolderLock(sys.argv[1]).acquire(); print('held', flush=True); time.sleep(60)"
    )
    p = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(outputs.FolderBusy, match=f"pid {p.pid}"):
            outputs.FolderLock(tmp_path).acquire()
    finally:
        p.kill()
        p.wait()
    with outputs.FolderLock(tmp_path):  # the kernel released the dead holder's lock
        pass


# ----------------------------------------------------------------------------- checkpoint


def test_partial_round_trip(tmp_path):
    axes = {"young_modulus": np.array([2e5, 6e5]), "mass": np.array([0.0, 0.1, 0.2])}
    flat = {
        "value": np.arange(6.0),
        "status": np.zeros(6, np.int32),
        "limiting_kind": np.ones(6, np.int32),
        "limiting_contact": np.zeros(6, np.int32),
        "equilibrium_energy": np.arange(6.0) + 10,
    }
    done = np.array([1, 1, 1, 1, 0, 0], bool)
    p = SweepCheckpoint.from_flat(axes, done, flat, jaxgrasp.presets.cube().to_numpy(), 2)
    outputs.write_file(tmp_path / "p.npz", p.save)
    q = SweepCheckpoint.load(tmp_path / "p.npz")
    assert q.shape == (2, 3) and q.total == 6 and q.done_count == 4 and q.chunk_size == 2
    np.testing.assert_array_equal(q.results["value"], [[0, 1, 2], [3, np.nan, np.nan]])
    np.testing.assert_array_equal(q.results["status"], [[0, 0, 0], [0, -1, -1]])
    assert q.results["status"].dtype == np.int32
    np.testing.assert_array_equal(q.grasp["radius"], jaxgrasp.presets.cube().radius)
    _result().to_npz(tmp_path / "r.npz")
    with pytest.raises(ValueError, match="not a jaxgrasp sweep checkpoint"):
        SweepCheckpoint.load(tmp_path / "r.npz")


def test_interrupt_writes_the_checkpoint_a_throttled_chunk_skipped(tmp_path, monkeypatch):
    """A chunk whose checkpoint write was skipped (writes too frequent) is still kept when
    the sweep is interrupted: abandon() runs the skipped write first."""
    import threading

    from jaxgrasp.cli._keepers import SweepKeeper

    monkeypatch.setattr(_files, "PUBLISH_LOCK", threading.Lock())  # abandon() keeps it forever
    monkeypatch.setattr(_files, "_ABANDONED", False)
    axes = {"mass": np.array([0.0, 0.1, 0.2, 0.3])}
    flat = {
        "value": np.arange(4.0),
        "status": np.zeros(4, dtype=np.int32),
        "limiting_kind": np.zeros(4, dtype=np.int32),
        "limiting_contact": np.ones(4, dtype=np.int32),
        "equilibrium_energy": np.arange(4.0) + 10,
    }
    path = tmp_path / "sweep.partial.npz"
    cp = SweepKeeper(path, jaxgrasp.presets.cube(), axes, chunk=1)
    try:
        cp(0, 1, flat)  # the first chunk is always written
        assert SweepCheckpoint.load(path).done_count == 1
        cp._cost = 1e9  # the last write was slow: the next ones are skipped
        cp(1, 2, flat)
        cp(2, 3, flat)
        assert SweepCheckpoint.load(path).done_count == 1
        notes = _notes.abandon(0.1)
    finally:
        _notes.clear_notes()
    kept = SweepCheckpoint.load(path)
    assert kept.done_count == 3
    np.testing.assert_array_equal(kept.results["value"][:3], [0.0, 1.0, 2.0])
    assert notes == [f"kept 3 of 4 points in {path}"]
    assert not _tmp_files(tmp_path)


def test_full_disk_keeps_the_last_sweep_checkpoint(tmp_path, monkeypatch):
    """A full disk while a sweep rewrites its checkpoint: one DiskFull naming it, the
    previous checkpoint whole, no temporary file, and the error can say what is kept."""
    import errno

    from jaxgrasp.cli._keepers import SweepKeeper

    path = tmp_path / "sweep.partial.npz"
    flat = {"value": np.arange(2.0), "status": np.zeros(2, np.int32), "limiting_kind": np.zeros(2, np.int32),
            "limiting_contact": np.zeros(2, np.int32), "equilibrium_energy": np.zeros(2)}
    keeper = SweepKeeper(path, jaxgrasp.presets.cube(), {"mass": np.array([0.0, 0.1])}, chunk=1)
    try:
        keeper(0, 1, flat)
        monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device")))
        with pytest.raises(outputs.DiskFull, match=f"^no space left on device writing {path}$"):
            keeper(1, 2, flat)
        assert _notes.keeping() == [f"1 of 2 finished points kept in {path}"]
    finally:
        _notes.clear_notes()
    monkeypatch.undo()
    assert SweepCheckpoint.load(path).done_count == 1 and _tmp_files(tmp_path) == []
