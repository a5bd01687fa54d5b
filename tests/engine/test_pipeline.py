"""The engine's pipeline declaration and chunk plan, without compiling anything.

What the two runners compute is checked elsewhere against each other and against Ipopt
(``test_batch.py``: ``evaluate_batch``, the staged runner, equals ``evaluate``, the inline
one); here: the declaration is well formed, the staged runner calls the stages in its
order with the arrays it names, and the chunk plan has its closed forms.
"""

import math

import jax
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.engine import _stages
from jaxgrasp.engine._plan import AUTO_CHUNKS, MIN_AUTO_CHUNK, ChunkPlan, bucket_size, default_chunk_size, plan_chunks


def test_every_step_reads_values_made_before_it():
    made = set(_stages.INPUTS)
    for step in _stages.PIPELINE:
        assert set(step.inputs) <= made, (step, made)
        assert step.output not in made, step  # each value is made once
        made.add(step.output)
    assert _stages.PIPELINE[-1].output == "evaluation"


def test_the_data_flow_is_the_methods():
    """Eq. 1: the boundary problems start around the *solved* (and settled) equilibrium,
    the finish stage reads that same equilibrium, and the verdict reads every solved
    problem and the differentiable parameters (its envelope derivatives go through them;
    the solver's data carries no gradient)."""
    flow = {s.output: (s.stage, s.inputs) for s in _stages.PIPELINE}
    assert flow == {
        "eq_starts": ("equilibrium", ("data",)),
        "eq_lanes": ("lanes", ("data", "eq_starts")),
        "eq": ("settle", ("data", "eq_lanes")),
        "lane_starts": ("starts", ("data", "eq")),
        "solved": ("lanes", ("data", "lane_starts")),
        "problems": ("finish", ("data", "eq", "solved", "lane_starts")),
        "evaluation": ("evaluation", ("params", "problems")),
    }


def test_stage_names_and_functions_agree():
    functions = _stages.stage_functions(jaxgrasp.EvaluateOptions())
    assert set(functions) == set(_stages.STAGES)
    assert _stages.STAGES == ("equilibrium", "lanes", "settle", "starts", "finish", "evaluation")
    assert [s.stage for s in _stages.PIPELINE].count(_stages.SOLVE) == 2  # one per round
    # run one executable at a time, the settle step runs in the starts stage's
    assert _stages.EXECUTABLES == ("equilibrium", "lanes", "starts", "finish", "evaluation")
    assert set(_stages.flat_stages(jaxgrasp.EvaluateOptions(), ("positions",))) == set(_stages.EXECUTABLES)


def test_run_staged_calls_the_declared_steps_in_order():
    """A recording ``call``: each executable gets the grasp fields, then the leaves of the
    earlier values its steps read, and returns its own values' leaves; the settle step's
    equilibrium comes out of the starts call, and the finish call reads it."""
    calls = []
    sizes = {s.output: s.tree().num_leaves for s in _stages.PIPELINE}
    steps = [s for s in _stages.PIPELINE if s.stage != "settle"]
    settle = next(s for s in _stages.PIPELINE if s.stage == "settle")

    def call(stage, *arrays):
        step = steps[len(calls)]
        calls.append((stage, arrays))
        assert stage == step.stage
        reads = ("data", "eq_lanes") if stage == "starts" else step.inputs
        expect = 2 + sum(sizes[n] for n in reads if n not in _stages.INPUTS)
        assert len(arrays) == expect, (stage, len(arrays), expect)
        made = (settle, step) if stage == "starts" else (step,)
        return tuple((s.output, i) for s in made for i in range(sizes[s.output]))

    out = _stages.run_staged(call, "f0", "f1")
    assert [c[0] for c in calls] == ["equilibrium", "lanes", "starts", "lanes", "finish", "evaluation"]
    assert out == tuple(("evaluation", i) for i in range(sizes["evaluation"]))
    # the starts stage reads the equilibrium's lanes; the second solve the boundary
    # starts, not the equilibrium's; the finish stage the settled equilibrium
    assert calls[2][1][2:] == tuple(("eq_lanes", i) for i in range(sizes["eq_lanes"]))
    assert calls[3][1][2:] == tuple(("lane_starts", i) for i in range(sizes["lane_starts"]))
    assert calls[4][1][2 : 2 + sizes["eq"]] == tuple(("eq", i) for i in range(sizes["eq"]))


