"""The README and the docs site (``docs/``) cannot rot: their code runs here.

Every fenced block in ``README.md`` and ``docs/**/*.md`` has a language. ``python`` blocks
of a page run in order in one namespace, in this process (so they reuse what the rest of
the session compiled); ``bash``/``shell`` blocks run with ``bash -e -o pipefail`` in a
subprocess. Both run in a temporary folder per page that holds a copy of ``examples/``,
with ``JAXGRASP_CACHE_DIR`` set to the session's cache folder (``store_dir`` in
``tests/conftest.py``), so a shell block's ``jaxgrasp`` command loads what an earlier
block or test compiled. Blocks in other languages (``text`` for output and citations,
``toml``/``json`` for file contents) are not code.

A runnable block that must not run here (an install into a fresh virtual environment, the
test suite itself, a script that takes minutes, several hosts) is preceded by the line
``<!-- docs-test: skip (why) -->``; :data:`MAX_SKIPS` keeps those few.

Besides running the blocks: the API reference lists every name in ``jaxgrasp.__all__``,
the README stays small and free of history, the statuses tables name every status, and
every page is in the site's navigation.
"""

from __future__ import annotations

import dataclasses
import importlib
import logging
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import jaxgrasp

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]

RUN = {"python": "python", "bash": "shell", "shell": "shell"}
"""Fence languages that are run, and how."""
INERT = {"text", "toml", "json"}
"""Fence languages that are shown, not run: output, citations, file contents."""
SKIP_MARKER = "<!-- docs-test: skip"
MAX_SKIPS = 15  # 10, plus the install lines of the sim and hands extras (issues 37, 38), the two-host batch launch (issue 41)
# and the Shadow-hand plans of the planning guide, in Python and on the command line (minutes on a CPU; issue 67's
# tests run the planner and the command on the two-finger test hand)
README_MAX_BYTES = 12 * 1024


@dataclasses.dataclass(frozen=True)
class Block:
    language: str
    code: str
    line: int  # 1-based line of the opening fence
    skipped: bool  # preceded by SKIP_MARKER


def read_blocks(text: str) -> list[Block]:
    """The fenced blocks of a Markdown text, in order.

    Raises ``ValueError`` for a fence that is never closed, so that a broken page fails
    rather than hiding its code from the test.
    """
    lines = text.splitlines()
    out, i = [], 0
    while i < len(lines):
        match = re.match(r"^```(\S*)\s*$", lines[i])
        if match is None:
            i += 1
            continue
        start = i
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == "```"), None)
        if end is None:
            raise ValueError(f"line {start + 1}: a fence that is never closed")
        before = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        out.append(Block(match.group(1), "\n".join(lines[start + 1 : end]) + "\n", start + 1,
                         before.strip().startswith(SKIP_MARKER)))
        i = end + 1
    return out


def rel(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


BLOCKS = {rel(page): read_blocks(page.read_text(encoding="utf-8")) for page in PAGES}
RUNNABLE = [name for name, blocks in BLOCKS.items() if any(b.language in RUN and not b.skipped for b in blocks)]


# ----------------------------------------------------------------------------- the pages' shape
def test_read_blocks_finds_fences_and_skip_markers():
    text = "x\n```python\na = 1\n```\n\n<!-- docs-test: skip (why) -->\n\n```bash\nfalse\n```\n```text\nout\n```\n"
    assert read_blocks(text) == [
        Block("python", "a = 1\n", 2, False),
        Block("bash", "false\n", 8, True),
        Block("text", "out\n", 11, False),
    ]
    with pytest.raises(ValueError, match="never closed"):
        read_blocks("```python\na = 1\n")


def test_every_block_has_a_known_language_and_few_are_skipped():
    unknown = [f"{name}:{b.line}: {b.language or '(none)'}" for name, blocks in BLOCKS.items()
               for b in blocks if b.language not in RUN and b.language not in INERT]
    assert not unknown, "fences need a language from RUN or INERT:\n" + "\n".join(unknown)
    markers = sum(page.read_text(encoding="utf-8").count(SKIP_MARKER) for page in PAGES)
    skipped = [b for blocks in BLOCKS.values() for b in blocks if b.skipped]
    assert markers == len(skipped), "a skip marker must stand right before the block it skips"
    assert all(b.language in RUN for b in skipped), "only runnable blocks need a skip marker"
    assert 0 < len(skipped) <= MAX_SKIPS


def test_api_reference_lists_every_public_name():
    text = (DOCS / "api.md").read_text(encoding="utf-8")
    listed = re.findall(r"^::: jaxgrasp\.(\w+)\s*$", text, flags=re.MULTILINE)
    assert sorted(listed) == sorted(jaxgrasp.__all__)


def test_readme_is_small_and_tells_no_history():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.encode("utf-8")) <= README_MAX_BYTES
    history = re.findall(r"\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b|\bissue \d+|\bthis round\b", text)
    assert not history
    assert "](experiments/" not in text  # pictures the package index cannot show
    first = next(b for b in BLOCKS["README.md"] if b.language in RUN)
    assert re.search(r"pip install .* && jaxgrasp sweep$", first.code.strip())
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert "python -m pytest -q -n 2 tests\n" in ci and "python -m pytest -q -n 2 tests" in text


