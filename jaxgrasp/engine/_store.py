"""The executable store on disk and the switches of every cache of jaxgrasp.

Three layers, each skipping more of the work of building an evaluator:

* the in-process memo (:func:`jaxgrasp.engine._compile.compiled`): an executable
  compiled once is reused by every later call with the same key;
* the executable store (:func:`set_executable_dir`): the compiled executable itself,
  serialized (``jax.experimental.serialize_executable``), so that a later process neither
  traces :func:`jaxgrasp.evaluate` in Python nor lowers nor compiles it: it loads the
  machine code;
* JAX's persistent compilation cache, for the user's own ``jit`` functions and
  jaxgrasp's executables that are not stored. An executable the store keeps is not
  written there as well (a second copy of the same machine code, written for nothing); an
  executable whose stored file is missing, stale or corrupt is traced and compiled again,
  and stored again.

The executables of :func:`jaxgrasp.evaluate` on a concrete grasp
(:func:`jaxgrasp.engine._evaluate.compiled_executable`), of :func:`jaxgrasp.evaluate_batch`
and of :func:`jaxgrasp.sweep` (:func:`jaxgrasp.engine._evaluator.compiled_evaluator`) all
come from :func:`~jaxgrasp.engine._compile.compiled`. A traced grasp (inside the caller's
``jit``, ``vmap`` or ``grad``) is traced with the caller's function and uses none of these.

The two stores on disk are off by default, as JAX's own cache is. One call turns both on,
:func:`enable_compilation_cache` (``jaxgrasp.enable_compilation_cache()``): XLA's cache in
the folder :func:`default_dir`, the executables in its subfolder ``jaxgrasp-executables``. Two
things call it by themselves:

* the ``jaxgrasp`` command, always;
* ``import jaxgrasp``, when the environment variable ``JAXGRASP_CACHE_DIR`` (:data:`ENV_VAR`)
  names a folder (:func:`enable_from_environment`): so every process of an application,
  or of a test runner, starts warm without a change to its code.

``JAXGRASP_CACHE_DIR`` is also the folder the command uses (default
``~/.cache/jaxgrasp/xla``). Like XLA's cache, the folder holds machine code that is loaded
and run: keep it where only you can write. Tests and benchmarks read what the caches did
with :func:`stats` and start afresh with :func:`clear_compiled`.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import platform
import tempfile
import threading
import warnings
from pathlib import Path
from typing import Callable, Hashable, Sequence

import jax
import numpy as np

from jaxgrasp.engine._pipeline import Staged

__all__ = [
    "ENV_VAR",
    "EXECUTABLE_SUBDIR",
    "default_dir",
    "enable_compilation_cache",
    "enable_from_environment",
    "set_executable_dir",
    "executable_dir",
    "source_digest",
    "executable_path",
    "load_executable",
    "save_executable",
    "stats",
]


ENV_VAR = "JAXGRASP_CACHE_DIR"
"""The environment variable naming the cache folder; where set, ``import jaxgrasp`` turns
the caches on (:func:`enable_from_environment`)."""

EXECUTABLE_SUBDIR = "jaxgrasp-executables"
"""Folder of the executable store inside the compilation cache folder."""

_EXECUTABLE_DIR: Path | None = None

_STATS = {"traced": 0, "deserialized": 0, "cache_errors": 0}


def default_dir() -> Path:
    """The compilation cache folder: ``$JAXGRASP_CACHE_DIR`` or ``~/.cache/jaxgrasp/xla``."""
    return Path(os.environ.get(ENV_VAR) or str(Path.home() / ".cache" / "jaxgrasp" / "xla"))


def enable_from_environment() -> Path | None:
    """Turn the caches on (:func:`enable_compilation_cache`) if ``$JAXGRASP_CACHE_DIR``
    names a folder (unset or empty: leave them as they are); the folder or ``None``.
    ``import jaxgrasp`` calls it once."""
    if not os.environ.get(ENV_VAR):
        return None
    return enable_compilation_cache()


def enable_compilation_cache(path=None) -> Path | None:
    """Turn on both caches on disk, so that a new process neither traces nor compiles again.

    JAX's persistent compilation cache lives in ``path`` (default :func:`default_dir`),
    the compiled executables in its subfolder ``jaxgrasp-executables`` (:func:`set_executable_dir`):
    a repeated :func:`jaxgrasp.evaluate` of a concrete grasp, batch or sweep in a new
    process loads its compiled executable instead of tracing, lowering and compiling it.
    Calling it again (with the same folder) changes nothing. A folder that cannot be
    created leaves every setting as it was (every run compiles). A folder that exists
    but cannot be written is still read (a shared, pre-filled cache works) and new
    compilations are not saved, quietly: JAX's own warning for every entry it fails to
    write (two lines on stderr per compilation, every run) is silenced.

    Returns:
        The folder, or ``None`` when it could not be created.
    """
    folder = default_dir() if path is None else Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # no writable cache: compile every time
    if not _writable(folder):
        warnings.filterwarnings("ignore", message=_JAX_WRITE_ERROR, category=UserWarning)
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    set_executable_dir(folder / EXECUTABLE_SUBDIR)
    return folder

_JAX_WRITE_ERROR = r"Error writing persistent compilation cache entry"
"""The start of the warning JAX gives for every cache entry it fails to write."""


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (``os.access`` says yes to root even
    where the file system refuses)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def set_executable_dir(path) -> None:
    """Keep compiled executables in folder ``path``; ``None``: don't.

    A later process building the same executable (same jaxgrasp source, JAX and jaxlib
    versions, key, device count, precision, backend and processor) loads it instead of
    tracing and compiling it. A missing, stale or corrupt file is ignored (the executable is
    built and the file rewritten).
    """
    global _EXECUTABLE_DIR
    _EXECUTABLE_DIR = None if path is None else Path(path)


def executable_dir() -> Path | None:
    """The folder of stored executables, ``None`` when they are not kept."""
    return _EXECUTABLE_DIR


def source_digest() -> str:
    """Hash of jaxgrasp's own source files, subpackages included (an editable install
    keeps its version number while its code changes)."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _machine() -> str:
    """What compiled code depends on beyond JAX's version: the backend (platform, version,
    device kind) and, on the CPU, the processor's instruction-set flags, so that a cache
    folder shared by machines with different processors never loads code built for
    another (it builds its own)."""
    dev = jax.devices()[0]
    parts = [dev.platform, dev.client.platform_version, dev.device_kind, platform.machine()]
    if dev.platform == "cpu":
        try:
            with open("/proc/cpuinfo") as f:
                parts.append(next((ln for ln in f if ln.startswith(("flags", "Features"))), ""))
        except OSError:
            parts.append(platform.processor())
    return repr(parts)


