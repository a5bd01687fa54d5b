"""Planning: the grasps of a real object that tolerate the most energy, found from its mesh.

[`plan`][jaxgrasp.plan] runs five stages, each a function here:

1. **draw** geometric candidates (`jaxgrasp.planning._sampling`): antipodal pairs by
   ray casting for two fingers, spread tuples from a pool of surface samples (their normals
   nearly balancing, or adding up to a push that carries the weight) for three or more, or
   plain uniform samples (``sampler="uniform"``, the baseline); each candidate gets one
   initial deformation drawn uniformly in rule 5's range;
2. **keep** the candidates that keep every contact rule ([`jaxgrasp.surface.check_contacts`][jaxgrasp.surface.check_contacts]),
   drawing more rounds until ``samples`` are valid;
3. **evaluate** them all in batches (the engine's runner, in chunks of `CHUNK`:
   `evaluate_in_chunks`);
4. **refine** the best ``refine`` by gradient tuning of positions (sliding along the surface)
   and initial deformations ([`jaxgrasp.tune`][jaxgrasp.tune] of a [`MeshGrasp`][jaxgrasp.MeshGrasp]),
   keeping a tuned grasp only where it still keeps every rule and settles;
5. **rank** the settled grasps by value and give the ``top`` of them, each rebuilt exactly as
   its grasp file will load ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] with its normals, centre of mass
   and mass) and evaluated again by [`jaxgrasp.evaluate`][jaxgrasp.evaluate], with its epsilon.
"""

from __future__ import annotations

import dataclasses
import time
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.analysis import Uncertainty, epsilon, robust_batch, tune
from jaxgrasp.engine import evaluate, evaluate_in_chunks
from jaxgrasp.io import from_mesh, load_mesh
from jaxgrasp.model import DEFAULT_GRAVITY, Grasp, GraspValueError
from jaxgrasp.planning._limits import MAX_FINGERS, SAMPLERS
from jaxgrasp.planning._hand_close import CloseSettings
from jaxgrasp.planning._hand_plan import plan_hand_stages as plan_hand_checked
from jaxgrasp.planning._hand_plan import HAND_SAMPLES, check_caps, check_hand_plan
from jaxgrasp.planning._hand_result import HandPlanResult
from jaxgrasp.planning._progress import PlanProgress
from jaxgrasp.planning._progress import stage as _stage
from jaxgrasp.planning._result import PlanResult, PlanStatus
from jaxgrasp.planning._sampling import antipodal_pairs, spread_tuples, surface_points
from jaxgrasp.surface import (
    PAD_FACES,
    ContactRules,
    MeshGrasp,
    RuleCheck,
    FaceTree,
    Surface,
    build_tree,
    check_contacts,
    deformation_range,
    mass_properties,
)
from jaxgrasp.tolerance import GraspStatus

__all__ = ["plan", "check_plan", "PlanInputs"]

_ROUND = 512
"""Candidates drawn and checked per round."""

CHUNK = 64
"""Candidates per compiled evaluation call."""

_MAX_DRAWS = 100
"""Candidates drawn per valid one asked for, at most (and at least 40 rounds): past that the
plan goes on with the valid candidates it has (the result counts them)."""


@dataclasses.dataclass(frozen=True)
class _Setup:
    """The object and fingertips of a plan (mesh frame, SI units)."""

    mesh: object
    surface: Surface  # padded (PAD_FACES), for compiled checks
    triangles: np.ndarray  # (F, 3, 3) m, the mesh's own faces, for sampling
    face_normals: np.ndarray  # (F, 3)
    tree: FaceTree  # of triangles, for ray casts
    com: np.ndarray
    mass: float
    gravity: np.ndarray
    fingertip: dict  # radius, young_modulus, friction, max_force: floats
    source: str
    units: str


