"""Equality harness of issue 64: every output field of the batch, dataset, sweep, robust
and plan paths, recorded on one tree and compared with another.

Usage (run with the tree under test first on ``PYTHONPATH``)::

    python equality.py record OUTDIR            # one OUTDIR/<path>.npz per path, meta.json
    python equality.py record OUTDIR --only batch,plan
    python equality.py compare BASEDIR NEWDIR   # exit 1 on any difference beyond the bound

What ``record`` evaluates (the same construction, seeds and options on every tree):

* ``batch``: the batch benchmark's mixed set (``experiments/batch_benchmark/batch_benchmark.py``:
  ``make_grasps(1000, seed=0)``: ``tests/grasp_draws.py:build_grasp`` of
  ``np.random.default_rng(0)``, contact counts ``2 + i % 6``), default
  :class:`jaxgrasp.EvaluateOptions`, default chunk size, through ``evaluate_batch``;
* ``dataset``: the first 50 of those grasps written by ``save_dataset`` to a ``.jsonl``
  whose line 8 (row 7) is then made invalid (contact 0's friction -0.5), read by ``load_dataset``,
  evaluated by ``evaluate_dataset`` whole, then again resumed halfway (``done`` = the
  first 25 rows' results of the whole run), and by ``evaluate_batch`` of the set;
* ``sweep``: the paper's Fig. 6 grid that ``jaxgrasp sweep`` runs by default (cube preset,
  Young's modulus 2e5..1e6 Pa x 9, initial deformation 1..5 mm x 41);
* ``robust``: ``robust`` of the cube preset (64 samples) and ``robust_batch`` of grasps
  0, 1, 6, 7, 12 of the batch set (contact counts 2 and 3; 32 samples), one small
  :class:`jaxgrasp.Uncertainty` of every source;
* ``plan``: ``plan`` of ``examples/meshes/pybullet_000_mm.obj`` (mm, 2 fingers, 20
  samples, the docs' fingertip), with ``refine=0`` and with ``refine=1``.

Every result is walked whole (dataclass fields, dicts, sequences, arrays, numbers,
strings; a trimesh or other opaque object by its type name only) and stored flat as
``<group>/<field path>``; the public attribute names (``res.value``, ``res.status`` ...)
are also stored under ``<group>/pub.<name>`` so that a refactor that moves an internal
field still meets them. Wall-clock fields (``compile_seconds``, ``run_seconds``,
``elapsed_s``) are not compared (kept in ``meta.json`` with each path's record time).
The grasp inputs of the batch set are stored as ``batch/input.*`` so that a changed
generator shows up as an input difference, not as a result difference.

``compare`` prints, per path and field: ``identical`` (bit-identical, NaN where NaN), or
the max absolute and max relative difference (``|a - b| / max(|a|, |b|)``) and, for a
status field, how many entries differ. It fails (exit 1) when a status or any integer,
boolean or text field differs, when a float differs by more than ``REL_BOUND`` relative
(or has NaN / inf in other places), or when a field of the base is missing from the new
record (a ``tree`` field whose name moved is reported, and fails too unless
``--allow-moved``, in which case its ``pub.`` twin still has to match).
"""

from __future__ import annotations

import argparse
import dataclasses
import enum
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

REL_BOUND = 1e-9
"""Largest relative difference ``|a - b| / max(|a|, |b|)`` a float field may have."""

SKIP = {"compile_seconds", "run_seconds", "elapsed_s", "devices"}
"""Wall-clock fields and the device count (a layout, not a result: the results must not
depend on it, which is what is compared): recorded in the meta files, never compared."""

PATHS = ("batch", "dataset", "sweep", "robust", "plan")

BATCH_COUNT, BATCH_SEED = 1000, 0
DATASET_COUNT, DATASET_BAD_ROW, DATASET_RESUME_AT = 50, 7, 25


# --------------------------------------------------------------------------- names that may move


def find(*dotted):
    """The first of ``dotted`` names (``"jaxgrasp.engine.evaluate_dataset"``) that resolves."""
    import importlib

    for name in dotted:
        mod, _, attr = name.rpartition(".")
        try:
            obj = getattr(importlib.import_module(mod), attr)
        except (ImportError, AttributeError):
            continue
        return obj
    raise SystemExit(f"none of {', '.join(dotted)} exists in this tree")


def tree_root() -> Path:
    import jaxgrasp

    return Path(jaxgrasp.__file__).resolve().parent.parent


# --------------------------------------------------------------------------- flattening


