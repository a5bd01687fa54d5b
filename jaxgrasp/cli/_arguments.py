"""The ``jaxgrasp`` command's arguments: every sub-command's options, help and argument
checks, without JAX.

`jaxgrasp.cli.build_parser` adds the sub-commands of `COMMANDS` with `add_commands`;
`jaxgrasp.cli.main` parses the command line with it before the library (and JAX) is
loaded, so that ``--help``, ``--version`` and every argument error (an unknown option, a
missing value, an invalid choice, a value ``type=`` rejects) are answered at once. This
module imports Python's standard library and jaxgrasp's constants alone (the grasp fields,
the presets' names, the samplers, the optimisers, the limits: each package face loads
them from a module without JAX, `jaxgrasp._startup.attach`); the commands' modules
``jaxgrasp.cli._<name>`` hold their ``run(args)``.
"""

from __future__ import annotations

import argparse
import math

from jaxgrasp.analysis import (
    MAX_GRID_POINTS,
    MAX_ROBUST_SAMPLES,
    MAX_TUNE_ITERATIONS,
    METHODS,
    ROBUST_SAMPLES_WHAT,
    TUNE_ITERATIONS_WHAT,
)
from jaxgrasp.base import over_limit, whole_number
from jaxgrasp.cli._parser import UsageError
from jaxgrasp.engine import CHUNK_SIZE_WHAT, MAX_CHUNK_SIZE
from jaxgrasp.model import FIELD, SWEEPABLE, TUNABLE
from jaxgrasp.planning import (
    MAX_FINGERS,
    MAX_PLAN_REFINE,
    MAX_PLAN_SAMPLES,
    PLAN_REFINE_WHAT,
    PLAN_SAMPLES_WHAT,
    SAMPLERS,
)
from jaxgrasp.presets import PRESETS
from jaxgrasp.simulation import MAX_KICK_SCALE, MAX_SIMULATED_S, MAX_STEPS, TIMESTEP_FRACTION

__all__ = [
    "COMMANDS",
    "add_commands",
    "parse_number",
    "OVERRIDES",
    "add_grasp_source",
    "add_allow_dir",
    "add_overrides",
    "Count",
    "add_chunk_size",
    "add_epsilon_option",
    "add_robust_options",
    "DEFAULT_ROBUST_SAMPLES",
    "add_process_options",
    "axis_spec",
    "PAPER_AXES",
    "DEFAULT_TOP",
    "MAX_TOP",
    "DEFAULT_ROBUST",
    "PLAN_DEFAULTS",
    "plan_fields",
    "MAGNIFICATION_RANGE",
]

COMMANDS = {
    "evaluate": "evaluate one grasp and print a summary",
    "sweep": "evaluate a grasp over a grid of parameters (npz, csv, png)",
    "batch": "evaluate and rank every grasp of a dataset file (csv, npz, png)",
    "tune": "maximise the value over chosen parameters; write the tuned grasp and a plot",
    "plan": "find the best grasps on a meshed object; write them ranked, the best's file and picture",
    "show": "draw one grasp in 3-D with the motion that makes it fail (png; --glb for a 3-D viewer)",
    "simulate": "hold, disturb and kick the grasp in MuJoCo (needs jaxgrasp[sim]); results.json and a plot",
}
"""The sub-commands, in the order of ``jaxgrasp --help``, each with its line there; each
runs ``jaxgrasp.cli._<name>.run(args)``."""


def add_commands(sub) -> None:
    """Add every sub-command of `COMMANDS`, in its order, to the ``jaxgrasp`` sub-parsers ``sub``."""
    adders = {"evaluate": add_evaluate, "sweep": add_sweep, "batch": add_batch, "tune": add_tune,
              "plan": add_plan, "show": add_show, "simulate": add_simulate}
    for name in COMMANDS:
        adders[name](sub)


# --------------------------------------------------------------------------- shared arguments

OVERRIDES = SWEEPABLE
"""Fields one number sets for the whole grasp (every contact at once), in option order:
``jaxgrasp evaluate --young-modulus PA ...`` and the sweep's axes."""


def parse_number(option: str, text: str, what: str = "value") -> float:
    """``text`` as a finite float; a `UsageError` naming ``option`` otherwise."""
    t = text.strip()
    try:
        x = float(t)
    except ValueError:
        raise UsageError(f"{option}: {what} {t!r} is not a number") from None
    if not math.isfinite(x):
        raise UsageError(f"{option}: {what} {t!r} must be finite")
    return x


