"""Small contractions as one product and sum (:func:`jaxgrasp.base.contract`, below the solver and the model), and the
gathered blocks of rows (:mod:`jaxgrasp.solver._rows`) the solver runs its rare branches on.

:func:`contract` must be ``einsum`` to rounding for every pattern the model and the
solver use (transposed operands, three operands, full contractions, outer products),
under ``vmap`` as on one lane, with gradients; :func:`over_rows` must visit exactly the
rows in use, each once, in increasing order, whatever their count.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.base import contract
from jaxgrasp.solver._rows import over_rows, put_rows  # importing jaxgrasp turns on float64

# every pattern jaxgrasp's model and solver contract with, with operand shapes
PATTERNS = [
    ("nb,ab->na", [(7, 3), (3, 3)]),  # points by a rotation's transpose
    ("ab,bc->ac", [(3, 3), (3, 3)]),
    ("ijk,k->ij", [(3, 3, 3), (3,)]),
    ("ijk,ij->k", [(3, 3, 3), (3, 3)]),
    ("a,a->", [(3,), (3,)]),
    ("a,ab,b->", [(3,), (3, 3), (3,)]),
    ("a,b->ab", [(3,), (3,)]),
    ("abk,nb->nka", [(3, 3, 3), (7, 3)]),
    ("nka,na->nk", [(7, 3, 3), (7, 3)]),
    ("n,nka,nla->kl", [(7,), (7, 3, 3), (7, 3, 3)]),
    ("n,na,nk->ak", [(7,), (7, 3), (7, 3)]),
    ("nk,nkj->j", [(7, 4), (7, 4, 6)]),
    ("rn,rnkl->nkl", [(3, 7), (3, 7, 4, 4)]),
    ("njm,njl->ml", [(7, 4, 6), (7, 4, 6)]),
    ("mi,m,mj->ij", [(21, 6), (21,), (21, 6)]),
    ("mi,m->i", [(21, 6), (21,)]),
    ("mi,i->m", [(21, 6), (6,)]),
]


@pytest.mark.parametrize("subscripts,shapes", PATTERNS, ids=[p[0] for p in PATTERNS])
def test_contract_is_einsum_to_rounding(subscripts, shapes):
    rng = np.random.default_rng(len(subscripts))
    ops = [rng.standard_normal(s) for s in shapes]
    want = np.einsum(subscripts, *ops)
    got = np.asarray(contract(subscripts, *ops))
    assert got.shape == want.shape and got.dtype == np.float64
    scale = np.einsum(subscripts, *[np.abs(o) for o in ops])  # the sum of |terms|: rounding's scale
    np.testing.assert_array_less(np.abs(got - want), 1e-14 * (scale + 1e-300))


def test_contract_under_vmap_and_grad_matches_einsum():
    rng = np.random.default_rng(3)
    a, w, b = rng.standard_normal((5, 21, 6)), rng.standard_normal((5, 21)), rng.standard_normal((5, 21, 6))
    batched = jax.vmap(lambda a, w, b: contract("mi,m,mj->ij", a, w, b))(a, w, b)
    np.testing.assert_allclose(batched, np.einsum("zmi,zm,zmj->zij", a, w, b), rtol=1e-13, atol=1e-13)
    f = lambda w: jnp.sum(contract("mi,m,mj->ij", a[0], w, b[0]) ** 2)  # noqa: E731
    g = lambda w: jnp.sum(jnp.einsum("mi,m,mj->ij", a[0], w, b[0]) ** 2)  # noqa: E731
    np.testing.assert_allclose(jax.grad(f)(w[0]), jax.grad(g)(w[0]), rtol=1e-12)


def test_contract_has_no_dot_under_vmap():
    # the point of contract: a batch of small products is a fused loop, not a batched dot
    a = jnp.ones((128, 21, 6))
    text = jax.jit(jax.vmap(lambda a: contract("mi,mj->ij", a, a))).lower(a).as_text()
    assert "dot_general" not in text


@pytest.mark.parametrize(
    "subscripts,shapes,match",
    [
        ("ab,bc->ac", [(3, 3)], "2 operand subscripts for 1 operands"),
        ("aa->a", [(3, 3)], "do not fit"),
        ("ab->a", [(3,)], "do not fit"),
    ],
)
def test_contract_refuses_subscripts_that_do_not_fit(subscripts, shapes, match):
    with pytest.raises(ValueError, match=match):
        contract(subscripts, *[np.ones(s) for s in shapes])


@pytest.mark.parametrize("count", [0, 1, 7, 8, 9, 23])
@pytest.mark.parametrize("block", [1, 8])
def test_over_rows_visits_the_rows_in_use_once_in_order(count, block):
    size = 23
    rng = np.random.default_rng(count)
    use = np.zeros(size, bool)
    use[rng.choice(size, count, replace=False)] = True

    def update(rows, valid, c):
        seen, order, k = c
        seen = put_rows(seen, rows, valid, seen[rows] + 1)
        order = put_rows(order, jnp.where(valid, k + jnp.arange(rows.shape[0]), size).astype(rows.dtype), valid, rows.astype(order.dtype))
        return seen, order, k + jnp.sum(valid, dtype=jnp.int32)

    carry = (jnp.zeros(size, jnp.int32), jnp.full(size, -1, jnp.int32), jnp.asarray(0, jnp.int32))
    seen, order, k = jax.jit(lambda u: over_rows(u, block, update, carry))(jnp.asarray(use))
    np.testing.assert_array_equal(seen, use.astype(np.int32))  # every row in use once, no other
    assert int(k) == count
    np.testing.assert_array_equal(order[:count], np.flatnonzero(use))  # in increasing order
