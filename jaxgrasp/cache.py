"""Every cache of jaxgrasp: compiled programs in this process, traced programs on disk, XLA's.

Three layers, each skipping more of the work of building an evaluator:

* the in-process memo (:func:`compiled`): a program compiled once is reused by every
  later call with the same key (at most :data:`MEMO_SIZE` are kept);
* the export store (:func:`set_export_dir`): the traced program, serialized with
  ``jax.export``, so that a later process skips tracing :func:`jaxgrasp.evaluate` in
  Python (the cube: 1.5-4 s on 2 cores);
* JAX's persistent compilation cache, so that the XLA compilation of that program is a
  cache load (the cube: 0.5-1 s instead of 7-22 s; ``experiments/compile_time.py``).

The programs of :func:`jaxgrasp.evaluate` on a concrete grasp
(:func:`jaxgrasp.evaluate.compiled_program`), of :func:`jaxgrasp.evaluate_batch` and of
:func:`jaxgrasp.sweep` (:func:`jaxgrasp.batch.compiled_evaluator`) all come from
:func:`compiled`. A traced grasp (inside the caller's ``jit``, ``vmap`` or ``grad``) is
traced with the caller's program and uses none of these.

The two stores on disk are off by default, as JAX's own cache is. One call turns both on,
:func:`enable_compilation_cache` (``jaxgrasp.enable_compilation_cache()``): XLA's cache in
the folder :func:`default_dir`, the exported programs in its subfolder
``jaxgrasp-export``. Two things call it by themselves:

* the ``jaxgrasp`` command, always;
* ``import jaxgrasp``, when the environment variable ``JAXGRASP_CACHE_DIR`` (:data:`ENV_VAR`)
  names a folder (:func:`enable_from_environment`): so every process of a program, or of
  a test runner, starts warm without a change to its code.

``JAXGRASP_CACHE_DIR`` is also the folder the command uses (default
``~/.cache/jaxgrasp/xla``). Tests and benchmarks read what the caches did with
:func:`stats` and start afresh with :func:`clear_compiled`.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Hashable, Sequence

import jax
import numpy as np

from .options import COMPILER_OPTIONS

__all__ = [
    "ENV_VAR",
    "MEMO_SIZE",
    "EXPORT_SUBDIR",
    "default_dir",
    "enable_compilation_cache",
    "enable_from_environment",
    "set_export_dir",
    "export_dir",
    "source_digest",
    "export_path",
    "load_exported",
    "save_exported",
    "compiled",
    "clear_compiled",
    "stats",
]

ENV_VAR = "JAXGRASP_CACHE_DIR"
"""The environment variable naming the cache folder; where set, ``import jaxgrasp`` turns
the caches on (:func:`enable_from_environment`)."""

MEMO_SIZE = 16
"""Most compiled programs kept in this process (the least recently used is dropped first)."""

EXPORT_SUBDIR = "jaxgrasp-export"
"""Folder of the exported programs inside the compilation cache folder."""

_MEMO: dict[Hashable, Any] = {}
_EXPORT_DIR: Path | None = None
_STATS = {"traced": 0, "deserialized": 0, "cache_errors": 0}


# --------------------------------------------------------------------------- XLA's cache


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
    the exported programs in its subfolder ``jaxgrasp-export`` (:func:`set_export_dir`):
    a repeated :func:`jaxgrasp.evaluate` of a concrete grasp, batch or sweep in a new
    process loads its program instead of tracing it in Python and compiling it in XLA.
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
    set_export_dir(folder / EXPORT_SUBDIR)
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


# --------------------------------------------------------------------------- export store


def set_export_dir(path) -> None:
    """Keep traced programs (``jax.export``) in folder ``path``; ``None``: don't.

    A later process building the same program (same jaxgrasp source, JAX version, key,
    devices and precision) deserializes it instead of tracing it in Python again. A
    missing, stale or corrupt file is ignored (the program is traced and the file
    rewritten).
    """
    global _EXPORT_DIR
    _EXPORT_DIR = None if path is None else Path(path)


def export_dir() -> Path | None:
    """The folder of exported programs, ``None`` when they are not kept."""
    return _EXPORT_DIR


def source_digest() -> str:
    """Hash of jaxgrasp's own source files, subpackages included (an editable install
    keeps its version number while its code changes)."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def export_path(name: str, key: Hashable) -> Path | None:
    """File of the exported program ``name`` (``"sweep"``) for ``key``; ``None`` when
    exported programs are not kept. ``key`` must be the same in every process that
    builds the same program (device counts, not device ids)."""
    if _EXPORT_DIR is None:
        return None
    import jaxlib

    text = repr((key, source_digest(), jax.__version__, jaxlib.__version__, jax.default_backend()))
    return _EXPORT_DIR / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.jaxexport"


