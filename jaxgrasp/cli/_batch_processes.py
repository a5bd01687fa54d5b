"""``jaxgrasp batch`` over several processes joined by ``jax.distributed`` (``--num-processes``).

Each process (one per host, or several on one) runs the same command with its own
``--process-id``; process 0 is also the coordinator (``--coordinator HOST:PORT``, an
address every process reaches). Process ``i`` of ``P`` reads, validates and evaluates its
share of the dataset, the grasps ``i, i + P, i + 2P, ...``
(`share_rows`), on its own devices
(``jax.local_devices()``), through the same engine as one process
(`evaluate_dataset`). The processes meet twice
(`exchange`): once every share is read (the dataset's
largest contact count, which every share is padded to, so that every process runs the
program one process would, but where a share of a mixed dataset holds only grasps of the
largest count: that one runs without a contact mask, equal to round-off; the file's SHA-256, which must be the same everywhere; and
whether any process failed), and once the shares are evaluated (their results, to
process 0). Process 0 alone writes ``--out`` (its files as one set, in input order, as
one process would); the others write nothing there.

An error in any process (a bad option, a file one host cannot read, ``--strict`` and an
invalid grasp, an ``--out`` process 0 cannot write) ends every process at the next
meeting, each with one line naming the process. There is no checkpoint: ``--resume``
is refused, and a run whose process dies must be started again.
"""

from __future__ import annotations

import json
from typing import Any, Callable

import numpy as np

from jaxgrasp.cli._common import UsageError, check_out, lock_out
from jaxgrasp.cli._hosts import exchange, pack, parse_coordinator, unpack
from jaxgrasp.engine import BatchResult, mark_invalid
from jaxgrasp.engine import grasps_by_count
from jaxgrasp.io import load_share, share_rows
from jaxgrasp.tolerance import FIELDS, Evaluation

__all__ = ["check_process_options", "attempt", "open_share", "agree_on_inputs",
           "share_blob", "gather_results"]


def check_process_options(args) -> bool:
    """Whether the run has several processes; one-line errors for options that do not
    go together. ``--num-processes 1`` is a run of one process."""
    named = {"--coordinator": args.coordinator, "--num-processes": args.num_processes,
             "--process-id": args.process_id}
    missing = [k for k, v in named.items() if v is None]
    if len(missing) == 3:
        return False
    if missing:
        raise UsageError(f"--coordinator, --num-processes and --process-id go together: {', '.join(missing)} missing")
    try:
        parse_coordinator(args.coordinator)
    except ValueError as exc:
        raise UsageError(f"--coordinator {exc}") from None
    if args.num_processes < 1:
        raise UsageError(f"--num-processes must be >= 1, got {args.num_processes}")
    if not 0 <= args.process_id < args.num_processes:
        raise UsageError(f"--process-id must be in 0..{args.num_processes - 1}, got {args.process_id}")
    if args.resume and args.num_processes > 1:
        raise UsageError("--resume finishes a run of one process; a run of several processes keeps no checkpoint")
    return args.num_processes > 1


def attempt(fn: Callable[[], Any]) -> tuple[Any, BaseException | None]:
    """``(fn(), None)``, or ``(None, the exception)`` where ``fn`` raised one: a process
    that fails still goes to the next meeting, so that the others do not wait for it."""
    try:
        return fn(), None
    except Exception as exc:  # noqa: BLE001 - passed on to every process, raised here after the meeting
        return None, exc


def _raise_first(failures: list[str | None], mine: BaseException | None) -> None:
    """After a meeting: this process's own exception, else a one-line error naming the
    first process that failed; nothing where none did."""
    if mine is not None:
        raise mine
    for p, text in enumerate(failures):
        if text is not None:
            raise UsageError(f"process {p} of {len(failures)} failed: {text}")


def open_share(args, out, partial, held) -> tuple:
    """Read this process's share of ``args.file`` (``--strict``: none invalid); process 0
    also checks ``--out``, which must hold no unfinished run (a checkpoint folder
    ``partial``), and takes its lock (held by ``held``, a `contextlib.ExitStack`).
    ``(share, the file's grasps)``."""
    share, total = load_share(args.file, args.process_id, args.num_processes, allowed_dirs=args.allow_dir)
    if args.strict:
        share.raise_if_invalid()
    if args.process_id == 0:
        check_out(out)
        held.enter_context(lock_out(out))
        if partial.exists():
            raise UsageError(
                f"--out: {partial} holds an unfinished run of one process: finish it with --resume "
                "in one process, or remove that folder"
            )
    return share, total


