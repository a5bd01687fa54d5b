"""What the ``jaxgrasp`` sub-commands share when they run: one-line errors, the grasp to use,
output folders, progress lines. Their arguments are defined in `jaxgrasp.cli._arguments`.

Every error in the input (bad file, bad value, bad option) is a `UsageError` (or a
[`GraspValueError`][jaxgrasp.GraspValueError]), which `jaxgrasp.cli.main` prints as
one line ``jaxgrasp: error: ...`` on stderr, exiting with `EXIT_USAGE`.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from jaxgrasp import storage
from jaxgrasp.cli._arguments import OVERRIDES
from jaxgrasp.cli._parser import EXIT_USAGE, Parser, UsageError
from jaxgrasp.engine import ChunkProgress
from jaxgrasp.model import FIELD, counted
from jaxgrasp.presets import PRESETS

__all__ = [
    "EXIT_USAGE",
    "UsageError",
    "Parser",
    "check_chunk_size",
    "grasp_source",
    "grasp_notes",
    "load_grasp",
    "check_out",
    "lock_out",
    "replaced_text",
    "write_with_plot",
    "write_picture",
    "ChunkProgress",
    "say",
    "epsilon_columns",
    "check_names",
    "LONG_EVALUATION_CONTACTS",
    "announce_large_grasp",
    "announce_run",
    "robust_uncertainty",
]


def check_chunk_size(value: int | None) -> None:
    """``--chunk-size`` must be at least 1 (``None``: the default)."""
    if value is not None and value < 1:
        raise UsageError(f"--chunk-size must be >= 1, got {value}")


def grasp_source(args) -> str:
    """The grasp's name in messages: the file, or ``preset cube``."""
    return args.file or f"preset {args.preset}"


def grasp_notes(grasp) -> list[str]:
    """Remarks on a valid grasp that may not be what its author meant (one line each):
    normals pointing towards the centre of mass (`jaxgrasp.model._validation.inward_contacts`)."""
    from jaxgrasp.model import inward_contacts

    inward = inward_contacts(grasp.positions, grasp.normals)
    if not inward:
        return []
    names = [str(i) for i in inward]
    which = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    one = len(inward) == 1
    return [
        f"the normal{'' if one else 's'} of contact{'' if one else 's'} {which} "
        f"point{'s' if one else ''} towards the centre of mass (n . c <= 0): evaluated as an "
        "inside grip (a fingertip pressing outward on the wall of a cavity); if the fingertip "
        "presses from outside, flip the normal: normals point out of the object"
    ]


def load_grasp(args, overrides: bool = True, keep_mesh: bool = False):
    """The grasp named on the command line (file or preset), with overrides applied; with
    ``keep_mesh``, a file naming a mesh gives its [`MeshGrasp`][jaxgrasp.MeshGrasp] (the
    overrides applied to its grasp)."""
    from jaxgrasp.io import load
    from jaxgrasp.surface import MeshGrasp

    if (args.file is None) == (args.preset is None):
        if args.file is None and getattr(args, "default_preset", None):
            args.preset = args.default_preset
        else:
            raise UsageError(f"give either a grasp FILE or --preset {'|'.join(PRESETS)}")
    allowed = getattr(args, "allow_dir", None)
    loaded = load(args.file, keep_mesh=keep_mesh, allowed_dirs=allowed) if args.file is not None else PRESETS[args.preset]()
    if not overrides:
        return loaded
    if isinstance(loaded, MeshGrasp):
        return loaded.replace(grasp=_overridden(loaded.grasp, args))
    return _overridden(loaded, args)


def _overridden(grasp, args):
    """``grasp`` with the command line's overrides (``--young-modulus`` ...) applied."""
    import numpy as np

    from jaxgrasp.model import Grasp, GraspValueError, check_grasp_inputs

    given = {name: getattr(args, name) for name in OVERRIDES if getattr(args, name, None) is not None}
    if not given:
        return grasp
    fields = grasp.to_numpy()
    for name, value in given.items():
        _check_override(name, value)
        fields[name] = np.full_like(fields[name], value)
    options = ", ".join(f"{FIELD[n].option} {v:g}" for n, v in given.items())
    dr, r = fields["initial_deformation"], fields["radius"]
    if ("initial_deformation" in given or "radius" in given) and not np.all(dr < r):
        i = int(np.flatnonzero(~(dr < r))[0])
        raise UsageError(
            f"with {options}: initial_deformation ({dr[i]:g} m) must be below the fingertip "
            f"radius ({r[i]:g} m)"
        )
    try:
        return Grasp(**check_grasp_inputs(**fields))
    except GraspValueError as exc:  # another rule between fields, e.g. the energy scale
        raise UsageError(f"with {options}: {exc}") from None


