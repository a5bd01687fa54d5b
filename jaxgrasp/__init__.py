"""jaxgrasp: energy-tolerance grasp stability (Tsuji et al.) as a batched, differentiable JAX evaluator.

The names here (``jaxgrasp.__all__``) are the public API. The implementation lives in
packages, each importing only from those before it in this list:

* `jaxgrasp.base`: what the solver and the model share: named integer codes, contractions;
* `jaxgrasp.solver`: a generic augmented-Lagrangian solver and its lane queue;
* `jaxgrasp.storage`: files written whole or not at all, folder locks, private folders;
* `jaxgrasp.model`: grasp fields, [`Grasp`][jaxgrasp.Grasp], the potential field (eq. 3-21);
* `jaxgrasp.surface`: meshes in JAX ([`Surface`][jaxgrasp.surface.Surface]), the contact rules;
* [`jaxgrasp.presets`][jaxgrasp.presets]: the paper's two grasps (Sec. VII);
* `jaxgrasp.io`: grasp files, datasets, meshes;
* `jaxgrasp.tolerance`: the method (eq. 1): problems, starts, settling, verdict;
* `jaxgrasp.engine`: [`evaluate`][jaxgrasp.evaluate] and [`evaluate_batch`][jaxgrasp.evaluate_batch], compiled stages,
  the executable store, checkpoints;
* `jaxgrasp.analysis`: [`sweep`][jaxgrasp.sweep], [`tune`][jaxgrasp.tune], [`epsilon`][jaxgrasp.epsilon], [`robust`][jaxgrasp.robust];
* `jaxgrasp.hands`: [`Hand`][jaxgrasp.Hand] from MJCF (the ``hands`` extra), [`tune_hand`][jaxgrasp.tune_hand];
* `jaxgrasp.planning`: [`plan`][jaxgrasp.plan], the best grasps on a mesh, by free fingertips or a hand;
* `jaxgrasp.simulation`: [`simulate`][jaxgrasp.simulate], the grasp in MuJoCo (extra ``jaxgrasp[sim]``);
* `jaxgrasp.plots` and `jaxgrasp.cli` (the ``jaxgrasp`` command).

The top level holds what a user calls and holds for the method itself, plus each
feature's entry points. One rule chooses its names: *the functions a user calls to
build, check, evaluate and store grasps, one or many, and to set up the process, with the
types passed in and returned and the error raised; and each feature's entry function (or
class)*. A
feature's own types (its results, statuses, uncertainty model), internals
([`LaneStatus`][jaxgrasp.solver.LaneStatus], [`Surface`][jaxgrasp.surface.Surface]) and
dict-level twins ([`jaxgrasp.io.grasp_from_dict`][jaxgrasp.io.grasp_from_dict]) live on the feature's package
face: ``jaxgrasp.analysis.SweepResult``, ``jaxgrasp.planning.PlanResult``,
``jaxgrasp.hands.HandTuneResult``, ``jaxgrasp.simulation.SimulationResult``.

Importing jaxgrasp turns on JAX's 64-bit mode (``jax_enable_x64``) for the whole process,
so that results are float64 without the user touching JAX's configuration, also where the
user's own ``jit``/``vmap``/``grad`` trace [`evaluate`][jaxgrasp.evaluate]. JAX fixes dtypes when it
traces, in the caller's mode: with x64 on only inside jaxgrasp's own calls, the user's
``jax.jit`` and ``jax.grad`` of [`evaluate`][jaxgrasp.evaluate] would mix float32 and float64 and fail,
and the user's own arrays would be float32. Set the environment variable
``JAX_ENABLE_X64`` (to ``0`` or ``1``) before importing to keep JAX's own setting: with
``JAX_ENABLE_X64=0`` jaxgrasp computes in float32. Every public function takes and
returns SI units (m, Pa, N, kg, J, rad).

That is the import's only process-wide change: it imports JAX and nothing else of
jaxgrasp. The names below are loaded when first used (PEP 562 ``__getattr__``,
`jaxgrasp._startup.attach`), as every package face's are, so that the ``jaxgrasp``
command, whose ``--version``, ``--help`` and argument errors need no JAX, reads its
command line cheaply: in the command (`jaxgrasp._startup.is_command_line`) the import
does not even load JAX, and the command turns float64 on itself once its command line is
read, before it loads the library. Everything else jaxgrasp sets for the process (the CPU device
count, the executable store on disk, where its messages go) is chosen at its first
use or by [`configure`][jaxgrasp.configure]; the guide's page "Process-wide settings"
(``docs/guide/caching.md``) lists each and when.

Quick start::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002)
    result = jaxgrasp.evaluate(grasp)
    result.value, result.status_name   # J, 'stable'
"""

