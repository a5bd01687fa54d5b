"""``jaxgrasp tune``: maximise a grasp's value over chosen parameters; write the tuned grasp.

Writes the tuned grasp to ``--out`` (``.toml`` or ``.json``) and a plot of the value over
the iterations next to it (same name, ``.png``), and prints one summary line. A hand grasp
file is tuned in its joints (`jaxgrasp.cli._tune_hand`). The folder
of ``--out`` is checked for writability before tuning; the grasp file and its plot then
replace the previous ones as one set (`jaxgrasp.storage.write_set`).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from jaxgrasp.cli._arguments import parse_number
from jaxgrasp.cli._common import UsageError, grasp_source, load_grasp, say, write_with_plot
from jaxgrasp.cli._hand_files import is_hand_file
from jaxgrasp import storage
from jaxgrasp.model import counted

__all__ = ["run", "parse_bounds", "check_bounds"]


def parse_bounds(items) -> dict:
    """``["initial_deformation=0.001:0.005", "positions=0.01"]`` -> bounds dict (SI units).

    ``NAME=LO:HI`` gives a range (every contact), ``positions=HALF_WIDTH`` a half-width in m;
    errors name the option and its syntax (`UsageError`).
    """
    out = {}
    for item in items or []:
        name, eq, spec = item.partition("=")
        name = name.strip()
        if not eq or not name or not spec.strip():
            raise UsageError(f"--bounds: {item!r} must be NAME=LO:HI (or positions=HALF_WIDTH)")
        if name in out:
            raise UsageError(f"--bounds: {name!r} given more than once")
        if name.partition(":")[0] == "positions":
            if ":" in spec:
                raise UsageError(
                    f"--bounds {item}: give positions=HALF_WIDTH, one number: how far (m) each "
                    "contact may move in its face"
                )
            h = parse_number("--bounds", spec, "half-width")
            if not h > 0:
                raise UsageError(f"--bounds {item}: the half-width must be > 0 m")
            out[name] = h
        elif ":" in spec:
            parts = spec.split(":")
            if len(parts) != 2:
                raise UsageError(f"--bounds: {item!r} must be NAME=LO:HI")
            lo = parse_number("--bounds", parts[0], "lower bound")
            hi = parse_number("--bounds", parts[1], "upper bound")
            if not lo < hi:
                raise UsageError(f"--bounds {item}: LO must be below HI")
            out[name] = (lo, hi)
        else:
            raise UsageError(f"--bounds {item}: give a range, {name}=LO:HI (only positions takes one number)")
    return out


def check_bounds(params, bounds: dict) -> None:
    """Every ``--param`` without default bounds has ``--bounds``, and every ``--bounds`` is
    of a ``--param`` (`UsageError` naming the options; library messages would show
    Python syntax such as ``bounds={'positions': 0.01}``)."""
    from jaxgrasp.analysis import parse_param
    from jaxgrasp.model import FIELD

    specs = [parse_param(p) for p in params]
    tuned = {s.name for s in specs} | {s.label for s in specs}
    for key in bounds:
        if key not in tuned:
            raise UsageError(
                f"--bounds {key}=...: {key} is not tuned (add --param {key.partition(':')[0]}, "
                f"or drop these bounds)"
            )
    for s in specs:
        if s.name == "initial_deformation" or s.name in bounds or s.label in bounds:
            continue
        if s.name == "positions":
            form = "positions=HALF_WIDTH (m, how far each contact may move in its face)"
        else:
            form = f"{s.name}=LO:HI ({FIELD[s.name].unit or 'dimensionless'})"
        raise UsageError(f"--param {s.label} needs --bounds {form}; only initial_deformation has default bounds")


def run(args) -> int:
    """Tune the grasp of the command line; write it (and a plot) and print one summary line.

    Unless ``--quiet``, a first line on stderr says what is tuned, before the value and
    its gradient are compiled; then one line per iteration. The summary line names the
    [`TuneStatus`][jaxgrasp.analysis.TuneStatus] with its explanation: why the search stopped and
    whether the tuned grasp is usable.
    """
    from jaxgrasp.analysis import tune
    from jaxgrasp.tolerance import EvaluateOptions

    out = _check_options(args)
    if is_hand_file(args):  # the hand's joints (and wrist) are tuned: jaxgrasp.cli._tune_hand
        from jaxgrasp.cli._tune_hand import run_hand

        return run_hand(args, out)
    if args.tune_wrist:
        raise UsageError("--tune-wrist: only with a hand grasp file (a grasp file has no wrist)")
    bounds = parse_bounds(args.bounds)
    params = args.param or ["initial_deformation"]
    check_bounds(params, bounds)
    grasp = load_grasp(args, keep_mesh=True)  # with the overrides (--young-modulus ...); a mesh's positions slide on it
    source = grasp_source(args)
    if not args.quiet:
        say(
            f"jaxgrasp: tuning {', '.join(params)} of {source} ({_contacts(grasp)} contacts) by {args.method}, "
            f"at most {counted(args.maxiter, 'iteration')}; compiling the value and its gradient first"
        )
    options = EvaluateOptions(smooth_min_temperature=args.smooth_min_temperature)
    progress = _progress_printer(args.quiet)
    res = tune(grasp, params, bounds, maxiter=args.maxiter, options=options, method=args.method, callback=progress)
    replaced = _write_outputs(res, out, None if args.no_plot else f"jaxgrasp tune: {source}")
    print(_summary_line(res, source, out, args.no_plot, replaced))
    return 0


def _summary_line(res, source: str, out: Path, no_plot: bool, replaced: list[str]) -> str:
    """``tune SOURCE: value A J -> B J (xG, N iterations, STATUS: why it stopped; whether
    usable); tuned values; wrote FILES``."""
    tuned = "; ".join(f"{k} = {_fmt(v)}" for k, v in res.params.items() if k != "positions")
    if "positions" in res.params:
        tuned = (tuned + "; " if tuned else "") + "positions moved"
    note = res.start_note()
    return (
        f"tune {source}: value {res.start_value:.6e} J -> {res.value:.6e} J "
        f"(x{res.gain:.4f}, {counted(res.iterations, 'iteration')}, {res.status}: {res.message}); {tuned}; "
        + (f"{note}; " if note else "")
        + f"wrote {out}"
        + ("" if no_plot else f", {out.with_suffix('.png')}")
        + (f" (replacing the previous {', '.join(replaced)})" if replaced else "")
    )


def _check_options(args) -> Path:
    """Reject a bad ``--out``, ``--maxiter`` or ``--smooth-min-temperature``; the out path."""
    out = Path(args.out)
    if out.suffix.lower() not in (".toml", ".json"):
        raise UsageError(f"--out {str(out)!r}: the tuned grasp file must end in .toml or .json")
    if out.exists() and out.is_dir():
        raise UsageError(f"--out {str(out)!r} is a folder; give a file name ending in .toml or .json")
    if args.maxiter < 1:
        raise UsageError(f"--maxiter must be >= 1, got {args.maxiter}")
    t = args.smooth_min_temperature
    if t is not None and not (math.isfinite(t) and t > 0):
        raise UsageError(f"--smooth-min-temperature must be a finite number > 0 (J), got {t}")
    try:
        storage.check_writable(out.parent)  # before any computation; creates nothing
    except storage.OutputError as exc:
        raise UsageError(f"--out {str(out)!r}: {exc}") from None
    return out


def _progress_printer(quiet: bool):
    """``callback(iteration, value, u)`` of [`jaxgrasp.tune`][jaxgrasp.tune]: one line per iteration."""
    t0 = time.perf_counter()

    def progress(it, value, _u):
        if not quiet:
            el = time.perf_counter() - t0
            note = " (includes compilation)" if it == 1 else ""
            say(f"jaxgrasp: iteration {it}: value {value:.6e} J, elapsed {el:.1f} s{note}")

    return progress


def _write_outputs(res, out: Path, title: str | None) -> list[str]:
    """Write the tuned grasp to ``out`` and (with a ``title``) its history plot beside it,
    as one set; the names of the previous files they replaced."""
    from jaxgrasp.io import mesh_reference, to_text

    if res.mesh_grasp is None:
        members = {out: to_text(res.grasp, out).encode("utf-8")}
    else:  # the tuned file names the mesh; a copy beside it where the mesh is elsewhere
        name, raw = mesh_reference(res.mesh_grasp, out.parent, copy=True)
        members = {out: to_text(res.mesh_grasp, out, name).encode("utf-8")}
        if raw is not None:
            members[out.parent / name] = raw
    figure = None
    if title is not None:
        from jaxgrasp.plots import plot_history

        figure = plot_history(res, title=title)
    return write_with_plot(members, out, figure)


def _contacts(grasp) -> int:
    """The number of contacts of a grasp or a mesh grasp."""
    return getattr(grasp, "grasp", grasp).num_contacts


def _fmt(v) -> str:
    a = np.atleast_1d(np.asarray(v, dtype=np.float64))
    s = ", ".join(f"{x:.6g}" for x in a)
    return s if a.size == 1 else f"[{s}]"
