"""Every program settled on grasps of real objects (issue 42).

Valid candidate grasps of real meshes, drawn by the planner's own code
(:func:`jaxgrasp.planning.draw_valid`, so that every candidate keeps the contact
rules) on ``pybullet_data``'s ``random_urdfs`` objects 000-099, ``duck_vhacd``, ``bunny``
and ``teddy2_VHACD_CHs``, with 2, 3 and 4 fingertips (r = 10 mm, E = 3e5 Pa, mu = 0.8,
f_max = 15 N, density 500 kg/m^3, gravity -z in the mesh axes). The meshes are made here
from ``pybullet_data``: the ``random_urdfs`` objects are in the URDF's units of 0.015 m
(their vertices times 15 are mm), duck, bunny and teddy are scaled to 120 mm across.

Every candidate is evaluated with :func:`jaxgrasp.evaluate_batch` (one batch per finger
count). The script counts the unsettled programs (the equilibrium, the slip and the
force-limit boundaries: ``Evaluation.equilibrium_status``, ``boundary_status``) and the
grasps ``not_converged``, saves the unsettled grasps to a small dataset (``--unsettled``,
to iterate on them alone) and checks a sample against the independent CasADi/Ipopt
multi-start reference (``tests/ipopt_reference.py``): every unsettled grasp and ``--ipopt``
random ones. It writes a JSON summary (``--json``); the log goes to stderr::

    nice python experiments/settling/settle_real.py > experiments/settle_real.log 2>&1

``--per-object 6 --ipopt 4 --json /tmp/s.json`` is a quick run.
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import json
import math
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

FINGERTIP = dict(radius=0.01, young_modulus=3e5, friction=0.8, max_force=15.0)
DENSITY = 500.0
ACROSS_MM = 120.0  # duck, bunny, teddy: scaled to this largest extent
URDF_UNIT_MM = 15.0  # random_urdfs: vertices in units of 0.015 m
NAMED = ("duck_vhacd", "bunny", "teddy2_VHACD_CHs")
STATUS = ("stable", "unstable", "infeasible", "not_converged")
LANE = ("converged", "infeasible", "not_converged", "no_start")
REL = 1e-6


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--per-object", type=int, default=102, help="valid candidates per object, split over 2, 3, 4 fingers")
    p.add_argument("--objects", type=int, default=100, help="random_urdfs objects 000 .. (default 100)")
    p.add_argument("--ipopt", type=int, default=40, help="random grasps checked against Ipopt besides the unsettled")
    p.add_argument("--n-starts", type=int, default=24, help="Ipopt starts per problem")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=Path(__file__).resolve().parent / "settle_real.json")
    p.add_argument("--unsettled", type=Path, default=Path(__file__).resolve().parent / "settle_real_unsettled.npz")
    p.add_argument("--reference", type=Path, default=None,
                   help="the --json of an earlier run on the same candidates: its Ipopt values are reused")
    p.add_argument("--include", type=Path, default=None,
                   help="a --unsettled file of an earlier run: its grasps join the Ipopt sample")
    p.add_argument("--candidates", type=Path, nargs="*", default=(),
                   help=".npz files of candidates: read (joined) if they all exist (the draw skipped), else the "
                        "draw written to the first")
    p.add_argument("--part", default="0/1", help="K/P: draw only the objects k with k %% P == K")
    p.add_argument("--no-ipopt", action="store_true", help="count only: no Ipopt comparison")
    p.add_argument("--draw-only", action="store_true", help="draw, write --candidates and stop")
    return p.parse_args()


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def meshes(num_objects: int):
    """``(name, trimesh in mm)`` of every object, made from ``pybullet_data``."""
    import pybullet_data
    import trimesh

    data = Path(pybullet_data.getDataPath())
    for k in range(num_objects):
        m = trimesh.load(data / "random_urdfs" / f"{k:03d}" / f"{k:03d}.obj", force="mesh")
        m.apply_scale(URDF_UNIT_MM)
        yield f"{k:03d}", m
    for name in NAMED:
        m = trimesh.load(data / f"{name}.obj", force="mesh")
        m.apply_scale(ACROSS_MM / float(np.max(m.extents)))
        yield name, m


def mass_and_com(mesh):
    """``(mass, density, centre of mass)`` for :func:`jaxgrasp.planning.setup`: the density alone for a
    watertight mesh (its own mass and centre of mass), else (``random_urdfs`` 037 and 099
    have holes) the mass and centre of mass of its convex hull at that density (kg, m)."""
    if mesh.is_watertight:
        return None, DENSITY, None
    hull = mesh.convex_hull
    log(f"not watertight: mass and centre of mass of its convex hull")
    return DENSITY * float(hull.volume) * 1e-9, None, np.asarray(hull.center_mass) * 1e-3


def draw(args):
    """Valid candidates per finger count: ``{n: dict(pos, nrm, dr, mass, gravity, object)}``
    (SI units, the centre-of-mass frame as :func:`jaxgrasp.planning.grasps_of` makes it)."""
    from jaxgrasp.planning import draw_valid, grasps_of, setup as plan_setup
    from jaxgrasp.surface import ContactRules

    rules = ContactRules()
    out = {n: collections.defaultdict(list) for n in (2, 3, 4)}
    rng = np.random.default_rng(args.seed)
    shares = {2: args.per_object - 2 * (args.per_object // 3), 3: args.per_object // 3, 4: args.per_object // 3}
    part, parts = (int(x) for x in args.part.split("/"))
    for k, (name, mesh) in enumerate(meshes(args.objects)):
        if k % parts != part:
            continue
        setup = plan_setup(mesh, "mm", *mass_and_com(mesh), (0.0, 0.0, -9.81), **FINGERTIP)
        for n, want in shares.items():
            sampler = "antipodal" if n == 2 else "spread"
            try:
                pos, nrm, dr, _, _ = draw_valid(setup, n, want, sampler, rules, rng, None)
            except ValueError as exc:  # the planner's antipodal sampler on an empty pool of single contacts
                log(f"{name}, {n} fingers: the planner's draw failed ({exc}); none drawn")
                continue
            g = grasps_of(setup, pos, nrm, dr)
            d = out[n]
            d["pos"].append(np.asarray(g.positions))
            d["nrm"].append(np.asarray(g.normals))
            d["dr"].append(np.asarray(g.initial_deformation))
            d["mass"].append(np.asarray(g.mass))
            d["gravity"].append(np.asarray(g.gravity))
            d["object"] += [name] * len(pos)
        log(f"{name}: drawn ({sum(len(out[n]['object']) for n in out)} so far)")
    return {n: {k: (np.concatenate(v) if k != "object" else np.array(v)) for k, v in d.items()} for n, d in out.items()}


def cached_draw(args):
    """:func:`draw`, or its candidates as ``--candidates`` saved them (several files joined)."""
    keys = ("pos", "nrm", "dr", "mass", "gravity", "object")
    paths = list(args.candidates)
    if paths and all(p.exists() for p in paths):
        zs = [np.load(p) for p in paths]
        return {n: {k: np.concatenate([z[f"n{n}_{k}"] for z in zs]) for k in keys} for n in (2, 3, 4)}
    cands = draw(args)
    if paths:
        np.savez_compressed(paths[0], **{f"n{n}_{k}": v for n, d in cands.items() for k, v in d.items()})
    return cands


def grasp_of(d, i):
    """Candidate ``i`` of a finger count's arrays as a :class:`jaxgrasp.Grasp`."""
    import jaxgrasp

    n = d["dr"].shape[1]
    full = lambda v: np.full(n, v)  # noqa: E731
    return jaxgrasp.Grasp(
        positions=d["pos"][i], normals=d["nrm"][i], initial_deformation=d["dr"][i],
        radius=full(FINGERTIP["radius"]), young_modulus=full(FINGERTIP["young_modulus"]),
        friction=full(FINGERTIP["friction"]), max_force=full(FINGERTIP["max_force"]),
        mass=d["mass"][i], gravity=d["gravity"][i],
    )


