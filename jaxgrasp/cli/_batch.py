"""``jaxgrasp batch``: evaluate and rank every grasp of a dataset file; write csv, npz and a picture.

The dataset is a ``.npz`` or ``.jsonl`` file (`jaxgrasp.io._dataset`), grasps with any
contact counts, padded to the largest and evaluated in chunks by one compiled evaluator
([`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch]). An invalid grasp does not stop the run: its row has
status ``invalid`` and its one-line error (``--strict``: exit 2 before computing).

Nothing finished is lost: each finished chunk is kept at once in ``DIR/results.partial``
(`jaxgrasp.cli._keepers.BatchCheckpoint`, one atomic file per chunk), so a run stopped at
any moment (Ctrl-C, SIGTERM, ``kill -9``) is finished by ``--resume`` without
recomputing those chunks; a resumed run must read the same dataset and the same mesh files
its rows name (`resume_key`), and a chunk file that is not this run's (its digest over its
rows' inputs and the options, `batch_checkpoint`) is evaluated again, never merged. At the
end ``results.csv``, ``results.npz`` and ``results.png`` replace the previous ones as one
set and the checkpoint is removed.
"""

from __future__ import annotations

import contextlib
import hashlib
import time
from pathlib import Path

import jax
import numpy as np

from jaxgrasp import storage
from jaxgrasp.cli import _batch_processes as processes
from jaxgrasp.cli import _notes
from jaxgrasp.cli._common import (
    ChunkProgress,
    UsageError,
    announce_run,
    check_chunk_size,
    check_out,
    epsilon_columns,
    lock_out,
    replaced_text,
    robust_uncertainty,
    say,
)
from jaxgrasp.cli._hand_batch import hand_input, load_hand_data
from jaxgrasp.engine import prefetch
from jaxgrasp.model import counted

__all__ = ["run", "resume_key", "batch_checkpoint", "OUTPUT_NAMES", "PARTIAL_NAME"]

OUTPUT_NAMES = ("results.csv", "results.npz", "results.png")
"""The files of one batch's output set, in ``--out``."""

PARTIAL_NAME = "results.partial"
"""The checkpoint folder of the finished chunks (`jaxgrasp.cli._keepers.BatchCheckpoint`), in ``--out``."""

# --------------------------------------------------------------------------- the command


def run(args) -> int:
    """Evaluate the dataset of the command line; write the files and print a summary."""
    from jaxgrasp.engine import evaluate_dataset, grasps_by_count, plan_widths
    from jaxgrasp.io import load_dataset

    _check_numbers(args)
    uncertainty = robust_uncertainty(args)
    hands = hand_input(args)
    if processes.check_process_options(args):
        return run_processes(args, uncertainty)
    out = Path(args.out)
    if hands:
        check_out(out)  # before the fingertips are placed, which takes a while on a large dataset
    hand_data = load_hand_data(args) if hands else None
    gset = hand_data.grasps if hands else load_dataset(args.file, allowed_dirs=args.allow_dir)
    if args.strict:
        gset.raise_if_invalid()
    if not gset.valid.any():
        raise UsageError(f"{args.file}: no valid grasp ({len(gset)} invalid; first: {gset.errors[0]})")
    check_out(out)
    widths = plan_widths(grasps_by_count(gset.num_contacts), jax.devices()[0].platform)  # what evaluate_dataset picks

    t_start = time.perf_counter()
    with lock_out(out):
        checkpoint = batch_checkpoint(out, args.file, gset, widths)
        rows, results = _open_checkpoint(checkpoint, args.resume, len(gset))
        progress = ChunkProgress("evaluating", "grasp", show=not args.quiet)
        announce_run("batch", args.file, int(np.count_nonzero(np.delete(gset.valid, rows))), "grasp", args.quiet)
        if not args.no_plot:  # after the first line, which a thread importing matplotlib would delay
            prefetch("jaxgrasp.plots._plots")  # matplotlib's import overlaps the compile
        merged, result = evaluate_dataset(
            gset, done=(rows, results), on_chunk_rows=checkpoint.keeper(rows.size, len(gset)),
            chunk_size=args.chunk_size, progress=progress, widths=widths,
        )
        wall = time.perf_counter() - t_start
        extra = hand_data.columns() if hands else {}  # contact k is fingertip k: their columns first
        if args.epsilon:
            extra.update(_epsilon(gset))
        if uncertainty is not None:
            extra.update(_robust(gset, uncertainty, args))
        written, replaced, removed = _write_outputs(merged, out, checkpoint, args, extra)
    names = hand_data.fingertip_names if hands else None
    print(_summary(merged, args.file, wall, _timing(result, rows.size), out, written, replaced, removed, args.top,
                   names))
    if uncertainty is not None:
        print(_robust_line(extra, uncertainty, args))
    return 0


