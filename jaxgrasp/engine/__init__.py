"""Running the method: one grasp or many, through one declared pipeline, compiled in
stages, sharded over the devices, kept in an executable store on disk, with checkpoints.

`PIPELINE` is the evaluation, step by step; [`evaluate`][jaxgrasp.evaluate] runs it inline under
the caller's trace (``jit``, ``vmap``, ``grad``), [`evaluate_batch`][jaxgrasp.evaluate_batch] and
`evaluate_dataset` run it one compiled stage at a time over chunks of grasps cut by
`plan_chunks`, in segments by contact count (`plan_segments`, each at the
width `plan_widths` gives it). `solve_problems` stops it at the solved problems.

[`configure`][jaxgrasp.configure] chooses the engine's process-wide settings (CPU devices, the executable
store, messages), else its first use does (`jaxgrasp.engine._setup`); long calls
report on the ``"jaxgrasp"`` logger (`ChunkProgress`, `jaxgrasp.engine._progress`).

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages and for the studies in ``experiments/``, not promised (the
faces' convention: ``docs/development.md``, "Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.engine._batch import evaluate_batch, evaluate_dataset
    from jaxgrasp.engine._batch_result import BatchResult
    from jaxgrasp.engine._evaluate import evaluate, solve_problems
    from jaxgrasp.engine._progress import ChunkProgress
    from jaxgrasp.engine._plan import ChunkPlan, SegmentPlan, plan_chunks, plan_segments, plan_widths
    from jaxgrasp.engine._setup import configure
    from jaxgrasp.engine._stages import PIPELINE, run_inline, stage_functions
    from jaxgrasp.engine._store import enable_compilation_cache
    from jaxgrasp.engine._xla_options import COMPILER_OPTIONS

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.engine._batch import evaluate_in_chunks
    from jaxgrasp.engine._batch_result import assemble, mark_invalid
    from jaxgrasp.engine._checkpoint import (BATCH_FOLDER, SWEEP_FILE, BatchCheckpoint, CheckpointBusy, SweepKeeper,
                                             run_key)
    from jaxgrasp.engine._compile import StoredFunction, wait_for_saves
    from jaxgrasp.engine._devices import configure_cpu_devices
    from jaxgrasp.engine._evaluate import evaluate_compiled
    from jaxgrasp.engine._gradient import value_and_grad_builder
    from jaxgrasp.engine._limits import CHUNK_SIZE_WHAT, MAX_CHUNK_SIZE
    from jaxgrasp.engine._plan import check_chunk_size, grasps_by_count
    from jaxgrasp.engine._prefetch import prefetch
    from jaxgrasp.engine._runner import GraspSource, Stacked, plan_source, run_batch, start_progress
    from jaxgrasp.engine._settling import INLINE, RETRY
    from jaxgrasp.engine._store import default_dir, enable_from_environment, log_lines_on_stderr, matplotlib_dir

    # For the studies in experiments/ (instruments): not in __all__, not promised to users (see the docstring).
    from jaxgrasp.engine._compile import clear_compiled
    from jaxgrasp.engine._evaluate import evaluate_batch_traced
    from jaxgrasp.engine._evaluator import compiled_evaluator, over_devices
    from jaxgrasp.engine._plan import COMPILE_CPU_SECONDS, batch_sharding, default_chunk_size, grasp_cpu_seconds
    from jaxgrasp.engine._stages import inputs_of
    from jaxgrasp.engine._store import executable_dir, set_executable_dir, stats
    from jaxgrasp.engine._xla_options import LATENCY_CPU_OPTIONS

__all__ = [
    "evaluate",
    "evaluate_batch",
    "evaluate_dataset",
    "BatchResult",
    "solve_problems",
    "PIPELINE",
    "run_inline",
    "stage_functions",
    "ChunkPlan",
    "plan_chunks",
    "SegmentPlan",
    "plan_segments",
    "plan_widths",
    "configure",
    "enable_compilation_cache",
    "ChunkProgress",
    "COMPILER_OPTIONS",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
