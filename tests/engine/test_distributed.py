"""The sharded path over two processes (``jax.distributed``, issue 12, part 6).

Two processes on localhost, one CPU device each, joined by ``jax.distributed.initialize``
with gloo CPU collectives, evaluate one set of grasps together (``evaluate_batch``, its
chunks sharded over both devices, each process supplying its own slice, the results
gathered to both; sweeps run through the same engine). Both must get the same arrays,
equal to ``evaluate`` of every grasp in one process. Cost: both compile the batch's
program at once (~25 s on 2 cores); the set is of 2-contact grasps (padding has its own
tests in one process, ``tests/engine/test_batch.py``; a 3-contact program costs ~10 s more).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import numpy as np

import jaxgrasp

E = [2e5, 6e5, 1e6]
DR = [1e-3, 2e-3]

WORKER = r"""
import json, sys
i, port, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
import jax
jax.config.update("jax_cpu_collectives_implementation", "gloo")
jax.distributed.initialize(f"127.0.0.1:{port}", 2, i)
import numpy as np, jaxgrasp
grasps = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=d) for e in %(E)r for d in %(DR)r]
r = jaxgrasp.evaluate_batch(grasps)
np.savez(out, **{f: np.asarray(getattr(r, f)) for f in jaxgrasp.tolerance._result.FIELDS})
print("RESULT " + json.dumps({"devices": r.devices, "processes": jax.process_count(),
                             "local_devices": jax.local_device_count()}))
""" % {"E": E, "DR": DR}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_evaluate_a_set_like_one(tmp_path, evaluate_many):
    port = _free_port()
    # one CPU device per process (import jaxgrasp would otherwise make one per core)
    env = dict(os.environ, JAXGRASP_CACHE_DIR=str(tmp_path / "cache"), JAX_PLATFORMS="cpu", JAXGRASP_CPU_DEVICES="1")
    env.pop("XLA_FLAGS", None)
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WORKER, str(i), str(port), str(tmp_path / f"out{i}.npz")],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        for i in range(2)
    ]
    outs = []
    try:
        for p in procs:
            out, err = p.communicate(timeout=300)
            assert p.returncode == 0, err[-3000:]
            outs.append(json.loads(next(ln for ln in out.splitlines() if ln.startswith("RESULT "))[7:]))
    finally:
        for p in procs:
            p.kill()
    assert all(o == {"devices": 2, "processes": 2, "local_devices": 1} for o in outs), outs
    z = [dict(np.load(tmp_path / f"out{i}.npz")) for i in range(2)]
    for f in z[0]:
        np.testing.assert_array_equal(z[0][f], z[1][f], err_msg=f)  # both processes gathered the same

    grasps = [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=d) for e in E for d in DR]
    for k, ref in enumerate(evaluate_many(grasps)):
        n = grasps[k].num_contacts
        np.testing.assert_allclose(z[0]["value"][k], ref.value, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(z[0]["equilibrium_energy"][k], ref.equilibrium_energy, rtol=1e-12)
        np.testing.assert_allclose(z[0]["boundary_energy"][k][:, :n], ref.boundary_energy, rtol=1e-10)
        assert z[0]["status"][k] == ref.status
        assert z[0]["limiting_kind"][k] == ref.limiting_kind
        assert z[0]["limiting_contact"][k] == ref.limiting_contact
    assert (z[0]["value"] > 0).all()  # every grasp stable: the comparison is not of zeros