class Count:
    """The ``type`` of a count option (``--samples``, ``--chunk-size``, ...): a whole number,
    also written as a float (``1e5``), at most ``limit`` where one is given; otherwise a
    one-line error naming the option (and its cap), as argparse reads it, before anything
    is loaded. Lower bounds are the commands' own checks."""

    __name__ = "int"  # argparse's "invalid int value: 'x'" for what is not a whole number

    def __init__(self, option: str, limit: int | None = None, what: str = ""):
        self.option, self.limit, self.what = option, limit, what

    def __call__(self, text: str) -> int:
        n = whole_number(text)
        if n is None:
            raise ValueError(text)
        problem = None if self.limit is None else over_limit(self.option, n, self.limit, self.what)
        if problem:
            raise UsageError(problem)
        return n


def add_chunk_size(p: argparse.ArgumentParser, help: str) -> None:
    """``--chunk-size N``: grasps per compiled batch, at most `MAX_CHUNK_SIZE`."""
    p.add_argument("--chunk-size", type=Count("--chunk-size", MAX_CHUNK_SIZE, CHUNK_SIZE_WHAT), default=None,
                   metavar="N", help=f"{help}; at most {MAX_CHUNK_SIZE:,}")


def add_grasp_source(p: argparse.ArgumentParser) -> None:
    """The grasp to use: a positional ``file`` or ``--preset NAME``; ``--allow-dir``."""
    p.add_argument("file", nargs="?", help="grasp file (.toml or .json, SI units)")
    p.add_argument("--preset", choices=list(PRESETS), help="one of the paper's grasps instead of a file")
    add_allow_dir(p)


def add_allow_dir(p: argparse.ArgumentParser) -> None:
    """``--allow-dir DIR`` (repeatable): a folder outside the input file's own that the
    meshes it names, and a hand file's includes and assets, may be in
    (`jaxgrasp.io._inputs.confine`)."""
    p.add_argument(
        "--allow-dir", action="append", default=None, metavar="DIR", dest="allow_dir",
        help=("also read meshes (and a hand file's includes and assets) the input file names "
              "from DIR (repeatable); by default only files inside the input file's own folder "
              "are read"),
    )


def add_overrides(p: argparse.ArgumentParser) -> None:
    """``--young-modulus PA`` etc.: one number for a field of the whole grasp (`OVERRIDES`)."""
    for name in OVERRIDES:
        field = FIELD[name]
        p.add_argument(field.option, dest=name, type=float, metavar=field.metavar, help=field.help)


def add_epsilon_option(p: argparse.ArgumentParser) -> None:
    """``--epsilon``: add the Ferrari-Canny metric's columns to a command's tables."""
    p.add_argument(
        "--epsilon",
        action="store_true",
        help="add columns epsilon and force_closure (Ferrari-Canny metric, 8 cone edges, soft fingers)",
    )


DEFAULT_ROBUST_SAMPLES = 256
"""Perturbed copies per grasp of ``--robust`` (``--samples``)."""


def add_robust_options(p: argparse.ArgumentParser) -> None:
    """``--robust SPEC``, ``--samples N`` and ``--seed N``: the robust value under uncertainty
    ([`jaxgrasp.robust`][jaxgrasp.robust])."""
    p.add_argument(
        "--robust", metavar="SPEC", default=None,
        help=("also evaluate SAMPLES perturbed copies of each grasp; SPEC gives each source's spread "
              "in SI units, e.g. friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3 "
              "(also friction_per_fingertip, mass, gravity_angle; see jaxgrasp.analysis.Uncertainty)"),
    )
    p.add_argument("--samples", type=Count("--samples", MAX_ROBUST_SAMPLES, ROBUST_SAMPLES_WHAT),
                   default=DEFAULT_ROBUST_SAMPLES, metavar="N",
                   help=(f"perturbed copies per grasp with --robust, 2 to {MAX_ROBUST_SAMPLES:,} "
                         f"(default {DEFAULT_ROBUST_SAMPLES})"))
    p.add_argument("--seed", type=int, default=0, metavar="N", help="seed of the --robust draws (default 0)")


