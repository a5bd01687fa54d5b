"""Ctrl-C, SIGTERM and output files of the ``jaxgrasp`` command (issue 11, items 1-4).

The interrupt tests run the command in a subprocess (``python -m jaxgrasp``, with the
``PYTHONPATH`` of the tests) and send the signal at a chosen moment, found by watching
its stderr: during XLA's compilation (a fresh cache folder and ``JAX_LOG_COMPILES``),
between chunks of a sweep (its progress lines), while matplotlib is imported or while
the plot is written (a wrapper makes those slow, so the moment is certain). Each checks
the exit status, the one line, the time from signal to exit and what is left on disk.

Cost: the sweeps share one cache folder and one grid and chunk size, so one sweep
program is compiled for the module (~20 s on 2 cores); every other run loads it (~2.5 s).
The check of the checkpoint against ``evaluate`` uses the session's ``evaluate_many``,
compiled already by earlier modules in a whole run (~20 s more when this file runs alone).
"""

from __future__ import annotations

import importlib
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import cli

ROOT = Path(__file__).resolve().parents[2]
EXIT_LIMIT_S = 1.0  # the bound from signal to exit

E_SPEC, DR_SPEC, CHUNK = "2e5:1e6:3", "1e-3:5e-3:8", "3"  # 24 points, 8 chunks of 3
SWEEP_ARGS = ["--preset", "cube", "--young-modulus", E_SPEC, "--initial-deformation", DR_SPEC, "--chunk-size", CHUNK]
TOTAL = 24
SET = ("sweep.npz", "sweep.csv", "sweep.png")
PARTIAL = "sweep.partial.npz"

# Runs the command after making one step slow (JAXGRASP_TEST_SLOW): "import" (of
# matplotlib) or "savefig" (the plot's bytes are half written). The step announces
# itself on stderr first, so the test knows when to send the signal.
SLOW_WRAPPER = r"""
import os, sys, time
slow = os.environ["JAXGRASP_TEST_SLOW"]

def announce(what):
    sys.stderr.write(f"test: slow {what}\n"); sys.stderr.flush()

if slow == "import":
    # slow in the module's execution, not in finding it: Python holds its global import
    # lock while it asks the finders, which would stall every other thread's imports
    import importlib.abc, importlib.machinery
    class SlowLoader(importlib.abc.Loader):
        def __init__(self, real):
            self.real = real
        def __getattr__(self, name):
            return getattr(self.real, name)
        def create_module(self, spec):
            return self.real.create_module(spec)
        def exec_module(self, module):
            announce("import"); time.sleep(60)
            self.real.exec_module(module)
    class SlowMatplotlib(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name != "matplotlib":
                return None
            spec = importlib.machinery.PathFinder.find_spec(name, path)
            if spec is not None:
                spec.loader = SlowLoader(spec.loader)
            return spec
    sys.meta_path.insert(0, SlowMatplotlib())
elif slow == "savefig":
    import matplotlib.figure
    def savefig(self, fname, **kwargs):
        fh = open(fname, "wb") if isinstance(fname, (str, os.PathLike)) else fname
        fh.write(b"\x89PNG half"); fh.flush()
        announce("savefig"); time.sleep(60)
    matplotlib.figure.Figure.savefig = savefig
from jaxgrasp.cli import main
sys.exit(main())
"""


# ----------------------------------------------------------------------------- helpers


pytestmark = pytest.mark.slow  # subprocesses that compile and are signalled


@pytest.fixture(scope="module")
def sweep_cache(tmp_path_factory):
    """The compilation cache folder of every sweep subprocess of this module."""
    return tmp_path_factory.mktemp("interrupt-cache")


def _env(cache: Path, **extra) -> dict:
    # one CPU device: the chunk counts and progress lines below are for batches of 3 (with
    # two devices a batch is rounded up to an even size)
    return dict(os.environ, JAXGRASP_CACHE_DIR=str(cache), JAXGRASP_CPU_DEVICES="1", **extra)