def evaluate(cands):
    """``{n: BatchResult}``, one :func:`jaxgrasp.evaluate_batch` per finger count."""
    import jaxgrasp

    res = {}
    for n, d in cands.items():
        t0 = time.perf_counter()
        res[n] = jaxgrasp.evaluate_batch([grasp_of(d, i) for i in range(len(d["dr"]))])
        log(f"N={n}: {len(d['dr'])} grasps evaluated in {time.perf_counter() - t0:.0f} s")
    return res


def counts(cands, res) -> dict:
    """Statuses of grasps and of programs, by finger count and kind."""
    out = {}
    for n, r in res.items():
        st = np.asarray(r.status)
        eq = np.asarray(r.equilibrium_status)
        bs = np.asarray(r.boundary_status)  # (B, 2, N): slip, force limit
        out[n] = dict(
            grasps=int(len(st)),
            status={s: int(np.sum(st == k)) for k, s in enumerate(STATUS)},
            programs=int(len(st) * (1 + 2 * n)),
            equilibrium={s: int(np.sum(eq == k)) for k, s in enumerate(LANE)},
            slip={s: int(np.sum(bs[:, 0] == k)) for k, s in enumerate(LANE)},
            force_limit={s: int(np.sum(bs[:, 1] == k)) for k, s in enumerate(LANE)},
            grasps_with_unsettled_program={
                "equilibrium": int(np.sum(eq == 2)),
                "slip": int(np.sum(np.any(bs[:, 0] == 2, axis=-1))),
                "force_limit": int(np.sum(np.any(bs[:, 1] == 2, axis=-1))),
            },
        )
    return out