def add_process_options(sp) -> None:
    """Add ``--coordinator``, ``--num-processes`` and ``--process-id`` to ``sp`` (a batch over
    several processes, `jaxgrasp.cli._batch_processes`)."""
    g = sp.add_argument_group(
        "several processes",
        "run one process per host, each with the same command and its own --process-id; "
        "each evaluates its share of the dataset and process 0 writes DIR (no --resume)",
    )
    g.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address, which every process reaches")
    g.add_argument("--num-processes", type=int, metavar="P", help="how many processes run the batch")
    g.add_argument("--process-id", type=int, metavar="I", help="this process's index, 0 .. P-1")


# --------------------------------------------------------------------------- sweep axes

PAPER_AXES = {
    "young_modulus": "2e5:1e6:9",
    "initial_deformation": "1e-3:5e-3:41",
}
"""The grid of the paper's Fig. 6 (``jaxgrasp sweep`` without any axis)."""


def axis_spec(option: str, spec: str) -> list[float] | tuple[str, str, int]:
    """A sweep axis spec checked: a list or number as its floats; a range
    ``START:STOP:COUNT`` as its ``(start, stop, count)`` text and count, not yet expanded
    (`jaxgrasp.cli._sweep.parse_axis_spec` expands it).

    Raises:
        UsageError: malformed spec, or a range of more than `MAX_GRID_POINTS` (one
            line, naming the option), before the array is allocated.
    """
    text = spec.strip()
    if not text:
        raise UsageError(f"{option}: empty value; give START:STOP:COUNT, a comma list or a number")
    if ":" in text:
        return _axis_range(option, spec, text)
    items = text.split(",")
    if any(not s.strip() for s in items):
        raise UsageError(f"{option}: list {spec!r} has an empty item")
    return [parse_number(option, s) for s in items]


def _axis_range(option: str, spec: str, text: str) -> tuple[str, str, int]:
    parts = text.split(":")
    if len(parts) != 3:
        raise UsageError(f"{option}: range {spec!r} must be START:STOP:COUNT (e.g. 1e-3:5e-3:41)")
    start = parse_number(option, parts[0], "start")
    stop = parse_number(option, parts[1], "stop")
    c = parts[2].strip()
    try:
        count = int(c)
    except ValueError:
        raise UsageError(f"{option}: count {c!r} of range {spec!r} must be a whole number") from None
    if count < 1:
        raise UsageError(f"{option}: range {spec!r} is empty (count {count}); the count must be >= 1")
    if count == 1 and start != stop:
        raise UsageError(f"{option}: range {spec!r} has count 1 but start != stop; give a single number")
    if count > MAX_GRID_POINTS:
        raise UsageError(f"{option}: range {spec!r} has {count:,} points, more than a whole grid may have "
                         f"({MAX_GRID_POINTS:,}); split the sweep")
    return parts[0].strip(), parts[1].strip(), count


class _AxisSpec:
    """The ``type`` of a sweep axis option: its spec checked (`axis_spec`) as argparse reads
    it, kept as typed (the sweep expands it)."""

    def __init__(self, option: str):
        self.option = option

    def __call__(self, text: str) -> str:
        axis_spec(self.option, text)  # a UsageError is the command's one line
        return text


