"""Planning with a hand: the configurations of a robot hand that tolerate the most energy on an object.

[`jaxgrasp.plan`][jaxgrasp.plan] with ``hand=`` runs six stages, each a function here:

1. **set up** the object (`_object`): its mesh in metres, centre of mass and mass, its
   padded [`Surface`][jaxgrasp.surface.Surface] and a [`DistanceGrid`][jaxgrasp.surface.DistanceGrid] of it
   (`jaxgrasp.surface._grid`) for the closing search;
2. **close** ``samples`` candidates onto it (`jaxgrasp.planning._hand_close`: wrist poses
   around the object, pre-shapes, joints and wrist moved together by a differentiable
   search through the kinematics and the surface's signed distance), in chunks of
   `CLOSE_CHUNK` (one compiled program whatever the count);
3. **evaluate** them all ([`jaxgrasp.hands.hand_batch`][jaxgrasp.hands.hand_batch] on the exact surface, then the
   engine's runner) and measure how deep the hand's other links lie in the object;
4. **keep** the eligible ones: at least ``min_fingertips`` fingertips in contact, links at
   most ``max_penetration`` inside the object and inside each other (the pairs MuJoCo
   would collide, [`Hand.self_overlap`][jaxgrasp.Hand.self_overlap]), a settled evaluation;
5. **refine** the best ``refine`` by the objective: the value by its exact gradient over
   joints and wrist ([`tune_hand`][jaxgrasp.tune_hand], within the joint limits and couplings, links
   kept out), or epsilon (which has no gradient here) by a local random search of as
   many evaluations as tuning is allowed iterations;
6. **rank** by the objective and give the ``top``, each rebuilt as its hand grasp file
   loads and evaluated again by [`jaxgrasp.evaluate`][jaxgrasp.evaluate], with its epsilon.
"""

from __future__ import annotations

import dataclasses
import os
import time
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.analysis import MAX_ROBUST_SAMPLES, MAX_TUNE_ITERATIONS, ROBUST_SAMPLES_WHAT, TUNE_ITERATIONS_WHAT, epsilon
from jaxgrasp.base import over_limit
from jaxgrasp.engine import evaluate, evaluate_dataset
from jaxgrasp.io import load_mesh
from jaxgrasp.model import DEFAULT_GRAVITY, GraspValueError
from jaxgrasp.planning._hand_close import CloseSettings, close_hands, hand_starts, unpack
from jaxgrasp.planning._hand_result import HandPlanResult
from jaxgrasp.planning._progress import stage as _stage
from jaxgrasp.planning._limits import MAX_PLAN_REFINE, MAX_PLAN_SAMPLES, PLAN_REFINE_WHAT, PLAN_SAMPLES_WHAT
from jaxgrasp.planning._result import PlanStatus
from jaxgrasp.surface import PAD_FACES, Surface, distance_grid, mass_properties
from jaxgrasp.tolerance import GraspStatus

__all__ = ["plan_hand", "check_caps", "check_hand_plan", "HandPlanInputs", "OBJECTIVES", "CLOSE_CHUNK", "HAND_SAMPLES"]

OBJECTIVES = ("value", "epsilon")
"""What a hand plan maximises: the paper's value (energy tolerance, J) or the Ferrari-Canny epsilon."""

CLOSE_CHUNK = 64
"""Candidates per call of the compiled closing search."""

_GRID_MARGIN = 0.015  # m around the object's box: the fingertips and links that matter are this close
_BAND = (0.25, 0.5, 0.4)  # dr* drawn in [0.25, 0.5] dr_max, its band 0.4 dr_max wide: eq. 4 under f_max
_EPSILON_STEP = (0.02, 0.002, 0.02)  # the epsilon search's steps: joint range fraction, wrist m, wrist rad

PREFERRED_FINGERTIPS = 3
HAND_SAMPLES = 128  # closed candidates by default: several close stable on most objects (experiments/hand_planning)
"""Fingertips in contact a plan prefers: of its eligible grasps, those with at least this many
(or all the hand's, if it has fewer) rank first, stable ones before them by the value."""