def plan(
    mesh, fingers: int | None = None, *, radius: float | None = None, young_modulus: float, friction: float,
    max_force: float, mass: float | None = None, density: float | None = None, center_of_mass=None,
    gravity=DEFAULT_GRAVITY, units: str = "m", samples: int | None = None, top: int = 10, refine: int = 3,
    seed: int = 0, rules: ContactRules | None = None, sampler: str | None = None, tune_maxiter: int = 30,
    robust: Uncertainty | None = None, robust_samples: int = 64, hand=None, fingertips=None,
    min_fingertips: int = 2, objective: str = "value", max_penetration: float = 1e-3, progress=None,
) -> PlanResult | HandPlanResult:
    """Find the grasps of a meshed object that tolerate the most energy: by ``fingers`` free
    fingertips, or by a robot ``hand``.

    Args:
        mesh: ``trimesh.Trimesh`` or mesh file (STL, OBJ, PLY, OFF, GLB), vertices in ``units``.
        fingers: number of free fingertips, 2 to 8 (default 2; not with ``hand``).
        radius, young_modulus, friction, max_force: every fingertip's radius (m; free
            fingertips only: a hand's are its own), Young's modulus (Pa), friction
            coefficient and force limit (N).
        mass, density, center_of_mass: the object's mass (kg) or density (kg/m^3), and its
            centre of mass (m, mesh frame; default the watertight mesh's), as
            [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh].
        gravity: ``(3,)`` m/s^2 in the mesh's axes. units: the mesh's, ``"m"``, ``"cm"``, ``"mm"``.
        samples: valid candidates to evaluate (fewer when ``_MAX_DRAWS`` draws per valid one
            asked for do not find them: the result says how many).
        top: ranked grasps to return. refine: of the best, how many to tune. seed: of every
            random draw: equal seeds give equal plans.
        rules: the rules' tolerances (default ``ContactRules()``, [`ContactRules`][jaxgrasp.surface.ContactRules]).
        sampler: one of `SAMPLERS` (default ``antipodal`` for two, else ``spread``). tune_maxiter: per refinement.
        robust: an [`Uncertainty`][jaxgrasp.analysis.Uncertainty]: rank the ``top`` by the mean value over ``robust_samples``
            perturbed copies ([`jaxgrasp.robust_batch`][jaxgrasp.robust_batch]; ties by value); ``None``: by the value.
        robust_samples: perturbed copies of each ranked grasp. progress: ``progress(stage,
            done, total)`` (stage ``"draw"``, ``"evaluate"``, ``"refine"``, ``"robust"``);
            default a `PlanProgress`: records on the ``"jaxgrasp"`` logger.
        hand: a [`Hand`][jaxgrasp.Hand], or its MJCF or URDF file with ``fingertips`` (names, as
            [`Hand.from_file`][jaxgrasp.Hand.from_file]): plan the hand's configurations instead
            (`jaxgrasp.planning._hand_plan`); ``samples`` (default 128) counts its closed candidates.
        min_fingertips, objective, max_penetration: with a hand, the fewest fingertips in contact
            of a ranked grasp; what is maximised, ``"value"`` or ``"epsilon"`` (the Ferrari-Canny
            epsilon); how deep (m) its other links may lie in the object.

    Returns:
        A [`PlanResult`][jaxgrasp.planning.PlanResult]; with a hand a [`HandPlanResult`][jaxgrasp.planning.HandPlanResult].

    Raises:
        GraspValueError: bad arguments or mesh (one line), before anything is computed.
    """
    t0 = time.perf_counter()
    if hand is not None:
        return _with_hand(mesh, hand, fingertips, (fingers, radius, rules, sampler, robust), progress, t0, dict(
            young_modulus=young_modulus, friction=friction, max_force=max_force, mass=mass, density=density,
            center_of_mass=center_of_mass, gravity=gravity, units=units, samples=HAND_SAMPLES if samples is None else samples,
            top=top, refine=refine, seed=seed, min_fingertips=min_fingertips, objective=objective,
            tune_maxiter=tune_maxiter, max_penetration=max_penetration))
    fingers, samples = _free_defaults(fingers, samples, radius, fingertips)
    checked = check_plan(mesh, fingers, radius=radius, young_modulus=young_modulus, friction=friction,
                         max_force=max_force, mass=mass, density=density, center_of_mass=center_of_mass,
                         gravity=gravity, units=units, samples=samples, top=top, refine=refine, seed=seed,
                         rules=rules, sampler=sampler, tune_maxiter=tune_maxiter, robust=robust,
                         robust_samples=robust_samples)
    progress = PlanProgress(t0) if progress is None else progress
    return _planned(checked, fingers, samples, top, refine, seed, tune_maxiter, robust, robust_samples, progress, t0)


