"""jaxgrasp: energy-tolerance grasp stability (Tsuji et al.) as a batched, differentiable JAX evaluator.

The names here (``jaxgrasp.__all__``) are the public API. The implementation lives in
packages, each importing only from those before it in this list:

* :mod:`jaxgrasp.base`: what the solver and the model share: named integer codes, contractions;
* :mod:`jaxgrasp.solver`: a generic augmented-Lagrangian solver and its lane queue;
* :mod:`jaxgrasp.storage`: files written whole or not at all, folder locks, private folders;
* :mod:`jaxgrasp.model`: grasp fields, :class:`Grasp`, the potential field (eq. 3-21);
* :mod:`jaxgrasp.surface`: meshes in JAX (:class:`Surface`), the contact rules;
* :mod:`jaxgrasp.presets`: the paper's two grasps (Sec. VII);
* :mod:`jaxgrasp.io`: grasp files, datasets, meshes;
* :mod:`jaxgrasp.tolerance`: the method (eq. 1): problems, starts, settling, verdict;
* :mod:`jaxgrasp.engine`: :func:`evaluate` and :func:`evaluate_batch`, compiled stages,
  the executable store, checkpoints;
* :mod:`jaxgrasp.analysis`: :func:`sweep`, :func:`tune`, :func:`epsilon`, :func:`robust`;
* :mod:`jaxgrasp.planning`: :func:`plan`, the best grasps on a mesh;
* :mod:`jaxgrasp.hands`: :class:`Hand` from MJCF (the ``hands`` extra), :func:`tune_hand`;
* :mod:`jaxgrasp.simulation`: :func:`simulate`, the grasp in MuJoCo (extra ``jaxgrasp[sim]``);
* :mod:`jaxgrasp.plots` and :mod:`jaxgrasp.cli` (the ``jaxgrasp`` command).

Importing jaxgrasp turns on JAX's 64-bit mode (``jax_enable_x64``) for the whole process,
so that results are float64 without the user touching JAX's configuration, also where the
user's own ``jit``/``vmap``/``grad`` trace :func:`evaluate`. JAX fixes dtypes when it
traces, in the caller's mode: with x64 on only inside jaxgrasp's own calls, the user's
``jax.jit`` and ``jax.grad`` of :func:`evaluate` would mix float32 and float64 and fail,
and the user's own arrays would be float32. Set the environment variable
``JAX_ENABLE_X64`` (to ``0`` or ``1``) before importing to keep JAX's own setting: with
``JAX_ENABLE_X64=0`` jaxgrasp computes in float32. It also asks JAX for one CPU device
per core, so that batches and sweeps run on every core (``JAXGRASP_CPU_DEVICES=1`` keeps
JAX's single device; see :mod:`jaxgrasp.engine`). Every public function takes and
returns SI units (m, Pa, N, kg, J, rad).

Compiling an evaluator takes seconds. Importing jaxgrasp turns on its executable store
in the user's cache folder (``~/.cache/jaxgrasp/xla``, private): a later process loads
what an earlier one compiled (each compilation is reported once on the ``logging`` logger
``"jaxgrasp"``). The environment variable ``JAXGRASP_CACHE_DIR`` moves the folder, and
``JAXGRASP_CACHE_DIR=off`` switches it off. JAX's own persistent cache (for the user's
``jit`` functions too) is turned on only by :func:`enable_compilation_cache` and the
``jaxgrasp`` command (see :mod:`jaxgrasp.engine._store`).

Quick start::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002)
    result = jaxgrasp.evaluate(grasp)
    result.value, result.status_name   # J, 'stable'
"""

from jaxgrasp import _startup

# First of all: a Ctrl-C from here on, while JAX loads, is one line and exit 130 (in the
# command only). Every import above this line widens the window of Python's traceback.
_startup.install_if_command_line()

import os as _os  # noqa: E402
from importlib import metadata as _metadata  # noqa: E402

import jax as _jax  # noqa: E402

if "JAX_ENABLE_X64" not in _os.environ:  # an explicit choice of the user's stands
    _jax.config.update("jax_enable_x64", True)

from jaxgrasp.engine import configure_cpu_devices as _configure_cpu_devices  # noqa: E402

_configure_cpu_devices()  # before JAX makes its devices: batches run on every core

from jaxgrasp.engine import enable_from_environment as _enable_from_environment  # noqa: E402

_enable_from_environment()  # the executable store, in the user's cache folder: every process starts warm

from jaxgrasp import presets  # noqa: E402
from jaxgrasp.analysis import (  # noqa: E402
    EpsilonResult,
    SweepResult,
    TuneResult,
    TuneStatus,
    Uncertainty,
    epsilon,
    robust,
    robust_batch,
    sweep,
    tune,
)
from jaxgrasp.engine import BatchResult, enable_compilation_cache, evaluate, evaluate_batch  # noqa: E402
from jaxgrasp.hands import Hand, tune_hand  # noqa: E402  (mujoco is imported when a hand is read)
from jaxgrasp.io import (  # noqa: E402  (trimesh is imported when a mesh is used)
    GraspSet,
    from_mesh,
    grasp_from_dict,
    grasp_to_dict,
    load,
    load_dataset,
    save,
    save_dataset,
)
from jaxgrasp.model import BoundaryKind, Grasp, GraspValueError, check, stack  # noqa: E402
from jaxgrasp.planning import PlanResult, plan  # noqa: E402
from jaxgrasp.simulation import simulate  # noqa: E402  (mujoco is imported when it runs)
from jaxgrasp.solver import LaneStatus, SolverOptions  # noqa: E402
from jaxgrasp.surface import MeshGrasp, Surface  # noqa: E402
from jaxgrasp.tolerance import EvaluateOptions, Evaluation, GraspStatus  # noqa: E402

try:  # the version is defined once, in pyproject.toml; the installed metadata carries it
    __version__ = _metadata.version("jaxgrasp")
except _metadata.PackageNotFoundError:  # a source tree on sys.path that was never installed
    __version__ = "0+unknown"

__all__ = [
    # one grasp
    "Grasp",
    "stack",
    "presets",
    "evaluate",
    "EvaluateOptions",
    "SolverOptions",
    "Evaluation",
    # statuses
    "GraspStatus",
    "LaneStatus",
    "BoundaryKind",
    "TuneStatus",
    # files
    "load",
    "save",
    "grasp_from_dict",
    "grasp_to_dict",
    "from_mesh",
    "MeshGrasp",
    "load_dataset",
    "save_dataset",
    "GraspSet",
    "Surface",
    # many grasps and analyses
    "evaluate_batch",
    "BatchResult",
    "sweep",
    "SweepResult",
    "tune",
    "TuneResult",
    "plan",
    "PlanResult",
    "epsilon",
    "EpsilonResult",
    "robust",
    "robust_batch",
    "Uncertainty",
    "simulate",
    # hands
    "Hand",
    "tune_hand",
    # errors and set-up
    "GraspValueError",
    "check",
    "enable_compilation_cache",
]
