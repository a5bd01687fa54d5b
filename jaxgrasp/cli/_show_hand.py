"""``jaxgrasp show --hand FILE``: the picture of a hand's grasp (its links, the object, the
way it fails), from a hand grasp file (:mod:`jaxgrasp.hands._file`)."""

from __future__ import annotations

from jaxgrasp.cli._common import UsageError, write_picture

__all__ = ["run_hand"]


def run_hand(args, targets) -> int:
    """Evaluate the hand grasp of ``args.hand`` and write the picture (and the GLB) as one
    set (``targets``, checked by ``show``); one summary line."""
    from jaxgrasp.engine._evaluate import evaluate
    from jaxgrasp.hands._file import load_hand_grasp
    from jaxgrasp.plots._hand import hand_scene, plot_hand_grasp

    if args.file is not None or args.preset is not None:
        raise UsageError("give either a grasp FILE, --preset or --hand FILE, not more than one")
    hg = load_hand_grasp(args.hand, getattr(args, "allow_dir", None))
    if hg.status != "grasp":
        raise UsageError(f"{args.hand}: {hg.num_active} fingertip(s) touch the object; a grasp needs at least 2")
    result = evaluate(hg.grasp.compact())
    fig = plot_hand_grasp(hg, result=result, magnification=args.magnification)
    scene = hand_scene(hg, result, magnification=args.magnification)
    replaced = write_picture(targets, fig, scene)
    limit = f", limited by {scene.limiting_kind} of contact {scene.limiting_contact}" if scene.limiting_kind else ""
    print(f"show --hand {args.hand}: {scene.status}, value {scene.value:.6e} J{limit}, {hg.num_active} fingertips "
          f"in contact; wrote " + ", ".join(map(str, targets))
          + (f" (replacing the previous {', '.join(p.name for p in replaced)})" if replaced else ""))
    return 0
