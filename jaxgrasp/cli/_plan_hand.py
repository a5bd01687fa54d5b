"""``jaxgrasp plan MESH --hand HAND --fingertips A,B,C --out DIR``: the best grasps a robot
hand can make on a meshed object ([`jaxgrasp.plan`][jaxgrasp.plan] with ``hand=``).

Everything is checked before the plan starts (the options, the mesh, the hand and its
fingertips, ``DIR`` writable and locked), so that bad input creates nothing. The set written
into ``DIR`` (`jaxgrasp.storage.write_set`, all or none) is self-contained:

* ``best.toml``: the best grasp as a hand grasp file (`jaxgrasp.hands._file`): the hand's
  model (copied into ``DIR/hand/``), its fingertips, ``qpos`` and ``wrist``; the object's
  mesh (copied beside it), units, pose and mass (kg); the fingertips' fields.
  ``jaxgrasp evaluate DIR/best.toml`` gives the value of ``results.csv``'s first row;
* ``ranked.jsonl``: the ranked grasps, best first, one JSON object per line (the columns
  of ``results.csv`` with ``qpos``, rad or m, and ``wrist``: translation m, rotation vector
  rad, the hand's model frame in the mesh's);
* ``results.csv``: `HAND_RESULT_COLUMNS` (rank, ``value_J``, status, fingertips in contact,
  the deepest link's penetration in mm, the deepest overlap of two of the hand's own
  links in mm, epsilon, refined);
* ``best.png``: the ``jaxgrasp show`` picture of the best grasp;
* ``dexgraspbench/``: the ranked grasps in DexGraspBench's input format (``0.npy`` ...,
  `jaxgrasp.hands.save_dexgraspbench`) with the object at ``dexgraspbench/OBJECT/mesh/simplified.obj``
  in metres, as that benchmark reads it (written as a second set once the first is in place).

A hand grasp file records no gravity (gravity is ``-z`` of the world at 9.81 m/s^2), so
``--gravity`` is refused with ``--hand`` where it differs from that.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

from jaxgrasp.cli._common import UsageError, check_out, lock_out, replaced_text, say

__all__ = ["run_hand", "MAX_HAND_FOLDER_BYTES"]

MAX_HAND_FOLDER_BYTES = 64 * 2**20
"""The most bytes of a hand's folder ``plan --hand`` copies into its output (the model and its
meshes); a larger folder is refused before planning."""

_FREE_ONLY = (("fingers", "--fingers"), ("radius", "--radius"), ("sampler", "--sampler"),
              ("flatness", "--flatness"), ("robust", "--robust"))


def run_hand(args) -> int:
    """Check every option, the mesh and the hand, create and lock ``--out``, plan, write the
    set, print one summary line."""
    from jaxgrasp.planning import PlanProgress, check_hand_plan, plan

    out = Path(args.out)
    _refuse_free_options(args)
    kwargs = _hand_options(args)
    hand = _read_hand(args)
    check_hand_plan(args.mesh, hand, **kwargs)  # bad input: one line, nothing created or printed
    folder = _hand_folder(args, hand)  # the copy best.toml will name, checked to load to the same hand
    check_out(out)
    if not args.quiet:
        say(f"jaxgrasp: plan {args.mesh} with the hand {args.hand} ({len(hand.fingertip_names)} fingertips, "
            f"{hand.num_joints} joints): {kwargs['samples']} candidates to close onto the object and evaluate, "
            "the best refined; compiling (or loading from the cache) first")
    with lock_out(out):
        t0 = time.perf_counter()
        res = plan(args.mesh, hand=hand, progress=PlanProgress(t0, show=not args.quiet), **kwargs)
        written, replaced = _write(res, out, args, folder)
    print(f"plan {args.mesh} --hand {args.hand}: {res.summary()}; wrote {out}/{{{','.join(written)}}}"
          + replaced_text(replaced, ()))
    return 0


def _refuse_free_options(args) -> None:
    """The options of free fingertips have no meaning with a hand: one line naming them."""
    given = [opt for name, opt in _FREE_ONLY if getattr(args, name, None) is not None]
    if args.rank != "value":
        given.append("--rank")
    if given:
        raise UsageError(f"{', '.join(given)}: not used with --hand (the hand's fingertips are its own; "
                         "rank with --objective value|epsilon)")
    if args.fingertips is None:
        raise UsageError("--hand needs --fingertips A,B,C: the hand's fingertip geoms, bodies or links")


def _hand_options(args) -> dict:
    """The keyword arguments of [`jaxgrasp.plan`][jaxgrasp.plan] with a hand (mesh and hand aside)."""
    from jaxgrasp.cli._arguments import plan_fields
    from jaxgrasp.model import DEFAULT_GRAVITY

    fields = plan_fields(args)
    fields.pop("radius")
    if [float(g) for g in fields["gravity"]] != [float(g) for g in DEFAULT_GRAVITY]:
        raise UsageError(f"--gravity {args.gravity}: a hand grasp file records no gravity (it is -z at 9.81 "
                         "m/s^2), so best.toml could not be evaluated as planned; turn the mesh instead")
    from jaxgrasp.planning import HAND_SAMPLES

    given = lambda v, default: default if v is None else v  # noqa: E731
    return dict(samples=given(args.samples, HAND_SAMPLES), top=args.top, refine=args.refine, seed=args.seed,
                min_fingertips=given(args.min_fingertips, 2), objective=given(args.objective, "value"),
                max_penetration=given(args.max_penetration, 1e-3), **fields)


def _read_hand(args):
    """The [`Hand`][jaxgrasp.Hand] of ``--hand`` with ``--fingertips`` (its errors one line)."""
    from jaxgrasp.hands import Hand

    return Hand.from_file(args.hand, _tips(args))


def _tips(args) -> list[str]:
    """The names of ``--fingertips``, at least two."""
    tips = [t.strip() for t in args.fingertips.split(",") if t.strip()]
    if len(tips) < 2:
        raise UsageError(f"--fingertips {args.fingertips!r}: name at least two, separated by commas")
    return tips


def _hand_folder(args, hand) -> dict[str, bytes]:
    """The files of the hand's folder (relative name -> bytes), to copy into ``DIR/hand/``:
    every regular file under it (symbolic links and ``--out`` left out), at most
    `MAX_HAND_FOLDER_BYTES`; a `UsageError` if the copy does not load to the same hand."""
    from jaxgrasp.hands import Hand
    from jaxgrasp.model import GraspValueError

    root = Path(args.hand).resolve().parent
    skip = Path(args.out).resolve()
    files, total = {}, 0
    for here, dirs, names in os.walk(root):
        dirs[:] = [d for d in dirs if not os.path.islink(os.path.join(here, d)) and Path(here, d).resolve() != skip]
        for name in names:
            path = Path(here, name)
            if path.is_symlink() or not path.is_file():
                continue
            total += path.stat().st_size
            if total > MAX_HAND_FOLDER_BYTES:
                raise UsageError(f"--hand {args.hand}: its folder {str(root)!r} holds more than "
                                 f"{MAX_HAND_FOLDER_BYTES >> 20} MiB, too much to copy beside best.toml; put the "
                                 "model and the meshes it names in a folder of their own")
            files[str(path.relative_to(root))] = path.read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        for name, raw in files.items():
            Path(tmp, name).parent.mkdir(parents=True, exist_ok=True)
            Path(tmp, name).write_bytes(raw)
        try:
            same = Hand.from_file(Path(tmp, Path(args.hand).resolve().name), _tips(args)).digest() == hand.digest()
        except GraspValueError:  # the copy misses a file the model names (one behind a link)
            same = False
    if not same:
        raise UsageError(f"--hand {args.hand}: a copy of its folder {str(root)!r} reads as another hand (a "
                         "symbolic link in it?); put the model and the meshes it names in a folder of their own")
    return files


def _write(res, out: Path, args, folder: dict[str, bytes]) -> tuple[list[str], list[str]]:
    """Write the set into ``out`` (then the DexGraspBench files); the names written and those
    that replaced previous files."""
    from jaxgrasp import storage
    from jaxgrasp.hands import save_dexgraspbench
    from jaxgrasp.io import copied_mesh
    from jaxgrasp.planning import HAND_RESULT_COLUMNS

    if not res.grasps:
        raise UsageError(f"plan {args.mesh} --hand {args.hand}: {res.status.message}; nothing written")
    name, raw = copied_mesh(args.mesh, out)
    model = f"hand/{Path(args.hand).resolve().name}"
    ranked = res.to_dict()["ranked"]
    members = {out / "hand" / n: b for n, b in folder.items()}
    members.update({
        out / "best.toml": _best_toml(res, args, model, name).encode("utf-8"),
        out / "ranked.jsonl": "".join(json.dumps(r) + "\n" for r in ranked).encode("utf-8"),
        out / "results.csv": storage.csv_content(HAND_RESULT_COLUMNS, ([r[c] for c in HAND_RESULT_COLUMNS]
                                                                       for r in res.rows())),
        out / "dexgraspbench" / Path(name).stem / "mesh" / "simplified.obj": _obj_in_metres(res.best.mesh),
    })
    if raw is not None:
        members[out / name] = raw
    if not args.no_plot:
        members[out / "best.png"] = _picture(res)
    for path in members:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        replaced = storage.write_set(members)
        save_dexgraspbench(out / "dexgraspbench", list(res.grasps), obj_path=Path(name).stem, hand=res.best.hand)
    except OSError as exc:
        raise UsageError(f"cannot write to --out {str(out)!r}: {exc.strerror or exc}") from None
    top = [p.relative_to(out).parts[0] for p in members]
    return sorted(set(top)), [p.name for p in replaced]


def _best_toml(res, args, model: str, mesh: str) -> str:
    """The hand grasp file of the best grasp: the hand copied at ``model``, the mesh at ``mesh``
    (both relative to ``DIR``), the object's units, pose (the mesh frame is the world's) and
    mass (kg: ``--mass``, or ``--density`` times the mesh's volume), the fingertips' fields."""
    from jaxgrasp.hands import hand_grasp_toml

    s = res.settings
    return hand_grasp_toml({
        "hand": {"model": model, "fingertips": _tips(args), "qpos": res.qpos[0], "wrist": res.wrist[0]},
        "object": {"mesh": mesh, "units": args.units, "pose": [0.0] * 6, "mass": float(s["mass"])},
        "fingertip": {k: float(s[k]) for k in ("young_modulus", "friction", "max_force")},
    })


def _obj_in_metres(mesh) -> bytes:
    """The object (a ``trimesh.Trimesh`` in metres) as Wavefront OBJ text."""
    import trimesh.exchange.obj

    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False).encode("utf-8")


def _picture(res):
    """``write(fh)`` of the best grasp's ``show --hand`` picture."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.plots import plot_hand_grasp, save_figure

    fig = plot_hand_grasp(res.best, result=evaluate(res.best.grasp))
    return lambda fh: save_figure(fig, fh, format="png")
