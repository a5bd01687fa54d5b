"""The public face of jaxgrasp (issues 34, 64): a curated, documented ``__all__`` of at most 30
names, chosen by the rule in ``jaxgrasp``'s docstring and loaded when first used; no function
hides a module of the same name; the enum aliases and internals off the top level, each on
its package face; every result type on a package face and in the API reference; each
subpackage documented with an ``__all__``; the ``jaxgrasp`` command's entry point.

Each check is a function of a package that returns its offenders, one line each;
``test_checks_find_planted_offenders`` runs them on a small fake package that breaks each
rule once.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import importlib
import inspect
import json
import pkgutil
import sys
import textwrap
import tomllib
import types
from pathlib import Path

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import _startup

MAX_PUBLIC_NAMES = 30
"""Issue 34's bound, restored in issue 64 by one rule (``jaxgrasp``'s docstring)."""
OFF_THE_TOP_LEVEL = ("STABLE", "STATUS_NAMES", "KINDS", "COMPILER_OPTIONS")
"""Names that left the top level in issue 34: an enum alias, tables and an internal."""
MOVED_TO_FACES = {
    "LaneStatus": "jaxgrasp.solver",
    "BoundaryKind": "jaxgrasp.model",
    "Surface": "jaxgrasp.surface",
    "grasp_from_dict": "jaxgrasp.io",
    "grasp_to_dict": "jaxgrasp.io",
    "enable_compilation_cache": "jaxgrasp.engine",
    "SweepResult": "jaxgrasp.analysis",
    "TuneResult": "jaxgrasp.analysis",
    "TuneStatus": "jaxgrasp.analysis",
    "EpsilonResult": "jaxgrasp.analysis",
    "Uncertainty": "jaxgrasp.analysis",
    "PlanResult": "jaxgrasp.planning",
}
"""Names that left the top level in issue 64 (a feature's own types, internals, dict-level
twins, a cache switch), and the package face that holds each."""
RESULT_TYPES = {
    "jaxgrasp.solver": ("SolverResult",),
    "jaxgrasp.tolerance": ("Evaluation",),
    "jaxgrasp.engine": ("BatchResult",),
    "jaxgrasp.analysis": ("SweepResult", "TuneResult", "EpsilonResult", "RobustResult", "RobustBatch"),
    "jaxgrasp.planning": ("PlanResult",),
    "jaxgrasp.simulation": ("SimulationResult",),
    "jaxgrasp.hands": ("HandTuneResult", "HandValue"),
}
"""What the public functions return, by the package face that holds it."""

REPO = Path(__file__).resolve().parent.parent


def _fail_if(what: str, offenders: list[str]) -> None:
    """Fail with every offender on a line of its own."""
    if offenders:
        pytest.fail(f"{len(offenders)} {what}:\n" + "\n".join(offenders), pytrace=False)


def subpackages(package: types.ModuleType) -> list[types.ModuleType]:
    """The direct subpackages of ``package``, imported."""
    return [
        importlib.import_module(f"{package.__name__}.{info.name}")
        for info in pkgutil.iter_modules(package.__path__)
        if info.ispkg
    ]


def import_everything(package: types.ModuleType) -> None:
    """Import every module below ``package``, so that each submodule's name is bound in
    its parent: to the module, or to a function imported after it that hides it."""
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        if not info.name.endswith("__main__"):
            importlib.import_module(info.name)


def own_docstring(obj, package: str) -> str | None:
    """``obj``'s docstring, not one it inherits or one Python writes for it.

    A class defined in ``package`` has one only if its source has one: dataclasses,
    named tuples and enums otherwise get a generated ``__doc__``, or their base's.
    """
    if isinstance(obj, type):
        if obj.__module__.split(".")[0] == package:
            try:
                source = textwrap.dedent(inspect.getsource(obj))
            except (OSError, TypeError):
                return None
            node = ast.parse(source).body[0]
            return ast.get_docstring(node) if isinstance(node, ast.ClassDef) else None
        return obj.__dict__.get("__doc__")
    if isinstance(obj, types.ModuleType) or callable(obj):
        return obj.__doc__
    return None  # a value: its __doc__ is its type's


def undocumented_names(package: types.ModuleType) -> list[str]:
    """Names of ``package.__all__`` that are missing or have no docstring of their own."""
    out = []
    root = package.__name__.split(".")[0]
    for name in package.__all__:
        if not hasattr(package, name):
            out.append(f"{package.__name__}.{name}: in __all__ but missing")
            continue
        obj = getattr(package, name)
        doc = own_docstring(obj, root)
        if not (doc and doc.strip()):
            kind = "a value, not a module, class or function" if not (
                isinstance(obj, (type, types.ModuleType)) or callable(obj)) else type(obj).__name__
            out.append(f"{package.__name__}.{name}: no docstring of its own ({kind})")
    return out


def missing_names(package: types.ModuleType) -> list[str]:
    """Names of ``package.__all__`` that it lacks, repeated names, and no ``__all__``."""
    names = getattr(package, "__all__", None)
    if names is None:
        return [f"{package.__name__}: no __all__"]
    out = [f"{package.__name__}.{n}: in __all__ but missing" for n in names if not hasattr(package, n)]
    out += [f"{package.__name__}.{n}: {names.count(n)} times in __all__" for n in sorted(set(names)) if names.count(n) > 1]
    return out


def hidden_modules(package: types.ModuleType) -> list[str]:
    """Submodules of ``package`` whose name is bound in it to something else (a function
    of the same name hides the module: ``package.name.X`` fails)."""
    out = []
    for info in pkgutil.iter_modules(package.__path__):
        module = sys.modules.get(f"{package.__name__}.{info.name}")
        attr = getattr(package, info.name, module)
        if attr is not module:
            out.append(f"{package.__name__}.{info.name}: a {type(attr).__name__}, and a submodule of that name")
    return out


# ----------------------------------------------------------------------------- jaxgrasp
@pytest.fixture(scope="module")
def packages() -> list[types.ModuleType]:
    """The subpackages of jaxgrasp, once every module below jaxgrasp is imported (here,
    not at collection, so that other test files see jaxgrasp as they would alone)."""
    import_everything(jaxgrasp)
    return subpackages(jaxgrasp)


def test_at_most_30_public_names():
    assert len(jaxgrasp.__all__) <= MAX_PUBLIC_NAMES, f"{len(jaxgrasp.__all__)} names: {jaxgrasp.__all__}"


def test_every_public_name_exists_and_has_its_own_docstring(packages):
    _fail_if("problems with jaxgrasp.__all__", missing_names(jaxgrasp) + undocumented_names(jaxgrasp))


def test_no_function_hides_a_module(packages):
    offenders = hidden_modules(jaxgrasp)
    for package in packages:
        offenders += hidden_modules(package)
    _fail_if("names bound to something other than the submodule of that name", offenders)


def test_enum_aliases_and_internals_are_off_the_top_level():
    from jaxgrasp.analysis import TuneStatus
    from jaxgrasp.model import BoundaryKind
    from jaxgrasp.solver import LaneStatus

    statuses = (jaxgrasp.GraspStatus, LaneStatus, BoundaryKind, TuneStatus)
    names = dict.fromkeys([*OFF_THE_TOP_LEVEL, *MOVED_TO_FACES, *(member.name for enum in statuses for member in enum)])
    offenders = [f"jaxgrasp.{n}" for n in names if hasattr(jaxgrasp, n) or n in jaxgrasp.__all__]
    _fail_if("enum aliases or internals at the top level (the enums carry the names)", offenders)


def test_moved_names_are_on_their_package_faces():
    offenders = [f"{face}.{name}" for name, face in MOVED_TO_FACES.items()
                 if name not in importlib.import_module(face).__all__]
    _fail_if("names that left the top level but are not on their package face", offenders)


def test_every_result_type_is_on_a_face_and_in_the_api_reference():
    reference = "\n".join(p.read_text() for p in sorted((REPO / "docs").glob("api*.md")))
    offenders = []
    for face, names in RESULT_TYPES.items():
        module = importlib.import_module(face)
        for name in names:
            if name not in module.__all__:
                offenders.append(f"{face}.{name}: not in {face}.__all__")
            top = name in jaxgrasp.__all__
            if f"::: {face}.{name}\n" not in reference + "\n" and not (top and f"::: jaxgrasp.{name}\n" in reference):
                offenders.append(f"{face}.{name}: not in the API reference (docs/api*.md)")
    _fail_if("result types without a documented face", offenders)


def test_the_face_loads_each_name_from_its_package_when_first_used():
    """``jaxgrasp.__getattr__`` finds each name of ``__all__`` on the package face that the
    static imports for tools (``if TYPE_CHECKING:``) name, a face, not a private module;
    ``presets`` is a module of its own."""
    homes = {name: module for name, (module, _) in jaxgrasp._LAZY.items()}
    assert sorted(homes) == sorted(jaxgrasp.__all__)
    assert homes.pop("presets") == "jaxgrasp.presets"
    faces = {f"jaxgrasp.{p.parent.name}" for p in (REPO / "jaxgrasp").glob("*/__init__.py")}
    assert set(homes.values()) <= faces, set(homes.values()) - faces
    for name, face in homes.items():
        assert getattr(jaxgrasp, name) is getattr(importlib.import_module(face), name), name


def test_every_face_loads_its_names_from_its_static_imports(packages):
    """Every package face (and the top level) lists its names once, as the imports of its
    ``if TYPE_CHECKING:`` block that type checkers and the API reference read;
    `jaxgrasp._startup.attach` reads the same block, and each name is the object its
    module holds. A name of ``__all__`` is in that block or defined in the face."""
    offenders = []
    for face in [jaxgrasp, *packages]:
        source = Path(face.__file__).read_text(encoding="utf-8")
        if getattr(face, "_LAZY", None) != _startup.lazy_names(face.__name__, source):
            offenders.append(f"{face.__name__}: _LAZY is not what its TYPE_CHECKING block imports")
            continue
        for name, (module, attr) in face._LAZY.items():
            target = importlib.import_module(module)
            if getattr(face, name) is not (getattr(target, attr) if attr else target):
                offenders.append(f"{face.__name__}.{name}: not {module}.{attr}")
        own = {n for n, v in vars(face).items() if getattr(v, "__module__", face.__name__) == face.__name__}
        offenders += [f"{face.__name__}.{n}: in __all__, neither imported under TYPE_CHECKING nor defined there"
                      for n in face.__all__ if n not in face._LAZY and n not in own and n not in _EAGER.get(face.__name__, ())]
    _fail_if("faces whose names are not loaded from their static imports", offenders)


_EAGER = {"jaxgrasp.cli": ("COMMANDS", "UsageError", "EXIT_USAGE", "parse_number")}
"""Names a face imports at run time (the command's parser needs them at once, without JAX)."""


def test_lazy_names_reads_the_type_checking_block():
    source = textwrap.dedent(
        """
        from typing import TYPE_CHECKING
        from pkg import _startup

        if TYPE_CHECKING:  # the face's names
            from pkg.face._a import A, b as renamed
            from pkg import sub

            # for other packages
            from pkg.other import C
        """
    )
    assert _startup.lazy_names("pkg", source) == {
        "A": ("pkg.face._a", "A"), "renamed": ("pkg.face._a", "b"), "sub": ("pkg.sub", ""), "C": ("pkg.other", "C"),
    }
    for bad, why in [("import pkg.face._a", "only 'from jaxgrasp"), ("from ._a import A", "only 'from jaxgrasp"),
                     ("from pkg._a import A\n    from pkg._b import A", "'A' imported twice")]:
        with pytest.raises(ValueError, match=why):
            _startup.lazy_names("pkg", f"if TYPE_CHECKING:\n    {bad}\n")


def test_the_package_and_its_subpackages_have_a_face(packages):
    assert len(packages) >= 5, [p.__name__ for p in packages]
    offenders = [f"{p.__name__}: no docstring" for p in [jaxgrasp, *packages] if not (p.__doc__ or "").strip()]
    for package in packages:
        offenders += missing_names(package)
    _fail_if("subpackages without a docstring or a sound __all__", offenders)


SHORT_DEFAULT = 40
"""Characters a default value may take in a public signature (issue 35: ``help`` showed a
600-character ``EvaluateOptions(...)``)."""


def test_signatures_are_readable_in_help():
    offenders = []
    for name in jaxgrasp.__all__:
        obj = getattr(jaxgrasp, name)
        if not inspect.isfunction(obj):
            continue
        for param in inspect.signature(obj).parameters.values():
            if param.default is not param.empty and len(repr(param.default)) > SHORT_DEFAULT:
                offenders.append(f"{name}({param.name}=...): {len(repr(param.default))} characters")
    _fail_if(f"defaults longer than {SHORT_DEFAULT} characters in help()", offenders)
    assert len(str(inspect.signature(jaxgrasp.evaluate))) < 200


def test_options_repr_names_only_what_differs_and_round_trips():
    from jaxgrasp import EvaluateOptions, SolverOptions

    assert repr(EvaluateOptions()) == "EvaluateOptions()"
    changed = EvaluateOptions(seed=3, solver=SolverOptions(tol=1e-12))
    assert repr(changed) == "EvaluateOptions(solver=SolverOptions(tol=1e-12), seed=3)"
    assert eval(repr(changed), {"EvaluateOptions": EvaluateOptions, "SolverOptions": SolverOptions}) == changed


def test_cli_entry_point():
    from jaxgrasp import cli

    assert callable(cli.main) and "main" in cli.__all__
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"jaxgrasp": "jaxgrasp.cli:main"}


