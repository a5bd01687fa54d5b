"""The value and gradient of an evaluation along a parametrised grasp: the one builder
behind both gradient-based tuners ([`jaxgrasp.tune`][jaxgrasp.tune], [`jaxgrasp.tune_hand`][jaxgrasp.tune_hand]).

The gradient is the envelope theorem's (`jaxgrasp.tolerance.envelope_energy`,
through `evaluate_compiled`): exact, with no
differentiation through the solver. Where the value is not finite (or the grasp is not one
to count) it is 0, and so is its gradient; a non-finite gradient entry is 0.
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp

from jaxgrasp.engine._evaluate import evaluate_compiled
from jaxgrasp.tolerance import EvaluateOptions

__all__ = ["value_and_grad_builder"]


def value_and_grad_builder(grasp_of: Callable[[Any, Any], tuple[Any, Any]], options: EvaluateOptions, *,
                           temperature_of: Callable[[Any], Any] | None = None,
                           counts: Callable[[Any], Any] | None = None,
                           objective: Callable[[Any, Any], Any] | None = None) -> Callable:
    """``vg(x, data) -> ((f, (evaluation, aux)), df_dx)``, traceable (to be compiled by the
    caller, e.g. `StoredFunction`).

    Args:
        grasp_of: ``grasp_of(x, data) -> (grasp, aux)``: the [`Grasp`][jaxgrasp.Grasp] (SI
            units) at the parameters ``x`` (any shape), and anything the caller wants back.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions] of the evaluation
            (``smooth_min_temperature`` ignored: see ``temperature_of``).
        temperature_of: ``temperature_of(data)``, the soft-minimum temperature in mJ
            (``()``); default the hard minimum (0).
        counts: ``counts(grasp)``, ``()`` bool: whether the value counts (it is 0
            otherwise, as where it is not finite); default always.
        objective: ``objective(value, data)``, what is differentiated, from the value in J
            (``()``); default the value itself.

    Returns:
        ``vg``: ``f`` the objective, ``evaluation`` the [`Evaluation`][jaxgrasp.Evaluation],
        ``df_dx`` shaped like ``x`` with non-finite entries 0.
    """

    def f(x, data):
        grasp, aux = grasp_of(x, data)
        temperature = jnp.float64(0.0) if temperature_of is None else temperature_of(data)
        ev = evaluate_compiled(grasp, temperature, options)
        ok = jnp.isfinite(ev.value) if counts is None else jnp.isfinite(ev.value) & counts(grasp)
        v = jnp.where(ok, ev.value, 0.0)
        return (v if objective is None else objective(v, data)), (ev, aux)

    vg = jax.value_and_grad(f, has_aux=True)

    def finite_vg(x, data):
        (out, aux), g = vg(x, data)
        return (out, aux), jnp.where(jnp.isfinite(g), g, 0.0)

    return finite_vg