def _jaxgrasp(*args) -> list[str]:
    return [sys.executable, "-m", "jaxgrasp", *map(str, args)]


def _slow(*args) -> list[str]:
    return [sys.executable, "-c", SLOW_WRAPPER, *map(str, args)]


class Run:
    """A command in a subprocess whose stderr is read line by line."""

    def __init__(self, cmd, env, cwd=ROOT, kill_after=300.0):
        # The command starts with Ctrl-C's default disposition, as from a terminal. A
        # suite started as a shell's background job has SIGINT ignored, which the command
        # would inherit until its own handler is installed (a signal before then is lost).
        ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
        if ignored:  # a Python handler is reset to the default in the child at exec
            signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            self.proc = subprocess.Popen(
                cmd, env=env, cwd=str(cwd), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
            )
        finally:
            if ignored:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
        self.before: list[str] = []  # stderr lines before the signal
        self._timer = threading.Timer(kill_after, self.proc.kill)  # never hang the suite
        self._timer.start()

    def wait_for(self, pattern: str) -> str:
        """Read stderr until a line matches ``pattern``; that line."""
        for line in self.proc.stderr:
            self.before.append(line)
            if re.search(pattern, line):
                return line
        self.proc.wait()
        raise AssertionError(f"no line matching {pattern!r}; rc {self.proc.returncode}; stderr:\n{''.join(self.before)[-3000:]}")

    def interrupt(self, signum=signal.SIGINT, wait_s: float = 60.0):
        """Send ``signum``; (exit status, seconds from signal to exit, stderr after it, stdout)."""
        t0 = time.perf_counter()
        self.proc.send_signal(signum)
        try:
            rc = self.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        dt = time.perf_counter() - t0
        self._timer.cancel()
        return rc, dt, self.proc.stderr.read(), self.proc.stdout.read()

    def finish(self):
        """Wait for the end; (exit status, stdout, whole stderr)."""
        out, err = self.proc.communicate(timeout=300)
        self._timer.cancel()
        return self.proc.returncode, out, "".join(self.before) + err


def _assert_one_line(rc, dt, after, expect_rc=130, word="interrupted"):
    """Exit ``expect_rc`` within the limit; after the signal only progress lines of the
    worker (it runs until the handler does) and then exactly one line, the last."""
    assert rc == expect_rc, f"exit {rc} after {dt:.2f} s; stderr after the signal:\n{after[-3000:]}"
    assert dt < EXIT_LIMIT_S, f"{dt:.2f} s from signal to exit"
    for bad in ("Traceback", "Fatal Python error", "Error", "Exception ignored"):
        assert bad not in after, after
    lines = [ln for ln in after.splitlines() if ln.startswith("jaxgrasp:")]
    assert lines and lines[-1] == after.splitlines()[-1], after
    assert lines[-1].startswith(f"jaxgrasp: {word}"), after
    assert all(re.match(r"jaxgrasp: chunk \d+/\d+ ", ln) for ln in lines[:-1]), after
    return lines[-1]


def _listing(folder: Path) -> set[str]:
    return set(os.listdir(folder))


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {n: (folder / n).read_bytes() for n in SET}


@pytest.fixture(scope="module")
def finished_run(sweep_cache, tmp_path_factory):
    """A finished sweep into a folder holding an older run's files; (folder, stdout)."""
    out = tmp_path_factory.mktemp("previous") / "out"
    out.mkdir()
    for n in SET:
        (out / n).write_bytes(b"older run")
    rc, stdout, stderr = Run(_jaxgrasp("sweep", *SWEEP_ARGS, "--out", out), _env(sweep_cache)).finish()
    assert rc == 0, stderr[-3000:]
    return out, stdout


@pytest.fixture
def previous_set(finished_run, tmp_path) -> tuple[Path, dict[str, bytes]]:
    """A copy of a finished run's folder (the previous set of a new run); (folder, its files' bytes)."""
    out = tmp_path / "out"
    shutil.copytree(finished_run[0], out)
    return out, _snapshot(out)