import sys as _sys
from typing import TYPE_CHECKING

from jaxgrasp import _startup

if not _startup.is_command_line(list(getattr(_sys, "orig_argv", []))):
    _startup.enable_x64()  # before any array exists: the user's own arrays are float64 too

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its package face when first used
    from jaxgrasp import presets
    from jaxgrasp.analysis import epsilon, robust, robust_batch, sweep, tune
    from jaxgrasp.engine import BatchResult, configure, evaluate, evaluate_batch
    from jaxgrasp.hands import Hand, tune_hand  # mujoco is imported when a hand is read
    from jaxgrasp.io import GraspSet, from_mesh, load, load_dataset, save, save_dataset
    from jaxgrasp.surface import MeshGrasp
    from jaxgrasp.model import Grasp, GraspValueError, check, stack
    from jaxgrasp.planning import plan
    from jaxgrasp.simulation import simulate  # mujoco is imported when it runs
    from jaxgrasp.solver import SolverOptions
    from jaxgrasp.tolerance import EvaluateOptions, Evaluation, GraspStatus

__all__ = [
    # one grasp
    "Grasp",
    "stack",
    "presets",
    "check",
    "evaluate",
    "EvaluateOptions",
    "SolverOptions",
    "Evaluation",
    "GraspStatus",
    "GraspValueError",
    # files
    "load",
    "save",
    "from_mesh",
    "MeshGrasp",
    "load_dataset",
    "save_dataset",
    "GraspSet",
    # many grasps
    "evaluate_batch",
    "BatchResult",
    "configure",
    # features
    "sweep",
    "tune",
    "epsilon",
    "robust",
    "robust_batch",
    "plan",
    "simulate",
    "Hand",
    "tune_hand",
]

_load, _dir, _LAZY = _startup.attach(__name__)  # _LAZY: each name -> (its package face, the name)

_SUBMODULES = ("solver", "model", "surface", "presets", "io", "tolerance", "engine", "analysis", "hands",
               "planning", "simulation", "plots", "cli")
"""The packages (and the module ``presets``) that ``jaxgrasp.<name>`` loads when first used."""


def __getattr__(name: str):
    """Load a top-level name from its package face, or a subpackage, the first time it is used."""
    if name == "__version__":
        globals()[name] = _version()
        return globals()[name]
    if name not in _LAZY and name not in _SUBMODULES:
        raise AttributeError(f"module 'jaxgrasp' has no attribute {name!r}")
    _choose_cpu_devices()
    return _load(name)  # kept here for later uses


_DEVICES_CHOSEN = False


def _choose_cpu_devices() -> None:
    """At the first use of a top-level name: ask JAX for one CPU device per core
    (``jaxgrasp.engine.configure_cpu_devices``), before the program's first jaxgrasp array
    makes JAX start its devices, so that a script's batches run on every core without a
    call of [`configure`][jaxgrasp.configure]. Sets a JAX option only: no file, no handler. Where JAX runs
    already, or the user chose the count, it changes nothing."""
    global _DEVICES_CHOSEN
    if _DEVICES_CHOSEN or _startup.is_command_line(list(getattr(_sys, "orig_argv", []))):
        return  # the command chooses its devices in jaxgrasp.cli, after parsing
    _DEVICES_CHOSEN = True
    from jaxgrasp.engine import configure_cpu_devices

    try:
        configure_cpu_devices()
    except ValueError:  # a bad JAXGRASP_CPU_DEVICES: jaxgrasp.configure() says so in one line at first use
        pass


def __dir__() -> list[str]:
    return sorted(set(_dir()) | set(_SUBMODULES) | {"__version__"})


def _version() -> str:
    """The installed jaxgrasp's version: defined once, in ``pyproject.toml``, and carried
    by the package's installed metadata."""
    from importlib import metadata

    try:
        return metadata.version("jaxgrasp")
    except metadata.PackageNotFoundError:  # a source tree on sys.path that was never installed
        return "0+unknown"
