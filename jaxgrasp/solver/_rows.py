"""Work on the rows of a batch that need it, gathered in fixed-size blocks.

Under ``vmap`` a branch taken by a few lanes costs as much as one taken by all of them.
`over_rows` instead runs a computation on the rows where a mask is true, ``block``
rows at a time, in as many blocks as there are such rows (none where there are none):
the shapes stay static, the cost follows the count. `jaxgrasp.solver._direction` uses it for
``eigh``, `jaxgrasp.solver._line_search` for the ladder past the full step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["over_rows", "put_rows"]


def over_rows(use, block: int, update, carry):
    """Fold ``update(rows, valid, carry) -> carry`` over the rows where ``use`` ``(B,)``
    is true, ``block`` at a time (static; at most ``B``): ``rows`` ``(block,)`` uint32 are
    row indices, ``valid`` ``(block,)`` bool is false on the padding rows of the last
    block (which repeat a real row: write with `put_rows`)."""
    size = use.shape[0]
    block = min(block, size)
    num_blocks = -(-size // block)
    # the rows in use, in increasing order, then row 0 as padding: each row in use is
    # scattered to its rank among them (a cumulative sum, where a sort would order the
    # whole batch); unsigned, so that indexing with them adds no wrap-around of negative
    # indices
    rank = jnp.cumsum(use.astype(jnp.int32)) - 1
    slot = jnp.where(use, rank, num_blocks * block)
    order = jnp.zeros(num_blocks * block, jnp.uint32).at[slot].set(jnp.arange(size, dtype=jnp.uint32), mode="drop")
    count = rank[-1] + 1

    def body(c):
        i, carry = c
        rows = jax.lax.dynamic_slice(order, (i * block,), (block,))
        return i + 1, update(rows, i * block + jnp.arange(block) < count, carry)

    return jax.lax.while_loop(lambda c: c[0] * block < count, body, (jnp.asarray(0, jnp.int32), carry))[1]


def put_rows(a, rows, valid, values):
    """``a`` with ``a[rows] = values`` where ``valid`` (the other writes are dropped)."""
    return a.at[jnp.where(valid, rows, jnp.asarray(a.shape[0], rows.dtype))].set(values, mode="drop")