def run_processes(args, uncertainty) -> int:
    """The command as process ``--process-id`` of ``--num-processes`` (see
    `_batch_processes`): join the others, evaluate this process's share of the
    dataset on this host's devices, meet the others; process 0 writes the files in input
    order and prints the summary, the others one line."""
    from jaxgrasp.cli._hosts import join, leave

    out, me = Path(args.out), args.process_id
    if not args.no_plot and me == 0:
        prefetch("jaxgrasp.plots._plots")
    t_start = time.perf_counter()
    join(args.coordinator, args.num_processes, me)
    try:
        with contextlib.ExitStack() as held:
            opened, failure = processes.attempt(lambda: processes.open_share(args, out, out / PARTIAL_NAME, held))
            n_contacts, counts = processes.agree_on_inputs(opened, failure)
            blob, failure = processes.attempt(lambda: _evaluate_share(opened[0], n_contacts, counts, uncertainty, args))
            merged, extra, timing = processes.gather_results(blob, failure, opened[1], n_contacts, jax.device_count())
            if me != 0:
                print(f"batch {args.file}: process {me} of {args.num_processes} ({jax.local_device_count()} of "
                      f"{merged.devices} devices): evaluated {counted(int(opened[0].valid.sum()), 'grasp')} "
                      f"of its share; process 0 writes {out}")
                return 0
            wall = time.perf_counter() - t_start
            written, replaced, removed = _write_outputs(merged, out, None, args, extra)
    finally:
        leave()
    timing = (f"{timing['processes']} processes, {merged.devices} devices: longest compile "
              f"{merged.compile_seconds:.1f} s, longest run {merged.run_seconds:.1f} s, "
              f"{timing['evaluated'] / max(merged.run_seconds, 1e-9):.1f} grasps per second in all")
    print(_summary(merged, args.file, wall, timing, out, written, replaced, removed, args.top))
    if uncertainty is not None:
        print(_robust_line(extra, uncertainty, args))
    return 0


def _evaluate_share(share, n_contacts: int, counts: dict[int, int], uncertainty, args) -> bytes:
    """This process's share evaluated on its own devices, padded to the dataset's
    ``n_contacts``, each contact count at the width a run of one process gives it (from
    the dataset's ``counts``, ``{count: grasps}``), with its ``--epsilon`` and
    ``--robust`` columns: what it sends process 0 (`_batch_processes.share_blob`)."""
    from jaxgrasp.engine import evaluate_dataset, plan_widths
    from jaxgrasp.io import padded_set

    if not share.valid.any():
        return processes.share_blob(share, None, None, {})
    share, local = padded_set(share, n_contacts), jax.local_devices()
    progress = ChunkProgress("evaluating", "grasp", show=not args.quiet)
    announce_run("batch", f"{args.file} (share {args.process_id} of {args.num_processes})",
                 int(share.valid.sum()), "grasp", args.quiet)
    widths = plan_widths(counts, local[0].platform)
    merged, run = evaluate_dataset(share, chunk_size=args.chunk_size, progress=progress, devices=local, widths=widths)
    extra = _epsilon(share) if args.epsilon else {}
    if uncertainty is not None:
        extra.update(_robust(share, uncertainty, args, devices=local))
    return processes.share_blob(share, merged, run, extra)


def resume_key(gset) -> str:
    """The checkpoint's ``source_sha256``: what a resumed run must have read again. The
    dataset's bytes' SHA-256 where its rows name no mesh; otherwise the SHA-256 of that
    and of every mesh file read (real path and bytes' SHA-256, sorted by path), so that
    editing a mesh the dataset names refuses ``--resume`` (its rows would change)."""
    if not gset.mesh_sha256:
        return gset.source_sha256
    lines = [f"dataset {gset.source_sha256}"] + [f"mesh {sha} {path}" for path, sha in sorted(gset.mesh_sha256.items())]
    return hashlib.sha256("\n".join(lines).encode("utf-8", "surrogateescape")).hexdigest()


