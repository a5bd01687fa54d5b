"""Shared helpers of the studies in ``experiments/`` (each study is a folder beside this one).

A study's script finds this package by putting ``experiments/`` on ``sys.path`` (the two
lines at the top of every script) and imports what it needs from here:

* :func:`say`, :func:`agreement`, :func:`agreement_numbers`: log lines with the load
  average, and two runs of the same grasps compared;
* :func:`parse_args`, :class:`Progress`, :func:`finding`, :func:`timings`,
  :func:`write_rows`, :func:`refine_interval`, :func:`force_limit_deformation`: the
  figure scripts' options and outputs (a study writes into its own folder; ``--quick``
  into ``<study>/quick/``, so the full-size outputs are not overwritten);
* :func:`reuse`: a script that builds on another study's code (the 1000-grasp set of
  ``batch_benchmark``, say) names that study, and its folder goes on ``sys.path``;
* ``_lab.grasp_draws``, ``_lab.ipopt_reference``: the test suite's seeded random grasps
  and its independent CasADi + Ipopt reference solver, loaded from ``tests/`` (shared
  with the tests so that experiments measure what the tests check; the Ipopt reference
  does not use jaxgrasp at all), and :func:`stack_same` / :func:`unstack`;
* :func:`module_of`: for the few instruments that replace a global of the module that
  defines a public function (no public hook reports what they count).

Everything from ``jaxgrasp`` is imported from its public faces (``jaxgrasp``,
``jaxgrasp.<package>``), never from a private module.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parent.parent
"""The ``experiments/`` folder: one folder per study."""
ROOT = EXPERIMENTS.parent
"""The repository's root."""
TESTS = ROOT / "tests"


def reuse(*studies: str) -> None:
    """Put the folders of other studies on ``sys.path`` so that their scripts import as
    modules (``reuse("batch_benchmark")``, then ``from batch_benchmark import make_grasps``)."""
    for study in studies:
        folder = EXPERIMENTS / study
        if not folder.is_dir():
            raise FileNotFoundError(f"no study {study!r} in {EXPERIMENTS}")
        if str(folder) not in sys.path:
            sys.path.insert(0, str(folder))


def _from_tests(name: str, as_name: str):
    """Run ``tests/<name>.py`` as the module ``as_name`` (in ``sys.modules`` under that name,
    so that worker processes, which import ``_lab``'s modules by name, unpickle its objects)."""
    spec = importlib.util.spec_from_file_location(as_name, TESTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[as_name] = module
    spec.loader.exec_module(module)
    return module


def stack_same(grasps):
    """Stack same-``N`` grasps into one batched grasp along a new leading axis (no mask
    added: unlike ``jaxgrasp.model.stack``, which pads to a common ``N``)."""
    import jax
    import jax.numpy as jnp

    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *grasps)


def unstack(tree, i: int):
    """Element ``i`` of a batched pytree."""
    import jax

    return jax.tree_util.tree_map(lambda a: a[i], tree)


def say(msg: str) -> None:
    """One log line with the time and the 1-minute load average (timings are read against it)."""
    print(f"[{time.strftime('%H:%M:%S')} load {os.getloadavg()[0]:.2f}] {msg}", flush=True)


def agreement_numbers(status, value, ref_status, ref_value) -> dict:
    """Two runs of the same grasps compared: ``status_mismatches``, ``finite_mismatches``
    (finite against NaN values) and ``value_max_rel_diff`` (the largest relative
    difference of the values finite in both, relative to the reference)."""
    status, value, ref_status, ref_value = (np.asarray(a) for a in (status, value, ref_status, ref_value))
    both = np.isfinite(value) & np.isfinite(ref_value)
    rel = np.abs(value - ref_value)[both] / np.maximum(np.abs(ref_value[both]), 1e-300)
    return {"status_mismatches": int(np.sum(status != ref_status)),
            "finite_mismatches": int(np.sum(np.isfinite(value) != np.isfinite(ref_value))),
            "value_max_rel_diff": float(rel.max()) if rel.size else 0.0}


def agreement(status, value, ref_status, ref_value) -> str:
    """:func:`agreement_numbers` as one line."""
    a = agreement_numbers(status, value, ref_status, ref_value)
    return (f"statuses differing {a['status_mismatches']}, finite/NaN differing {a['finite_mismatches']}, "
            f"largest relative value difference {a['value_max_rel_diff']:.1e}")


def parse_args(description: str, study: str | Path) -> argparse.Namespace:
    """The figure scripts' options; ``study`` is the script's ``__file__`` (its folder is
    the default output folder)."""
    folder = Path(study).resolve().parent
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="small grid (minutes), written to <study>/quick/")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: the study's folder)")
    args = p.parse_args()
    if args.out is None:
        args.out = folder / "quick" if args.quick else folder
    args.out.mkdir(parents=True, exist_ok=True)
    # reuse compilations across runs (same cache as the jaxgrasp command)
    import jaxgrasp

    jaxgrasp.engine.enable_compilation_cache()
    return args


class Progress:
    """A ``progress(done, total)`` callback printing chunk progress on stderr."""

    def __init__(self, label: str):
        self.label = label
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        el = time.perf_counter() - self.t0
        print(f"  [{self.label}] {done}/{total} points, {el:.1f} s", file=sys.stderr, flush=True)


def force_limit_deformation(young_modulus: float, max_force: float) -> float:
    """Initial deformation at which the initial normal force ``pi E dr^2`` reaches ``f_max``, m."""
    return math.sqrt(max_force / (math.pi * young_modulus))


def write_rows(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in r])


def finding(text: str, ok: bool) -> bool:
    print(f"FINDING [{'holds' if ok else 'DOES NOT HOLD'}]: {text}", flush=True)
    return ok


def timings(label: str, t_wall: float, compile_s: float, run_s: float) -> None:
    print(
        f"TIMING {label}: wall {t_wall:.1f} s (compile {compile_s:.1f} s, evaluation {run_s:.1f} s)",
        flush=True,
    )


def refine_interval(grid: np.ndarray, k: int) -> tuple[float, float]:
    """The interval between the neighbours of grid point ``k`` (for a second, finer pass)."""
    lo = grid[max(k - 1, 0)]
    hi = grid[min(k + 1, len(grid) - 1)]
    return float(lo), float(hi)


def module_of(public):
    """The module that defines a public jaxgrasp function, for an instrument that replaces
    one of that module's globals at run time (``solver_steps/queue_steps.py`` counts the
    work queue's loop steps this way: no public hook reports them)."""
    return sys.modules[public.__module__]
