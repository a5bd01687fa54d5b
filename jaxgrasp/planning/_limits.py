"""What [`plan`][jaxgrasp.plan]'s arguments may be, in plain Python: the command line's parser
reads them without loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["MAX_FINGERS", "MAX_PLAN_REFINE", "MAX_PLAN_SAMPLES", "PLAN_REFINE_WHAT", "PLAN_SAMPLES_WHAT", "SAMPLERS"]

SAMPLERS = ("antipodal", "spread", "uniform")
"""Candidate generators: ``antipodal`` (two fingers), ``spread`` (three or more), ``uniform``
(independent uniform surface points: plain random sampling, the baseline)."""

MAX_FINGERS = 8
"""The most fingertips of a planned grasp (``fingers``, ``--fingers``): the paper's grasps have 2
to 8, and the samplers' rules (fingertips apart, one contact each) find few valid tuples of more
on an ordinary object."""

MAX_PLAN_SAMPLES = 100_000
"""The most valid candidates one [`plan`][jaxgrasp.plan] evaluates (``samples``, ``--samples``;
also the most it ranks, ``top``). A candidate costs its draws (up to 100 per valid one, in rounds
of 512), its positions, normals and deformations (7 numbers per fingertip) and its evaluation
(about as long as a robust copy's, ``experiments/limits/FINDINGS.md``): the cap is well under
1 GB of memory and a long run on a CPU, while 150 (the default) to a few thousand find the best
grasps of an ordinary object. A larger count (``--samples 1e12`` ran without end) is refused
before the mesh is read; to search wider, run plans with other seeds."""

MAX_PLAN_REFINE = 1_000
"""The most best candidates one [`plan`][jaxgrasp.plan] refines (``refine``, ``--refine``): each is a
gradient tuning of up to ``tune_maxiter`` iterations, tens of evaluations of the value and its
gradient, so a thousand refinements are already a long run."""

PLAN_SAMPLES_WHAT = ("candidates per plan (MAX_PLAN_SAMPLES: each is an evaluation; to search wider, run plans "
                     "with other seeds)")
"""What `MAX_PLAN_SAMPLES` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""

PLAN_REFINE_WHAT = "refined candidates per plan (MAX_PLAN_REFINE: each is a gradient tuning)"
"""What `MAX_PLAN_REFINE` counts, in its one-line refusal (`jaxgrasp.base.over_limit`)."""
