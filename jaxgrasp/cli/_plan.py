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
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from jaxgrasp.cli._common import UsageError, check_out, lock_out, parse_number, replaced_text, say
from jaxgrasp import storage

__all__ = ["add_parser", "run", "RESULT_COLUMNS", "DEFAULTS"]

RESULT_COLUMNS = ("rank", "value_J", "status", "limiting_kind", "limiting_contact", "epsilon", "refined")
"""The columns of ``results.csv``; with ``--rank robust`` also `ROBUST_COLUMNS`."""

ROBUST_COLUMNS = ("p_stable", "value_mean_J", "value_q05_J")
"""The robust columns of ``results.csv`` (``--rank robust``)."""

DEFAULT_ROBUST = "friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3"
"""The uncertainty ``--rank robust`` assumes without ``--robust SPEC``."""

DEFAULTS = dict(fingers=2, radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0, density=500.0)
"""Defaults of the command's fingertip and object options (SI units): a 10 mm silicone-like
fingertip on a light plastic-like object."""


def add_parser(sub) -> None:
    """Add the ``plan`` command to the ``jaxgrasp`` sub-parsers."""
    from jaxgrasp.planning import SAMPLERS

    sp = sub.add_parser(
        "plan",
        help="find the best grasps on a meshed object; write them ranked, the best's file and picture",
        description=(
            "Draw candidate grasps on the object's mesh, keep those the model describes (flat contact "
            "patch, fingertips apart, one contact each, deformation in range), evaluate them, refine the "
            "best by gradient tuning along the surface, and write them ranked into --out."
        ),
        epilog="Example: jaxgrasp plan part.obj --units mm --fingers 3 --out plan-part",
    )
    d = DEFAULTS
    sp.add_argument("mesh", help="the object's mesh file (STL, OBJ, PLY, OFF or GLB)")
    sp.add_argument("--fingers", type=int, default=d["fingers"], metavar="N", help="fingertips, 2 to 8 (default 2)")
    sp.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="the mesh's length unit (default m)")
    for opt, key, unit in (("--radius", "radius", "m"), ("--young-modulus", "young_modulus", "Pa"),
                           ("--friction", "friction", ""), ("--max-force", "max_force", "N")):
        sp.add_argument(opt, dest=key, type=float, default=d[key], metavar=unit.upper() or "MU",
                        help=f"every fingertip's {key.replace('_', ' ')}" + (f", {unit}" if unit else "")
                        + f" (default {d[key]:g})")
    mass = sp.add_mutually_exclusive_group()
    mass.add_argument("--density", type=float, default=None, metavar="KG_M3",
                      help=f"object density, kg/m^3; mass = density x volume (default {d['density']:g})")
    mass.add_argument("--mass", type=float, default=None, metavar="KG", help="object mass, kg")
    sp.add_argument("--gravity", default="0,0,-9.81", metavar="GX,GY,GZ",
                    help="gravity in the mesh's axes, m/s^2 (default 0,0,-9.81)")
    sp.add_argument("--samples", type=int, default=150, metavar="N", help="valid candidates to evaluate (default 150)")
    sp.add_argument("--top", type=int, default=10, metavar="K", help="ranked grasps to write (default 10)")
    sp.add_argument("--refine", type=int, default=3, metavar="K", help="best candidates to tune (default 3)")
    sp.add_argument("--seed", type=int, default=0, help="seed of the random draws (default 0)")
    sp.add_argument("--sampler", choices=SAMPLERS, default=None,
                    help="candidate generator (default antipodal for 2 fingers, spread for more)")
    sp.add_argument("--flatness", type=float, default=25.0, metavar="DEG",
                    help="largest angle between the contact normal and a face under the fingertip (default 25)")
    sp.add_argument("--rank", choices=("value", "robust"), default="value",
                    help="rank by the value, or by the robust value (the mean over perturbed copies) (default value)")
    sp.add_argument("--robust", default=None, metavar="SPEC",
                    help=f"the uncertainty of --rank robust, as for evaluate --robust (default {DEFAULT_ROBUST})")
    sp.add_argument("--robust-samples", type=int, default=64, metavar="S",
                    help="perturbed copies per ranked grasp for --rank robust (default 64)")
    sp.add_argument("--out", default="plan", metavar="DIR", help="output folder (default ./plan)")
    sp.add_argument("--no-plot", action="store_true", help="do not write best.png")
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")
    sp.set_defaults(func=run)


def run(args) -> int:
    """Check every option and the mesh (`jaxgrasp.planning._plan.check_plan`), then
    create and lock ``--out``, plan, write the set, print one summary line."""
    from jaxgrasp.planning import PlanProgress, check_plan, plan

    out = Path(args.out)
    check_out(out)
    kwargs = _plan_options(args)
    check_plan(args.mesh, args.fingers, **kwargs)  # bad input: one line, nothing created or printed
    if not args.quiet:
        say(f"jaxgrasp: plan {args.mesh}: {args.samples} valid {args.fingers}-finger candidates to find and "
            "evaluate, the best refined; compiling (or loading from the cache) first")
    with lock_out(out):
        t0 = time.perf_counter()
        res = plan(args.mesh, args.fingers, progress=PlanProgress(t0, show=not args.quiet), **kwargs)
        written, replaced = _write(res, out, args)
    print(f"plan {args.mesh}: {res.summary()}; wrote {out}/{{{','.join(written)}}}" + replaced_text(replaced, ()))
    return 0


def _plan_options(args) -> dict:
    """The keyword arguments of [`jaxgrasp.plan`][jaxgrasp.plan] (mesh and fingers aside), the options
    that are the command's own checked."""
    from jaxgrasp.surface import ContactRules

    return dict(samples=args.samples, top=args.top, refine=args.refine, seed=args.seed,
                rules=ContactRules(flatness_deg=args.flatness), sampler=args.sampler,
                **_object_options(args), **_robust_options(args))


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


def _object_options(args) -> dict:
    """The fingertip and object keyword arguments of [`jaxgrasp.plan`][jaxgrasp.plan], checked."""
    parts = args.gravity.split(",")
    if len(parts) != 3:
        raise UsageError(f"--gravity {args.gravity!r}: give three numbers GX,GY,GZ in m/s^2")
    gravity = [parse_number("--gravity", p, "component") for p in parts]
    for name in ("radius", "young_modulus", "friction", "max_force", "density", "mass"):
        v = getattr(args, name)
        zero = name in ("density", "mass")  # 0: a weightless object (the model's default mass), honoured
        if v is not None and not (math.isfinite(v) and (v > 0 or (zero and v == 0))):
            raise UsageError(f"--{name.replace('_', '-')} must be a finite number {'>=' if zero else '>'} 0, got {v:g}")
    if args.mass is not None:
        mass = dict(mass=args.mass)
    else:
        mass = dict(density=DEFAULTS["density"] if args.density is None else args.density)
    return dict(radius=args.radius, young_modulus=args.young_modulus, friction=args.friction,
                max_force=args.max_force, gravity=gravity, units=args.units, **mass)


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
