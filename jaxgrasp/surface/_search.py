"""Searches of a `FaceTree` in JAX: one query per lane, depth first with a stack, traceable.

Each search walks the tree in a ``lax.while_loop`` with a stack of ``depth + 1`` nodes (a
node's nearer child is visited first, its farther child waits on the stack): a node is
skipped when the lower bound of what it may hold exceeds the search's bound, and a leaf
runs the exact test on its faces. Under ``vmap`` the lanes loop in lockstep until the last
finishes; memory is the queries times the stack and one leaf's faces, never the faces.

The walks pick faces and decide, so they run on stopped gradients (``while_loop`` has no
reverse-mode derivative); [`Surface.closest`][jaxgrasp.surface.Surface.closest] computes the
point again, differentiably, on the face chosen.

Bounds carry a slack of round-off (`_SLACK` of the distance squared, and `_FLOOR` of
the mesh's size squared): a node is pruned only when none of its faces can meet the test,
so the answers are those of a brute force over every face.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgrasp.surface._tree import FaceTree
from jaxgrasp.surface._triangles import closest_on_triangles

__all__ = ["TIE", "nearest_slot", "unaligned_within"]

_SLACK = 1e-12
"""Relative slack of a squared-distance bound (round-off of the boxes' lower bounds)."""

_FLOOR = 1e-16
"""Absolute slack of a squared-distance bound, of the mesh's size squared (the round-off
of a box's lower bound near zero, ``2 gap eps <= _SLACK gap^2 + eps^2 / _SLACK``)."""

TIE = 1e-12
"""Relative tie in distance (of the mesh's size) between faces sharing a closest point (an
edge or a vertex): faces within ``TIE scale`` m of the smallest distance are tied."""


def _box_d2(boxes, node, p):
    """Squared distance from ``p (3,)`` to the boxes of ``node (...)``."""
    gap = jnp.maximum(jnp.maximum(boxes[node, 0] - p, p - boxes[node, 1]), 0.0)
    return jnp.sum(gap * gap, axis=-1)


def _walk(tree: FaceTree, lower, bound, visit, acc, stop=lambda acc: jnp.bool_(False), start=True):
    """Depth-first search: ``lower(nodes) -> (...)`` the bound of what each node may hold,
    ``bound(acc)`` the largest lower bound worth visiting, ``visit(acc, leaf) -> acc`` at
    each leaf reached, ``stop(acc)`` an early end; ``start`` False: no search (``acc``).

    Each step of the outer loop tests one leaf; between two, an inner loop pops the stack
    and descends to the next leaf worth testing through the nearer children, the farther
    ones waiting on the stack (box tests only): in lockstep lanes no step tests a leaf for
    nothing."""
    leaves = tree.leaf_faces.shape[0]
    size = leaves.bit_length()  # depth + 1
    slots = jnp.arange(size)
    root = jnp.where(start, 1, 0).astype(jnp.int32)
    state = (jnp.int32(0), jnp.zeros(size, jnp.int32), jnp.zeros(size), root, lower(jnp.int32(1)))

    def descend(state, b):
        def step(s):
            sp, nodes, lows, cur, low = s
            empty, top = cur == 0, slots == sp - 1  # one-hot selects: cheaper than gathers in lockstep lanes
            cur = jnp.where(empty, jnp.max(jnp.where(top, nodes, 0)), cur)
            low = jnp.where(empty, jnp.max(jnp.where(top, lows, -jnp.inf)), low)
            sp = sp - empty.astype(jnp.int32)
            alive = low <= b
            kids = jnp.minimum(2 * cur + jnp.arange(2, dtype=jnp.int32), 2 * leaves - 1)
            kl = lower(kids)
            near = (kl[1] < kl[0]).astype(jnp.int32)
            go = alive & (cur < leaves)
            at = (slots == sp) & go & (kl[1 - near] <= b)  # the farther child waits
            nodes, lows = jnp.where(at, kids[1 - near], nodes), jnp.where(at, kl[1 - near], lows)
            sp = sp + jnp.any(at).astype(jnp.int32)
            down = go & (kl[near] <= b)
            cur = jnp.where(go, jnp.where(down, kids[near], 0), jnp.where(alive, cur, 0))
            low = jnp.where(go, kl[near], low)
            return sp, nodes, lows, cur, low

        return jax.lax.while_loop(lambda s: (s[3] < leaves) & ((s[3] > 0) | (s[0] > 0)), step, state)

    def body(carry):
        state, acc = carry
        state = descend(state, bound(acc))
        sp, nodes, lows, cur, low = state
        new = visit(acc, jnp.clip(cur - leaves, 0, leaves - 1))
        acc = jax.tree_util.tree_map(lambda a, b: jnp.where(cur >= leaves, a, b), new, acc)
        return (sp, nodes, lows, jnp.int32(0), low), acc

    def more(carry):
        (sp, _, _, cur, _), acc = carry
        return ((sp > 0) | (cur > 0)) & ~stop(acc)

    return jax.lax.while_loop(more, body, (state, acc))[1]


def nearest_slot(tree: FaceTree, p, scale) -> tuple[jax.Array, jax.Array]:
    """``(leaf, slot)`` int32 of the face closest to ``p (3,)`` (stopped gradients).

    Among the faces whose distance lies within ``TIE scale`` m of the smallest (an edge or
    a vertex; ``scale`` m the mesh's size), the one whose plane is farthest from ``p``
    along its normal, then the smallest face index: the rule of a brute force over every
    face.

    One search keeps the smallest squared distance and the best of the faces tied with it
    so far. A closer face found later drops the faces no longer tied; where it was closer
    by less than the tie and the best so far dropped out, a face seen earlier might still
    be tied and is not kept: such a query (a rare near tie) is searched again with the
    final bound, by a second search that runs only where some lane needs it.
    """
    tree, p, scale = jax.lax.stop_gradient((tree, p, scale))
    lower = lambda nodes: _box_d2(tree.boxes, nodes, p)  # noqa: E731
    none = jnp.iinfo(jnp.int32).max
    tied = lambda best: (jnp.sqrt(best) + TIE * scale) ** 2  # noqa: E731  (squared distances)
    slack = lambda limit: limit * (1.0 + _SLACK) + _FLOOR * scale**2  # noqa: E731

    def faces(leaf):
        q = closest_on_triangles(p, tree.leaf_triangles[leaf])
        d2 = jnp.sum((q - p) ** 2, axis=-1)
        return d2, jnp.abs(jnp.einsum("kd,kd->k", p - q, tree.leaf_normals[leaf])), tree.leaf_faces[leaf]

    def pick(acc, leaf, d2, h, f, limit):
        """The best of the winner so far and this leaf's faces within ``limit``."""
        best, height, face, dw, at, unsure = acc
        h = jnp.where(d2 <= limit, h, -1.0)
        k = jnp.argmin(jnp.where(h == jnp.max(h), f, none))
        keep = dw <= limit
        height, face = jnp.where(keep, height, -1.0), jnp.where(keep, face, none)
        better = (h[k] > height) | ((h[k] == height) & (f[k] < face))
        return (best, jnp.where(better, h[k], height), jnp.where(better, f[k], face), jnp.where(better, d2[k], dw),
                jnp.where(better, jnp.stack([leaf, k]).astype(jnp.int32), at), unsure)

    def running(acc, leaf):
        d2, h, f = faces(leaf)
        best = jnp.minimum(acc[0], jnp.min(d2))
        dropped = (acc[3] > tied(best)) & (acc[0] <= tied(best))  # faces seen earlier may still tie
        acc = pick(acc, leaf, d2, h, f, tied(best))
        return (best,) + acc[1:5] + (acc[5] | dropped,)

    start = (jnp.float64(jnp.inf), jnp.float64(-1.0), jnp.int32(none), jnp.float64(jnp.inf), jnp.zeros(2, jnp.int32),
             jnp.bool_(False))
    acc = _walk(tree, lower, lambda acc: slack(tied(acc[0])), running, start)
    limit = tied(acc[0])

    def final(acc, leaf):
        d2, h, f = faces(leaf)
        return pick(acc, leaf, d2, h, f, limit)

    again = start[:1] + (jnp.float64(-1.0), jnp.int32(none), jnp.float64(jnp.inf)) + start[4:]
    acc = _walk(tree, lower, lambda _: slack(limit), final, jax.tree_util.tree_map(
        lambda a, b: jnp.where(acc[5], a, b), again, acc), start=acc[5])
    return acc[4][0], acc[4][1]


def unaligned_within(tree: FaceTree, p, n, radius, cos_max, scale) -> jax.Array:
    """``()`` bool: some face lies within ``radius`` m of ``p (3,)`` (its closest point) with
    a normal at more than ``arccos(cos_max)`` from the unit ``n (3,)`` (``n . m < cos_max``);
    ``scale`` m, the mesh's size.

    Nodes farther than ``radius`` are skipped, and so are nodes whose normals' box lies
    wholly within the angle; the search ends at the first such face.
    """
    tree, p, n, radius, scale = jax.lax.stop_gradient((tree, p, n, radius, scale))

    def lower(nodes):
        nb = tree.normal_boxes[nodes]  # the least n . m over the box bounds every face's below
        least = jnp.sum(jnp.minimum(nb[..., 0, :] * n, nb[..., 1, :] * n), axis=-1)
        return jnp.where(least >= cos_max + 1e-12, jnp.inf, _box_d2(tree.boxes, nodes, p))

    def visit(found, leaf):
        q = closest_on_triangles(p, tree.leaf_triangles[leaf])
        within = jnp.linalg.norm(q - p, axis=-1) <= radius
        return found | jnp.any(within & (tree.leaf_normals[leaf] @ n < cos_max))

    r2 = radius * radius
    bound = r2 * (1.0 + _SLACK) + _FLOOR * scale**2
    return _walk(tree, lower, lambda found: bound, visit, jnp.bool_(False), stop=lambda f: f)
