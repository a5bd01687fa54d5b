"""Several processes joined by ``jax.distributed``: joining, and passing bytes between them.

``jaxgrasp batch --num-processes P`` runs one process per host (or several on one host),
each evaluating its own share of a dataset on its own devices; they meet twice, through
`exchange`: once their inputs are read (so that every process learns the largest
contact count and whether any failed) and once their results are in (so that process 0
writes one file in input order). Nothing else passes between them, so a slow share does
not hold the others up chunk by chunk.

The bytes go through JAX's own collectives (`jax.experimental.multihost_utils.process_allgather`,
gloo on CPU hosts), so nothing but ``jax.distributed`` needs to be set up.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys

import jax
import numpy as np

__all__ = ["join", "leave", "exchange", "pack", "unpack", "parse_coordinator"]

_HOST_PORT = re.compile(r"^(?P<host>\[[0-9A-Fa-f:.]+\]|[^\s:\[\]]+):(?P<port>[0-9]{1,5})$")


def parse_coordinator(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (an IPv6 host in brackets) -> ``(host, port)``.

    Raises:
        ValueError: one line, if ``text`` is not of that form or the port not in 1..65535.
    """
    m = _HOST_PORT.match(text)
    port = int(m["port"]) if m else 0
    if not m or not 1 <= port <= 65535:
        raise ValueError(f"must be HOST:PORT (e.g. 10.0.0.1:12355, a port in 1..65535), got {text!r}")
    return m["host"], port


def join(coordinator: str, num_processes: int, process_id: int) -> None:
    """Join the ``num_processes`` processes of one run as process ``process_id``
    (``jax.distributed.initialize``; process 0 serves as the coordinator at
    ``coordinator``, ``HOST:PORT``), with gloo collectives on CPU hosts unless JAX was
    told otherwise. Must come before any JAX computation of the process; returns once
    every process has joined."""
    if jax.config.jax_cpu_collectives_implementation in (None, "", "none"):
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(coordinator, num_processes, process_id)


def leave() -> None:
    """Leave the run (``jax.distributed.shutdown``, which waits for every process), so
    that no process ends while another still talks to it."""
    jax.distributed.shutdown()


@contextlib.contextmanager
def _stdout_on_stderr():
    """Whatever the process writes on its standard output meanwhile goes to its standard
    error: gloo announces its connections there, and a command's standard output is
    its result."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


BARRIER_TIMEOUT_MS = 7 * 24 * 3600 * 1000
"""How long a process waits for the others at a meeting (ms): a week, as a share may take
hours longer than another's."""

_MEETINGS = [0]  # meetings so far in this process: each barrier's name


def _wait_for_the_others() -> None:
    """Wait until every process has come to this meeting, at a barrier of JAX's
    coordination service (which also notices a process that died), so that the
    collective that follows starts with every process there: XLA's CPU collectives give
    up after a time limit of their own, shorter than a long share may take. Where JAX's
    client lacks the barrier (a private entry point), the collective waits alone."""
    _MEETINGS[0] += 1
    try:
        from jax._src import distributed

        wait = distributed.global_state.client.wait_at_barrier
    except (ImportError, AttributeError):  # pragma: no cover - another JAX
        return
    wait(f"jaxgrasp-meeting-{_MEETINGS[0]}", BARRIER_TIMEOUT_MS)


def exchange(blob: bytes) -> list[bytes]:
    """Every process's ``blob``, by process index (each process gets all of them). A
    collective: every process of the run must call it, the same number of times."""
    _wait_for_the_others()
    with _stdout_on_stderr():
        return _exchange(blob)


def _exchange(blob: bytes) -> list[bytes]:
    from jax.experimental.multihost_utils import process_allgather

    data = np.frombuffer(blob, dtype=np.uint8)
    sizes = np.asarray(process_allgather(np.int64(data.size))).reshape(-1)
    padded = np.zeros(max(int(sizes.max()), 1), dtype=np.uint8)
    padded[: data.size] = data
    every = np.asarray(process_allgather(padded))
    return [every[p, : int(n)].tobytes() for p, n in enumerate(sizes)]


def pack(arrays: dict[str, np.ndarray]) -> bytes:
    """Named NumPy arrays (numbers, bools or strings; no objects) as ``.npz`` bytes."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def unpack(blob: bytes) -> dict[str, np.ndarray]:
    """The arrays of `pack`, by name (no pickles read)."""
    with np.load(io.BytesIO(blob), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
