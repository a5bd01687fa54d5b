"""Hostile input to the command line: ``jaxgrasp evaluate FILE`` and its options.

``tests/model/test_inputs.py`` fuzzes ``grasp_from_dict``/``load``; this module fuzzes the whole
command, in-process (``jaxgrasp.cli.main`` with ``capsys``) and, for a few cases, as a
subprocess. The contract for every input:

* exit status 2 with exactly one line ``jaxgrasp: error: ...`` on stderr naming the
  problem and nothing on stdout; or
* exit status 0 with a valid result: a finite value ``>= 0``, a status name, a one-line
  explanation, and (``--json``) strict JSON without NaN or infinity;
* never a traceback, a hang, or a NaN presented as a value.

Files come from hypothesis: random bytes, and mutations of a valid 2-contact cube file
(wrong types, missing and unknown keys, NaN and infinity, huge and tiny numbers, empty
contact lists, two contacts at the same point, normals pointing inward or all parallel),
written as JSON or TOML. Most mutations make the file invalid (cheap); the few valid
ones are evaluated (one compiled evaluator for 2 contacts, shared with ``test_cli.py``).

Normals pointing inward (towards the centre of mass) are valid input: on a non-convex
object (a cavity, an inside grip) the outward surface normal can point anywhere, and
the model needs nothing else. They are evaluated, not rejected.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from conftest import without_compile_reports
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxgrasp

EXAMPLES = int(os.environ.get("JAXGRASP_FUZZ_EXAMPLES", "60"))


def base_doc() -> dict:
    return {
        "fingertip": {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15.0},
        "object": {"mass": 0.0, "gravity": [0.0, 0.0, -9.81]},
        "contacts": [
            {"position": [0.05, 0.0, 0.0], "normal": [1.0, 0.0, 0.0], "initial_deformation": 0.002},
            {"position": [-0.05, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "initial_deformation": 0.002},
        ],
    }


# ----------------------------------------------------------------------------- writers
def _toml_key(k) -> str:
    return json.dumps(str(k))


def _toml_value(v) -> str | None:
    """Inline TOML for any JSON-like value; ``None`` (no TOML null) -> dropped."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(x for x in (_toml_value(i) for i in v) if x is not None) + "]"
    if isinstance(v, dict):
        items = [(k, _toml_value(x)) for k, x in v.items()]
        return "{" + ", ".join(f"{_toml_key(k)} = {x}" for k, x in items if x is not None) + "}"
    return None


def to_toml(doc) -> str:
    if not isinstance(doc, dict):  # not representable as a TOML document: make it a key
        return f"value = {_toml_value(doc) or '0'}\n"
    lines = []
    for k, v in doc.items():
        x = _toml_value(v)
        if x is not None:
            lines.append(f"{_toml_key(k)} = {x}")
    return "\n".join(lines) + "\n"


def to_json(doc) -> str:
    return json.dumps(doc, allow_nan=True)  # NaN/Infinity tokens: Python's reader accepts them


# ----------------------------------------------------------------------------- strategies
HOSTILE_NUMBERS = st.sampled_from(
    [
        math.nan,
        math.inf,
        -math.inf,
        0.0,
        -0.0,
        5e-324,
        1e-308,
        1e-300,
        1e-30,
        1e-12,
        -1.0,
        1e30,
        1e300,
        1.7976931348623157e308,
        -1e300,
        10**400,
        2**64,
        -(2**63),
    ]
) | st.floats(allow_nan=True, allow_infinity=True)
NOT_NUMBERS = st.sampled_from([None, True, False, "0.5", "nan", "", [], {}, [1.0, 2.0], {"x": 1.0}, [[0.0, 0.0, 0.0]]])

NUMERIC_PATHS = [
    ("fingertip", "radius"),
    ("fingertip", "young_modulus"),
    ("fingertip", "friction"),
    ("fingertip", "max_force"),
    ("object", "mass"),
    ("object", "gravity", 0),
    ("object", "gravity", 2),
    ("contacts", 0, "position", 0),
    ("contacts", 1, "position", 1),
    ("contacts", 0, "normal", 0),
    ("contacts", 1, "normal", 2),
    ("contacts", 0, "initial_deformation"),
    ("contacts", 1, "initial_deformation"),
]
KEY_PATHS = [
    ("fingertip",),
    ("object",),
    ("contacts",),
    ("fingertip", "radius"),
    ("fingertip", "young_modulus"),
    ("object", "mass"),
    ("object", "gravity"),
    ("contacts", 0, "position"),
    ("contacts", 1, "normal"),
    ("contacts", 0, "initial_deformation"),
    ("object", "gravity", 1),
]
TABLE_PATHS = [(), ("fingertip",), ("object",), ("contacts", 0), ("contacts", 1)]


