"""Property-based tests (hypothesis) of physical invariances of the evaluation value.

Random, physically sensible grasps (2 to 5 fingertips pressed onto a sphere or a box
around the centre of mass, outward normals, random fingertips, masses and gravity
directions; see :func:`build_grasp`) are checked for:

* rotating the whole grasp together with gravity leaves the value unchanged;
* a mirror image (positions, normals and gravity reflected through a plane) has the
  same value;
* renumbering the contacts leaves the value unchanged and permutes ``boundary_energy``;
* with zero mass, scaling ``young_modulus`` and ``max_force`` by one factor scales the
  value (and every energy) by that factor;
* the value is finite and ``>= 0``, the status is stable, unstable or infeasible, never
  ``not_converged``.

For speed, each example's original and transformed grasps go through ONE batched call
of the session's ``evaluate_many`` (one compiled ``jit(vmap(evaluate))`` per contact
count, shared with the other test modules). Environment:

* ``JAXGRASP_PROPERTY_PROFILE``: ``ci`` (default, :data:`PROFILES`) or ``long`` (200
  examples per property, for a run before a release: 4-5 minutes on 2 shared cores, see
  ``experiments/robustness/property_long.sh`` and its logs ``experiments/robustness/property_long*.log``);
* ``JAXGRASP_PROPERTY_EXAMPLES``: examples per property, overriding the profile;
* ``JAXGRASP_PROPERTY_RANDOM=1``: new random examples each run (default: derandomized,
  the same examples every run);
* ``JAXGRASP_PROPERTY_SHRINK=1``: let hypothesis shrink a failure (off by default: every
  shrink step is an evaluation, and a failure message prints the grasp literally anyway).

``experiments/robustness/robustness.py`` reuses :func:`build_grasp` on 1000 seeded grasps;
:func:`test_seeded_grasps_converge` is its 16-grasp version.

The value is a minimum over a multi-start search. The start directions live in the
grasp's own frame (:func:`jaxgrasp.tolerance._starts.start_frame`), so a rotated, mirrored or
renumbered grasp is searched from the same physical starts and reaches the same local
minima, up to rounding (the frame's ties and open signs are settled by the world's
coordinate axes, e.g. in symmetric grasps). A transformed grasp landing on a different (lower or
higher) local minimum would be a real finding about the start heuristic, not noise: the
tolerances are tight (relative ``1e-6`` on values and on every boundary energy) and are
not to be loosened to hide one. One exception is the first wave's, stated in
:func:`assert_same`: a boundary far above the value may be reachable on one side only
(its first six starts all infeasible on the other), which a rotation turned up in CI.
"""

from __future__ import annotations

import math
import os

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

import jaxgrasp
from jaxgrasp.tolerance._stages import VALUE_MARGIN

from grasp_draws import HypothesisDraw, grasps, literal, permute, random_rotation, random_unit, reflection, scaled, seeded_grasps, transform

REL = 1e-6
"""Relative tolerance on values (and boundary energies above the equilibrium)."""

PROFILES = {"ci": 30, "long": 200}
"""Examples per property of each ``$JAXGRASP_PROPERTY_PROFILE``."""
PROFILE = os.environ.get("JAXGRASP_PROPERTY_PROFILE", "ci")
if PROFILE not in PROFILES:
    raise ValueError(f"JAXGRASP_PROPERTY_PROFILE={PROFILE!r}: expected one of {sorted(PROFILES)}")
EXAMPLES = int(os.environ.get("JAXGRASP_PROPERTY_EXAMPLES", PROFILES[PROFILE]))




# ----------------------------------------------------------------------------- transforms


# ----------------------------------------------------------------------------- checks
def describe(res) -> str:
    return (
        f"status={jaxgrasp.GraspStatus.labels()[int(res.status)]} value={float(res.value)!r} "
        f"limiting=({int(res.limiting_kind)},{int(res.limiting_contact)}) "
        f"U0={float(res.equilibrium_energy)!r} boundary_energy={np.asarray(res.boundary_energy).tolist()} "
        f"boundary_status={np.asarray(res.boundary_status).tolist()}"
    )


