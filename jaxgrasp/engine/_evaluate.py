"""Energy-tolerance evaluation of a grasp (Tsuji et al., eq. 1), batched and differentiable.

[`evaluate`][jaxgrasp.evaluate] runs the engine's pipeline (`PIPELINE`),
which follows the paper's steps, one named function each:

1. solve the equilibrium problem and every boundary problem from its starts (the
   ``equilibrium``, ``lanes``, ``settle``, ``starts`` and ``finish`` stages);
2. keep the lowest converged start of each boundary problem
   (`best_starts`);
3. decide the grasp's status from the solver's outputs
   (`grasp_status`);
4. the minimum energies with their envelope-theorem derivatives
   (`energies`);
5. the value: the least boundary energy above ``U0``, or a soft minimum
   (`value_of`);
6. the [`Evaluation`][jaxgrasp.Evaluation] in SI units
   (`to_evaluation`).

Derivatives of ``value`` (and of every energy) are exact and cheap (envelope theorem, see
`jaxgrasp.tolerance.envelope_energy`). The derivative is that of the *selected* boundary: where two
boundaries tie for the minimum (e.g. the two contacts of a symmetric grasp) ``value`` has
a kink and the gradient is that of the one reported in ``limiting_*`` (a one-sided
derivative).

Where ``value`` is 0 because the grasp is unstable or infeasible, its gradient is exactly 0
(never NaN): the Lagrangian of a discarded problem is evaluated at a safe point (the
initial state, zero multipliers) so that no non-finite partial derivative can leak into
the zero cotangent.

With ``EvaluateOptions(smooth_min_temperature=T)`` the hard minimum over boundaries is
replaced by a soft minimum (log-sum-exp, temperature ``T`` in J): see
[`EvaluateOptions`][jaxgrasp.EvaluateOptions].
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.engine import _compile
from jaxgrasp.engine._settling import RETRY, check_settle, settle_then_retry
from jaxgrasp.engine._stages import run_inline, stage_functions
from jaxgrasp.engine._xla_options import latency_options
from jaxgrasp.model import Grasp
from jaxgrasp.tolerance import FIELDS as RESULT_FIELDS
from jaxgrasp.tolerance import EvaluateOptions, Evaluation, Problems, split_temperature

__all__ = ["evaluate", "evaluate_traced", "evaluate_batch_traced", "evaluate_compiled", "compiled_executable", "solve_problems"]


def _is_concrete(tree) -> bool:
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def evaluate(grasp: Grasp, options: EvaluateOptions = EvaluateOptions()) -> Evaluation:
    """Evaluate the energy tolerance of ``grasp`` (eq. 1 of Tsuji et al.).

    Args:
        grasp: a [`Grasp`][jaxgrasp.Grasp] (SI units). Under ``jax.vmap``, any field may
            carry a batch axis.
        options: [`EvaluateOptions`][jaxgrasp.EvaluateOptions].

    Returns:
        An [`Evaluation`][jaxgrasp.Evaluation] (SI units) with the value in J, a status, the
        limiting boundary, the equilibrium and every boundary problem's minimum.

    Raises:
        GraspValueError: a grasp with batch axes (its fields' shapes are those of one
            grasp inside ``jax.vmap``, so a batch needs ``jax.vmap(jaxgrasp.evaluate)``
            or [`jaxgrasp.sweep`][jaxgrasp.sweep]); or, for a concrete grasp, invalid fields (checked
            before anything is compiled).

    ``evaluate`` can be wrapped in ``jax.jit`` and ``jax.vmap`` and differentiated with
    ``jax.grad``/``jax.jacfwd`` (envelope theorem, `jaxgrasp.tolerance.envelope_energy`);
    a traced grasp becomes part of the caller's computation. Validation happens outside
    traced code only: a traced grasp's values are unknown when it is traced, so an invalid
    one (a negative friction, a NaN) is evaluated as given, with a meaningless result.
    Check traced or batched grasps with [`jaxgrasp.check`][jaxgrasp.check], which states the same
    rules as arrays (``jnp.where(jaxgrasp.check(g).valid, value, jnp.nan)``). A concrete grasp runs an
    executable compiled once per process for its shapes and options
    (`compiled_executable`), loaded from the executable store instead where the
    caches are on: by the settling policy `RETRY`, first
    the one without the settling stage, then, only if a problem did not settle, the one
    with it; the result is the traced path's.
    """
    _check_unbatched(grasp)
    if not _is_concrete(grasp):  # inside the caller's jit, vmap or grad
        return evaluate_traced(grasp, options)
    options, temperature = split_temperature(options)
    from jaxgrasp.model import check_grasp_inputs

    check_grasp_inputs(**grasp.to_numpy())
    leaves = jax.tree_util.tree_leaves(grasp)

    def run(settle: bool) -> dict:
        fn, _ = compiled_executable(grasp, options, settle=settle)
        return dict(zip(RESULT_FIELDS, fn(temperature, *leaves)))

    # one grasp rarely needs the settling stage: RETRY spares it the stage (see _settling)
    return Evaluation(**settle_then_retry(run(check_settle(RETRY)), lambda rows: run(True)))


def evaluate_traced(grasp: Grasp, options: EvaluateOptions, settle: bool = True) -> Evaluation:
    """[`evaluate`][jaxgrasp.evaluate] of a grasp inside the caller's trace (``jit``, ``vmap``), with or
    without the settling stage (``settle``, see
    `stage_functions`)."""
    options, temperature = split_temperature(options)
    return evaluate_compiled(grasp, temperature, options, settle)


def _check_unbatched(grasp) -> None:
    """One grasp, not a batch: a one-line error that points to ``jax.vmap`` otherwise
    (shapes are static, so this holds for traced grasps too; inside ``vmap`` they are
    those of one grasp)."""
    from jaxgrasp.model import FIELDS, GraspValueError

    if not isinstance(grasp, Grasp):
        raise GraspValueError(f"evaluate needs a jaxgrasp.Grasp, got {type(grasp).__name__}")
    batched = [
        f"{f.name} {tuple(np.shape(getattr(grasp, f.name)))}"
        for f in FIELDS
        if np.ndim(getattr(grasp, f.name)) > f.ndim
    ]
    if grasp.active is not None and np.ndim(grasp.active) > 1:
        batched.append(f"active {tuple(np.shape(grasp.active))}")
    if batched:
        more = f" and {len(batched) - 3} more" if len(batched) > 3 else ""
        raise GraspValueError(
            f"evaluate takes one grasp, but this one has batch axes ({', '.join(batched[:3])}{more}; "
            "one grasp has positions (N, 3), per-contact fields (N,), mass ()): "
            "use jax.vmap(jaxgrasp.evaluate)(grasp) for a batch, or jaxgrasp.sweep for a grid"
        )


def compiled_executable(grasp: Grasp, options: EvaluateOptions, settle: bool = True):
    """The compiled `evaluate_compiled` (with ``settle``) for grasps shaped like the
    concrete ``grasp``; ``(fn, seconds)``.

    ``fn(temperature, *jax.tree_util.tree_leaves(grasp))`` takes the soft-minimum
    temperature (mJ, ``()`` float) and the grasp's fields (with a contact mask, ``active``
    last) and returns every [`Evaluation`][jaxgrasp.Evaluation] field (`RESULT_FIELDS`).
    It comes from `jaxgrasp.engine._compile.compiled`, as the batches' executables do:
    memoised in the process and, where the executable store is on, loaded from it instead of built
    (``seconds``: the time to build it, 0 on a memo hit). Its results are those of
    `evaluate_compiled` bit for bit (the same computation).
    """
    leaves, treedef = jax.tree_util.tree_flatten(grasp)
    avals = tuple((np.shape(x), _compile.canonical_dtype(x).name) for x in leaves)
    x64 = jax.config.jax_enable_x64
    spec = [jax.ShapeDtypeStruct((), _compile.canonical_dtype(np.float64(0.0)))]
    spec += [jax.ShapeDtypeStruct(shape, dtype) for shape, dtype in avals]

    def build():
        def evaluate_fields(temperature, *leaves):  # arrays in, arrays out: the store keeps flat executables
            r = evaluate_compiled(jax.tree_util.tree_unflatten(treedef, leaves), temperature, options, settle)
            return tuple(getattr(r, f) for f in RESULT_FIELDS)

        return jax.jit(evaluate_fields, compiler_options=latency_options(_compile.default_device().platform))

    masked = grasp.active is not None
    return _compile.compiled(
        ("evaluate", options, settle, masked, avals, x64, jax.config.jax_default_device),
        build,
        spec,
        name="evaluate_settled" if settle else "evaluate",
        what=f"evaluate for {np.shape(grasp.positions)[0]} contacts",
        store_key=(options, settle, masked, avals, x64),
        n_outputs=len(RESULT_FIELDS),
    )


def _one(grasp: Grasp) -> Grasp:
    """``grasp`` as a batch of one (a leading axis of 1 on every field)."""
    return jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], grasp)


def _first(tree):
    return jax.tree_util.tree_map(lambda a: a[0], tree)


@partial(jax.jit, static_argnames=("options", "settle"))
def evaluate_compiled(grasp: Grasp, temperature, options: EvaluateOptions, settle: bool = True) -> Evaluation:
    """The jitted evaluator behind [`evaluate`][jaxgrasp.evaluate] (no input validation): the pipeline
    (`run_inline`) on a batch of one; ``settle`` as in
    `stage_functions`.

    ``temperature`` is the soft-minimum temperature in mJ (``0``: the hard minimum) as a
    traced argument, so tuning at any temperature shares one compilation;
    ``options.smooth_min_temperature`` is ignored.
    """
    return _first(run_inline(_one(grasp), stage_functions(options, settle, temperature)))


def evaluate_batch_traced(grasps: Grasp, options: EvaluateOptions, settle: bool = True) -> Evaluation:
    """`evaluate_traced` of a batch of grasps (leading axis ``B`` on every field,
    ``active`` included where given), the result with a leading ``B``: the pipeline run
    inline on the whole batch, so the solver's work queue is traced once for it."""
    return run_inline(grasps, stage_functions(options, settle))


@partial(jax.jit, static_argnames=("options", "settle"))
def solve_problems(grasp: Grasp, options: EvaluateOptions = EvaluateOptions(), settle: bool = True) -> Problems:
    """Every problem of ``grasp`` solved, lane by lane (for diagnostics and benchmarks;
    [`evaluate`][jaxgrasp.evaluate] is this plus the verdict): the pipeline up to its ``problems``."""
    return _first(run_inline(_one(grasp), stage_functions(options, settle), until="problems"))
