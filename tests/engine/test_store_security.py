"""The executable store cannot be used against its user (issue 40, item 1; issue 35, item 4).

A stored executable is a pickle, and its payload loads machine code: whoever can write a
file the store reads can run code as the user. These tests plant what another user could
(files and folders owned by ``nobody``, uid 65534: the suite runs as root, which may give
files away), damage stored files, and plant symbolic links, and check that nothing planted
is unpickled, a damaged or foreign file is rebuilt and replaced with the same results as a
clean build, and no link is written through. They store a tiny jitted function through the
same path as the evaluators (:func:`jaxgrasp.engine._compile.compiled`): no evaluator is
compiled here.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import stat

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.engine import _compile
from jaxgrasp import storage
from jaxgrasp.engine import _store as store
from jaxgrasp.storage import _files

NOBODY = 65534
SPEC = (jax.ShapeDtypeStruct((4,), jnp.float64),)
X = np.linspace(0.0, 1.0, 4)


def _build(scale: float = 2.0):
    return lambda: jax.jit(lambda x: (jnp.sin(x) * scale + 1.0,))


def _compiled(scale: float = 2.0):
    """``(fn, stats difference)``: the tiny executable for option ``scale``, from the memo
    (cleared first), the store, or built now (and stored: waited for)."""
    _compile.clear_compiled()
    before = store.stats()
    fn, _ = _compile.compiled(("tiny", scale), _build(scale), SPEC, name="tiny", store_key=("tiny", scale))
    _compile.wait_for_saves()
    return fn, {k: v - before[k] for k, v in store.stats().items()}


def _entry(scale: float = 2.0) -> store.StoreEntry:
    return store.executable_entry("tiny", (("tiny", scale), 0), SPEC)


def _result(fn) -> np.ndarray:
    return np.asarray(fn(X)[0])


def _assert_replaced(want: np.ndarray) -> None:
    """The stored file is the user's, private, and loads (not traced) with ``want``'s numbers."""
    st = os.lstat(_entry().path)
    assert stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid() and stat.S_IMODE(st.st_mode) == 0o600
    fn, counted = _compiled()
    assert counted == {"traced": 0, "deserialized": 1, "cache_errors": 0}
    np.testing.assert_array_equal(_result(fn), want)


@contextlib.contextmanager
def _xla_cache_off():
    """XLA's persistent cache off inside, and exactly as it was after (test-only: JAX keeps
    the cache it opened in its module state, which its settings no longer reach, so an
    earlier in-process command's cache would serve the tiny executable here; an executable
    that cache serves is never stored, rightly, and these tests need one built)."""
    from jax._src import compilation_cache as xla_cache

    state = (xla_cache._cache, xla_cache._cache_checked, xla_cache._cache_used)
    xla_cache._cache, xla_cache._cache_checked, xla_cache._cache_used = None, True, False
    try:
        yield
    finally:
        xla_cache._cache, xla_cache._cache_checked, xla_cache._cache_used = state


@pytest.fixture
def folder(tmp_path):
    """A store folder turned on for the test (restored after it), empty, with XLA's
    persistent cache off (:func:`_xla_cache_off`)."""
    saved = store.executable_dir()
    path = tmp_path / "cache" / store.EXECUTABLE_SUBDIR
    with _xla_cache_off():
        assert store.set_executable_dir(path) == path
        yield path
        store.set_executable_dir(saved)
        _compile.clear_compiled()


@pytest.fixture
def clean(folder):
    """The tiny executable's results and its stored file's bytes, from a clean build."""
    fn, counted = _compiled()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    return _result(fn), _entry().path.read_bytes()


def _planted_pickle(marker) -> bytes:
    """A pickle that creates ``marker`` when it is unpickled."""

    class Payload:
        def __reduce__(self):
            return exec, (f"open({str(marker)!r}, 'w').close()",)

    return pickle.dumps(Payload())


def test_folders_are_created_private(tmp_path):
    """Every level of a new folder is 0700, even under a umask that would leave less."""
    saved, old_umask = store.executable_dir(), os.umask(0o277)
    try:
        path = tmp_path / "a" / "b" / "c"
        assert store.set_executable_dir(path) == path
    finally:
        os.umask(old_umask)
        store.set_executable_dir(saved)
    for level in (tmp_path / "a", tmp_path / "a" / "b", path):
        assert stat.S_IMODE(level.stat().st_mode) == 0o700, level


def test_planted_pickle_does_not_run(clean, tmp_path, caplog):
    """A file in the right format, with the right key and checksum, but owned by another
    user: never unpickled (the marker its pickle would create is absent), one warning,
    a cache error; the executable is rebuilt and the planted file replaced by the user's."""
    marker = tmp_path / "marker"
    payload = _planted_pickle(marker)
    path = _entry().path
    path.write_bytes(store._encode(_entry().key, payload))
    os.chown(path, NOBODY, NOBODY)
    with caplog.at_level(logging.WARNING, logger="jaxgrasp"):
        fn, counted = _compiled()
    assert not marker.exists()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING] == [
        f"jaxgrasp: not loading stored executable {path}: owned by user id {NOBODY}, not by this user ({os.geteuid()})"
    ]
    np.testing.assert_array_equal(_result(fn), clean[0])
    _assert_replaced(clean[0])
    # the same file, the user's but writable by others: refused too, for its mode
    path.write_bytes(store._encode(_entry().key, payload))
    path.chmod(0o666)
    fn, counted = _compiled()
    assert not marker.exists() and counted["cache_errors"] == 1 and counted["deserialized"] == 0


