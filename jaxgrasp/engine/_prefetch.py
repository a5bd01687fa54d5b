"""Import a module in a background thread while the caller's long native call runs.

A module that a command needs only after a compile or the load of a stored executable
(both release Python's GIL: XLA works in C++) is imported meanwhile, so that its import
overlaps that wait instead of following it: SciPy's qhull for the epsilon metric,
matplotlib for the figure of ``jaxgrasp sweep`` or ``jaxgrasp batch``. A later
``import`` of the module simply waits for the thread's (Python's per-module import
locks); an import that fails in the thread is left for that later import to report.
"""

from __future__ import annotations

import importlib
import threading

__all__ = ["prefetch"]


def prefetch(module: str) -> None:
    """Start importing ``module`` (a dotted name) in a background thread; returns at once."""

    def load():
        try:
            importlib.import_module(module)
        except Exception:  # noqa: BLE001 - the caller's own import reports it
            pass

    threading.Thread(target=load, name=f"jaxgrasp-prefetch-{module}", daemon=True).start()