def flatten(obj, prefix: str, out: dict, meta: dict, depth: int = 0) -> None:
    """Every leaf of ``obj`` into ``out`` as a NumPy array under ``prefix.path``."""
    name = prefix.rsplit(".", 1)[-1].rsplit("/", 1)[-1]
    if name in SKIP:
        meta[prefix] = None if obj is None else float(obj)
        return
    if depth > 12:
        out[prefix] = np.asarray(f"<too deep: {type(obj).__name__}>")
        return
    if obj is None:
        out[prefix] = np.asarray("<None>")
    elif isinstance(obj, enum.Enum):
        out[prefix] = np.asarray(int(obj.value) if isinstance(obj.value, (int, np.integer)) else str(obj.value))
    elif isinstance(obj, (str, bytes)):
        out[prefix] = np.asarray(obj)
    elif isinstance(obj, (bool, int, float, complex, np.generic)):
        out[prefix] = np.asarray(obj)
    elif isinstance(obj, (np.ndarray, jax.Array)):
        a = np.asarray(obj)
        if a.dtype == object:
            for i, x in enumerate(a.ravel().tolist()):
                flatten(x, f"{prefix}[{i}]", out, meta, depth + 1)
            out[prefix + ".shape"] = np.asarray(a.shape)
        else:
            out[prefix] = a
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            flatten(getattr(obj, f.name), f"{prefix}.{f.name}", out, meta, depth + 1)
    elif isinstance(obj, dict):
        for k in obj:
            flatten(obj[k], f"{prefix}.{k}", out, meta, depth + 1)
    elif isinstance(obj, (tuple, list)):
        out[prefix + ".len"] = np.asarray(len(obj))
        for i, x in enumerate(obj):
            flatten(x, f"{prefix}[{i}]", out, meta, depth + 1)
    else:  # a trimesh, a function: its type only (its numbers are the inputs' business)
        out[prefix] = np.asarray(f"<{type(obj).__module__}.{type(obj).__qualname__}>")


def public(obj, names, prefix: str, out: dict) -> None:
    """The attributes ``names`` of ``obj`` (what a user reads) under ``prefix/pub.NAME``."""
    for n in names:
        if n in SKIP:
            continue
        try:
            v = getattr(obj, n)
        except AttributeError:
            out[f"{prefix}/pub.{n}"] = np.asarray("<missing attribute>")
            continue
        if callable(v):
            v = v()
        sub: dict = {}
        flatten(v, f"{prefix}/pub.{n}", sub, {})
        out.update(sub)


def evaluation_fields() -> tuple[str, ...]:
    ev = find("jaxgrasp.Evaluation", "jaxgrasp.tolerance.Evaluation")
    return tuple(f.name for f in dataclasses.fields(ev))


def batch_record(res, prefix: str, out: dict, meta: dict) -> None:
    """A BatchResult: its public attributes and its whole tree."""
    public(res, (*evaluation_fields(), "num_contacts", "active", "errors", "devices"), prefix, out)
    flatten(res, f"{prefix}/tree", out, meta)


# --------------------------------------------------------------------------- the paths


def batch_grasps(count: int = BATCH_COUNT, seed: int = BATCH_SEED) -> list:
    """The batch benchmark's mixed set (its ``make_grasps``), from this tree's tests/."""
    tests = str(tree_root() / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)
    from grasp_draws import NumpyDraw, build_grasp

    rng = np.random.default_rng(seed)
    return [build_grasp(NumpyDraw(rng), n=2 + i % 6) for i in range(count)]


def path_batch(out: dict, meta: dict) -> None:
    grasps = batch_grasps()
    stack = find("jaxgrasp.stack", "jaxgrasp.model.stack")
    flatten(stack(grasps), "batch/input", out, meta)
    res = find("jaxgrasp.evaluate_batch", "jaxgrasp.engine.evaluate_batch")(grasps)
    batch_record(res, "batch", out, meta)