def test_evaluation_leaves_are_the_result_fields_in_order():
    from jaxgrasp.tolerance._result import FIELDS

    tree = _stages.PIPELINE[-1].tree()
    leaves = jax.tree_util.tree_unflatten(tree, list(FIELDS))
    assert tuple(getattr(leaves, f) for f in FIELDS) == FIELDS


def test_the_inline_loop_carries_what_later_steps_read():
    """The equilibrium's starts feed only its own solve, and its lanes only the settle
    step of the next round: the loop carries the rest."""
    steps = _stages.PIPELINE
    rounds = [(steps[0:1], steps[1]), (steps[2:4], steps[4])]
    assert _stages._read_later(rounds, steps[5:], "evaluation") == {"eq_lanes", "eq", "lane_starts", "solved"}
    assert _stages._read_later(rounds, (), "eq_starts") == {"eq_starts", "eq_lanes"}
    assert _stages._read_later(rounds, (), "solved") == {"eq_lanes", "solved"}


def test_run_inline_names_a_value_that_exists():
    with pytest.raises(ValueError, match="no step of the pipeline makes 'nothing'"):
        _stages.run_inline(jaxgrasp.presets.cube(), {}, until="nothing")


@pytest.mark.parametrize("total", [1, 2, 5, 16, 17, 100, 369, 4097])
@pytest.mark.parametrize("chunk_size", [None, 1, 6, 64, 4096])
def test_plan_covers_the_batch_in_buckets(total, chunk_size):
    plan = plan_chunks(total, chunk_size)
    n = len(jax.devices())
    assert isinstance(plan, ChunkPlan) and plan.total == total and plan.n_devices == n
    assert plan.chunk % n == 0
    assert plan.n_chunks == math.ceil(total / plan.chunk)
    cap = default_chunk_size() if chunk_size is None else chunk_size
    assert plan.chunk <= -(-cap // n) * n  # never above the cap (rounded up to the devices)
    per = plan.chunk // n
    assert per == -(-cap // n) or per in {4**k for k in range(12)}  # a bucket, or the cap


def test_auto_plan_is_about_a_tenth_of_a_long_run():
    n, cap = len(jax.devices()), default_chunk_size()
    assert plan_chunks(369, auto=True).chunk == bucket_size(bucket_size(cap, max(MIN_AUTO_CHUNK * n, 37)), 369, n)
    long = plan_chunks(10**6, chunk_size=None, auto=True)
    assert long.chunk == cap  # a tenth is more than the default: the default caps it
    short = plan_chunks(AUTO_CHUNKS * MIN_AUTO_CHUNK * n, auto=True)
    assert short.chunk == bucket_size(bucket_size(cap, MIN_AUTO_CHUNK * n), AUTO_CHUNKS * MIN_AUTO_CHUNK * n, n)
    assert plan_chunks(369, 16, auto=True).chunk == plan_chunks(369, 16).chunk  # an explicit size wins


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "64"])
def test_plan_rejects_bad_chunk_sizes_in_one_line(bad):
    with pytest.raises(jaxgrasp.GraspValueError, match="chunk_size must be a positive integer") as e:
        plan_chunks(10, bad)
    assert "\n" not in str(e.value)


def test_plan_needs_a_device():
    with pytest.raises(jaxgrasp.GraspValueError, match="at least one device"):
        plan_chunks(10, devices=())


def test_result_assembly_places_rows_and_marks_invalid():
    from jaxgrasp.engine._batch_result import assemble
    from jaxgrasp.tolerance._result import FIELDS

    rng = np.random.default_rng(0)
    full = {f: rng.normal(size=(6, 2)) if f != "status" else np.zeros(6, np.int32) for f in FIELDS}
    parts = [(np.array([4, 0]), {f: a[[4, 0]] for f, a in full.items()}),
             (np.array([1, 3, 5]), {f: a[[1, 3, 5]] for f, a in full.items()})]
    active = np.ones((6, 2), dtype=bool)
    active[2] = False
    res = assemble(parts, 6, [2], active, [None, None, "bad", None, None, None], run_seconds=1.5, devices=2)
    for f in FIELDS:
        got = np.asarray(getattr(res, f))
        np.testing.assert_array_equal(np.delete(got, 2, axis=0), np.delete(full[f], 2, axis=0))
    assert res.status[2] == jaxgrasp.GraspStatus.INVALID and np.all(np.isnan(res.value[2]))
    assert list(res.num_contacts) == [2, 2, 0, 2, 2, 2] and res.errors[2] == "bad"
    assert (res.run_seconds, res.devices, res.compile_seconds) == (1.5, 2, 0.0)
