"""Every cache of jaxgrasp: compiled programs in this process, on disk, and XLA's.

Three layers, each skipping more of the work of building an evaluator:

* the in-process memo (:func:`compiled`): a program compiled once is reused by every
  later call with the same key (at most :data:`MEMO_SIZE` are kept);
* the program store (:func:`set_program_dir`): the compiled program itself, serialized
  (``jax.experimental.serialize_executable``), so that a later process neither traces
  :func:`jaxgrasp.evaluate` in Python nor lowers nor compiles it: it loads the machine
  code (the cube: ~0.3 s instead of 3-5 s on 2 cores; ``experiments/compile_time.py``);
* JAX's persistent compilation cache, for the user's own ``jit`` programs and
  jaxgrasp's programs that are not stored. A program the store keeps is not written
  there as well: a second copy of the same machine code, whose writing cost 0.16 s of a
  cold default sweep (``experiments/compile_time.py``); a program whose stored file is
  missing, stale or corrupt is traced and compiled again, and stored again.

The programs of :func:`jaxgrasp.evaluate` on a concrete grasp
(:func:`jaxgrasp.evaluate.compiled_program`), of :func:`jaxgrasp.evaluate_batch` and of
:func:`jaxgrasp.sweep` (:func:`jaxgrasp.batch.compiled_evaluator`) all come from
:func:`compiled`. A traced grasp (inside the caller's ``jit``, ``vmap`` or ``grad``) is
traced with the caller's program and uses none of these.

The two stores on disk are off by default, as JAX's own cache is. One call turns both on,
:func:`enable_compilation_cache` (``jaxgrasp.enable_compilation_cache()``): XLA's cache in
the folder :func:`default_dir`, the programs in its subfolder ``jaxgrasp-programs``. Two
things call it by themselves:

* the ``jaxgrasp`` command, always;
* ``import jaxgrasp``, when the environment variable ``JAXGRASP_CACHE_DIR`` (:data:`ENV_VAR`)
  names a folder (:func:`enable_from_environment`): so every process of a program, or of
  a test runner, starts warm without a change to its code.

``JAXGRASP_CACHE_DIR`` is also the folder the command uses (default
``~/.cache/jaxgrasp/xla``). Like XLA's cache, the folder holds machine code that is loaded
and run: keep it where only you can write. Tests and benchmarks read what the caches did
with :func:`stats` and start afresh with :func:`clear_compiled`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
import pickle
import platform
import tempfile
import threading
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Hashable, Mapping, Sequence

import jax
import numpy as np


__all__ = [
    "ENV_VAR",
    "MEMO_SIZE",
    "PROGRAM_SUBDIR",
    "default_dir",
    "enable_compilation_cache",
    "enable_from_environment",
    "default_device",
    "set_program_dir",
    "program_dir",
    "source_digest",
    "program_path",
    "load_program",
    "save_program",
    "wait_for_saves",
    "compiled",
    "Pipeline",
    "Staged",
    "lower_stages",
    "clear_compiled",
    "stats",
]

ENV_VAR = "JAXGRASP_CACHE_DIR"
"""The environment variable naming the cache folder; where set, ``import jaxgrasp`` turns
the caches on (:func:`enable_from_environment`)."""

MEMO_SIZE = 16
"""Most compiled programs kept in this process (the least recently used is dropped first)."""

PROGRAM_SUBDIR = "jaxgrasp-programs"
"""Folder of the stored compiled programs inside the compilation cache folder."""

_MEMO: dict[Hashable, Any] = {}
_PROGRAM_DIR: Path | None = None
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
    the compiled programs in its subfolder ``jaxgrasp-programs`` (:func:`set_program_dir`):
    a repeated :func:`jaxgrasp.evaluate` of a concrete grasp, batch or sweep in a new
    process loads its compiled program instead of tracing, lowering and compiling it.
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
    set_program_dir(folder / PROGRAM_SUBDIR)
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


# --------------------------------------------------------------------------- program store


def set_program_dir(path) -> None:
    """Keep compiled programs in folder ``path``; ``None``: don't.

    A later process building the same program (same jaxgrasp source, JAX and jaxlib
    versions, key, device count, precision, backend and processor) loads it instead of
    tracing and compiling it. A missing, stale or corrupt file is ignored (the program is
    built and the file rewritten).
    """
    global _PROGRAM_DIR
    _PROGRAM_DIR = None if path is None else Path(path)


def program_dir() -> Path | None:
    """The folder of stored programs, ``None`` when they are not kept."""
    return _PROGRAM_DIR


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


def program_path(name: str, key: Hashable) -> Path | None:
    """File of the stored program ``name`` (``"sweep"``) for ``key``; ``None`` when
    programs are not kept. ``key`` must be the same in every process that builds the same
    program (device counts, not device ids)."""
    if _PROGRAM_DIR is None:
        return None
    import jaxlib

    text = repr((key, source_digest(), jax.__version__, jaxlib.__version__, _machine()))
    return _PROGRAM_DIR / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.xla"


_XLA_CACHE_HITS = [0]
"""Programs JAX's persistent cache has served in this process (counted from its events)."""


