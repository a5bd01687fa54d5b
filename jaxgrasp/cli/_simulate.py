"""``jaxgrasp simulate``: the grasp in MuJoCo (``jaxgrasp[sim]``): results.json and a plot.

``--protocol dexgraspbench`` (a hand grasp file only): the whole hand in MuJoCo
(`jaxgrasp.simulation._hand_simulate`); ``--friction MU`` is then the protocol's sliding
friction (the grasp's own friction has no part in it), the other field overrides are
refused as for any hand grasp file, and ``--timestep``, ``--sim-friction`` and
``--simulate-unstable`` (the jaxgrasp protocol's) are refused; the trial durations and
kicks are the jaxgrasp protocol's and not used. ``results.json`` is the result's
``to_dict()`` (its per-fingertip lists one entry per fingertip, ``null`` where not in
contact) with ``hand`` (`jaxgrasp.cli._hand_files.hand_fields`); the picture shows each
push's displacement and rotation.

Under the jaxgrasp protocol a hand grasp file is simulated as its contacts (each fingertip a fixed sphere, as for any
grasp; the hand's links are not in the simulation). The simulator numbers only the
contacts it simulates, the fingertips in contact; ``results.json`` numbers them by
fingertip (contact ``k`` is fingertip ``k``, `jaxgrasp.cli._hand_files`), ``null`` for a
fingertip not in contact, with the fingertips' names in ``hand``.
"""

from __future__ import annotations

import json
from pathlib import Path

from jaxgrasp.cli._arguments import parse_number
from jaxgrasp.cli._common import UsageError, check_out, grasp_source, load_grasp, lock_out, replaced_text, say
from jaxgrasp.cli._hand_files import hand_fields, is_hand_file, load_hand
from jaxgrasp import storage
from jaxgrasp.simulation import check_options

__all__ = ["OPTION_NAMES", "PLOT", "RESULTS", "run", "by_fingertip"]

RESULTS = "results.json"
"""The results file in ``--out``."""

PLOT = "trials.png"
"""The plot of displacement and rotation over time per trial in ``--out``."""


OPTION_NAMES = {
    "hold_time_s": "--hold-time", "six_axis_time_s": "--six-axis-time", "kick_time_s": "--kick-time",
    "kick_scales": "--scales", "random_kicks": "--random-kicks", "friction": "--sim-friction", "timestep": "--timestep",
}
"""The options of [`jaxgrasp.simulate`][jaxgrasp.simulate] this command sets, by their parameter's name."""


def _options(args) -> dict:
    """The options for [`jaxgrasp.simulate`][jaxgrasp.simulate], checked by the simulation's own rules
    (`check_options`) under their option names."""
    opts = {k: parse_number(OPTION_NAMES[k], getattr(args, k[:-2]), "time")
            for k in ("hold_time_s", "six_axis_time_s", "kick_time_s")}
    opts["kick_scales"] = list(args.scales)  # parsed and bounded by the parser (`jaxgrasp.cli._arguments`)
    opts["random_kicks"] = args.random_kicks
    if args.sim_friction is not None:
        opts["friction"] = parse_number("--sim-friction", args.sim_friction, "friction")
    if args.timestep is not None:
        opts["timestep"] = parse_number("--timestep", args.timestep, "timestep")
    check_options(**opts, names=OPTION_NAMES)
    return opts | {"simulate_unstable": args.simulate_unstable}


def _protocol(args) -> str:
    """``--protocol``, checked with the options it refuses (module notes)."""
    from jaxgrasp.simulation import PROTOCOLS

    if args.protocol not in PROTOCOLS:
        raise UsageError(f"--protocol must be one of {', '.join(PROTOCOLS)}, got {args.protocol!r}")
    if args.protocol == "dexgraspbench":
        given = [o for o, v in (("--timestep", args.timestep), ("--sim-friction", args.sim_friction),
                                ("--simulate-unstable", args.simulate_unstable or None)) if v is not None]
        if given:
            raise UsageError(f"{given[0]}: an option of --protocol jaxgrasp; with dexgraspbench the protocol's "
                             "settings hold (--friction MU sets its friction)")
        if not is_hand_file(args):
            raise UsageError(f"--protocol dexgraspbench simulates a hand: {grasp_source(args)} is not a hand grasp "
                             "file")
    return args.protocol