# ----------------------------------------------------------------------------- the checks can fail
_FAKE = {
    "__init__.py": '''"""Fake."""
import dataclasses, enum
from typing import NamedTuple
from fakeapi.sub import sub  # the function hides its module, as jaxgrasp.sweep once did
from fakeapi import inner

@dataclasses.dataclass
class Plain:  # no docstring: dataclasses write one
    x: int = 0

class Pair(NamedTuple):  # no docstring: NamedTuple writes one
    a: int

class Color(enum.IntEnum):  # no docstring
    RED = 1

class Documented:
    """Has one."""

def undocumented():
    pass

TABLE = {"a": 1}
__all__ = ["Plain", "Pair", "Color", "Documented", "undocumented", "TABLE", "gone", "sub", "sub"]
''',
    "sub.py": 'def sub():\n    """Hides its module."""\n',
    "inner/__init__.py": "from fakeapi.inner._impl import run\n__all__ = ['run', 'absent']\n",
    "inner/_impl.py": 'def run():\n    """Run."""\n',
}


def test_checks_find_planted_offenders(tmp_path, monkeypatch):
    for rel, text in _FAKE.items():
        path = tmp_path / "fakeapi" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in [m for m in sys.modules if m == "fakeapi" or m.startswith("fakeapi.")]:
        monkeypatch.delitem(sys.modules, name)
    fake = importlib.import_module("fakeapi")
    import_everything(fake)
    try:
        assert missing_names(fake) == ["fakeapi.gone: in __all__ but missing", "fakeapi.sub: 2 times in __all__"]
        assert undocumented_names(fake) == [
            "fakeapi.Plain: no docstring of its own (type)",
            "fakeapi.Pair: no docstring of its own (type)",
            "fakeapi.Color: no docstring of its own (EnumType)",
            "fakeapi.undocumented: no docstring of its own (function)",
            "fakeapi.TABLE: no docstring of its own (a value, not a module, class or function)",
            "fakeapi.gone: in __all__ but missing",
        ]
        assert hidden_modules(fake) == ["fakeapi.sub: a function, and a submodule of that name"]
        (inner,) = subpackages(fake)
        assert missing_names(inner) == ["fakeapi.inner.absent: in __all__ but missing"]
        assert hidden_modules(inner) == []
    finally:
        for name in [m for m in sys.modules if m == "fakeapi" or m.startswith("fakeapi.")]:
            del sys.modules[name]


