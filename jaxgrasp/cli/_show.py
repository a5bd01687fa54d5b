"""``jaxgrasp show``: a 3-D picture of one grasp and the way it fails (and a GLB of the scene)."""

from __future__ import annotations

import math
from pathlib import Path

from jaxgrasp.cli._arguments import MAGNIFICATION_RANGE
from jaxgrasp.cli._common import UsageError, announce_large_grasp, grasp_source, load_grasp, write_picture
from jaxgrasp.cli._hand_files import is_hand_file
from jaxgrasp import storage

__all__ = ["run", "PICTURE_SUFFIXES", "MAGNIFICATION_RANGE"]

PICTURE_SUFFIXES = (".png", ".pdf", ".svg")
"""The picture formats ``--out`` may name."""


def run(args) -> int:
    """Evaluate the grasp, write the picture (and the GLB) as one set; one summary line."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.plots import draw_scene, grasp_scene

    targets = _check_outputs(args)
    hand = getattr(args, "hand", None)
    if hand is not None or is_hand_file(args):  # FILE a hand grasp file draws as --hand FILE does
        from jaxgrasp.cli._show_hand import run_hand

        return run_hand(args, targets, args.file if hand is None else hand)
    grasp = load_grasp(args, keep_mesh=True)
    plain = grasp.grasp if isinstance(grasp, MeshGrasp) else grasp
    announce_large_grasp(plain.num_contacts, grasp_source(args))
    result = evaluate(plain)
    scene = grasp_scene(grasp, result, magnification=args.magnification)
    replaced = write_picture(targets, draw_scene(scene), scene)
    limit = (f", limited by {scene.limiting_kind} of {scene.label(scene.limiting_contact)} (ghost motion "
             f"x{scene.magnification:g})" if scene.limiting_kind else "")
    print(
        f"show {grasp_source(args)}: {scene.status}, value {scene.value:.6e} J{limit}; wrote "
        + ", ".join(map(str, targets))
        + (f" (replacing the previous {', '.join(p.name for p in replaced)})" if replaced else "")
    )
    return 0


def _check_outputs(args) -> list[Path]:
    """The picture and GLB paths, checked before any computation (suffix, writable folder)."""
    m = args.magnification
    lo, hi = MAGNIFICATION_RANGE
    if m is not None and not (math.isfinite(m) and lo <= m <= hi):
        raise UsageError(f"--magnification must be a number from {lo:g} to {hi:g}, got {m:g}")
    targets = [("--out", Path(args.out), PICTURE_SUFFIXES)]
    if args.glb is not None:
        targets.append(("--glb", Path(args.glb), (".glb",)))
    for option, path, suffixes in targets:
        if path.suffix.lower() not in suffixes:
            raise UsageError(f"{option} {str(path)!r}: the file must end in {' or '.join(suffixes)}")
        if path.is_dir():
            raise UsageError(f"{option} {str(path)!r} is a folder; give a file name")
        try:
            storage.check_writable(path.parent)  # creates nothing
        except storage.OutputError as exc:
            raise UsageError(f"{option} {str(path)!r}: {exc}") from None
    if len(targets) > 1 and targets[0][1].resolve() == targets[1][1].resolve():
        raise UsageError("--out and --glb name the same file")
    return [path for _, path, _ in targets]
