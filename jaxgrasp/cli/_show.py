"""``jaxgrasp show``: a 3-D picture of one grasp and the way it fails (and a GLB of the scene)."""

from __future__ import annotations

import math
from pathlib import Path

from jaxgrasp.cli._common import (
    UsageError,
    add_grasp_source,
    add_overrides,
    announce_large_grasp,
    grasp_source,
    load_grasp,
    write_picture,
)
from jaxgrasp import storage

__all__ = ["add_parser", "run", "PICTURE_SUFFIXES", "MAGNIFICATION_RANGE"]

PICTURE_SUFFIXES = (".png", ".pdf", ".svg")
"""The picture formats ``--out`` may name."""

MAGNIFICATION_RANGE = (1e-3, 1e12)
"""The ``--magnification`` factors ``show`` accepts, inclusive. Below 1e-3 the ghost cannot
be told from the object at any picture size; above 1e12 the motion drawn is float64's
rounding of the pose (about 1e-16 of the object's size) magnified into view, not the
motion, and factors near 1e300 overflow the coordinates to infinity."""


def add_parser(sub) -> None:
    """Add the ``show`` command to the ``jaxgrasp`` sub-parsers."""
    p = sub.add_parser(
        "show",
        help="draw one grasp in 3-D with the motion that makes it fail (png; --glb for a 3-D viewer)",
        description=(
            "Evaluate one grasp and draw it in 3-D: the object (its mesh, or the contacts' hull), "
            "each fingertip pressed into its contact with its normal and friction cone, the limiting "
            "contact in red, and the object at the least-energy pose of the limiting boundary as a "
            "ghost, the motion magnified by the factor the title states. --glb writes the same "
            "scene as a GLB file for any 3-D viewer."
        ),
    )
    add_grasp_source(p)
    add_overrides(p)
    p.add_argument("--out", default="grasp.png", metavar="FILE", help="the picture, .png, .pdf or .svg (default grasp.png)")
    p.add_argument("--glb", metavar="FILE", help="also write the scene as a GLB file (.glb)")
    p.add_argument("--magnification", type=float, metavar="X",
                   help=(f"factor the ghost's motion is magnified by, {MAGNIFICATION_RANGE[0]:g} to "
                         f"{MAGNIFICATION_RANGE[1]:g} (default: a round one that makes it visible)"))
    p.add_argument("--hand", metavar="FILE",
                   help=("draw a hand's grasp instead: a hand grasp file (.toml, see docs/guide/hands.md), which "
                         "sets the fingertips and the object (no --young-modulus etc. with it)"))
    p.set_defaults(func=run)


def run(args) -> int:
    """Evaluate the grasp, write the picture (and the GLB) as one set; one summary line."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.plots import draw_scene, grasp_scene

    targets = _check_outputs(args)
    if getattr(args, "hand", None) is not None:
        from jaxgrasp.cli._show_hand import run_hand

        return run_hand(args, targets)
    grasp = load_grasp(args, keep_mesh=True)
    plain = grasp.grasp if isinstance(grasp, MeshGrasp) else grasp
    announce_large_grasp(plain.num_contacts, grasp_source(args))
    result = evaluate(plain)
    scene = grasp_scene(grasp, result, magnification=args.magnification)
    replaced = write_picture(targets, draw_scene(scene), scene)
    limit = (f", limited by {scene.limiting_kind} of contact {scene.limiting_contact} (ghost motion "
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