def _run_hand(args, out: Path) -> int:
    """``--protocol dexgraspbench``: the hand grasp file's whole hand in MuJoCo."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.simulation import simulate

    import math

    friction, args.friction = args.friction, None  # the protocol's friction, not the grasp's field
    if friction is not None and not (math.isfinite(friction) and friction > 0):
        raise UsageError(f"--friction must be finite and > 0, got {friction:g}")
    hand = load_hand(args)
    source = grasp_source(args)
    say(f"jaxgrasp: simulate {source}: evaluating (compiling the evaluator or loading it from the cache)")
    evaluation = evaluate(hand.grasp)
    say(f"jaxgrasp: simulate {source}: {evaluation.status_name}, value {float(evaluation.value):.6e} J; running "
        "MuJoCo (the whole hand, DexGraspBench's protocol)")
    result = simulate(hand, protocol="dexgraspbench", evaluation=evaluation, friction=friction,
                      allowed_dirs=getattr(args, "allow_dir", None))
    d = {**result.to_dict(), "hand": hand_fields(hand)}
    members = {out / RESULTS: (json.dumps(d, indent=1, allow_nan=False) + "\n").encode()}
    if result.six_axis:
        members[out / PLOT] = _plot_bytes(result)
    with lock_out(out):
        replaced = storage.write_set(members, remove=[] if result.six_axis else [out / PLOT])
    print(_hand_summary(source, result) + f"; wrote {', '.join(str(p) for p in members)}"
          + replaced_text([p.name for p in replaced], []))
    return 0


def _hand_summary(source: str, result) -> str:
    import numpy as np

    line = f"simulate {source} (dexgraspbench): {'success' if result.success else 'failure'}"
    if result.six_axis:
        line += f", {sum(t.success for t in result.six_axis)}/6 pushes held"
        err = np.abs(result.normal_force_error)
        if np.any(np.isfinite(err)):
            line += f"; settled normal forces within {100 * np.nanmax(err):.2g} % of eq. 4"
    return line if result.simulated else f"{line} ({result.reason})"


def run(args) -> int:
    """Check the options and the output folder, evaluate, simulate, write results.json and
    the plot as one set."""
    from jaxgrasp.engine import evaluate
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.simulation import load_mujoco, simulate

    try:
        load_mujoco()
    except ImportError as exc:
        raise UsageError(str(exc)) from None
    out = Path(args.out)
    check_out(out)
    if _protocol(args) == "dexgraspbench":
        return _run_hand(args, out)
    opts = _options(args)
    hand = load_hand(args) if is_hand_file(args) else None
    grasp = hand.mesh_grasp() if hand is not None else load_grasp(args, keep_mesh=True)
    plain = grasp.grasp if isinstance(grasp, MeshGrasp) else grasp  # a hand's masked: contact k is fingertip k
    source = grasp_source(args)
    say(f"jaxgrasp: simulate {source}: evaluating (compiling the evaluator or loading it from the cache)")
    evaluation = evaluate(plain)
    say(f"jaxgrasp: simulate {source}: {evaluation.status_name}, value {float(evaluation.value):.6e} J; "
        "running MuJoCo (hold, six axes, kicks)")
    result = simulate(grasp, evaluation=evaluation, **opts)
    d = result.to_dict() if hand is None else by_fingertip(result.to_dict(), hand, evaluation)
    members = {out / RESULTS: (json.dumps(d, indent=1) + "\n").encode()}
    if result.simulated:
        members[out / PLOT] = _plot_bytes(result)
    with lock_out(out):
        replaced = storage.write_set(members, remove=[] if result.simulated else [out / PLOT])
    print(_summary(source, result, d.get("limiting")) + f"; wrote {', '.join(str(p) for p in members)}"
          + replaced_text([p.name for p in replaced], []))
    return 0


_PER_CONTACT = ("settled_normal_force_N", "model_normal_force_N")
_PER_CONTACT_PARAMETERS = ("contact_surfaces", "friction_sliding", "friction_torsional_m", "stiffness_N_m",
                           "spring_offset_m", "damping_N_s_m", "initial_deformation_m", "initial_normal_force_N",
                           "equilibrium_deformation_m", "slip_threshold_m")


def by_fingertip(d: dict, hand, evaluation) -> dict:
    """``results.json`` (``SimulationResult.to_dict()``) of a hand's grasp, numbered by
    fingertip: the simulator's contact ``i`` (the ``i``-th fingertip in contact) becomes
    fingertip ``k``'s entry of lists of one per fingertip (``None`` where not in contact),
    a trial's ``slipped_contact`` ``k`` with ``slipped_fingertip`` its name; added:
    ``limiting`` (the ``evaluation``'s limiting boundary: ``kind``, ``contact`` = fingertip
    number, ``fingertip`` its name; ``None`` without one) and ``hand``
    (`jaxgrasp.cli._hand_files.hand_fields`)."""
    import numpy as np

    h = hand_fields(hand)
    tips = np.flatnonzero(h["in_contact"])  # simulated contact i is fingertip tips[i]

    def spread(values):
        if values is None or len(values) != len(tips):
            return values  # not per contact (never expected: said rather than renumbered wrongly)
        out = [None] * len(h["fingertips"])
        for i, v in zip(tips, values):
            out[i] = v
        return out

    def trial(t):
        if t is None:
            return None
        k = t["slipped_contact"]
        t = {**t, "max_sliding_m": spread(t["max_sliding_m"]),
             "slipped_contact": None if k is None else int(tips[k])}
        t["slipped_fingertip"] = None if k is None else h["fingertips"][int(tips[k])]
        return t

    d = {**d, **{key: spread(d[key]) for key in _PER_CONTACT}, "hold": trial(d["hold"]),
         "six_axis": [trial(t) for t in d["six_axis"]], "kicks": [trial(t) for t in d["kicks"]]}
    d["parameters"] = {k: spread(v) if k in _PER_CONTACT_PARAMETERS else v for k, v in d["parameters"].items()}
    lim = evaluation.to_dict()["limiting"]  # the masked grasp's: its contact is the fingertip's number
    d["limiting"] = None if lim is None else {**lim, "fingertip": h["fingertips"][lim["contact"]]}
    d["hand"] = h
    return d


def _plot_bytes(result) -> bytes:
    import io

    from jaxgrasp.plots import plot_trials, save_figure

    buf = io.BytesIO()
    save_figure(plot_trials(result), buf, format="png")
    return buf.getvalue()


def _summary(source: str, result, limiting: dict | None = None) -> str:
    """One line; ``limiting`` (a hand's: kind, contact, fingertip) named after the value."""
    if not result.simulated:
        return f"simulate {source}: {result.status_name}, not simulated ({result.reason})"
    lim = f" (limited by {limiting['kind']} of contact {limiting['contact']} ({limiting['fingertip']}))" if limiting else ""
    line = (f"simulate {source}: value {result.value:.6e} J{lim}; hold {result.hold.outcome()} "
            f"({1e3 * result.hold.max_displacement_m:.3g} mm)")
    if result.six_axis:
        line += f"; six-axis {sum(t.success for t in result.six_axis)}/6 held"
    if result.kicks:
        slipped = sum(k.outcome() == "failed" for k in result.kicks)
        line += f"; kicks with a slip {slipped}/{len(result.kicks)}"
    if result.diverged:  # never counted as held: said first-hand
        line += f"; diverged: {result.reason}"
    return line