def executable_path(name: str, key: Hashable) -> Path | None:
    """File of the stored executable ``name`` (``"sweep"``) for ``key``; ``None`` when
    executables are not kept. ``key`` must be the same in every process that builds the same
    executable (device counts, not device ids)."""
    if _EXECUTABLE_DIR is None:
        return None
    import jaxlib

    text = repr((key, source_digest(), jax.__version__, jaxlib.__version__, _machine()))
    return _EXECUTABLE_DIR / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.xla"

_FORMAT = "jaxgrasp-executable-3"
"""Tag of a stored executable's file (a file without it is stale)."""


def _register_handlers() -> None:
    """Register the CPU's LAPACK handlers (``eigh``, ``solve``), which a loaded executable
    calls. JAX registers them while it lowers such a function; an executable loaded without
    lowering would call unregistered handlers and crash the process. JAX's own loader of
    exported functions does the same (``jax._src.export``); where that private entry point
    is gone, lowering a 2 x 2 ``eigh`` registers them through public API."""
    try:
        from jax._src.lib import lapack

        lapack._lapack.initialize()
    except Exception:
        import jax.numpy as jnp

        jax.jit(jnp.linalg.eigh).lower(jax.ShapeDtypeStruct((2, 2), np.float32))


def _registering(devices: Sequence):
    """A started thread that runs :func:`_register_handlers` for a CPU executable (it imports
    SciPy's LAPACK while the executable's machine code loads; join it before the
    executable runs), or ``None`` where there is nothing to register."""
    if devices[0].platform != "cpu":
        return None
    thread = threading.Thread(target=_register_handlers, name="jaxgrasp-lapack", daemon=True)
    thread.start()
    return thread


