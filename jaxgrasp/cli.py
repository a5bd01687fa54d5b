"""The ``jaxgrasp`` command line: ``jaxgrasp evaluate``, ``jaxgrasp sweep``, ``jaxgrasp tune``.

Every error in the input (bad file, bad value, bad option) prints one line
``jaxgrasp: error: ...`` on stderr and exits with status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from .cache import enable_compilation_cache

EXIT_USAGE = 2


class UsageError(Exception):
    """A problem with the command line or its input; reported in one line, exit 2."""


def parse_number(option: str, text: str, what: str = "value") -> float:
    """``text`` as a finite float; a :class:`UsageError` naming ``option`` otherwise."""
    t = text.strip()
    try:
        x = float(t)
    except ValueError:
        raise UsageError(f"{option}: {what} {t!r} is not a number") from None
    if not math.isfinite(x):
        raise UsageError(f"{option}: {what} {t!r} must be finite")
    return x


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of usage + message
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _add_grasp_source(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", nargs="?", help="grasp file (.toml or .json, SI units)")
    p.add_argument("--preset", choices=["cube", "prism"], help="one of the paper's grasps instead of a file")


def _add_overrides(p: argparse.ArgumentParser) -> None:
    p.add_argument("--young-modulus", type=float, metavar="PA", help="Young's modulus of every fingertip, Pa")
    p.add_argument(
        "--initial-deformation", type=float, metavar="M", help="initial deformation of every fingertip, m"
    )
    p.add_argument("--mass", type=float, metavar="KG", help="object mass, kg")
    p.add_argument("--friction", type=float, help="friction coefficient of every fingertip")
    p.add_argument("--max-force", type=float, metavar="N", help="normal force limit of every fingertip, N")
    p.add_argument("--radius", type=float, metavar="M", help="fingertip radius, m")


_OVERRIDES = ("young_modulus", "initial_deformation", "mass", "friction", "max_force", "radius")


def load_grasp(args, overrides: bool = True):
    """The grasp named on the command line (file or preset), with overrides applied."""
    import numpy as np

    from . import presets
    from .gripfile import load
    from .validation import check_grasp_inputs
    from .grasp import Grasp

    if (args.file is None) == (args.preset is None):
        if args.file is None and getattr(args, "default_preset", None):
            args.preset = args.default_preset
        else:
            raise UsageError("give either a grasp FILE or --preset cube|prism")
    grasp = load(args.file) if args.file is not None else presets.PRESETS[args.preset]()
    if not overrides:
        return grasp
    fields = grasp.to_numpy()
    for name in _OVERRIDES:
        value = getattr(args, name, None)
        if value is not None:
            fields[name] = np.full_like(fields[name], value)
    return Grasp(**check_grasp_inputs(**fields))


def _format_summary(d: dict, source: str) -> str:
    lines = [f"grasp: {source}"]
    lines.append(f"status: {d['status']}")
    if d.get("explanation"):
        lines.append(f"explanation: {d['explanation']}")
    lines.append(f"value: {d['value']:.6e} J   (least energy that makes a fingertip slip or overload)")
    lim = d["limiting"]
    if lim is not None:
        lines.append(f"limiting boundary: {lim['kind']} of contact {lim['contact']}")
    lines.append(f"equilibrium energy: {d['equilibrium_energy']:.6e} J")
    t = ", ".join(f"{v:.3e}" for v in d["equilibrium_translation"])
    w = ", ".join(f"{v:.3e}" for v in d["equilibrium_rotation"])
    lines.append(f"equilibrium pose: translation ({t}) m, rotation ({w}) rad")
    lines.append("boundaries (minimum energy above equilibrium):")
    for b in d["boundaries"]:
        if b["energy"] is None:
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: not reachable ({b['status']})")
        else:
            de = b["energy"] - d["equilibrium_energy"]
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: {de:.6e} J ({b['status']})")
    return "\n".join(lines)


def _cmd_evaluate(args) -> int:
    grasp = load_grasp(args)
    from .evaluate import evaluate

    result = evaluate(grasp)
    d = result.to_dict()
    if args.json:
        print(json.dumps(d, indent=2, allow_nan=False))
    else:
        print(_format_summary(d, args.file or f"preset {args.preset}"))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="jaxgrasp", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    ev = sub.add_parser("evaluate", help="evaluate one grasp and print a summary")
    _add_grasp_source(ev)
    _add_overrides(ev)
    ev.add_argument("--json", action="store_true", help="print a JSON object instead")
    ev.set_defaults(func=_cmd_evaluate)
    from .sweep_cli import add_sweep_parser
    from .tune_cli import add_tune_parser

    add_sweep_parser(sub)
    add_tune_parser(sub)
    return parser


def main(argv=None) -> int:
    from .validation import GraspValueError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            raise UsageError("choose a command: evaluate, sweep or tune (see 'jaxgrasp --help')")
        enable_compilation_cache()
        return args.func(args)
    except (UsageError, GraspValueError) as exc:
        print(f"jaxgrasp: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("jaxgrasp: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    # Run through the package module, so that exception classes are the package's own.
    from jaxgrasp.cli import main as _main

    sys.exit(_main())
