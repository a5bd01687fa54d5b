"""jaxgrasp: energy-tolerance grasp stability (Tsuji et al.) as a batched, differentiable JAX evaluator.

Importing jaxgrasp turns on JAX's 64-bit mode (``jax_enable_x64``) for the whole process,
so that results are float64 without the user touching JAX's configuration, also where the
user's own ``jit``/``vmap``/``grad`` trace :func:`evaluate` (JAX fixes dtypes when it
traces, in the caller's mode: ``experiments/x64_scope.py`` measures what a narrower scope
breaks). Set the environment variable ``JAX_ENABLE_X64`` (to ``0`` or ``1``) before
importing to keep JAX's own setting: with ``JAX_ENABLE_X64=0`` jaxgrasp computes in
float32. It also asks JAX for one CPU device per core, so that batches and sweeps run on
every core (``JAXGRASP_CPU_DEVICES=1`` keeps JAX's single device; see
:mod:`jaxgrasp.cores`). Every public function takes and returns SI units (m, Pa, N, kg, J, rad).

Compilation takes seconds in every new process unless the caches on disk are on: call
:func:`enable_compilation_cache` once, or set the environment variable
``JAXGRASP_CACHE_DIR`` to a folder before importing (see :mod:`jaxgrasp.cache`). The
``jaxgrasp`` command turns them on by itself.

Quick start::

    import jaxgrasp
    grasp = jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002)
    result = jaxgrasp.evaluate(grasp)
    result.value, result.status_name   # J, 'stable'
"""

import os as _os

from . import startup as _startup

_startup.install_if_command_line()  # Ctrl-C while JAX loads: one line, exit 130 (the program only)

import jax as _jax  # noqa: E402

if "JAX_ENABLE_X64" not in _os.environ:  # an explicit choice of the user's stands
    _jax.config.update("jax_enable_x64", True)

from . import cores as _cores  # noqa: E402

_cores.configure_cpu_devices()  # one CPU device per core: batches run on every core

from . import cache  # noqa: E402

cache.enable_from_environment()  # $JAXGRASP_CACHE_DIR set: every process starts warm

from . import presets  # noqa: E402
from .evaluate import evaluate  # noqa: E402
from .options import COMPILER_OPTIONS, EvaluateOptions  # noqa: E402
from .grasp import STANDARD_GRAVITY, Grasp, stack  # noqa: E402
from .gripfile import grasp_from_dict, grasp_to_dict, load, save  # noqa: E402
from .mesh import MeshGrasp, from_mesh  # noqa: E402  (trimesh is imported when a mesh is used)
from .dataset import GraspSet, load_batch, save_batch  # noqa: E402
from .model import KINDS  # noqa: E402
from .status import BoundaryKind, GraspStatus, LaneStatus, TuneStatus  # noqa: E402
from .result import (  # noqa: E402
    INFEASIBLE,
    INVALID,
    NOT_CONVERGED,
    STABLE,
    STATUS_NAMES,
    UNSTABLE,
    Evaluation,
)
from .solver import SolverOptions  # noqa: E402
from .batch import evaluate_batch  # noqa: E402
from .batch_result import BatchResult  # noqa: E402
from .ferrari_canny import EpsilonResult, epsilon  # noqa: E402
from .sweep import PARAMETERS, SweepResult, sweep  # noqa: E402
from .tune import TuneResult, tune  # noqa: E402
from .validation import GraspValueError  # noqa: E402
from .cache import enable_compilation_cache  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "Grasp",
    "stack",
    "STANDARD_GRAVITY",
    "evaluate",
    "EvaluateOptions",
    "COMPILER_OPTIONS",
    "SolverOptions",
    "Evaluation",
    "STATUS_NAMES",
    "STABLE",
    "UNSTABLE",
    "INFEASIBLE",
    "NOT_CONVERGED",
    "INVALID",
    "KINDS",
    "GraspStatus",
    "LaneStatus",
    "BoundaryKind",
    "TuneStatus",
    "load",
    "save",
    "grasp_from_dict",
    "grasp_to_dict",
    "from_mesh",
    "MeshGrasp",
    "load_batch",
    "save_batch",
    "GraspSet",
    "presets",
    "evaluate_batch",
    "BatchResult",
    "sweep",
    "SweepResult",
    "epsilon",
    "EpsilonResult",
    "PARAMETERS",
    "tune",
    "TuneResult",
    "GraspValueError",
    "enable_compilation_cache",
]