def _shapes(xs) -> list:
    return [(tuple(x.shape), np.dtype(x.dtype)) for x in jax.tree_util.tree_leaves(xs)]


def load_executable(path: Path, spec: Sequence, devices: Sequence, n_outputs: int | None = None,
                 drive: Callable | None = None):
    """The compiled executable stored at ``path`` (a ``jax.stages.Compiled``, or a
    :class:`Staged` of several, called by ``drive``: :class:`Pipeline`), loaded onto
    ``devices``, if it takes ``spec`` (``jax.ShapeDtypeStruct`` leaves) and returns
    ``n_outputs`` arrays; ``None`` otherwise (missing, stale, corrupt, or built for
    other devices)."""
    from jax.experimental import serialize_executable

    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError:
        _STATS["cache_errors"] += 1
        return None
    try:
        tag, stages = pickle.loads(data)
        if tag != _FORMAT or not stages or (drive is None) != (len(stages) == 1 and stages[0][0] is None):
            raise ValueError("stale stored executable")
        registering = _registering(devices)
        loaded = {}
        try:
            for name, payload, in_tree, out_tree in stages:
                if in_tree != jax.tree_util.tree_structure(((0,) * in_tree.num_leaves, {})):  # flat arrays
                    raise ValueError("stale stored executable")
                loaded[name] = serialize_executable.deserialize_and_load(
                    payload, in_tree, out_tree, backend=devices[0].client, execution_devices=list(devices)
                )
        finally:
            if registering is not None:
                registering.join()

        def call(name, *args):  # each stage must take what the driver gives it
            fn = loaded[name]
            if _shapes(fn.args_info) != _shapes(args):
                raise ValueError("stale stored executable")
            return tuple(jax.ShapeDtypeStruct(o.shape, o.dtype) for o in jax.tree_util.tree_leaves(fn.out_info))

        out = call(None, *spec) if drive is None else drive(call, *spec)
        if n_outputs is not None and len(out) != n_outputs:
            raise ValueError("stale stored executable")
        return loaded[None] if drive is None else Staged(loaded, drive)
    except Exception:  # corrupt, stale, or from an incompatible JAX: build it again
        _STATS["cache_errors"] += 1
        return None


def save_executable(path: Path, fn) -> None:
    """Write the compiled executable ``fn`` (``jax.stages.Compiled`` or :class:`Staged`) to
    ``path`` atomically; never raises (an executable that cannot be serialized is built again
    next time)."""
    from jax.experimental import serialize_executable

    try:
        named = fn.stages.items() if isinstance(fn, Staged) else [(None, fn)]
        stages = [(name, *serialize_executable.serialize(f)) for name, f in named]
        data = pickle.dumps((_FORMAT, stages), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:
        _STATS["cache_errors"] += 1
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, path)  # atomic: a concurrent reader sees the old file or the new one
    except OSError:
        pass  # no writable cache: build every time


def stats() -> dict[str, int]:
    """What the caches did in this process, counted since it started (a copy):

    * ``traced``: executables traced and compiled (and stored, where the store is on);
    * ``deserialized``: compiled executables loaded from the executable store instead;
    * ``cache_errors``: stored files that could not be used or written.
    """
    return dict(_STATS)
