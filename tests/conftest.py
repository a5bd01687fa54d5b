"""Session-wide helpers that keep the suite fast.

jaxgrasp's ``evaluate`` costs tens of seconds to compile per number of contacts ``N``
and about a second per grasp to run, so:

* :func:`evaluate_many` evaluates lists of grasps through ONE ``jax.jit(jax.vmap(...))``
  per ``N``, in chunks of :data:`CHUNK` grasps (padded by repeating the last grasp), kept
  in the session's executable store: the first worker that needs an ``N`` compiles it
  (the other waits for it, then loads it without tracing), every later call reuses it.
  Results are cached per grasp for the whole session.
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
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

# jaxgrasp's first use turns on its executable store in JAXGRASP_CACHE_DIR, else in the
# user's ~/.cache: the suite (and every subprocess it starts, which inherits the variable)
# uses a folder of its own instead, so that it neither loads programs compiled elsewhere
# (and counts no traces) nor fills the developer's or the CI's cache. Removed at the end.
# Under pytest-xdist (``-n 2``) the workers share their controller's folder (named by its
# process id, their parent's), so that a program one worker compiled the other loads; the
# store writes atomically, so two workers may fill it at once. The controller removes it.
XDIST_WORKER = os.environ.get("PYTEST_XDIST_WORKER") is not None
SESSION_CACHE = Path(tempfile.gettempdir()) / f"jaxgrasp-test-cache-{os.getppid() if XDIST_WORKER else os.getpid()}"
SESSION_CACHE.mkdir(mode=0o700, exist_ok=True)
os.environ["JAXGRASP_CACHE_DIR"] = str(SESSION_CACHE)

import jaxgrasp  # noqa: E402  turns on jax_enable_x64 by itself (tested in test_evaluate.py)
from jaxgrasp.engine._xla_options import latency_options  # noqa: E402

TESTS_DIR = Path(__file__).resolve().parent
if str(TESTS_DIR) not in sys.path:  # so that the Ipopt worker can import the reference
    sys.path.insert(0, str(TESTS_DIR))

GRASP_FIELDS = jaxgrasp.model._fields.NAMES
EVALUATION_TREE = jaxgrasp.tolerance._result.EVALUATION_TREE

# Grasps per compiled call of evaluate_many, for every N: one size, so that the executable
# of an N is the same in every module and worker (and a grasp's result does not depend on
# which module asked first). Padding costs about one grasp evaluation per unused slot, far
# less than a compilation (~50 s on 2 cores).
CHUNK = 16


ACCELERATOR_RTOL, ACCELERATOR_ATOL = 1e-9, 1e-15
"""How far two compilations of one program may differ on an accelerator (relative, and
absolute for numbers that are zero on one side). On a CPU they agree to the last digit.
On a GPU, XLA autotunes its kernels at each compilation and may pick kernels that round
differently: on an H100, a stored program and a fresh compilation of it gave a zero
translation as 0.0 and -5.4e-82 m."""


def assert_same_numbers(actual, desired, where: str = "") -> None:
    """``actual`` equals ``desired`` (numbers, arrays, and dicts and lists of them, as
    ``json.loads`` gives): to the last digit on a CPU, NaN equal to NaN; on an accelerator,
    to :data:`ACCELERATOR_RTOL` (:data:`ACCELERATOR_ATOL` absolute)."""
    if isinstance(desired, dict):
        assert isinstance(actual, dict) and actual.keys() == desired.keys(), (where, actual, desired)
        for k in desired:
            assert_same_numbers(actual[k], desired[k], f"{where}.{k}")
        return
    if isinstance(desired, (list, tuple)) and not all(isinstance(v, (int, float)) for v in desired):
        assert isinstance(actual, (list, tuple)) and len(actual) == len(desired), (where, actual, desired)
        for i, (a, d) in enumerate(zip(actual, desired)):
            assert_same_numbers(a, d, f"{where}[{i}]")
        return
    if isinstance(desired, (str, bool)) or desired is None:
        assert actual == desired, (where, actual, desired)
        return
    a, d = np.asarray(actual), np.asarray(desired)
    if jax.default_backend() == "cpu" or not np.issubdtype(d.dtype, np.floating):
        np.testing.assert_array_equal(a, d, err_msg=where)
    else:
        np.testing.assert_allclose(a, d, rtol=ACCELERATOR_RTOL, atol=ACCELERATOR_ATOL, err_msg=where)


def json_from_new_process(code: str, *argv: str) -> dict:
    """Run ``code`` in a new Python process with ``argv`` and this session's environment
    (its executable store, ``JAXGRASP_CACHE_DIR``); the JSON it printed. A non-zero exit
    fails the test with the end of its stderr."""
    proc = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, env=os.environ,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


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
    """``jax.jit(jax.vmap(jaxgrasp.evaluate))`` with one executable per contact count (and
    contact mask or none), stored in the session's folder and shared by the workers."""

    def __init__(self, chunk: int = CHUNK):
        self.chunk = chunk
        self._fns: dict[tuple, object] = {}
        self._cache: dict = {}
        self.calls = 0

    def _executable(self, n: int, masked: bool, arrays: list):
        """The compiled flat program for ``arrays`` (the stacked fields, then the mask):
        from this process, else from the store, else compiled here under a lock on the
        session folder, so that two workers never compile the same one at once."""
        from jaxgrasp.engine import _compile

        key = (n, masked)
        if key not in self._fns:
            names = GRASP_FIELDS

            def flat(*a):
                grasps = jaxgrasp.Grasp(**dict(zip(names, a)), active=a[len(names)] if masked else None)
                return tuple(jax.tree_util.tree_leaves(jax.vmap(lambda g: jaxgrasp.evaluate(g))(grasps)))

            # evaluate() skips input validation when traced, so it is vmappable. The options
            # jaxgrasp.evaluate compiles a concrete grasp with (LLVM's optimisation skipped
            # on the CPU) halve the compile and cost little run time: each runs a few times.
            build = lambda: jax.jit(flat, compiler_options=latency_options(jax.default_backend()))  # noqa: E731
            spec = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in arrays]
            with open(SESSION_CACHE / f"evaluate-many-{n}-{int(masked)}.lock", "w") as lock:
                if fcntl is not None:  # without it (Windows) both workers may compile it
                    fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
                fn, _ = _compile.compiled(("tests.evaluate_many", key, self.chunk), build, spec, name="test-evaluate-many",
                                          store_key=("tests.evaluate_many", key, self.chunk))
                _compile.wait_for_saves()  # on disk before the other worker may look
            self._fns[key] = fn
        return self._fns[key]

    def _run(self, gs):
        n, masked = gs[0].num_contacts, gs[0].active is not None
        arrays = [np.stack([np.asarray(getattr(g, name), np.float64) for g in gs]) for name in GRASP_FIELDS]
        if masked:
            arrays.append(np.stack([np.asarray(g.active, bool) for g in gs]))
        out = self._executable(n, masked, arrays)(*arrays)
        return jax.tree_util.tree_unflatten(EVALUATION_TREE, [np.asarray(a) for a in out])

    def __call__(self, grasps):
        grasps = list(grasps)
        todo: dict[tuple, dict] = {}  # (N, masked) -> {key: grasp}, insertion-ordered
        for g in grasps:
            k = grasp_key(g)
            if k not in self._cache:
                todo.setdefault((g.num_contacts, g.active is not None), {}).setdefault(k, g)
        for _, by_key in sorted(todo.items()):
            items = list(by_key.items())
            for start in range(0, len(items), self.chunk):
                part = items[start : start + self.chunk]
                gs = [g for _, g in part]
                res = self._run(gs + [gs[-1]] * (self.chunk - len(gs)))
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