def batch_checkpoint(out: Path, source: str, gset, widths):
    """The checkpoint ``jaxgrasp batch`` keeps in ``out`` for dataset ``gset`` read from
    ``source``, run at ``widths`` (`plan_widths`) with the default options
    (`jaxgrasp.cli._keepers.BatchCheckpoint`): each chunk's digest covers its rows' grasp
    fields and contact counts and the run's key (`run_key`: options, widths, platform,
    jaxgrasp's source, JAX's version), so that a chunk copied from another run is evaluated
    again, not merged."""
    from jaxgrasp.cli._keepers import BatchCheckpoint
    from jaxgrasp.engine import run_key
    from jaxgrasp.tolerance import EvaluateOptions

    columns = gset.columns()
    return BatchCheckpoint(out / PARTIAL_NAME, source, resume_key(gset), len(gset), int(gset.num_contacts.max()),
                           inputs={**columns.fields, "counts": columns.counts, "active": columns.active},
                           key=run_key(EvaluateOptions(), widths, jax.devices()[0].platform))


def _check_numbers(args) -> None:
    check_chunk_size(args.chunk_size)
    if args.top < 0:
        raise UsageError(f"--top must be >= 0, got {args.top}")


def _open_checkpoint(checkpoint, resume: bool, total: int) -> tuple[np.ndarray, dict]:
    """The rows a previous run finished (``--resume``) and their results, saying so; a
    fresh checkpoint otherwise. An unfinished run's checkpoint is never overwritten silently."""
    from jaxgrasp.engine import CheckpointBusy

    try:
        rows, results, resumed = checkpoint.open(resume)
    except CheckpointBusy as busy:
        raise UsageError(
            f"--out: {busy.folder} holds an unfinished run: add --resume to finish it, "
            "or remove that folder to start afresh"
        ) from None
    except ValueError as exc:
        raise UsageError(f"--resume: {exc}") from None
    if resumed:
        say(f"jaxgrasp: resuming: {rows.size} of {counted(total, 'grasp')} were finished in {checkpoint.folder}")
        if checkpoint.skipped_note():  # damaged chunk files: their rows are evaluated again
            say(checkpoint.skipped_note())
    elif resume:
        say(f"jaxgrasp: --resume: no unfinished run in {checkpoint.folder.parent}; starting afresh")
    return rows, results


def _write_outputs(result, out: Path, checkpoint, args, extra=None) -> tuple[list[str], list[str], list[str]]:
    """Write ``results.csv``, ``results.npz`` and (unless ``--no-plot``) ``results.png``
    as one set, removing the checkpoint (``None``: none was kept) in the same step;
    ``extra``: more columns (``--epsilon``)."""
    members = {
        out / "results.csv": lambda fh: result.to_csv(fh, extra),
        out / "results.npz": lambda fh: result.to_npz(fh, extra),
    }
    if not args.no_plot:
        from jaxgrasp.plots import plot_ranking, save_figure

        fig = plot_ranking(result, top=args.top, title=f"jaxgrasp batch: {args.file} ({counted(len(result), 'grasp')})")
        members[out / "results.png"] = lambda fh: save_figure(fig, fh, format="png")
    stale = [out / n for n in OUTPUT_NAMES if out / n not in members and (out / n).exists()]
    try:
        replaced = storage.write_set(
            members,
            remove=stale + (checkpoint.files() if checkpoint is not None else []),
            on_publish=lambda: _notes.set_note("batch", f"the results are in {out}"),
        )
    except OSError as exc:
        raise UsageError(f"cannot write to --out {str(out)!r}: {exc.strerror or exc}") from None
    try:
        if checkpoint is not None:
            checkpoint.folder.rmdir()
    except OSError:
        pass  # something else was put there: leave it
    return [p.name for p in members], [p.name for p in replaced], [p.name for p in stale]


def _epsilon(gset) -> dict:
    """The ``--epsilon`` columns of every input row (NaN and False for an invalid grasp)."""
    from jaxgrasp.model import Grasp

    columns = gset.columns()
    valid = columns.valid
    batch = Grasp(**{k: a[valid] for k, a in columns.fields.items()}, active=columns.active[valid])
    cols = epsilon_columns(batch)
    out = {"epsilon": np.full(len(gset), np.nan), "force_closure": np.zeros(len(gset), dtype=bool)}
    for k, v in cols.items():
        out[k][valid] = v
    return out