class _AxisInOrder(argparse.Action):
    """Store an axis spec and remember the order the axes were given in (``args.axis_order``):
    the grid's axes follow it, as the library's keyword order."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        order = [n for n in getattr(namespace, "axis_order", None) or [] if n != self.dest]
        namespace.axis_order = order + [self.dest]


# --------------------------------------------------------------------------- the sub-commands

DEFAULT_TOP = 5
"""Best grasps listed in the summary of ``jaxgrasp batch`` (``--top``)."""

MAX_TOP = 1_000
"""The most best grasps ``jaxgrasp batch --top`` lists and labels in its picture: each is a
line of the summary and a label of ``results.png``, and matplotlib places every label, so a
``--top`` as large as a dataset of 100,000 grasps would hold up the picture; the full
ranking is in ``results.csv``."""

DEFAULT_ROBUST = "friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3"
"""The uncertainty ``jaxgrasp plan --rank robust`` assumes without ``--robust SPEC``."""

PLAN_DEFAULTS = dict(fingers=2, radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0, density=500.0)
"""Defaults of ``jaxgrasp plan``'s fingertip and object options (SI units): a 10 mm
silicone-like fingertip on a light plastic-like object."""

MAGNIFICATION_RANGE = (1e-3, 1e12)
"""The ``--magnification`` factors ``jaxgrasp show`` accepts, inclusive. Below 1e-3 the ghost
cannot be told from the object at any picture size; above 1e12 the motion drawn is
float64's rounding of the pose (about 1e-16 of the object's size) magnified into view, not
the motion, and factors near 1e300 overflow the coordinates to infinity."""


def add_evaluate(sub) -> None:
    """Add the ``evaluate`` command to the ``jaxgrasp`` sub-parsers."""
    p = sub.add_parser("evaluate", help=COMMANDS["evaluate"])
    add_grasp_source(p)
    add_overrides(p)
    p.add_argument("--json", action="store_true", help="print a JSON object instead")
    add_robust_options(p)
    add_chunk_size(p, "perturbed grasps per compiled batch with --robust (default 64 per CPU device, 1024 per GPU)")


def add_sweep(sub) -> None:
    """Add the ``sweep`` command to the ``jaxgrasp`` sub-parsers."""
    sp = sub.add_parser(
        "sweep",
        help=COMMANDS["sweep"],
        description=(
            "Evaluate a grasp over the Cartesian grid of the given parameter axes; write "
            "DIR/sweep.npz, DIR/sweep.csv (one row per grid point, SI units) and DIR/sweep.png "
            "as one set, replacing a previous set at once. Until then the finished points are "
            "kept in DIR/sweep.partial.npz (what an interrupted sweep leaves); one sweep at a "
            "time per DIR."
        ),
        epilog=(
            "SPEC is START:STOP:COUNT (inclusive), a comma list or a number, in SI units; "
            f"the grid may have at most {MAX_GRID_POINTS:,} points, in the order the axes are given. "
            "Without a grasp: preset cube. Without any axis: the paper's Fig. 6 grid "
            f"(--young-modulus {PAPER_AXES['young_modulus']} "
            f"--initial-deformation {PAPER_AXES['initial_deformation']}). "
            "Example: jaxgrasp sweep --preset prism --young-modulus 2e5:1e6:5 "
            "--initial-deformation 1e-3:5e-3:41 --mass 0,0.1,0.2 --out out/"
        ),
    )
    add_grasp_source(sp)
    for name in OVERRIDES:  # the axes, in option order
        field = FIELD[name]
        sp.add_argument(field.option, dest=name, metavar="SPEC", type=_AxisSpec(field.option), action=_AxisInOrder,
                        help=f"{field.help} (axis spec)")
    sp.add_argument(
        "--out", default="jaxgrasp-out", metavar="DIR", help="output folder (default jaxgrasp-out)"
    )
    add_chunk_size(sp, "grid points per compiled batch (default: 64 per CPU device; on a GPU about a tenth "
                       "of the grid, 64 to 1024 per device)")
    sp.add_argument("--no-plot", action="store_true", help="do not write sweep.png")
    add_epsilon_option(sp)
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")
    sp.set_defaults(default_preset="cube")


def add_batch(sub) -> None:
    """Add the ``batch`` command to the ``jaxgrasp`` sub-parsers."""
    sp = sub.add_parser(
        "batch",
        help=COMMANDS["batch"],
        description=(
            "Evaluate every grasp of a dataset file (.npz arrays named like the grasp fields, "
            "or .jsonl with one grasp-file JSON object per line; SI units; any contact counts) "
            "and rank them. Writes DIR/results.csv (one row per grasp in input order), "
            "DIR/results.npz (every result array) and DIR/results.png (the ranking) as one set. "
            "Finished chunks are kept in DIR/results.partial until then: an interrupted run "
            "is finished by the same command with --resume."
        ),
        epilog="Example: jaxgrasp batch grasps.jsonl --out ranked/ --top 10",
    )
    sp.add_argument("file", help="dataset file (.npz or .jsonl), a hand grasp file (.toml, one or many "
                    "configurations), or hand data in the format --format names")
    sp.add_argument("--out", default="jaxgrasp-out", metavar="DIR", help="output folder (default jaxgrasp-out)")
    add_chunk_size(sp, "grasps per compiled batch (default 64 per CPU device, 1024 per GPU)")
    add_hand_data_options(sp)
    sp.add_argument("--top", type=Count("--top", MAX_TOP, "best grasps listed (MAX_TOP: results.csv ranks them all)"),
                    default=DEFAULT_TOP, metavar="K", help=f"list the K best grasps, at most {MAX_TOP:,} (default {DEFAULT_TOP})")
    sp.add_argument("--strict", action="store_true", help="any invalid grasp: exit 2 before computing")
    sp.add_argument("--resume", action="store_true", help="finish an interrupted run into the same DIR")
    sp.add_argument("--no-plot", action="store_true", help="do not write results.png")
    add_allow_dir(sp)
    add_epsilon_option(sp)
    add_robust_options(sp)
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_process_options(sp)


HAND_FORMATS = ("dexgraspnet", "dexgraspbench")
"""The hand-grasp datasets of the field ``jaxgrasp batch --format`` reads (docs/guide/hands.md)."""

HAND_DATA_DEFAULTS = dict(young_modulus=3e5, friction=0.8, max_force=15.0)
"""The fingertip fields of ``jaxgrasp batch --format`` where not given (SI units), as ``plan``'s."""


