"""What happens when jaxgrasp starts: float64 for a library user, Ctrl-C for the command.

Nothing here imports more than Python's own start-up modules, except `enable_x64`
(which imports JAX when it is called).

* ``import jaxgrasp`` calls `enable_x64` unless the process is the ``jaxgrasp``
  command (`is_command_line`): the only process-wide setting of the import.
* The command (`jaxgrasp.cli.main`) calls `install_if_command_line` before it
  loads JAX, then `enable_x64`. Its own handling (`jaxgrasp.cli._interrupt`)
  begins only once the library is loaded, which takes a while; a Ctrl-C before that
  would unwind the import and print Python's multi-line ``KeyboardInterrupt`` traceback.
  So in the ``jaxgrasp`` command only (the console script, ``python -m jaxgrasp`` or
  ``python -m jaxgrasp.cli``), SIGINT and SIGTERM then print ``jaxgrasp: interrupted``
  (``terminated``) and end the process with status 130 (143) at once; nothing has been
  written yet at that stage. A script that imports jaxgrasp keeps Python's own handlers.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

__all__ = ["EXIT", "X64_ENV_VAR", "enable_x64", "is_command_line", "install_if_command_line"]

EXIT = {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated")}
"""The signals the ``jaxgrasp`` command handles: signal -> (exit status, 128 + the signal
number as a shell reports it; the word of its one line). `jaxgrasp.cli._interrupt`
uses the same table once the command runs."""

X64_ENV_VAR = "JAX_ENABLE_X64"
"""JAX's own switch of 64-bit mode: where it is set (to anything), `enable_x64`
leaves JAX's setting alone."""

_COMMAND = "jaxgrasp"
_MODULES = ("jaxgrasp", "jaxgrasp.cli")
_OPTIONS_WITH_VALUE = ("-X", "-W", "--check-hash-based-pycs")  # interpreter options taking the next word


def is_command_line(orig_argv: list[str]) -> bool:
    """Whether the interpreter's command line ``orig_argv`` (``sys.orig_argv``) runs the
    ``jaxgrasp`` command: its console script, or ``python -m jaxgrasp[.cli]``."""
    if len(orig_argv) >= 2 and os.path.basename(orig_argv[1]) == _COMMAND:
        return True  # python .../bin/jaxgrasp ... (how a console script is started)
    i = 1
    while i < len(orig_argv) - 1:
        arg = orig_argv[i]
        if arg == "-m":
            return orig_argv[i + 1] in _MODULES
        if arg == "-c" or not arg.startswith("-"):
            return False  # -c code, or a script: not the command
        i += 2 if arg in _OPTIONS_WITH_VALUE else 1
    return False


def _end_at_once(signum, _frame) -> None:
    status, word = EXIT[signum]
    try:
        os.write(2, f"jaxgrasp: {word}\n".encode())
    except OSError:  # pragma: no cover - stderr closed: the status still tells
        pass
    os._exit(status)


def install_if_command_line() -> bool:
    """In the ``jaxgrasp`` command's main thread, end the process on SIGINT/SIGTERM with
    one line (status 130/143) until the command installs its own handlers; whether done."""
    if not is_command_line(list(getattr(sys, "orig_argv", []))):
        return False
    if threading.current_thread() is not threading.main_thread():
        return False
    for signum in EXIT:
        signal.signal(signum, _end_at_once)
    return True


def enable_x64(environ=os.environ) -> bool:
    """Turn on JAX's 64-bit mode (``jax_enable_x64``) for the process, unless the user
    chose with ``JAX_ENABLE_X64`` (`X64_ENV_VAR`); whether it was turned on here.
    Imports JAX; starts none of its backends."""
    if X64_ENV_VAR in environ:  # an explicit choice of the user's stands
        return False
    import jax

    jax.config.update("jax_enable_x64", True)
    return True
