"""What the analyses' arguments may be, in plain Python: the command line's parser reads
them without loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["MAX_GRID_POINTS", "METHODS"]

MAX_GRID_POINTS = 10_000_000
"""The most grid points one [`sweep`][jaxgrasp.sweep] takes. Its result arrays hold 5 numbers of 8 bytes
per point (0.4 GB at the cap), ``jaxgrasp sweep``'s CSV about 100 bytes per point (1 GB)
and its grid of axis values 8 bytes per point and axis, all in memory at the end; and a
2-core CPU needs a day or more for that many points. A larger grid (three axes of 465
points: 1e8) is refused before anything is allocated; split it into several sweeps."""

METHODS = ("scipy_lbfgsb", "jaxopt_lbfgsb", "projected_gradient")
"""Optimisers, all on the same compiled value and envelope gradient: SciPy's L-BFGS-B
(default; ``scipy.optimize.minimize``), ``jaxopt.LBFGSB`` and ``jaxopt.ProjectedGradient``
with ``projection_box``. At a maximum on a kink (the cube's shared deformation)
``jaxopt.LBFGSB`` takes short steps and compiles its update separately, and projected
gradient oscillates around the kink; SciPy's L-BFGS-B is the default."""
