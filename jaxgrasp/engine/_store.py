"""The executable store on disk and the switches of every cache of jaxgrasp.

Three layers, each skipping more of the work of building an evaluator:

* the in-process memo (`jaxgrasp.engine._compile.compiled`): an executable
  compiled once is reused by every later call with the same key;
* the executable store (`set_executable_dir`): the compiled executable itself,
  serialized (``jax.experimental.serialize_executable``), so that a later process neither
  traces [`jaxgrasp.evaluate`][jaxgrasp.evaluate] in Python nor lowers nor compiles it: it loads the
  machine code;
* JAX's persistent compilation cache, for the user's own ``jit`` functions and
  jaxgrasp's executables that are not stored. An executable the store keeps is not
  written there as well (a second copy of the same machine code, written for nothing).

The executables of [`jaxgrasp.evaluate`][jaxgrasp.evaluate] on a concrete grasp, of
[`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch], of [`jaxgrasp.sweep`][jaxgrasp.sweep] and the value and gradient of
[`jaxgrasp.tune`][jaxgrasp.tune] and [`jaxgrasp.tune_hand`][jaxgrasp.tune_hand]
(`StoredFunction`) all come from
`compiled`. A traced grasp (inside the caller's ``jit``,
``vmap`` or ``grad``) is traced with the caller's function and uses none of these.

Which caches are on:

* jaxgrasp's first use (its first compilation or batch, or [`jaxgrasp.configure`][jaxgrasp.configure])
  turns on the executable store alone (`enable_from_environment`), in the subfolder
  ``jaxgrasp-executables`` of `default_dir`: every process of a script starts warm,
  without a change to its code; ``import jaxgrasp`` writes nothing. It does not turn on
  JAX's persistent compilation cache, which is global to the process: it would change how
  the user's own ``jit`` functions are compiled and stored, which is the user's choice.
* [`enable_compilation_cache`][jaxgrasp.engine.enable_compilation_cache] (``jaxgrasp.engine.enable_compilation_cache()``) and the
  ``jaxgrasp`` command turn on both: JAX's cache in `default_dir`, the executables
  in its subfolder.
* The environment variable ``JAXGRASP_CACHE_DIR`` (`ENV_VAR`) moves the folder;
  ``JAXGRASP_CACHE_DIR=off`` switches every jaxgrasp cache off (the first use's, the
  command's and ``enable_compilation_cache()``'s; a folder passed to it explicitly is
  still used). Unset, the folder is ``$XDG_CACHE_HOME/jaxgrasp/xla``, else
  ``~/.cache/jaxgrasp/xla``.

Both caches load machine code that is then run, and a stored executable is a pickle
(so is the payload of ``serialize_executable``): whoever can write a file there can run
code as the user. So nothing is read that another user could have written:

* a folder jaxgrasp creates is private (mode 0700, every level it creates);
* before any cache is turned on, the folder and the executable subfolder must be owned by
  the user, not writable by group or others, and not symbolic links; otherwise neither
  cache is turned on and one warning line names the folder and why;
* every stored file is opened without following links and checked the same way (a regular
  file, the user's, not writable by group or others) before a byte of it is unpickled;
  otherwise it is skipped with a warning (and counted in `stats`);
* a stored file starts with a format line and a JSON header holding the executable's full
  key (options, shapes, versions, jaxgrasp's source digest, machine, ``XLA_FLAGS``) and the SHA-256 and
  length of its payload; a file whose key is not exactly the expected one, or whose
  payload does not match, is not unpickled: the executable is compiled again and the file
  replaced;
* files are written as every file of jaxgrasp (`jaxgrasp.storage.write_file`):
  through a temporary file created exclusively (``O_EXCL``, ``O_NOFOLLOW``, here mode
  0600) under a random name in the same folder, synced, then renamed over the file
  (atomic: a reader sees the old file or the new one); a failed write removes it, and
  temporary files of dead processes (or older than
  `jaxgrasp.storage.STALE_TEMP_SECONDS`) are removed when the store is turned on
  (`jaxgrasp.storage.remove_stale_temps`). The private folders and files are
  `jaxgrasp.storage.private_folder` and `jaxgrasp.storage.read_private`.

Warnings and the report of each compilation go to the ``logging`` logger ``"jaxgrasp"``
(`LOGGER`): a compilation is reported at INFO level (what, why, where it is stored),
which the ``jaxgrasp`` command prints on stderr. Tests and benchmarks read what the caches
did with `stats` and start afresh with
`jaxgrasp.engine._compile.clear_compiled`.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import logging
import os
import pickle
import platform
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable, Hashable, Sequence
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from jaxgrasp import storage
from jaxgrasp.engine._pipeline import Staged

__all__ = [
    "ENV_VAR",
    "EXECUTABLE_SUBDIR",
    "LOGGER",
    "OFF",
    "StoreEntry",
    "default_dir",
    "discard",
    "enable_compilation_cache",
    "enable_from_environment",
    "chosen_dir",
    "executable_dir",
    "executable_entry",
    "load_executable",
    "log_lines_on_stderr",
    "save_executable",
    "serialized_stages",
    "set_executable_dir",
    "source_digest",
    "stats",
]


ENV_VAR = "JAXGRASP_CACHE_DIR"
"""The environment variable that moves the cache folder (`default_dir`), or with the
value `OFF` switches every jaxgrasp cache off."""

OFF = "off"
"""The value of ``JAXGRASP_CACHE_DIR`` (any case) that switches every jaxgrasp cache off."""

EXECUTABLE_SUBDIR = "jaxgrasp-executables"
"""Folder of the executable store inside the cache folder."""

LOGGER = logging.getLogger("jaxgrasp")
"""Where the caches report: refused folders and files (WARNING), compilations (INFO)."""

_EXECUTABLE_DIR: Path | None = None
_CHOSEN = False
"""Whether the store was chosen (`set_executable_dir`, directly or through
[`enable_compilation_cache`][jaxgrasp.engine.enable_compilation_cache] or `enable_from_environment`), on or off."""

_STATS = {"traced": 0, "deserialized": 0, "cache_errors": 0}

_WARNED: set[str] = set()
"""Warnings already given in this process (each is given once)."""


def _warn_once(message: str) -> None:
    if message not in _WARNED:
        _WARNED.add(message)
        LOGGER.warning(message)


def default_dir() -> Path | None:
    """The cache folder: ``$JAXGRASP_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxgrasp/xla``,
    else ``~/.cache/jaxgrasp/xla``; without a usable home folder (`_home`), the user's
    own folder in the temporary folder, ``jaxgrasp-cache-UID/xla`` (`_temporary_dir`);
    ``None`` where ``JAXGRASP_CACHE_DIR=off``."""
    value = os.environ.get(ENV_VAR, "").strip()
    if value.lower() == OFF:
        return None
    if value:
        return Path(value).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if os.path.isabs(xdg):  # XDG: a relative value is ignored
        return Path(xdg) / "jaxgrasp" / "xla"
    home = _home()
    return home / ".cache" / "jaxgrasp" / "xla" if home is not None else _temporary_dir()


def _home() -> Path | None:
    """The home folder the cache may go in: ``$HOME`` (or the user's entry in the password
    database where it is unset); ``None`` where it is empty, relative or the file system's
    root (``HOME=""`` reads as ``/``: the cache would land in ``/.cache``), or is not an
    existing folder (a system user's ``/nonexistent`` is not created)."""
    value = os.environ.get("HOME")
    if value is None:
        try:
            value = os.path.expanduser("~")  # the password database
        except (RuntimeError, KeyError):  # pragma: no cover - no entry for this user
            return None
    home = Path(value) if value else None
    if home is None or not home.is_absolute() or home == Path(home.anchor) or not home.is_dir():
        return None
    return home


def matplotlib_dir() -> Path | None:
    """Where matplotlib should keep its cache and configuration (``MPLCONFIGDIR``) in a
    process of a user without a usable home folder (`_home`): ``jaxgrasp-cache-UID/matplotlib``
    in the temporary folder, beside `_temporary_dir`; ``None`` where the user has a home
    folder (matplotlib's own choice is right). Without it, ``HOME=""`` puts matplotlib's
    cache in ``/.cache/matplotlib`` (where the root user can write)."""
    if os.environ.get("XDG_CACHE_HOME") or _home() is not None:
        return None
    return Path(tempfile.gettempdir()) / f"jaxgrasp-cache-{os.geteuid()}" / "matplotlib"


def _temporary_dir() -> Path:
    """The cache folder of a user without a usable home folder: ``jaxgrasp-cache-UID/xla``
    in the temporary folder (``$TMPDIR``, else ``/tmp``...), private as every cache folder
    (one owned by another user, or open to others, is refused with a warning: nothing
    planted there is loaded). Said once, at INFO level."""
    folder = Path(tempfile.gettempdir()) / f"jaxgrasp-cache-{os.geteuid()}" / "xla"
    message = f"jaxgrasp: no usable home folder (HOME={os.environ.get('HOME')!r}); caching compiled code in {folder}"
    if message not in _WARNED:
        _WARNED.add(message)
        LOGGER.info(message)
    return folder


def chosen_dir() -> tuple[bool, Path | None]:
    """``(chosen, folder)``: whether the program chose the store already (`set_executable_dir`,
    directly or through [`enable_compilation_cache`][jaxgrasp.engine.enable_compilation_cache]
    or `enable_from_environment`), and its folder (``None``: off). jaxgrasp's first use
    ([`jaxgrasp.configure`][jaxgrasp.configure]) keeps such a choice."""
    return _CHOSEN, _EXECUTABLE_DIR


def enable_from_environment() -> Path | None:
    """Turn on the executable store alone in `default_dir`'s subfolder
    ``jaxgrasp-executables`` (not JAX's own cache, see the module docstring); the folder
    of the store, or ``None`` (switched off, refused, or it cannot be created). It starts
    no JAX backend."""
    folder = default_dir()
    if folder is None:
        return None
    problem = storage.private_folder(folder, create=True)
    if problem is not None:
        _refuse(folder, problem)
        return None
    return set_executable_dir(folder / EXECUTABLE_SUBDIR)


def enable_compilation_cache(path=None) -> Path | None:
    """Turn on both caches on disk, so that a new process neither traces nor compiles again.

    JAX's persistent compilation cache lives in ``path`` (default `default_dir`; with
    ``JAXGRASP_CACHE_DIR=off`` and no ``path``: nothing is turned on), the compiled
    executables in its subfolder ``jaxgrasp-executables`` (`set_executable_dir`).
    A folder that does not exist is created, private (0700). A folder another user owns
    or can write (or a symbolic link) turns on neither cache: one warning line says why.
    Calling it again (with the same folder) changes nothing. A folder that cannot be
    created leaves every setting as it was (every run compiles). A folder of the user's
    that exists but cannot be written is still read (a pre-filled cache works) and new
    compilations are not saved, quietly: JAX's own warning for every entry it fails to
    write (two lines on stderr per compilation, every run) is silenced, and XLA's own
    caches (on a GPU, its autotuning results) are not pointed into it.

    Returns:
        The folder, or ``None`` where no cache was turned on.
    """
    folder = default_dir() if path is None else Path(path).expanduser()
    if folder is None:
        return None
    problem = (storage.private_folder(folder, create=True)
               or storage.private_folder(folder / EXECUTABLE_SUBDIR, create=False))
    if problem is not None:
        _refuse(folder, problem)
        return None
    if not _writable(folder):
        warnings.filterwarnings("ignore", message=_JAX_WRITE_ERROR, category=UserWarning)
        # JAX would also point XLA's own caches (a GPU's autotuning results) into the
        # folder, and XLA logs every write it is refused on stderr.
        jax.config.update("jax_persistent_cache_enable_xla_caches", "none")
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    set_executable_dir(folder / EXECUTABLE_SUBDIR)
    return folder


_JAX_WRITE_ERROR = r"Error writing persistent compilation cache entry"
"""The start of the warning JAX gives for every cache entry it fails to write."""


def _refuse(folder: Path, problem: str) -> None:
    """Warn (once) that ``folder`` is not used, and stop storing executables there."""
    global _EXECUTABLE_DIR
    if problem.startswith("cannot be created"):  # nowhere to write: quietly compile every run
        LOGGER.info("jaxgrasp: cache folder %s %s; compiling every run", folder, problem)
    else:
        _warn_once(f"jaxgrasp: not using cache folder {folder}: {problem}; compiling every run")
    if _EXECUTABLE_DIR is not None and folder in (_EXECUTABLE_DIR, _EXECUTABLE_DIR.parent):
        _EXECUTABLE_DIR = None


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (``os.access`` says yes to root even
    where the file system refuses)."""
    try:
        storage.check_writable(folder)
        return True
    except storage.OutputError:
        return False


def set_executable_dir(path) -> Path | None:
    """Keep compiled executables in folder ``path``; ``None``: don't. Returns the folder,
    or ``None`` where it is not used.

    The folder is created private (0700) where it is missing and the folder above it can
    be written. A folder another user owns or can write, or a symbolic link, is refused
    (one warning; the store is off). A later process building the same executable (same
    jaxgrasp source, JAX and jaxlib versions, key, shapes, device count, precision,
    backend and processor) loads it instead of tracing and compiling it. A missing,
    stale or damaged file is ignored (the executable is built and the file replaced).
    Temporary files of the store left by dead processes are removed.
    """
    global _EXECUTABLE_DIR, _CHOSEN
    _CHOSEN = True
    if path is None:
        _EXECUTABLE_DIR = None
        return None
    folder = Path(path).expanduser()
    problem = storage.private_folder(folder, create=True)
    if problem is not None and os.path.isdir(folder.parent) and problem.startswith("cannot be created"):
        problem = storage.private_folder(folder, create=False)  # a read-only cache: read what it has
    if problem is not None:
        _refuse(folder, problem)
        _EXECUTABLE_DIR = None
        return None
    _EXECUTABLE_DIR = folder
    storage.remove_stale_temps(folder, earlier_store_names=True)
    return folder


def executable_dir() -> Path | None:
    """The folder of stored executables, ``None`` when they are not kept."""
    return _EXECUTABLE_DIR


@functools.cache
def source_digest() -> str:
    """Hash of jaxgrasp's own source files, subpackages included (an editable install
    keeps its version number while its code changes)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _machine() -> str:
    """What compiled code depends on beyond JAX's version: the backend (platform, version,
    device kind), the ``XLA_FLAGS`` the process runs with (they change the code XLA emits:
    an executable built under other flags is another program) and, on the CPU, the
    processor's instruction-set flags, so that a cache folder shared by machines with
    different processors never loads code built for another (it builds its own)."""
    dev = jax.devices()[0]
    parts = [dev.platform, dev.client.platform_version, dev.device_kind, platform.machine(),
             os.environ.get("XLA_FLAGS", "")]
    if dev.platform == "cpu":
        try:
            with open("/proc/cpuinfo") as f:
                parts.append(next((ln for ln in f if ln.startswith(("flags", "Features"))), ""))
        except OSError:
            parts.append(platform.processor())
    return repr(parts)


