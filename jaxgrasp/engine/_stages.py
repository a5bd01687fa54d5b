"""The evaluation pipeline, declared once, and its two runners.

`PIPELINE` lists the method's stages in order (Tsuji et al., eq. 1: the equilibrium
problem, then the 2N boundary problems from starts around the equilibrium, then the
verdict), each a `Step` naming the values it reads and the value it makes. Every
path of jaxgrasp runs this one list:

* `run_inline` runs it under the caller's trace (``jit``, ``vmap``, ``grad``):
  [`jaxgrasp.evaluate`][jaxgrasp.evaluate] and [`jaxgrasp.tune`][jaxgrasp.tune]. The solve stage, which occurs
  twice, is traced once: its occurrences are the iterations of a loop.
* `run_staged` runs it one compiled stage at a time on flat arrays (the stages of
  `flat_stages`, each compiled once, sharded over the devices and kept in the
  executable store): [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] and [`jaxgrasp.sweep`][jaxgrasp.sweep].

The stages are the method's functions (`jaxgrasp.tolerance`), bound to the options
by `stage_functions`; each takes the batch's data or parameters (`inputs_of`,
derived once from the grasps; leading axis ``B``) and the earlier values it names.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp

from jaxgrasp.model import Grasp, model_params
from jaxgrasp.solver import SolverResult
from jaxgrasp.tolerance import (
    EvaluateOptions,
    Evaluation,
    LaneStarts,
    batch_data,
    boundary_starts,
    depend_on,
    equilibrium_starts,
    evaluations_of,
    finish_problems,
    problems_treedef,
    settled_equilibrium,
    solve_stage,
    split_temperature,
    unsolved,
)

__all__ = [
    "Step",
    "PIPELINE",
    "STAGES",
    "EXECUTABLES",
    "SOLVE",
    "INPUTS",
    "inputs_of",
    "stage_functions",
    "run_inline",
    "flat_stages",
    "run_staged",
]


def _tree(cls) -> jax.tree_util.PyTreeDef:
    """The pytree structure of a dataclass of array leaves (it depends on no shape)."""
    return jax.tree_util.tree_structure(cls(*(0,) * len(dataclasses.fields(cls))))


@dataclasses.dataclass(frozen=True)
class Step:
    """One step of the pipeline: ``output = stage(*inputs)``.

    Attributes:
        stage: the stage's name (a key of `stage_functions`).
        inputs: names of the values it reads: an input of the pipeline (`INPUTS`)
            or an earlier step's output.
        output: the name of the value it makes.
        tree: the pytree structure of that value (to pass it between compiled stages
            as flat arrays).
        compiled_with: where the pipeline runs one compiled stage at a time
            (`run_staged`), the stage of a later step whose executable runs this
            step first (``None``: its own executable).
    """

    stage: str
    inputs: tuple[str, ...]
    output: str
    tree: Callable[[], jax.tree_util.PyTreeDef]
    compiled_with: str | None = None


SOLVE = "lanes"
"""The stage that runs the solver: every lane of every grasp in one work queue."""

PIPELINE: tuple[Step, ...] = (
    Step("equilibrium", ("data",), "eq_starts", lambda: _tree(LaneStarts)),
    Step(SOLVE, ("data", "eq_starts"), "eq_lanes", lambda: _tree(SolverResult)),
    Step("settle", ("data", "eq_lanes"), "eq", lambda: _tree(SolverResult), compiled_with="starts"),
    Step("starts", ("data", "eq"), "lane_starts", lambda: _tree(LaneStarts)),
    Step(SOLVE, ("data", "lane_starts"), "solved", lambda: _tree(SolverResult)),
    Step("finish", ("data", "eq", "solved", "lane_starts"), "problems", problems_treedef),
    Step("evaluation", ("params", "problems"), "evaluation", lambda: _tree(Evaluation)),
)
"""The evaluation of a batch of grasps, step by step: the equilibrium problem's lanes,
solved; each grasp's equilibrium (settled where asked); the boundary problems' lanes from
starts around that equilibrium, solved; the solved `Problems`
(settled where asked); every [`Evaluation`][jaxgrasp.Evaluation] field (the verdict, steps 2-6
of the method). The equilibrium is its own step because two later steps read it: made
once, it is traced and compiled once. Run one compiled stage at a time, it shares the
starts stage's executable (without settling it is a mere selection, not worth a call)."""

STAGES = tuple(dict.fromkeys(s.stage for s in PIPELINE))
"""The stages' names, in the order the pipeline first calls them."""


def _calls() -> tuple[tuple[str, tuple[Step, ...]], ...]:
    """`PIPELINE` as `run_staged` calls it: ``(executable, steps)`` pairs, a
    step that is ``compiled_with`` a later stage run by that stage's next executable."""
    calls, waiting = [], []
    for step in PIPELINE:
        if step.compiled_with is not None:
            waiting.append(step)
            continue
        calls.append((step.stage, (*(w for w in waiting if w.compiled_with == step.stage), step)))
        waiting = [w for w in waiting if w.compiled_with != step.stage]
    if waiting:
        raise ValueError(f"no later step of the pipeline has the stage {waiting[0].compiled_with!r}")
    return tuple(calls)


