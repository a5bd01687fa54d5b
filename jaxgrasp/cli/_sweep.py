"""``jaxgrasp sweep``: evaluate a grasp over a grid of parameters; write npz, csv and a plot.

Axis specs (SI units): ``start:stop:count`` (inclusive, evenly spaced; each value the
float nearest its decimal, so ``0.1:0.5:5`` gives ``0.4``), a comma list ``0,0.1,0.2`` or
a single number, each checked as the command line is read
(`jaxgrasp.cli._arguments.axis_spec`). The grid's axes follow the order they are given in,
and it has at most `MAX_GRID_POINTS` points (checked before anything is allocated). With no axis at all the paper's Fig. 6 grid is swept (E 2e5..1e6 Pa x 9,
initial deformation 1..5 mm x 41); with no grasp, preset ``cube``.

The output folder is checked for writability before anything is computed and locked
(`jaxgrasp.storage.FolderLock`) for the whole run, so a second sweep into it fails
at once. After each chunk the finished points are kept in ``DIR/sweep.partial.npz``
(`jaxgrasp.cli._keepers.SweepKeeper`); at the end ``sweep.npz``, ``sweep.csv`` and ``sweep.png``
replace the previous ones as one set (`jaxgrasp.storage.write_set`) and the
checkpoint is removed.
"""

from __future__ import annotations

import math
import time
from decimal import Decimal, Inexact, localcontext
from pathlib import Path

import numpy as np

from jaxgrasp import storage
from jaxgrasp.analysis import MAX_GRID_POINTS
from jaxgrasp.cli import _notes
from jaxgrasp.cli._arguments import OVERRIDES, PAPER_AXES, axis_spec
from jaxgrasp.cli._common import (
    ChunkProgress,
    UsageError,
    announce_run,
    check_chunk_size,
    check_out,
    epsilon_columns,
    grasp_source,
    load_grasp,
    lock_out,
    replaced_text,
)
from jaxgrasp.engine import prefetch
from jaxgrasp.model import NO_BOUNDARY
from jaxgrasp.model import FIELD
from jaxgrasp.model import counted

__all__ = ["run", "parse_axis_spec", "AXES", "PAPER_AXES"]

AXES = OVERRIDES
"""The parameters a sweep can vary (`jaxgrasp.model._fields.SWEEPABLE`), in option order."""

OUTPUT_NAMES = ("sweep.npz", "sweep.csv", "sweep.png")
"""The files of one sweep's output set, in ``--out``."""

PARTIAL_NAME = "sweep.partial.npz"
"""The checkpoint of the finished points (`jaxgrasp.cli._keepers.SweepKeeper`), in ``--out``."""


FIG6_TITLE = "Fig. 6: evaluation value for each Young's modulus and initial deformation (cube)"


def parse_axis_spec(option: str, spec: str) -> np.ndarray:
    """Parse ``start:stop:count``, ``a,b,c`` or ``x`` into a 1-D float array.

    Every value is the float nearest to the decimal number it stands for: ``0.1:0.5:5``
    gives ``0.4``, not ``np.linspace``'s ``0.39999999999999997``, so that the CSV shows
    the values as typed (`_decimal_range`).

    Raises:
        UsageError: malformed spec, or a range of more than `MAX_GRID_POINTS` (one
            line, naming the option), before the array is allocated.
    """
    parsed = _parse_spec(option, spec)
    if isinstance(parsed, np.ndarray):
        return parsed
    return _decimal_range(*parsed)


def _parse_spec(option: str, spec: str) -> np.ndarray | tuple[str, str, int]:
    """A list or number as its array; a range as its checked ``(start, stop, count)`` text
    and count, not yet expanded (its count is checked against the cap first): the parser
    checked the spec already (`jaxgrasp.cli._arguments.axis_spec`), the paper's axes not."""
    parsed = axis_spec(option, spec)
    return np.asarray(parsed, dtype=np.float64) if isinstance(parsed, list) else parsed


def _decimal_range(start: str, stop: str, count: int) -> np.ndarray:
    """``count`` evenly spaced values from ``start`` to ``stop`` (decimal texts), each the
    float nearest to its exact decimal value.

    Where the step is a terminating decimal (``1e-4`` for ``1e-3:5e-3:41``), every value
    is an integer times a power of ten, both exact in float64, so one IEEE division (or
    product) rounds it correctly; otherwise (``0:1:4``, step 1/3) ``np.linspace``, whose
    endpoints are the typed numbers.
    """
    a, b = Decimal(start), Decimal(stop)
    if count == 1:
        return np.asarray([float(a)])
    with localcontext() as ctx:
        ctx.prec = 60
        ctx.clear_flags()
        step = (b - a) / (count - 1)
        exact = not ctx.flags[Inexact]  # a terminating decimal step (not 1/3)
    digits = -min(a.as_tuple().exponent, step.normalize().as_tuple().exponent) if exact else None
    if digits is None or abs(digits) > 22:  # 10**22 is the largest power of ten exact in float64
        return np.linspace(float(a), float(b), count)
    first, inc = int(a.scaleb(digits)), int(step.scaleb(digits))
    if max(abs(first), abs(first + (count - 1) * inc)) >= 2**53:  # not every integer exact in float64
        return np.linspace(float(a), float(b), count)
    n = (first + inc * np.arange(count, dtype=np.int64)).astype(np.float64)
    return n / 10.0**digits if digits >= 0 else n * 10.0**-digits


# --------------------------------------------------------------------------- the command


