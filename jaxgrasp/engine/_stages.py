"""The batch engine's evaluator as five compiled programs, and the driver that calls them.

:func:`jaxgrasp.engine._evaluate.evaluate_batch_traced` is the batch's evaluation as one traced
function. The batch engine (:func:`jaxgrasp.engine._batch.compiled_evaluator`) compiles the same
work as these stages (a :class:`jaxgrasp.engine._pipeline.Pipeline`), each a function of the
batch's :class:`~jaxgrasp.Grasp` fields (:func:`jaxgrasp.engine._batch.grasp_fields`) and of
earlier stages' results, flat arrays in and out (the program store keeps flat programs):

1. ``equilibrium``: the lanes of the grasps' equilibrium problems
   (:func:`~jaxgrasp.tolerance._starts.equilibrium_starts`);
2. ``lanes``: lanes solved (:func:`~jaxgrasp.tolerance._stages.solve_stage`), every grasp's in
   one work queue: called twice per batch, on the equilibrium's lanes and then on the
   boundary problems';
3. ``starts``: the boundary problems' lanes from the solved equilibria
   (:func:`~jaxgrasp.tolerance._starts.boundary_starts`);
4. ``finish``: the solved :class:`~jaxgrasp.tolerance._problems.Problems`
   (:func:`~jaxgrasp.tolerance._stages.finish_problems`, with the settling stage where asked);
5. ``evaluation``: every :class:`~jaxgrasp.Evaluation` field (steps 2-6,
   :func:`~jaxgrasp.tolerance._verdict.evaluations_of`).

:func:`drive` calls them in that order. Why stages: the solver's loop is most of the
program (2.3 s of the default sweep's 3.4 s XLA compilation on 2 cores), and XLA
compiles it in a thread of its own while Python traces and lowers the rest, which is
then compiled beside it; in one program the rest had to be traced and lowered before
XLA could start (``experiments/BENCHMARK.md``). Each stage runs the functions that
:func:`~jaxgrasp.tolerance._stages.problems_of_batch` runs in one program, so the results are
the same to rounding.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import jax

from jaxgrasp.tolerance._options import EvaluateOptions
from jaxgrasp.tolerance._verdict import evaluations_of
from jaxgrasp.model._grasp import Grasp
from jaxgrasp.model._potential import model_params
from jaxgrasp.tolerance._starts import (
    LaneStarts,
    boundary_starts,
    equilibrium_of,
    equilibrium_starts,
)
from jaxgrasp.tolerance._problems import ProblemData, batch_data, problems_treedef
from jaxgrasp.tolerance._stages import finish_problems, solve_stage
from jaxgrasp.tolerance._result import FIELDS as RESULT_FIELDS
from jaxgrasp.solver._solver import SolverResult

__all__ = ["STAGES", "stage_functions", "drive"]

STAGES = ("equilibrium", "lanes", "starts", "finish", "evaluation")
"""The stages' names, in the order :func:`drive` first calls them."""

_LANES_IN = 4  # LaneStarts fields the solver takes: x0, eq_mask, nu0, active


def _tree(cls) -> jax.tree_util.PyTreeDef:
    """The pytree structure of a dataclass of array leaves (no shape needed)."""
    return jax.tree_util.tree_structure(cls(*(0,) * len(dataclasses.fields(cls))))


def stage_functions(options: EvaluateOptions, names: tuple[str, ...], settle: bool = True) -> dict[str, Callable]:
    """The five stages as functions of flat arrays (each returns a tuple of arrays), for
    a batch whose :class:`~jaxgrasp.Grasp` fields are ``names``, in that order, leading
    axis ``B`` on every array; ``settle`` as in :func:`~jaxgrasp.tolerance._stages.problems_of`."""
    n_fields = len(names)
    starts_tree, lanes_tree, programs_tree = _tree(LaneStarts), _tree(SolverResult), problems_treedef()
    n_lanes = lanes_tree.num_leaves

    def grasps(fields) -> Grasp:
        return Grasp(**dict(zip(names, fields)))

    def data(fields) -> ProblemData:
        return batch_data(jax.vmap(model_params)(grasps(fields)))

    def flat(tree) -> tuple:
        return tuple(jax.tree_util.tree_leaves(tree))

    def equilibrium(*fields):
        return flat(equilibrium_starts(data(fields), options))

    def lanes(*args):
        fields, (x0, eq_mask, nu0, active) = args[:n_fields], args[n_fields:]
        return flat(solve_stage(data(fields), LaneStarts(x0, eq_mask, nu0, active, None, None), options))

    def starts(*args):
        fields, eq_lanes = args[:n_fields], jax.tree_util.tree_unflatten(lanes_tree, args[n_fields:])
        return flat(boundary_starts(data(fields), equilibrium_of(eq_lanes), options))

    def finish(*args):
        fields, rest = args[:n_fields], args[n_fields:]
        eq_lanes = jax.tree_util.tree_unflatten(lanes_tree, rest[:n_lanes])
        solved = jax.tree_util.tree_unflatten(lanes_tree, rest[n_lanes : 2 * n_lanes])
        lane_starts = jax.tree_util.tree_unflatten(starts_tree, rest[2 * n_lanes :])
        return flat(finish_problems(data(fields), equilibrium_of(eq_lanes), solved, lane_starts, options, settle))

    def evaluation(*args):
        fields, progs = args[:n_fields], jax.tree_util.tree_unflatten(programs_tree, args[n_fields:])
        r = evaluations_of(grasps(fields), progs, options)
        return tuple(getattr(r, f) for f in RESULT_FIELDS)

    return dict(equilibrium=equilibrium, lanes=lanes, starts=starts, finish=finish, evaluation=evaluation)


def drive(call: Callable, *fields) -> tuple:
    """The batch's evaluation from its stages (:func:`stage_functions`), each run by
    ``call(name, *arrays)``: every :class:`~jaxgrasp.Evaluation` field
    (:data:`jaxgrasp.tolerance._result.FIELDS`), leading axis ``B``. A :class:`jaxgrasp.engine._pipeline.Pipeline`'s
    driver: it only passes arrays on."""
    eq_starts = call("equilibrium", *fields)
    eq_lanes = call("lanes", *fields, *eq_starts[:_LANES_IN])
    lane_starts = call("starts", *fields, *eq_lanes)
    solved = call("lanes", *fields, *lane_starts[:_LANES_IN])
    progs = call("finish", *fields, *eq_lanes, *solved, *lane_starts)
    return call("evaluation", *fields, *progs)