def pytest_sessionfinish(session, exitstatus):
    """Remove the session's cache folder (:data:`SESSION_CACHE`)."""
    from jaxgrasp.engine import _compile

    _compile.wait_for_saves(timeout=60)  # no write into a folder being removed
    if not XDIST_WORKER:  # the controller ends last
        shutil.rmtree(SESSION_CACHE, ignore_errors=True)


@pytest.fixture(scope="session")
def store_dir() -> Path:
    """The session's cache folder (``JAXGRASP_CACHE_DIR``, :data:`SESSION_CACHE`): XLA's
    compilation cache (once the command turns it on), and jaxgrasp's executable store in
    its subfolder (on from the import). Every test module and subprocess shares it, so a
    program compiled by one is loaded by the next."""
    return SESSION_CACHE


COMPILE_REPORT = re.compile(r"^jaxgrasp: compiling .*$\n?", re.MULTILINE)
"""A line the command prints on stderr before it compiles an evaluator (once per shape)."""


def without_compile_reports(err: str) -> str:
    """``err`` (the command's stderr) without its compilation reports, which appear only
    where the session's store did not hold the program yet (it depends on test order)."""
    return COMPILE_REPORT.sub("", err)


@pytest.fixture(scope="session", autouse=True)
def first_use():
    """jaxgrasp's first use (`jaxgrasp.engine._setup.first_use`: the CPU devices, the
    session's store) before the first test, as the first evaluate would do it. A test that
    sets the store and puts back what it found (``executable_dir()``) then puts back the
    session's store: before the first use it found ``None``, "not chosen yet", and put
    back "off", so a later module's programs were not stored for its subprocesses."""
    from jaxgrasp.engine import _setup

    _setup.first_use()


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
import json, logging
import numpy as np
logging.basicConfig(level=logging.INFO, format="%(name)s %(levelname)s %(message)s")
import jaxgrasp
{setup}
r = jaxgrasp.evaluate(jaxgrasp.presets.cube(6e5, 0.002))
fields = {{f: np.asarray(getattr(r, f)).tolist() for f in jaxgrasp.tolerance._result.FIELDS}}
print(json.dumps({{"stats": jaxgrasp.engine._store.stats(), "fields": fields}}))
"""

_SETUPS = {
    "store": "",  # what jaxgrasp's first use turns on: the executable store alone
    "both": "jaxgrasp.engine.enable_compilation_cache()",  # as the command does
    "xla": "jaxgrasp.engine.enable_compilation_cache(); jaxgrasp.engine._store.set_executable_dir(None)",
}
"""What a process turns on after ``import jaxgrasp``, before its first use, by name (:meth:`WarmCache.evaluate_in_new_process`)."""


@dataclasses.dataclass(frozen=True)
class WarmCache:
    """The cache of a user with a fresh home folder (``HOME``; no ``JAXGRASP_CACHE_DIR``,
    no ``XDG_CACHE_HOME``), filled by a library process that only imported jaxgrasp and
    evaluated the cube (``jaxgrasp.presets.cube(6e5, 0.002)``, = examples/cube.toml).

    Attributes:
        home: the home folder; the cache is :attr:`folder`, ``~/.cache/jaxgrasp/xla``.
        first: what that process printed: ``stats`` (:func:`jaxgrasp.engine._store.stats`),
            ``fields`` (every Evaluation field, as lists) and ``log`` (its stderr: logging
            at INFO level).
    """

    home: Path
    first: dict

    @property
    def folder(self) -> Path:
        return self.home / ".cache" / "jaxgrasp" / "xla"

    def run(self, argv: list[str]) -> subprocess.CompletedProcess:
        """Run ``argv`` in the repository as the user of :attr:`home`."""
        env = {k: v for k, v in os.environ.items() if k not in ("JAXGRASP_CACHE_DIR", "XDG_CACHE_HOME")}
        env["HOME"] = str(self.home)
        proc = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=TESTS_DIR.parent, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc

    def evaluate_in_new_process(self, setup: str = "store") -> dict:
        """A new library process evaluates the cube: its ``stats``, ``fields`` and ``log``.
        ``setup``: the caches it turns on after the import (:data:`_SETUPS`: ``"store"``,
        the import's default; ``"both"``; ``"xla"``, XLA's cache alone)."""
        proc = self.run([sys.executable, "-c", _FILL_CACHE.format(setup=_SETUPS[setup])])
        return json.loads(proc.stdout) | {"log": proc.stderr}

    def program_files(self) -> set[str]:
        """The stored evaluators' files: jaxgrasp's compiled programs and XLA's cache entries."""
        from jaxgrasp.engine._store import EXECUTABLE_SUBDIR

        stored = {f"{EXECUTABLE_SUBDIR}/{p.name}" for p in (self.folder / EXECUTABLE_SUBDIR).glob("evaluate-*")}
        return stored | {p.name for p in self.folder.glob("jit_evaluate_fields-*")}


