"""Running the method: one grasp or many, in stages compiled once, sharded over devices,
kept in an executable store on disk, with checkpoints.
"""

from jaxgrasp.engine._batch import evaluate_batch
from jaxgrasp.engine._batch_result import BatchResult
from jaxgrasp.engine._evaluate import evaluate
from jaxgrasp.engine._store import enable_compilation_cache
from jaxgrasp.engine._xla_options import COMPILER_OPTIONS

__all__ = [
    "evaluate",
    "evaluate_batch",
    "BatchResult",
    "enable_compilation_cache",
    "COMPILER_OPTIONS",
]
