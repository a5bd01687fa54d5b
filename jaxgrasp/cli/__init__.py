"""The ``jaxgrasp`` command line: ``jaxgrasp evaluate``, ``sweep``, ``batch``, ``tune``, ``plan``, ``show``, ``simulate``.

Every error in the input (bad file, bad value, bad option, an output that cannot be
written) prints one line ``jaxgrasp: error: ...`` on stderr and exits with status 2, never
a traceback. A failure of the machine while writing (a full disk, an I/O error) is one
line too, with status 1; a batch's finished chunks stay in its checkpoint for
``--resume``. Ctrl-C (or SIGTERM) at any moment ends the command within a second with one
line ``jaxgrasp: interrupted ...`` and status 130 (143), see `_interrupt`.

One module per sub-command (`_evaluate`, `_sweep`, `_batch`,
`_tune`, `_plan`, `_show`, `_simulate`), each with ``add_parser(sub)`` and ``run(args)``; what they
share is in `_common`. The commands parse, call the library, print and write.
"""

from __future__ import annotations

import importlib
import sys

from jaxgrasp import _startup
from jaxgrasp.cli._parser import EXIT_USAGE, Parser, UsageError

__all__ = [
    "main",
    "build_parser",
    "COMMANDS",
    "UsageError",
    "EXIT_USAGE",
    "EXIT_ENVIRONMENT",
    "EXIT_STATUS_HELP",
    "parse_number",
    "load_grasp",
    "enable_compilation_cache",
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
"""The sub-commands, in the order of ``jaxgrasp --help``, each with its line there. Its
module ``jaxgrasp.cli._<name>`` gives the same line to ``add_parser`` (a test compares
the two ``--help`` texts); here it answers ``--help`` without loading the library."""

EXIT_ENVIRONMENT = 1
"""Exit status of a command the machine failed: no space left on the device, an I/O error."""

EXIT_STATUS_HELP = (
    "exit status: 0 done; 1 the machine failed (e.g. no space left on the device: a batch's "
    "finished chunks are kept, rerun with --resume); 2 bad input or options; 130 (143) "
    "interrupted by Ctrl-C (SIGTERM)"
)
"""The epilog of ``jaxgrasp --help``."""

_LAZY = {"parse_number": "jaxgrasp.cli._common", "load_grasp": "jaxgrasp.cli._common",
         "enable_compilation_cache": "jaxgrasp.engine"}
"""Names of this face that load the library (and JAX), loaded when first used."""


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'jaxgrasp.cli' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value  # later uses (and a test's replacement) find it here
    return value


def _parser_and_commands() -> tuple[Parser, object]:
    """The ``jaxgrasp`` parser without its sub-commands, and its sub-parsers' action."""
    # the docstring's first line without its reStructuredText markup
    parser = Parser(prog="jaxgrasp", description=__doc__.splitlines()[0].replace("``", ""), epilog=EXIT_STATUS_HELP)
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    return parser, parser.add_subparsers(dest="command", parser_class=Parser)


def top_parser() -> Parser:
    """The ``jaxgrasp`` parser with each sub-command's name and line but none of its
    options: what ``--version``, ``--help`` and a missing or unknown command need,
    without the library (and JAX). Its ``--help`` is `build_parser`'s."""
    parser, sub = _parser_and_commands()
    for name, line in COMMANDS.items():
        sub.add_parser(name, help=line, add_help=False)
    return parser


def build_parser() -> Parser:
    """The ``jaxgrasp`` argument parser with every sub-command (it loads the library)."""
    _startup.enable_x64()  # before the library is loaded: in the command, the import did not
    parser, sub = _parser_and_commands()
    for name in COMMANDS:
        importlib.import_module(f"jaxgrasp.cli._{name}").add_parser(sub)
    return parser


def package_version() -> str:
    """The installed jaxgrasp's version, as ``jaxgrasp.__version__`` reads it: defined once,
    in ``pyproject.toml``, and carried by the package's installed metadata."""
    from importlib import metadata

    try:
        return metadata.version("jaxgrasp")
    except metadata.PackageNotFoundError:  # a source tree on sys.path that was never installed
        return "0+unknown"


def main(argv=None) -> int:
    """Run ``jaxgrasp`` with ``argv``; the exit status.

    The command runs in a worker thread while this (main) thread handles Ctrl-C and
    SIGTERM (`_interrupt`): on either, the process ends within a second with status
    130 (143), one line ``jaxgrasp: interrupted ...`` and no temporary file left.

    Without ``argv`` (the installed ``jaxgrasp`` command, ``python -m jaxgrasp``) it reads
    ``sys.argv[1:]`` and, once the command is done, ends the process with its status at
    once (``os._exit``, after flushing stdout and stderr), so that no interrupt lands in
    the interpreter's teardown. Pass ``argv`` to get the status returned instead.

    ``--version``, ``--help`` and a missing or unknown command are answered by
    `top_parser` before the library (and JAX) is loaded. In the ``jaxgrasp``
    command, a Ctrl-C or SIGTERM while the library loads ends the process with one line
    (`jaxgrasp._startup.install_if_command_line`).
    """
    _startup.install_if_command_line()  # first: before anything slow is loaded
    status = _answer_without_library(sys.argv[1:] if argv is None else list(argv))
    if status is not None:
        return status
    from jaxgrasp.cli._interrupt import run_interruptibly

    return run_interruptibly(lambda: _main(argv), end_process=argv is None)


def _answer_without_library(argv: list[str]) -> int | None:
    """The exit status of a command line `top_parser` answers alone (no command, an
    unknown command or top-level option), after printing its one line; ``None`` for a
    sub-command to run. ``--version`` and ``--help`` print and raise ``SystemExit(0)``,
    as argparse does."""
    try:
        args, rest = top_parser().parse_known_args(argv)
    except UsageError as exc:
        print(f"jaxgrasp: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.command is None:
        line = (f"unrecognized arguments: {' '.join(rest)} (see 'jaxgrasp --help')" if rest else
                "choose a command: evaluate, sweep, batch, tune, plan, show or simulate (see 'jaxgrasp --help')")
        print(f"jaxgrasp: error: {line}", file=sys.stderr)
        return EXIT_USAGE
    return None


def _main(argv) -> int:
    """Parse ``argv`` and run its command; input errors as one line, exit status 2; a
    failure of the machine (a full disk, an I/O error) as one line, exit status 1."""
    from jaxgrasp.cli._notes import clear_notes
    from jaxgrasp.engine import log_lines_on_stderr, wait_for_saves
    from jaxgrasp.model import GraspValueError
    from jaxgrasp.storage import OutputError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)  # a command is given: main answered the command line without one
        from jaxgrasp.cli._common import check_names

        check_names(args)  # a name that is not UTF-8 would fail only when printed, after the work
        with log_lines_on_stderr():  # "jaxgrasp: compiling ...", chunks, cache warnings, one line each
            _configure()  # before the command makes its first array: a batch runs on every core
            sys.modules[__name__].enable_compilation_cache()  # looked up here, so that tests can replace it
            return args.func(args)
    except (UsageError, GraspValueError, OutputError) as exc:
        return _report(exc)
    except OSError as exc:  # the machine, not the input: a full disk, an I/O error
        return _report(exc)
    finally:
        clear_notes()
        wait_for_saves()  # the process may end with os._exit next


def _configure() -> None:
    """[`jaxgrasp.configure`][jaxgrasp.configure] from the environment; a bad ``JAXGRASP_CPU_DEVICES`` is a
    `UsageError`."""
    from jaxgrasp.engine import configure

    try:
        configure()
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _report(exc: Exception) -> int:
    """Print the one line of an error that ended a command (`_error_line`); its exit status.

    A write abandoned by an interrupt prints nothing: the command's thread reaches it
    while the main thread ends the process with the interrupt's one line, which must be
    the only line after the progress lines."""
    from jaxgrasp.storage import Abandoned

    if isinstance(exc, Abandoned):
        return 130
    status, line = _error_line(exc)
    print(f"jaxgrasp: error: {line}", file=sys.stderr)
    return status


def _error_line(exc: Exception) -> tuple[int, str]:
    """The exit status and one-line message of an error that ended a command.

    A full disk (`DiskFull`, or an ``OSError`` with its errno
    that no writer turned into one) and any other ``OSError`` (the machine, not the input:
    an I/O error, a file removed meanwhile) exit 1; a full disk's line also says what
    the command kept (`keeping`). The rest is bad input, exit 2.
    """
    from jaxgrasp import storage
    from jaxgrasp.cli import _notes

    full = isinstance(exc, storage.DiskFull) or (isinstance(exc, OSError) and exc.errno in storage.NO_SPACE)
    if isinstance(exc, OSError) and not full:
        what = (exc.strerror or str(exc) or type(exc).__name__).lower()
        return EXIT_ENVIRONMENT, f"{exc.filename}: {what}" if exc.filename else what
    if not full:
        return EXIT_USAGE, str(exc)
    if not isinstance(exc, storage.DiskFull):
        exc = storage.DiskFull(exc.filename or "an output file", exc)
    return EXIT_ENVIRONMENT, "; ".join([str(exc), *_notes.keeping()])