# ----------------------------------------------------------------------------- results alike (issue 64)
# docs/getting-started.md, "What every result holds": one convention for every result type.
PYTREE_RESULTS = ("Evaluation", "SolverResult")
"""Results that pass through ``jit`` and ``vmap``: ``status`` is an integer array there."""
BATCHED_RESULTS = ("BatchResult", "SweepResult", "RobustBatch")
"""Results with a leading axis of entries, each a single result's members: codes and names
by entry (``status``, ``status_names``), ``value`` by entry."""
WITHOUT_STATUS = ("EpsilonResult",)
"""Results without an outcome code (epsilon's outcome is ``force_closure``)."""
WITHOUT_VALUE = ("SolverResult",)
"""Results without a headline value (the solver's objective is in its scaled units)."""
TIMED = ("BatchResult", "SweepResult", "PlanResult")
"""Results that time their own run: ``elapsed_s``."""
TUNED = ("TuneResult", "HandTuneResult")
"""Results of a tuning: ``start_value``, the value before it."""


def result_types() -> dict[str, type]:
    """Every result type on a package face: the classes of the faces' ``__all__`` whose name
    ends in ``Result``, ``Evaluation``, ``RobustBatch`` and those `RESULT_TYPES` lists."""
    import_everything(jaxgrasp)
    out = {}
    for package in subpackages(jaxgrasp):
        for name in getattr(package, "__all__", ()):
            obj = getattr(package, name, None)
            listed = name in RESULT_TYPES.get(package.__name__, ())
            if isinstance(obj, type) and (name.endswith("Result") or name in ("Evaluation", "RobustBatch") or listed):
                out[name] = obj
    return out