def path_dataset(out: dict, meta: dict) -> None:
    save_dataset = find("jaxgrasp.save_dataset", "jaxgrasp.io.save_dataset")
    load_dataset = find("jaxgrasp.load_dataset", "jaxgrasp.io.load_dataset")
    evaluate_dataset = find("jaxgrasp.engine.evaluate_dataset", "jaxgrasp.evaluate_dataset",
                            "jaxgrasp.io.evaluate_dataset")
    grasps = batch_grasps()[:DATASET_COUNT]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "set.jsonl"
        save_dataset(path, grasps)
        lines = path.read_text().splitlines()
        row = json.loads(lines[DATASET_BAD_ROW])
        row["contacts"][0]["friction"] = -0.5  # one invalid row: kept as a row, not evaluated
        lines[DATASET_BAD_ROW] = json.dumps(row)
        path.write_text("\n".join(lines) + "\n")
        gset = load_dataset(path)
    errors = getattr(gset, "errors", None)
    out["dataset/set.errors"] = np.asarray(["<None>" if e is None else str(e) for e in errors])
    full, run = evaluate_dataset(gset)
    batch_record(full, "dataset/whole", out, meta)
    batch_record(run, "dataset/whole_run", out, meta)
    invalid = int(find("jaxgrasp.GraspStatus", "jaxgrasp.tolerance.GraspStatus").INVALID)
    valid = np.flatnonzero(np.asarray(full.status) != invalid)
    rows = valid[valid < DATASET_RESUME_AT]
    done = (rows, {f: np.asarray(getattr(full, f))[rows] for f in evaluation_fields()})
    full2, run2 = evaluate_dataset(gset, done=done)
    batch_record(full2, "dataset/resumed", out, meta)
    batch_record(run2, "dataset/resumed_run", out, meta)
    evaluate_batch = find("jaxgrasp.evaluate_batch", "jaxgrasp.engine.evaluate_batch")
    batch_record(evaluate_batch(gset), "dataset/evaluate_batch", out, meta)


def cube():
    return find("jaxgrasp.presets.cube")()


def path_sweep(out: dict, meta: dict) -> None:
    # the CLI's decimal-exact ranges 2e5:1e6:9 and 1e-3:5e-3:41: integers times a power of ten
    young = np.array([k * 1e5 for k in range(2, 11)])
    deformation = np.array([k / 1e4 for k in range(10, 51)])
    sweep = find("jaxgrasp.sweep", "jaxgrasp.analysis.sweep")
    res = sweep(cube(), young_modulus=young, initial_deformation=deformation)
    public(res, ("value", "status", "limiting_kind", "limiting_contact", "equilibrium_energy", "shape",
                 "names", "devices"), "sweep", out)
    out["sweep/pub.axes.young_modulus"] = np.asarray(res.axes["young_modulus"])
    out["sweep/pub.axes.initial_deformation"] = np.asarray(res.axes["initial_deformation"])
    flatten(res, "sweep/tree", out, meta)


def uncertainty():
    Uncertainty = find("jaxgrasp.Uncertainty", "jaxgrasp.analysis.Uncertainty")
    return Uncertainty(friction=0.1, friction_per_fingertip=0.05, young_modulus=0.1, initial_deformation=2e-4,
                       position=1e-3, mass=0.1, gravity_angle=0.05)


ROBUST_FIELDS = ("status", "p_stable", "p_stable_stderr", "value_mean", "quantile_levels", "quantiles", "values",
                 "statuses", "converged", "clipped", "samples", "seed")


def path_robust(out: dict, meta: dict) -> None:
    robust = find("jaxgrasp.robust", "jaxgrasp.analysis.robust")
    robust_batch = find("jaxgrasp.robust_batch", "jaxgrasp.analysis.robust_batch")
    one = robust(cube(), uncertainty(), samples=64, seed=0)
    public(one, ROBUST_FIELDS, "robust/cube", out)
    public(one.nominal, evaluation_fields(), "robust/cube/nominal", out)
    flatten(one, "robust/cube/tree", out, meta)
    # grasps of two contact counts (2, 3, 2, 3, 2): two groups, few compilations
    many = robust_batch([batch_grasps()[i] for i in ROBUST_ROWS], uncertainty(), samples=32, seed=0)
    public(many, ROBUST_FIELDS, "robust/batch", out)
    batch_record(many.nominal, "robust/batch/nominal", out, meta)
    flatten(many, "robust/batch/tree", out, meta)


ROBUST_ROWS = (0, 1, 6, 7, 12)
"""Rows of the batch set that ``robust_batch`` evaluates (contact counts 2, 3, 2, 3, 2)."""

PLAN_FIELDS = ("status", "values", "statuses", "limiting_kind", "limiting_contact", "epsilon", "refined",
               "mesh_positions", "sampled", "valid", "rule_failures", "stable", "dropped", "refine_tried",
               "refine_kept", "seed")


