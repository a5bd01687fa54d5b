"""Random, physically sensible grasps for tests and experiments: seeded NumPy draws and
hypothesis strategies, and the transforms (rotation, mirror, renumbering, scaling) the
invariance tests apply to them.

A grasp has 2 to 5 fingertips pressed onto a sphere or a box around the centre of mass,
outward normals, random fingertips, masses and gravity directions (:func:`build_grasp`).
``tests/tolerance/test_properties.py`` checks the value's invariances on them;
``experiments/robustness/robustness.py`` evaluates 1000 seeded ones.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

import jaxgrasp

PER_CONTACT = ("positions", "normals", "initial_deformation", "radius", "young_modulus", "friction", "max_force")


G = 9.81


class NumpyDraw:
    """The draw interface of :func:`build_grasp` on a NumPy generator (seeded sets)."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def uniform(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def integer(self, lo: int, hi: int) -> int:  # inclusive
        return int(self.rng.integers(lo, hi + 1))

    def boolean(self, p: float = 0.5) -> bool:
        return bool(self.rng.random() < p)


class HypothesisDraw:
    """The draw interface of :func:`build_grasp` inside ``st.composite`` (shrinkable)."""

    def __init__(self, draw):
        self.draw = draw

    def uniform(self, lo: float, hi: float) -> float:
        return self.draw(st.floats(lo, hi, allow_nan=False, allow_infinity=False))

    def integer(self, lo: int, hi: int) -> int:
        return self.draw(st.integers(lo, hi))

    def boolean(self, p: float = 0.5) -> bool:
        return self.draw(st.booleans())


def random_rotation(d) -> np.ndarray:
    """A rotation matrix from three uniforms (Shoemake's uniform quaternion)."""
    u1, u2, u3 = d.uniform(0.0, 1.0), d.uniform(0.0, 1.0), d.uniform(0.0, 1.0)
    a, b = math.sqrt(1.0 - u1), math.sqrt(u1)
    q = np.array(
        [a * math.sin(2 * math.pi * u2), a * math.cos(2 * math.pi * u2), b * math.sin(2 * math.pi * u3), b * math.cos(2 * math.pi * u3)]
    )
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_unit(d) -> np.ndarray:
    z = d.uniform(-1.0, 1.0)
    a = d.uniform(0.0, 2.0 * math.pi)
    s = math.sqrt(max(0.0, 1.0 - z * z))
    return np.array([s * math.cos(a), s * math.sin(a), z])