def test_sequential_rerun_replaces_previous_set_and_says_so(finished_run):
    """Item 4: a second run into a folder used to overwrite the previous files silently."""
    out, stdout = finished_run
    assert stdout.count("\n") == 1
    assert stdout.rstrip().endswith(
        f"wrote {out}/{{sweep.npz,sweep.csv,sweep.png}} (replacing the previous sweep.npz, sweep.csv, sweep.png)"
    ), stdout
    assert all((out / n).read_bytes() != b"older run" for n in SET)
    assert _listing(out) == set(SET)  # the checkpoint is gone once the set is written; no lock, no *.tmp


def _partial(path: Path) -> dict:
    """The checkpoint's arrays (read with NumPy alone: the documented format)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: np.array(z[k]) for k in z.files}


# ----------------------------------------------------------------------------- item 1


@pytest.mark.parametrize("module", ["jax.version", "jax._src.xla_bridge"])
def test_sigint_while_jax_loads_exits_130_in_one_line(module):
    """Item 1: Ctrl-C while ``import jaxgrasp`` loads JAX (before the command's own
    handling) used to print Python's KeyboardInterrupt traceback.

    The signal goes once ``module`` has been imported (``-X importtime`` reports each
    import on stderr as it ends): one of JAX's first modules, and one deep in its import.
    A fixed delay after the start is no moment: on a loaded machine Python had not reached
    jaxgrasp's handler 0.12 s after the start (CI, f535462)."""
    run = Run([sys.executable, "-X", "importtime", *_jaxgrasp("evaluate", "--preset", "cube")[1:]], dict(os.environ))
    run.wait_for(rf"^import time:.*\|\s*{re.escape(module)}$")
    rc, dt, after, stdout = run.interrupt()
    after = "".join(ln for ln in after.splitlines(keepends=True) if not ln.startswith("import time:"))
    assert _assert_one_line(rc, dt, after) == "jaxgrasp: interrupted"
    assert stdout == ""


def test_startup_handler_comes_before_every_other_import():
    """The window of Python's traceback ends where :func:`jaxgrasp.cli.main` installs the
    handler, first thing: nothing is imported before ``jaxgrasp.cli`` is (whose import
    ends before ``main`` runs) but modules of Python's own and ``jaxgrasp._startup``;
    JAX and NumPy come after, when the sub-command loads the library (here to find a
    negative modulus, which only the library's field rules refuse; ``--help`` and argument
    errors load no JAX at all: ``tests/test_startup.py``)."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "jaxgrasp", "evaluate", "--preset", "cube", "--young-modulus", "-1"],
        capture_output=True, text=True, timeout=300,
    )
    # -X importtime writes a line per import, also from the command's background imports
    # (prefetch threads), which can land in the middle of the error line: cut each out whole
    timing = re.compile(r"import time:[^|\n]*\|[^|\n]*\|\s*([^\n]*)\n")
    said = timing.sub("", proc.stderr).splitlines()
    assert proc.returncode == 2 and said == ["jaxgrasp: error: --young-modulus -1: young_modulus must be positive (Pa)"], said
    names = [name.strip() for name in timing.findall(proc.stderr)][1:]  # after the header
    first = names.index("jaxgrasp.cli")
    assert names.index("jaxgrasp._startup") < first
    assert not any(n.startswith(("jax.", "jaxlib", "numpy", "importlib.metadata")) or n == "jax"
                   for n in names[:first]), names[: first + 1]
    assert "jax" in names[first:]  # the command's run loads the library


@pytest.mark.parametrize(
    "orig_argv, expected",
    [
        (["python", "-m", "jaxgrasp", "sweep"], True),
        (["python", "-X", "dev", "-m", "jaxgrasp.cli", "evaluate"], True),
        (["/venv/bin/python", "/venv/bin/jaxgrasp", "evaluate"], True),
        (["python", "-m", "pytest", "tests"], False),
        (["python", "-c", "import jaxgrasp", "-m", "jaxgrasp"], False),
        (["python", "script.py", "-m", "jaxgrasp"], False),
        (["python"], False),
    ],
)
def test_startup_handler_only_in_the_program(orig_argv, expected):
    """The early Ctrl-C handler is for the jaxgrasp program alone: a program that imports
    jaxgrasp keeps Python's KeyboardInterrupt."""
    from jaxgrasp._startup import is_command_line

    assert is_command_line(orig_argv) is expected