def run(args) -> int:
    """Sweep the grasp of the command line; write the files and print one summary line."""
    from jaxgrasp.analysis import check_inputs, grid_grasp, sweep
    from jaxgrasp.cli._keepers import SweepKeeper
    from jaxgrasp.engine import plan_chunks

    axes, paper = _parse_axes(args)
    check_chunk_size(args.chunk_size)
    grasp = load_grasp(args, overrides=False)
    check_inputs(grasp, chunk_size=args.chunk_size, **axes)  # bad input: nothing touched yet
    out = Path(args.out)
    check_out(out)

    plan = plan_chunks(int(np.prod([a.size for a in axes.values()])), args.chunk_size, auto=True)
    if not args.no_plot:
        prefetch("jaxgrasp.plots._plots")  # matplotlib's import overlaps the compile
    with lock_out(out):
        progress = ChunkProgress("sweeping", "point", show=not args.quiet)
        announce_run("sweep", grasp_source(args), plan.total, "point", args.quiet)
        t_start = time.perf_counter()
        keeper = SweepKeeper(out / PARTIAL_NAME, grasp, axes, plan.chunk)
        result = sweep(grasp, chunk_size=plan.chunk, progress=progress, on_chunk=keeper, **axes)
        wall = time.perf_counter() - t_start

        title = f"jaxgrasp sweep: {grasp_source(args)}"
        if paper and args.preset == "cube" and args.file is None:
            title = FIG6_TITLE
        extra = epsilon_columns(grid_grasp(grasp, **axes), result.shape) if args.epsilon else None
        written, replaced, removed = _write_outputs(result, out, None if args.no_plot else title, extra)
    print(_summary_line(result, grasp_source(args), wall, out, written, replaced, removed))
    return 0


def _parse_axes(args) -> tuple[dict[str, np.ndarray], bool]:
    """The axes given on the command line, in the order given, or the paper's; (axes,
    whether the paper's). The grid's size is checked against `MAX_GRID_POINTS`
    before any axis is expanded."""
    order = getattr(args, "axis_order", None) or AXES  # AXES: a namespace not made by the parser
    given = {n: getattr(args, n) for n in order if getattr(args, n, None) is not None}
    paper = not given
    specs = dict(PAPER_AXES) if paper else given
    parsed = {n: _parse_spec(FIELD[n].option, s) for n, s in specs.items()}
    sizes = [p.size if isinstance(p, np.ndarray) else p[2] for p in parsed.values()]
    total = math.prod(sizes)
    if total > MAX_GRID_POINTS:
        shape = " x ".join(f"{k:,}" for k in sizes)
        raise UsageError(
            f"the grid has {total:,} points ({shape}), more than the {MAX_GRID_POINTS:,} a sweep may have "
            "(its results and CSV must fit in memory); use fewer points per axis or split the sweep"
        )
    axes = {n: p if isinstance(p, np.ndarray) else _decimal_range(*p) for n, p in parsed.items()}
    return axes, paper


def _write_outputs(result, out: Path, title: str | None, extra=None) -> tuple[list[str], list[str], list[str]]:
    """Write ``sweep.npz``, ``sweep.csv`` and (with a ``title``) ``sweep.png`` as one set.

    The set replaces the previous one at once, removing a previous ``sweep.png`` that the
    new set lacks, and the checkpoint ``sweep.partial.npz``. Returns the names written,
    those that replaced a previous file and the previous files removed.
    """
    members = {
        out / "sweep.npz": lambda fh: result.to_npz(fh, extra),
        out / "sweep.csv": lambda fh: result.to_csv(fh, extra),
    }
    if title is not None:
        from jaxgrasp.plots import plot_sweep, save_figure

        fig = plot_sweep(result, title=title)
        members[out / "sweep.png"] = lambda fh: save_figure(fig, fh, format="png")
    stale = [out / n for n in OUTPUT_NAMES if out / n not in members and (out / n).exists()]
    try:
        replaced = storage.write_set(
            members,
            remove=stale + [out / PARTIAL_NAME],
            on_publish=lambda: _published(out),
        )
    except OSError as exc:
        raise UsageError(f"cannot write to --out {str(out)!r}: {exc.strerror or exc}") from None
    return [p.name for p in members], [p.name for p in replaced], [p.name for p in stale]


def _published(out: Path) -> None:
    """The whole set is in place: an interrupt now only says so (no checkpoint to write)."""
    _notes.set_last_write("sweep", None)
    _notes.set_note("sweep", f"the results are in {out}")


def _fmt_param(name: str, x: float) -> str:
    unit = FIELD[name].unit
    return f"{name}={x:.6g}" + (f" {unit}" if unit else "")


def _best_text(result) -> str:
    best = result.best()
    if best is None:
        return "best: none (no converged point)"
    if best["status"] != "stable":  # every trusted point has value 0
        return "best: none (no stable point)"
    where = ", ".join(_fmt_param(n, best[n]) for n in result.axes)
    lim = (
        f"{best['limiting_kind']} of contact {best['limiting_contact']}"
        if best["limiting_contact"] != NO_BOUNDARY
        else best["status"]
    )
    return f"best {best['value']:.6e} J at {where} ({lim})"


def _summary_line(
    result, source: str, wall: float, out: Path, written: list[str], replaced=(), removed=()
) -> str:
    c = result.counts()
    shape = " x ".join(f"{len(a)} {n}" for n, a in result.axes.items())
    return (
        f"sweep {source}: {counted(result.size, 'point')} ({shape}); "
        f"stable {c['stable']}, unstable {c['unstable']}, infeasible {c['infeasible']}, "
        f"not_converged {c['not_converged']}; {_best_text(result)}; "
        f"wall {wall:.1f} s (compile {result.compile_seconds:.1f} s, run {result.run_seconds:.1f} s); "
        f"wrote {out}/{{{','.join(written)}}}"
        + replaced_text(replaced, removed)
    )