def add_hand_data_options(sp: argparse.ArgumentParser) -> None:
    """``--format``, ``--hand``, ``--fingertips``, ``--mesh`` and the fingertip and object
    fields of a dataset of hand configurations (``jaxgrasp batch``)."""
    g = sp.add_argument_group("hand datasets (with --format)")
    g.add_argument("--format", choices=HAND_FORMATS, default=None,
                   help="FILE holds hand configurations in this dataset format: dexgraspnet (a .npy of one "
                        "object's grasps), dexgraspbench (a .npy grasp or a folder of them)")
    g.add_argument("--hand", metavar="FILE", default=None, help="the hand's model (MJCF .xml or URDF .urdf)")
    g.add_argument("--fingertips", metavar="A,B,C", default=None,
                   help="the hand's fingertips, comma-separated geom (or link) names; contact k is the k-th")
    g.add_argument("--mesh", metavar="FILE", default=None,
                   help="the object's mesh (dexgraspnet: required, scaled per grasp; dexgraspbench: default each "
                        "grasp's obj_path)")
    g.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="the mesh's length unit (default m)")
    d = HAND_DATA_DEFAULTS
    for opt, key, unit in (("--young-modulus", "young_modulus", "Pa"), ("--friction", "friction", ""),
                           ("--max-force", "max_force", "N")):
        g.add_argument(opt, dest=key, type=float, default=None, metavar=unit.upper() or "MU",
                       help=f"every fingertip's {key.replace('_', ' ')}" + (f", {unit}" if unit else "")
                       + f" (default {d[key]:g})")
    mass = g.add_mutually_exclusive_group()
    mass.add_argument("--density", type=float, default=None, metavar="KG_M3", help="object density, kg/m^3")
    mass.add_argument("--mass", type=float, default=None, metavar="KG", help="object mass, kg (default 0: no weight)")


