"""The ``jaxgrasp`` command line: ``jaxgrasp evaluate``, ``jaxgrasp sweep``, ``jaxgrasp tune``.

Every error in the input (bad file, bad value, bad option) prints one line
``jaxgrasp: error: ...`` on stderr and exits with status 2, never a traceback.

One module per sub-command (:mod:`.evaluate`, :mod:`.sweep`, :mod:`.tune`), each with
``add_parser(sub)`` and ``run(args)``; what they share is in :mod:`.common`.
"""

from __future__ import annotations

import sys

from ..cache import enable_compilation_cache
from . import evaluate, sweep, tune
from .common import EXIT_USAGE, Parser, UsageError, load_grasp, parse_number

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

COMMANDS = (evaluate, sweep, tune)
"""The sub-command modules, in the order of ``jaxgrasp --help``."""


def build_parser() -> Parser:
    """The ``jaxgrasp`` argument parser with every sub-command."""
    # the docstring's first line without its reStructuredText markup
    parser = Parser(prog="jaxgrasp", description=__doc__.splitlines()[0].replace("``", ""))
    sub = parser.add_subparsers(dest="command", parser_class=Parser)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Run ``jaxgrasp`` with ``argv`` (default ``sys.argv[1:]``); the exit status."""
    from ..validation import GraspValueError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            raise UsageError("choose a command: evaluate, sweep or tune (see 'jaxgrasp --help')")
        enable_compilation_cache()  # looked up here, so that tests can replace it
        return args.func(args)
    except (UsageError, GraspValueError) as exc:
        print(f"jaxgrasp: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("jaxgrasp: interrupted", file=sys.stderr)
        return 130
