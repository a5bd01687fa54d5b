"""The shape of the package, read from its source with ``ast`` and ``tokenize`` (nothing is
imported, so this file runs in a second).

Issue 34's done-when list: the top level of ``jaxgrasp/`` holds subpackages and few
modules; the packages form layers and none imports one above it; no import cycle between
modules; implementation modules are private; no function is longer than 60 lines; no
comment or docstring cites a timing, a speed-up, a percentage or a benchmark log (those
live in the write-ups of ``experiments/``, one ``FINDINGS.md`` per study). Issue 64: no
module imports another package's private module; the other packages import from its face.

Each check is a function of a source folder that returns its offenders, one line each;
``test_checks_find_planted_offenders`` plants one of each kind in a small fake package so
that every check shows it can fail.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "jaxgrasp"

LAYERS = ["_startup", "base", "solver", "storage", "model", "surface", "presets", "io", "tolerance", "engine", "analysis", "hands", "planning", "simulation", "plots", "cli"]
"""The layers from the bottom up: a module may import from its own layer or one below."""

TOP = len(LAYERS)  # jaxgrasp/__init__.py and jaxgrasp/__main__.py: the faces above every layer
MAX_TOP_MODULES = 3  # top-level modules besides __init__ and __main__
MIN_SUBPACKAGES = 5
MAX_FUNCTION_LINES = 60


# ----------------------------------------------------------------------------- the source
@dataclass
class Module:
    name: str  # dotted: "jaxgrasp.engine._store"; a package's __init__ is the package's name
    path: Path
    tree: ast.Module
    source: str
    is_package: bool


@dataclass
class Edge:
    source: str
    target: str
    line: int
    local: bool  # inside a function (a deferred import)


@dataclass
class Source:
    root: Path
    modules: dict[str, Module] = field(default_factory=dict)

    def rel(self, module: Module) -> str:
        return module.path.relative_to(self.root.parent).as_posix()


def read_source(root: Path) -> Source:
    """Every ``.py`` file under ``root`` (a package folder), parsed."""
    src = Source(root)
    for path in sorted(root.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts.pop()
        text = path.read_text(encoding="utf-8")
        name = ".".join(parts)
        src.modules[name] = Module(name, path, ast.parse(text, filename=str(path)), text, is_package)
    return src


def _function_local_nodes(tree: ast.AST) -> set[int]:
    """ids of the nodes inside a function body."""
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            for sub in ast.walk(node):
                if sub is not node:
                    inside.add(id(sub))
    return inside


def import_edges(src: Source) -> list[Edge]:
    """Every import between modules of the package, at module level or inside functions.

    ``from a.b import c`` is an edge to the module ``a.b.c`` where that is a module, else
    to ``a.b`` (the package's ``__init__``); ``import a.b.c`` is an edge to ``a.b.c``.
    The parents that Python imports on the way are not edges.
    """
    top = src.root.name
    edges = []
    for mod in src.modules.values():
        local = _function_local_nodes(mod.tree)
        package = mod.name if mod.is_package else mod.name.rpartition(".")[0]
        for node in ast.walk(mod.tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base_parts = package.split(".")
                    base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                    base = ".".join(base_parts + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    targets.append(sub if sub in src.modules else base)
            for target in targets:
                if target == top or target.startswith(top + "."):
                    while target not in src.modules and "." in target:  # a name, not a module
                        target = target.rpartition(".")[0]
                    edges.append(Edge(mod.name, target, node.lineno, id(node) in local))
    return edges


# ----------------------------------------------------------------------------- the checks
def layer_of(name: str) -> int | None:
    """The index in LAYERS of a dotted module name, TOP for the package's faces, None if
    the module belongs to no layer."""
    parts = name.split(".")
    if len(parts) == 1 or parts[1] == "__main__":
        return TOP
    return LAYERS.index(parts[1]) if parts[1] in LAYERS else None


def top_level_offenders(root: Path) -> list[str]:
    """What the top-level folder holds beyond subpackages, ``__init__``, ``__main__`` and
    MAX_TOP_MODULES other modules, and too few subpackages."""
    out = []
    modules, subpackages = [], []
    for entry in sorted(root.iterdir()):
        if entry.name == "__pycache__" or entry.name.startswith("."):
            continue
        if entry.is_dir():
            if (entry / "__init__.py").is_file():
                subpackages.append(entry.name)
            else:
                out.append(f"{entry.name}/: a folder without __init__.py")
        elif entry.suffix == ".py":
            if entry.name not in ("__init__.py", "__main__.py"):
                modules.append(entry.name)
        elif entry.name != "py.typed":
            out.append(f"{entry.name}: neither a module nor a subpackage")
    if len(modules) > MAX_TOP_MODULES:
        out.append(f"{len(modules)} top-level modules (at most {MAX_TOP_MODULES}): {', '.join(modules)}")
    if len(subpackages) < MIN_SUBPACKAGES:
        out.append(f"{len(subpackages)} subpackages (at least {MIN_SUBPACKAGES}): {', '.join(subpackages)}")
    return out


def unlayered_offenders(src: Source) -> list[str]:
    """Modules in no layer of LAYERS."""
    return [f"{src.rel(m)}: in no layer of LAYERS" for m in src.modules.values() if layer_of(m.name) is None]


def upward_import_offenders(src: Source) -> list[str]:
    """Imports from a layer above the importing module's."""
    out = []
    for e in import_edges(src):
        a, b = layer_of(e.source), layer_of(e.target)
        if a is not None and b is not None and b > a:
            where = "in a function" if e.local else "at module level"
            out.append(
                f"{src.rel(src.modules[e.source])}:{e.line}: {e.source} ({_layer_name(a)}) imports "
                f"{e.target} ({_layer_name(b)}), a layer above, {where}"
            )
    return out


def _layer_name(index: int) -> str:
    return LAYERS[index] if index < TOP else "top"


def strongly_connected(nodes: list[str], succ: dict[str, list[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for start in nodes:
        if start in index:
            continue
        work = [(start, iter(succ.get(start, ())))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(succ.get(w, ()))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    out.append(sorted(comp))
    return out


def cycle_offenders(src: Source) -> list[str]:
    """Import cycles between modules: each strongly connected component of more than one
    module (or a module importing itself), on one line with the imports inside it."""
    edges = import_edges(src)
    succ: dict[str, list[str]] = {}
    for e in edges:
        succ.setdefault(e.source, []).append(e.target)
    out = []
    for comp in strongly_connected(sorted(src.modules), succ):
        members = set(comp)
        inner = [e for e in edges if e.source in members and e.target in members]
        if len(comp) == 1 and not inner:
            continue
        closing = sorted({  # one per import statement and target
            (e.source, e.line, f"{src.rel(src.modules[e.source])}:{e.line} imports {e.target}"
             + (" (in a function)" if e.local else ""))
            for e in inner
        })
        closing = [text for _, _, text in closing]
        out.append(f"cycle of {len(comp)} modules: {', '.join(comp)}; by {'; '.join(closing)}")
    return out


def public_module_offenders(src: Source) -> list[str]:
    """Modules (or folders) below a top-level package whose names are public."""
    out = []
    for m in src.modules.values():
        parts = m.path.relative_to(src.root).parts
        if len(parts) < 2:
            continue  # top level: the faces and the top-level modules
        below = parts[1:]  # below the top-level package
        public = [p for p in below if p != "__init__.py" and not p.startswith("_")]
        if public:
            out.append(f"{src.rel(m)}: public name below {parts[0]}/ ({'/'.join(public)}); make it _private")
    return out


def package_of(src: Source, name: str) -> str | None:
    """The subpackage a dotted module name belongs to (``"engine"`` for
    ``jaxgrasp.engine._store`` and for ``jaxgrasp.engine``); None for the top level's own
    modules (``jaxgrasp``, ``jaxgrasp.__main__``, ``jaxgrasp._startup``, ``jaxgrasp.presets``),
    which are outside every subpackage."""
    parts = name.split(".")
    if len(parts) > 2 or (len(parts) == 2 and name in src.modules and src.modules[name].is_package):
        return parts[1]
    return None


def private_import_offenders(src: Source) -> list[str]:
    """Imports of another package's private module: a module ``jaxgrasp.P._m`` (any part
    below ``P`` private, dunders aside) imported by a module outside ``P``, in any form
    (``from jaxgrasp.P._m import x``, ``import jaxgrasp.P._m``, ``from jaxgrasp.P import
    _m``, relative, in a function). The other packages import from ``P``'s face, its
    ``__init__``. One line per import statement and module."""
    top = src.root.name
    found = sorted({
        (src.rel(src.modules[e.source]), e.line, e.source, e.target, e.local)
        for e in import_edges(src)
        if any(p.startswith("_") and not p.startswith("__") for p in e.target.split(".")[2:])
        and package_of(src, e.target) != package_of(src, e.source)
    })
    return [
        f"{rel}:{line}: {source} imports {target}, a private module of {top}.{package_of(src, target)}"
        f"{' (in a function)' if local else ''}; import from {top}.{package_of(src, target)}"
        for rel, line, source, target, local in found
    ]


def long_function_offenders(src: Source, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """Functions longer than ``limit`` lines, from the ``def`` line to the last."""
    out = []
    for m in src.modules.values():
        for node in ast.walk(m.tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{src.rel(m)}:{node.lineno}: {node.name} has {n} lines (at most {limit})")
    return out


MEASUREMENT = re.compile(
    "|".join(
        f"(?:{p})"
        for p in (
            r"\b\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?\s?(?:ms|us|µs|s|secs?|seconds?|min|minutes?)\b",  # a timing
            r"\b\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?\s?%",  # a percentage
            r"\b\d+(?:\.\d+)?[x×](?![\w(])(?!\s*[-+*/=^(\d])",  # a speed-up (not 2x + 1, not 3x3)
            r"BENCHMARK",  # the former experiments/BENCHMARK.md
            r"(?i:\bbenchmark\w*\.(?:py|md|json|log)\b)",
            r"(?<!np)(?<!math)(?<!numpy)(?<!lax)\.log\b",  # a log file, not np.log
            r"(?i:experiments/[\w/.-]+\.json\b)",
            r"\b(?:grasps|programs|points|chunks)/s\b",  # a rate
            r"\bfaster\b",
            r"\bslower\b",
            r"(?i:\bspeed-?ups?\b)",
        )
    )
)
"""What a measurement looks like in prose."""

ALLOWED = {
    # (file, phrase on the line): numbers that define something, not measurements
    ("jaxgrasp/analysis/_tune_spec.py", "1% of the radius"),  # a default bound
    ("jaxgrasp/tolerance/_options.py", "1% of them"),  # advice on choosing T
    ("jaxgrasp/plots/_scene.py", "15 % of its"),  # the ghost's drawing scale
    ("jaxgrasp/tolerance/_verdict.py", "10 % of the value"),  # the rule in the code below it
    ("jaxgrasp/solver/_solver.py", "did not fall 4x"),  # the penalty rule's factor
}


def prose(module: Module) -> list[tuple[int, str]]:
    """``(line, text)`` of every comment and every string statement (docstrings of
    modules, classes, functions and attributes), one line of text each."""
    out = []
    for tok in tokenize.generate_tokens(io.StringIO(module.source).readline):
        if tok.type == tokenize.COMMENT:
            out.append((tok.start[0], tok.string))
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            for i, line in enumerate(node.value.value.splitlines()):
                out.append((node.lineno + i, line))
    return sorted(out)


def measurement_offenders(src: Source) -> list[str]:
    """Comments and docstrings that cite a timing, speed-up, percentage or benchmark."""
    out = []
    for m in src.modules.values():
        rel = src.rel(m)
        for line, text in prose(m):
            if any(f == rel and phrase in text for f, phrase in ALLOWED):
                continue
            hits = [h.group(0) for h in MEASUREMENT.finditer(text)]
            if hits:
                out.append(f"{rel}:{line}: {', '.join(repr(h) for h in hits)} in {text.strip()[:100]!r}")
    return out


def _assert_none(what: str, offenders: list[str]) -> None:
    """Fail with every offender on a line of its own."""
    if offenders:
        pytest.fail(f"{len(offenders)} {what}:\n" + "\n".join(offenders), pytrace=False)


# ----------------------------------------------------------------------------- the tests
SOURCE = read_source(ROOT)


def test_top_level_holds_subpackages_and_few_modules():
    offenders = top_level_offenders(ROOT)
    _assert_none("problems with the top level of jaxgrasp/", offenders)


def test_every_module_is_in_a_layer():
    offenders = unlayered_offenders(SOURCE)
    _assert_none("modules in no layer", offenders)


def test_no_import_from_a_layer_above():
    offenders = upward_import_offenders(SOURCE)
    _assert_none("imports from a layer above", offenders)


def test_no_import_cycle_between_modules():
    offenders = cycle_offenders(SOURCE)
    _assert_none("import cycles", offenders)


def test_implementation_modules_are_private():
    offenders = public_module_offenders(SOURCE)
    _assert_none("public modules below a package", offenders)


def test_no_import_of_another_packages_private_module():
    offenders = private_import_offenders(SOURCE)
    _assert_none("imports of another package's private module (import from its face)", offenders)


def test_no_function_over_60_lines():
    offenders = long_function_offenders(SOURCE)
    _assert_none("functions over 60 lines", offenders)


def test_no_comment_or_docstring_cites_a_measurement():
    offenders = measurement_offenders(SOURCE)
    _assert_none("comments or docstrings citing a measurement (they go to experiments/<study>/FINDINGS.md)", offenders)


# ----------------------------------------------------------------------------- the checks can fail
_FAKE = {
    "__init__.py": '"""Fake."""\nfrom pkg import engine\n',
    "__main__.py": "from pkg.cli import main\n",
    "_startup.py": "",
    "presets.py": "",
    "extra_a.py": "",
    "extra_b.py": "",
    "notes.txt": "",
    "solver/__init__.py": "from pkg.solver._a import f\n",
    "solver/_a.py": "def f():\n    from pkg.engine import g  # upward, deferred\n    return g\n",
    "model/__init__.py": "",
    "model/_b.py": "from . import _c\n",
    "model/_c.py": "from pkg.model._b import x\nimport pkg.model._c\n",
    "engine/__init__.py": "from pkg.engine.public import g\n",
    "engine/public.py": "def g():\n" + "    x = 1\n" * 60 + "    return x\n",
    "engine/_ok.py": "def h():\n" + "    x = 1\n" * 58 + "    return x\n",
    "cli/__init__.py": "def main():\n    # runs 2.5x faster, 12 ms a call, 20-30 % of the time\n    pass\n",
    "cli/_d.py": '"""See experiments/BENCHMARK.md and sweep.log; 40 grasps/s. Not 2x + 1, not 3x3, not np.log."""\n',
    "stray/_e.py": "import pkg.nowhere._f\n",
    "cli/_f.py": "import pkg.model._b\nfrom pkg.model import _c, x\nfrom pkg.solver import f\n\n\ndef late():\n    from ..model._c import y\n    return y\n",
}


def _fake_package(tmp_path: Path) -> Path:
    root = tmp_path / "pkg"
    for rel, text in _FAKE.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_checks_find_planted_offenders(tmp_path):
    root = _fake_package(tmp_path)
    src = read_source(root)

    top = top_level_offenders(root)
    assert any("4 top-level modules" in line for line in top), top
    assert any("notes.txt" in line for line in top), top
    assert any("stray/" in line for line in top), top  # no __init__.py
    assert any("4 subpackages" in line for line in top), top  # cli, engine, model, solver

    assert unlayered_offenders(src) == [
        f"pkg/{name}: in no layer of LAYERS" for name in ("extra_a.py", "extra_b.py", "stray/_e.py")
    ]

    up = upward_import_offenders(src)
    assert len(up) == 1 and "pkg/solver/_a.py:2: pkg.solver._a (solver) imports pkg.engine (engine)" in up[0], up
    assert up[0].endswith("in a function")

    cycles = cycle_offenders(src)
    assert cycles == [  # with the self-import; pkg.engine -> pkg.engine.public is no cycle
        "cycle of 2 modules: pkg.model._b, pkg.model._c; by pkg/model/_b.py:1 imports pkg.model._c; "
        "pkg/model/_c.py:1 imports pkg.model._b; pkg/model/_c.py:2 imports pkg.model._c"
    ], cycles

    assert public_module_offenders(src) == ["pkg/engine/public.py: public name below engine/ (public.py); make it _private"]

    assert long_function_offenders(src) == ["pkg/engine/public.py:1: g has 62 lines (at most 60)"]

    assert private_import_offenders(src) == [  # not pkg.model._c's import of pkg.model._b, its own package's
        "pkg/cli/_f.py:1: pkg.cli._f imports pkg.model._b, a private module of pkg.model; import from pkg.model",
        "pkg/cli/_f.py:2: pkg.cli._f imports pkg.model._c, a private module of pkg.model; import from pkg.model",
        "pkg/cli/_f.py:7: pkg.cli._f imports pkg.model._c, a private module of pkg.model (in a function); import from pkg.model",
    ]

    found = measurement_offenders(src)
    assert len(found) == 2, found
    assert found[0].startswith("pkg/cli/__init__.py:2: '2.5x', 'faster', '12 ms', '20-30 %'"), found
    assert found[1].startswith("pkg/cli/_d.py:1: 'BENCHMARK', '.log', 'grasps/s' in"), found


def test_imports_for_static_tools_are_edges_too(tmp_path):
    # The faces import their names under ``if TYPE_CHECKING:`` (jaxgrasp._startup.attach
    # loads them from there when first used): those imports are edges, checked as any other.
    for rel, text in {
        "__init__.py": "",
        "model/__init__.py": "",
        "model/_b.py": "",
        "solver/__init__.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.engine import g\n",
        "engine/__init__.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.model._b import x\n",
    }.items():
        path = tmp_path / "pkg" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    src = read_source(tmp_path / "pkg")
    up = upward_import_offenders(src)
    assert len(up) == 1 and up[0].startswith("pkg/solver/__init__.py:3: pkg.solver (solver) imports pkg.engine"), up
    assert private_import_offenders(src) == [
        "pkg/engine/__init__.py:3: pkg.engine imports pkg.model._b, a private module of pkg.model; import from pkg.model"
    ]
    faces = {e.target for e in import_edges(SOURCE) if e.source == "jaxgrasp.model"}
    assert {"jaxgrasp.model._fields", "jaxgrasp.model._grasp", "jaxgrasp._startup"} <= faces, faces


def test_layers_cover_the_planned_packages():
    # the order of issue 34, with the surfaces (36), planning (36), hands (37) and physics
    # check (38) packages, the base below the solver and the model, and storage under every
    # writer (64); a change here is a change of the architecture
    assert LAYERS == ["_startup", "base", "solver", "storage", "model", "surface", "presets", "io", "tolerance", "engine", "analysis", "hands", "planning", "simulation", "plots", "cli"]
    assert [layer_of(n) for n in ("jaxgrasp", "jaxgrasp.__main__", "jaxgrasp.solver._lanes", "jaxgrasp.cli")] == [TOP, TOP, 2, 15]


def test_package_docstring_and_developers_guide_list_the_layers_in_order():
    # Both are where a reader learns the layout; a package added to LAYERS but not to them
    # (or listed out of order) leaves the reader a wrong map.
    guide = (ROOT.parent / "docs" / "development.md").read_text(encoding="utf-8")
    layout = guide.split("## Layout", 1)[1].split("\n## ", 1)[0]
    face = (ROOT / "__init__.py").read_text(encoding="utf-8").split('"""', 2)[1]
    for text in (layout, face):
        listed = re.findall(r"^[-*] \[?`jaxgrasp\.(\w+)`", text, flags=re.MULTILINE)
        assert listed == [layer for layer in LAYERS[1:] if layer != "cli"], listed
