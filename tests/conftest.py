"""Session-wide helpers that keep the suite fast.

jaxgrasp's ``evaluate`` costs tens of seconds to compile per number of contacts ``N``
and about a second per grasp to run, so:

* :func:`evaluate_many` evaluates lists of grasps through ONE ``jax.jit(jax.vmap(...))``
  per ``N``. Batches are cut into chunks of one size per ``N`` (padded by repeating the
  last grasp), so every call with the same ``N`` reuses the same executable. Results are
  cached per grasp for the whole session.
* :func:`ipopt_reference` runs the independent CasADi/Ipopt reference
  (``tests/ipopt_reference.py``) in a separate worker process, so that Ipopt runs while
  JAX compiles. Submit early (``ipopt_reference.submit``), collect late
  (``ipopt_reference.get``). Results are cached per (grasp, n_starts, seed).
* One cache folder for the session (:func:`store_dir`): XLA's cache and jaxgrasp's
  executable store for every ``jaxgrasp.cli.main`` run (:func:`cache_dir`). A test that
  needs a cold or a broken store makes its own (``warm_cache``, ``tmp_path``); the
  developer's own ``JAXGRASP_CACHE_DIR`` is never used.
* The ``slow`` marker (``pyproject.toml``): compile-heavy, subprocess and long tests. The
  developer's loop is ``python -m pytest -m "not slow"``; CI runs everything. A test that
  uses one of :data:`SLOW_FIXTURES` is slow by itself (:func:`pytest_collection_modifyitems`),
  so that no fast test pays for those fixtures; others carry ``@pytest.mark.slow``.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import multiprocessing
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# Where set, the developer's JAXGRASP_CACHE_DIR would turn on their own stores at
# ``import jaxgrasp``: tests would load programs compiled elsewhere, and count no traces.
os.environ.pop("JAXGRASP_CACHE_DIR", None)

import jaxgrasp  # noqa: E402  turns on jax_enable_x64 by itself (tested in test_evaluate.py)

TESTS_DIR = Path(__file__).resolve().parent
if str(TESTS_DIR) not in sys.path:  # so that the Ipopt worker can import the reference
    sys.path.insert(0, str(TESTS_DIR))

GRASP_FIELDS = jaxgrasp.model._fields.NAMES

# Largest batch per compiled call. The batch size for each N is fixed by the first call
# with that N (its grasps in balanced chunks of at most CHUNK), so every N compiles once.
# Padding costs about one grasp evaluation per unused slot: pass all grasps of an N in
# the first call.
CHUNK = 16


def grasp_key(grasp) -> tuple:
    """A hashable, exact key of a grasp's field values."""
    out = []
    for name in GRASP_FIELDS:
        a = np.asarray(getattr(grasp, name), dtype=np.float64)
        out.append((name, a.shape, a.tobytes()))
    if grasp.active is not None:  # a contact mask makes a different grasp
        a = np.asarray(grasp.active, dtype=bool)
        out.append(("active", a.shape, a.tobytes()))
    return tuple(out)


def grasp_to_numpy(grasp) -> dict:
    return {name: np.asarray(getattr(grasp, name), dtype=np.float64) for name in GRASP_FIELDS}


def stack(grasps):
    """Stack a list of same-``N`` grasps into one batched grasp (leading axis)."""
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *grasps)


def unstack(tree, i):
    """Element ``i`` of a batched pytree."""
    return jax.tree_util.tree_map(lambda a: a[i], tree)


