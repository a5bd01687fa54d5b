"""Small tensor contractions written as one broadcast product and one sum.

The solver's and the model's lanes contract arrays of a few entries per axis (``3 x 3`` rotations, the
``3N x 6`` constraint Jacobian, ``4 x 6`` kinematic Jacobians). Under ``vmap`` a
``jnp.einsum`` or ``@`` of such arrays becomes a batched ``dot``, which XLA's CPU backend
runs as one small matrix product per lane, each a call of its own, and which fuses with
nothing around it. `contract` computes the same contraction as an elementwise
product of the operands broadcast to every index, summed over the contracted ones: a loop
that XLA fuses with the operations that make its operands and use its result, the same
for every lane. The sum's order differs from a ``dot``'s, so results differ by rounding.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["contract"]


def contract(subscripts: str, *operands):
    """``jnp.einsum(subscripts, *operands)`` for explicit subscripts (``"nka,na->nk"``;
    each index at most once per operand, every output index in some operand), computed
    as the product of the operands broadcast to the output indices followed by the
    contracted ones, summed over the contracted ones.

    The product holds one entry per combination of all indices, so this is for small
    operands only (at most a few thousand entries in that product)."""
    inputs, output = subscripts.replace(" ", "").split("->")
    specs = inputs.split(",")
    if len(specs) != len(operands):
        raise ValueError(f"contract: {len(specs)} operand subscripts for {len(operands)} operands")
    contracted = "".join(sorted(set("".join(specs)) - set(output)))
    full = output + contracted
    product = None
    for spec, operand in zip(specs, operands):
        operand = jnp.asarray(operand)
        if len(set(spec)) != len(spec) or len(spec) != operand.ndim:
            raise ValueError(f"contract: subscripts {spec!r} do not fit an operand of shape {operand.shape}")
        present = sorted(spec, key=full.index)
        operand = jnp.transpose(operand, [spec.index(c) for c in present])
        operand = operand.reshape([operand.shape[present.index(c)] if c in present else 1 for c in full])
        product = operand if product is None else product * operand
    return jnp.sum(product, axis=tuple(range(len(output), len(full)))) if contracted else product
