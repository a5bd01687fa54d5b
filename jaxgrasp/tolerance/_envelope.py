"""Minimum energies with their exact derivative (envelope theorem), and the soft minimum.

The solver runs on ``stop_gradient`` parameters and its iterations are never
differentiated. Each minimum energy is instead passed through `envelope_energy`, a
``jax.custom_jvp`` function whose value is the solver's ``U*`` and whose tangent is
``dL/dtheta . dtheta`` at the fixed solution ``(z*, lam*, nu*)``: by the envelope theorem
that is the derivative of ``min_z U(z; theta)`` at a regular KKT point. ``jax.grad``,
``jax.jacfwd``, ``jax.jvp`` and their ``vmap`` all go through that rule.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgrasp.model import energy_scale
from jaxgrasp.tolerance._problems import lagrangian, problem_data

__all__ = ["envelope_energy", "soft_minimum"]


@jax.custom_jvp
def envelope_energy(params, z, lam, nu, eq_mask, objective):
    """A problem's minimum energy with its envelope-theorem derivative, mJ.

    ``objective`` is the solver's scaled minimum ``f(z*) = U(z*) / scale`` of the problem
    with constraints ``g(z; params) >= 0`` and equality row ``eq_mask``, attained at
    ``z`` with multipliers ``lam`` (inequalities) and ``nu`` (equality). Returns
    ``scale * objective``; its tangent in ``params`` is

        ``scale * dL/dparams . dparams``,  ``L = f(z) + nu h(z) - lam . g(z)``

    with ``(z, lam, nu)`` held fixed (envelope theorem, valid at a regular KKT point).
    Tangents of ``z``, ``lam``, ``nu``, ``eq_mask`` and ``objective`` are ignored: they
    are the solver's outputs, which are never differentiated. Works under ``jax.grad``,
    ``jax.jacfwd``, ``jax.jvp`` and ``jax.vmap`` (``params`` is a
    `jaxgrasp.model.ModelParams`).
    """
    return energy_scale(params) * objective


@envelope_energy.defjvp
def _envelope_energy_jvp(primals, tangents):
    params, z, lam, nu, eq_mask, objective = primals
    dparams = tangents[0]
    scale = energy_scale(params)
    _, dl = jax.jvp(lambda q: lagrangian(z, lam, nu, eq_mask, problem_data(q)), (params,), (dparams,))
    return scale * objective, scale * dl


def soft_minimum(du, mask, temperature):
    """``-T log sum_{b in mask} exp(-du_b / T)``, computed stably; ``+inf`` for an empty mask.

    Entries outside ``mask`` (or infinite) are left out and get a zero gradient. Bias:
    ``min(du) - T log K <= result <= min(du)`` with ``K`` the number of entries kept.
    """
    du = jnp.asarray(du)
    mask = mask & jnp.isfinite(du)
    ref = jax.lax.stop_gradient(jnp.min(jnp.where(mask, du, jnp.inf)))
    any_kept = jnp.any(mask)
    ref_safe = jnp.where(any_kept, ref, 0.0)
    shifted = jnp.where(mask, du, ref_safe) - ref_safe  # >= 0 where kept, 0 elsewhere
    w = jnp.where(mask, jnp.exp(-shifted / temperature), 0.0)  # in [0, 1]; 1 at the min
    total = jnp.where(any_kept, jnp.sum(w), 1.0)
    return jnp.where(any_kept, ref_safe - temperature * jnp.log(total), jnp.inf)
