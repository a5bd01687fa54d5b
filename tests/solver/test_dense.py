"""``jaxgrasp.solver._dense``, and the batch engine's program free of batched LAPACK calls that
could split over the thread pool.

jaxlib's LAPACK kernels split a large batch over XLA's thread pool and wait for the
pieces; with one device per core (the batch engine) every device can be waiting at once
and the process hangs (:mod:`jaxgrasp.solver._dense`). The settling stage's polish used
``jnp.linalg.solve`` (``lapack_dgetrf_ffi``) on every grasp of a chunk and hung
``evaluate_batch`` on 2 devices; its systems are now solved by ``dense.solve``. The start
frame's ``eigh``, one per grasp, hung ``evaluate_batch(..., chunk_size=512)`` (256 grasps
per device) on 2 devices; it is now ``dense.eigh``, one LAPACK call per matrix. The only
batched LAPACK call left is the Newton direction's ``eigh``, on gathered blocks of
``EIGH_BLOCK`` (16) lanes.
"""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrasp.engine import _evaluator, _pipeline, _plan
from jaxgrasp.engine import _stages as batch_stages
from jaxgrasp.solver._dense import eigh, solve
from jaxgrasp.solver._direction import EIGH_BLOCK
from jaxgrasp.tolerance._options import EvaluateOptions


@pytest.mark.parametrize("m", [1, 2, 6, 27])
def test_solve_agrees_with_numpy(m):
    """Residual at rounding level, and numpy's solution, on random systems whose first
    pivot is zero (elimination without row exchanges would divide by it)."""
    rng = np.random.default_rng(m)
    a = rng.standard_normal((40, m, m))
    if m > 1:
        a[:, 0, 0] = 0.0
    b = rng.standard_normal((40, m))
    x = np.asarray(jax.jit(jax.vmap(solve))(a, b))
    ref = np.linalg.solve(a, b[..., None])[..., 0]
    resid = np.abs(np.einsum("bij,bj->bi", a, x) - b).max(axis=1)
    scale = np.abs(a).max(axis=(1, 2)) * np.abs(x).max(axis=1) + np.abs(b).max(axis=1)
    assert np.all(resid <= 1e-13 * scale), resid / scale
    cond = np.linalg.cond(a)
    assert np.all(np.abs(x - ref).max(axis=1) <= 1e-14 * cond * np.abs(ref).max(axis=1)), cond


def test_singular_system_gives_non_finite():
    assert not np.all(np.isfinite(np.asarray(solve(jnp.zeros((3, 3)), jnp.ones(3)))))


def _lapack_calls(text: str) -> list[tuple[str, str]]:
    """``(target, operand type)`` of every LAPACK custom call in lowered StableHLO."""
    return re.findall(r"custom_call @(\w*lapack\w*)\([^)]*\)[^\n]*?: \((tensor<[^>]*>)", text)


def test_eigh_under_vmap_is_one_lapack_call_per_matrix():
    """``dense.eigh`` under ``vmap`` gives ``jnp.linalg.eigh``'s digits, and its program
    calls LAPACK on one 6 x 6 matrix at a time, however large the batch."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((300, 6, 6))
    # on a CPU device: the LAPACK kernels are the CPU's (a GPU lowers eigh to cuSOLVER)
    a = jax.device_put(a + np.swapaxes(a, 1, 2), jax.devices("cpu")[0])
    w, v = jax.jit(jax.vmap(eigh))(a)
    w_ref, v_ref = jax.jit(jax.vmap(jnp.linalg.eigh))(a)
    assert np.array_equal(np.asarray(w), np.asarray(w_ref)) and np.array_equal(np.asarray(v), np.asarray(v_ref))
    assert np.allclose(np.asarray(w), np.linalg.eigvalsh(a), rtol=0, atol=1e-12)
    calls = _lapack_calls(jax.jit(jax.vmap(eigh)).trace(a).lower(lowering_platforms=("cpu",)).as_text())
    assert calls == [("lapack_dsyevd_ffi", "tensor<6x6xf64>")], calls
    w_one, _ = eigh(a[7])  # unbatched: plain eigh
    assert np.array_equal(np.asarray(w_one), np.asarray(w_ref[7]))


@pytest.mark.slow  # compiles a batched evaluator
def test_batched_program_calls_no_lapack_but_small_eigh():
    """The batch engine's programs (every stage), with and without the settling stage,
    for 128 grasps per device: every LAPACK custom call is the symmetric eigensolver (``syevd``) on at
    most ``EIGH_BLOCK`` matrices, never on one per grasp of the chunk."""
    cpus = jax.devices("cpu")  # the hang is the CPU's thread pool; a GPU lowers eigh to cuSOLVER
    sharding = _plan.batch_sharding(cpus)
    assert EIGH_BLOCK <= 64
    for settle in (False, True):
        pipeline = _evaluator._staged(EvaluateOptions(), sharding, masked=True, settle=settle)
        spec = _evaluator._chunk_spec(3, 128 * len(cpus), sharding, masked=True)
        lowered = _pipeline.lower_stages(pipeline, spec)
        assert tuple(lowered) == batch_stages.EXECUTABLES  # every executable lowered, each once
        text = "".join(low.as_text() for low in lowered.values())
        calls = _lapack_calls(text)
        assert calls and all("syevd" in target for target, _ in calls), (settle, calls)
        for _, operand in calls:
            dims = [int(d) for d in operand[len("tensor<"):].split("x")[:-1]]
            assert dims[-2:] == [6, 6] and int(np.prod(dims[:-2])) <= EIGH_BLOCK, (settle, operand)


@pytest.mark.slow  # a subprocess running a large chunk
def test_large_chunk_does_not_hang():
    """``evaluate_batch`` of 300 cube grasps in one chunk of 512 (256 grasps per device on
    2 devices): it hung, every device waiting in the start frames' batched ``eigh``
    (checked on the code before ``dense.eigh``). Run in a subprocess with a time limit;
    the values are :func:`jaxgrasp.evaluate`'s."""
    code = textwrap.dedent(
        """
        import numpy as np, jaxgrasp
        g = jaxgrasp.presets.cube()
        grasps = [g.replace(young_modulus=np.full(2, e)) for e in np.linspace(2e5, 1e6, 300)]
        v = np.asarray(jaxgrasp.evaluate_batch(grasps, chunk_size=512).evaluation.value)
        ref = [float(jaxgrasp.evaluate(grasps[i]).value) for i in (0, 299)]
        assert np.all(np.isfinite(v)) and np.allclose(v[[0, 299]], ref, rtol=1e-12, atol=0), (v, ref)
        print("ok")
        """
    )
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240)
    except subprocess.TimeoutExpired:
        pytest.fail("evaluate_batch with chunk_size=512 did not finish in 240 s (hung?)")
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr[-2000:]