def _free_defaults(fingers, samples, radius, fingertips) -> tuple[int, int]:
    """``(fingers, samples)`` of a plan by free fingertips (defaults 2 and 150); one line for
    a missing ``radius`` or a ``fingertips`` without a hand."""
    if fingertips is not None:
        raise GraspValueError("plan: fingertips= names a hand's fingertips; give hand= too")
    if radius is None:
        raise GraspValueError("plan: radius= (m, every fingertip's) is needed without a hand")
    return 2 if fingers is None else fingers, 150 if samples is None else samples


def _with_hand(mesh, hand, fingertips, free: tuple, progress, t0: float, kwargs: dict) -> HandPlanResult:
    """[`plan`][jaxgrasp.plan] with a hand: the options of free fingertips ``free`` (fingers,
    radius, rules, sampler, robust) refused (one line), the rest checked, then planned."""
    for name, v in zip(("fingers", "radius", "rules", "sampler", "robust"), free):
        if v is not None:
            raise GraspValueError(f"plan: {name}= is for free fingertips, not with hand= (a hand has its own)")
    inputs = check_hand_plan(mesh, hand, fingertips, **kwargs)
    progress = PlanProgress(t0) if progress is None else progress
    k = kwargs
    return plan_hand_checked(inputs, k["samples"], k["top"], k["refine"], k["seed"], k["min_fingertips"],
                             k["objective"], k["tune_maxiter"], k["max_penetration"], CloseSettings(), progress, t0)


def _planned(checked: "PlanInputs", fingers, samples, top, refine, seed, tune_maxiter, robust, robust_samples,
             progress, t0) -> PlanResult:
    """[`plan`][jaxgrasp.plan] on its checked inputs: draw, evaluate, rank, refine, (robust) rank again;
    ``t0`` the `time.perf_counter` at which the plan began."""
    setup, sampler, rules = checked.setup, checked.sampler, checked.rules
    rng = np.random.default_rng(seed)
    pos, nrm, dr, sampled, failures = draw_valid(setup, fingers, samples, sampler, rules, rng, progress)
    if len(pos) == 0:
        return _empty(PlanStatus.NO_VALID, sampled, failures, seed, t0, setup, fingers, sampler, rules)
    values, statuses = _evaluate(setup, pos, nrm, dr, progress)
    order = _ranked(values, statuses)
    pool = [(pos[i], nrm[i], dr[i], False) for i in order[: max(top, refine)]]
    kept = _refine(setup, pool[:refine], rules, tune_maxiter, progress)
    ranked = _final(setup, kept + pool[refine:], top)
    if robust is not None and len(ranked["grasps"]):
        ranked = _robust_ranked(ranked, robust, robust_samples, seed, progress)
    counts = dict(valid=len(pos), stable=int(np.sum(statuses == GraspStatus.STABLE)),
                  dropped=int(np.sum(statuses == GraspStatus.NOT_CONVERGED)), refine_tried=min(refine, len(pool)),
                  refine_kept=sum(1 for p in kept if p[3]))
    settings = dict(fingers=fingers, sampler=sampler, rules=dataclasses.asdict(rules), samples=samples,
                    rank="value" if robust is None else f"robust ({robust.to_spec()}, {robust_samples} samples)")
    return _result(ranked, setup, sampled, failures, counts, seed, t0, settings)


@dataclasses.dataclass(frozen=True)
class PlanInputs:
    """A plan's inputs as `check_plan` found them.

    Attributes:
        sampler: the candidate generator, one of `SAMPLERS` (the default resolved).
        rules: the [`ContactRules`][jaxgrasp.surface.ContactRules].
        mesh: the object's ``trimesh.Trimesh``, m, mesh frame.
        center_of_mass: ``(3,)`` m, mesh frame. mass: kg.
        setup: everything [`plan`][jaxgrasp.plan] computes from (internal).
    """

    sampler: str
    rules: ContactRules
    setup: _Setup

    @property
    def mesh(self):
        return self.setup.mesh

    @property
    def center_of_mass(self) -> np.ndarray:
        return self.setup.com

    @property
    def mass(self) -> float:
        return self.setup.mass


