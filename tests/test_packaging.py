"""Packaging: the version defined once, ``--version``, and the files a release carries.

Nothing here builds a wheel (that takes longer than the whole file should); the build
itself is checked by ``python -m build`` and ``twine check`` (see ``docs/development.md``).
These tests check what those read: ``pyproject.toml``, ``MANIFEST.in``, ``LICENSE``,
``CITATION.cff`` and ``CHANGELOG.md``.
"""

from __future__ import annotations

import fnmatch
import os
import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import jaxgrasp
import jaxgrasp.cli

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
VERSION = PYPROJECT["project"]["version"]

PAPER_AUTHORS = ["Tsuji", "Baba", "Tahara", "Harada", "Morooka", "Kurazume"]
PAPER_TITLE = "Grasp Stability Evaluation based on Energy Tolerance in Potential Field"


# ----------------------------------------------------------------------------- a small YAML reader
def _scalar(text: str):
    """A YAML scalar as written in CITATION.cff: a quoted or plain string."""
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
        return text[1:-1]
    return text


def parse_cff(text: str) -> dict:
    """The block-style YAML subset CITATION.cff uses: nested mappings, lists of scalars and
    lists of mappings, ``#`` comments, quoted strings. (PyYAML is not a test dependency.)

    Raises ``ValueError`` on a line this subset does not know, so a file that drifts into
    other YAML fails the test rather than parsing wrongly.
    """
    lines = []
    for raw in text.splitlines():
        stripped = raw.split(" #")[0].rstrip() if not raw.lstrip().startswith("#") else ""
        if stripped.strip():
            lines.append((len(stripped) - len(stripped.lstrip()), stripped.strip()))
    value, end = _block(lines, 0, 0)
    if end != len(lines):
        raise ValueError(f"unparsed line: {lines[end][1]!r}")
    return value


def _block(lines, i, indent):
    """The mapping or list whose lines start at ``lines[i]`` with ``indent``; and where it ends."""
    if lines[i][1].startswith("- "):
        out = []
        while i < len(lines) and lines[i][0] == indent and lines[i][1].startswith("- "):
            item = lines[i][1][2:]
            if re.match(r"^[\w-]+:", item):  # a mapping inside the list: its keys align with item
                lines[i] = (indent + 2, item)
                value, i = _block(lines, i, indent + 2)
                out.append(value)
            else:
                out.append(_scalar(item))
                i += 1
        return out, i
    out = {}
    while i < len(lines) and lines[i][0] == indent:
        match = re.match(r"^([\w-]+):(?:\s+(.*))?$", lines[i][1])
        if match is None:
            raise ValueError(f"not a key: {lines[i][1]!r}")
        key, rest = match.groups()
        i += 1
        if rest:
            out[key] = _scalar(rest)
        elif i < len(lines) and lines[i][0] > indent:
            out[key], i = _block(lines, i, lines[i][0])
        else:
            out[key] = None
    return out, i


def test_parse_cff_reads_nested_lists_and_refuses_other_yaml():
    cff = parse_cff("a: 1\nb:\n  - x\n  - 'y'\nc:\n  - name: n  # note\n    k: v\n  - name: m\n")
    assert cff == {"a": "1", "b": ["x", "y"], "c": [{"name": "n", "k": "v"}, {"name": "m"}]}
    with pytest.raises(ValueError):
        parse_cff("a: 1\n{flow: style}\n")


# ----------------------------------------------------------------------------- the version
def test_version_is_defined_once_and_read_everywhere():
    assert re.fullmatch(r"\d+\.\d+\.\d+", VERSION)
    assert jaxgrasp.__version__ == VERSION
    assert metadata.version("jaxgrasp") == VERSION
    assert jaxgrasp.cli.package_version() == VERSION
    init = (ROOT / "jaxgrasp" / "__init__.py").read_text(encoding="utf-8")
    assert f'"{VERSION}"' not in init  # not typed a second time


def test_cli_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        jaxgrasp.cli.main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"jaxgrasp {VERSION}"


@pytest.mark.slow
def test_python_dash_m_version_in_a_process():
    out = subprocess.run(
        [sys.executable, "-m", "jaxgrasp", "--version"],
        check=False, capture_output=True, text=True, timeout=120, env=dict(os.environ), cwd=ROOT,
    )
    assert (out.returncode, out.stdout.strip(), out.stderr) == (0, f"jaxgrasp {VERSION}", "")


# ----------------------------------------------------------------------------- the files
def test_license_is_mit_and_named_in_pyproject():
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License")
    assert "Copyright (c) 2026 the jaxgrasp developers" in text
    assert PYPROJECT["project"]["license"] == "MIT"
    assert "LICENSE" in PYPROJECT["project"]["license-files"]


def test_citation_names_the_software_and_the_paper():
    cff = parse_cff((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"].startswith("1.2")
    assert cff["type"] == "software" and cff["version"] == VERSION and cff["license"] == "MIT"
    paper = cff["preferred-citation"]
    assert paper["title"] == PAPER_TITLE
    assert [a["family-names"] for a in paper["authors"]] == PAPER_AUTHORS
    assert all(a["given-names"] for a in paper["authors"])


def test_changelog_describes_this_version():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert "Keep a Changelog" in text
    assert re.search(rf"^## \[?{re.escape(VERSION)}\]?", text, flags=re.MULTILINE)


def test_release_carries_types_examples_docs_and_licence():
    project = PYPROJECT["project"]
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["jaxgrasp"]
    assert (ROOT / "jaxgrasp" / "py.typed").is_file()
    assert "Typing :: Typed" in project["classifiers"] and project["keywords"]
    docs = " ".join(project["optional-dependencies"]["docs"])
    assert all(tool in docs for tool in ("mkdocs", "mkdocs-material", "mkdocstrings[python]"))
    manifest = (ROOT / "MANIFEST.in").read_text(encoding="utf-8")
    for line in ("include LICENSE", "recursive-include examples", "recursive-include docs"):
        assert line in manifest


def test_source_distribution_carries_every_example_doc_and_test_file():
    # The sdist takes from these folders only what MANIFEST.in's patterns name: a hand's
    # MJCF, a mesh or a licence notice left out would break the docs' commands from it.
    patterns = {}
    for line in (ROOT / "MANIFEST.in").read_text(encoding="utf-8").splitlines():
        words = line.split()
        if words[:1] == ["recursive-include"]:
            patterns[words[1]] = words[2:]
    missed = [
        str(f.relative_to(ROOT))
        for folder in ("examples", "docs", "tests")
        for f in sorted((ROOT / folder).rglob("*"))
        if f.is_file() and "__pycache__" not in f.parts and f.suffix != ".pyc"
        and not any(fnmatch.fnmatch(f.name, pat) for pat in patterns.get(folder, ()))
    ]
    assert not missed, f"MANIFEST.in leaves out {missed}"
