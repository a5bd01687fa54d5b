"""The ``jaxgrasp`` command line: ``jaxgrasp evaluate``, ``sweep``, ``batch``, ``tune``, ``plan``, ``show``, ``simulate``.

Every error in the input (bad file, bad value, bad option, an output that cannot be
written) prints one line ``jaxgrasp: error: ...`` on stderr and exits with status 2, never
a traceback. A failure of the machine while writing (a full disk, an I/O error) is one
line too, with status 1; a batch's finished chunks stay in its checkpoint for
``--resume``. Ctrl-C (or SIGTERM) at any moment ends the command within a second with one
line ``jaxgrasp: interrupted ...`` and status 130 (143), see `_interrupt`.

One module per sub-command (`_evaluate`, `_sweep`, `_batch`, `_tune`, `_plan`, `_show`,
`_simulate`), each with ``run(args)``; what they share is in `_common`. Their arguments
are defined in `_arguments`, without JAX: `main` parses the whole command line before it
loads the library, so that ``--help``, ``--version`` and every argument error are
answered at once. The commands parse, call the library, print and write.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import TYPE_CHECKING

from jaxgrasp import _startup
from jaxgrasp.cli._arguments import COMMANDS, add_commands, parse_number
from jaxgrasp.cli._parser import EXIT_USAGE, Parser, UsageError

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded when first used; these load JAX
    from jaxgrasp.cli._common import load_grasp
    from jaxgrasp.engine import enable_compilation_cache

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

EXIT_ENVIRONMENT = 1
"""Exit status of a command the machine failed: no space left on the device, an I/O error."""

EXIT_STATUS_HELP = (
    "exit status: 0 done; 1 the machine failed (e.g. no space left on the device: a batch's "
    "finished chunks are kept, rerun with --resume); 2 bad input or options; 130 (143) "
    "interrupted by Ctrl-C (SIGTERM)"
)
"""The epilog of ``jaxgrasp --help``."""

__getattr__, __dir__, _LAZY = _startup.attach(__name__)


def build_parser() -> Parser:
    """The ``jaxgrasp`` argument parser with every sub-command (`COMMANDS`); it loads neither
    the library nor JAX."""
    # the docstring's first line without its reStructuredText markup
    parser = Parser(prog="jaxgrasp", description=__doc__.splitlines()[0].replace("``", ""), epilog=EXIT_STATUS_HELP)
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    add_commands(parser.add_subparsers(dest="command", parser_class=Parser))
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

    The whole command line is parsed (`build_parser`) before the library (and JAX) is
    loaded: ``--version``, ``--help`` (``SystemExit(0)``, as argparse raises it) and every
    argument error are answered at once, an error as one line with exit status 2. In the
    ``jaxgrasp`` command, a Ctrl-C or SIGTERM while the library loads ends the process
    with one line (`jaxgrasp._startup.install_if_command_line`).
    """
    _startup.install_if_command_line()  # first: before anything slow is loaded
    try:
        args = _parse(sys.argv[1:] if argv is None else list(argv))
    except UsageError as exc:
        print(f"jaxgrasp: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    _startup.enable_x64()  # before the library is loaded: in the command, the import did not
    from jaxgrasp.cli._interrupt import run_interruptibly  # the first module that loads the library

    return run_interruptibly(lambda: _main(args), end_process=argv is None)


def _parse(argv: list[str]) -> argparse.Namespace:
    """The command line ``argv`` parsed; a `UsageError` where it is wrong or names no command."""
    args = build_parser().parse_args(argv)
    if args.command is None:
        raise UsageError("choose a command: evaluate, sweep, batch, tune, plan, show or simulate "
                         "(see 'jaxgrasp --help')")
    return args


def _main(args: argparse.Namespace) -> int:
    """Load the library and run the command of ``args``; input errors as one line, exit
    status 2; a failure of the machine (a full disk, an I/O error) as one line, exit status 1."""
    from jaxgrasp.cli._notes import clear_notes
    from jaxgrasp.engine import log_lines_on_stderr, wait_for_saves
    from jaxgrasp.model import GraspValueError
    from jaxgrasp.storage import OutputError

    try:
        from jaxgrasp.cli._common import check_names

        check_names(args)  # a name that is not UTF-8 would fail only when printed, after the work
        with log_lines_on_stderr():  # "jaxgrasp: compiling ...", chunks, cache warnings, one line each
            _configure()  # before the command makes its first array: a batch runs on every core
            _matplotlib_without_home()
            sys.modules[__name__].enable_compilation_cache()  # looked up here, so that tests can replace it
            return importlib.import_module(f"jaxgrasp.cli._{args.command}").run(args)
    except (UsageError, GraspValueError, OutputError) as exc:
        return _report(exc)
    except OSError as exc:  # the machine, not the input: a full disk, an I/O error
        return _report(exc)
    finally:
        clear_notes()
        wait_for_saves()  # the process may end with os._exit next


def _matplotlib_without_home() -> None:
    """Point matplotlib's cache into the temporary folder where the user has no usable home
    folder (``HOME=""``), unless ``MPLCONFIGDIR`` says where (`jaxgrasp.engine.matplotlib_dir`)."""
    from jaxgrasp.engine import matplotlib_dir

    folder = matplotlib_dir()
    if folder is not None and not os.environ.get("MPLCONFIGDIR"):
        os.environ["MPLCONFIGDIR"] = str(folder)


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