def check_plan(
    mesh, fingers: int = 2, *, radius: float, young_modulus: float, friction: float, max_force: float,
    mass: float | None = None, density: float | None = None, center_of_mass=None, gravity=DEFAULT_GRAVITY,
    units: str = "m", samples: int = 150, top: int = 10, refine: int = 3, seed: int = 0,
    rules: ContactRules | None = None, sampler: str | None = None, tune_maxiter: int = 30,
    robust: Uncertainty | None = None, robust_samples: int = 64,
) -> PlanInputs:
    """Check [`plan`][jaxgrasp.plan]'s arguments and read its mesh, computing nothing: the one check
    [`plan`][jaxgrasp.plan] makes first, for callers that must know the input is good before they
    start (``jaxgrasp plan`` checks it before it creates ``--out``).

    Args: as [`plan`][jaxgrasp.plan] (``progress`` aside).

    Returns:
        The checked `PlanInputs`.

    Raises:
        GraspValueError: one line: a count out of range (``fingers`` 2 to 8, ``samples`` and
        ``top`` 1 to `MAX_PLAN_SAMPLES`, ``refine`` 0 to `MAX_PLAN_REFINE`, ``seed`` >= 0,
        ``tune_maxiter`` 1 to `MAX_TUNE_ITERATIONS`, ``robust_samples`` 2 to
        `MAX_ROBUST_SAMPLES`), an unknown sampler or one that cannot make ``fingers``-finger grasps, a
        fingertip value, mass, density or gravity that is not a finite number in range, a
        bad mesh (`jaxgrasp.io._mesh.load_mesh`; not watertight without
        ``center_of_mass``), or rules that no initial deformation keeps (rule 5).
    """
    sampler = _checked_args(fingers, samples, top, refine, seed, sampler)
    for name, v, lo in (("tune_maxiter", tune_maxiter, 1), ("robust_samples", robust_samples, 2)):
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
            raise GraspValueError(f"plan: {name} must be an integer >= {lo}, got {v!r}")
    check_caps(samples, top, refine, tune_maxiter, robust_samples)
    if robust is not None and not isinstance(robust, Uncertainty):
        raise GraspValueError(f"plan: robust must be an Uncertainty or None, got {type(robust).__name__}")
    rules = ContactRules() if rules is None else rules
    if not isinstance(rules, ContactRules):
        raise GraspValueError(f"plan: rules must be a ContactRules or None, got {type(rules).__name__}")
    built = setup(mesh, units, mass, density, center_of_mass, gravity, radius, young_modulus, friction, max_force)
    _dr_range(built, rules)
    return PlanInputs(sampler, rules, built)


def _checked_args(fingers, samples, top, refine, seed, sampler) -> str:
    """The sampler to use; one-line errors for bad counts."""
    for name, v, lo in (("fingers", fingers, 2), ("samples", samples, 1), ("top", top, 1), ("refine", refine, 0),
                        ("seed", seed, 0)):
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
            raise GraspValueError(f"plan: {name} must be an integer >= {lo}, got {v!r}")
    if fingers > MAX_FINGERS:
        raise GraspValueError(f"plan: fingers = {fingers} is more than {MAX_FINGERS}")
    sampler = sampler or ("antipodal" if fingers == 2 else "spread")
    if sampler not in SAMPLERS:
        raise GraspValueError(f"plan: unknown sampler {sampler!r}; choose from {', '.join(SAMPLERS)}")
    if sampler == "antipodal" and fingers != 2:
        raise GraspValueError(f"plan: the antipodal sampler makes two-finger grasps, not {fingers}")
    return sampler