def test_sigint_during_xla_compilation_exits_130_at_once(tmp_path):
    """Item 1: Ctrl-C while XLA compiles evaluate (fresh cache: 17 s of compilation then, 2-3 s now)
    used to wait for XLA, then segfault (exit 139)."""
    env = _env(tmp_path / "fresh-cache", JAX_LOG_COMPILES="1")
    run = Run(_jaxgrasp("evaluate", "--preset", "cube"), env)
    run.wait_for(r"Finished jaxpr to MLIR module conversion jit\(evaluate_fields\)")
    time.sleep(0.3)  # inside XLA's compiler now
    rc, dt, after, stdout = run.interrupt()
    line = _assert_one_line(rc, dt, after)
    assert line == "jaxgrasp: interrupted"
    assert stdout == ""
    assert "Finished XLA compilation of jit(evaluate_fields)" not in after  # it was compiling


# ----------------------------------------------------------------------------- item 4 (chunks)


def test_sigint_between_chunks_keeps_finished_points(sweep_cache, tmp_path, evaluate_many):
    """Item 4: an interrupted sweep used to throw away its finished chunks. Now the
    checkpoint holds them, equal to evaluate() of those points."""
    out = tmp_path / "out"
    run = Run(_jaxgrasp("sweep", *SWEEP_ARGS, "--out", out), _env(sweep_cache))
    run.wait_for(r"jaxgrasp: chunk 1/8 ")
    rc, dt, after, stdout = run.interrupt()
    line = _assert_one_line(rc, dt, after)
    m = re.fullmatch(r"jaxgrasp: interrupted; kept (\d+) of 24 points in (.+)", line)
    assert m and Path(m[2]) == out / PARTIAL, line
    kept = int(m[1])
    assert kept >= 3 and kept % 3 == 0 or kept == TOTAL, kept
    # every chunk reported done before the exit is kept, also one whose checkpoint write
    # was skipped as too frequent (the interrupt writes it)
    reported = [int(d) for d in re.findall(r"chunk \d+/8 \((\d+)/24 points\)", "".join(run.before) + after)]
    assert kept >= max(reported), (kept, reported)
    assert stdout == ""
    assert _listing(out) == {PARTIAL}  # no half set, no temporary file, no lock

    z = _partial(out / PARTIAL)
    assert str(z["format"]) == "jaxgrasp-sweep-partial-1"
    assert [str(n) for n in z["axis_names"]] == ["young_modulus", "initial_deformation"]
    done = z["done"]
    assert done.shape == (3, 8) and done.sum() == kept
    assert done.ravel()[:kept].all() and not done.ravel()[kept:].any()  # C order, a prefix
    assert np.isnan(z["value"][~done]).all() and (z["status"][~done] == -1).all()
    np.testing.assert_array_equal(z["grasp_young_modulus"], jaxgrasp.presets.cube().young_modulus)

    base = jaxgrasp.presets.cube()
    idx = np.argwhere(done)
    grasps = [
        base.replace(
            young_modulus=np.full(2, z["axis_young_modulus"][i]),
            initial_deformation=np.full(2, z["axis_initial_deformation"][j]),
        )
        for i, j in idx
    ]
    for (i, j), r in zip(idx, evaluate_many(grasps)):
        np.testing.assert_allclose(z["value"][i, j], r.value, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(z["equilibrium_energy"][i, j], r.equilibrium_energy, rtol=1e-12, atol=1e-18)
        assert z["status"][i, j] == r.status
        assert z["limiting_kind"][i, j] == r.limiting_kind
        assert z["limiting_contact"][i, j] == r.limiting_contact


# ----------------------------------------------------------------------------- item 2 (+ lock)


def test_sigint_while_matplotlib_imports(sweep_cache, previous_set):
    """Item 2: Ctrl-C during matplotlib's import (made slow here) used to raise inside
    the import (ImportError and fatal errors, or exit -2 without a message, by timing),
    after the new npz/csv had already replaced the previous ones. The command starts
    that import in a thread while it compiles (jaxgrasp.engine._prefetch); the signal comes once
    every point is done, while the command waits for the import to write its figure."""
    out, before = previous_set
    run = Run(_slow("sweep", *SWEEP_ARGS, "--out", out), _env(sweep_cache, JAXGRASP_TEST_SLOW="import"))
    run.wait_for(r"test: slow import")  # (on a progress line not yet ended, at times)
    run.wait_for(rf"jaxgrasp: chunk {TOTAL // int(CHUNK)}/{TOTAL // int(CHUNK)} ")  # every point kept
    rc, dt, after, stdout = run.interrupt()
    line = _assert_one_line(rc, dt, after)
    assert line == f"jaxgrasp: interrupted; kept 24 of 24 points in {out / PARTIAL}"
    assert stdout == ""
    assert _snapshot(out) == before  # the previous set, untouched
    assert _listing(out) == set(SET) | {PARTIAL}  # no *.tmp, no lock file
    assert _partial(out / PARTIAL)["done"].all()


# ----------------------------------------------------------------------------- item 4 (set)


def test_sigterm_while_writing_outputs_keeps_previous_set_and_folder_locked(sweep_cache, previous_set):
    """Item 4: an interrupt while the plot is written used to leave the new npz and
    csv beside the previous png (SIGTERM here: it used to kill at once, exit -15); two
    runs into one folder used to overwrite each other silently. Now the previous set
    stays whole with no temporary file, and a second sweep started meanwhile fails at
    once (before computing), naming the first one's pid."""
    out, before = previous_set
    first = Run(_slow("sweep", *SWEEP_ARGS, "--out", out, "--quiet"), _env(sweep_cache, JAXGRASP_TEST_SLOW="savefig"))
    first.wait_for(r"^test: slow savefig")  # npz and csv staged, the png half written
    try:
        second = subprocess.run(
            _jaxgrasp("sweep", *SWEEP_ARGS, "--out", out), env=_env(sweep_cache), cwd=str(ROOT),
            capture_output=True, text=True, timeout=300,
        )
    finally:
        rc, dt, after, stdout = first.interrupt(signal.SIGTERM)
    line = _assert_one_line(rc, dt, after, expect_rc=143, word="terminated")
    assert line == f"jaxgrasp: terminated; kept 24 of 24 points in {out / PARTIAL}"
    assert stdout == ""
    assert _snapshot(out) == before
    assert _listing(out) == set(SET) | {PARTIAL}  # no *.tmp, no lock file

    assert second.returncode == 2, second.stderr[-3000:]
    assert second.stdout == ""
    assert second.stderr.count("\n") == 1 and second.stderr.startswith("jaxgrasp: error: --out: "), second.stderr
    assert f"is being written by another jaxgrasp process (pid {first.proc.pid})" in second.stderr
    assert "sweeping" not in second.stderr  # nothing computed


# ----------------------------------------------------------------------------- item 3


def _without_root_override() -> list[str]:
    """A command prefix that makes a read-only folder read-only to the command: nothing
    for a normal user; for root, ``setpriv`` dropping CAP_DAC_OVERRIDE (root keeps its
    uid, so it still reads its own files, but the permission bits bind it)."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    if setpriv is None:  # pragma: no cover - util-linux missing
        pytest.skip("running as root without setpriv: a read-only folder is writable")
    return [setpriv, "--bounding-set", "-dac_override"]


def test_out_folder_not_writable_fails_before_computing(sweep_cache, tmp_path):
    """Item 3: a read-only --out used to fail only after the whole sweep (exit 1,
    PermissionError traceback, every result lost)."""
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        p = subprocess.run(
            _without_root_override() + _jaxgrasp("sweep", *SWEEP_ARGS, "--out", out), env=_env(sweep_cache),
            cwd=str(ROOT), capture_output=True, text=True, timeout=300,
        )
        assert p.returncode == 2, p.stderr[-3000:]
        assert p.stdout == ""
        assert p.stderr.count("\n") == 1, p.stderr
        assert p.stderr.startswith(f"jaxgrasp: error: --out: cannot write to '{out}'"), p.stderr
        assert "not writable" in p.stderr and "sweeping" not in p.stderr  # nothing computed
        assert os.listdir(out) == []
    finally:
        out.chmod(0o755)


@pytest.mark.parametrize("command", ["sweep", "tune"])
def test_out_under_a_file_fails_before_computing(command, tmp_path, monkeypatch, capsys):
    """Item 3: ``--out`` under a regular file (fails as root too) used to be found only
    after the computation (sweep) or not at all before it (tune)."""
    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)
    computed = []
    module = importlib.import_module("jaxgrasp.analysis")  # the commands import it from the face
    monkeypatch.setattr(module, command, lambda *a, **k: computed.append(1) or pytest.fail("computed"))
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    if command == "sweep":
        argv = ["sweep", "--preset", "cube", "--mass", "0", "--out", str(blocker / "sub" / "out")]
    else:
        argv = ["tune", "--preset", "cube", "--out", str(blocker / "sub" / "tuned.toml")]
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert computed == []
    assert err.count("\n") == 1 and err.startswith("jaxgrasp: error: --out"), err
    assert "is a file, not a folder" in err and str(blocker) in err
    assert blocker.read_text() == "not a folder"


# ----------------------------------------------------------------------------- batch (issue 12, item 5)

BATCH_TOTAL = 48  # with --chunk-size 3: 16 chunks of the sweeps' compiled program (2 contacts, batch 3)


@pytest.fixture(scope="module")
def batch_file(tmp_path_factory) -> Path:
    """48 cube grasps (6 E x 8 dr) in a ``.jsonl`` dataset."""
    path = tmp_path_factory.mktemp("batch") / "cubes.jsonl"
    cube = jaxgrasp.presets.cube
    grasps = [
        cube(young_modulus=float(e), initial_deformation=float(d))
        for e in np.linspace(2e5, 1e6, 6)
        for d in np.linspace(1e-3, 4.9e-3, 8)
    ]
    jaxgrasp.save_dataset(path, grasps)
    return path


def _batch(path: Path, out: Path, *extra) -> list[str]:
    return _jaxgrasp("batch", path, "--out", out, "--chunk-size", "3", *extra)


def _chunk_files(out: Path) -> dict[str, tuple[int, bytes]]:
    """The checkpoint's chunk files: name -> (inode, bytes)."""
    return {p.name: (p.stat().st_ino, p.read_bytes()) for p in sorted((out / "results.partial").glob("rows-*.npz"))}


def _kept_rows(files: dict) -> int:
    import io

    return sum(np.load(io.BytesIO(data))["rows"].size for _, data in files.values())


def test_batch_killed_and_resumed_equals_an_uninterrupted_run(sweep_cache, batch_file, tmp_path):
    """Issue 12, item 5: ``kill -9`` after the first chunk, SIGTERM in the resumed run,
    then ``--resume`` again. Every finished chunk stays on disk untouched (not recomputed)
    and the final files equal those of a run that was never interrupted."""
    out, env = tmp_path / "out", _env(sweep_cache)
    killed = Run(_batch(batch_file, out), env)
    killed.wait_for(r"^jaxgrasp: chunk 1/16 \(3/48 grasps\)")  # its chunk file is written before this line
    killed.proc.kill()
    killed.proc.wait()
    killed._timer.cancel()
    assert killed.proc.returncode == -signal.SIGKILL
    first = _chunk_files(out)
    kept1 = _kept_rows(first)
    assert 3 <= kept1 < BATCH_TOTAL and kept1 % 3 == 0, kept1
    assert not (out / "results.csv").exists()

    second = Run(_batch(batch_file, out, "--resume"), env)
    assert f"resuming: {kept1} of 48 grasps were finished" in second.wait_for(r"^jaxgrasp: resuming: ")
    second.wait_for(rf"^jaxgrasp: evaluating {BATCH_TOTAL - kept1} grasps ")  # only those not kept
    second.wait_for(r"^jaxgrasp: chunk 1/")
    rc, dt, after, stdout = second.interrupt(signal.SIGTERM)
    line = _assert_one_line(rc, dt, after, expect_rc=143, word="terminated")
    m = re.fullmatch(
        rf"jaxgrasp: terminated; kept (\d+) of 48 grasps in {re.escape(str(out / 'results.partial'))}; "
        "the same command with --resume finishes the rest",
        line,
    )
    assert m, line
    kept2 = int(m[1])
    now = _chunk_files(out)
    assert {k: now[k] for k in first} == first  # the killed run's chunks: same files, same bytes
    assert _kept_rows(now) == kept2 and kept1 + 3 <= kept2 < BATCH_TOTAL, (kept1, kept2)

    rc, stdout, stderr = Run(_batch(batch_file, out, "--resume"), env).finish()
    assert rc == 0, stderr[-3000:]
    assert f"resuming: {kept2} of 48 grasps were finished" in stderr
    assert f"; {kept2} resumed from the checkpoint)" in stdout, stdout
    assert _listing(out) == {"results.csv", "results.npz", "results.png"}  # no checkpoint, *.tmp or lock

    rc, _, stderr = Run(_batch(batch_file, tmp_path / "ref", "--quiet"), env).finish()
    assert rc == 0, stderr[-3000:]
    got = jaxgrasp.BatchResult.from_npz(out / "results.npz")
    ref = jaxgrasp.BatchResult.from_npz(tmp_path / "ref" / "results.npz")
    for f in jaxgrasp.tolerance._result.FIELDS:
        a, b = getattr(got, f), getattr(ref, f)
        if np.issubdtype(a.dtype, np.floating):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, err_msg=f)
        else:
            np.testing.assert_array_equal(a, b, err_msg=f)
    assert len(set(got.status_names)) >= 2  # the set has more than one status


