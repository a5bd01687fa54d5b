"""``jaxgrasp tune FILE`` for a hand grasp file: tune the hand's joints (and with
``--tune-wrist`` its wrist) by [`jaxgrasp.tune_hand`][jaxgrasp.tune_hand]; write the tuned
configuration as a hand grasp file and the value over the iterations beside it.

The tuned file is the input's tables with the tuned ``qpos`` and ``wrist``, its ``mjcf`` and
``mesh`` rewritten relative to the tuned file's folder, so that it loads again where it
is written: a file it names must lie in that folder or in an ``--allow-dir`` folder (the
rule every hand grasp file is read by, `jaxgrasp.hands._file`), else the command refuses
before tuning (one line naming the file and the fix). The file and its plot replace the
previous ones as one set (`jaxgrasp.storage.write_set`).
"""

from __future__ import annotations

import os
import time
import tomllib
from pathlib import Path

from jaxgrasp.analysis import METHODS
from jaxgrasp.cli._common import UsageError, say, write_with_plot
from jaxgrasp.model import counted

__all__ = ["run_hand"]


def run_hand(args, out: Path) -> int:
    """Tune the hand grasp of ``args.file`` (``--out`` already checked writable); write the
    tuned hand grasp file and its plot; one summary line."""
    from jaxgrasp.cli._hand_files import load_hand
    from jaxgrasp.hands import tune_hand
    from jaxgrasp.tolerance import EvaluateOptions

    _check_hand_options(args, out)
    hg = load_hand(args)
    tables = _tuned_tables(args, out)  # before tuning: the paths the tuned file will name
    obj, tip = tables["object"], tables["fingertip"]
    fields = {k: obj[k] for k in ("mass", "density", "units") if k in obj} | {k: tip[k] for k in tip}
    if not args.quiet:
        say(f"jaxgrasp: tuning the joints{' and the wrist' if args.tune_wrist else ''} of {args.file} "
            f"({len(hg.hand.joint_names)} joints, {hg.num_active} fingertips in contact), at most "
            f"{counted(args.maxiter, 'iteration')}; compiling the value and its gradient first")
    res = tune_hand(hg.hand, hg.mesh, hg.qpos, hg.wrist, object_pose=obj.get("pose"), tune_wrist=args.tune_wrist,
                    maxiter=args.maxiter, options=EvaluateOptions(smooth_min_temperature=args.smooth_min_temperature),
                    callback=_progress(args.quiet), **{k: v for k, v in fields.items() if k != "units"})
    tables["hand"] = {**tables["hand"], "qpos": res.qpos, "wrist": res.wrist}
    replaced = _write(tables, res, out, None if args.no_plot else f"jaxgrasp tune: {args.file}")
    print(_summary(res, args.file, out, args.no_plot, replaced))
    return 0


def _check_hand_options(args, out: Path) -> None:
    """Refuse what has no meaning for a hand: ``--param``, ``--bounds``, another ``--method``,
    a ``.json`` output (the overrides are refused by `load_hand`)."""
    for option, given in (("--param", args.param), ("--bounds", args.bounds)):
        if given:
            raise UsageError(f"{option}: not used with a hand grasp file ({args.file}): its joint angles are tuned "
                             "within their limits (--tune-wrist: the wrist too)")
    if args.method != METHODS[0]:
        raise UsageError(f"--method {args.method}: a hand grasp is tuned by {METHODS[0]} alone")
    if out.suffix.lower() != ".toml":
        raise UsageError(f"--out {str(out)!r}: a tuned hand grasp is written as a hand grasp file; name a .toml file")


def _tuned_tables(args, out: Path) -> dict:
    """The input's tables with the hand file (``model`` or ``mjcf``) and ``mesh`` relative to ``out``'s folder; a
    `UsageError` where the tuned file could not read one of them from there."""
    from jaxgrasp.io import allowed_folders

    src = Path(args.file)
    with open(src, "rb") as fh:  # read and checked by load_hand already
        tables = tomllib.loads(fh.read().decode("utf-8-sig"))
    there = os.path.realpath(out.parent)
    folders = (there, *allowed_folders(args.allow_dir))
    model = "model" if "model" in tables["hand"] else "mjcf"  # load_hand checked that it has one of them
    for table, key in (("hand", model), ("object", "mesh")):
        real = os.path.realpath(os.path.join(src.parent, tables[table][key]))
        if not any(os.path.commonpath([real, f]) == f for f in folders):
            raise UsageError(
                f"--out {str(out)!r}: the tuned file would name [{table}] {key} {real!r}, outside its folder "
                f"{there!r}, and could not be read again; write it in a folder that holds that file, or pass "
                f"--allow-dir {os.path.dirname(real)!r} (and again when reading the tuned file)")
        tables[table] = {**tables[table], key: os.path.relpath(real, there)}
    return tables


def _progress(quiet: bool):
    """``callback(iteration, value, x)`` of `tune_hand`: one line per iteration on stderr."""
    t0 = time.perf_counter()

    def progress(it, value, _x):
        if not quiet:
            note = " (includes compilation)" if it == 1 else ""
            say(f"jaxgrasp: iteration {it}: value {value:.6e} J, elapsed {time.perf_counter() - t0:.1f} s{note}")

    return progress


def _write(tables: dict, res, out: Path, title: str | None) -> list[str]:
    """The tuned hand grasp file and (with a ``title``) its plot, as one set; the names of
    the previous files they replaced."""
    from jaxgrasp.hands import hand_grasp_toml

    figure = None
    if title is not None:
        from jaxgrasp.plots import plot_hand_history

        figure = plot_hand_history(res, title=title)
    return write_with_plot({out: hand_grasp_toml(tables).encode("utf-8")}, out, figure)


def _summary(res, source: str, out: Path, no_plot: bool, replaced: list[str]) -> str:
    """``tune SOURCE: value A J -> B J (xG, N iterations, STATUS: why); deepest link
    penetration D mm (start S mm); fingertips in contact K (names); wrote FILES``."""
    import numpy as np

    hg = res.grasp
    tips = ", ".join(f"{k} {n}" for k, (n, a) in enumerate(zip(hg.hand.fingertip_names, np.asarray(hg.active))) if a)
    return (
        f"tune {source}: value {res.start_value:.6e} J -> {res.value:.6e} J (x{res.gain:.4f}, "
        f"{counted(res.iterations, 'iteration')}, {res.status_name}: {res.message}); deepest link penetration "
        f"{1e3 * res.deepest:.3f} mm (start {1e3 * res.start_deepest:.3f} mm; negative: clear); fingertips in "
        f"contact: {tips}; wrote {out}" + ("" if no_plot else f", {out.with_suffix('.png')}")
        + (f" (replacing the previous {', '.join(replaced)})" if replaced else "")
    )
