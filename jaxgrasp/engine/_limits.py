"""The engine's limits, in plain Python: the command line's parser reads them without
loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["MAX_CHUNK_SIZE", "CHUNK_SIZE_WHAT"]

MAX_CHUNK_SIZE = 65_536
"""The most grasps one compiled call evaluates (``chunk_size``, ``--chunk-size``), over all
devices: 64 times the default of one GPU (1024), 8 GPUs' defaults 8 times over. XLA's
temporaries of a chunk grow with it (about 25 KB per grasp of two contacts on a CPU, more
with more contacts), so the cap is about 2 GB for two contacts; a larger chunk only
compiles longer and risks the device's memory (a chunk is at most the run's own size
anyway)."""


CHUNK_SIZE_WHAT = "grasps per compiled call (MAX_CHUNK_SIZE: a chunk's memory grows with it)"
"""What `MAX_CHUNK_SIZE` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""