def _check_override(name: str, value: float) -> None:
    """One override's own rules, named by its option (``--friction -1: must be positive``)."""
    import numpy as np

    field = FIELD[name]
    text = f"{field.option} {value:g}"
    if not math.isfinite(value):
        raise UsageError(f"{text}: {name} must be finite")
    if not field.allows(np.float64(value)):
        raise UsageError(f"{text}: {name} must be {field.rule}" + (f" ({field.unit})" if field.unit else ""))


# --------------------------------------------------------------------------- names


PATH_ARGUMENTS = ("file", "mesh", "out", "glb", "hand", "allow_dir")
"""The arguments that name a file or folder: an empty one is refused (`check_names`)."""


def check_names(args) -> None:
    """Every text argument (input file, ``--out``, ``--glb`` ...) must be valid UTF-8.

    A file name made of bytes that are not UTF-8 (``b"\\xff"``) reaches Python as lone
    surrogates (`os.fsdecode`); it can be opened, but not printed, written into a
    CSV or drawn in a figure title, so it would fail only after all the computing. Here it
    is a `UsageError` before anything is read or computed.
    """
    for dest, value in sorted(vars(args).items()):
        for text in value if isinstance(value, (list, tuple)) else [value]:
            if not isinstance(text, str):
                continue
            if dest in PATH_ARGUMENTS and not text.strip():  # Path("") is the working folder
                what = "the input file name" if dest in ("file", "mesh") else f"--{dest.replace('_', '-')}"
                raise UsageError(f"{what} is empty: give a file or folder name")
            try:
                text.encode("utf-8")
            except UnicodeEncodeError:
                what = "the input file name" if dest == "file" else f"--{dest.replace('_', '-')}"
                raise UsageError(
                    f"{what} {_shown(text)} is not valid UTF-8 text (jaxgrasp prints it and writes it "
                    "into files and figure titles); rename it or use another name"
                ) from None


def _shown(text: str) -> str:
    """``text`` with its undecodable bytes as ``\\xff`` escapes, quoted, printable."""
    try:
        raw = os.fsencode(text)  # the bytes as given on the command line
    except UnicodeEncodeError:
        raw = text.encode("utf-8", "backslashreplace")
    return "'" + raw.decode("utf-8", "backslashreplace") + "'"


# --------------------------------------------------------------------------- output folders


def check_out(out: Path) -> None:
    """``--out`` must be a folder (existing or not) where files can be created, and hold
    no symbolic link where jaxgrasp keeps its own files (the lock file and the
    checkpoints): a link there is refused, before anything is computed, not followed; so
    is a folder where a file belongs (the lock file, a sweep's checkpoint) or a file where
    a folder belongs (a batch's finished chunks)."""
    from jaxgrasp.engine import BATCH_FOLDER, SWEEP_FILE

    try:
        storage.check_writable(out)
        for name, what, folder in ((storage.LOCK_NAME, "its lock file", False),
                                   (BATCH_FOLDER, "a batch's finished chunks", True),
                                   (SWEEP_FILE, "a sweep's finished points", False)):
            path = out / name
            storage.refuse_link(path, what)
            if path.exists() and path.is_dir() != folder:  # else found only when written, after the work
                kind = "not a folder" if folder else "a folder"
                raise storage.OutputError(f"{str(path)!r}, where jaxgrasp keeps {what}, is {kind}: "
                                          "remove it or choose another --out")
    except storage.OutputError as exc:
        raise UsageError(f"--out: {exc}") from None


def lock_out(out: Path) -> storage.FolderLock:
    """The lock of ``--out`` (created if needed), held; a one-line error if another run
    holds it or its lock file is a link. Taking it removes the stale temporary files of
    killed runs in ``--out``."""
    lock = storage.FolderLock(out)
    try:
        return lock.acquire()
    except storage.DiskFull:
        raise  # exit 1, not an input error
    except storage.OutputError as exc:  # FolderBusy, or a link at the lock file's path
        raise UsageError(f"--out: {exc}") from None
    except OSError as exc:
        raise UsageError(f"cannot create --out folder {str(out)!r}: {exc.strerror or exc}") from None


def write_picture(targets, fig, scene) -> list:
    """Write the picture ``fig`` to ``targets[0]`` (PNG, SVG or PDF by its suffix) and, where
    given, ``scene``'s GLB to ``targets[1]``, as one set; the previous files replaced."""
    from jaxgrasp.plots import save_figure

    members = {targets[0]: lambda fh: save_figure(fig, fh, format=targets[0].suffix[1:].lower())}
    if len(targets) > 1:
        members[targets[1]] = scene.to_trimesh().export(file_type="glb")
    try:
        for t in targets:
            t.parent.mkdir(parents=True, exist_ok=True)
        return storage.write_set(members)
    except OSError as exc:
        raise UsageError(f"cannot write {', '.join(map(str, targets))}: {exc.strerror or exc}") from None