# ----------------------------------------------------------------------------- a full disk (issue 40, item 4)


def _small_dataset(folder: Path) -> Path:
    """The grasps of ``tests/cli/test_batch_cli.py`` (2, 3, 4 and 2 contacts): with
    ``--chunk-size 2`` the program that module and ``tests/engine/test_batch.py`` compile."""
    path = folder / "set.jsonl"
    cube, prism = jaxgrasp.presets.cube, jaxgrasp.presets.prism
    jaxgrasp.save_dataset(path, [
        cube(young_modulus=6e5, initial_deformation=0.002), prism(mass=0.1),
        jaxgrasp.load(ROOT / "examples" / "four_finger.json"), cube(young_modulus=1e6, initial_deformation=4.5e-3),
    ])
    return path


def _fsync_full_after(count: int, where: str):
    """``os.fsync`` that fails with ENOSPC for the temporary files under ``where`` after
    ``count`` of them (the folder's own fsync is not counted)."""
    import errno

    real, seen = os.fsync, []

    def fsync(fd):
        name = os.readlink(f"/proc/self/fd/{fd}")
        if name.startswith(where) and name.endswith(".tmp"):
            seen.append(fd)
            if len(seen) > count:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd)

    return fsync


def test_full_disk_is_one_line_exit_1_and_resume_finishes(run_cli, tmp_path, monkeypatch):
    """Issue 40, item 4: a full disk while ``batch`` kept its second chunk used to end in
    three chained tracebacks. Now: one line naming the file and the checkpoint, exit 1,
    the first chunk kept byte for byte; ``--resume`` then finishes with the results of an
    uninterrupted run. A link planted at ``results.csv`` is replaced, its target untouched."""
    data, out, ref = _small_dataset(tmp_path), tmp_path / "out", tmp_path / "ref"
    partial = out / "results.partial"
    out.mkdir()
    elsewhere = tmp_path / "elsewhere.csv"
    elsewhere.write_bytes(b"not jaxgrasp's")
    (out / "results.csv").symlink_to(elsewhere)
    argv = ["batch", data, "--chunk-size", "2", "--no-plot"]

    with monkeypatch.context() as m:
        m.setattr(os, "fsync", _fsync_full_after(2, str(partial)))  # the manifest and the first chunk
        rc, stdout, err = run_cli([*argv, "--out", out])
    assert rc == 1 and stdout == "", err
    assert "Traceback" not in err and err.splitlines()[-1] == (
        f"jaxgrasp: error: no space left on device writing {partial / 'rows-000000002.npz'}; "
        f"finished chunks kept in {partial}, rerun with --resume"
    ), err
    assert sorted(os.listdir(partial)) == ["manifest.json", "rows-000000000.npz"]  # no temporary file
    first = (partial / "rows-000000000.npz").read_bytes()
    (partial / "rows-000000002.npz").write_bytes(first[: len(first) // 2])  # as if cut short (item 4 too)

    rc, stdout, err = run_cli([*argv, "--out", out, "--resume"])
    assert rc == 0, err
    assert "resuming: 2 of 4 grasps were finished" in err, err
    assert f"jaxgrasp: --resume: skipped 1 damaged chunk file in {partial} (first: rows-000000002.npz: " in err, err
    assert sorted(os.listdir(out)) == ["results.csv", "results.npz"] and not (out / "results.csv").is_symlink()
    assert elsewhere.read_bytes() == b"not jaxgrasp's"

    rc, _, err = run_cli([*argv, "--out", ref, "--quiet"])
    assert rc == 0, err
    assert (out / "results.csv").read_bytes() == (ref / "results.csv").read_bytes()
    got, want = jaxgrasp.BatchResult.from_npz(out / "results.npz"), jaxgrasp.BatchResult.from_npz(ref / "results.npz")
    for f in jaxgrasp.tolerance._result.FIELDS:
        np.testing.assert_array_equal(getattr(got, f), getattr(want, f), err_msg=f)
    import io

    assert np.load(io.BytesIO(first))["rows"].tolist() == [0, 1]


@pytest.mark.parametrize(
    "error, line",
    [
        (OSError(5, "Input/output error", "out/results.npz"), "out/results.npz: input/output error"),
        (OSError(28, "No space left on device", "out/x.csv"), "no space left on device writing out/x.csv"),
    ],
)
def test_machine_failures_are_one_line_exit_1(error, line, monkeypatch, capsys):
    """An OSError out of a command (the machine, not the input) used to be a traceback;
    one that no writer named a full disk is still one. The exit statuses are in --help."""
    from jaxgrasp.cli import _evaluate

    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)
    monkeypatch.setattr(_evaluate, "run", lambda args: (_ for _ in ()).throw(error))
    assert cli.main(["evaluate", "--preset", "cube"]) == 1
    assert capsys.readouterr().err == f"jaxgrasp: error: {line}\n"
    help_text = " ".join(cli.build_parser().format_help().split())
    assert "1 the machine failed (e.g. no space left on the device" in help_text and "2 bad input" in help_text


def test_a_write_abandoned_by_the_interrupt_prints_no_line(capsys):
    """The command's thread can reach a write after the main thread abandoned output
    writing (the interrupt's handler, which prints the last line): it ends with the
    interrupt's status and no ``error`` line of its own, whatever it was writing."""
    from jaxgrasp import storage as outputs

    assert issubclass(outputs.Abandoned, outputs.OutputError)
    assert cli._report(outputs.Abandoned("output writing was abandoned (interrupted)")) == 130
    assert capsys.readouterr().err == ""
    assert cli._report(outputs.OutputError("cannot write")) == 2  # any other output error: its line
    assert capsys.readouterr().err == "jaxgrasp: error: cannot write\n"