def _cube_evaluation(value: float = 8.794009946243486e-05, status: int = 0):
    """One grasp's `Evaluation` of two contacts, with the numbers of the cube's (no compilation)."""
    u0 = 3.3510321638291125e-03
    return jaxgrasp.Evaluation(
        value=np.float64(value), status=np.int32(status), limiting_kind=np.int32(0), limiting_contact=np.int32(0),
        equilibrium_energy=np.float64(u0), equilibrium_translation=np.zeros(3), equilibrium_rotation=np.zeros(3),
        boundary_energy=np.array([[u0 + value, u0 + value], [u0 + 2e-3, np.inf]]),
        boundary_translation=np.zeros((2, 2, 3)), boundary_rotation=np.zeros((2, 2, 3)),
        boundary_status=np.array([[0, 0], [0, 1]], dtype=np.int32), equilibrium_status=np.int32(0),
        equilibrium_margins=np.full((3, 2), 0.5), kkt=np.zeros((5, 3)), steps=np.arange(5, dtype=np.int32),
    )


def built_results(tmp_path) -> dict[str, list]:
    """Instances of every result type, built without compiling anything: from their fields
    (the numbers of the cube's evaluation) or by cheap calls (`epsilon`, indexing a batch,
    a file's round trip)."""
    import jax

    from jaxgrasp.analysis import (EpsilonResult, RobustBatch, RobustStatus, SweepResult, TuneResult, TuneStatus,
                                   Uncertainty)
    from jaxgrasp.engine import BatchResult
    from jaxgrasp.hands import HandTuneResult, HandValue
    from jaxgrasp.planning import HandPlanResult, PlanResult, PlanStatus
    from jaxgrasp.simulation import SimulationResult, SimulationStatus, Trial
    from jaxgrasp.solver import SolverResult

    cube = jaxgrasp.presets.cube()
    ev, bad = _cube_evaluation(), _cube_evaluation(value=np.nan, status=jaxgrasp.GraspStatus.INVALID)
    stacked = jax.tree_util.tree_map(lambda *a: np.stack(a), ev, bad, _cube_evaluation(0.0, 1))
    batch = BatchResult(evaluation=stacked, num_contacts=np.array([2, 0, 2]), active=np.ones((3, 2), bool),
                        errors=(None, "friction = -1 must be >= 0", None), compile_seconds=1.5, run_seconds=0.25)
    sweep = SweepResult(axes={"young_modulus": np.array([2e5, 6e5])}, value=np.array([8.8e-5, 2.6e-4]),
                        status=np.array([0, 0], np.int32), limiting_kind=np.array([0, 1], np.int32),
                        limiting_contact=np.array([0, 1], np.int32), equilibrium_energy=np.array([3e-3, 3e-3]),
                        compile_seconds=2.0, run_seconds=0.5)
    sweep.to_npz(tmp_path / "sweep.npz")
    nominal = BatchResult(evaluation=jax.tree_util.tree_map(lambda a: a[[0, 2]], stacked), num_contacts=np.array([2, 2]),
                          active=np.ones((2, 2), bool), errors=(None, None))
    statuses = np.array([[0, 0, 3], [1, 3, 0]])
    robust = RobustBatch(
        status=np.array([RobustStatus.PARTLY_CONVERGED] * 2), p_stable=np.array([1.0, 0.5]),
        p_stable_stderr=np.array([0.0, 0.5]), value_mean=np.array([8.7e-5, 4.4e-5]), quantile_levels=(0.05, 0.5),
        quantiles=np.array([[8.4e-5, 8.7e-5], [0.0, 4.4e-5]]), values=np.where(statuses == 0, 8.7e-5, 0.0),
        statuses=statuses, converged=np.array([2, 2]), nominal=nominal, clipped={"friction": np.array([0, 1])},
        uncertainty=Uncertainty(friction=0.1), samples=3, seed=0)
    tuned = TuneResult(
        grasp=cube, value=9.6e-4, initial_value=8.8e-5, history=np.array([8.8e-5, 9.6e-4]),
        history_status=np.array([0, 0]), params={"initial_deformation:shared": np.float64(3e-3)},
        initial_params={"initial_deformation:shared": np.float64(2e-3)},
        bounds={"initial_deformation:shared": (np.float64(2.5e-4), np.float64(5e-3))}, evaluation=ev,
        status=TuneStatus.STALLED, iterations=1, evaluations=3, not_converged_evaluations=0, method="scipy_lbfgsb",
        message=TuneStatus.STALLED.message, start_value=8.8e-5)
    hand_tuned = HandTuneResult(
        qpos=np.zeros(4), wrist=np.zeros(6), grasp=None, value=2e-4, start_value=1e-4, deepest=-1e-3,
        start_deepest=-1e-3, history=np.array([1e-4, 2e-4]), depth_history=np.array([-1e-3, -1e-3]),
        status=TuneStatus.CONVERGED, iterations=1, evaluations=2, message="the projected gradient vanished")
    hand_value = HandValue(value=1e-4, grad_qpos=np.zeros(4), grad_wrist=np.zeros(6), evaluation=ev,
                           deepest=-1e-3, tilt=np.zeros(2))
    plan = PlanResult(
        status=PlanStatus.FOUND, grasps=(jaxgrasp.MeshGrasp(cube, None, np.zeros(3)),), values=np.array([8.8e-5]),
        statuses=np.array([0]), limiting_kind=np.array([0]), limiting_contact=np.array([0]),
        epsilon=np.array([0.026]), refined=np.array([False]), mesh_positions=np.zeros((1, 2, 3)), sampled=10,
        valid=4, rule_failures={"flatness": 6}, stable=1, dropped=0, refine_tried=0, refine_kept=0, seed=0,
        elapsed_s=1.25, settings={"fingers": 2, "gravity": np.array([0.0, 0.0, -9.81])})
    hand_plan = HandPlanResult(
        status=PlanStatus.FOUND, grasps=(None,), values=np.array([1e-3]), statuses=np.array([0]), active=np.array([3]),
        penetration=np.array([-2e-4]), self_overlap=np.array([-1e-3]), epsilon=np.array([0.1]), refined=np.array([True]), qpos=np.zeros((1, 4)),
        wrist=np.zeros((1, 6)), candidates=64, evaluated=60, eligible=50, stable=5, refine_tried=3, refine_kept=2,
        seed=0, elapsed_s=12.5, timings={"close": 5.0}, settings={"objective": "value", "gravity": np.zeros(3)})
    hold = Trial(kind="hold", success=True, max_displacement_m=1e-4, max_rotation_rad=1e-3, slipped_contact=None,
                 slip_time_s=None, time_s=np.array([0.0, 0.5]), displacement_m=np.array([0.0, 1e-4]),
                 rotation_rad=np.array([0.0, 1e-3]), max_sliding_m=np.zeros(2))
    simulated = SimulationResult(
        status=SimulationStatus.SIMULATED, grasp_status="stable", value=8.8e-5, reason="", hold=hold,
        six_axis=(dataclasses.replace(hold, kind="six_axis", axis="+x", success=False),), kicks=(),
        settled_normal_force_N=np.array([2.0, np.nan]), model_normal_force_N=np.array([2.0, 2.0]),
        parameters={"timestep_s": 1e-3})
    not_simulated = SimulationResult(  # a bare int, as before: taken as its SimulationStatus
        status=1, grasp_status="unstable", value=0.0, reason="unstable: ...", hold=None, six_axis=(), kicks=(),
        settled_normal_force_N=np.full(2, np.nan), model_normal_force_N=np.full(2, np.nan), parameters={})
    lane = SolverResult(x=np.zeros(6), lam=np.zeros(4), nu=np.float64(0.0), objective=np.float64(-1.5),
                        status=np.int32(0), stationarity=np.float64(1e-10), feasibility=np.float64(0.0),
                        complementarity=np.float64(np.inf), steps=np.int32(12))
    return {
        "Evaluation": [ev, batch[1]],
        "BatchResult": [batch, BatchResult.from_arrays(batch.arrays())],
        "SweepResult": [sweep, SweepResult.from_npz(tmp_path / "sweep.npz"), sweep.max_over("young_modulus")[0]],
        "TuneResult": [tuned],
        "HandTuneResult": [hand_tuned],
        "HandValue": [hand_value],
        "RobustBatch": [robust],
        "RobustResult": [robust[0], robust[1]],
        "PlanResult": [plan, dataclasses.replace(plan, status=PlanStatus.NO_VALID, grasps=(), values=np.zeros(0))],
        "HandPlanResult": [hand_plan, dataclasses.replace(hand_plan, status=PlanStatus.NO_VALID, grasps=(),
                                                          values=np.zeros(0))],
        "SimulationResult": [simulated, not_simulated],
        "EpsilonResult": [jaxgrasp.epsilon(cube), EpsilonResult(np.array([0.1, -0.2]), np.array([True, False]),
                                                                np.array([0.05, 0.05]), 8, True)],
        "SolverResult": [lane],
    }


