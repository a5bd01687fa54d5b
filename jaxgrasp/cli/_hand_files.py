"""Hand grasp files on the command line: every command that takes a grasp file takes a
hand grasp file (a ``.toml`` with a ``[hand]`` table, `jaxgrasp.hands._file`) too.

A hand grasp file sets its fingertips' fields (``[fingertip]``) and its object (``[object]``),
so the field overrides (``--young-modulus`` ...) are refused with it. Its contacts are
numbered by fingertip, in the order ``fingertips`` lists them, in every output
(`jaxgrasp.hands._batch`, "One numbering").
"""

from __future__ import annotations

from jaxgrasp.cli._arguments import OVERRIDES
from jaxgrasp.cli._common import UsageError
from jaxgrasp.model import FIELD

__all__ = ["is_hand_file", "load_hand", "reject_overrides", "hand_fields"]


def is_hand_file(args) -> bool:
    """Whether the command's input ``FILE`` is a hand grasp file."""
    if getattr(args, "file", None) is None:  # a preset: no module to import before the first line
        return False
    from jaxgrasp.hands import is_hand_grasp_file

    return is_hand_grasp_file(args.file)


def load_hand(args, path: str | None = None):
    """The [`HandGrasp`][jaxgrasp.hands.HandGrasp] of the hand grasp file ``path`` (default the
    command's ``FILE``), with at least 2 fingertips in contact; the overrides refused."""
    from jaxgrasp.hands import load_hand_grasp

    path = args.file if path is None else path
    reject_overrides(args, path)
    hg = load_hand_grasp(path, getattr(args, "allow_dir", None))
    if hg.status != "grasp":
        raise UsageError(f"{path}: {hg.num_active} fingertip(s) touch the object; a grasp needs at least 2")
    return hg


def reject_overrides(args, path: str) -> None:
    """``--young-modulus`` etc. have no meaning with a hand grasp file: it sets its
    fingertips (``[fingertip]``, their radius and squeeze from the hand's model and pose)
    and its object (``[object]``); a one-line `UsageError` naming those given."""
    given = [FIELD[name].option for name in OVERRIDES if getattr(args, name, None) is not None]
    if given:
        raise UsageError(f"{', '.join(given)}: not used with a hand grasp file; {path} sets its fingertips "
                         "([fingertip], the radius and squeeze from the hand's model and pose) and its object "
                         "([object]); edit the file instead")


def hand_fields(hg) -> dict:
    """What a hand grasp's output adds to its evaluation: ``fingertips`` (names, in the
    order that numbers the contacts), ``in_contact`` (bool each), ``dr_m`` (the initial
    deformation, m; ``None`` where not in contact) and ``tilt_deg``."""
    import numpy as np

    active = np.asarray(hg.active, dtype=bool)
    dr = np.asarray(hg.grasp.initial_deformation, dtype=np.float64)
    return {
        "fingertips": list(hg.hand.fingertip_names),
        "in_contact": active.tolist(),
        "dr_m": [float(d) if a else None for d, a in zip(dr, active)],
        "tilt_deg": np.degrees(np.asarray(hg.tilt, dtype=np.float64)).tolist(),
    }