def add_tune(sub) -> None:
    """Add the ``tune`` command to the ``jaxgrasp`` sub-parsers."""

    sp = sub.add_parser(
        "tune",
        help=COMMANDS["tune"],
        description=(
            "Maximise the evaluation value of a grasp over the chosen parameters within "
            "bounds (gradient-based, L-BFGS-B); write the tuned grasp to --out and a plot "
            "of the value over the iterations next to it (.png)."
        ),
        epilog=(
            f"PARAM is one of {', '.join(TUNABLE)}; per-contact ones tune one value per "
            "contact, or one shared value with the suffix ':shared' (e.g. "
            "initial_deformation:shared). 'positions' moves each contact in its tangent plane (along the surface for a grasp file naming a mesh) "
            "(give --bounds positions=HALF_WIDTH in m). Only initial_deformation has "
            "default bounds. Example: jaxgrasp tune --preset cube --param "
            "initial_deformation:shared --bounds initial_deformation=0.001:0.005 --out tuned.toml. "
            "A hand grasp file (FILE with a [hand] table): its joint angles are tuned (jaxgrasp.tune_hand), "
            "the other links kept out of the object; the tuned configuration is written as a hand grasp file. "
            "Example: jaxgrasp tune examples/hands/two_finger/pinch.toml --out tuned_pinch.toml"
        ),
    )
    add_grasp_source(sp)
    add_overrides(sp)  # --young-modulus PA etc., as every other command
    sp.add_argument(
        "--param",
        action="append",
        metavar="PARAM",
        help="a parameter to tune (repeatable; default initial_deformation)",
    )
    sp.add_argument(
        "--bounds",
        action="append",
        metavar="NAME=LO:HI",
        help="bounds of a parameter in SI units (repeatable); positions=HALF_WIDTH in m",
    )
    sp.add_argument("--maxiter", type=Count("--maxiter", MAX_TUNE_ITERATIONS, TUNE_ITERATIONS_WHAT), default=50,
                    metavar="N", help=f"most iterations, at most {MAX_TUNE_ITERATIONS:,} (default 50)")
    sp.add_argument("--method", choices=METHODS, default=METHODS[0], help=f"optimiser (default {METHODS[0]})")
    sp.add_argument(
        "--smooth-min-temperature",
        type=float,
        default=None,
        metavar="J",
        help="tune the soft minimum over boundaries at this temperature, J (default: hard minimum)",
    )
    sp.add_argument(
        "--tune-wrist", action="store_true",
        help=("with a hand grasp file: also move the wrist, within 10 mm and 0.1 rad of its start "
              "(a hand grasp file's joints are always tuned, within their limits; no --param or --bounds)"),
    )
    sp.add_argument(
        "--out", default="tuned.toml", metavar="FILE",
        help="tuned grasp file, .toml or .json; a hand grasp file's: .toml (default tuned.toml)"
    )
    sp.add_argument("--no-plot", action="store_true", help="do not write the .png plot")
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")


def plan_fields(args) -> dict:
    """The fingertip and object keyword arguments of [`jaxgrasp.plan`][jaxgrasp.plan], checked (``radius``
    ``None`` where not given)."""
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
        mass = dict(density=PLAN_DEFAULTS["density"] if args.density is None else args.density)
    return dict(radius=args.radius, young_modulus=args.young_modulus, friction=args.friction,
                max_force=args.max_force, gravity=gravity, units=args.units, **mass)