@dataclasses.dataclass(frozen=True)
class HandPlanInputs:
    """A hand plan's checked inputs (internal): the hand, the object and the fields.

    Attributes:
        hand: the [`Hand`][jaxgrasp.Hand]. mesh: ``trimesh.Trimesh``, m. source: the mesh's
        file name (or ``"<trimesh>"``). units: the mesh file's. com: ``(3,)`` m, mesh frame.
        mass: kg. gravity: ``(3,)`` m/s^2, mesh frame. fields: young_modulus (Pa),
        friction, max_force (N), numbers.
    """

    hand: object
    mesh: object
    source: str
    units: str
    com: np.ndarray
    mass: float
    gravity: np.ndarray
    fields: dict

    def grasp_kwargs(self) -> dict:
        """The keyword arguments of [`Hand.grasp`][jaxgrasp.Hand.grasp] and [`tune_hand`][jaxgrasp.tune_hand]
        for this object (the mesh in metres, its mass and centre of mass given)."""
        return dict(mass=self.mass, gravity=self.gravity, center_of_mass=self.com, **self.fields)


def _number(name: str, v, zero_ok: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v) or (
            v < 0 if zero_ok else v <= 0):
        raise GraspValueError(f"plan: {name} = {v!r} must be a finite number {'>=' if zero_ok else '>'} 0 (SI units)")
    return float(v)


def _hand_of(hand, fingertips):
    """The [`Hand`][jaxgrasp.Hand] given, or read from its file with ``fingertips``."""
    from jaxgrasp.hands import Hand

    if isinstance(hand, Hand):
        if fingertips is not None and tuple(fingertips) != hand.fingertip_names:
            raise GraspValueError("plan: fingertips= names other fingertips than the Hand given has; give one of them")
        return hand
    if not isinstance(hand, (str, os.PathLike)):
        raise GraspValueError(f"plan: hand must be a jaxgrasp.Hand or an MJCF/URDF file, got {type(hand).__name__}")
    if not fingertips:
        raise GraspValueError("plan: a hand file needs fingertips= (its fingertip geoms, bodies or links)")
    return Hand.from_file(hand, list(fingertips))


def check_caps(samples, top, refine, tune_maxiter, robust_samples=None) -> None:
    """Every count of a plan at most its cap (`jaxgrasp.planning._limits`; ``robust_samples``
    where given), before the mesh is read: a one-line `GraspValueError` naming the first over it."""
    counts = [("samples", samples, MAX_PLAN_SAMPLES, PLAN_SAMPLES_WHAT), ("top", top, MAX_PLAN_SAMPLES, PLAN_SAMPLES_WHAT),
              ("refine", refine, MAX_PLAN_REFINE, PLAN_REFINE_WHAT),
              ("tune_maxiter", tune_maxiter, MAX_TUNE_ITERATIONS, TUNE_ITERATIONS_WHAT)]
    if robust_samples is not None:
        counts.append(("robust_samples", robust_samples, MAX_ROBUST_SAMPLES, ROBUST_SAMPLES_WHAT))
    for name, v, cap, what in counts:
        problem = over_limit(f"plan: {name}", v, cap, what)
        if problem:
            raise GraspValueError(problem)


