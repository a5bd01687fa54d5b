"""``jaxgrasp show FILE`` for a hand grasp file (or ``show --hand FILE``): the picture of a
hand's grasp (its links, the object, the way it fails), from a hand grasp file
(`jaxgrasp.hands._file`). Contact ``k`` is fingertip ``k`` in the labels, the title and the
summary line, named by its fingertip (`jaxgrasp.cli._hand_files`)."""

from __future__ import annotations

from jaxgrasp.cli._common import UsageError, write_picture
from jaxgrasp.cli._hand_files import load_hand

__all__ = ["run_hand"]


def run_hand(args, targets, path: str) -> int:
    """Evaluate the hand grasp of the file ``path`` (``FILE`` or ``--hand FILE``) and write the
    picture (and the GLB) as one set (``targets``, checked by ``show``); one summary line."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.plots import hand_scene, plot_hand_grasp

    if args.preset is not None or (args.hand is not None and args.file is not None):
        raise UsageError("give either a grasp FILE, --preset or --hand FILE, not more than one")
    hg = load_hand(args, path)
    result = evaluate(hg.grasp)  # masked, not compacted: contact k is fingertip k
    fig = plot_hand_grasp(hg, result=result, magnification=args.magnification)
    scene = hand_scene(hg, result, magnification=args.magnification)
    replaced = write_picture(targets, fig, scene)
    limit = (f", limited by {scene.limiting_kind} of {scene.label(scene.limiting_contact)}"
             if scene.limiting_kind else "")
    source = path if args.hand is None else f"--hand {path}"
    print(f"show {source}: {scene.status}, value {scene.value:.6e} J{limit}, {hg.num_active} fingertips "
          f"in contact; wrote " + ", ".join(map(str, targets))
          + (f" (replacing the previous {', '.join(p.name for p in replaced)})" if replaced else ""))
    return 0