def setup(mesh, units, mass, density, center_of_mass, gravity, radius, young_modulus, friction, max_force) -> _Setup:
    """The checked object and fingertips."""
    import os

    surface_mesh = load_mesh(mesh, units, how='pass --units {} (Python: units="{}")')  # a mm mesh read as m: named
    if center_of_mass is None and not surface_mesh.is_watertight:
        where = f"mesh {os.fspath(mesh)!r}" if isinstance(mesh, (str, os.PathLike)) else "the mesh"
        raise GraspValueError(
            f"plan: {where} is not watertight (not a closed surface), so it has no centre of mass or "
            "volume of its own: plan needs a closed mesh (jaxgrasp.plan also takes center_of_mass= and mass=)"
        )
    for name, v in (("mass", mass), ("density", density)):
        if v is not None and not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) and v >= 0):
            raise GraspValueError(f"plan: {name} = {v!r} must be a finite number >= 0 (SI units)")
    com, m = mass_properties(surface_mesh, mass, density, center_of_mass)
    tip = {}
    for name, v in (("radius", radius), ("young_modulus", young_modulus), ("friction", friction),
                    ("max_force", max_force)):
        if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
            raise GraspValueError(f"plan: {name} = {v!r} must be a finite number > 0 (SI units)")
        tip[name] = float(v)
    g = np.asarray(gravity, dtype=np.float64)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise GraspValueError(f"plan: gravity must be 3 finite numbers, m/s^2; got {gravity!r}")
    source = os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else "<trimesh>"
    bare = Surface.from_trimesh(surface_mesh)
    tri, fn = np.asarray(bare.triangles), np.asarray(bare.normals)
    return _Setup(surface_mesh, bare.padded(PAD_FACES), tri, fn, build_tree(tri, fn), com, float(m), g, tip, source,
                  units)




# ------------------------------------------------------------------------------ draw, keep


@lru_cache(maxsize=8)
def _checker(rules: ContactRules):
    """``check(surface, positions (B, N, 3), normals, dr (B, N), radius, E, f_max) -> RuleCheck``."""
    one = lambda s, p, n, d, r, e, f: check_contacts(s, p, n, d, r, e, f, rules)  # noqa: E731
    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0, None, None, None)))


def _check(setup: _Setup, rules: ContactRules, pos, nrm, dr) -> RuleCheck:
    """The rule check of ``B <= _ROUND`` candidates (padded to ``_ROUND``: one compilation)."""
    b = len(pos)
    pad = lambda a: np.concatenate([a, np.repeat(a[:1], _ROUND - b, axis=0)])  # noqa: E731
    tip = setup.fingertip
    out = _checker(rules)(setup.surface, pad(pos), pad(nrm), pad(dr), tip["radius"], tip["young_modulus"],
                          tip["max_force"])
    return jax.tree_util.tree_map(lambda a: np.asarray(a)[:b], out)


def _draw_round(setup: _Setup, fingers: int, sampler: str, rules: ContactRules, rng):
    """One round of candidates: ``(positions (K, N, 3), normals (K, N, 3), dr (K, N))``, mesh
    frame, each position put exactly on the surface."""
    lo, hi = _dr_range(setup, rules)
    tri, fn = setup.triangles, setup.face_normals
    if sampler == "uniform":
        p, n = surface_points(tri, fn, _ROUND * fingers, rng)
        pos, nrm = p.reshape(_ROUND, fingers, 3), n.reshape(_ROUND, fingers, 3)
    else:  # from a pool of single contacts that keep the rules at the smallest deformation
        p, n = surface_points(tri, fn, _ROUND, rng)
        one = _check(setup, rules, p[:, None], n[:, None], np.full((_ROUND, 1), lo))
        ok = one.flat[:, 0] & one.alone[:, 0]
        if sampler == "antipodal":
            pos, nrm = antipodal_pairs(setup.tree, fn, p[ok], n[ok], setup.fingertip["friction"])
        elif ok.sum() >= fingers:
            g = np.linalg.norm(setup.gravity) * setup.mass
            down = setup.gravity / np.linalg.norm(setup.gravity) if g > 0 else None
            pos, nrm = spread_tuples(p[ok], n[ok], fingers, _ROUND, rng, down)
        else:
            pos, nrm = np.zeros((0, fingers, 3)), np.zeros((0, fingers, 3))
    if len(pos):
        pos = np.asarray(setup.surface.closest(pos).point)  # rays and sums leave round-off off the surface
    dr = np.repeat(rng.uniform(lo, hi, size=(len(pos), 1)), fingers, axis=1)
    return pos, nrm, dr


def _dr_range(setup: _Setup, rules: ContactRules) -> tuple[float, float]:
    """Rule 5's range of the initial deformation, m; one line where it is empty."""
    tip = setup.fingertip
    lo, hi = (float(x) for x in deformation_range(tip["radius"], tip["young_modulus"], tip["max_force"], rules.dr_min))
    if hi < lo:
        raise GraspValueError(
            f"plan: no initial deformation keeps rule 5: dr_min = {lo:g} m is above "
            f"min(0.9 radius, sqrt(max_force / (pi young_modulus))) = {hi:g} m"
        )
    return lo, hi


