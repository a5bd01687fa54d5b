"""Numbers as JSON: what every result's ``to_dict`` writes its floats with."""

from __future__ import annotations

import numpy as np

__all__ = ["json_floats"]


def json_floats(x) -> list | float | None:
    """A number or an array of any shape as (nested) Python floats, ``None`` where not
    finite (NaN, inf): what `json.dumps` writes with ``allow_nan=False``."""
    a = np.asarray(x, dtype=np.float64)
    return np.where(np.isfinite(a), a, None).tolist()
