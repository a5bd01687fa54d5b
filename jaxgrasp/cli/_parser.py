"""The command line's argument parser and its one-line errors: Python's standard library only.

With the sub-commands' arguments (`jaxgrasp.cli._arguments`), `jaxgrasp.cli.main` answers
``--version``, every ``--help`` and every argument error with these, before it loads JAX.
"""

from __future__ import annotations

import argparse
import re

__all__ = ["EXIT_USAGE", "UsageError", "Parser"]

EXIT_USAGE = 2
"""Exit status of a command whose input is wrong."""


class UsageError(Exception):
    """A problem with the command line or its input; reported in one line, exit 2."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one `UsageError` line, not usage + message.

    A value that starts with a minus sign followed by a digit or a point (``-2e5``,
    ``-9.81,0,0``, ``-0.1:0.5:3``) is a value, not an option: argparse's own rule knows only
    plain integers and decimals, so ``--gravity -9.81,0,0`` failed with "expected one
    argument" and ``--young-modulus -2e5`` never reached the check that says it must be
    positive. No jaxgrasp option starts with ``-`` and a digit."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")
