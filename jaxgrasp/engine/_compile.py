"""Compiling a pipeline: stages lowered and compiled in threads, memoised in the process, saved to the store."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import jax
import numpy as np

from jaxgrasp.engine._pipeline import Pipeline, Staged, lower_stages
from jaxgrasp.engine._setup import first_use
from jaxgrasp.engine._store import (
    _STATS,
    LOGGER,
    StoreEntry,
    discard,
    executable_entry,
    load_executable,
    save_executable,
    serialized_stages,
)

__all__ = ["MEMO_SIZE", "StoredFunction", "canonical_dtype", "clear_compiled", "compiled", "default_device",
           "forget", "wait_for_saves"]


MEMO_SIZE = 16
"""Most compiled executables kept in this process (the least recently used is dropped first)."""

_MEMO: dict[Hashable, Any] = {}

_XLA_CACHE_HITS = [0]
"""Executables JAX's persistent cache has served in this process (counted from its events)."""


def _count_xla_cache_hits(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _XLA_CACHE_HITS[0] += 1

jax.monitoring.register_event_listener(_count_xla_cache_hits)


def _compile(built, spec, quiet_xla: bool):
    """Trace, lower and compile ``built`` (a jitted function, or a `Pipeline`) for
    the arguments ``spec``. A pipeline's stages are lowered as its driver first calls
    them (`lower_stages`), each compiled in a thread of its own (XLA's compiler
    releases the GIL) while the driver goes on; the wait for those threads is not cut
    short by an interrupt (it is raised once they are done: XLA still compiling in a
    thread while the interpreter unwinds can crash the process). ``quiet_xla``: JAX's
    persistent cache writes no entry for them (`_no_xla_cache_write`)."""

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
    except BaseException as exc:  # noqa: BLE001  raised again in the calling thread
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


def compiled(
    key: Hashable,
    build: Callable[[], Any],
    spec: Sequence,
    *,
    name: str = "executable",
    what: str | None = None,
    store_key: Hashable | None = None,
    devices: Sequence | None = None,
    n_outputs: int | None = None,
):
    """A compiled executable, from the memo, the executable store or built now; ``(fn, seconds)``.

    Args:
        key: what makes the executable unique in this process (the memo's key).
        build: ``build()`` returns the jitted function (``jax.jit(...)`` with its
            shardings and compiler options; arrays in, arrays out), or a
            `Pipeline` of them; called when the executable is
            not in the memo (it must be cheap: nothing is traced before it is compiled).
        spec: its arguments as ``jax.ShapeDtypeStruct`` (with their shardings).
        name: prefix of its stored file.
        what: what it is, in words, for the report of its compilation (default ``name``).
        store_key: what makes it unique across processes (device counts, not ids);
            ``None``: never stored.
        devices: the devices it runs on, in its order (default: JAX's default device).
        n_outputs: the number of arrays it returns (a stored one must match).

    Returns:
        ``fn``, the compiled executable (``jax.stages.Compiled``, or a
        `Staged`),
        and the seconds spent building or loading it (0 on a memo hit).
    """
    hit = _MEMO.pop(key, None)
    if hit is not None:
        _MEMO[key] = hit  # now the most recently used
        return hit, 0.0
    first_use()  # the executable store (and the CPU devices, where JAX has not made them yet)
    t0 = time.perf_counter()
    entry = None if store_key is None else executable_entry(name, (store_key, len(devices or ()), *_process()), spec)
    built = build()
    fn, why = None, "the executable store is off"
    if entry is not None:
        drive = built.drive if isinstance(built, Pipeline) else None
        fn, why = load_executable(entry, spec, _devices(devices), n_outputs, drive)
    if fn is None:
        fn = _build(built, spec, entry, what or name, why)
    else:
        _STATS["deserialized"] += 1
        LOGGER.debug("jaxgrasp: loaded %s from %s", what or name, entry.path)
    seconds = time.perf_counter() - t0
    if len(_MEMO) >= MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = fn
    return fn, seconds


def canonical_dtype(x) -> np.dtype:
    """The dtype JAX gives ``x`` as an argument (float64 becomes float32 without x64)."""
    return np.dtype(jax.dtypes.canonicalize_dtype(x.dtype if hasattr(x, "dtype") else np.result_type(x)))


class StoredFunction:
    """``fun`` (traceable: pytrees of arrays in, a pytree of arrays out) compiled once per
    shape of its arguments through `compiled`: memoised in the process and, where
    the executable store is on, loaded from it, so that a later process calling it on
    arguments of the same shapes neither traces nor compiles it. This is how the
    gradient-based tuners' value and gradient reach the store (the evaluators build
    their flat executables themselves).

    Args:
        fun: the function; ``self(*args)`` returns ``fun(*args)`` (the same computation).
        key: what makes it unique across processes besides its arguments' shapes and
            tree (its ``repr`` holds every option: a stored file is found by that text).
        out_tree: the tree of ``fun``'s output, which must not depend on the arguments'
            values: a loaded executable returns flat arrays and is not traced.
        name: prefix of its stored file; what: what it is, in words (its compile report).
        compiler_options: XLA's options for ``jax.jit``.

    ``__wrapped__`` is ``fun`` itself (for a caller that needs its output shapes, or
    traces it inside its own ``jit``).
    """

    def __init__(self, fun: Callable, key: Hashable, out_tree, *, name: str, what: str,
                 compiler_options: dict | None = None):
        self.__wrapped__, self.key, self.out_tree = fun, key, out_tree
        self.name, self.what, self.compiler_options = name, what, compiler_options

    def _executable(self, leaves: list, treedef):
        avals = tuple((np.shape(x), canonical_dtype(x).name) for x in leaves)
        spec = [jax.ShapeDtypeStruct(shape, dtype) for shape, dtype in avals]
        # A treedef's text names every node and key in order: two layouts of the
        # arguments (a dict with or without an entry) differ in every process.
        store_key = (self.key, str(treedef), avals, jax.config.jax_enable_x64)

        def build():
            def flat(*leaves):  # arrays in, arrays out: the store keeps flat executables
                out = self.__wrapped__(*jax.tree_util.tree_unflatten(treedef, leaves))
                out_leaves, tree = jax.tree_util.tree_flatten(out)
                if tree != self.out_tree:
                    raise TypeError(f"{self.what}: returned {tree}, not the declared {self.out_tree}")
                return tuple(out_leaves)

            return jax.jit(flat, compiler_options=self.compiler_options)

        fn, _ = compiled((self.name, store_key, jax.config.jax_default_device), build, spec, name=self.name,
                         what=self.what, store_key=store_key, n_outputs=self.out_tree.num_leaves)
        return fn

    def __call__(self, *args):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        return jax.tree_util.tree_unflatten(self.out_tree, self._executable(leaves, treedef)(*leaves))


def _build(built, spec, entry: StoreEntry | None, what: str, why: str):
    """Compile ``built`` for ``spec`` (reported once, at INFO, on `LOGGER`: ``what``,
    ``why`` it is compiled, and where it will be stored) and store it at ``entry``."""
    where = "it will be stored in " + str(entry.path.parent) if entry is not None else "it is not stored"
    LOGGER.info("jaxgrasp: compiling %s (%s); %s", what, why, where)
    hits = _XLA_CACHE_HITS[0]
    fn = _compile(built, spec, quiet_xla=entry is not None)
    _STATS["traced"] += 1
    if entry is None:
        return fn
    # An executable that XLA's cache served cannot be serialized again (XLA on the CPU
    # then writes one whose kernels are missing when it is loaded): store only one
    # that was compiled here. (XLA's cache holds no stored executable, but may hold
    # one written for another function of the same HLO or by an older jaxgrasp;
    # later processes then trace it and load XLA's copy.)
    if _XLA_CACHE_HITS[0] == hits:
        _save_in_background(entry, fn)
    elif entry.path.exists():  # a file that was not usable, and is not replaced: not read again
        discard(entry)
    return fn

_SAVES: list[threading.Thread] = []
"""Threads writing a compiled executable to the store (`_save_in_background`)."""


def _save_in_background(entry: StoreEntry, fn) -> None:
    """Serialize ``fn`` now, before it first runs (`serialized_stages` says why), and
    write it to the store in a thread (`save_executable`), so that the write overlaps
    the first run instead of delaying it. The thread is not a daemon (the interpreter
    waits for it at exit); a process that ends with ``os._exit`` (the ``jaxgrasp``
    command) calls `wait_for_saves` first."""
    stages = serialized_stages(fn)
    if stages is None:
        return
    thread = threading.Thread(target=save_executable, args=(entry, stages), name="jaxgrasp-save")
    _SAVES.append(thread)
    thread.start()


def wait_for_saves(timeout: float | None = None) -> None:
    """Wait until the executables being written to the store are on disk (each write is
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
    minimum compile time for an entry raised to infinity, thread-locally): for executables
    that the executable store keeps. Where this JAX has no such setting, a context that
    changes nothing."""
    try:
        from jax._src import config as jax_config

        return jax_config.persistent_cache_min_compile_time_secs(float("inf"))
    except (ImportError, AttributeError, TypeError):
        return contextlib.nullcontext()


def _process() -> tuple:
    """What a stored executable's key adds in process 1, 2, ... of several
    (``jax.distributed``): its process index, as a stored executable names its devices by
    id and those ids differ from process to process (one stored by process 1 does not
    load in process 0 or in a process of its own, nor the other way round). Nothing in
    process 0, whose device ids are those of a process of its own: they share."""
    return ("process", jax.process_index()) if jax.process_index() > 0 else ()


def default_device():
    """The device an executable without ``devices`` runs on: JAX's default device
    (``jax_default_device``: a device, or a platform name for its first device), else
    the first device."""
    default = jax.config.jax_default_device
    if default is None:
        return jax.devices()[0]
    return jax.devices(default)[0] if isinstance(default, str) else default


def _devices(devices: Sequence | None) -> list:
    """``devices``, or ``[default_device()]``."""
    return list(devices) if devices else [default_device()]


def forget(key: Hashable) -> None:
    """Drop the executable of ``key`` from this process's memo: its memory (tens of MiB
    for a batch evaluator) is freed once nothing else holds it; the next build loads it
    from the store, or compiles it where the store is off."""
    _MEMO.pop(key, None)


def clear_compiled() -> None:
    """Forget every compiled executable of this process (the next build traces or loads),
    once the executables being stored are on disk."""
    wait_for_saves()
    _MEMO.clear()
