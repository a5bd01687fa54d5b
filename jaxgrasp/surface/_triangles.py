"""The one closest-point rule of jaxgrasp: the closest point on each of many triangles, in JAX or NumPy."""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["closest_on_triangles"]


def closest_on_triangles(p, tri, xp=jnp):
    """The closest point to ``p (3,)`` on each triangle of ``tri (F, 3, 3)``, ``(F, 3)`` (or to
    ``p (F, 3)``, one point per triangle).

    Exact, by the triangle's Voronoi regions (Ericson, *Real-Time Collision Detection*,
    Sec. 5.1.5); denominators are guarded so that the branches not taken carry finite
    derivatives. Triangles must have non-zero area.

    ``xp`` is the array library: ``jax.numpy`` (the default: traceable, differentiable) or
    ``numpy``, for the host code that snaps a mesh grasp's contacts
    (`grasp_on_mesh`, once per grasp of a dataset or a plan) and searches the face tree on
    the host (`jaxgrasp.surface._tree.nearest_faces`), where dispatching each operation to
    JAX would cost more than the arithmetic. One rule, run by either library; the tests
    hold the two to each other. Over every face of a mesh it costs memory of the faces:
    [`Surface.closest`][jaxgrasp.surface.Surface.closest] runs it on the faces its tree
    finds.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac = b - a, c - a
    d1, d2 = _dot(ab, p - a, xp), _dot(ac, p - a, xp)
    d3, d4 = _dot(ab, p - b, xp), _dot(ac, p - b, xp)
    d5, d6 = _dot(ab, p - c, xp), _dot(ac, p - c, xp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    inside = a + ab * _ratio(vb, denom, xp) + ac * _ratio(vc, denom, xp)
    regions = [  # (condition, point), in Ericson's order: the first that holds applies
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + _ratio(d1, d1 - d3, xp) * ab),
        ((d6 >= 0) & (d5 <= d6), c),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + _ratio(d2, d2 - d6, xp) * ac),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + _ratio(d4 - d3, (d4 - d3) + (d5 - d6), xp) * (c - b)),
    ]
    out = inside
    for cond, point in reversed(regions):
        out = xp.where(cond[:, None], point, out)
    return out


def _dot(u, v, xp):
    return xp.einsum("fd,fd->f", u, xp.broadcast_to(v, u.shape))


def _ratio(num, den, xp):
    safe = xp.where(den == 0, 1.0, den)
    return (xp.where(den == 0, 0.0, num) / safe)[:, None]
