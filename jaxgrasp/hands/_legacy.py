"""MJCF that MuJoCo refuses, explained in one line: the element, where it is written, and the fix.

Hand files written for MuJoCo 2 often fail to compile in MuJoCo 3 and later: an attribute
removed (``<option apirate>``, removed in MuJoCo 3), an actuator or sensor naming a joint
the file no longer has (DexGraspNet's Shadow hand drops the wrist joints but keeps their
actuators and sensors). MuJoCo names one problem at a time, with a line number of the text
it was given (includes expanded), in its own words. `explain` turns the refusals it
recognises into one line naming the element as written, its file and line, and the edit
that fixes it, followed by the other elements that name missing joints (so one reading
gives every edit); any other refusal is left to MuJoCo's words.
"""

from __future__ import annotations

import re

__all__ = ["explain"]

_REMOVED = {("option", "apirate"): "MuJoCo 3 removed the attribute apirate"}
_ATTRIBUTE = re.compile(r"unrecognized attribute: '([^']+)'.*?Element '([^']+)'")
_JOINT_TARGET = re.compile(r"unknown transmission target '([^']+)'|unrecognized name '([^']+)' of sensorized object")
_RENAMING = ("replicate", "attach", "composite", "flexcomp")  # elements that make names: references not checkable


def explain(message: str, source, version: str) -> str | None:
    """One line for MuJoCo's refusal ``message`` of the checked hand file ``source``
    (`jaxgrasp.hands._mjcf_files.HandSource`, MJCF) compiled by MuJoCo ``version``, or
    ``None`` where it is not one `explain` recognises (module notes)."""
    if source.kind != "mjcf":
        return None
    dangling = _dangling(source.root)
    attribute = _ATTRIBUTE.search(message)
    if attribute:
        attr, tag = attribute.groups()
        el = next((e for e in source.root.iter(tag) if attr in e.attrib), None)
        if el is None:
            return None
        why = _REMOVED.get((tag, attr), f"MuJoCo {version} has no attribute {attr} on <{tag}> (removed or misspelt)")
        return f"{_where(source, el, attr)}: {why}; delete it" + _also(source, dangling, "then delete the")
    target = _JOINT_TARGET.search(message)
    if target and dangling:
        el, kind, joint = dangling[0]
        return (f"{_where(source, el, 'name')} names joint {joint!r}, which the model does not have; delete the {kind}"
                + _also(source, dangling[1:], "and the other"))
    return None


def _where(source, el, attr: str) -> str:
    """``<option apirate="200"> (line 3)``: the element with one attribute, where written."""
    value = el.get(attr)
    shown = f'<{el.tag} {attr}="{value[:60]}">' if value is not None else f"<{el.tag}>"
    file, line = source.lines.get(el, (None, None))
    if line is None:
        return shown
    main = next(iter(source.lines.values()))[0]
    return f"{shown} ({'' if file == main else f'{file} '}line {line})"


def _also(source, dangling: list, lead: str) -> str:
    """``; and the other 3 elements that name joints the model does not have (lines ...)``."""
    if not dangling:
        return ""
    lines = ", ".join(str(source.lines.get(el, ("", "?"))[1]) for el, _, _ in dangling[:12])
    more = ", ..." if len(dangling) > 12 else ""
    n = len(dangling)
    what = "element that names a joint" if n == 1 else f"{n} elements that name joints"
    return f"; {lead} {what} the model does not have (line{'s' if n > 1 else ''} {lines}{more})"


def _dangling(root) -> list:
    """``[(element, "actuator" | "sensor" | "tendon" | "equality", joint)]``: the elements
    that name a joint no body has (none where names are made by replicates and the like)."""
    if any(next(root.iter(tag), None) is not None for tag in _RENAMING):
        return []
    joints = {j.get("name") for body in root.iter("body") for j in body if j.tag in ("joint", "freejoint")}
    out = []
    for section, kind, keys in (("actuator", "actuator", ("joint",)), ("sensor", "sensor", ("joint",)),
                                ("equality", "equality", ("joint1", "joint2"))):
        for group in root.iter(section):
            out += [(el, kind, el.get(k)) for el in group for k in keys if el.get(k) and el.get(k) not in joints]
    for tendon in root.iter("tendon"):
        out += [(j, "tendon's joint", j.get("joint")) for fixed in tendon for j in fixed
                if j.tag == "joint" and j.get("joint") not in joints]
    return out