def add_plan(sub) -> None:
    """Add the ``plan`` command to the ``jaxgrasp`` sub-parsers."""

    sp = sub.add_parser(
        "plan",
        help=COMMANDS["plan"],
        description=(
            "Draw candidate grasps on the object's mesh, keep those the model describes (flat contact "
            "patch, fingertips apart, one contact each, deformation in range), evaluate them, refine the "
            "best by gradient tuning along the surface, and write them ranked into --out. With --hand, "
            "close a robot hand's configurations onto the object instead, keep those with enough fingertips in "
            "contact and the other links out, refine the best over joints and wrist."
        ),
        epilog=("Examples: jaxgrasp plan part.obj --units mm --fingers 3 --out plan-part; "
                "jaxgrasp plan part.obj --units mm --hand shadow/shadow_hand.xml "
                "--fingertips robot0:C_ffdistal,robot0:C_thdistal --out plan-hand"),
    )
    d = PLAN_DEFAULTS
    sp.add_argument("mesh", help="the object's mesh file (STL, OBJ, PLY, OFF or GLB)")
    sp.add_argument("--fingers", type=Count("--fingers", MAX_FINGERS, "fingertips"), default=None, metavar="N",
                    help=f"free fingertips, 2 to {MAX_FINGERS} (default 2; not with --hand)")
    sp.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="the mesh's length unit (default m)")
    sp.add_argument("--radius", type=float, default=None, metavar="M",
                    help=f"every free fingertip's radius, m (default {d['radius']:g}; with --hand: the hand's own)")
    for opt, key, unit in (("--young-modulus", "young_modulus", "Pa"), ("--friction", "friction", ""),
                           ("--max-force", "max_force", "N")):
        sp.add_argument(opt, dest=key, type=float, default=d[key], metavar=unit.upper() or "MU",
                        help=f"every fingertip's {key.replace('_', ' ')}" + (f", {unit}" if unit else "")
                        + f" (default {d[key]:g})")
    mass = sp.add_mutually_exclusive_group()
    mass.add_argument("--density", type=float, default=None, metavar="KG_M3",
                      help=f"object density, kg/m^3; mass = density x volume (default {d['density']:g})")
    mass.add_argument("--mass", type=float, default=None, metavar="KG", help="object mass, kg")
    sp.add_argument("--gravity", default="0,0,-9.81", metavar="GX,GY,GZ",
                    help="gravity in the mesh's axes, m/s^2 (default 0,0,-9.81)")
    sp.add_argument("--samples", type=Count("--samples", MAX_PLAN_SAMPLES, PLAN_SAMPLES_WHAT), default=None, metavar="N",
                    help=f"valid candidates to evaluate, at most {MAX_PLAN_SAMPLES:,} (default 150; with --hand: "
                    "closed hand configurations, default 128)")
    sp.add_argument("--top", type=Count("--top", MAX_PLAN_SAMPLES, PLAN_SAMPLES_WHAT), default=10, metavar="K",
                    help="ranked grasps to write (default 10)")
    sp.add_argument("--refine", type=Count("--refine", MAX_PLAN_REFINE, PLAN_REFINE_WHAT), default=3, metavar="K",
                    help=f"best candidates to tune, at most {MAX_PLAN_REFINE:,} (default 3)")
    sp.add_argument("--seed", type=int, default=0, help="seed of the random draws (default 0)")
    sp.add_argument("--sampler", choices=SAMPLERS, default=None,
                    help="candidate generator (default antipodal for 2 fingers, spread for more)")
    sp.add_argument("--flatness", type=float, default=None, metavar="DEG",
                    help="largest angle between the contact normal and a face under the fingertip (default 25; "
                    "not with --hand)")
    _add_plan_hand(sp)
    sp.add_argument("--rank", choices=("value", "robust"), default="value",
                    help="rank by the value, or by the robust value (the mean over perturbed copies) (default value)")
    sp.add_argument("--robust", default=None, metavar="SPEC",
                    help=f"the uncertainty of --rank robust, as for evaluate --robust (default {DEFAULT_ROBUST})")
    sp.add_argument("--robust-samples", type=Count("--robust-samples", MAX_ROBUST_SAMPLES, ROBUST_SAMPLES_WHAT),
                    default=64, metavar="S",
                    help=f"perturbed copies per ranked grasp for --rank robust, at most {MAX_ROBUST_SAMPLES:,} (default 64)")
    sp.add_argument("--out", default="plan", metavar="DIR", help="output folder (default ./plan)")
    sp.add_argument("--no-plot", action="store_true", help="do not write best.png")
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _add_plan_hand(sp) -> None:
    """The options of ``plan --hand``."""
    hand = sp.add_argument_group("with a hand", "plan a robot hand's joints and wrist (jaxgrasp.plan(hand=...))")
    hand.add_argument("--hand", default=None, metavar="HAND", help="the hand's MJCF or URDF file")
    hand.add_argument("--fingertips", default=None, metavar="A,B,C",
                      help="the hand's fingertip geoms, bodies or links, comma-separated")
    hand.add_argument("--min-fingertips", type=int, default=None, metavar="K",
                      help="the fewest fingertips in contact of a ranked grasp (default 2)")
    hand.add_argument("--objective", choices=("value", "epsilon"), default=None,
                      help="what the plan maximises: the value (energy tolerance) or the Ferrari-Canny epsilon "
                      "(default value)")
    hand.add_argument("--max-penetration", type=float, default=None, metavar="M",
                      help="how deep the hand's other links may lie in the object, m (default 0.001)")


def add_show(sub) -> None:
    """Add the ``show`` command to the ``jaxgrasp`` sub-parsers."""
    p = sub.add_parser(
        "show",
        help=COMMANDS["show"],
        description=(
            "Evaluate one grasp and draw it in 3-D: the object (its mesh, or the contacts' hull), "
            "each fingertip pressed into its contact with its normal and friction cone, the limiting "
            "contact in red, and the object at the least-energy pose of the limiting boundary as a "
            "ghost, the motion magnified by the factor the title states. --glb writes the same "
            "scene as a GLB file for any 3-D viewer."
        ),
    )
    add_grasp_source(p)
    add_overrides(p)
    p.add_argument("--out", default="grasp.png", metavar="FILE", help="the picture, .png, .pdf or .svg (default grasp.png)")
    p.add_argument("--glb", metavar="FILE", help="also write the scene as a GLB file (.glb)")
    p.add_argument("--magnification", type=float, metavar="X",
                   help=(f"factor the ghost's motion is magnified by, {MAGNIFICATION_RANGE[0]:g} to "
                         f"{MAGNIFICATION_RANGE[1]:g} (default: a round one that makes it visible)"))
    p.add_argument("--hand", metavar="FILE",
                   help=("draw a hand's grasp instead: a hand grasp file (.toml, see docs/guide/hands.md), which "
                         "sets the fingertips and the object (no --young-modulus etc. with it)"))