CALLS = _calls()
"""``(executable, steps)``: the calls of `run_staged`, in order."""

EXECUTABLES = tuple(dict.fromkeys(name for name, _ in CALLS))
"""The names of the executables `flat_stages` makes, in the order they are first
called: the stages, less those ``compiled_with`` another."""


def _outer_inputs(steps: tuple[Step, ...]) -> tuple[str, ...]:
    """The values ``steps`` (run in order) read and do not make themselves, in order."""
    made = {s.output for s in steps}
    return tuple(dict.fromkeys(n for s in steps for n in s.inputs if n not in made))


INPUTS = ("params", "data")
"""The pipeline's inputs, both derived from the batch of grasps by `inputs_of`."""


def inputs_of(grasps: Grasp) -> dict[str, Any]:
    """The pipeline's inputs for a batch of grasps (leading axis ``B``): ``params``, the
    grasps in internal units (`jaxgrasp.model.model_params`, differentiable: the
    verdict's envelope derivatives go through them), and ``data``, the problems' data
    (`batch_data`, no gradient: the solver sees none)."""
    params = jax.vmap(model_params)(grasps)
    return {"params": params, "data": batch_data(params)}


def stage_functions(options: EvaluateOptions, settle: bool = True, temperature=None) -> dict[str, Callable]:
    """Each stage of `PIPELINE` as a function of the values its step names (the
    pipeline's inputs, `inputs_of`, and earlier steps' outputs; leading axis ``B``).

    ``settle`` (static): whether the settle stage certifies a stalled equilibrium
    (`settle_equilibrium`) and the finish stage stalled
    boundary lanes (`settle_stalled`);
    without it the stages are smaller, and equal wherever no problem ends unsettled. ``temperature``: the
    soft-minimum temperature (mJ, ``0`` for the hard minimum; traced or not); default the
    options' own.
    """
    if temperature is None:
        options, temperature = split_temperature(options)
    return {
        "equilibrium": lambda data: equilibrium_starts(data, options),
        SOLVE: lambda data, starts: solve_stage(data, starts, options),
        "settle": lambda data, eq_lanes: settled_equilibrium(data, eq_lanes, options, settle),
        "starts": lambda data, eq: boundary_starts(data, eq, options),
        "finish": lambda data, eq, lanes, starts: finish_problems(data, eq, lanes, starts, options, settle),
        "evaluation": lambda params, problems: evaluations_of(params, problems, temperature, options),
    }


def _call(functions: Mapping[str, Callable], step: Step, env: Mapping[str, Any]):
    return functions[step.stage](*(env[name] for name in step.inputs))


def _through(until: str) -> tuple[Step, ...]:
    """The steps of `PIPELINE` up to the one that makes ``until``."""
    outputs = [s.output for s in PIPELINE]
    if until not in outputs:
        raise ValueError(f"no step of the pipeline makes {until!r}; its values are {outputs}")
    return PIPELINE[: outputs.index(until) + 1]


def run_inline(grasps: Grasp, functions: Mapping[str, Callable], until: str = "evaluation"):
    """Run `PIPELINE` on the batch ``grasps`` under the caller's trace, up to the
    value ``until``, which it returns (leading axis ``B``); ``functions`` from
    `stage_functions`.

    The solve stage occurs once per round (a round: the steps after the previous solve,
    the last of which makes lanes' starts, then `SOLVE`); the rounds are the
    iterations of one loop (`_solved_rounds`), so the solver's loop is traced and
    compiled once rather than once per round.
    """
    steps = _through(until)
    solves = [i for i, s in enumerate(steps) if s.stage == SOLVE]
    env: dict[str, Any] = inputs_of(grasps)
    if solves:
        rounds = [(steps[a:i], steps[i]) for a, i in zip([0] + [i + 1 for i in solves[:-1]], solves)]
        steps = steps[solves[-1] + 1 :]
        env.update(_solved_rounds(rounds, _read_later(rounds, steps, until), functions, env))
    for step in steps:
        env[step.output] = _call(functions, step, env)
    return env[until]


def _read_later(rounds, after, until: str) -> set[str]:
    """The values the ``rounds`` (each ``(steps before the solve, solve step)``) make that
    a later round's steps, a step ``after`` them, or the caller (``until``) reads: what
    the loop carries."""
    made = [(k, name) for k, (pre, v) in enumerate(rounds) for name in (*(s.output for s in pre), v.output)]
    later = {until} | {n for step in after for n in step.inputs}
    read = lambda k: {n for pre, v in rounds[k + 1 :] for step in (*pre, v) for n in step.inputs}  # noqa: E731
    return {name for k, name in made if name in later or name in read(k)}