def _count_xla_cache_hits(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _XLA_CACHE_HITS[0] += 1


jax.monitoring.register_event_listener(_count_xla_cache_hits)

_FORMAT = "jaxgrasp-program-3"
"""Tag of a stored program's file (a file without it is stale)."""


def _register_handlers() -> None:
    """Register the CPU's LAPACK handlers (``eigh``, ``solve``), which a loaded program
    calls. JAX registers them while it lowers such a program; a program loaded without
    lowering would call unregistered handlers and crash the process. JAX's own loader of
    exported programs does the same (``jax._src.export``); where that private entry point
    is gone, lowering a 2 x 2 ``eigh`` registers them through public API."""
    try:
        from jax._src.lib import lapack

        lapack._lapack.initialize()
    except Exception:
        import jax.numpy as jnp

        jax.jit(jnp.linalg.eigh).lower(jax.ShapeDtypeStruct((2, 2), np.float32))


def _registering(devices: Sequence):
    """A started thread that runs :func:`_register_handlers` for a CPU program (it imports
    SciPy's LAPACK, ~0.15 s, while the program's machine code loads; join it before the
    program runs), or ``None`` where there is nothing to register."""
    if devices[0].platform != "cpu":
        return None
    thread = threading.Thread(target=_register_handlers, name="jaxgrasp-lapack", daemon=True)
    thread.start()
    return thread


def _spec_of(x) -> jax.ShapeDtypeStruct:
    """``x``'s shape, dtype and sharding (where it has one)."""
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=getattr(x, "sharding", None))


def _shapes(xs) -> list:
    return [(tuple(x.shape), np.dtype(x.dtype)) for x in jax.tree_util.tree_leaves(xs)]