def convention_offenders(name: str, r) -> list[str]:
    """What ``r``, an instance of result type ``name``, lacks of the convention."""
    out = []
    say = lambda what: out.append(f"{name}: {what}")  # noqa: E731
    if name in BATCHED_RESULTS:
        codes, names = np.asarray(r.status), np.asarray(r.status_names)
        if not np.issubdtype(codes.dtype, np.integer) or names.shape != codes.shape:
            say(f"status {codes.dtype} {codes.shape} and status_names {names.shape}: codes and names by entry")
        if not all(type(x) is str for x in names.ravel().tolist()):
            say("status_names are not all str")
        if np.shape(r.value) != codes.shape:
            say(f"value {np.shape(r.value)} is not by entry, as status {codes.shape}")
    elif name not in WITHOUT_STATUS:
        if name in PYTREE_RESULTS:
            ok = np.shape(r.status) == () and np.issubdtype(np.asarray(r.status).dtype, np.integer)
        else:
            ok = isinstance(r.status, enum.Enum) and r.status_name == r.status.label
        if not ok:
            say(f"status {r.status!r} is not a named code")
        if type(r.status_name) is not str:
            say(f"status_name {r.status_name!r} is not a str")
    if name not in WITHOUT_VALUE and name not in BATCHED_RESULTS and np.ndim(r.value) != 0:
        if name != "EpsilonResult":  # one grasp's or a batch's, as its arrays
            say(f"value of shape {np.shape(r.value)}, not one number")
    if name in WITHOUT_VALUE and hasattr(r, "value"):
        say("a value, though listed as without one")
    if name in TIMED:
        if type(r.elapsed_s) is not float or not r.elapsed_s >= 0.0:
            say(f"elapsed_s {r.elapsed_s!r} is not seconds as a float")
        if hasattr(r, "compile_seconds") and r.elapsed_s != r.compile_seconds + r.run_seconds:
            say("elapsed_s is not compile_seconds + run_seconds")
    if name in TUNED and not (isinstance(r.start_value, float) and r.gain == r.value / r.start_value):
        say("no start_value (J) with gain = value / start_value")
    text = r.summary()
    if not (isinstance(text, str) and text.strip()):
        say("summary() is not text")
    d = r.to_dict()
    try:
        json.dumps(d, allow_nan=False)
    except (TypeError, ValueError) as exc:
        say(f"json.dumps(to_dict()) fails: {exc}")
    if name not in WITHOUT_STATUS:
        written = d.get("status", d.get("robust_status"))
        wanted = r.status_names.tolist() if name in BATCHED_RESULTS else r.status_name
        if written != wanted:
            say(f"to_dict() writes status {written!r}, not its name(s) {wanted!r}")
    return out