def test_foreign_or_open_folder_is_neither_used_nor_read(clean, folder, caplog):
    """A store folder writable by others (0777), or owned by another user, turns on no
    cache (neither the store nor XLA's), with one warning naming it; its files are not
    read (the executable is traced although a good file is there)."""
    xla_dir = jax.config.jax_compilation_cache_dir
    for problem, spoil in [("writable by group or others (mode 777)", lambda: folder.chmod(0o777)),
                           (f"owned by user id {NOBODY}", lambda: os.chown(folder, NOBODY, NOBODY))]:
        spoil()
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="jaxgrasp"):
            assert store.set_executable_dir(folder) is None
            assert store.enable_compilation_cache(folder.parent) is None
        assert store.executable_dir() is None and jax.config.jax_compilation_cache_dir == xla_dir
        assert any(r.getMessage().startswith(f"jaxgrasp: not using cache folder {folder}: {problem}")
                   for r in caplog.records), [r.getMessage() for r in caplog.records]
        _, counted = _compiled()
        assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 0}
        os.chown(folder, 0, 0)
        folder.chmod(0o700)


DAMAGE = {  # where a byte is flipped -> why the file is not loaded
    "magic": "not a stored executable of this version's format",
    "key": "it was built for another key (other options, shapes, versions or machine)",
    "separator": "its header is damaged",
    "payload": "its checksum does not match (damaged)",
    "last": "its checksum does not match (damaged)",
}


@pytest.mark.parametrize("where", DAMAGE)
def test_damaged_file_is_rebuilt_and_replaced(clean, where, caplog):
    """One flipped byte anywhere in a stored file (the payload's middle is the machine
    code): found before anything is unpickled, rebuilt (the same numbers as a clean build)
    and the file replaced, so that the next process loads again."""
    want, good = clean
    path = _entry().path
    header_end = good.index(b"\n", len(store._MAGIC) + 1)
    at = {"magic": 3, "key": good.index(b'"key"') + 10, "separator": header_end,
          "payload": (header_end + len(good)) // 2, "last": len(good) - 1}[where]
    path.write_bytes(good[:at] + bytes([good[at] ^ 0x01]) + good[at + 1:])
    with caplog.at_level(logging.INFO, logger="jaxgrasp"):
        fn, counted = _compiled()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    assert f"(its stored file is unusable: {DAMAGE[where]})" in caplog.text
    np.testing.assert_array_equal(_result(fn), want)
    _assert_replaced(want)


def test_file_of_other_options_is_rebuilt(clean, caplog):
    """An executable built with other options (its key differs), copied over the
    default's file name: refused by its header's key, rebuilt, same numbers as clean; the
    compilation is reported with why and where."""
    want = clean[0]
    other, _ = _compiled(scale=0.5)
    assert not np.array_equal(_result(other), want)  # it would give other numbers
    _entry().path.write_bytes(_entry(0.5).path.read_bytes())
    with caplog.at_level(logging.INFO, logger="jaxgrasp"):
        fn, counted = _compiled()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    np.testing.assert_array_equal(_result(fn), want)
    _assert_replaced(want)
    assert [r.getMessage() for r in caplog.records] == [(
        "jaxgrasp: compiling tiny (its stored file is unusable: it was built for another key (other options, "
        f"shapes, versions or machine)); it will be stored in {_entry().path.parent}"
    )]


def test_executable_of_other_xla_flags_is_not_loaded(clean, monkeypatch):
    """``XLA_FLAGS`` change the code XLA emits, so they are part of the key: under other
    flags the stored executable is not loaded (built again, under its own file name), and
    under the flags it was built with it loads again (found on a GPU lease, 2026-11-28:
    a run with command buffers turned on loaded the executable built without them)."""
    want, default_bytes = clean
    default = _entry()
    monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_fast_math=false")
    other = _entry()
    assert other.path != default.path and other.key != default.key
    fn, counted = _compiled()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 0}
    np.testing.assert_array_equal(_result(fn), want)
    assert other.path.is_file() and default.path.read_bytes() == default_bytes
    monkeypatch.undo()
    fn, counted = _compiled()
    assert counted == {"traced": 0, "deserialized": 1, "cache_errors": 0}