def load_exported(path: Path, spec: Sequence, n_devices: int, n_outputs: int | None = None):
    """The exported program at ``path`` if it takes ``spec`` (``jax.ShapeDtypeStruct``
    leaves), runs on ``n_devices`` of this platform and returns ``n_outputs`` arrays;
    ``None`` otherwise (missing, stale, corrupt or from an incompatible JAX)."""
    try:
        exp = jax.export.deserialize(bytearray(path.read_bytes()))
        want = [(tuple(s.shape), np.dtype(s.dtype)) for s in jax.tree_util.tree_leaves(spec)]
        have = [(tuple(a.shape), np.dtype(a.dtype)) for a in exp.in_avals]
        stale_outputs = n_outputs is not None and len(exp.out_avals) != n_outputs
        if have != want or exp.nr_devices != n_devices or stale_outputs:
            raise ValueError("stale exported program")
        if jax.default_backend() not in exp.platforms:
            raise ValueError("exported for another platform")
        return exp
    except FileNotFoundError:
        return None
    except Exception:  # corrupt, stale, or from an incompatible JAX: trace again
        _STATS["cache_errors"] += 1
        return None


def save_exported(path: Path, exp) -> None:
    """Write the exported program ``exp`` to ``path`` atomically; never raises."""
    try:
        data = exp.serialize()  # needs the 'flatbuffers' package
    except Exception:  # e.g. ImportError: keep working, trace every time
        _STATS["cache_errors"] += 1
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, path)  # atomic: a concurrent reader sees the old file or the new one
    except OSError:
        pass  # no writable cache: trace every time


# --------------------------------------------------------------------------- compiled programs


def compiled(
    key: Hashable,
    build: Callable[[], Any],
    spec: Sequence,
    *,
    name: str = "program",
    export_key: Hashable | None = None,
    sharding=None,
    n_devices: int = 1,
    n_outputs: int | None = None,
):
    """A compiled program, from the memo, the export store or built now; ``(fn, seconds)``.

    Args:
        key: what makes the program unique in this process (the memo's key).
        build: ``build()`` returns the jitted function (``jax.jit(...)``, arrays in,
            arrays out), called only when the program is not in the memo.
        spec: its arguments as ``jax.ShapeDtypeStruct`` (with their shardings).
        name: prefix of its exported file.
        export_key: what makes it unique across processes; ``None``: never exported.
        sharding: in and out shardings of the deserialized program (those of ``build()``).
        n_devices: the number of devices it runs on (an exported one must match).
        n_outputs: the number of arrays it returns (an exported one must match).

    Returns:
        ``fn``, the compiled program (``jax.stages.Compiled``), and the seconds spent
        building it (0 on a memo hit).
    """
    hit = _MEMO.pop(key, None)
    if hit is not None:
        _MEMO[key] = hit  # now the most recently used
        return hit, 0.0
    t0 = time.perf_counter()
    path = None if export_key is None else export_path(name, export_key)
    if path is None:
        fn = build().lower(*spec).compile()
        _STATS["traced"] += 1
    else:
        exp = load_exported(path, spec, n_devices, n_outputs)
        if exp is None:
            exp = jax.export.export(build())(*spec)
            save_exported(path, exp)
            _STATS["traced"] += 1
        else:
            _STATS["deserialized"] += 1
        # the XLA compilation of the exported program hits JAX's persistent cache, if on
        fn = jax.jit(
            _named(exp.call, f"{name}_stored"),
            in_shardings=sharding,
            out_shardings=sharding,
            compiler_options=COMPILER_OPTIONS,
        )
        fn = fn.lower(*spec).compile()
    seconds = time.perf_counter() - t0
    if len(_MEMO) >= MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = fn
    return fn, seconds


def _named(fn: Callable, name: str) -> Callable:
    """``fn`` under ``name``, the name JAX gives its program in logs (``jit(name)``)."""

    def named(*args):
        return fn(*args)

    named.__name__ = named.__qualname__ = name
    return named


def clear_compiled() -> None:
    """Forget every compiled program of this process (the next build traces or loads)."""
    _MEMO.clear()


def stats() -> dict[str, int]:
    """What the caches did in this process, counted since it started (a copy):

    * ``traced``: programs traced in Python (and exported, where the store is on);
    * ``deserialized``: programs loaded from the export store instead;
    * ``cache_errors``: exported files that could not be used or written.
    """
    return dict(_STATS)