def draw_valid(setup: _Setup, fingers, samples, sampler, rules, rng, progress):
    """Rounds of candidates until ``samples`` keep every rule (or ``_MAX_DRAWS`` per sample):
    ``(positions, normals, dr, drawn, failures by rule)`` of the first ``samples`` valid."""
    keep: list = []
    drawn, failures, valid = 0, dict.fromkeys(RuleCheck.RULES, 0), 0
    for _ in range(max(40, -(-_MAX_DRAWS * samples // _ROUND))):
        pos, nrm, dr = _draw_round(setup, fingers, sampler, rules, rng)
        if len(pos):
            chk = _check(setup, rules, pos, nrm, dr)
            for rule in RuleCheck.RULES:
                failures[rule] += int(np.sum(~np.all(getattr(chk, rule), axis=-1)))
            keep.append((pos[chk.valid], nrm[chk.valid], dr[chk.valid]))
            valid += int(chk.valid.sum())
        drawn += len(pos)
        if progress is not None:
            progress("draw", min(valid, samples), samples)
        if valid >= samples:
            break
    if not keep:
        return np.zeros((0, fingers, 3)), np.zeros((0, fingers, 3)), np.zeros((0, fingers)), drawn, failures
    pos, nrm, dr = (np.concatenate(a)[:samples] for a in zip(*keep))
    return pos, nrm, dr, drawn, failures


# ---------------------------------------------------------------------- evaluate, refine, rank


def grasps_of(setup: _Setup, pos, nrm, dr) -> Grasp:
    """The batched grasp ``(B, N, ...)`` of candidates, in the centre-of-mass frame."""
    b, n = dr.shape
    full = lambda v: jnp.full((b, n), v, jnp.float64)  # noqa: E731
    tip = setup.fingertip
    return Grasp(
        positions=jnp.asarray(pos - setup.com), normals=jnp.asarray(nrm), initial_deformation=jnp.asarray(dr),
        radius=full(tip["radius"]), young_modulus=full(tip["young_modulus"]), friction=full(tip["friction"]),
        max_force=full(tip["max_force"]), mass=jnp.full((b,), setup.mass, jnp.float64),
        gravity=jnp.broadcast_to(jnp.asarray(setup.gravity), (b, 3)), active=None,
    )


def _evaluate(setup: _Setup, pos, nrm, dr, progress) -> tuple[np.ndarray, np.ndarray]:
    """``(values (B,) J, statuses (B,))`` of the candidates, in chunks of exactly
    `CHUNK` (`evaluate_in_chunks`), so that every plan
    of a finger count runs one compiled evaluator, whatever its number of samples."""
    ev = evaluate_in_chunks(grasps_of(setup, pos, nrm, dr), CHUNK, progress=_stage(progress, "evaluate"))
    return np.asarray(ev.value), np.asarray(ev.status)


def _ranked(values, statuses) -> np.ndarray:
    """Indices of the settled grasps, best value first (ties in input order)."""
    settled = np.flatnonzero(statuses != GraspStatus.NOT_CONVERGED)
    return settled[np.argsort(-values[settled], kind="stable")]


def _mesh_grasp(setup: _Setup, pos, nrm, dr) -> MeshGrasp:
    """One candidate as its grasp file loads: [`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] with its normals,
    the centre of mass and the mass given."""
    made = from_mesh(setup.mesh, pos, normals=list(nrm), initial_deformation=dr, center_of_mass=setup.com,
                     mass=setup.mass, gravity=setup.gravity, **setup.fingertip)
    return made.replace(source=setup.source, units=setup.units)


def _refine(setup: _Setup, entries, rules, maxiter, progress) -> list:
    """Each entry ``(pos, nrm, dr, refined)`` replaced by its tuned grasp where tuning
    (positions along the surface, initial deformations in rule 5's range) raised the value
    and the tuned grasp keeps every rule and is stable."""
    lo, hi = _dr_range(setup, rules)
    out = []
    for i, (pos, nrm, dr, _) in enumerate(entries):
        out.append((pos, nrm, dr, False))
        mg = _mesh_grasp(setup, pos, nrm, dr)
        try:
            res = tune(mg, ["positions", "initial_deformation"], {"positions": setup.fingertip["radius"],
                       "initial_deformation": (lo, hi)}, maxiter=maxiter)
        except GraspValueError:  # an unstable start: nothing to follow
            continue
        finally:
            if progress is not None:
                progress("refine", i + 1, len(entries))
        g = res.mesh_grasp.grasp
        new = (np.asarray(g.positions) + setup.com, np.asarray(g.normals), np.asarray(g.initial_deformation))
        chk = _check(setup, rules, new[0][None], new[1][None], new[2][None])
        if bool(chk.valid[0]) and int(res.evaluation.status) == GraspStatus.STABLE and res.value > res.start_value:
            out[-1] = (*new, True)
    return out


def _final(setup: _Setup, entries, top: int) -> dict:
    """The ``top`` best settled entries, rebuilt as their files load and evaluated again,
    best first, with their epsilon."""
    grasps = [_mesh_grasp(setup, p, n, d) for p, n, d, _ in entries]
    # one at a time, as `jaxgrasp evaluate` of the grasp's file does, for its very numbers:
    # the batch's may round apart from them (tests/engine/test_single_vs_batch.py bounds
    # how far), and a refined grasp was never in a batch
    evs = [evaluate(g.grasp) for g in grasps]
    ev = jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *evs)
    values, statuses = np.asarray(ev.value), np.asarray(ev.status)
    order = _ranked(values, statuses)[:top]
    return dict(
        grasps=tuple(grasps[i] for i in order), values=values[order], statuses=statuses[order],
        limiting_kind=np.asarray(ev.limiting_kind)[order], limiting_contact=np.asarray(ev.limiting_contact)[order],
        epsilon=np.array([epsilon(grasps[i].grasp).value for i in order]),
        refined=np.array([entries[i][3] for i in order], dtype=bool),
        mesh_positions=np.array([entries[i][0] for i in order]).reshape(len(order), -1, 3),
    )


def _robust_ranked(ranked: dict, uncertainty: Uncertainty, samples: int, seed: int, progress) -> dict:
    """``ranked`` reordered by the robust value ([`jaxgrasp.robust_batch`][jaxgrasp.robust_batch]), best first,
    with its columns (``p_stable``, ``value_mean``, quantiles) under ``"robust"``."""
    rb = robust_batch(list(ranked["grasps"]), uncertainty, samples, seed, progress=_stage(progress, "robust"))
    order = rb.rank("value_mean")
    out = {k: (tuple(v[i] for i in order) if isinstance(v, tuple) else v[order]) for k, v in ranked.items()}
    out["robust"] = {k: np.asarray(v)[order] for k, v in rb.columns().items()}
    return out


def _result(ranked, setup, sampled, failures, counts, seed, t0, settings) -> PlanResult:
    found = len(ranked["values"]) and ranked["statuses"][0] == GraspStatus.STABLE
    settings = {**settings, **setup.fingertip, "mass": setup.mass, "gravity": setup.gravity.tolist(),
                "center_of_mass": setup.com.tolist(), "units": setup.units, "mesh": setup.source}
    return PlanResult(
        status=PlanStatus.FOUND if found else PlanStatus.NONE_STABLE, **ranked, sampled=sampled,
        rule_failures=failures, **counts, seed=seed,
        elapsed_s=time.perf_counter() - t0, settings=settings,
    )


def _empty(status, sampled, failures, seed, t0, setup, fingers, sampler, rules) -> PlanResult:
    """The result of a plan that evaluated nothing."""
    none = np.zeros(0)
    ranked = dict(grasps=(), values=none, statuses=none.astype(int), limiting_kind=none.astype(int),
                  limiting_contact=none.astype(int), epsilon=none, refined=none.astype(bool),
                  mesh_positions=np.zeros((0, fingers, 3)))
    res = _result(ranked, setup, sampled, failures, dict(valid=0, stable=0, dropped=0, refine_tried=0, refine_kept=0), seed, t0,
                  dict(fingers=fingers, sampler=sampler, rules=dataclasses.asdict(rules)))
    return dataclasses.replace(res, status=status)