def check_hand_plan(mesh, hand, fingertips=None, *, young_modulus, friction, max_force, mass=None, density=None,
                    center_of_mass=None, gravity=DEFAULT_GRAVITY, units: str = "m", samples: int = HAND_SAMPLES, top: int = 10,
                    refine: int = 3, seed: int = 0, min_fingertips: int = 2, objective: str = "value",
                    tune_maxiter: int = 30, max_penetration: float = 1e-3) -> HandPlanInputs:
    """Check a hand plan's arguments, read the hand and the mesh, computing nothing else
    (``jaxgrasp plan --hand`` calls it before it creates ``--out``). Arguments: as
    `plan_hand`. Raises `GraspValueError` (one line) for anything out of range."""
    for name, v, lo in (("samples", samples, 1), ("top", top, 1), ("refine", refine, 0), ("seed", seed, 0),
                        ("min_fingertips", min_fingertips, 2), ("tune_maxiter", tune_maxiter, 1)):
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
            raise GraspValueError(f"plan: {name} must be an integer >= {lo}, got {v!r}")
    check_caps(samples, top, refine, tune_maxiter)
    if objective not in OBJECTIVES:
        raise GraspValueError(f"plan: objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    _number("max_penetration", max_penetration, zero_ok=True)
    fields = {k: _number(k, v) for k, v in (("young_modulus", young_modulus), ("friction", friction),
                                            ("max_force", max_force))}
    h = _hand_of(hand, fingertips)
    if min_fingertips > h.num_fingertips:
        raise GraspValueError(f"plan: min_fingertips = {min_fingertips} is more than the hand's {h.num_fingertips} fingertips")
    return _object(mesh, units, mass, density, center_of_mass, gravity, h, fields)


def _object(mesh, units, mass, density, center_of_mass, gravity, hand, fields) -> HandPlanInputs:
    """The checked object (stage 1 without its surface)."""
    m = load_mesh(mesh, units, how='pass --units {} (Python: units="{}")')
    if center_of_mass is None and not m.is_watertight:
        raise GraspValueError("plan: the mesh is not watertight (not a closed surface), so it has no centre of mass "
                              "of its own: plan needs a closed mesh (jaxgrasp.plan also takes center_of_mass= and mass=)")
    for name, v in (("mass", mass), ("density", density)):
        if v is not None:
            _number(name, v, zero_ok=True)
    com, kg = mass_properties(m, mass, density, center_of_mass)
    g = np.asarray(gravity, dtype=np.float64)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise GraspValueError(f"plan: gravity must be 3 finite numbers, m/s^2; got {gravity!r}")
    source = os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else "<trimesh>"
    return HandPlanInputs(hand, m, source, units, np.asarray(com, np.float64), float(kg), g, fields)


def _surfaces(inputs: HandPlanInputs, progress) -> tuple:
    """``(surface, grid)``: the padded exact surface and its distance grid over the
    object's box and `_GRID_MARGIN` (stage 1)."""
    surface = Surface.from_trimesh(inputs.mesh, pad_to=PAD_FACES)
    lo, hi = inputs.mesh.bounds
    grid = distance_grid(surface, lo - _GRID_MARGIN, hi + _GRID_MARGIN, progress=_stage(progress, "grid"))
    return surface, grid


def _targets(inputs: HandPlanInputs, count: int, rng) -> tuple[np.ndarray, float]:
    """``(dr* (count, F) m, band m)``: each candidate's target deformation (one for all its
    fingertips) and the band's width, from ``dr_max``, the least of each fingertip's
    eq. 4 deformation at its force limit and half its radius."""
    hand, f = inputs.hand, inputs.fields
    dr_max = float(min(np.sqrt(f["max_force"] / (np.pi * f["young_modulus"])), 0.5 * np.min(hand.radius)))
    low = rng.uniform(_BAND[0] * dr_max, _BAND[1] * dr_max, size=(count, 1))
    return np.broadcast_to(low, (count, hand.num_fingertips)).copy(), _BAND[2] * dr_max


def _close(inputs: HandPlanInputs, surface, grid, samples: int, rng, settings: CloseSettings, progress):
    """``(qpos (S, J), wrist (S, 6))``: the ``samples`` candidates closed (stage 2)."""
    hand = inputs.hand
    x0 = hand_starts(hand, inputs.com, samples, rng)
    target, band = _targets(inputs, samples, rng)
    settings = dataclasses.replace(settings, band=band)
    data = dict(surface=surface, grid=grid, center_of_mass=jnp.asarray(inputs.com),
                young_modulus=jnp.full(hand.num_fingertips, inputs.fields["young_modulus"]),
                size=jnp.asarray(0.5 * float(np.linalg.norm(inputs.mesh.extents))))
    out = np.empty_like(x0)
    for start in range(0, samples, CLOSE_CHUNK):
        rows = np.arange(start, min(start + CLOSE_CHUNK, samples))
        pad = np.concatenate([rows, np.full(CLOSE_CHUNK - len(rows), rows[-1])])
        x, _ = close_hands(hand, settings, x0[pad], target[pad], data)
        out[rows] = np.asarray(x)[: len(rows)]
        if progress is not None:
            progress("close", int(rows[-1]) + 1, samples)
    q, w = _unpack_function(hand)(jnp.asarray(out))
    return np.asarray(q), np.asarray(w)


@lru_cache(maxsize=8)
def _unpack_function(hand):
    """``fn(x (S, J + 6)) -> (qpos (S, J), wrist (S, 6))``, compiled once per hand."""
    return jax.jit(jax.vmap(lambda x: unpack(hand, x)))


def _in_chunks(fn, *arrays) -> np.ndarray:
    """``fn`` of ``arrays`` (each ``(S, ...)``) in chunks of `CLOSE_CHUNK` rows, the last padded by
    repeating its last row: one shape whatever ``S``, so one compilation."""
    n = len(arrays[0])
    out = []
    for i in range(0, n, CLOSE_CHUNK):
        rows = np.minimum(np.arange(i, i + CLOSE_CHUNK), n - 1)
        out.append(np.asarray(fn(*(a[rows] for a in arrays)))[: min(CLOSE_CHUNK, n - i)])
    return np.concatenate(out + [np.zeros(0)])


@lru_cache(maxsize=8)
def _depth_function(hand):
    """``fn(surface, q (S, J), w (S, 6)) -> (S,)``, compiled once per hand (the surface an argument)."""
    return jax.jit(jax.vmap(lambda s, a, b: jnp.max(hand.link_depths(a, b, jnp.zeros(6), s)), in_axes=(None, 0, 0)))


@lru_cache(maxsize=8)
def _overlap_function(hand):
    """``fn(q (S, J)) -> (S,)``, the deepest self-overlap of each, compiled once per hand."""
    return jax.jit(jax.vmap(lambda a: jnp.max(hand.self_overlap(a))))


def _overlaps(hand, q) -> np.ndarray:
    """``(S,)`` m, the deepest overlap of two of the hand's own links in each configuration."""
    return _in_chunks(_overlap_function(hand), np.asarray(q))


def _depths(hand, surface, q, w) -> np.ndarray:
    """``(S,)`` m, the deepest link sample of each configuration on the exact surface."""
    fn = _depth_function(hand)
    return _in_chunks(lambda a, b: fn(surface, a, b), np.asarray(q), np.asarray(w))


def _measure(inputs: HandPlanInputs, surface, q, w, progress) -> dict:
    """Stage 3: ``value`` (S,) J, ``status`` (S,) (-1: fewer than two fingertips in contact,
    not evaluated), ``active`` (S,) fingertips in contact, ``depth`` (S,) m, ``self`` (S,) m
    (the deepest self-overlap)."""
    from jaxgrasp.hands import hand_batch

    hb = hand_batch(inputs.hand, inputs.mesh, q, wrist=w, **inputs.grasp_kwargs())
    active = np.asarray(hb.active).sum(axis=1)
    value, status = np.zeros(len(q)), np.full(len(q), -1)
    if np.any(active >= 2):
        res, _ = evaluate_dataset(hb.grasps, progress=_stage(progress, "evaluate"))
        ok = active >= 2
        value[ok], status[ok] = np.asarray(res.value)[ok], np.asarray(res.status)[ok]
    return dict(value=value, status=status, active=active, depth=_depths(inputs.hand, surface, q, w),
                self=_overlaps(inputs.hand, q))


def _eligible(m: dict, min_fingertips: int, max_penetration: float) -> np.ndarray:
    """Stage 4: the candidates a plan may rank (module notes)."""
    settled = (m["status"] >= 0) & (m["status"] != GraspStatus.NOT_CONVERGED)
    clear = (m["depth"] <= max_penetration) & (m["self"] <= max_penetration)
    return settled & (m["active"] >= min_fingertips) & clear


def _contact_grasps(inputs: HandPlanInputs, surface, q, w):
    """The batched [`Grasp`][jaxgrasp.Grasp] ``(S, F, ...)`` of configurations ``q`` ``(S, J)``,
    ``w`` ``(S, 6)`` on the exact ``surface`` (`jaxgrasp.hands.contact_grasp`), its
    ``active`` the fingertips in contact."""
    from jaxgrasp.hands import material

    hand, f = inputs.hand, inputs.fields
    mat = material(hand.num_fingertips, inputs.mesh, f["young_modulus"], f["friction"], f["max_force"], inputs.mass,
                   None, inputs.gravity, inputs.com)
    return _contact_function(hand)(surface, mat, jnp.asarray(q), jnp.asarray(w))


@lru_cache(maxsize=8)
def _contact_function(hand):
    """``fn(surface, material, q (S, J), w (S, 6))`` -> the batched grasp, compiled once per hand:
    the epsilon search calls it at every step."""
    from jaxgrasp.hands import contact_grasp

    one = lambda s, m, a, b: contact_grasp(hand, a, b, jnp.zeros(6), s, m)[0]  # noqa: E731
    return jax.jit(jax.vmap(one, in_axes=(None, None, 0, 0)))


def _epsilons(inputs: HandPlanInputs, surface, q, w) -> np.ndarray:
    """``(S,)`` the Ferrari-Canny epsilon of each configuration's grasp (0 with fewer than
    two fingertips in contact)."""
    grasps = _contact_grasps(inputs, surface, q, w)
    active = np.asarray(grasps.active).sum(axis=1)
    out = np.zeros(len(q))
    for i in np.flatnonzero(active >= 2):
        out[i] = _epsilon(jax.tree_util.tree_map(lambda a: a[i], grasps))
    return out


def _epsilon(grasp) -> float:
    """The Ferrari-Canny epsilon of ``grasp``; 0 for one the model refuses (two fingertips
    touching the surface at the same point: near a mesh corner, several fingertip centres
    have that corner as their closest point)."""
    try:
        return float(epsilon(grasp).value)
    except GraspValueError:
        return 0.0


def _evaluated(grasp):
    """[`jaxgrasp.evaluate`][jaxgrasp.evaluate] of ``grasp``, or ``None`` for one the model refuses
    (as `_epsilon`): such a configuration is never ranked."""
    try:
        return evaluate(grasp)
    except GraspValueError:
        return None


def _grasp(inputs: HandPlanInputs, q, w):
    """The [`HandGrasp`][jaxgrasp.hands.HandGrasp] of one configuration, as its hand grasp file loads."""
    return inputs.hand.grasp(np.asarray(q), inputs.mesh, wrist=np.asarray(w), **inputs.grasp_kwargs())


def _refine_value(inputs: HandPlanInputs, q, w, maxiter: int, max_penetration: float, fewest: int):
    """``(qpos, wrist)`` tuned by [`tune_hand`][jaxgrasp.tune_hand] over joints and wrist, every
    accepted iterate with at least ``fewest`` fingertips in contact, or ``None`` where the
    start cannot be tuned (not stable, links too deep)."""
    from jaxgrasp.hands import tune_hand

    try:
        res = tune_hand(inputs.hand, inputs.mesh, q, w, tune_wrist=True, maxiter=maxiter,
                        max_penetration=max_penetration, min_fingertips=fewest, **inputs.grasp_kwargs())
    except GraspValueError:
        return None
    return np.asarray(res.qpos), np.asarray(res.wrist)


def _refine_epsilon(inputs: HandPlanInputs, surface, q, w, maxiter: int, rng, rules: tuple):
    """``(qpos, wrist)`` after ``maxiter`` rounds of a local random search on epsilon: each
    round perturbs the best so far (joints by `_EPSILON_STEP` of their ranges, projected
    onto the couplings; the wrist by its steps) and keeps the perturbed configuration where
    it has at least ``rules[0]`` fingertips in contact, links at most ``rules[1]`` m deep and
    a larger epsilon. Epsilon has no gradient here, so this is its refinement."""
    hand = inputs.hand
    lo, hi = np.where(np.isfinite(hand.lower), hand.lower, q), np.where(np.isfinite(hand.upper), hand.upper, q)
    scale = np.r_[_EPSILON_STEP[0] * (hi - lo), np.full(3, _EPSILON_STEP[1]), np.full(3, _EPSILON_STEP[2])]
    best_q, best_w, best = q, w, _epsilons(inputs, surface, q[None], w[None])[0]
    for _ in range(maxiter):
        step = rng.normal(size=hand.num_joints + 6) * scale
        cq = np.asarray(hand.project_joints(jnp.asarray(np.clip(best_q + step[:hand.num_joints], lo, hi))))
        cw = best_w + step[hand.num_joints:]
        g = jax.tree_util.tree_map(lambda a: a[0], _contact_grasps(inputs, surface, cq[None], cw[None]))
        deep = max(_depths(hand, surface, cq[None], cw[None])[0], _overlaps(hand, cq[None])[0])
        if int(np.sum(np.asarray(g.active))) < rules[0] or deep > rules[1]:
            continue
        e = _epsilon(g)
        if e > best:
            best_q, best_w, best = cq, cw, e
    return best_q, best_w


def _final(inputs: HandPlanInputs, surface, pool: list, top: int, objective: str, rules: tuple) -> dict:
    """Stage 6: the pool's configurations ``(qpos, wrist, refined)`` rebuilt as their files
    load, evaluated one at a time by [`jaxgrasp.evaluate`][jaxgrasp.evaluate] (the numbers
    ``jaxgrasp evaluate`` of the file gives), the eligible ones ranked by ``objective``."""
    q = np.array([p[0] for p in pool]).reshape(len(pool), inputs.hand.num_joints)
    w = np.array([p[1] for p in pool]).reshape(len(pool), 6)
    grasps = [_grasp(inputs, a, b) for a, b in zip(q, w)]
    evs = [_evaluated(g.grasp) if g.num_active >= 2 else None for g in grasps]
    values = np.array([float(e.value) if e is not None else 0.0 for e in evs])
    statuses = np.array([int(e.status) if e is not None else -1 for e in evs])
    m = dict(value=values, status=statuses, active=np.array([g.num_active for g in grasps]),
             depth=_depths(inputs.hand, surface, q, w) if len(pool) else np.zeros(0), self=_overlaps(inputs.hand, q))
    eps = np.array([_epsilon(g.grasp) if g.num_active >= 2 else 0.0 for g in grasps])
    order = _order(inputs, np.flatnonzero(_eligible(m, *rules)), m, values if objective == "value" else eps,
                   objective)[:top]
    return dict(grasps=tuple(grasps[i] for i in order), values=values[order], statuses=statuses[order],
                active=m["active"][order], penetration=m["depth"][order],
                self_overlap=m["self"][order], epsilon=eps[order],
                refined=np.array([pool[i][2] for i in order], dtype=bool), qpos=q[order], wrist=w[order])


def _order(inputs: HandPlanInputs, idx, m: dict, key, objective: str) -> np.ndarray:
    """``idx`` best first: for the value, stable grasps first; then those with at least
    `PREFERRED_FINGERTIPS` fingertips in contact; then by ``key`` (the objective),
    descending (ties in input order). The epsilon objective does not look at the value's
    status."""
    many = m["active"][idx] >= min(PREFERRED_FINGERTIPS, inputs.hand.num_fingertips)
    stable = (m["status"][idx] == GraspStatus.STABLE) if objective == "value" else np.ones(len(idx), bool)
    return idx[np.lexsort((-key[idx], ~many, ~stable))]


def _pool(inputs, surface, q, w, m, eligible, objective, top, refine, maxiter, rng, rules, progress):
    """Stage 5: the ranked eligible candidates (``top`` of them) with the best ``refine``
    refined, as ``(qpos, wrist, refined)``; and how many refinements were tried. A refined
    grasp keeps at least as many fingertips in contact as its start, up to
    `PREFERRED_FINGERTIPS`."""
    key = m["value"] if objective == "value" else _epsilons(inputs, surface, q, w)
    order = _order(inputs, np.flatnonzero(eligible), m, key, objective)
    pool = [(q[i], w[i], False) for i in order[: max(top, refine)]]
    tried = min(refine, len(pool))
    for k, i in enumerate(order[:tried]):
        if objective == "value":
            fewest = max(rules[0], min(PREFERRED_FINGERTIPS, int(m["active"][i])))
            new = _refine_value(inputs, q[i], w[i], maxiter, rules[1], fewest)
        else:
            new = _refine_epsilon(inputs, surface, q[i], w[i], maxiter, rng, rules)
        if new is not None:
            pool.append((*new, True))
        if progress is not None:
            progress("refine", k + 1, tried)
    return pool, tried


def plan_hand(mesh, hand, fingertips=None, *, young_modulus, friction, max_force, mass=None, density=None,
              center_of_mass=None, gravity=DEFAULT_GRAVITY, units: str = "m", samples: int = HAND_SAMPLES, top: int = 10,
              refine: int = 3, seed: int = 0, min_fingertips: int = 2, objective: str = "value",
              tune_maxiter: int = 30, max_penetration: float = 1e-3, settings: CloseSettings = CloseSettings(),
              progress=None) -> HandPlanResult:
    """[`jaxgrasp.plan`][jaxgrasp.plan] with a hand (module notes); its arguments are documented there."""
    t0 = time.perf_counter()
    inputs = check_hand_plan(mesh, hand, fingertips, young_modulus=young_modulus, friction=friction,
                             max_force=max_force, mass=mass, density=density, center_of_mass=center_of_mass,
                             gravity=gravity, units=units, samples=samples, top=top, refine=refine, seed=seed,
                             min_fingertips=min_fingertips, objective=objective, tune_maxiter=tune_maxiter,
                             max_penetration=max_penetration)
    return plan_hand_stages(inputs, samples, top, refine, seed, min_fingertips, objective, tune_maxiter,
                            max_penetration, settings, progress, t0)


def plan_hand_stages(inputs, samples, top, refine, seed, min_fingertips, objective, tune_maxiter, max_penetration,
                     settings, progress, t0) -> HandPlanResult:
    """`plan_hand` on its checked inputs (`check_hand_plan`): the six stages, timed."""
    rng, rules, times = np.random.default_rng(seed), (min_fingertips, max_penetration), {}
    clock = [time.perf_counter()]

    def lap(name):
        now = time.perf_counter()
        times[name], clock[0] = now - clock[0], now

    surface, grid = _surfaces(inputs, progress)
    lap("setup")
    q, w = _close(inputs, surface, grid, samples, rng, settings, progress)
    lap("close")
    m = _measure(inputs, surface, q, w, progress)
    eligible = _eligible(m, *rules)
    lap("evaluate")
    pool, tried = _pool(inputs, surface, q, w, m, eligible, objective, top, refine, tune_maxiter, rng, rules, progress)
    lap("refine")
    ranked = _final(inputs, surface, pool, top, objective, rules)
    lap("rank")
    kept = int(np.sum(ranked["refined"]))
    found = len(ranked["values"]) and ranked["statuses"][0] == GraspStatus.STABLE
    status = PlanStatus.FOUND if found else (PlanStatus.NONE_STABLE if np.any(eligible) else PlanStatus.NO_VALID)
    counts = dict(candidates=samples, evaluated=int(np.sum(m["active"] >= 2)), eligible=int(np.sum(eligible)),
                  stable=int(np.sum(eligible & (m["status"] == GraspStatus.STABLE))), refine_tried=tried,
                  refine_kept=kept)
    return HandPlanResult(status=status, **ranked, **counts, seed=seed, elapsed_s=time.perf_counter() - t0,
                          timings=times, settings=_settings(inputs, objective, min_fingertips, max_penetration, samples))


def _settings(inputs: HandPlanInputs, objective, min_fingertips, max_penetration, samples) -> dict:
    hand = inputs.hand
    return dict(hand=hand.tree.source, fingertips=list(hand.fingertip_names), objective=objective,
                min_fingertips=min_fingertips, max_penetration=max_penetration, samples=samples, **inputs.fields,
                mass=inputs.mass, gravity=inputs.gravity.tolist(), center_of_mass=inputs.com.tolist(),
                units=inputs.units, mesh=inputs.source)
