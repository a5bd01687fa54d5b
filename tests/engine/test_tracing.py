"""What a batched program costs to build: the solver's work queue is traced as few times as
JAX allows (issue 13, "compile less").

Under ``jax.vmap`` the queue (:func:`jaxgrasp.solver._lanes.solve_lanes`, a ``custom_vmap``) is
traced once for one grasp (``custom_vmap`` builds its own jaxpr) and once folded over the
batch (its batching rule). JAX's loop batching traces a loop body again when the body
makes an unbatched carry batched; the two-stage loop of
:func:`jaxgrasp.tolerance._stages.problems_of` starts with a batched carry so that the folded
queue, the largest part of the program, is traced once (it used to be traced twice: a
batch of 128 cube grasps over 2 devices traced in 4.0-4.5 s instead of 2.6 s).

The batch engine's program (:func:`jaxgrasp.engine._evaluate.evaluate_batch_traced`) takes the
batch itself and traces the queue once, folded.

Each case uses its own ``EvaluateOptions(seed=...)``, so that no trace cached by another
test is reused, and counts the calls of ``lanes._solve_lanes`` by lane count.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import pytest

import jaxgrasp
from jaxgrasp.solver import _lanes as lanes
from jaxgrasp.engine._evaluate import evaluate_batch_traced, evaluate_traced


@pytest.fixture
def queue_traces(monkeypatch):
    """The lane counts of every trace of the work queue, in order."""
    calls = []
    real = lanes._solve_lanes

    def counting(problem, theta, x0, *rest):
        calls.append(x0.shape[0])
        return real(problem, theta, x0, *rest)

    monkeypatch.setattr(lanes, "_solve_lanes", counting)
    return calls


def _lanes_per_grasp(grasp, options) -> int:
    return 2 * grasp.num_contacts * options.num_starts


def test_batch_traces_the_folded_queue_once(queue_traces):
    options = jaxgrasp.EvaluateOptions(seed=9101)
    cubes = [jaxgrasp.presets.cube(young_modulus=e) for e in (3e5, 6e5, 9e5)]
    batch = jaxgrasp.stack(cubes)
    jax.jit(jax.vmap(lambda g: evaluate_traced(g, options, settle=False))).trace(batch)
    per = _lanes_per_grasp(cubes[0], options)
    assert queue_traces == [per, 3 * per]


def test_batch_over_one_field_traces_the_folded_queue_once(queue_traces):
    """A vmap over the mass alone (every other field shared) is batched from the start too."""
    options = jaxgrasp.EvaluateOptions(seed=9102)
    cube = jaxgrasp.presets.prism()

    def of_mass(m):
        return evaluate_traced(cube.replace(mass=m), options, settle=False)

    jax.jit(jax.vmap(of_mass)).trace(jnp.array([0.0, 0.1]))
    per = _lanes_per_grasp(cube, options)
    assert queue_traces == [per, 2 * per]


@pytest.mark.slow  # compiles the engine's programs of its own
def test_engine_traces_the_queue_once(queue_traces):
    """The engine's evaluator of a batch: no trace for one grasp, the folded queue once;
    its results are those of the vmap of the one-grasp evaluator."""
    options = jaxgrasp.EvaluateOptions(seed=9103)
    cubes = [jaxgrasp.presets.cube(young_modulus=e) for e in (3e5, 6e5, 9e5)]
    batch = jaxgrasp.stack(cubes)
    got = jax.jit(lambda g: evaluate_batch_traced(g, options, settle=False))(batch)
    per = _lanes_per_grasp(cubes[0], options)
    assert queue_traces == [3 * per]
    want = jax.jit(jax.vmap(lambda g: evaluate_traced(g, options, settle=False)))(batch)
    for field in ("value", "equilibrium_energy", "boundary_energy"):
        assert jnp.allclose(getattr(got, field), getattr(want, field), rtol=1e-12, atol=0), field
    assert jnp.array_equal(got.status, want.status) and jnp.array_equal(got.steps, want.steps)