def test_every_result_follows_the_convention(tmp_path):
    types_ = result_types()
    built = built_results(tmp_path)
    missing = sorted(set(types_) - set(built))
    assert not missing, f"result types on a face with no instance in built_results(): {missing}"
    offenders = [f"{name} (unknown to result_types)" for name in sorted(set(built) - set(types_))]
    for name, instances in built.items():
        for r in instances:
            assert type(r) is types_.get(name, type(r)), (name, type(r))
            offenders += convention_offenders(name, r)
    _fail_if("departures from the results' convention", offenders)


def test_results_convention_details(tmp_path):
    """What the convention fixes beyond names: the numbers it derives, and how a file keeps them."""
    from jaxgrasp.simulation import SimulationStatus

    built = built_results(tmp_path)
    batch, again = built["BatchResult"][:2]
    assert batch.elapsed_s == again.elapsed_s == 1.75  # from the npz arrays' two timings
    assert built["SweepResult"][1].elapsed_s == 2.5
    assert batch.to_dict()["value"][1] is None and batch.to_dict()["status"][1] == "invalid"
    robust = built["RobustBatch"][0]
    assert robust.value.tolist() == [8.794009946243486e-05, 0.0] and robust[0].value == float(robust.nominal.value[0])
    plan, empty = built["PlanResult"]
    assert plan.value == 8.8e-5 and empty.value == 0.0 and not hasattr(plan, "best_value")
    assert json.loads(json.dumps(plan.to_dict()))["ranked"][0]["value_J"] == 8.8e-5
    simulated, not_simulated = built["SimulationResult"]
    assert not_simulated.status is SimulationStatus.UNSTABLE and int(not_simulated.status) == 1
    assert simulated.to_dict()["status"] == "simulated" and "value_J" in simulated.to_dict()
    tuned = built["TuneResult"][0]
    assert tuned.status_name == "stalled" and type(tuned.status_name) is str and tuned.status.label == "stalled"
    assert built["Evaluation"][0].summary().splitlines()[0] == "stable: value 8.794010e-05 J; limited by slip of contact 0"


