"""``jaxgrasp evaluate``: evaluate one grasp; print a summary or a JSON object."""

from __future__ import annotations

import json

from jaxgrasp.cli._common import (
    add_grasp_source,
    add_overrides,
    announce_large_grasp,
    grasp_notes,
    grasp_source,
    load_grasp,
)

__all__ = ["add_parser", "run", "format_summary"]


def add_parser(sub) -> None:
    """Add the ``evaluate`` command to the ``jaxgrasp`` sub-parsers."""
    p = sub.add_parser("evaluate", help="evaluate one grasp and print a summary")
    add_grasp_source(p)
    add_overrides(p)
    p.add_argument("--json", action="store_true", help="print a JSON object instead")
    p.set_defaults(func=run)


def run(args) -> int:
    """Evaluate the grasp of the command line and print the result; exit status 0."""
    from jaxgrasp.analysis._epsilon import epsilon, prefetch_qhull
    from jaxgrasp.engine._evaluate import evaluate

    prefetch_qhull()  # SciPy's import overlaps the evaluation's compile or cache load

    grasp = load_grasp(args)
    announce_large_grasp(grasp.num_contacts, grasp_source(args))
    d = evaluate(grasp).to_dict()
    eps = epsilon(grasp)  # the Ferrari-Canny metric on the same contacts, beside the value
    d["epsilon"] = float(eps.value)
    d["force_closure"] = bool(eps.force_closure)
    notes = grasp_notes(grasp)
    if notes:  # otherwise Evaluation.to_dict() with epsilon and force_closure
        d["notes"] = notes
    if args.json:
        print(json.dumps(d, indent=2, allow_nan=False))
    else:
        print(format_summary(d, grasp_source(args)))
    return 0


def format_summary(d: dict, source: str) -> str:
    """The human-readable summary of an evaluation (``Evaluation.to_dict()``, with
    ``epsilon`` and ``force_closure`` where given) of ``source``."""
    lines = [f"grasp: {source}"]
    lines.append(f"status: {d['status']}")
    if d.get("explanation"):
        lines.append(f"explanation: {d['explanation']}")
    lines += [f"note: {note}" for note in d.get("notes", [])]
    lines.append(f"value: {d['value']:.6e} J   (least energy that makes a fingertip slip or overload)")
    lim = d["limiting"]
    if lim is not None:
        lines.append(f"limiting boundary: {lim['kind']} of contact {lim['contact']}")
    if "epsilon" in d:  # the command adds it; Evaluation.to_dict() alone has none
        closure = "force closure" if d["force_closure"] else "not force closure"
        lines.append(f"epsilon: {d['epsilon']:.6e}   (Ferrari-Canny, 8 cone edges, soft fingers; {closure})")
    lines.append(f"equilibrium energy: {d['equilibrium_energy']:.6e} J")
    t = ", ".join(f"{v:.3e}" for v in d["equilibrium_translation"])
    w = ", ".join(f"{v:.3e}" for v in d["equilibrium_rotation"])
    lines.append(f"equilibrium pose: translation ({t}) m, rotation ({w}) rad")
    lines.append("boundaries (energy above equilibrium, J):")
    for b in d["boundaries"]:
        if b["energy"] is None:
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: not reachable ({b['status']})")
        else:
            de = b["energy_above_equilibrium"]
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: {de:.6e} J ({b['status']})")
    return "\n".join(lines)