def test_links_are_never_written_through(folder, tmp_path, monkeypatch, caplog):
    """A link planted at the stored file's name is not read (refused) and replaced by a
    file; a link planted at the temporary file's name is skipped (another name is used);
    neither link's target changes. A failed write leaves no temporary file."""
    target = tmp_path / "precious"
    target.write_bytes(b"precious")
    path = _entry().path
    path.symlink_to(target)
    names = iter(["0" * 8, "1" * 8])
    monkeypatch.setattr(_files.secrets, "token_hex", lambda n: next(names))
    (folder / f"{path.name}.{os.getpid()}-{'0' * 8}.tmp").symlink_to(target)
    with caplog.at_level(logging.WARNING, logger="jaxgrasp"):
        built, counted = _compiled()
    assert counted == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    assert "it is a symbolic link" in caplog.text
    assert target.read_bytes() == b"precious"
    _assert_replaced(_result(built))
    assert not (folder / f"{path.name}.{os.getpid()}-{'1' * 8}.tmp").exists()
    # a write that fails at the rename removes its temporary file
    monkeypatch.setattr(_files.secrets, "token_hex", lambda n: "2" * 8)
    monkeypatch.setattr(store.os, "replace", lambda *a: (_ for _ in ()).throw(OSError(28, "No space left")))
    assert store.save_executable(_entry(), store.serialized_stages(built)) is False
    assert not (folder / f"{path.name}.{os.getpid()}-{'2' * 8}.tmp").exists()


def test_stale_temporary_files_are_removed(tmp_path):
    """Turning the store on removes its temporary files of dead processes and old ones,
    and keeps a fresh one of a live process and every other file."""
    live, dead = os.getpid(), 99_999_999  # above any pid_max: no such process
    names = {f".a.xla.{dead}.00ff.tmp": False, f"b.tmp{dead}": False, f".c.xla.{live}.00ff.tmp": True,
             f".d.xla.{live}.00ff.tmp": False, "e.xla": True}
    for name in names:
        (tmp_path / name).write_bytes(b"")
    old = tmp_path / f".d.xla.{live}.00ff.tmp"
    os.utime(old, (old.stat().st_atime - 2 * storage.STALE_TEMP_SECONDS,) * 2)
    saved = store.executable_dir()
    try:
        store.set_executable_dir(tmp_path)
    finally:
        store.set_executable_dir(saved)
    assert {n: (tmp_path / n).exists() for n in names} == names