def _robust(gset, uncertainty, args, devices=None) -> dict:
    """The ``--robust`` columns of every input row ([`jaxgrasp.analysis.RobustBatch.columns`][jaxgrasp.analysis.RobustBatch.columns]:
    ``p_stable``, ``p_stable_stderr``, ``value_mean``, ``value_q05``, ``value_q50``), NaN
    for an invalid grasp; every valid grasp's samples through one compiled evaluator,
    on ``devices`` (default every device)."""
    from jaxgrasp.analysis import robust_batch
    from jaxgrasp.model import Grasp

    columns = gset.columns()
    valid = columns.valid
    active = columns.active[valid]
    batch = Grasp(**{k: a[valid] for k, a in columns.fields.items()}, active=None if active.all() else active)
    progress = ChunkProgress("evaluating robust samples:", "perturbed grasp", show=not args.quiet)
    rb = robust_batch(batch, uncertainty, args.samples, args.seed, chunk_size=args.chunk_size, progress=progress,
                      devices=devices)
    out = {}
    for name, col in rb.columns().items():
        out[name] = np.full(len(gset), np.nan)
        out[name][valid] = col
    return out


def _robust_line(columns: dict, uncertainty, args) -> str:
    """The summary's line of ``--robust``: the spreads, the samples, the most robust grasp."""
    p = columns["p_stable"]
    best = int(np.nanargmax(np.nan_to_num(columns["value_mean"], nan=-np.inf)))
    return (
        f"robust: {uncertainty.to_spec()}; {args.samples} samples per grasp, seed {args.seed}; "
        f"mean p_stable {np.nanmean(p):.4f}; best value_mean: grasp {best} ({columns['value_mean'][best]:.6e} J, "
        f"p_stable {p[best]:.4f}); columns p_stable, value_mean, value_q05 in results.csv"
    )


def _timing(run, resumed: int) -> str:
    """The summary's timings of this run's evaluation (``run``: its
    [`BatchResult`][jaxgrasp.BatchResult], ``None`` where nothing was left), with the rows
    ``resumed`` from a checkpoint."""
    timing = "no chunk left to evaluate" if run is None else (
        f"compile {run.compile_seconds:.1f} s, run {run.run_seconds:.1f} s, "
        f"{len(run) / max(run.run_seconds, 1e-9):.1f} grasps per second"
    )
    return timing + (f"; {resumed} resumed from the checkpoint" if resumed else "")


def _summary(result, source, wall, timing, out, written, replaced, removed, top, names=None) -> str:
    """The summary: counts, ``timing`` (`_timing`), files, then the ``top`` best
    grasps, one per line."""
    c = result.counts()
    counts = ", ".join(f"{k} {v}" for k, v in c.items() if v or k != "invalid")
    valid = result.num_contacts[result.num_contacts > 0]
    span = f"{valid.min()}-{valid.max()}" if valid.min() != valid.max() else f"{valid.min()}"
    lines = [
        f"batch {source}: {counted(len(result), 'grasp')} ({span} contacts); {counts}; "
        f"wall {wall:.1f} s ({timing}); wrote {out}/{{{','.join(written)}}}"
        + replaced_text(replaced, removed)
    ]
    lines += _top_lines(result, top, names)
    if c.get("invalid"):
        first = next(e for e in result.errors if e)
        lines.append(f"note: {counted(c['invalid'], 'invalid grasp')} not evaluated (first: {first}); see the error column")
    return "\n".join(lines)


def _contact(result, i: int, names) -> str:
    """Grasp ``i``'s limiting contact: its number, and where the contacts are a hand's
    fingertips (``names``), the fingertip's name: ``4 (robot0:C_thdistal)``."""
    k = int(result.limiting_contact[i])
    return f"{k} ({names[k]})" if names is not None and 0 <= k < len(names) else str(k)


def _top_lines(result, top: int, names=None) -> list[str]:
    """``top`` lines: rank, input index, value, contacts and limiting boundary of the best
    stable grasps."""
    from jaxgrasp.tolerance import GraspStatus

    best = [int(i) for i in result.rank()[:top] if result.status[i] == GraspStatus.STABLE]
    if top and not best:
        return ["top: none (no stable grasp)"]
    width = len(str(max(best, default=0)))
    lines = []
    for r, i in enumerate(best, start=1):
        kind = result.limiting_kind_names[i]
        lines.append(
            f"  #{r} grasp {i:>{width}}: {float(result.value[i]):.6e} J "
            f"({result.num_contacts[i]} contacts; limited by {kind} of contact {_contact(result, i, names)})"
        )
    return [f"top {len(best)}:"] + lines if lines else []
