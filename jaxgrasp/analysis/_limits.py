"""What the analyses' arguments may be, in plain Python: the command line's parser reads
them without loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["MAX_GRID_POINTS", "MAX_ROBUST_SAMPLES", "MAX_TUNE_ITERATIONS", "METHODS", "ROBUST_SAMPLES_WHAT",
           "TUNE_ITERATIONS_WHAT"]

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

MAX_ROBUST_SAMPLES = 100_000
"""The most perturbed copies per grasp of [`robust`][jaxgrasp.robust] (``samples``; ``--samples``
with ``--robust``, ``plan --robust-samples``). Every copy's draws, perturbed fields and result
arrays stay in memory until the statistics, about 1 KB per copy of a two-contact grasp and a
few KB for eight (``experiments/limits/FINDINGS.md``): well under 1 GB per grasp at the cap,
and a long evaluation on a CPU. The statistics need far fewer: the standard error of
``p_stable`` is at most 0.005 at 10,000 copies. A larger count (``--samples 1e12`` asked NumPy
for 29 TiB) is refused before anything is drawn."""

MAX_TUNE_ITERATIONS = 10_000
"""The most iterations of one [`tune`][jaxgrasp.tune] (``maxiter``, ``jaxgrasp tune --maxiter``)
and of each refinement of [`plan`][jaxgrasp.plan] (``tune_maxiter``). Each iteration evaluates the
value and its gradient, and its history is kept; L-BFGS-B converges within a few hundred
iterations on the paper's grasps, so the cap only ever ends a run that no longer improves."""

ROBUST_SAMPLES_WHAT = "perturbed copies per grasp (MAX_ROBUST_SAMPLES: every copy is held in memory and evaluated)"
"""What `MAX_ROBUST_SAMPLES` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""

TUNE_ITERATIONS_WHAT = "iterations (MAX_TUNE_ITERATIONS: L-BFGS-B converges within a few hundred)"
"""What `MAX_TUNE_ITERATIONS` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""
