"""A surface's signed distance sampled on a regular grid, read back by trilinear interpolation.

Closing a hand onto an object asks, at every step of a search and for every one of a
hand's few hundred link samples, how deep the point lies in the object. The exact answer
([`Surface.closest`][jaxgrasp.surface.Surface.closest], a tree search per point) is computed here once per
grid point; a lookup afterwards is eight reads and a blend, traceable and differentiable
almost everywhere. Trilinear interpolation of a distance is exact on planes and off by
at most about ``spacing**2 / (8 R)`` near a curved patch of radius ``R``, more at edges
and corners the grid does not resolve: the grid guides a search; the grasp it finds is
measured on the exact surface afterwards.

Outside the grid's box a point reads the value at the nearest grid point plus its
distance to the box: never less than the truth by more than the interpolation's error
at the box, so a point far from the object reads far.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["DistanceGrid", "distance_grid", "GRID_POINTS_PER_AXIS"]

GRID_POINTS_PER_AXIS = 48
"""Grid points along each axis by default: 110,592 points, 2 mm apart over a 94 mm box."""

_CHUNK = 8192  # points per call of the exact search: a fixed shape, compiled once


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DistanceGrid:
    """The signed distance to a surface (m, negative inside) at the points of a regular grid.

    Attributes:
        origin: ``(3,)`` m, the grid point of index ``(0, 0, 0)`` (mesh frame).
        spacing: ``()`` m, the distance between neighbouring grid points.
        values: ``(nx, ny, nz)`` m, the signed distance at each grid point.
    """

    origin: jax.Array
    spacing: jax.Array
    values: jax.Array

    def __call__(self, points):
        """``(...)`` m: the interpolated signed distance at ``points`` ``(..., 3)`` m
        (module notes for outside the box). Traceable."""
        values = jnp.asarray(self.values)
        shape = jnp.asarray(values.shape)
        u = (jnp.asarray(points) - self.origin) / self.spacing
        inside = jnp.clip(u, 0.0, shape - 1.0)
        beyond = jnp.sum(((u - inside) * self.spacing) ** 2, axis=-1)
        # the distance to the box, with the derivative 0 (not NaN) inside it
        outside = jnp.where(beyond > 0.0, jnp.sqrt(jnp.where(beyond > 0.0, beyond, 1.0)), 0.0)
        i0 = jnp.clip(jnp.floor(inside).astype(jnp.int32), 0, shape - 2)
        t = inside - i0
        total = 0.0
        for corner in range(8):
            bits = np.array([(corner >> k) & 1 for k in range(3)])
            idx = i0 + bits
            weight = jnp.prod(jnp.where(bits == 1, t, 1.0 - t), axis=-1)
            total = total + weight * values[idx[..., 0], idx[..., 1], idx[..., 2]]
        return total + outside


@jax.jit
def _signed_distance(surface, points):
    """``(P,)`` m: the signed distance of ``points`` ``(P, 3)`` m to ``surface``. One jitted
    function for every grid, so that surfaces of one padded shape share its executable
    (a function jitted inside `distance_grid` compiled again for every grid)."""
    return surface.closest(points).signed_distance


def distance_grid(surface, lower, upper, points_per_axis: int = GRID_POINTS_PER_AXIS,
                  progress: Callable[[int, int], object] | None = None) -> DistanceGrid:
    """The [`DistanceGrid`][jaxgrasp.surface.DistanceGrid] of ``surface`` (a
    [`Surface`][jaxgrasp.surface.Surface], mesh frame) over the cube of ``points_per_axis``
    points a side centred on the box ``lower`` ``(3,)`` to ``upper`` ``(3,)`` m and holding it: one
    shape for every object, so that a program reading it compiles once (its spacing is the
    box's longest side over ``points_per_axis - 1``). ``progress(done, total)`` after each
    chunk of points."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    n = int(points_per_axis)
    if not 2 <= n <= 256:
        raise ValueError(f"points_per_axis must be 2 to 256, got {n}")
    spacing = float(np.max(upper - lower)) / (n - 1)
    if not spacing > 0.0:
        raise ValueError(f"the box {lower} to {upper} is empty")
    origin = 0.5 * (lower + upper) - 0.5 * spacing * (n - 1)
    axes = [origin[k] + spacing * np.arange(n) for k in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    out = np.empty(len(points))
    for start in range(0, len(points), _CHUNK):
        part = points[start:start + _CHUNK]
        padded = np.concatenate([part, np.repeat(part[-1:], _CHUNK - len(part), 0)]) if len(part) < _CHUNK else part
        out[start:start + len(part)] = np.asarray(_signed_distance(surface, jnp.asarray(padded)))[: len(part)]
        if progress is not None:
            progress(start + len(part), len(points))
    return DistanceGrid(jnp.asarray(origin), jnp.asarray(spacing), jnp.asarray(out.reshape(n, n, n)))