def path_plan(out: dict, meta: dict) -> None:
    plan = find("jaxgrasp.plan", "jaxgrasp.planning.plan")
    mesh = tree_root() / "examples" / "meshes" / "pybullet_000_mm.obj"
    for refine in (0, 1):
        t0 = time.perf_counter()
        res = plan(str(mesh), 2, units="mm", radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0,
                            density=500.0, samples=20, refine=refine, seed=0)
        meta[f"plan/refine{refine}_s"] = time.perf_counter() - t0
        p = f"plan/refine{refine}"
        public(res, PLAN_FIELDS, p, out)
        for i, g in enumerate(res.grasps):  # each ranked grasp's model-frame fields
            flatten(g.grasp, f"{p}/pub.grasps[{i}].grasp", out, meta)
            out[f"{p}/pub.grasps[{i}].center_of_mass"] = np.asarray(g.center_of_mass)
        flatten(res, f"{p}/tree", out, meta)


RUNNERS = {"batch": path_batch, "dataset": path_dataset, "sweep": path_sweep, "robust": path_robust,
           "plan": path_plan}


# --------------------------------------------------------------------------- record


def record(outdir: Path, only) -> None:
    import jax

    import jaxgrasp

    # JAX's devices as every tree makes them by default: before issue 64 the import asked
    # for one CPU device per core; since, jaxgrasp.configure() (or the first use) does. The
    # count changes a chunk's per-device shape, and with it rounding.
    getattr(jaxgrasp, "configure", lambda: None)()
    outdir.mkdir(parents=True, exist_ok=True)
    meta = {"jaxgrasp_file": jaxgrasp.__file__, "jax": jax.__version__, "devices": len(jax.devices()),
            "backend": jax.default_backend(), "x64": bool(jax.config.jax_enable_x64),
            "load_start": os.getloadavg(), "env": {k: v for k, v in os.environ.items()
                                                    if k.startswith(("JAX", "XLA", "JAXGRASP"))},
            "paths": {}}
    try:
        import subprocess

        meta["commit"] = subprocess.run(["git", "-C", str(tree_root()), "rev-parse", "HEAD"], capture_output=True,
                                        text=True).stdout.strip()
    except OSError:
        pass
    for name in only:
        out: dict = {}
        pmeta: dict = {}
        t0 = time.perf_counter()
        RUNNERS[name](out, pmeta)
        seconds = time.perf_counter() - t0
        np.savez(outdir / f"{name}.npz", **{k: v for k, v in out.items()})
        pm = {"record_s": seconds, "fields": len(out), "load_end": os.getloadavg(), "timings": pmeta}
        meta["paths"][name] = pm
        print(f"{name}: {len(out)} fields, {seconds:.1f} s (load {os.getloadavg()[0]:.2f})", flush=True)
        # one meta file per path, so that records of different paths may run side by side
        (outdir / f"{name}.meta.json").write_text(json.dumps(dict(meta, paths={name: pm}), indent=1, default=str))


# --------------------------------------------------------------------------- compare


def is_status(key: str) -> bool:
    leaf = key.rsplit("/", 1)[-1]
    return "status" in leaf


def compare_field(a: np.ndarray, b: np.ndarray, rel_bound: float, status: bool = False) -> tuple[bool, str]:
    """``(ok, line)`` for one field."""
    if a.shape != b.shape:
        return False, f"SHAPE {a.shape} -> {b.shape}"
    if a.dtype.kind in "US" or b.dtype.kind in "US":
        if a.dtype.kind != b.dtype.kind:
            return False, f"KIND {a.dtype} -> {b.dtype}"
        n = int(np.sum(a != b))
        return n == 0, "identical" if n == 0 else f"TEXT {n} of {a.size} differ"
    if a.dtype.kind != b.dtype.kind and not {a.dtype.kind, b.dtype.kind} <= {"i", "u"}:
        return False, f"DTYPE {a.dtype} -> {b.dtype}"
    if a.dtype.kind in "fc":
        if a.tobytes() == b.tobytes() and a.dtype == b.dtype:
            return True, "identical"
        fa, fb = a.astype(np.float64), b.astype(np.float64)
        same_nan = np.array_equal(np.isnan(fa), np.isnan(fb))
        fin = np.isfinite(fa) & np.isfinite(fb)
        same_inf = np.array_equal(fa[~fin & ~np.isnan(fa)], fb[~fin & ~np.isnan(fb)]) and np.array_equal(
            np.isinf(fa), np.isinf(fb))
        d = np.abs(fa[fin] - fb[fin])
        scale = np.maximum(np.abs(fa[fin]), np.abs(fb[fin]))
        rel = np.where(d == 0, 0.0, d / np.where(scale == 0, 1.0, scale))
        n = int(np.sum(d != 0))
        mabs = float(d.max()) if d.size else 0.0
        mrel = float(rel.max()) if rel.size else 0.0
        ok = same_nan and same_inf and mrel <= rel_bound
        line = f"max abs {mabs:.3e}, max rel {mrel:.3e}, {n} of {a.size} entries differ"
        if not same_nan:
            line += f"; NaN in other places ({int(np.sum(np.isnan(fa) != np.isnan(fb)))})"
        if not same_inf:
            line += "; inf in other places"
        if a.dtype != b.dtype:
            line += f"; dtype {a.dtype} -> {b.dtype}"
        return ok, line
    n = int(np.sum(a != b))
    if n == 0:
        return True, "identical" if a.dtype == b.dtype else f"identical values, dtype {a.dtype} -> {b.dtype}"
    word = "STATUSES" if status else "VALUES"
    return False, f"{word}: {n} of {a.size} differ"