def agree_on_inputs(opened, failure: BaseException | None) -> tuple[int, dict[int, int]]:
    """The first meeting: every process's share read (``opened``: ``(share, total)``, or
    ``None`` with its ``failure``). Returns the dataset's largest contact count and its
    valid grasps by contact count (``{count: grasps}``, from which every process plans
    the same widths, `plan_widths`); raises where any
    process failed, where the processes read different files (by SHA-256 and number of
    grasps), or where the dataset has no valid grasp."""
    facts = {"failure": None if failure is None else str(failure)}
    if opened is not None:
        share, total = opened
        counts = {str(c): n for c, n in grasps_by_count(share.num_contacts).items()}  # JSON: keys are text
        facts.update(contacts=int(share.num_contacts.max(initial=0)), valid=int(share.valid.sum()), total=total,
                     sha256=share.source_sha256, counts=counts)
    every = [json.loads(b) for b in exchange(json.dumps(facts).encode())]
    _raise_first([f["failure"] for f in every], failure)
    if len({(f["total"], f["sha256"]) for f in every}) > 1:
        seen = "; ".join(f"process {p}: {f['total']} grasps, SHA-256 {f['sha256'][:12]}" for p, f in enumerate(every))
        raise UsageError(f"the processes read different datasets ({seen}): give every host the same file")
    if not sum(f["valid"] for f in every):
        raise UsageError(f"{opened[0].source}: no valid grasp ({opened[1]} invalid)")
    histogram: dict[int, int] = {}
    for f in every:
        for c, n in f["counts"].items():
            histogram[int(c)] = histogram.get(int(c), 0) + n
    return max(f["contacts"] for f in every), dict(sorted(histogram.items()))


def share_blob(share, merged, run, extra: dict) -> bytes:
    """What a process sends process 0: its share's results (``merged``, the
    [`BatchResult`][jaxgrasp.BatchResult] of its rows, ``None`` where none is valid), contact
    counts, errors, ``extra`` columns (``--epsilon``, ``--robust``) and timings (``run``:
    the evaluation's [`BatchResult`][jaxgrasp.BatchResult])."""
    arrays = {f"extra.{k}": np.asarray(v) for k, v in extra.items()}
    arrays.update(num_contacts=np.asarray(share.num_contacts, dtype=np.int64),
                  error=np.asarray([e or "" for e in share.errors], dtype=str),
                  timing=np.asarray([0.0, 0.0, 0.0] if run is None else
                                    [run.compile_seconds, run.run_seconds, len(run)]))
    if merged is not None:
        arrays.update({f: np.asarray(getattr(merged, f)) for f in FIELDS})
    return pack(arrays)


def gather_results(blob, failure, total: int, n_contacts: int, devices: int):
    """The second meeting: every process's `share_blob` (``None`` with its
    ``failure``), put together in input order. ``(BatchResult of every row, extra columns,
    timing)`` (``timing``: the longest compile and run of the processes, s, and the
    grasps evaluated); raises where any process failed."""
    every = exchange(b"" if blob is None else blob)
    _raise_first([None if b else "its evaluation failed (see its own error)" for b in every], failure)
    parts = [unpack(b) for b in every]
    count = len(parts)
    num_contacts = np.zeros(total, dtype=np.int64)
    errors = np.empty(total, dtype=object)
    arrays, extra = {}, {}
    for p, part in enumerate(parts):
        rows = share_rows(total, p, count)
        num_contacts[rows], errors[rows] = part["num_contacts"], part["error"]
        for name, a in part.items():
            key = name.removeprefix("extra.")
            if name in FIELDS or key != name:
                into = arrays if name in FIELDS else extra
                if key not in into:  # rows no process sets (of shares without a valid grasp): NaN, False
                    into[key] = np.full((total, *a.shape[1:]), np.nan if a.dtype.kind == "f" else 0, dtype=a.dtype)
                into[key][rows] = a
    mark_invalid(arrays, num_contacts == 0)  # rows of shares without a valid grasp were never set
    timing = np.stack([p["timing"] for p in parts])
    merged = BatchResult(
        evaluation=Evaluation(**arrays), num_contacts=num_contacts,
        active=np.arange(n_contacts) < num_contacts[:, None], errors=tuple(str(e) or None for e in errors),
        compile_seconds=float(timing[:, 0].max()), run_seconds=float(timing[:, 1].max()), devices=devices,
    )
    return merged, extra, {"evaluated": int(timing[:, 2].sum()), "processes": count}
