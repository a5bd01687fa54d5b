"""``jaxgrasp sweep``: evaluate a grasp over a grid of parameters; write npz, csv and a plot.

Axis specs (SI units): ``start:stop:count`` (inclusive ``linspace``), a comma list
``0,0.1,0.2`` or a single number. With no axis at all the paper's Fig. 6 grid is swept
(E 2e5..1e6 Pa x 9, initial deformation 1..5 mm x 41); with no grasp, preset ``cube``.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from .cli import UsageError, _add_grasp_source, load_grasp, parse_number

__all__ = ["add_sweep_parser", "parse_axis_spec", "PAPER_AXES"]

_AXIS_OPTIONS = {
    # parameter: (option, metavar, help)
    "young_modulus": ("--young-modulus", "SPEC", "Young's modulus of every fingertip, Pa"),
    "initial_deformation": ("--initial-deformation", "SPEC", "initial deformation of every fingertip, m"),
    "mass": ("--mass", "SPEC", "object mass, kg"),
    "friction": ("--friction", "SPEC", "friction coefficient of every fingertip"),
    "max_force": ("--max-force", "SPEC", "normal force limit of every fingertip, N"),
    "radius": ("--radius", "SPEC", "fingertip radius, m"),
}

PAPER_AXES = {
    "young_modulus": "2e5:1e6:9",
    "initial_deformation": "1e-3:5e-3:41",
}
"""The grid of the paper's Fig. 6 (used when no axis is given)."""

_MIN_AUTO_CHUNK = 64
_AUTO_CHUNKS = 10  # aim for about this many progress steps on a long sweep


def parse_axis_spec(option: str, spec: str) -> np.ndarray:
    """Parse ``start:stop:count``, ``a,b,c`` or ``x`` into a 1-D float array.

    Raises:
        UsageError: malformed spec (one line, naming the option).
    """
    text = spec.strip()
    if not text:
        raise UsageError(f"{option}: empty value; give START:STOP:COUNT, a comma list or a number")
    if ":" in text:
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
        return np.linspace(start, stop, count)
    items = text.split(",")
    if any(not s.strip() for s in items):
        raise UsageError(f"{option}: list {spec!r} has an empty item")
    return np.asarray([parse_number(option, s) for s in items], dtype=np.float64)


def add_sweep_parser(sub) -> None:
    """Add the ``sweep`` command to the ``jaxgrasp`` sub-parsers."""
    sp = sub.add_parser(
        "sweep",
        help="evaluate a grasp over a grid of parameters (npz, csv, png)",
        description=(
            "Evaluate a grasp over the Cartesian grid of the given parameter axes; write "
            "DIR/sweep.npz, DIR/sweep.csv (one row per grid point, SI units) and DIR/sweep.png."
        ),
        epilog=(
            "SPEC is START:STOP:COUNT (inclusive), a comma list or a number, in SI units. "
            "Without a grasp: preset cube. Without any axis: the paper's Fig. 6 grid "
            f"(--young-modulus {PAPER_AXES['young_modulus']} "
            f"--initial-deformation {PAPER_AXES['initial_deformation']}). "
            "Example: jaxgrasp sweep --preset prism --young-modulus 2e5:1e6:5 "
            "--initial-deformation 1e-3:5e-3:41 --mass 0,0.1,0.2 --out out/"
        ),
    )
    _add_grasp_source(sp)
    for name, (opt, metavar, help_) in _AXIS_OPTIONS.items():
        sp.add_argument(opt, dest=name, metavar=metavar, help=f"{help_} (axis spec)")
    sp.add_argument(
        "--out", default="jaxgrasp-out", metavar="DIR", help="output folder (default jaxgrasp-out)"
    )
    sp.add_argument(
        "--chunk-size",
        type=int,
        default=None,
        metavar="N",
        help=(
            "grid points per compiled batch (default: about a tenth of the grid, "
            "at most 64 per CPU device, 1024 per GPU)"
        ),
    )
    sp.add_argument("--no-plot", action="store_true", help="do not write sweep.png")
    sp.add_argument("--quiet", action="store_true", help="no progress on stderr")
    sp.set_defaults(func=_cmd_sweep, default_preset="cube")