def test_environment_moves_or_switches_off(tmp_path, monkeypatch):
    """``JAXGRASP_CACHE_DIR=off``: no folder and no cache turned on; another value moves
    the folder; unset, ``$XDG_CACHE_HOME`` or ``~/.cache``."""
    saved, xla_dir = store.executable_dir(), jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv(store.ENV_VAR, "OFF")
        assert store.default_dir() is None
        assert store.enable_from_environment() is None and store.enable_compilation_cache() is None
        assert store.executable_dir() == saved and jax.config.jax_compilation_cache_dir == xla_dir
        monkeypatch.setenv(store.ENV_VAR, str(tmp_path / "moved"))
        assert store.enable_from_environment() == tmp_path / "moved" / store.EXECUTABLE_SUBDIR
        assert stat.S_IMODE((tmp_path / "moved").stat().st_mode) == 0o700
        monkeypatch.delenv(store.ENV_VAR)
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        assert store.default_dir() == tmp_path / "xdg" / "jaxgrasp" / "xla"
        monkeypatch.delenv("XDG_CACHE_HOME")
        (tmp_path / "home").mkdir()
        monkeypatch.setenv("HOME", str(tmp_path / "home"))
        assert store.default_dir() == tmp_path / "home" / ".cache" / "jaxgrasp" / "xla"
    finally:
        store.set_executable_dir(saved)


def test_first_use_keeps_the_store_the_program_chose(tmp_path, monkeypatch):
    """``jaxgrasp.configure`` (jaxgrasp's first use) reads ``JAXGRASP_CACHE_DIR`` only where
    the program has not chosen a store: a folder set before stays."""
    from jaxgrasp.engine import configure

    saved = store.executable_dir()
    try:
        monkeypatch.setenv(store.ENV_VAR, str(tmp_path / "from-env"))
        store.set_executable_dir(tmp_path / "mine")
        assert configure()["executable_store"] == tmp_path / "mine" == store.executable_dir()
        assert not (tmp_path / "from-env").exists()
    finally:
        store.set_executable_dir(saved)


def test_log_lines_go_to_stderr_in_the_command(capsys):
    """What the command prints of the ``jaxgrasp`` logger: INFO lines, one line each, only
    inside the block."""
    with store.log_lines_on_stderr():
        store.LOGGER.info("jaxgrasp: compiling something (why); it is not stored")
        store.LOGGER.debug("jaxgrasp: not shown")
    store.LOGGER.info("jaxgrasp: not shown either")
    assert capsys.readouterr().err == "jaxgrasp: compiling something (why); it is not stored\n"