def compare(base: Path, new: Path, rel_bound: float, allow_moved: bool, verbose: bool) -> int:
    failed = 0
    files = sorted(p.name for p in base.glob("*.npz"))
    if not files:
        print(f"no records in {base}")
        return 1
    for fname in files:
        path = fname[:-4]
        if not (new / fname).exists():
            print(f"== {path}: MISSING in {new}")
            failed += 1
            continue
        a, b = np.load(base / fname), np.load(new / fname)
        ka, kb = set(a.files), set(b.files)
        fails, same, status_diff, lines = 0, 0, 0, []
        for k in sorted(ka):
            if k.rsplit("/", 1)[-1].rsplit(".", 1)[-1] in SKIP:  # a field a base record kept before SKIP grew
                continue
            if k not in kb:
                moved = "/tree" in k and allow_moved
                lines.append(f"  {k}: MISSING in new{' (tree field, allowed)' if moved else ''}")
                fails += not moved
                continue
            status = is_status(k)
            ok, line = compare_field(a[k], b[k], rel_bound, status)
            if line == "identical":
                same += 1
                if verbose:
                    lines.append(f"  {k}: identical")
                continue
            if status and a[k].shape == b[k].shape and a[k].dtype.kind in "iub":
                status_diff += int(np.sum(a[k] != b[k]))
            fails += not ok
            lines.append(f"  {k}: {'ok  ' if ok else 'FAIL'} {line}")
        for k in sorted(kb - ka):
            lines.append(f"  {k}: only in new (not compared)")
        print(f"== {path}: {len(ka)} fields, {same} identical, {fails} failing, "
              f"{status_diff} status entries differ")
        print("\n".join(lines))
        failed += fails
    for fname in files:
        path = fname[:-4]
        try:
            ma, mb = (json.loads((d / f"{path}.meta.json").read_text()) for d in (base, new))
        except (OSError, ValueError):
            continue
        print(f"   {path}: record {ma['paths'][path]['record_s']:.1f} s -> {mb['paths'][path]['record_s']:.1f} s; "
              + "; ".join(f"{k} {ma.get(k)} -> {mb.get(k)}" for k in ("devices", "x64", "commit", "jaxgrasp_file")
                          if ma.get(k) != mb.get(k) or k == "devices"))
    print(f"RESULT: {'FAIL' if failed else 'PASS'} ({failed} failing fields; bound {rel_bound:g} relative)")
    return 1 if failed else 0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="evaluate every path, write OUTDIR/<path>.npz and meta.json")
    r.add_argument("outdir", type=Path)
    r.add_argument("--only", default=",".join(PATHS), help=f"comma list of paths (default {','.join(PATHS)})")
    c = sub.add_parser("compare", help="compare two records; exit 1 on any difference beyond the bound")
    c.add_argument("base", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--rel", type=float, default=REL_BOUND, help=f"relative bound for floats (default {REL_BOUND:g})")
    c.add_argument("--allow-moved", action="store_true", help="a tree field missing in new is reported, not failed")
    c.add_argument("-v", "--verbose", action="store_true", help="also list identical fields")
    args = p.parse_args()
    if args.cmd == "record":
        only = [s.strip() for s in args.only.split(",") if s.strip()]
        bad = [s for s in only if s not in RUNNERS]
        if bad:
            raise SystemExit(f"unknown path(s) {bad}; choose from {PATHS}")
        record(args.outdir, only)
    else:
        sys.exit(compare(args.base, args.new, args.rel, args.allow_moved, args.verbose))


if __name__ == "__main__":
    main()