class BatchEvaluator:
    """``jax.jit(jax.vmap(jaxgrasp.evaluate))`` with one executable per contact count."""

    def __init__(self, chunk: int = CHUNK):
        self.chunk = chunk
        self._chunk_n: dict[int, int] = {}  # batch size used for each N (fixed at first use)
        # evaluate() skips input validation when traced, so the lambda is vmappable.
        self._fn = jax.jit(jax.vmap(lambda g: jaxgrasp.evaluate(g)), compiler_options=jaxgrasp.engine.COMPILER_OPTIONS)
        self._cache: dict = {}
        self.calls = 0

    def __call__(self, grasps):
        grasps = list(grasps)
        todo: dict[int, dict] = {}  # N -> {key: grasp}, insertion-ordered
        for g in grasps:
            k = grasp_key(g)
            if k not in self._cache:
                todo.setdefault(g.num_contacts, {}).setdefault(k, g)
        for n, by_key in sorted(todo.items()):
            items = list(by_key.items())
            if n not in self._chunk_n:  # balanced chunks of at most self.chunk grasps
                parts = -(-len(items) // self.chunk)
                self._chunk_n[n] = -(-len(items) // parts)
            chunk = self._chunk_n[n]
            for start in range(0, len(items), chunk):
                part = items[start : start + chunk]
                gs = [g for _, g in part]
                gs = gs + [gs[-1]] * (chunk - len(gs))
                res = jax.tree_util.tree_map(np.asarray, self._fn(stack(gs)))
                self.calls += 1
                for i, (k, _) in enumerate(part):
                    self._cache[k] = unstack(res, i)
        return [self._cache[grasp_key(g)] for g in grasps]


@pytest.fixture(scope="session")
def evaluate_many():
    """``evaluate_many(grasps) -> [Evaluation, ...]`` (NumPy leaves), batched and cached.

    Pass every grasp of a test module in as few calls as possible; grasps may have
    different contact counts (they are grouped by ``N``).
    """
    return BatchEvaluator()


class IpoptReference:
    """Cached, asynchronous access to ``ipopt_reference.reference_evaluate``."""

    def __init__(self):
        import ipopt_reference  # tests/ipopt_reference.py (needs casadi)

        self._run = ipopt_reference.reference_evaluate  # pickled by name for the worker
        self._futures: dict = {}
        self._pool = None
        try:
            ctx = multiprocessing.get_context("spawn")  # never fork a process running JAX
            self._pool = concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=ctx)
        except Exception:  # pragma: no cover - no process pool: run in-process
            self._pool = None

    def submit(self, grasps, n_starts: int = 24, seed: int = 0) -> None:
        """Start the reference runs of ``grasps`` (a grasp or a list) without waiting."""
        if not isinstance(grasps, (list, tuple)):
            grasps = [grasps]
        for g in grasps:
            key = (grasp_key(g), n_starts, seed)
            if key in self._futures:
                continue
            fields = grasp_to_numpy(g)
            if self._pool is not None:
                try:
                    self._futures[key] = self._pool.submit(self._run, fields, n_starts=n_starts, seed=seed)
                    continue
                except Exception:  # pragma: no cover - broken pool: fall back
                    self._pool = None
            fut = concurrent.futures.Future()
            fut.set_result(self._run(fields, n_starts=n_starts, seed=seed))
            self._futures[key] = fut

    def get(self, grasp, n_starts: int = 24, seed: int = 0) -> dict:
        """The reference result of ``grasp`` (waits for it; submits it if needed)."""
        self.submit(grasp, n_starts, seed)
        key = (grasp_key(grasp), n_starts, seed)
        try:
            return self._futures[key].result()
        except concurrent.futures.BrokenExecutor:  # pragma: no cover - worker died: retry here
            self._pool = None
            del self._futures[key]
            self.submit(grasp, n_starts, seed)
            return self._futures[key].result()

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


@pytest.fixture(scope="session")
def ipopt_reference():
    """An :class:`IpoptReference` (``.submit(grasps)``, ``.get(grasp) -> dict``), or
    ``None`` where CasADi is not installed (tests that need it then skip themselves)."""
    try:
        import casadi  # noqa: F401
    except ImportError:
        yield None
        return
    ref = IpoptReference()
    yield ref
    ref.close()


# ----------------------------------------------------------------------------- CLI runs
_CACHE_OPTIONS = (
    "jax_compilation_cache_dir",
    "jax_persistent_cache_min_compile_time_secs",
    "jax_persistent_cache_min_entry_size_bytes",
)


@pytest.fixture(scope="session")
def store_dir(tmp_path_factory) -> Path:
    """The session's cache folder (``JAXGRASP_CACHE_DIR``): XLA's compilation cache, and
    jaxgrasp's executable store in its subfolder. Every test module that runs the command
    shares it, so a program compiled by one is loaded by the next."""
    return tmp_path_factory.mktemp("jaxgrasp-cache")


@pytest.fixture(scope="module")
def cache_dir(store_dir):
    """The session's cache folder (:func:`store_dir`) for ``jaxgrasp.cli.main`` (and its
    subprocesses).

    ``main`` turns on JAX's persistent compilation cache and jaxgrasp's executable store
    (process-wide settings); both are restored after the module so the rest of the
    session is unaffected.
    """
    from jaxgrasp.engine import _store as cache

    saved = {k: getattr(jax.config, k) for k in _CACHE_OPTIONS}
    saved_programs = cache.executable_dir()
    yield store_dir
    for k, v in saved.items():
        jax.config.update(k, v)
    cache.set_executable_dir(saved_programs)


@pytest.fixture
def run_cli(cache_dir, capsys, monkeypatch):
    """``run_cli(argv) -> (exit code, stdout, stderr)``: ``jaxgrasp.cli.main``, in-process."""
    from jaxgrasp import cli

    monkeypatch.setenv("JAXGRASP_CACHE_DIR", str(cache_dir))

    def run(argv):
        capsys.readouterr()  # drop anything printed before
        rc = cli.main([str(a) for a in argv])
        out = capsys.readouterr()
        return rc, out.out, out.err

    return run


# ----------------------------------------------------------------------------- warm caches
_FILL_CACHE = """
import json
import numpy as np
import jaxgrasp
r = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
fields = {f: np.asarray(getattr(r, f)).tolist() for f in jaxgrasp.tolerance._result.FIELDS}
print(json.dumps({"stats": jaxgrasp.engine._store.stats(), "fields": fields}))
"""


@dataclasses.dataclass(frozen=True)
class WarmCache:
    """A cache folder filled by a library process that only set ``JAXGRASP_CACHE_DIR``
    and evaluated the cube (``jaxgrasp.presets.cube(6e5, 0.002)``, = examples/cube.toml).

    Attributes:
        folder: the folder (``JAXGRASP_CACHE_DIR``).
        first: what that process printed: ``stats`` (:func:`jaxgrasp.engine._store.stats`) and
            ``fields`` (every Evaluation field, as lists).
    """

    folder: Path
    first: dict

    def run(self, argv: list[str]) -> subprocess.CompletedProcess:
        """Run ``argv`` in the repository with ``JAXGRASP_CACHE_DIR`` set to the folder."""
        env = dict(os.environ, JAXGRASP_CACHE_DIR=str(self.folder))
        proc = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=TESTS_DIR.parent, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc

    def evaluate_in_new_process(self, store: bool = True) -> dict:
        """A new library process evaluates the cube: its ``stats`` and ``fields``. With
        ``store`` false its program store is off (XLA's cache alone is on)."""
        script = _FILL_CACHE if store else _FILL_CACHE.replace(
            "import jaxgrasp\n", "import jaxgrasp\njaxgrasp.engine._store.set_executable_dir(None)\n", 1)
        return json.loads(self.run([sys.executable, "-c", script]).stdout)

    def program_files(self) -> set[str]:
        """The stored evaluators' files: jaxgrasp's compiled programs and XLA's cache entries."""
        from jaxgrasp.engine._store import EXECUTABLE_SUBDIR

        stored = {f"{EXECUTABLE_SUBDIR}/{p.name}" for p in (self.folder / EXECUTABLE_SUBDIR).glob("evaluate-*")}
        return stored | {p.name for p in self.folder.glob("jit_evaluate_fields-*")}


@pytest.fixture(scope="session")
def warm_cache(tmp_path_factory) -> WarmCache:
    """:class:`WarmCache`: one cold library process (traces and compiles the cube, ~10 s
    on 2 cores) whose stores later processes load.

    Its folder is its own, not :func:`store_dir`: the first process must find it empty
    (``test_cache`` checks that it traced once), whichever tests ran before."""
    folder = tmp_path_factory.mktemp("warm") / "cache"  # not there yet: jaxgrasp creates it
    filler = WarmCache(folder, {})
    return WarmCache(folder, filler.evaluate_in_new_process())


# ----------------------------------------------------------------------------- slow tests
SLOW_FIXTURES = frozenset({"evaluate_many", "ipopt_reference", "warm_cache"})
"""Session fixtures that compile an evaluator per contact count, run Ipopt in a worker
process, or fill a cache folder in a cold process: a test that uses one is slow."""


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects
def pytest_collection_modifyitems(config, items):
    """Mark ``slow`` every test that uses one of :data:`SLOW_FIXTURES`, directly or through
    another fixture (a module fixture's cost falls on whichever test uses it first)."""
    for item in items:
        if SLOW_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