@pytest.mark.parametrize("name", ["README.md", "docs/guide/statuses.md"])
def test_statuses_tables_name_every_status(name):
    text = (ROOT / name).read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(\w+)` \|", text, flags=re.MULTILINE)
    assert rows == list(jaxgrasp.GraspStatus.labels())


def test_every_page_is_in_the_navigation_and_every_link_resolves():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert {p for p in pages if f": {p}" not in nav} == set()
    for page in PAGES:
        for target in re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            assert (page.parent / target).is_file(), f"{rel(page)}: {target}"
    # the README's links into the docs (mkdocs build --strict checks the site's own)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", readme) if "://" not in t]
    assert targets and [t for t in targets if not (ROOT / t).is_file()] == []


def test_site_uses_material_and_mkdocstrings_strictly():
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert "name: material" in config and "- mkdocstrings:" in config and "strict: true" in config


# Fields whose type cannot be named where they are held: trimesh is imported when a mesh is
# used (not by `import jaxgrasp`); Hand's module imports the one HandGrasp lives in.
UNTYPED_FIELDS = {"MeshGrasp.mesh", "HandGrasp.mesh", "HandGrasp.hand"}


def test_api_reference_attributes_have_real_types():
    # the Attributes tables show a field's annotation: ``Any`` told a reader nothing
    text = (DOCS / "api.md").read_text(encoding="utf-8")
    untyped = set()
    for path in re.findall(r"^::: (jaxgrasp(?:\.\w+)+)\s*$", text, flags=re.MULTILINE):
        module, _, name = path.rpartition(".")
        obj = getattr(importlib.import_module(module), name)
        if isinstance(obj, type):
            untyped |= {f"{obj.__name__}.{field}" for field, annotation in vars(obj).get("__annotations__", {}).items()
                        if annotation in ("Any", "typing.Any")}
    assert untyped == UNTYPED_FIELDS


# A Sphinx role (:func:`x`) is text to mkdocstrings: the page shows ":func:" before the name's
# code span. Cross-references are written in autorefs' syntax, [`x`][jaxgrasp.x].
LITERAL_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|attr|data|exc|obj|const|ref|term|doc):(?=`|<code)")


def literal_roles(html: str) -> list[str]:
    """The Sphinx roles a built page shows as text, each with the text around it."""
    return [html[max(m.start() - 40, 0) : m.end() + 40] for m in LITERAL_ROLE.finditer(html)]


def test_literal_roles_finds_roles_as_markdown_renders_them():
    html = '<p>see :func:<code>evaluate</code> and :py:class:`Grasp`; <a href="#x"><code>plan</code></a>: done</p>'
    found = literal_roles(html)
    assert len(found) == 2 and ":func:<code>evaluate" in found[0] and ":py:class:`Grasp" in found[1]
    assert literal_roles('<p>ratio 1:2, <code>a:b</code>, "func:" in text</p>') == []


@pytest.mark.slow
def test_site_builds_strictly_with_no_literal_roles(tmp_path):
    pytest.importorskip("mkdocs", reason="the docs extra: pip install -e '.[docs]'")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-4000:]
    pages = {p.relative_to(tmp_path).as_posix(): p.read_text(encoding="utf-8") for p in tmp_path.rglob("*.html")}
    roles = {name: found for name, html in pages.items() if (found := literal_roles(html))}
    assert roles == {}, f"Sphinx roles shown as text (write [`name`][jaxgrasp.name]): {roles}"
    # the docstrings' cross-references are links between the API reference's entries (the
    # type annotations alone make 75; with the docstrings' roles as text the page had no more)
    assert pages["api/index.html"].count('class="autorefs autorefs-internal"') >= 150

# ----------------------------------------------------------------------------- running the blocks
@pytest.fixture
def page_folder(tmp_path, cache_dir, monkeypatch):
    """A temporary folder with ``examples/``, the working directory of a page's blocks;
    ``JAXGRASP_CACHE_DIR`` is the session's cache folder, also in this process."""
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("JAXGRASP_CACHE_DIR", str(cache_dir))
    jaxgrasp.engine.enable_compilation_cache(cache_dir)  # cache_dir restores the settings after the module
    root = logging.getLogger()
    saved = (root.level, list(root.handlers))
    yield tmp_path
    root.setLevel(saved[0])  # a page may configure logging (logging.basicConfig)
    root.handlers[:] = saved[1]


def _run_shell(name: str, block: Block, folder: Path) -> None:
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    proc = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", block.code], cwd=folder, env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, f"{name}:{block.line}: exit {proc.returncode}\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("name", RUNNABLE)
def test_page_blocks_run(name, page_folder):
    namespace = {"__name__": "__docs__"}
    for block in BLOCKS[name]:
        if block.skipped or block.language not in RUN:
            continue
        if RUN[block.language] == "shell":
            _run_shell(name, block, page_folder)
        else:
            exec(compile("\n" * block.line + block.code, name, "exec"), namespace)  # noqa: S102 - the page's own code; tracebacks name page lines