def check_sane(res, g) -> None:
    """A finite value >= 0 and a converged status (stable, unstable or infeasible, never
    ``not_converged``: ``experiments/robustness/robustness.py`` finds none in 1000 such grasps)."""
    v = float(res.value)
    assert math.isfinite(v) and v >= 0.0, describe(res) + "\n" + literal(g)
    assert int(res.status) in (jaxgrasp.GraspStatus.STABLE, jaxgrasp.GraspStatus.UNSTABLE, jaxgrasp.GraspStatus.INFEASIBLE), (
        f"{res.explain()}\n{describe(res)}\n{literal(g)}"
    )
    if int(res.status) in (jaxgrasp.GraspStatus.UNSTABLE, jaxgrasp.GraspStatus.INFEASIBLE):
        assert v == 0.0, describe(res)


def _rounding(res, factor=1.0) -> float:
    """Absolute rounding scale of an energy difference: 1e-9 of the equilibrium energy.

    Values and boundary energies above the equilibrium are differences of two energies,
    each computed to ~1e-12 relative; a difference far below the energies themselves (an
    unstable grasp's boundary at the equilibrium, a tiny value) is only known to that."""
    u0 = float(res.equilibrium_energy)
    return 1e-9 * abs(factor * u0) if math.isfinite(u0) else 0.0


def assert_same(a, b, ga, gb, what: str, perm=None, factor: float = 1.0) -> None:
    """``b`` is the evaluation of a transformed grasp: same status, value (times
    ``factor``), equilibrium energy and, column-permuted by ``perm``, boundary energies,
    to relative ``REL`` (plus the rounding of an energy difference, :func:`_rounding`)."""
    msg = f"{what}\n original:    {describe(a)}\n transformed: {describe(b)}\n {literal(ga)}"
    assert int(a.status) == int(b.status), msg
    va, vb = float(a.value), float(b.value)
    tiny = _rounding(a, factor)
    assert vb == pytest.approx(factor * va, rel=REL, abs=tiny), msg
    if int(a.status) == jaxgrasp.GraspStatus.INFEASIBLE:
        return  # no equilibrium: the statuses must agree, no more
    u0a, u0b = factor * float(a.equilibrium_energy), float(b.equilibrium_energy)
    assert u0b == pytest.approx(u0a, rel=1e-8, abs=1e-12), msg
    be_a = factor * np.asarray(a.boundary_energy, dtype=float)
    be_b = np.asarray(b.boundary_energy, dtype=float)
    if perm is not None:
        be_a = be_a[:, np.asarray(perm)]
    # every boundary: same reachability, same minimum energy above the equilibrium; but a
    # boundary that cannot set the value (more than VALUE_MARGIN times it above U0) may be
    # reachable on one side only: its first six starts settle it (the first wave), and
    # where all six are infeasible it is unreachable, though one of the others might
    # reach it (4 of 2887 such problems on the benchmark's set; whether a chaotic start
    # of the six converges can turn with rounding). Rotated, one such problem ran all 20.
    fa, fb = np.isfinite(be_a), np.isfinite(be_b)
    one_side = fa != fb
    far = np.where(fa, be_a - u0a, be_b - u0b) > VALUE_MARGIN * factor * va + tiny
    assert np.all(far[one_side]), msg
    both = fa & fb
    da, db = be_a[both] - u0a, be_b[both] - u0b
    np.testing.assert_allclose(db, da, rtol=REL, atol=REL * factor * va + tiny, err_msg=msg)
    # the limiting boundary maps to the transformed one, unless another one ties with it
    if int(a.status) == jaxgrasp.GraspStatus.STABLE:
        gaps = np.sort(be_a[fa] - u0a)
        if gaps.size == 1 or gaps[1] - gaps[0] > 10 * (REL * factor * va + tiny):
            ka, ja = int(a.limiting_kind), int(a.limiting_contact)
            jb = ja if perm is None else int(np.flatnonzero(np.asarray(perm) == ja)[0])
            assert (int(b.limiting_kind), int(b.limiting_contact)) == (ka, jb), msg


