"""XLA compiler options of the executables jaxgrasp compiles."""

from __future__ import annotations

__all__ = ['COMPILER_OPTIONS', 'LATENCY_CPU_OPTIONS']


def _jaxlib_version() -> tuple[int, ...]:
    from jaxlib.version import __version__  # no backend is started by this import

    return tuple(int(part) for part in __version__.split(".")[:3] if part.isdigit())

_YNN_FUSION_JAXLIB = (0, 8, 1)  # the first jaxlib whose XLA has the option below

COMPILER_OPTIONS = {
    "xla_cpu_use_fusion_emitters": False,
    **({"xla_cpu_experimental_ynn_fusion_type": ""} if _jaxlib_version() >= _YNN_FUSION_JAXLIB else {}),
}

"""XLA options every jaxgrasp program is compiled with (``jax.jit(..., compiler_options=...)``).

On the CPU, XLA's newer fusion emitters take twice as long to compile jaxgrasp's solver
loop and run it no faster; without them the cube's evaluator compiles in about half the
CPU time and runs ~15% faster, with the same results to the last digit
(``experiments/compile_time.py``). From jaxlib 0.8.1 on, XLA also hands small products
and reductions to YNNPACK kernels; on the solver's arrays (a few hundred lanes of 6 x 6
and 21 x 6 pieces) XLA's own loops are faster: with the option empty (no YNNPACK
fusion) a random batch runs ~8 % faster, and ~18 % faster once the Jacobian's and the
Hessian's small products are fused (:func:`jaxgrasp.tolerance._problems._first_order`;
``experiments/BENCHMARK.md``); results change by rounding only.
Older jaxlib does not know the option, so it is set only where it exists. Other backends
ignore both options. JAX takes compiler
options only on the outermost ``jax.jit``: jaxgrasp passes them where it compiles a
program itself (batches, sweeps, tuning, :func:`jaxgrasp.evaluate` of a concrete grasp);
pass them to your own outermost ``jax.jit`` around :func:`jaxgrasp.evaluate` to get the
same."""

LATENCY_CPU_OPTIONS = {**COMPILER_OPTIONS, "xla_backend_optimization_level": 0}

"""XLA options of the CPU programs whose first result matters more than their time per
call: the program :func:`jaxgrasp.evaluate` compiles for one concrete grasp, and the
batch engine's evaluation stage (:func:`jaxgrasp.engine._batch.compiled_evaluator`), which runs
once per chunk after the solver.

Without LLVM's optimisation passes the cube's one-grasp program compiles in about half
the time (1.1-1.25 s against 2.2-2.3 s on 2 cores) and a call takes 16-17 ms instead of
9-10 ms; the value agrees to 2 ulp (``experiments/compile_time.py``). The programs that
run the solver over many grasps (the batch engine's first stage, tuning) keep
:data:`COMPILER_OPTIONS`: level 1 there already costs 10 % of a random set's rate. Other
backends use :data:`COMPILER_OPTIONS` for both."""