def _get(doc, path):
    for p in path:
        doc = doc[p]
    return doc


def _set(doc, path, value):
    _get(doc, path[:-1])[path[-1]] = value


@st.composite
def mutation(draw):
    """One edit of the document: (description, function doc -> None)."""
    kind = draw(
        st.sampled_from(
            ["number", "not_number", "delete", "unknown_key", "empty_contacts", "one_contact", "same_point",
             "inward", "parallel", "whole_value"]
        )
    )
    if kind == "number":
        path, v = draw(st.sampled_from(NUMERIC_PATHS)), draw(HOSTILE_NUMBERS)
        return f"{path}={v!r}", lambda d: _set(d, path, v)
    if kind == "not_number":
        path, v = draw(st.sampled_from(NUMERIC_PATHS + KEY_PATHS[3:])), draw(NOT_NUMBERS)
        return f"{path}={v!r}", lambda d: _set(d, path, v)
    if kind == "delete":
        path = draw(st.sampled_from(KEY_PATHS))

        def delete(d):
            parent = _get(d, path[:-1])
            if isinstance(parent, list):
                parent.pop(path[-1])
            else:
                parent.pop(path[-1], None)

        return f"delete {path}", delete
    if kind == "unknown_key":
        path = draw(st.sampled_from(TABLE_PATHS))
        key = draw(st.sampled_from(["Radius", "youngs_modulus", "normals", "extra", "", "mass "]) | st.text(max_size=5))
        return f"{path}+{key!r}", lambda d: _get(d, path).__setitem__(key, 1.0)
    if kind == "empty_contacts":
        return "contacts=[]", lambda d: d.__setitem__("contacts", [])
    if kind == "one_contact":
        return "one contact", lambda d: d["contacts"].pop()
    if kind == "same_point":
        return "same point", lambda d: d["contacts"][1].__setitem__("position", list(d["contacts"][0]["position"]))
    if kind == "inward":

        def inward(d):
            for c in d["contacts"]:
                c["normal"] = [-x for x in c["normal"]]

        return "inward normals", inward
    if kind == "parallel":
        return "parallel normals", lambda d: d["contacts"][1].__setitem__("normal", list(d["contacts"][0]["normal"]))
    v = draw(NOT_NUMBERS | HOSTILE_NUMBERS)  # the whole document is a bare value

    def whole(d):
        d.clear()
        d["__whole__"] = v

    return f"document={v!r}", whole


def build(edits):
    doc = base_doc()
    for _, f in edits:
        try:
            f(doc)
        except (KeyError, IndexError, TypeError, AttributeError):
            pass  # an earlier edit removed or replaced the target
    if "__whole__" in doc:
        return doc["__whole__"]
    return doc


# ----------------------------------------------------------------------------- running
WORK = Path(tempfile.mkdtemp(prefix="jaxgrasp-fuzz-"))
EVALUATED: list[tuple[str, str]] = []  # (status, description) of the fuzzed files evaluated (rc 0)
FUZZ_FILES: list[str] = []  # descriptions of every fuzzed file run


def check_outcome(rc, out, err, as_json, what):
    ctx = f"{what}\nrc={rc}\nstdout={out[-2000:]}\nstderr={err[-2000:]}"
    assert "Traceback" not in err and "Traceback" not in out, ctx
    assert rc in (0, 2), ctx
    if rc == 2:
        assert out == "", ctx
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxgrasp: error: "), ctx
        assert len(lines[0]) > len("jaxgrasp: error: ") + 5, ctx
        return None
    assert without_compile_reports(err) == "", ctx
    if as_json:
        d = json.loads(out, parse_constant=lambda c: pytest.fail(f"non-finite {c} in JSON: {ctx}"))
        value, status, expl = d["value"], d["status"], d["explanation"]
        for k in ("equilibrium_energy",):
            assert d[k] is None or math.isfinite(d[k]), ctx
    else:
        fields = dict(line.split(": ", 1) for line in out.splitlines() if ": " in line and not line.startswith(" "))
        value = float(fields["value"].split()[0])
        status, expl = fields["status"], fields["explanation"]
        assert "nan" not in fields["equilibrium energy"].lower(), ctx
    assert math.isfinite(value) and value >= 0.0, ctx
    assert status in jaxgrasp.GraspStatus.labels(), ctx
    assert isinstance(expl, str) and expl and "\n" not in expl, ctx
    assert expl.startswith(status.replace("_", " ")), ctx
    return status


_FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=os.environ.get("JAXGRASP_PROPERTY_RANDOM", "") == "",
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large],
)


@_FUZZ
@given(st.binary(max_size=300), st.sampled_from([".toml", ".json"]), st.booleans())
def test_fuzz_random_bytes(run_cli, raw, ext, as_json):
    p = WORK / f"bytes{ext}"
    p.write_bytes(raw)
    rc, out, err = run_cli(["evaluate", p] + (["--json"] if as_json else []))
    check_outcome(rc, out, err, as_json, f"bytes {raw!r}")
    if rc == 2:
        assert str(p) in err


@_FUZZ
@given(st.lists(mutation(), min_size=1, max_size=3), st.sampled_from(["json", "toml"]), st.booleans())
def test_fuzz_grasp_file(run_cli, edits, fmt, as_json):
    doc = build(edits)
    text = to_json(doc) if fmt == "json" else to_toml(doc)
    p = WORK / f"grasp.{fmt}"
    p.write_text(text, encoding="utf-8")
    what = f"edits {[e[0] for e in edits]} -> {fmt}:\n{text}"
    rc, out, err = run_cli(["evaluate", p] + (["--json"] if as_json else []))
    status = check_outcome(rc, out, err, as_json, what)
    FUZZ_FILES.append(what)
    if rc == 0:
        EVALUATED.append((status, what))