def save_unsettled(path: Path, cands, res):
    """The grasps with any unsettled program (or status ``not_converged``), one file."""
    rows = collections.defaultdict(list)
    for n, r in res.items():
        st, eq, bs = np.asarray(r.status), np.asarray(r.equilibrium_status), np.asarray(r.boundary_status)
        bad = np.flatnonzero((st == 3) | (eq == 2) | np.any(bs == 2, axis=(1, 2)))
        for i in bad:
            rows[n].append(i)
    arrays = {}
    for n, idx in rows.items():
        d = cands[n]
        for k in ("pos", "nrm", "dr", "mass", "gravity", "object"):
            arrays[f"n{n}_{k}"] = d[k][idx]
        arrays[f"n{n}_index"] = np.asarray(idx)
        arrays[f"n{n}_value"] = np.asarray(res[n].value)[idx]
        arrays[f"n{n}_status"] = np.asarray(res[n].status)[idx]
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    return {n: [int(i) for i in idx] for n, idx in rows.items()}


def ipopt_sample(args, cands, unsettled, include=True):
    """The grasps checked against Ipopt, ``[(n, i)]``: every grasp of ``unsettled``
    (``{n: [i]}``), those listed in ``--include`` (a ``--unsettled`` file of an earlier
    run: the grasps that did not settle before a fix), and ``args.ipopt`` random others."""
    picked = {(n, i) for n, idx in unsettled.items() for i in idx}
    if include and args.include is not None:
        while not args.include.exists():  # an earlier run evaluating meanwhile
            time.sleep(10)
        z = np.load(args.include)
        picked |= {(n, int(i)) for n in (2, 3, 4) if f"n{n}_index" in z for i in z[f"n{n}_index"]}
    rng = np.random.default_rng(args.seed + 1)
    pool = [(n, i) for n, d in cands.items() for i in range(len(d["dr"]))]
    extra = rng.choice(len(pool), size=min(args.ipopt, len(pool)), replace=False)
    return sorted(picked | {pool[k] for k in extra})


def stored_references(args) -> dict:
    """``{(n, i): reference}`` from the JSON of an earlier run on the same candidates
    (``--reference``): its Ipopt statuses and values, not computed again."""
    if args.reference is None:
        return {}
    rows = json.loads(args.reference.read_text(encoding="utf-8"))["ipopt"]["rows"]
    return {(r["n"], r["index"]): dict(status=r["ipopt_status"], value=r["ipopt_value"]) for r in rows}


def submit_ipopt(args, cands, sample, pool, futures):
    """Start the Ipopt reference of each grasp of ``sample`` not yet in ``futures`` (a
    stored one, :func:`stored_references`, is taken as it is)."""
    from _lab import ipopt_reference

    stored = stored_references(args)
    for n, i in sample:
        if (n, i) in stored and (n, i) not in futures:
            futures[(n, i)] = concurrent.futures.Future()
            futures[(n, i)].set_result(stored[(n, i)])
        if (n, i) not in futures:
            futures[(n, i)] = pool.submit(ipopt_reference.reference_evaluate, grasp_of(cands[n], i).to_numpy(),
                                          n_starts=args.n_starts, seed=0)