class StoreEntry(NamedTuple):
    """Where an executable is stored, and the full text of its key (written in the file's
    header and compared on load)."""

    path: Path
    key: str


def _shapes(xs) -> list:
    return [(tuple(x.shape), np.dtype(x.dtype)) for x in jax.tree_util.tree_leaves(xs)]


def executable_entry(name: str, key: Hashable, spec: Sequence = ()) -> StoreEntry | None:
    """The file of the stored executable ``name`` (``"sweep"``) for ``key`` and arguments
    ``spec`` (``jax.ShapeDtypeStruct`` leaves), with its full key text; ``None`` when
    executables are not kept. ``key`` must be the same in every process that builds the
    same executable (device counts, not device ids), and its ``repr`` must hold every
    option (it is compared as text)."""
    if _EXECUTABLE_DIR is None:
        return None
    import jaxlib

    text = repr((key, _shapes(spec), source_digest(), jax.__version__, jaxlib.__version__, _machine()))
    return StoreEntry(_EXECUTABLE_DIR / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.xla", text)


_MAGIC = b"jaxgrasp-executable-4"
"""First line of a stored executable's file (a file of another format is stale)."""

MAX_EXECUTABLE_BYTES = 256 * 2**20
"""The largest stored executable read, bytes (256 MiB): a stored file is read whole, then
its payload copied and unpickled, so a file of a few gigabytes (a sparse one costs nothing
on disk) would take several times its size in memory. The executables jaxgrasp stores are
a few MiB on a CPU (``experiments/limits/FINDINGS.md``); a larger file is not read, the
executable is built again and the file replaced."""

_MAX_HEADER = 1 << 20
"""Longest header line read (bytes); a longer one is damaged."""


class _Unusable(Exception):
    """A stored file that is not loaded; the message says why."""


class _Refused(_Unusable):
    """A stored file that another user could have written: not read at all."""


def _read_private(path: Path) -> bytes:
    """The bytes of ``path`` (`jaxgrasp.storage.read_private`); raises
    ``FileNotFoundError``, `_Refused` or `_Unusable`."""
    try:
        return storage.read_private(path, MAX_EXECUTABLE_BYTES)
    except storage.NotPrivate as exc:
        raise _Refused(str(exc)) from None
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise _Unusable(f"it cannot be read ({exc.strerror})") from None


def _encode(key: str, payload: bytes) -> bytes:
    """A stored file: `_MAGIC`, a JSON header (key, payload's length and SHA-256),
    the payload."""
    header = {"key": key, "payload_bytes": len(payload), "payload_sha256": hashlib.sha256(payload).hexdigest()}
    return b"\n".join([_MAGIC, json.dumps(header, sort_keys=True).encode(), payload])


def _decode(data: bytes, key: str) -> bytes:
    """The payload of a stored file ``data`` whose header holds exactly ``key`` and whose
    payload has the length and SHA-256 the header gives; raises `_Unusable`."""
    magic, _, rest = data.partition(b"\n")
    if magic != _MAGIC:
        raise _Unusable("not a stored executable of this version's format")
    end = rest.find(b"\n", 0, _MAX_HEADER + 1)
    try:
        if end < 0:
            raise ValueError("no end of header")
        header = json.loads(rest[:end])
    except ValueError:
        raise _Unusable("its header is damaged") from None
    payload = rest[end + 1 :]
    if not isinstance(header, dict) or header.get("key") != key:
        raise _Unusable("it was built for another key (other options, shapes, versions or machine)")
    if header.get("payload_bytes") != len(payload) or header.get("payload_sha256") != hashlib.sha256(payload).hexdigest():
        raise _Unusable("its checksum does not match (damaged)")
    return payload


def _registering(devices: Sequence):
    """A started thread that registers the CPU's LAPACK handlers for a CPU executable (see
    `_register_handlers`; join it before the executable runs), or ``None``."""
    if devices[0].platform != "cpu":
        return None
    thread = threading.Thread(target=_register_handlers, name="jaxgrasp-lapack", daemon=True)
    thread.start()
    return thread


def _register_handlers() -> None:
    """Register the CPU's LAPACK handlers (``eigh``, ``solve``), which a loaded executable
    calls. JAX registers them while it lowers such a function; an executable loaded without
    lowering would call unregistered handlers and crash the process. JAX's own loader of
    exported functions does the same (``jax._src.export``); where that private entry point
    is gone, lowering a 2 x 2 ``eigh`` registers them through public API."""
    try:
        from jax._src.lib import lapack

        lapack._lapack.initialize()
    except Exception:  # noqa: BLE001  any failure: the public route below
        import jax.numpy as jnp

        jax.jit(jnp.linalg.eigh).lower(jax.ShapeDtypeStruct((2, 2), np.float32))


def _load_stages(stages, spec: Sequence, devices: Sequence, n_outputs: int | None, drive: Callable | None):
    """The executable of the unpickled ``stages`` (``[(name, payload, in_tree, out_tree)]``),
    loaded onto ``devices``, if it takes ``spec`` and returns ``n_outputs`` arrays; raises
    ``ValueError`` otherwise."""
    from jax.experimental import serialize_executable

    if not stages or (drive is None) != (len(stages) == 1 and stages[0][0] is None):
        raise ValueError("its stages do not fit the driver")
    registering = _registering(devices)
    loaded = {}
    try:
        for name, payload, in_tree, out_tree in stages:
            if in_tree != jax.tree_util.tree_structure(((0,) * in_tree.num_leaves, {})):  # flat arrays
                raise ValueError("its arguments are not flat arrays")
            loaded[name] = serialize_executable.deserialize_and_load(
                payload, in_tree, out_tree, backend=devices[0].client, execution_devices=list(devices)
            )
    finally:
        if registering is not None:
            registering.join()

    def call(name, *args):  # each stage must take what the driver gives it
        fn = loaded[name]
        if _shapes(fn.args_info) != _shapes(args):
            raise ValueError("a stage takes other shapes")
        return tuple(jax.ShapeDtypeStruct(o.shape, o.dtype) for o in jax.tree_util.tree_leaves(fn.out_info))

    out = call(None, *spec) if drive is None else drive(call, *spec)
    if n_outputs is not None and len(out) != n_outputs:
        raise ValueError("it returns another number of arrays")
    return loaded[None] if drive is None else Staged(loaded, drive)


def load_executable(entry: StoreEntry, spec: Sequence, devices: Sequence, n_outputs: int | None = None,
                    drive: Callable | None = None):
    """The compiled executable stored at ``entry`` (a ``jax.stages.Compiled``, or a
    `Staged` of several, called by ``drive``: `Pipeline`), loaded onto
    ``devices``, if it takes ``spec`` (``jax.ShapeDtypeStruct`` leaves) and returns
    ``n_outputs`` arrays; ``(executable, None)``, or ``(None, why)`` (a phrase: missing;
    refused with a warning, as another user could have written it; built for another key;
    damaged; built for other devices). Nothing is unpickled before the file's owner,
    mode, key and checksum are checked. Every file that is there but not loaded counts
    in ``stats()["cache_errors"]``."""
    try:
        stages = pickle.loads(_decode(_read_private(entry.path), entry.key))
    except FileNotFoundError:
        return None, "no stored executable yet"
    except _Refused as exc:
        _STATS["cache_errors"] += 1
        _warn_once(f"jaxgrasp: not loading stored executable {entry.path}: {exc}")
        return None, f"its stored file is refused: {exc}"
    except Exception as exc:  # noqa: BLE001  _Unusable, or a payload that does not unpickle
        _STATS["cache_errors"] += 1
        return None, f"its stored file is unusable: {exc if isinstance(exc, _Unusable) else 'it does not unpickle'}"
    try:
        return _load_stages(stages, spec, devices, n_outputs, drive), None
    except Exception as exc:  # noqa: BLE001  stale, or from an incompatible JAX: build it again
        _STATS["cache_errors"] += 1
        return None, f"its stored file does not load here ({exc})"


def serialized_stages(fn) -> list | None:
    """The stages of the compiled executable ``fn`` (``jax.stages.Compiled`` or
    `Staged`) serialized, as `save_executable` writes them; ``None`` where it
    cannot be serialized (counted in ``stats()["cache_errors"]``).

    Call it before ``fn`` first runs: XLA's CPU runtime may replace parts of an executable
    while it runs (a sort's comparison by a built-in one) with parts it cannot serialize,
    so serializing it during or after its first run fails at random."""
    from jax.experimental import serialize_executable as jax_serialize

    try:
        named = fn.stages.items() if isinstance(fn, Staged) else [(None, fn)]
        return [(name, *jax_serialize.serialize(f)) for name, f in named]
    except Exception:  # noqa: BLE001  not serializable: built again next time
        _STATS["cache_errors"] += 1
        return None


def save_executable(entry: StoreEntry, stages: list) -> bool:
    """Write serialized ``stages`` (`serialized_stages`) to ``entry`` atomically,
    with its key and checksum; whether it was written. Never raises (an executable that
    cannot be written is built again next time, and counts in ``stats()["cache_errors"]``)."""
    try:
        data = _encode(entry.key, pickle.dumps(stages, protocol=pickle.HIGHEST_PROTOCOL))
        if not entry.path.parent.is_dir():
            storage.make_private(entry.path.parent)
        storage.write_file(entry.path, data, mode=0o600)  # the user's alone: it is loaded and run
        return True
    except Exception:  # noqa: BLE001  no writable cache: build every time
        _STATS["cache_errors"] += 1
        return False


def discard(entry: StoreEntry) -> None:
    """Remove the stored file of ``entry`` (one that could not be used and is not replaced),
    so that later processes do not read it again; quietly where it cannot."""
    with contextlib.suppress(OSError):
        os.unlink(entry.path)


class _StderrLines(logging.Handler):
    """Each record's message as one line on the current ``sys.stderr`` (looked up at each
    line, so that a redirected stderr gets it)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            print(record.getMessage().splitlines()[0], file=sys.stderr, flush=True)
        except Exception:  # noqa: BLE001  pragma: no cover - stderr closed
            self.handleError(record)


@contextlib.contextmanager
def log_lines_on_stderr(level: int = logging.INFO):
    """Within the block, what `LOGGER` reports at ``level`` or above is printed on
    stderr, one line each (the ``jaxgrasp`` command's compilation reports and warnings)."""
    handler = _StderrLines(level)
    before = LOGGER.level
    LOGGER.addHandler(handler)
    LOGGER.setLevel(min(level, before) if before else level)
    try:
        yield
    finally:
        LOGGER.removeHandler(handler)
        LOGGER.setLevel(before)


def stats() -> dict[str, int]:
    """What the caches did in this process, counted since it started (a copy):

    * ``traced``: executables traced and compiled (and stored, where the store is on);
    * ``deserialized``: compiled executables loaded from the executable store instead;
    * ``cache_errors``: stored files that could not be used or written.
    """
    return dict(_STATS)
