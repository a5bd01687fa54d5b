"""XLA compiler options of the executables jaxgrasp compiles."""

from __future__ import annotations

__all__ = ["COMPILER_OPTIONS", "LATENCY_CPU_OPTIONS", "latency_options"]


def _jaxlib_version() -> tuple[int, ...]:
    from jaxlib.version import __version__  # no backend is started by this import

    return tuple(int(part) for part in __version__.split(".")[:3] if part.isdigit())


_YNN_FUSION_JAXLIB = (0, 8, 1)  # the first jaxlib whose XLA has xla_cpu_experimental_ynn_fusion_type
_NO_LEGACY_EMITTERS_JAXLIB = (0, 11, 0)  # from here XLA has no xla_cpu_use_fusion_emitters (0.11.2 rejects it)

COMPILER_OPTIONS = {
    **({"xla_cpu_use_fusion_emitters": False} if _jaxlib_version() < _NO_LEGACY_EMITTERS_JAXLIB else {}),
    **({"xla_cpu_experimental_ynn_fusion_type": ""} if _jaxlib_version() >= _YNN_FUSION_JAXLIB else {}),
}
"""XLA options every jaxgrasp executable is compiled with (``jax.jit(..., compiler_options=...)``).

* ``xla_cpu_use_fusion_emitters`` off: on the CPU, XLA's newer fusion emitters take
  longer to compile jaxgrasp's solver loop and run it no better; without them the
  results are the same to the last digit. XLA dropped the option (and the older
  emitters) in jaxlib 0.11, whose XLA refuses to compile with it, so it is set only
  before that.
* ``xla_cpu_experimental_ynn_fusion_type`` empty (no YNNPACK fusion): from jaxlib 0.8.1
  on, XLA hands small products and reductions to YNNPACK kernels, but on the solver's
  arrays (a few hundred lanes of ``6 x 6`` and ``3N x 6`` pieces) XLA's own fused loops
  do better, the more so where the Jacobian's and the Hessian's small products are
  written to fuse (`jaxgrasp.tolerance._problems._first_order`). Results change
  by rounding only. Older jaxlib does not know the option, so it is set only where it
  exists.

Other backends ignore both options (XLA checks only that it knows their names). JAX takes compiler options only on the outermost
``jax.jit``: jaxgrasp passes them where it compiles an executable itself (batches,
sweeps, tuning, [`jaxgrasp.evaluate`][jaxgrasp.evaluate] of a concrete grasp); pass them to your own
outermost ``jax.jit`` around [`jaxgrasp.evaluate`][jaxgrasp.evaluate] to get the same."""

LATENCY_CPU_OPTIONS = {**COMPILER_OPTIONS, "xla_backend_optimization_level": 0}
"""XLA options of the CPU executables whose first result matters more than their time per
call: the executable [`jaxgrasp.evaluate`][jaxgrasp.evaluate] compiles for one concrete grasp, and the
batch engine's ``evaluation`` stage, which runs once per chunk after the solver.

LLVM's optimisation passes are skipped: they take much of the compile and pay for
themselves only over many calls; the value agrees to 2 ulp. For an executable called
once the compile dominates. The executables that run the solver over many grasps (the batch
engine's solver stages, tuning) keep `COMPILER_OPTIONS`: there the calls dominate,
and a lower optimisation level would cost throughput. Other backends use
`COMPILER_OPTIONS` for both."""


def latency_options(platform: str) -> dict:
    """The XLA options of an executable whose first result matters more than its time per
    call, on a device of ``platform`` (``"cpu"``, ``"gpu"``, ...): `LATENCY_CPU_OPTIONS`
    on the CPU, `COMPILER_OPTIONS` elsewhere."""
    return LATENCY_CPU_OPTIONS if platform == "cpu" else COMPILER_OPTIONS
