"""``jaxgrasp plan MESH --fingers N --out DIR``: the best grasps of a meshed object.

Checks every option and the mesh first (`jaxgrasp.planning._plan.check_plan`, the
check [`jaxgrasp.plan`][jaxgrasp.plan] makes), so that bad input creates nothing; then runs
[`jaxgrasp.plan`][jaxgrasp.plan] and writes, as one set into ``DIR`` (checked writable and locked
before any computation, `jaxgrasp.storage.write_set`):

* ``ranked.jsonl``: the ranked grasps, best first, one grasp file (JSON) per line naming the
  mesh (a dataset: ``jaxgrasp batch DIR/ranked.jsonl`` evaluates it);
* ``best.toml``: the best grasp's file (``jaxgrasp evaluate DIR/best.toml`` gives the value
  of ``results.csv``'s first row);
* ``results.csv``: rank, value, status, limiting boundary, epsilon, whether tuning refined it
  (with ``--rank robust``: the probability of being stable, the mean value and its lower
  quantile over perturbed copies, the ranking's key);
* ``best.png``: the ``jaxgrasp show`` picture of the best grasp;
* the mesh file itself, unless it is in ``DIR`` already, so that ``DIR`` holds all the files name.

With ``--hand HAND --fingertips A,B,C`` the plan is a hand's (`jaxgrasp.cli._plan_hand`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from jaxgrasp.cli._arguments import DEFAULT_ROBUST, PLAN_DEFAULTS, plan_fields
from jaxgrasp.cli._common import UsageError, check_out, lock_out, replaced_text, say
from jaxgrasp import storage

__all__ = ["run", "RESULT_COLUMNS", "FREE_DEFAULTS"]

RESULT_COLUMNS = ("rank", "value_J", "status", "limiting_kind", "limiting_contact", "epsilon", "refined")
"""The columns of ``results.csv``; with ``--rank robust`` also `ROBUST_COLUMNS`."""

FREE_DEFAULTS = {"samples": 150, "flatness": 25.0}
"""Defaults of ``--samples`` and ``--flatness`` for free fingertips (without ``--hand``)."""

ROBUST_COLUMNS = ("p_stable", "value_mean_J", "value_q05_J")
"""The robust columns of ``results.csv`` (``--rank robust``)."""


def run(args) -> int:
    """Check every option and the mesh (`jaxgrasp.planning._plan.check_plan`), then
    create and lock ``--out``, plan, write the set, print one summary line."""
    if args.hand is not None:
        from jaxgrasp.cli._plan_hand import run_hand

        return run_hand(args)
    from jaxgrasp.planning import PlanProgress, check_plan, plan

    out = Path(args.out)
    for option in ("--fingertips", "--min-fingertips", "--objective", "--max-penetration"):
        if getattr(args, option[2:].replace("-", "_")) is not None:
            raise UsageError(f"{option}: for a plan with a hand; add --hand HAND or drop it")
    check_out(out)
    fingers = PLAN_DEFAULTS["fingers"] if args.fingers is None else args.fingers
    kwargs = _plan_options(args)
    check_plan(args.mesh, fingers, **kwargs)  # bad input: one line, nothing created or printed
    if not args.quiet:
        say(f"jaxgrasp: plan {args.mesh}: {kwargs['samples']} valid {fingers}-finger candidates to find and "
            "evaluate, the best refined; compiling (or loading from the cache) first")
    with lock_out(out):
        t0 = time.perf_counter()
        res = plan(args.mesh, fingers, progress=PlanProgress(t0, show=not args.quiet), **kwargs)
        written, replaced = _write(res, out, args)
    print(f"plan {args.mesh}: {res.summary()}; wrote {out}/{{{','.join(written)}}}" + replaced_text(replaced, ()))
    return 0


def _plan_options(args) -> dict:
    """The keyword arguments of [`jaxgrasp.plan`][jaxgrasp.plan] (mesh and fingers aside), the options
    that are the command's own checked."""
    from jaxgrasp.surface import ContactRules

    flatness = FREE_DEFAULTS["flatness"] if args.flatness is None else args.flatness
    samples = FREE_DEFAULTS["samples"] if args.samples is None else args.samples
    fields = plan_fields(args)
    if fields["radius"] is None:
        fields["radius"] = PLAN_DEFAULTS["radius"]
    return dict(samples=samples, top=args.top, refine=args.refine, seed=args.seed,
                rules=ContactRules(flatness_deg=flatness), sampler=args.sampler, **fields, **_robust_options(args))


def _robust_options(args) -> dict:
    """``robust`` and ``robust_samples`` of [`jaxgrasp.plan`][jaxgrasp.plan] (empty for ``--rank value``)."""
    from jaxgrasp.analysis import parse_spec

    if args.rank == "value":
        if args.robust is not None:
            raise UsageError("--robust SPEC is for --rank robust; add --rank robust or drop it")
        return {}
    if args.robust_samples < 2:
        raise UsageError(f"--robust-samples must be >= 2, got {args.robust_samples}")
    return dict(robust=parse_spec(args.robust or DEFAULT_ROBUST), robust_samples=args.robust_samples)


def _write(res, out: Path, args) -> tuple[list[str], list[str]]:
    """Write the set into ``out``; the names written and those that replaced previous files."""
    from jaxgrasp.io import dict_to_toml, mesh_grasp_to_dict, mesh_reference

    if not res.grasps:
        raise UsageError(f"plan {args.mesh}: {res.status.message}; nothing written")
    name, raw = mesh_reference(res.best, out, copy=True)
    columns = RESULT_COLUMNS + (ROBUST_COLUMNS if res.robust is not None else ())
    # the mesh-frame points each grasp was made from: each file loads to the grasp evaluated
    files = [mesh_grasp_to_dict(g, name, p) for g, p in zip(res.grasps, res.mesh_positions)]
    members = {
        out / "ranked.jsonl": "".join(json.dumps(d) + "\n" for d in files).encode("utf-8"),
        out / "best.toml": dict_to_toml(files[0]).encode("utf-8"),
        out / "results.csv": storage.csv_content(columns, ([r[c] for c in columns] for r in res.rows())),
    }
    if raw is not None:
        members[out / name] = raw
    if not args.no_plot:
        members[out / "best.png"] = _picture(res)
    try:
        replaced = storage.write_set(members)
    except OSError as exc:
        raise UsageError(f"cannot write to --out {str(out)!r}: {exc.strerror or exc}") from None
    return [p.name for p in members], [p.name for p in replaced]


def _picture(res):
    """``write(fh)`` of the best grasp's ``show`` picture."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.plots import draw_scene, grasp_scene, save_figure

    fig = draw_scene(grasp_scene(res.best, evaluate(res.best.grasp)))
    return lambda fh: save_figure(fig, fh, format="png")