@pytest.mark.slow
def test_real_results_follow_the_convention():
    """The same convention on what the entry points return (the cube: the 2-contact
    programs, the batch one in chunks of 4 as ``tests/analysis/test_robust.py``'s)."""
    from jaxgrasp.analysis import Uncertainty

    cube = jaxgrasp.presets.cube()
    squeezed = cube.replace(initial_deformation=np.full(2, 5e-3))  # infeasible
    robust = jaxgrasp.robust_batch([cube, squeezed], Uncertainty(friction=0.1), samples=2, chunk_size=4)
    real = {
        "Evaluation": [jaxgrasp.evaluate(cube), jaxgrasp.evaluate(squeezed)],
        "BatchResult": [jaxgrasp.evaluate_batch([cube, squeezed], chunk_size=4)],
        "SweepResult": [jaxgrasp.sweep(cube, young_modulus=[2e5, 6e5], chunk_size=4)],
        "RobustBatch": [robust],
        "RobustResult": [robust[0], robust[1]],
        "TuneResult": [jaxgrasp.tune(cube, ["initial_deformation:shared"], maxiter=2)],
        "EpsilonResult": [jaxgrasp.epsilon(cube)],
    }
    offenders = [line for name, rs in real.items() for r in rs for line in convention_offenders(name, r)]
    _fail_if("departures from the results' convention", offenders)
    assert real["Evaluation"][1].status_name == "infeasible" and robust[1].status_name == "estimated"
