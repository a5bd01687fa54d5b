"""What happens when jaxgrasp starts: float64 for a library user, Ctrl-C for the command,
names loaded when first used.

Nothing here imports more than Python's standard library, except `enable_x64`
(which imports JAX when it is called).

* Every package face (``jaxgrasp/<package>/__init__.py``, and the top level) loads its
  names when first used (`attach`, after the Scientific Python SPEC 1): importing a face
  loads none of its modules, so the ``jaxgrasp`` command reads the constants its
  argument parser needs (`jaxgrasp.model.FIELD`, `jaxgrasp.planning.SAMPLERS`, ...)
  without loading JAX.

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

import ast
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable

__all__ = ["EXIT", "X64_ENV_VAR", "enable_x64", "is_command_line", "install_if_command_line", "attach", "lazy_names"]

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


def lazy_names(name: str, source: str) -> dict[str, tuple[str, str]]:
    """The names the package face ``name`` loads when first used, read from its source:
    ``{name: (module, attribute)}`` for every ``from M import a, b as c`` statement of its
    top-level ``if TYPE_CHECKING:`` block, the one list of the face's names (type checkers
    and the API reference read the same statements). A face's own submodule
    (``from jaxgrasp import presets`` in ``jaxgrasp``) is ``(that module, "")``.

    Raises:
        ValueError: the block holds anything but absolute ``from ... import`` statements, or
            binds a name twice.
    """
    names: dict[str, tuple[str, str]] = {}
    for node in ast.parse(source).body:
        if not (isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"):
            continue
        for statement in node.body:
            if not (isinstance(statement, ast.ImportFrom) and statement.level == 0 and statement.module):
                raise ValueError(f"{name}: line {statement.lineno}: the TYPE_CHECKING block of a face holds "
                                 "only 'from jaxgrasp... import ...' statements")
            for alias in statement.names:
                bound = alias.asname or alias.name
                if bound in names:
                    raise ValueError(f"{name}: line {statement.lineno}: {bound!r} imported twice")
                own = statement.module == name  # a submodule of the face itself
                names[bound] = (f"{name}.{alias.name}", "") if own else (statement.module, alias.name)
    return names


def attach(name: str) -> tuple[Callable[[str], object], Callable[[], list[str]], dict[str, tuple[str, str]]]:
    """``__getattr__`` and ``__dir__`` for the package face ``name``, being imported, and its
    `lazy_names` (read from its source through its loader): a face ends with
    ``__getattr__, __dir__, _LAZY = _startup.attach(__name__)`` (PEP 562).

    The first use of a name imports the module it comes from and keeps the value in the
    face, where later uses (and a test's replacement) find it; ``from jaxgrasp.model import
    FIELD`` loads ``jaxgrasp.model._fields`` alone. Any other name that is not a dunder is
    tried as a submodule (``jaxgrasp.engine._plan``), as an eager face had imported them all.
    """
    spec = sys.modules[name].__spec__
    source = spec.loader.get_source(name) if spec is not None and spec.loader is not None else None
    if source is None:  # an installation without its .py files
        raise ImportError(f"{name}: its source is needed to know the names it loads when first used", name=name)
    lazy = lazy_names(name, source)

    def __getattr__(attr: str):
        if attr in lazy:
            module, original = lazy[attr]
            value = importlib.import_module(module)
            if original:
                value = getattr(value, original)
        elif not (attr.startswith("__") and attr.endswith("__")):
            try:
                value = importlib.import_module(f"{name}.{attr}")
            except ModuleNotFoundError as exc:
                if exc.name != f"{name}.{attr}":
                    raise  # the submodule exists but needs a module that is missing
                raise AttributeError(f"module {name!r} has no attribute {attr!r}") from None
        else:
            raise AttributeError(f"module {name!r} has no attribute {attr!r}")
        setattr(sys.modules[name], attr, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[name])) | set(lazy))

    return __getattr__, __dir__, lazy