def test_command_prints_the_compilation_report(monkeypatch, capsys):
    """The ``jaxgrasp`` command prints the store's reports on its stderr (a command whose
    run reports a compilation, as an evaluator's does, stands in for a real one)."""
    from jaxgrasp import cli
    from jaxgrasp.cli import _evaluate

    def run(args):
        store.LOGGER.info("jaxgrasp: compiling evaluate for 2 contacts (no stored executable yet); it is not stored")
        return 0

    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)  # no process-wide setting
    monkeypatch.setattr(_evaluate, "run", run)
    assert cli.main(["evaluate", "--preset", "cube"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "jaxgrasp: compiling evaluate for 2 contacts (no stored executable yet); it is not stored\n"
    assert captured.out == ""


# ----------------------------------------------------------------------------- sizes, FIFOs, home (issue 65)


def test_stored_file_over_the_cap_is_not_read(clean, monkeypatch, caplog):
    """A 3 GB (sparse: no disk, no memory) file at the stored file's name was read whole
    (killed at 6 GB): now it is refused by its size on the open file, before a byte is
    read, and the executable rebuilt and the file replaced."""
    want, _ = clean
    path = _entry().path
    os.truncate(path, 3 * 2**30)  # the user's own private file, only larger
    reads = []
    real_read = os.read

    def read(fd, n):
        if os.fstat(fd).st_size > store.MAX_EXECUTABLE_BYTES:
            reads.append(n)
            raise AssertionError("read a file over the cap")
        return real_read(fd, n)

    monkeypatch.setattr(os, "read", read)
    with caplog.at_level(logging.INFO, logger="jaxgrasp"):
        fn, counted = _compiled()
    monkeypatch.undo()
    assert reads == [] and counted == {"traced": 1, "deserialized": 0, "cache_errors": 1}
    assert "it holds 3,221,225,472 bytes, more than the 268,435,456 read at most" in caplog.text, caplog.text
    np.testing.assert_array_equal(_result(fn), want)
    _assert_replaced(want)


_FIFO_IN_STORE = """
import json, os, sys
import jax, jax.numpy as jnp, numpy as np
import jaxgrasp
from jaxgrasp.engine import _compile
from jaxgrasp.engine import _store as store
folder = store.set_executable_dir(sys.argv[1])
spec = (jax.ShapeDtypeStruct((4,), jnp.float64),)
entry = store.executable_entry("tiny", (("tiny", 2.0), 0), spec)
os.mkfifo(entry.path)  # nobody writes to it: opening it to read would wait for ever
fn, _ = _compile.compiled(("tiny", 2.0), lambda: jax.jit(lambda x: (jnp.sin(x) * 2.0 + 1.0,)), spec, name="tiny",
                          store_key=("tiny", 2.0))
_compile.wait_for_saves()
print(json.dumps({"stats": store.stats(), "value": np.asarray(fn(np.linspace(0.0, 1.0, 4))[0]).tolist(),
                  "regular": os.path.isfile(entry.path)}))
"""


def test_fifo_in_the_store_does_not_block(tmp_path):
    """A FIFO at a stored file's name blocked the process for ever (its open waited for a
    writer): opened without blocking, it is refused and replaced. Run in a subprocess
    with a timeout, so that a regression fails instead of hanging the suite."""
    import json
    import subprocess
    import sys

    env = {**os.environ, "JAX_PLATFORMS": "cpu", "JAX_ENABLE_X64": "1"}
    proc = subprocess.run([sys.executable, "-c", _FIFO_IN_STORE, str(tmp_path / "store")], capture_output=True,
                          text=True, env=env, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["stats"]["traced"] == 1 and got["stats"]["cache_errors"] == 1, got
    np.testing.assert_allclose(got["value"], np.sin(X) * 2.0 + 1.0, rtol=1e-15)
    assert got["regular"]  # the FIFO was replaced by the stored file
    assert "not a regular file" in proc.stderr, proc.stderr


@pytest.mark.parametrize("home", ["", "/", "missing"])
def test_without_a_usable_home_the_cache_is_a_private_temporary_folder(tmp_path, monkeypatch, home):
    """``HOME=""`` reads as ``/`` (the cache landed in ``/.cache``); ``/`` itself and a home
    that does not exist are no better: the cache goes to the user's own folder in the
    temporary folder, created private, and one INFO line says so."""
    import tempfile

    monkeypatch.delenv(store.ENV_VAR, raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "missing") if home == "missing" else home)
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    monkeypatch.setattr(tempfile, "tempdir", None)  # gettempdir reads TMPDIR again
    (tmp_path / "tmp").mkdir()
    store._WARNED.clear()
    want = tmp_path / "tmp" / f"jaxgrasp-cache-{os.geteuid()}" / "xla"
    saved = store.executable_dir()
    try:
        assert store.default_dir() == want
        assert store.enable_from_environment() == want / store.EXECUTABLE_SUBDIR
        assert stat.S_IMODE(want.parent.stat().st_mode) == 0o700 and not (tmp_path / "missing").exists()
    finally:
        store.set_executable_dir(saved)
    assert any("no usable home folder" in m and str(want) in m for m in store._WARNED)


def test_command_without_a_home_keeps_matplotlib_out_of_the_root(tmp_path, monkeypatch):
    """``HOME=""``: matplotlib would keep its cache in ``/.cache/matplotlib``; the command
    points it into the temporary folder (a given ``MPLCONFIGDIR`` stays)."""
    import tempfile

    from jaxgrasp import cli
    from jaxgrasp.cli import _evaluate

    monkeypatch.setenv("HOME", "")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.delenv("MPLCONFIGDIR", raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    monkeypatch.setattr(cli, "enable_compilation_cache", lambda: None)  # no process-wide setting
    monkeypatch.setattr(_evaluate, "run", lambda args: 0)
    assert cli.main(["evaluate", "--preset", "cube"]) == 0
    assert os.environ["MPLCONFIGDIR"] == str(tmp_path / f"jaxgrasp-cache-{os.geteuid()}" / "matplotlib")
    monkeypatch.setenv("MPLCONFIGDIR", str(tmp_path / "mine"))
    assert cli.main(["evaluate", "--preset", "cube"]) == 0 and os.environ["MPLCONFIGDIR"] == str(tmp_path / "mine")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("MPLCONFIGDIR")
    assert cli.main(["evaluate", "--preset", "cube"]) == 0 and "MPLCONFIGDIR" not in os.environ