# Derandomized (the same examples every run) unless $JAXGRASP_PROPERTY_RANDOM is set; no
# shrinking unless $JAXGRASP_PROPERTY_SHRINK is set: every step of a shrink is a batched
# evaluation, so shrinking a failure takes many minutes (the failure message already
# prints the grasp as a literal ``Grasp.create(...)``).
_PHASES = [Phase.explicit, Phase.reuse, Phase.generate, Phase.target]
if os.environ.get("JAXGRASP_PROPERTY_SHRINK"):
    _PHASES.append(Phase.shrink)
_PROP_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large],
    derandomize=not os.environ.get("JAXGRASP_PROPERTY_RANDOM"),
    database=None,
    phases=_PHASES,
    print_blob=False,
)


# ----------------------------------------------------------------------------- seeded set
SEEDED_COUNT = 16
"""Small version of ``experiments/robustness/robustness.py`` (4 grasps per contact count, seed 0)."""


def test_seeded_grasps_converge(evaluate_many):
    """Every grasp of a small seeded set: converged, finite value >= 0, stable => value > 0."""
    gs = seeded_grasps(SEEDED_COUNT, seed=0)
    res = evaluate_many(gs)
    problems = []
    for i, (g, r) in enumerate(zip(gs, res)):
        v = float(r.value)
        if int(r.status) == jaxgrasp.GraspStatus.NOT_CONVERGED or not (math.isfinite(v) and v >= 0.0) or (
            int(r.status) == jaxgrasp.GraspStatus.STABLE and not v > 0.0
        ):
            problems.append(f"grasp {i}: {r.explain()} [{describe(r)}]\n  {literal(g)}")
    statuses = sorted({jaxgrasp.GraspStatus.labels()[int(r.status)] for r in res})
    assert not problems, "\n".join(problems)
    assert "stable" in statuses and len(statuses) >= 2  # the set is varied


# ----------------------------------------------------------------------------- properties
@_PROP_SETTINGS
@given(grasps(), st.data())
def test_rotation_reflection_renumbering(evaluate_many, g, data):
    """One batched call per example: original, rotated, mirrored, renumbered."""
    d = HypothesisDraw(data.draw)
    n = g.num_contacts
    Q = random_rotation(d)
    H = reflection(random_unit(d))
    perm = data.draw(st.permutations(list(range(n))))
    rot, mir, ren = transform(g, Q), transform(g, H), permute(g, perm)
    a, b, c, e = evaluate_many([g, rot, mir, ren])
    event(f"N={n} {jaxgrasp.GraspStatus.labels()[int(a.status)]}")  # --hypothesis-show-statistics
    for res, gg in ((a, g), (b, rot), (c, mir), (e, ren)):
        check_sane(res, gg)
    assert_same(a, b, g, rot, f"rotation Q={Q.tolist()}")
    assert_same(a, c, g, mir, f"reflection H={H.tolist()}")
    assert_same(a, e, g, ren, f"renumbering perm={list(perm)}", perm=perm)


@_PROP_SETTINGS
@given(grasps(), st.floats(0.05, 20.0))
def test_zero_mass_scaling(evaluate_many, g, s):
    """m = 0: U is linear in E and the region is unchanged when E and f_max scale by s."""
    g0 = g.replace(mass=jnp.zeros((), jnp.float64))  # not weakly typed: no recompilation
    gs = scaled(g0, s)
    a, b = evaluate_many([g0, gs])
    event(f"N={g.num_contacts} {jaxgrasp.GraspStatus.labels()[int(a.status)]}")
    check_sane(a, g0)
    check_sane(b, gs)
    assert_same(a, b, g0, gs, f"scaling E, f_max by {s!r}", factor=s)