@pytest.fixture(scope="session")
def warm_cache(tmp_path_factory) -> WarmCache:
    """:class:`WarmCache`: one cold library process (traces and compiles the cube, ~10 s
    on 2 cores) whose store later processes load.

    Its home is its own, not :func:`store_dir`: the first process must find no cache
    (``test_cache`` checks that it traced once, and created the folder), whichever tests
    ran before."""
    home = tmp_path_factory.mktemp("warm-home")
    return WarmCache(home, WarmCache(home, {}).evaluate_in_new_process())


# ----------------------------------------------------------------------------- slow tests
SLOW_FIXTURES = frozenset({"evaluate_many", "ipopt_reference", "warm_cache"})
"""Session fixtures that compile an evaluator per contact count, run Ipopt in a worker
process, or fill a cache folder in a cold process: a test that uses one is slow."""


LONG_MODULES = (  # ordered by each module's setups and calls together, measured in one run of the suite
    "tests/test_docs.py",
    "tests/tolerance/test_gradients.py",
    "tests/tolerance/test_evaluate.py",
    "tests/planning/test_hand_plan.py",
    "tests/tolerance/test_degenerate.py",
    "tests/cli/test_interrupts.py",
    "tests/solver/test_solver.py",
    "tests/planning/test_plan.py",
    "tests/tolerance/test_settle_real.py",
    "tests/engine/test_padding.py",
    "tests/tolerance/test_properties.py",
    "tests/hands/test_couplings.py",
    "tests/analysis/test_tune_mesh.py",
    "tests/engine/test_batch.py",
    "tests/cli/test_batch_processes.py",
    "tests/solver/test_dense.py",
    "tests/tolerance/test_starts.py",
    "tests/simulation/test_simulate.py",
)
"""The test modules that take longest (each pays its own compilations), longest first: xdist's
``loadfile`` hands whole modules to whichever worker is free in this order, so that the
last modules are short and neither worker waits long for the other at the end (the
``tolerance`` folder, collected last otherwise, holds three of them)."""


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects
def pytest_collection_modifyitems(config, items):
    """Mark ``slow`` every test that uses one of :data:`SLOW_FIXTURES`, directly or through
    another fixture (a module fixture's cost falls on whichever test uses it first)."""
    for item in items:
        if SLOW_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
    # Longest modules first (xdist's loadfile hands whole modules to whichever worker is
    # free, in this order): a long module collected last would run alone at the end.
    first = {name: k for k, name in enumerate(LONG_MODULES)}
    items.sort(key=lambda it: first.get(it.nodeid.split("::")[0], len(first)))