def compare(cands, res, futures) -> list:
    """Each sampled grasp's jaxgrasp and Ipopt status and value."""
    rows = []
    for k, ((n, i), f) in enumerate(sorted(futures.items())):
        ref = f.result()
        js, jv = STATUS[int(res[n].status[i])], float(res[n].value[i])
        rs, rv = ref["status"], float(ref["value"])
        rel = (jv - rv) / rv if js == rs == "stable" and rv > 0 else float("nan")
        rows.append(dict(n=n, index=i, object=str(cands[n]["object"][i]), jax_status=js, jax_value=jv,
                         ipopt_status=rs, ipopt_value=rv, rel=rel,
                         mismatch=js != rs, above=bool(js == rs == "stable" and jv > rv * (1 + REL)),
                         below=bool(js == rs == "stable" and jv < rv * (1 - REL))))
        if (k + 1) % 10 == 0:
            log(f"Ipopt: {k + 1}/{len(futures)}")
    return rows


def evaluate_and_compare(args, cands):
    """``(results, counts, unsettled, comparisons, evaluate seconds)``; Ipopt runs in two
    worker processes while JAX evaluates."""
    ctx = multiprocessing.get_context("spawn")
    futures: dict = {}
    with concurrent.futures.ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
        if not args.no_ipopt:  # the random sample, while JAX evaluates
            submit_ipopt(args, cands, ipopt_sample(args, cands, {}, include=False), pool, futures)
        t0 = time.perf_counter()
        res = evaluate(cands)
        t_eval = time.perf_counter() - t0
        table = counts(cands, res)
        unsettled = save_unsettled(args.unsettled, cands, res)
        for n, c in table.items():
            log(f"N={n}: {c['status']}; unsettled programs: equilibrium {c['equilibrium']['not_converged']}, "
                f"slip {c['slip']['not_converged']}, force limit {c['force_limit']['not_converged']} "
                f"of {c['programs']}")
        if not args.no_ipopt:  # the --include file is read now: an earlier run may write it meanwhile
            submit_ipopt(args, cands, ipopt_sample(args, cands, unsettled), pool, futures)
        log(f"Ipopt on {len(futures)} grasps ({sum(map(len, unsettled.values()))} with an unsettled program now)")
        comps = compare(cands, res, futures)
    return res, table, unsettled, comps, t_eval


def main() -> int:
    args = parse_args()
    t0 = time.perf_counter()
    cands = cached_draw(args)
    t_draw = time.perf_counter() - t0
    log(f"drawn {sum(len(d['dr']) for d in cands.values())} valid candidates in {t_draw:.0f} s")
    if args.draw_only:
        return 0
    res, table, unsettled, comps, t_eval = evaluate_and_compare(args, cands)
    rels = [c["rel"] for c in comps if math.isfinite(c["rel"])]
    summary = dict(
        args={k: str(v) for k, v in vars(args).items()}, grasps=sum(c["grasps"] for c in table.values()),
        not_converged=sum(c["status"]["not_converged"] for c in table.values()),
        unsettled_programs=sum(c["equilibrium"]["not_converged"] + c["slip"]["not_converged"]
                               + c["force_limit"]["not_converged"] for c in table.values()),
        by_fingers={str(n): c for n, c in table.items()}, unsettled={str(n): v for n, v in unsettled.items()},
        ipopt=dict(checked=len(comps), mismatches=sum(c["mismatch"] for c in comps),
                   above=sum(c["above"] for c in comps), below=sum(c["below"] for c in comps),
                   max_abs_rel=max((abs(r) for r in rels), default=0.0), rows=comps),
        seconds=dict(draw=t_draw, evaluate=t_eval, total=time.perf_counter() - t0),
    )
    args.json.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    log(f"{summary['grasps']} grasps, {summary['not_converged']} not_converged, {summary['unsettled_programs']} "
        f"unsettled programs; Ipopt: {summary['ipopt']['checked']} checked, {summary['ipopt']['mismatches']} "
        f"status mismatches, {summary['ipopt']['above']} above, {summary['ipopt']['below']} below, "
        f"max |rel| {summary['ipopt']['max_abs_rel']:.2e}; wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