def _solved_rounds(rounds, carried: set[str], functions: Mapping[str, Callable], env: Mapping[str, Any]):
    """The values ``carried`` of those the ``rounds`` make (each ``(steps before the
    solve, solve step)``, the last of those steps making the solve's starts), the solve
    stage traced once: round ``k`` is iteration ``k`` of a ``fori_loop``, whose body runs
    the round's steps in the branch ``k`` of a ``lax.switch``. The counter is not batched
    data, so under a caller's ``vmap`` the switch stays a branch and the solver's queue
    runs once per round on every lane of the batch.

    The loop's carry starts as zeros shaped as each value (``jax.eval_shape``); the steps
    are jitted, so that the branch reuses the trace their shapes were read from."""
    for pre, solve in rounds:
        if not pre or solve.inputs[-1] != pre[-1].output or any(n not in INPUTS for n in solve.inputs[:-1]):
            raise ValueError(f"the pipeline's {solve.output!r} must solve the starts made just before it")
    jitted = {s.stage: jax.jit(functions[s.stage]) for pre, _ in rounds for s in pre}
    shapes = dict(env)
    for pre, solve in rounds:
        for s in pre:
            shapes[s.output] = jax.eval_shape(jitted[s.stage], *(shapes[n] for n in s.inputs))
        shapes[solve.output] = jax.eval_shape(unsolved, shapes[pre[-1].output])
    carry = {n: jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes[n]) for n in sorted(carried)}
    carry = depend_on(carry, env["data"])

    def branch(pre):
        def run(carry):
            values = {**env, **carry}
            for s in pre:
                values[s.output] = jitted[s.stage](*(values[n] for n in s.inputs))
            return {n: values[n] for n in carry}, values[pre[-1].output]

        return run

    def body(k, carry):
        carry, starts = jax.lax.switch(k, [branch(pre) for pre, _ in rounds], carry)
        solved = functions[SOLVE](*(env[n] for n in rounds[0][1].inputs[:-1]), starts)
        out = dict(carry)
        for i, (_, v) in enumerate(rounds):
            if v.output not in carried:
                continue
            if i == len(rounds) - 1:  # written every round: the last round's is what stays
                out[v.output] = solved
            else:
                out[v.output] = jax.lax.cond(k == i, lambda x=solved: x, lambda n=v.output: carry[n])
        return out

    return jax.lax.fori_loop(0, len(rounds), body, carry)


def flat_stages(options: EvaluateOptions, names: tuple[str, ...], settle: bool = True) -> dict[str, Callable]:
    """The executables of `EXECUTABLES` as functions of flat arrays, for compiling
    one at a time (the executable store keeps flat executables): each runs its steps
    (`CALLS`; the stages of `stage_functions`), takes the batch's
    [`Grasp`][jaxgrasp.Grasp] fields ``names`` (from which it derives the pipeline's inputs,
    `inputs_of`), then the leaves of each earlier value its steps read, and returns
    the leaves of every value its steps make, as one tuple."""
    functions = stage_functions(options, settle)
    trees = {s.output: s.tree() for s in PIPELINE}

    def flat(steps: tuple[Step, ...]) -> Callable:
        def run(*arrays):
            env, rest = inputs_of(Grasp(**dict(zip(names, arrays)))), arrays[len(names) :]
            for name in _outer_inputs(steps):
                if name in INPUTS:
                    continue
                n = trees[name].num_leaves
                env[name] = jax.tree_util.tree_unflatten(trees[name], rest[:n])
                rest = rest[n:]
            out = []
            for step in steps:
                env[step.output] = _call(functions, step, env)
                out += jax.tree_util.tree_leaves(env[step.output])
            return tuple(out)

        return run

    first = {}
    for name, steps in CALLS:
        first.setdefault(name, steps)  # the solve is called twice, with values shaped alike
    return {name: flat(steps) for name, steps in first.items()}


def run_staged(call: Callable, *fields) -> tuple:
    """Run `PIPELINE` by ``call(executable, *arrays)`` (a tuple of arrays back; the
    executables of `flat_stages`, compiled, in the order of `CALLS`) on the
    batch's [`Grasp`][jaxgrasp.Grasp] fields: every [`Evaluation`][jaxgrasp.Evaluation] field, in
    `jaxgrasp.tolerance._result.FIELDS` order. A
    `Pipeline`'s driver: it only passes arrays on."""
    env: dict[str, tuple] = {}
    for name, steps in CALLS:
        values = (a for n in _outer_inputs(steps) if n not in INPUTS for a in env[n])
        out = call(name, *fields, *values)
        for step in steps:
            k = step.tree().num_leaves
            env[step.output], out = tuple(out[:k]), out[k:]
    return env[PIPELINE[-1].output]
