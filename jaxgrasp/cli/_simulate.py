"""``jaxgrasp simulate``: the grasp in MuJoCo (``jaxgrasp[sim]``): results.json and a plot."""

from __future__ import annotations

import json
from pathlib import Path

from jaxgrasp.cli._arguments import parse_number
from jaxgrasp.cli._common import UsageError, check_out, grasp_source, load_grasp, lock_out, replaced_text, say
from jaxgrasp import storage
from jaxgrasp.simulation import check_options

__all__ = ["OPTION_NAMES", "PLOT", "RESULTS", "run"]

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
    opts = _options(args)
    grasp = load_grasp(args, keep_mesh=True)
    plain = grasp.grasp if isinstance(grasp, MeshGrasp) else grasp
    source = grasp_source(args)
    say(f"jaxgrasp: simulate {source}: evaluating (compiling the evaluator or loading it from the cache)")
    evaluation = evaluate(plain)
    say(f"jaxgrasp: simulate {source}: {evaluation.status_name}, value {float(evaluation.value):.6e} J; "
        "running MuJoCo (hold, six axes, kicks)")
    result = simulate(grasp, evaluation=evaluation, **opts)
    members = {out / RESULTS: (json.dumps(result.to_dict(), indent=1) + "\n").encode()}
    if result.simulated:
        members[out / PLOT] = _plot_bytes(result)
    with lock_out(out):
        replaced = storage.write_set(members, remove=[] if result.simulated else [out / PLOT])
    print(_summary(source, result) + f"; wrote {', '.join(str(p) for p in members)}"
          + replaced_text([p.name for p in replaced], []))
    return 0


def _plot_bytes(result) -> bytes:
    import io

    from jaxgrasp.plots import plot_trials, save_figure

    buf = io.BytesIO()
    save_figure(plot_trials(result), buf, format="png")
    return buf.getvalue()


def _summary(source: str, result) -> str:
    if not result.simulated:
        return f"simulate {source}: {result.status_name}, not simulated ({result.reason})"
    line = (f"simulate {source}: value {result.value:.6e} J; hold {result.hold.outcome()} "
            f"({1e3 * result.hold.max_displacement_m:.3g} mm)")
    if result.six_axis:
        line += f"; six-axis {sum(t.success for t in result.six_axis)}/6 held"
    if result.kicks:
        slipped = sum(k.outcome() == "failed" for k in result.kicks)
        line += f"; kicks with a slip {slipped}/{len(result.kicks)}"
    if result.diverged:  # never counted as held: said first-hand
        line += f"; diverged: {result.reason}"
    return line