def write_with_plot(members: dict, out: Path, figure=None) -> list[str]:
    """Write ``members`` (path -> bytes or a writer, `jaxgrasp.storage.write_set`) and,
    given a matplotlib ``figure``, it as a PNG beside ``out`` (same name), as one set,
    making ``out``'s folder; the names of the previous files they replaced. An unwritable
    folder is a one-line `UsageError`."""
    if figure is not None:
        from jaxgrasp.plots import save_figure

        members[out.with_suffix(".png")] = lambda fh: save_figure(figure, fh, format="png")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        replaced = storage.write_set(members)
    except OSError as exc:
        raise UsageError(f"cannot write {str(out)!r}: {exc.strerror or exc}") from None
    return [p.name for p in replaced]


def replaced_text(replaced, removed) -> str:
    """`` (replacing the previous sweep.npz, ...; removing the previous sweep.png)`` or ''."""
    parts = [f"{verb} the previous {', '.join(names)}" for verb, names in (("replacing", replaced), ("removing", removed)) if names]
    return f" ({'; '.join(parts)})" if parts else ""


# --------------------------------------------------------------------------- progress


def say(line: str) -> None:
    """One progress or note line on stderr, at once."""
    print(line, file=sys.stderr, flush=True)


def announce_run(command: str, source: str, count: int, noun: str, quiet: bool = False) -> None:
    """The first line of a command that evaluates many grasps, on stderr, once its input
    is checked and before the first long step (stacking the grasps, compiling or loading
    the evaluator): ``jaxgrasp: batch set.jsonl: 5 grasps to go; ...``; ``count``: the
    valid grasps (points) not yet done. Nothing where it is 0 (a resumed run with nothing
    left) or ``quiet``."""
    if count and not quiet:
        say(
            f"jaxgrasp: {command} {source}: {counted(count, noun)} to go; compiling the evaluator "
            "(or loading it from the cache) first"
        )


LONG_EVALUATION_CONTACTS = 16
"""Grasps of more contacts than this get a line on stderr before their evaluation
(`announce_large_grasp`). The evaluation of one grasp is one compiled call without
progress of its own; its 2 N boundary problems of N contacts each cost time and memory
that grow more than as N^2 (``experiments/limits/FINDINGS.md``): the line tells the user what
the wait is for. Above
`jaxgrasp.model.MAX_CONTACTS` (32) a grasp is refused."""


def announce_large_grasp(n_contacts: int, source: str) -> None:
    """Say on stderr what is about to be compiled and evaluated, where the grasp has more
    than `LONG_EVALUATION_CONTACTS` contacts (the one-grasp commands print nothing
    else until the result)."""
    if n_contacts > LONG_EVALUATION_CONTACTS:
        say(
            f"jaxgrasp: {source} has {n_contacts} contacts: compiling and solving its "
            f"{2 * n_contacts} boundary problems of {n_contacts} contacts each, in one step without "
            f"progress; above {LONG_EVALUATION_CONTACTS} contacts its time and memory grow more than in "
            "proportion to the number of contacts, so expect a wait"
        )


# --------------------------------------------------------------------------- epsilon column


def epsilon_columns(grasps, shape=None) -> dict:
    """``{"epsilon": values, "force_closure": bools}`` of a batched grasp
    ([`jaxgrasp.epsilon`][jaxgrasp.epsilon]), reshaped to ``shape`` (e.g. a sweep's grid)."""
    from jaxgrasp.analysis import epsilon

    eps = epsilon(grasps)
    cols = {"epsilon": eps.value, "force_closure": eps.force_closure}
    return {k: v.reshape(shape) if shape is not None else v for k, v in cols.items()}


# --------------------------------------------------------------------------- robust options


def robust_uncertainty(args):
    """The [`Uncertainty`][jaxgrasp.analysis.Uncertainty] of ``--robust`` (``None`` without it), after
    checking ``--samples`` and ``--seed``; a one-line `UsageError` otherwise."""
    from jaxgrasp.analysis import parse_spec
    from jaxgrasp.model import GraspValueError

    if args.robust is None:
        return None
    if args.samples < 2:
        raise UsageError(f"--samples must be >= 2, got {args.samples}")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    try:
        return parse_spec(args.robust)
    except GraspValueError as exc:
        raise UsageError(f"--robust: {exc}") from None
