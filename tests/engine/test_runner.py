"""The batch runner's sources and plans (:mod:`jaxgrasp.engine._runner`), without compiling:
what a source gives a chunk and how a source's grasps are cut."""

from __future__ import annotations

import numpy as np
import jax

from jaxgrasp.engine._runner import Stacked, _chunk_of, plan_source


def _fields(counts, width=4):
    b = len(counts)
    return {"positions": np.arange(b * width * 3, dtype=float).reshape(b, width, 3),
            "mass": np.arange(b, dtype=float), "active": np.arange(width) < np.asarray(counts)[:, None]}


def test_stacked_gives_its_rows_and_their_counts():
    src = Stacked(_fields([2, 4, 3, 1]), np.array([3, 1, 2]))
    assert (src.size, src.width) == (3, 4)
    assert src.counts().tolist() == [1, 4, 3]
    np.testing.assert_array_equal(src.gather(np.array([2, 2, 0]))["mass"], [2.0, 2.0, 3.0])


def test_a_chunk_is_padded_with_its_last_grasp_whose_contacts_are_off_in_a_masked_program():
    src = Stacked(_fields([2, 4, 3]), np.arange(3))
    at = np.array([0, 2])
    masked = _chunk_of(src, at, 0, 4)
    np.testing.assert_array_equal(masked["mass"], [0.0, 2.0, 2.0, 2.0])
    assert masked["active"][2:].sum() == 0 and masked["active"][1].sum() == 3
    kept = _chunk_of(src, at, 0, 4, keep_padding_active=True)  # an unmasked program solves the repeats
    assert kept["active"][2:].sum(axis=1).tolist() == [3, 3]


def test_plan_source_cuts_by_width_and_an_exact_chunk_keeps_its_size():
    devices = jax.devices()[:1]
    src = Stacked(_fields([2, 4, 3, 4, 4]), np.arange(5))
    plan = plan_source(src, 64, devices)
    assert [s.width for s in plan.segments] == [4] and plan.segments[0].plan.chunk == 16  # the bucket of 5
    exact = plan_source(src, 64, devices, exact_chunk=True)
    assert exact.segments[0].plan.chunk == 64 and exact.total == 5
    own = plan_source(src, 4, devices, widths={2: 2, 3: 4, 4: 4})
    assert [(s.width, s.plan.total) for s in own.segments] == [(4, 4), (2, 1)]