def load_program(path: Path, spec: Sequence, devices: Sequence, n_outputs: int | None = None,
                 drive: Callable | None = None):
    """The compiled program stored at ``path`` (a ``jax.stages.Compiled``, or a
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
            raise ValueError("stale stored program")
        registering = _registering(devices)
        loaded = {}
        try:
            for name, payload, in_tree, out_tree in stages:
                if in_tree != jax.tree_util.tree_structure(((0,) * in_tree.num_leaves, {})):  # flat arrays
                    raise ValueError("stale stored program")
                loaded[name] = serialize_executable.deserialize_and_load(
                    payload, in_tree, out_tree, backend=devices[0].client, execution_devices=list(devices)
                )
        finally:
            if registering is not None:
                registering.join()

        def call(name, *args):  # each stage must take what the driver gives it
            fn = loaded[name]
            if _shapes(fn.args_info) != _shapes(args):
                raise ValueError("stale stored program")
            return tuple(jax.ShapeDtypeStruct(o.shape, o.dtype) for o in jax.tree_util.tree_leaves(fn.out_info))

        out = call(None, *spec) if drive is None else drive(call, *spec)
        if n_outputs is not None and len(out) != n_outputs:
            raise ValueError("stale stored program")
        return loaded[None] if drive is None else Staged(loaded, drive)
    except Exception:  # corrupt, stale, or from an incompatible JAX: build it again
        _STATS["cache_errors"] += 1
        return None


def save_program(path: Path, fn) -> None:
    """Write the compiled program ``fn`` (``jax.stages.Compiled`` or :class:`Staged`) to
    ``path`` atomically; never raises (a program that cannot be serialized is built again
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


@dataclasses.dataclass(frozen=True)
class Pipeline:
    """A program as several jitted stages and the Python function that calls them: what
    ``build`` of :func:`compiled` returns for a program compiled in stages.

    Attributes:
        stages: stage name -> jitted function (``jax.jit(...)`` with its shardings and
            compiler options; arrays in, a tuple of arrays out).
        drive: ``drive(call, *args)`` -> a tuple of arrays, the program: it runs stage
            ``name`` on arrays ``xs`` by ``call(name, *xs)`` (a tuple of arrays back),
            in any order and as often as it likes, a stage always on arrays of the same
            shapes. It must do nothing else with the arrays but pass them on: it also
            runs on their shapes alone, to compile the stages and to check stored ones.

    A program in stages compiles faster than the same work as one: each stage is
    compiled by XLA in a thread of its own (XLA's compiler releases the GIL) while the
    next is traced and lowered, a stage called twice is compiled once, and each stage
    has its own compiler options (one that runs briefly can be compiled for latency).
    """

    stages: Mapping[str, Callable]
    drive: Callable


class Staged:
    """A compiled :class:`Pipeline`: ``Staged(stages, drive)(*args)`` runs ``drive``
    with each stage's compiled program (``jax.stages.Compiled``, in :attr:`stages`,
    by name, in the order the driver first calls them). Results between stages stay
    on the devices."""

    def __init__(self, stages: Mapping[str, Any], drive: Callable):
        self.stages = dict(stages)
        self.drive = drive

    def __call__(self, *args):
        return self.drive(lambda name, *xs: self.stages[name](*xs), *args)


def lower_stages(pipeline: Pipeline, spec: Sequence, on_lowered: Callable | None = None) -> dict:
    """Run ``pipeline``'s driver on the shapes ``spec`` (``jax.ShapeDtypeStruct``
    leaves, with their shardings), lowering each stage when it is first called; returns
    stage name -> ``jax.stages.Lowered``, in that order. ``on_lowered(name, lowered)``
    is called at once for each (:func:`_compile` starts its XLA compilation there). A
    stage called again on other shapes is a ``ValueError``."""
    lowered: dict[str, tuple] = {}  # name -> (argument specs, jax.stages.Lowered)

    def call(name, *args):
        args = tuple(_spec_of(a) for a in args)
        if name not in lowered:
            lowered[name] = (args, pipeline.stages[name].lower(*args))
            if on_lowered is not None:
                on_lowered(name, lowered[name][1])
        elif lowered[name][0] != args:
            raise ValueError(f"stage {name!r} called on arrays of other shapes: {lowered[name][0]} and {args}")
        return tuple(_spec_of(o) for o in jax.tree_util.tree_leaves(lowered[name][1].out_info))

    pipeline.drive(call, *spec)
    return {name: low for name, (_, low) in lowered.items()}


def _compile(built, spec, quiet_xla: bool):
    """Trace, lower and compile ``built`` (a jitted function, or a :class:`Pipeline`) for
    the arguments ``spec``. A pipeline's stages are lowered as its driver first calls
    them (:func:`lower_stages`), each compiled in a thread of its own (XLA's compiler
    releases the GIL) while the driver goes on; the wait for those threads is not cut
    short by an interrupt (it is raised once they are done: XLA still compiling in a
    thread while the interpreter unwinds can crash the process). ``quiet_xla``: JAX's
    persistent cache writes no entry for them (:func:`_no_xla_cache_write`)."""

    def compile_one(lowered):
        with _no_xla_cache_write() if quiet_xla else contextlib.nullcontext():
            return lowered.compile()

    if not isinstance(built, Pipeline):
        return compile_one(built.lower(*spec))
    results: dict[str, tuple] = {}
    threads = []

    def start(name, lowered):
        thread = threading.Thread(target=lambda: results.__setitem__(name, _outcome(compile_one, lowered)),
                                  name=f"jaxgrasp-compile-{name}", daemon=True)
        thread.start()
        threads.append(thread)

    try:
        names = list(lower_stages(built, spec, start))
    finally:
        _join_uninterrupted(threads)
    for ok, value in results.values():
        if not ok:
            raise value
    return Staged({name: results[name][1] for name in names}, built.drive)


def _outcome(f, *args):
    """``(True, f(*args))``, or ``(False, exception)``."""
    try:
        return True, f(*args)
    except BaseException as exc:  # raised again in the calling thread
        return False, exc


def _join_uninterrupted(threads) -> None:
    """Wait for every thread; a ``KeyboardInterrupt`` meanwhile is raised after the wait."""
    interrupted = None
    for thread in threads:
        while thread.is_alive():
            try:
                thread.join()
            except KeyboardInterrupt as exc:
                interrupted = exc
    if interrupted is not None:
        raise interrupted


# --------------------------------------------------------------------------- compiled programs


def compiled(
    key: Hashable,
    build: Callable[[], Any],
    spec: Sequence,
    *,
    name: str = "program",
    store_key: Hashable | None = None,
    devices: Sequence | None = None,
    n_outputs: int | None = None,
):
    """A compiled program, from the memo, the program store or built now; ``(fn, seconds)``.

    Args:
        key: what makes the program unique in this process (the memo's key).
        build: ``build()`` returns the jitted function (``jax.jit(...)`` with its
            shardings and compiler options; arrays in, arrays out), or a
            :class:`Pipeline` of them; called when the program is not in the memo
            (it must be cheap: nothing is traced before the program is compiled).
        spec: its arguments as ``jax.ShapeDtypeStruct`` (with their shardings).
        name: prefix of its stored file.
        store_key: what makes it unique across processes (device counts, not ids);
            ``None``: never stored.
        devices: the devices it runs on, in its order (default: JAX's default device).
        n_outputs: the number of arrays it returns (a stored one must match).

    Returns:
        ``fn``, the compiled program (``jax.stages.Compiled``, or a :class:`Staged`),
        and the seconds spent building or loading it (0 on a memo hit).
    """
    hit = _MEMO.pop(key, None)
    if hit is not None:
        _MEMO[key] = hit  # now the most recently used
        return hit, 0.0
    t0 = time.perf_counter()
    path = None if store_key is None else program_path(name, (store_key, len(devices or ())))
    built = build()
    fn = None
    if path is not None:
        fn = load_program(path, spec, _devices(devices), n_outputs, built.drive if isinstance(built, Pipeline) else None)
    if fn is None:
        hits = _XLA_CACHE_HITS[0]
        fn = _compile(built, spec, quiet_xla=path is not None)
        _STATS["traced"] += 1
        # An executable that XLA's cache served cannot be serialized again (XLA on the CPU
        # then writes a program whose kernels are missing when it is loaded): store only
        # one that was compiled here. (XLA's cache holds no stored program's executable,
        # but may hold one written by another program of the same HLO or an older
        # jaxgrasp; later processes then trace it and load XLA's copy.)
        if path is not None and _XLA_CACHE_HITS[0] == hits:
            _save_in_background(path, fn)
    else:
        _STATS["deserialized"] += 1
    seconds = time.perf_counter() - t0
    if len(_MEMO) >= MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = fn
    return fn, seconds


_SAVES: list[threading.Thread] = []
"""Threads writing a compiled program to the store (:func:`_save_in_background`)."""


def _save_in_background(path: Path, fn) -> None:
    """:func:`save_program` in a thread, so that serializing the program (~0.1 s for a
    batch evaluator) overlaps its first run instead of delaying it. The thread is not a
    daemon (the interpreter waits for it at exit); a process that ends with ``os._exit``
    (the ``jaxgrasp`` command) calls :func:`wait_for_saves` first."""
    thread = threading.Thread(target=save_program, args=(path, fn), name="jaxgrasp-save")
    _SAVES.append(thread)
    thread.start()


def wait_for_saves(timeout: float | None = None) -> None:
    """Wait until the programs being written to the store are on disk (each write is
    atomic), at most ``timeout`` seconds in all (``None``: as long as they take)."""
    end = None if timeout is None else time.monotonic() + timeout
    for thread in list(_SAVES):
        thread.join(None if end is None else max(0.0, end - time.monotonic()))
        if thread.is_alive():
            return  # timed out
        try:
            _SAVES.remove(thread)
        except ValueError:  # another thread waited for it too (the command and an interrupt)
            pass


def _no_xla_cache_write():
    """Context in which JAX's persistent cache writes no entry from this thread (its
    minimum compile time for an entry raised to infinity, thread-locally): for programs
    that the program store keeps. Where this JAX has no such setting, a context that
    changes nothing."""
    try:
        from jax._src import config as jax_config

        return jax_config.persistent_cache_min_compile_time_secs(float("inf"))
    except (ImportError, AttributeError, TypeError):
        return contextlib.nullcontext()


def default_device():
    """The device a program without ``devices`` runs on: JAX's default device
    (``jax_default_device``: a device, or a platform name for its first device), else
    the first device."""
    default = jax.config.jax_default_device
    if default is None:
        return jax.devices()[0]
    return jax.devices(default)[0] if isinstance(default, str) else default


def _devices(devices: Sequence | None) -> list:
    """``devices``, or ``[default_device()]``."""
    return list(devices) if devices else [default_device()]


def clear_compiled() -> None:
    """Forget every compiled program of this process (the next build traces or loads),
    once the programs being stored are on disk."""
    wait_for_saves()
    _MEMO.clear()


def stats() -> dict[str, int]:
    """What the caches did in this process, counted since it started (a copy):

    * ``traced``: programs traced and compiled (and stored, where the store is on);
    * ``deserialized``: compiled programs loaded from the program store instead;
    * ``cache_errors``: stored files that could not be used or written.
    """
    return dict(_STATS)
