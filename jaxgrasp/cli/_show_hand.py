"""``jaxgrasp show --hand FILE``: the picture of a hand's grasp (its links, the object, the
way it fails), from a hand grasp file (`jaxgrasp.hands._file`)."""

from __future__ import annotations

from jaxgrasp.cli._arguments import OVERRIDES
from jaxgrasp.cli._common import UsageError, write_picture
from jaxgrasp.model import FIELD

__all__ = ["run_hand"]


def run_hand(args, targets) -> int:
    """Evaluate the hand grasp of ``args.hand`` and write the picture (and the GLB) as one
    set (``targets``, checked by ``show``); one summary line."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.hands import load_hand_grasp
    from jaxgrasp.plots import hand_scene, plot_hand_grasp

    if args.file is not None or args.preset is not None:
        raise UsageError("give either a grasp FILE, --preset or --hand FILE, not more than one")
    _reject_overrides(args)
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


def _reject_overrides(args) -> None:
    """``--young-modulus`` etc. have no meaning with ``--hand``: the hand grasp file sets
    its fingertips (``[fingertip]``, their radius and squeeze from the hand's model and pose)
    and its object (``[object]``); a one-line `UsageError` naming those given."""
    given = [FIELD[name].option for name in OVERRIDES if getattr(args, name, None) is not None]
    if given:
        raise UsageError(f"{', '.join(given)}: not used with --hand; the hand grasp file {args.hand} sets its "
                         "fingertips ([fingertip], the radius and squeeze from the hand's model and pose) and "
                         "its object ([object]); edit the file instead")
