"""The ``jaxgrasp`` command line: ``jaxgrasp evaluate``, ``sweep``, ``batch``, ``tune``, ``show``.

Every error in the input (bad file, bad value, bad option, an output that cannot be
written) prints one line ``jaxgrasp: error: ...`` on stderr and exits with status 2, never
a traceback. Ctrl-C (or SIGTERM) at any moment ends the command within a second with one
line ``jaxgrasp: interrupted ...`` and status 130 (143), see :mod:`._interrupt`.

One module per sub-command (:mod:`._evaluate`, :mod:`._sweep`, :mod:`._batch`,
:mod:`._tune`, :mod:`._show`), each with ``add_parser(sub)`` and ``run(args)``; what they
share is in :mod:`._common`. The commands parse, call the library, print and write.
"""

from __future__ import annotations

import sys
from importlib import metadata

from jaxgrasp.cli import _batch, _evaluate, _show, _sweep, _tune
from jaxgrasp.cli._common import EXIT_USAGE, Parser, UsageError, load_grasp, parse_number
from jaxgrasp.cli._interrupt import run_interruptibly
from jaxgrasp.engine import _compile
from jaxgrasp.engine._store import enable_compilation_cache

__all__ = [
    "main",
    "build_parser",
    "COMMANDS",
    "UsageError",
    "EXIT_USAGE",
    "parse_number",
    "load_grasp",
    "enable_compilation_cache",
]

COMMANDS = (_evaluate, _sweep, _batch, _tune, _show)
"""The sub-command modules, in the order of ``jaxgrasp --help``."""


def build_parser() -> Parser:
    """The ``jaxgrasp`` argument parser with every sub-command."""
    # the docstring's first line without its reStructuredText markup
    parser = Parser(prog="jaxgrasp", description=__doc__.splitlines()[0].replace("``", ""))
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", parser_class=Parser)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def package_version() -> str:
    """The installed jaxgrasp's version, as ``jaxgrasp.__version__`` reads it: defined once,
    in ``pyproject.toml``, and carried by the package's installed metadata."""
    try:
        return metadata.version("jaxgrasp")
    except metadata.PackageNotFoundError:  # a source tree on sys.path that was never installed
        return "0+unknown"


def main(argv=None) -> int:
    """Run ``jaxgrasp`` with ``argv``; the exit status.

    The command runs in a worker thread while this (main) thread handles Ctrl-C and
    SIGTERM (:mod:`._interrupt`): on either, the process ends within a second with status
    130 (143), one line ``jaxgrasp: interrupted ...`` and no temporary file left.

    Without ``argv`` (the installed ``jaxgrasp`` command, ``python -m jaxgrasp``) it reads
    ``sys.argv[1:]`` and, once the command is done, ends the process with its status at
    once (``os._exit``, after flushing stdout and stderr), so that no interrupt lands in
    the interpreter's teardown. Pass ``argv`` to get the status returned instead.
    """
    return run_interruptibly(lambda: _main(argv), end_process=argv is None)


def _main(argv) -> int:
    """Parse ``argv`` and run its command; input errors as one line, exit status 2."""
    from jaxgrasp.io._outputs import OutputError, clear_notes
    from jaxgrasp.model._validation import GraspValueError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            raise UsageError("choose a command: evaluate, sweep, batch, tune or show (see 'jaxgrasp --help')")
        enable_compilation_cache()  # looked up here, so that tests can replace it
        return args.func(args)
    except (UsageError, GraspValueError, OutputError) as exc:
        print(f"jaxgrasp: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        clear_notes()
        _compile.wait_for_saves()  # the process may end with os._exit next