def build_grasp_fields(d, n: int | None = None) -> dict:
    """Fields of a random, physically sensible grasp (SI units), drawn with ``d``.

    The object is a sphere (radius 2-8 cm) or an axis-aligned box (half sides 2-8 cm)
    around the centre of mass. The ``n`` fingertips (2 to 5) sit around a great circle
    of a random frame (evenly spread azimuths, jitter up to +-0.3 pi/n, elevations up to +-0.3 rad),
    on the surface, normals outward (on the sphere tilted by up to 0.25 rad, as on a
    non-spherical convex surface). Fingertips: radius 15-30 mm, initial deformation
    0.8-3 mm, Young's modulus 1e5-1e6 Pa (log-uniform), friction 0.3-1.0, force limit
    0.9-3 times the largest initial normal force (so some grasps start above a limit);
    shared by all contacts or per contact.
    Mass: 0 (half of the time) or up to half of what friction could carry with the
    initial squeeze; gravity 9.81 m/s^2 in a random direction.

    Roughly half of these grasps are stable; the rest are mostly unstable (box contacts on
    adjacent faces, heavy objects) and a few infeasible, which is fine for the properties.
    """
    n = d.integer(2, 5) if n is None else n
    frame = random_rotation(d)
    sphere = d.boolean()
    if sphere:
        radius_obj = d.uniform(0.02, 0.08)
    else:
        half = np.array([d.uniform(0.02, 0.08) for _ in range(3)])
    pos, nrm = [], []
    for k in range(n):
        az = 2.0 * math.pi * k / n + d.uniform(-0.3, 0.3) * math.pi / n
        el = d.uniform(-0.3, 0.3)
        u = frame @ np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        if sphere:
            p = radius_obj * u
            tilt = d.uniform(0.0, 0.25)
            t = random_unit(d)
            t = t - np.dot(t, u) * u
            tn = np.linalg.norm(t)
            nv = u + (math.tan(tilt) * t / tn if tn > 1e-9 else 0.0)
            nv = nv / np.linalg.norm(nv)
        else:
            ratios = np.abs(u) / half
            j = int(np.argmax(ratios))
            p = u / ratios[j]
            nv = np.zeros(3)
            nv[j] = math.copysign(1.0, u[j])
        pos.append(p)
        nrm.append(nv)
    per = d.boolean()

    def tip(lo, hi, log=False):
        def one():
            if log:
                return 10.0 ** d.uniform(math.log10(lo), math.log10(hi))
            return d.uniform(lo, hi)

        return np.array([one() for _ in range(n)]) if per else np.full(n, one())

    r = tip(0.015, 0.03)
    dr = tip(0.0008, 0.003)
    dr = np.minimum(dr, 0.5 * r)
    E = tip(1e5, 1e6, log=True)
    mu = tip(0.3, 1.0)
    f0 = math.pi * E * dr**2  # initial normal force, N
    fmax = float(np.max(f0)) * tip(0.9, 3.0)
    if d.boolean():  # shrinks to the zero-mass case
        mass = 0.0
    else:
        mass = d.uniform(0.0, 0.5) * float(np.sum(mu * f0)) / G
    gravity = G * random_unit(d)
    return dict(
        positions=np.array(pos),
        normals=np.array(nrm),
        initial_deformation=dr,
        radius=r,
        young_modulus=E,
        friction=mu,
        max_force=fmax,
        mass=mass,
        gravity=gravity,
    )


def build_grasp(d, n: int | None = None) -> jaxgrasp.Grasp:
    return jaxgrasp.Grasp.create(**build_grasp_fields(d, n))


def seeded_grasps(count: int, seed: int = 0) -> list[jaxgrasp.Grasp]:
    """``count`` grasps from :func:`build_grasp`, contact counts cycling 2, 3, 4, 5."""
    rng = np.random.default_rng(seed)
    return [build_grasp(NumpyDraw(rng), n=2 + i % 4) for i in range(count)]


@st.composite
def grasps(draw, n=None):
    return build_grasp(HypothesisDraw(draw), n)


def literal(g: jaxgrasp.Grasp) -> str:
    """Python source of ``jaxgrasp.Grasp.create(...)`` for a grasp (for reports, repro)."""
    f = g.to_numpy()
    args = ", ".join(f"{k}={np.asarray(v).tolist()!r}" for k, v in f.items())
    return f"jaxgrasp.Grasp.create({args})"


def transform(g: jaxgrasp.Grasp, Q: np.ndarray) -> jaxgrasp.Grasp:
    """Apply an orthogonal map ``Q`` to positions, normals and gravity."""
    f = g.to_numpy()
    return g.replace(
        positions=jnp.asarray(f["positions"] @ Q.T),
        normals=jnp.asarray(f["normals"] @ Q.T),
        gravity=jnp.asarray(f["gravity"] @ Q.T),
    )


def permute(g: jaxgrasp.Grasp, perm) -> jaxgrasp.Grasp:
    perm = np.asarray(perm)
    return g.replace(**{k: jnp.asarray(np.asarray(getattr(g, k))[perm]) for k in PER_CONTACT})


def scaled(g: jaxgrasp.Grasp, s: float) -> jaxgrasp.Grasp:
    return g.replace(young_modulus=g.young_modulus * s, max_force=g.max_force * s)


def reflection(m: np.ndarray) -> np.ndarray:
    m = m / np.linalg.norm(m)
    return np.eye(3) - 2.0 * np.outer(m, m)
