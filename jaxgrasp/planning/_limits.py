"""What [`plan`][jaxgrasp.plan]'s arguments may be, in plain Python: the command line's parser
reads them without loading JAX (`jaxgrasp._startup.attach`)."""

from __future__ import annotations

__all__ = ["SAMPLERS"]

SAMPLERS = ("antipodal", "spread", "uniform")
"""Candidate generators: ``antipodal`` (two fingers), ``spread`` (three or more), ``uniform``
(independent uniform surface points: plain random sampling, the baseline)."""