def _auto_chunk(total: int, cap: int = 64) -> int:
    """About a tenth of the grid, at least 64, at most ``cap`` (jaxgrasp.sweep.default_chunk_size)."""
    chunk = min(cap, max(_MIN_AUTO_CHUNK, math.ceil(total / _AUTO_CHUNKS)))
    nchunks = math.ceil(total / chunk)
    return max(1, math.ceil(total / nchunks))  # same number of chunks, least padding


def _fmt_param(name: str, x: float) -> str:
    from .sweep import PARAMETERS

    unit = PARAMETERS[name].unit
    return f"{name}={x:.6g}" + (f" {unit}" if unit else "")


def _cmd_sweep(args) -> int:
    import jax

    from .sweep import batch_size, default_chunk_size, sweep

    given = {n: getattr(args, n) for n in _AXIS_OPTIONS if getattr(args, n) is not None}
    paper = not given
    specs = dict(PAPER_AXES) if paper else given
    axes = {n: parse_axis_spec(_AXIS_OPTIONS[n][0], s) for n, s in specs.items()}
    if args.chunk_size is not None and args.chunk_size < 1:
        raise UsageError(f"--chunk-size must be >= 1, got {args.chunk_size}")
    grasp = load_grasp(args, overrides=False)
    source = args.file or f"preset {args.preset}"
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {str(out)!r} exists and is not a folder")

    total = int(np.prod([a.size for a in axes.values()]))
    chunk = args.chunk_size if args.chunk_size is not None else _auto_chunk(total, default_chunk_size())
    n_devices = jax.device_count()
    chunk = batch_size(chunk, total, n_devices)  # a multiple of the device count
    nchunks = math.ceil(total / chunk)
    show = not args.quiet and nchunks > 1
    t_start = time.perf_counter()
    if show:
        on = f" on {n_devices} devices" if n_devices > 1 else ""
        print(
            f"jaxgrasp: sweeping {total} points in {nchunks} chunks of {chunk}{on} "
            "(the first chunk includes compilation)",
            file=sys.stderr,
            flush=True,
        )

    def progress(done: int, total_: int) -> None:
        if show:
            k = math.ceil(done / chunk)
            el = time.perf_counter() - t_start
            print(
                f"jaxgrasp: chunk {k}/{nchunks} ({done}/{total_} points), elapsed {el:.1f} s",
                file=sys.stderr,
                flush=True,
            )

    # validation errors (GraspValueError) surface before any compilation
    result = sweep(grasp, chunk_size=chunk, progress=progress, **axes)
    wall = time.perf_counter() - t_start

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot create --out folder {str(out)!r}: {exc.strerror}") from None
    result.to_npz(out / "sweep.npz")
    result.to_csv(out / "sweep.csv")
    written = ["sweep.npz", "sweep.csv"]
    if not args.no_plot:
        from .plots import plot_sweep

        title = f"jaxgrasp sweep: {source}"
        if paper and args.preset == "cube" and args.file is None:
            title = "Fig. 6: evaluation value for each Young's modulus and initial deformation (cube)"
        plot_sweep(result, out / "sweep.png", title=title)
        written.append("sweep.png")

    c = result.counts()
    shape = " x ".join(f"{len(a)} {n}" for n, a in result.axes.items())
    best = result.best()
    if best is None:
        best_text = "best: none (no converged point)"
    else:
        where = ", ".join(_fmt_param(n, best[n]) for n in result.axes)
        lim = (
            f"{best['limiting_kind']} of contact {best['limiting_contact']}"
            if best["limiting_contact"] >= 0
            else best["status"]
        )
        best_text = f"best {best['value']:.6e} J at {where} ({lim})"
    print(
        f"sweep {source}: {total} points ({shape}); "
        f"stable {c['stable']}, unstable {c['unstable']}, infeasible {c['infeasible']}, "
        f"not_converged {c['not_converged']}; {best_text}; "
        f"wall {wall:.1f} s (compile {result.compile_seconds:.1f} s, run {result.run_seconds:.1f} s); "
        f"wrote {out}/{{{','.join(written)}}}"
    )
    return 0
