"""``jaxgrasp batch`` of hand configurations: a hand grasp file of one or many
configurations, or a dataset of the field (``--format``) with the hand, its fingertips, the
object's mesh and the fingertips' fields on the command line.

Either way the configurations become a [`HandBatch`][jaxgrasp.hands.HandBatch] (`jaxgrasp.hands._batch`):
its grasps go through the batch's one path (checkpoints, ``--resume``, ranking, the output
set) and its columns (``active``, ``in_contact``, ``dr_k``, ``tilt_k``, contact ``k`` being
fingertip ``k`` of ``--fingertips``) are added to ``results.csv`` and ``results.npz``.
"""

from __future__ import annotations

import hashlib
import os
import time

from jaxgrasp.cli._arguments import HAND_DATA_DEFAULTS
from jaxgrasp.cli._common import UsageError, say
from jaxgrasp.cli._hand_files import is_hand_file

__all__ = ["hand_input", "load_hand_data"]

_DATA_OPTIONS = ("hand", "fingertips", "mesh", "young_modulus", "friction", "max_force", "mass", "density")


def hand_input(args) -> bool:
    """Whether the command's input is hand configurations (``--format``, or ``FILE`` a hand
    grasp file); the options that go with it checked (one-line `UsageError`)."""
    given = [f"--{n.replace('_', '-')}" for n in _DATA_OPTIONS if getattr(args, n, None) is not None]
    if args.format is None:
        if given:
            raise UsageError(f"{', '.join(given)}: only with --format (a dataset of hand configurations); "
                             "a grasp dataset or a hand grasp file names its own")
        return is_hand_file(args)
    missing = [o for o, v in (("--hand", args.hand), ("--fingertips", args.fingertips)) if v is None]
    if args.format == "dexgraspnet" and args.mesh is None:
        missing.append("--mesh")
    if missing:
        raise UsageError(f"--format {args.format} needs {', '.join(missing)}")
    if getattr(args, "num_processes", None):
        raise UsageError("--num-processes: not available for hand configurations yet; run one process")
    return True


def _fingertips(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",")]
    if len(names) < 2 or not all(names):
        raise UsageError(f"--fingertips {text!r}: give at least 2 comma-separated geom names, such as a_tip,b_tip")
    return names


def _reporter(quiet: bool):
    """``progress(done, total)`` of the fingertips' placement on stderr, at most a line a second."""
    if quiet:
        return None
    last = [0.0]

    def report(done: int, total: int) -> None:
        now = time.monotonic()
        if now - last[0] >= 1.0 or done == total:
            say(f"jaxgrasp: batch: placing the fingertips of {done}/{total} configurations")
            last[0] = now

    return report


def load_hand_data(args):
    """The [`HandBatch`][jaxgrasp.hands.HandBatch] of the command's input (`hand_input`)."""
    from jaxgrasp.hands import Hand, hand_batch, load_hand_batch

    progress = _reporter(args.quiet)
    if args.format is None:
        return load_hand_batch(args.file, args.allow_dir, progress=progress)
    from jaxgrasp.hands import read_dexgraspbench, read_dexgraspnet

    hand = Hand.from_file(args.hand, _fingertips(args.fingertips), args.allow_dir)
    reader = {"dexgraspnet": read_dexgraspnet, "dexgraspbench": read_dexgraspbench}[args.format]
    poses = reader(args.file, hand)
    meshes, objects = _meshes(args, poses)
    fields = {k: HAND_DATA_DEFAULTS[k] if getattr(args, k) is None else getattr(args, k)
              for k in ("young_modulus", "friction", "max_force")}
    key = hashlib.sha256("\n".join([_sources_sha256(poses.sources), hand.digest(), repr(sorted(fields.items())),
                                    repr((args.mass, args.density, args.units, [str(m) for m in meshes]))]).encode())
    return hand_batch(hand, meshes if objects is not None else meshes[0], poses.qpos, wrist=poses.wrist,
                      object_pose=poses.object_pose, scale=poses.scale, objects=objects, units=args.units,
                      mass=args.mass, density=args.density, progress=progress, source=str(args.file),
                      source_sha256=key.hexdigest(), **fields)


def _meshes(args, poses) -> tuple[list, object]:
    """``(meshes, objects)``: ``[--mesh]`` and ``None``, or (DexGraspBench without ``--mesh``)
    the mesh of each ``obj_path`` (``obj_path/mesh/simplified.obj``, a relative one from the
    working folder, where DexGraspBench runs; within it or an ``--allow-dir``) and each row's index."""
    import numpy as np

    from jaxgrasp.hands import DEXGRASPBENCH_MESH
    from jaxgrasp.io import allowed_folders, confine

    if args.mesh is not None:
        return [args.mesh], None
    names = sorted(set(poses.objects))
    allowed = allowed_folders(args.allow_dir)
    meshes = [confine(os.path.join(n, DEXGRASPBENCH_MESH), os.getcwd(), allowed, "working folder") for n in names]
    return meshes, np.searchsorted(names, poses.objects)


def _sources_sha256(sources) -> str:
    """SHA-256 (hex) of the bytes of the files ``sources`` name (``PATH`` or ``PATH#row``), each once."""
    from jaxgrasp.io import MAX_GRASP_FILE_BYTES, read_input

    h = hashlib.sha256()
    for path in dict.fromkeys(str(s).rsplit("#", 1)[0] for s in sources):
        h.update(read_input(path, 64 * MAX_GRASP_FILE_BYTES, "hand dataset"))
    return h.hexdigest()
