"""Batch and single evaluation: how far apart their numbers are, stated and bounded.

:func:`jaxgrasp.evaluate` of one grasp runs its own compiled program, a batch the staged
chunk program (:func:`~jaxgrasp.engine._runner.run_batch`), whose work queue serves many
lanes: the two take different solver paths to the same minima (their solver diagnostics,
``steps`` and the lanes' statuses, may differ), so their numbers agree to the solver's
precision, not bit for bit. Measured on 50 random 2-contact grasps in a chunk of 64: every
grasp status and limiting boundary equal, the values apart by at most 1.2e-14 of the
equilibrium energy |U0| (7e-17 J). The bound tested, :data:`BOUND`, is 1e-12 |U0|.

Within one program a grasp's numbers do not depend on its chunk's companions: that is what
lets a robust evaluation's nominal grasp share its samples' program
(``tests/analysis/test_robust.py``) and a plan rank its candidates in chunks of any fill.
"""

from __future__ import annotations

import numpy as np
import pytest

import jaxgrasp
from grasp_draws import NumpyDraw, build_grasp

BOUND = 1e-12
"""Largest ``|single - batch|`` of the value and the energies, relative to ``|U0|``."""


@pytest.fixture(scope="module")
def grasps():
    rng = np.random.default_rng(7)
    return [jaxgrasp.presets.cube(), *(build_grasp(NumpyDraw(rng), n=2) for _ in range(7))]


@pytest.mark.slow  # compiles evaluate's and the batch's 2-contact programs
def test_single_and_batch_agree_within_the_bound(grasps):
    batch = jaxgrasp.evaluate_batch(grasps, chunk_size=16)  # 8 grasps: one chunk
    for i, g in enumerate(grasps):
        one, row = jaxgrasp.evaluate(g), batch[i]
        assert int(one.status) == int(row.status)
        assert int(one.limiting_kind) == int(row.limiting_kind)
        assert int(one.limiting_contact) == int(row.limiting_contact)
        scale = BOUND * abs(float(one.equilibrium_energy))
        assert abs(float(one.value) - float(row.value)) <= scale
        assert abs(float(one.equilibrium_energy) - float(row.equilibrium_energy)) <= scale


@pytest.mark.slow  # the batch's 2-contact program
def test_a_grasp_has_the_same_numbers_whatever_its_companions(grasps):
    from jaxgrasp.engine._batch import evaluate_in_chunks

    alone = evaluate_in_chunks(grasps[:1], 16)  # padded with 15 copies of itself
    among = evaluate_in_chunks(grasps[::-1], 16)  # the cube last, beside seven others
    for f in ("value", "equilibrium_energy", "boundary_energy", "steps", "status"):
        np.testing.assert_array_equal(np.asarray(getattr(alone, f))[0], np.asarray(getattr(among, f))[-1])
