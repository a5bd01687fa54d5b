"""The one line that refuses a count over its cap, in plain Python: the command line's
parser (``--samples``, ``--chunk-size``, ...) and the library's functions (``samples=``,
``chunk_size=``) say it the same way, the parser without loading JAX."""

from __future__ import annotations

import math

__all__ = ["over_limit", "whole_number"]


def over_limit(name: str, value: int, limit: int, what: str) -> str | None:
    """``None`` where ``value <= limit``; else the one line that refuses it:
    ``"NAME must be at most LIMIT WHAT, got VALUE"`` (``name``: the argument as the caller
    spells it, ``samples`` or ``--samples``; ``what``: what is counted, and why the cap)."""
    if value <= limit:
        return None
    return f"{name} must be at most {limit:,} {what}, got {value:,}"


def whole_number(text: str) -> int | None:
    """``text`` as a whole number: ``"150"``, also written as a float (``"1e5"``,
    ``"2000.0"``); ``None`` where it is not one (``"1.5"``, ``"nan"``, ``"ten"``)."""
    t = text.strip()
    try:
        return int(t)
    except ValueError:
        pass
    try:
        x = float(t)
    except ValueError:
        return None
    return int(x) if math.isfinite(x) and x == int(x) else None