def _kick_scales(text: str) -> list[float]:
    """``--scales S,S,...``: at least one scale, no empty item, each finite, ``>= 0`` and
    at most `MAX_KICK_SCALE` (a kick beyond it is beyond what the simulator integrates;
    `jaxgrasp.simulation._limits`); a `UsageError` naming the option otherwise."""
    if not text.strip():
        raise UsageError("--scales: empty value; give at least one scale, e.g. 0.5,0.9,1.1,2")
    items = text.split(",")
    if any(not s.strip() for s in items):
        raise UsageError(f"--scales: list {text!r} has an empty item")
    scales = [parse_number("--scales", s, "scale") for s in items]
    for s in scales:
        if s < 0:
            raise UsageError(f"--scales must be finite and >= 0, got {s:g}")
        if s > MAX_KICK_SCALE:
            raise UsageError(f"--scales {s:g} is too large: a kick of {s:g} times the value is beyond what the "
                             f"simulator integrates; at most {MAX_KICK_SCALE:g}")
    return scales


def add_simulate(sub) -> None:
    """Add the ``simulate`` command to the ``jaxgrasp`` sub-parsers."""
    p = sub.add_parser(
        "simulate",
        help=COMMANDS["simulate"],
        description=(
            "Evaluate one grasp, then simulate it in MuJoCo: fingertips as fixed spheres calibrated to the "
            "paper's normal force (eq. 4), condim 4 with elliptic cones; hold under gravity, a force of "
            "m * 10 m/s^2 along +-x, +-y, +-z (DexGraspBench), and kicks with kinetic energy s times the "
            "value. Writes DIR/results.json and DIR/trials.png. Limits: all trials together at most "
            f"{MAX_SIMULATED_S:g} s of simulated time and {MAX_STEPS:,} MuJoCo steps (time / timestep; a few "
            f"minutes); a --timestep at most 1/{round(1 / TIMESTEP_FRACTION)} of the shortest trial. "
            "Needs: pip install \"jaxgrasp[sim]\"."
        ),
    )
    add_grasp_source(p)
    add_overrides(p)
    p.add_argument("--out", default="jaxgrasp-sim", metavar="DIR", help="output folder (default jaxgrasp-sim)")
    p.add_argument("--hold-time", default="1.0", metavar="S", help="hold under gravity, s (default 1)")
    p.add_argument("--six-axis-time", default="2.0", metavar="S", help="each disturbance, s (default 2)")
    p.add_argument("--kick-time", default="0.3", metavar="S", help="each energy kick, s (default 0.3)")
    p.add_argument("--scales", default="0.5,0.9,1.1,2", metavar="S,S,...", type=_kick_scales,
                   help=(f"kick energies as multiples of the value, each 0 to {MAX_KICK_SCALE:g} "
                         "(default 0.5,0.9,1.1,2)"))
    p.add_argument("--random-kicks", type=int, default=2, metavar="N", help="random kick directions per scale (default 2)")
    p.add_argument("--sim-friction", metavar="MU", help="the simulator's friction instead of the grasp's (a what-if)")
    p.add_argument("--timestep", metavar="S",
                   help=(f"simulator timestep, s, at most 1/{round(1 / TIMESTEP_FRACTION)} of the shortest trial "
                         "(default: from the contact stiffness)"))
    p.add_argument("--simulate-unstable", action="store_true",
                   help="also simulate an unstable grasp from its equilibrium pose")
    p.add_argument("--protocol", default="jaxgrasp", metavar="NAME",
                   help=("jaxgrasp (default: the fingertips as fixed spheres, the options above) or dexgraspbench: "
                         "a hand grasp file's whole hand (MJCF) in MuJoCo with DexGraspBench's settings, squeezed to "
                         "the model's normal forces and pushed with 10 m N along +-x, +-y, +-z for 2 s; --friction MU "
                         "replaces its sliding friction 0.6"))
