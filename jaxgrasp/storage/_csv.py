"""Tables as CSV files: numbers that read back exactly."""

from __future__ import annotations

from typing import Any, BinaryIO, Callable, Iterable, Sequence

import numpy as np

__all__ = ["csv_cell", "csv_content"]


def csv_cell(x) -> str:
    """A number as a CSV cell: floats with 17 significant digits (they read back exactly;
    NaN as an empty cell), booleans ``True``/``False``, integers and text as they are."""
    if isinstance(x, str):
        return x
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return "" if np.isnan(x) else repr(float(x))


def csv_content(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Callable[[BinaryIO], None]:
    """``write(fh)`` writing a UTF-8 CSV table (``header``, then ``rows``) to a binary file."""
    import csv
    import io

    def write(binary: BinaryIO) -> None:
        fh = io.TextIOWrapper(binary, encoding="utf-8", newline="")
        try:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(rows)
        finally:
            fh.detach()  # flushed; the binary file stays open for its owner

    return write