def test_fuzz_grasp_file_reaches_evaluation(run_cli):
    """The fuzzed files are not all rejected: a share of them is valid and goes through a
    whole evaluation (the contract's rc-0 branch is exercised), with more than one status.

    Measured on the derandomized default run: 15 of 60 files evaluated, 9 stable, 5
    unstable, 1 infeasible (selected alone, this test runs the fuzz test first)."""
    if not FUZZ_FILES:  # selected on its own: run the fuzz test (the same derandomized files)
        test_fuzz_grasp_file(run_cli)
    statuses = sorted({s for s, _ in EVALUATED})
    report = f"{len(EVALUATED)} of {len(FUZZ_FILES)} fuzzed files evaluated, statuses {statuses}"
    assert len(EVALUATED) >= max(3, len(FUZZ_FILES) // 10), report
    assert "stable" in statuses and len(statuses) >= 2, report


OPTION_VALUES = st.sampled_from(
    ["nan", "inf", "-inf", "1e400", "1e-400", "0", "-0", "1e300", "1e-300", "-1", "abc", "", "0x10", "1_000", "2e5", "0.004"]
) | st.floats(allow_nan=True, allow_infinity=True).map(repr)


@_FUZZ
@given(
    st.sampled_from(["--young-modulus", "--initial-deformation", "--mass", "--friction", "--max-force", "--radius"]),
    OPTION_VALUES,
)
def test_fuzz_overrides(run_cli, option, value):
    rc, out, err = run_cli(["evaluate", "--preset", "cube", f"{option}={value}", "--json"])
    check_outcome(rc, out, err, True, f"{option}={value}")


@pytest.mark.parametrize(
    "edit, fragment",
    [
        (lambda d: d.__setitem__("contacts", []), "contacts is empty"),
        (lambda d: d["contacts"][1].__setitem__("position", [0.05, 0.0, 0.0]), "same position"),
        (lambda d: d["fingertip"].__setitem__("young_modulus", math.nan), "young_modulus"),
        (lambda d: d["object"].__setitem__("mass", -math.inf), "mass = -inf kg must be finite"),
        (lambda d: d["contacts"][0].__setitem__("initial_deformation", 1e300), "initial_deformation"),
        (lambda d: d["contacts"][0].pop("normal"), "missing key 'normal'"),
        (lambda d: d["fingertip"].__setitem__("youngs_modulus", 2e5), "unknown key 'youngs_modulus'"),
        (lambda d: d["fingertip"].__setitem__("friction", True), "boolean"),
        (lambda d: d["contacts"][0].__setitem__("normal", [0.0, 0.0, 0.0]), "non-zero"),
        # absurdly heavy object: beyond the documented load range since issue 40
        (lambda d: d["object"].__setitem__("mass", 1e300), "times the fingertips' initial squeeze"),
    ],
    ids=["empty", "same-point", "nan", "minus-inf-mass", "huge-dr", "missing", "unknown", "bool", "zero-normal",
         "mass-1e300"],
)
@pytest.mark.parametrize("fmt", ["json", "toml"])
def test_named_errors(run_cli, tmp_path, edit, fragment, fmt):
    doc = base_doc()
    edit(doc)
    p = tmp_path / f"g.{fmt}"
    p.write_text(to_json(doc) if fmt == "json" else to_toml(doc), encoding="utf-8")
    rc, out, err = run_cli(["evaluate", p])
    check_outcome(rc, out, err, False, fragment)
    assert rc == 2 and fragment in err, err


@pytest.mark.parametrize(
    "edit, status",
    [
        # inside grip: valid input, mirror image of the outside grip
        (lambda d: [c.__setitem__("normal", [-x for x in c["normal"]]) for c in d["contacts"]], "stable"),
        # both tips push the same way: they let go
        (lambda d: d["contacts"][1].__setitem__("normal", [1.0, 0.0, 0.0]), "unstable"),
        # absurdly stiff fingertips: the initial squeeze is far above the force limit
        (lambda d: d["fingertip"].__setitem__("young_modulus", 1e300), "infeasible"),
        # stiff fingertips with force limits to match: an ordinary, scaled grasp
        (lambda d: d["fingertip"].update(young_modulus=1e300, max_force=1.5e301), "stable"),
    ],
    ids=["inward-normals", "parallel-normals", "E-1e300", "E-and-fmax-1e300"],
)
def test_hostile_but_valid(run_cli, tmp_path, edit, status):
    doc = base_doc()
    edit(doc)
    p = tmp_path / "g.json"
    p.write_text(to_json(doc), encoding="utf-8")
    for as_json in (True, False):
        rc, out, err = run_cli(["evaluate", p] + (["--json"] if as_json else []))
        assert check_outcome(rc, out, err, as_json, str(doc)) == status


@pytest.mark.parametrize("as_json", [True, False], ids=["json", "text"])
@pytest.mark.parametrize("dr", [1e-300, 1e-52])
def test_tiny_deformation_is_a_one_line_error(run_cli, tmp_path, as_json, dr):
    """E dr^3 below 1e-150 J (here 2e5 Pa x dr^3: 0 after underflow, or 2e-151 J): exit
    status 2 and the one-line error naming the 1e-150 J threshold, never a traceback."""
    doc = base_doc()
    for c in doc["contacts"]:
        c["initial_deformation"] = dr
    p = tmp_path / "g.json"
    p.write_text(to_json(doc), encoding="utf-8")
    try:
        rc, out, err = run_cli(["evaluate", p] + (["--json"] if as_json else []))
    except Exception as exc:  # the traceback a user would see
        pytest.fail(f"main raised {type(exc).__name__}: {exc}")
    check_outcome(rc, out, err, as_json, f"initial_deformation {dr}")
    assert rc == 2 and "contact 0: young_modulus * initial_deformation^3" in err, err
    assert "below 1e-150 J, too small to evaluate" in err, err


def _console():
    script = Path(sys.executable).with_name("jaxgrasp")
    return [str(script)] if script.exists() else [sys.executable, "-m", "jaxgrasp.cli"]


@pytest.mark.slow  # subprocesses
@pytest.mark.parametrize(
    "content, name, fragment",
    [
        (b"\xff\xfe\x00garbage", "g.toml", "not valid UTF-8"),
        (
            b'{"fingertip": {"radius": 0.025, "young_modulus": 2e5, "friction": 0.5, "max_force": 15},'
            b' "contacts": [{"position": [NaN, 0, 0], "normal": [1, 0, 0], "initial_deformation": 0.002},'
            b' {"position": [-0.05, 0, 0], "normal": [-1, 0, 0], "initial_deformation": 0.002}]}',
            "g.json",
            "positions[0] = [nan, 0, 0] m must be finite",
        ),
        (b"contacts = []\n", "g.toml", "contacts is empty"),
        (b"[[contacts]]\nposition = [1e999, 0, 0]\n", "g.toml", "contacts[0]"),
    ],
    ids=["bytes", "nan-json", "empty-contacts", "overflow-toml"],
)
def test_subprocess_errors(tmp_path, content, name, fragment):
    p = tmp_path / name
    p.write_bytes(content)
    proc = subprocess.run(_console() + ["evaluate", str(p)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("jaxgrasp")]
    assert len(lines) == 1 and lines[0].startswith("jaxgrasp: error: "), proc.stderr
    assert fragment in lines[0], lines[0]
