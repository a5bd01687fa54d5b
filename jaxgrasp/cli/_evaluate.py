"""``jaxgrasp evaluate``: evaluate one grasp; print a summary or a JSON object."""

from __future__ import annotations

import json

from jaxgrasp.cli._common import (
    UsageError,
    announce_large_grasp,
    check_chunk_size,
    grasp_notes,
    grasp_source,
    load_grasp,
    robust_uncertainty,
)
from jaxgrasp.cli._hand_files import hand_fields, is_hand_file, load_hand

__all__ = ["run", "format_summary"]


def run(args) -> int:
    """Evaluate the grasp of the command line and print the result; exit status 0."""
    from jaxgrasp.analysis import epsilon, prefetch_qhull
    from jaxgrasp.engine import evaluate

    prefetch_qhull()  # SciPy's import overlaps the evaluation's compile or cache load

    check_chunk_size(args.chunk_size)
    uncertainty = robust_uncertainty(args)  # a bad spec is reported before anything is loaded
    hand = load_hand(args) if is_hand_file(args) else None
    if hand is not None and uncertainty is not None:
        raise UsageError(f"--robust: not available for a hand grasp file ({args.file}) yet")
    loaded = hand.grasp if hand is not None else load_grasp(args, keep_mesh=uncertainty is not None)
    grasp = getattr(loaded, "grasp", loaded)
    announce_large_grasp(grasp.num_contacts, grasp_source(args))
    d = evaluate(grasp).to_dict()
    if hand is not None:  # contact k is fingertip k (jaxgrasp.cli._hand_files)
        d["hand"] = hand_fields(hand)
    eps = epsilon(grasp)  # the Ferrari-Canny metric on the same contacts, beside the value
    d["epsilon"] = float(eps.value)
    d["force_closure"] = bool(eps.force_closure)
    notes = grasp_notes(grasp)
    if notes:  # otherwise Evaluation.to_dict() with epsilon and force_closure
        d["notes"] = notes
    if uncertainty is not None:
        d.update(_robust_fields(loaded, uncertainty, args))
    if args.json:
        print(json.dumps(d, indent=2, allow_nan=False))
    else:
        print(format_summary(d, grasp_source(args)))
    return 0


def _robust_fields(grasp, uncertainty, args) -> dict:
    """The ``--robust`` fields: ``p_stable``, ``p_stable_stderr``, ``value_mean``, one
    ``value_qNN`` per quantile, and ``robust`` (status, samples, seed, spreads, clip counts)."""
    from jaxgrasp.analysis import robust

    r = robust(grasp, uncertainty, samples=args.samples, seed=args.seed, chunk_size=args.chunk_size).to_dict()
    stats = ("p_stable", "p_stable_stderr", "value_mean")
    out = {k: v for k, v in r.items() if k in stats or k.startswith("value_q")}
    out["robust"] = {k: v for k, v in r.items() if k not in out}
    return out


def format_summary(d: dict, source: str) -> str:
    """The human-readable summary of an evaluation (``Evaluation.to_dict()``, with
    ``epsilon`` and ``force_closure`` where given) of ``source``."""
    lines = [f"grasp: {source}"]
    lines.append(f"status: {d['status']}")
    if d.get("explanation"):
        lines.append(f"explanation: {d['explanation']}")
    lines += [f"note: {note}" for note in d.get("notes", [])]
    if "hand" in d:
        lines.append("fingertips (contact k is fingertip k): " + _fingertip_text(d["hand"]))
    lines.append(f"value: {d['value']:.6e} J   (least energy that makes a fingertip slip or overload)")
    lim = d["limiting"]
    if lim is not None:
        tip = f" ({d['hand']['fingertips'][lim['contact']]})" if "hand" in d else ""
        lines.append(f"limiting boundary: {lim['kind']} of contact {lim['contact']}{tip}")
    if "epsilon" in d:  # the command adds it; Evaluation.to_dict() alone has none
        closure = "force closure" if d["force_closure"] else "not force closure"
        lines.append(f"epsilon: {d['epsilon']:.6e}   (Ferrari-Canny, 8 cone edges, soft fingers; {closure})")
    if "p_stable" in d:
        lines += _robust_lines(d)
    lines.append(f"equilibrium energy: {d['equilibrium_energy']:.6e} J")
    t = ", ".join(f"{v:.3e}" for v in d["equilibrium_translation"])
    w = ", ".join(f"{v:.3e}" for v in d["equilibrium_rotation"])
    lines.append(f"equilibrium pose: translation ({t}) m, rotation ({w}) rad")
    lines.append("boundaries (energy above equilibrium, J):")
    touching = d["hand"]["in_contact"] if "hand" in d else None
    for b in d["boundaries"]:
        if touching is not None and not touching[b["contact"]]:
            continue  # a fingertip not in contact has no boundary; the fingertips line says so
        if b["energy"] is None:
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: not reachable ({b['status']})")
        else:
            de = b["energy_above_equilibrium"]
            lines.append(f"  contact {b['contact']} {b['kind']:<9}: {de:.6e} J ({b['status']})")
    return "\n".join(lines)


def _fingertip_text(h: dict) -> str:
    """``0 robot0:C_ffdistal (dr 1.2 mm, tilt 12 deg), 1 ... (not in contact)``."""
    parts = []
    for k, (name, on, dr, tilt) in enumerate(zip(h["fingertips"], h["in_contact"], h["dr_m"], h["tilt_deg"])):
        parts.append(f"{k} {name} " + (f"(dr {1e3 * dr:.3g} mm, tilt {tilt:.0f} deg)" if on else "(not in contact)"))
    return ", ".join(parts)


def _robust_lines(d: dict) -> list[str]:
    """The summary's lines of the ``--robust`` fields."""
    r = d["robust"]
    num = lambda x, f: "n/a" if x is None else format(x, f)  # noqa: E731
    quantiles = ", ".join(f"{k[len('value_'):]} {num(v, '.6e')} J" for k, v in d.items() if k.startswith("value_q"))
    spec = ",".join(f"{k}={v!r}" for k, v in r["uncertainty"].items() if v) or "none"
    clipped = sum(r["clipped"].values())
    lines = [
        f"robust: {spec}; {r['samples']} samples, seed {r['seed']} ({r['robust_status']}, {r['converged']} settled)",
        f"  p_stable: {num(d['p_stable'], '.4f')} +- {num(d['p_stable_stderr'], '.4f')} (standard error)",
        f"  value mean: {num(d['value_mean'], '.6e')} J; quantiles: {quantiles}",
    ]
    if clipped:
        lines.append(f"  clipped into the valid range: {', '.join(f'{k} {v}' for k, v in r['clipped'].items() if v)}")
    return lines
