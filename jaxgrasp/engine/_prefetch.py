"""Import a module in a background thread while the caller's long native call runs.

A module that a command needs only after a compile or a cached program's load (both
release Python's GIL: XLA works in C++) is imported meanwhile for free: SciPy's qhull for
the epsilon metric (~0.3 s), matplotlib for a sweep's or a batch's figure (~0.4 s, its
first result 0.3-0.4 s sooner). A later ``import`` of the module simply waits for the
thread's (Python's per-module import locks); an import that fails in the thread is left
for that later import to report.
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
