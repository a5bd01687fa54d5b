"""The engine's limits, in plain Python: the command line's parser reads them without
loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["CHUNK_SIZE_WHAT", "MAX_CHUNK_SIZE"]

MAX_CHUNK_SIZE = 65_536
"""The most grasps one compiled call evaluates (``chunk_size``, ``--chunk-size``), over all
devices: 64 times the default of one GPU (1024), 8 GPUs' defaults 8 times over. XLA's
temporaries of a chunk grow with it, about 0.1 MB per grasp of two contacts on a CPU and
more with more contacts (``experiments/limits/FINDINGS.md``): several GB at the cap, split
over the devices. A larger chunk only compiles longer and risks the devices' memory (a
chunk is at most the run's own size anyway)."""


CHUNK_SIZE_WHAT = "grasps per compiled call (MAX_CHUNK_SIZE: a chunk's memory grows with it)"
"""What `MAX_CHUNK_SIZE` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""
