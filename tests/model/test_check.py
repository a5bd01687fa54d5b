"""``jaxgrasp.check`` (issue 40, item 5): the rules of valid input as array code, on
concrete grasps and inside the caller's ``jit(vmap(...))``, where nothing can raise.

Each rule is broken once in a batch of cube grasps built with ``Grasp.replace`` (no
validation), checked under ``jax.jit(jax.vmap(check))`` and batched without ``vmap``;
the concrete validation (``Grasp.create``) must reject the same grasps, so the two
statements of the rules cannot drift apart. No evaluation is compiled.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import presets
from jaxgrasp.model import CheckReason
from jaxgrasp.model._validation import MAX_COORDINATE, MAX_FRICTION, MAX_LOAD_RATIO, GraspValueError

CUBE = presets.cube(young_modulus=6e5, initial_deformation=0.002)
SQUEEZE = 2 * np.pi * 6e5 * 0.002**2  # N, the cube's initial normal forces summed

BROKEN = {  # name: (grasp, the rule it breaks, the contact, -1 for a rule of the grasp)
    "valid": (CUBE, CheckReason.OK, -1),
    "negative friction": (CUBE.replace(friction=jnp.array([0.5, -0.5])), CheckReason.FRICTION, 1),
    "friction above the bound": (CUBE.replace(friction=jnp.full(2, 10 * MAX_FRICTION)), CheckReason.FRICTION, 0),
    "nan position": (CUBE.replace(positions=CUBE.positions.at[1, 2].set(jnp.nan)), CheckReason.NOT_FINITE, 1),
    "infinite mass": (CUBE.replace(mass=jnp.inf), CheckReason.NOT_FINITE, -1),
    "zero radius": (CUBE.replace(radius=jnp.array([0.025, 0.0])), CheckReason.RADIUS, 1),
    "zero young modulus": (CUBE.replace(young_modulus=jnp.zeros(2)), CheckReason.YOUNG_MODULUS, 0),
    "zero force limit": (CUBE.replace(max_force=jnp.array([15.0, 0.0])), CheckReason.MAX_FORCE, 1),
    "negative mass": (CUBE.replace(mass=-1.0), CheckReason.MASS, -1),
    "deformation beyond the radius": (CUBE.replace(initial_deformation=jnp.array([0.03, 0.002])),
                                      CheckReason.DEFORMATION, 0),
    "energy underflows": (CUBE.replace(young_modulus=jnp.full(2, 1e-200)), CheckReason.ENERGY_SCALE, 0),
    "zero normal": (CUBE.replace(normals=CUBE.normals.at[0].set(0.0)), CheckReason.ZERO_NORMAL, 0),
    "one active contact": (CUBE.replace(active=jnp.array([True, False])), CheckReason.TOO_FEW_CONTACTS, -1),
    "coincident contacts": (CUBE.replace(positions=CUBE.positions.at[1].set(CUBE.positions[0])),
                            CheckReason.COINCIDENT, 1),
    "weight beyond the bound": (CUBE.replace(mass=2 * MAX_LOAD_RATIO * SQUEEZE / 9.81), CheckReason.OVERLOAD, -1),
    "contact a kilometre away": (CUBE.replace(positions=CUBE.positions.at[1, 1].set(1.5 * MAX_COORDINATE)),
                                 CheckReason.FAR, 1),
    "fingertip radius in mm": (CUBE.replace(radius=jnp.array([0.025, 25.0])), CheckReason.SIZE, 1),
    "positions in mm": (CUBE.replace(positions=CUBE.positions * 1e3), CheckReason.SIZE, 0),
}


def _batch():
    grasps = [g.replace(active=jnp.ones(2, bool) if g.active is None else g.active) for g, _, _ in BROKEN.values()]
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *grasps)


def test_check_under_jit_vmap_names_each_broken_rule():
    got = jax.jit(jax.vmap(jaxgrasp.check))(_batch())
    want_reason = [int(r) for _, r, _ in BROKEN.values()]
    want_contact = [c for _, _, c in BROKEN.values()]
    assert got.reason.tolist() == want_reason, dict(zip(BROKEN, got.reason_names))
    assert got.contact.tolist() == want_contact
    assert got.valid.tolist() == [r == CheckReason.OK for r in want_reason]
    batched = jaxgrasp.check(_batch())  # a batched grasp without vmap: the same answers
    assert batched.reason.tolist() == want_reason and batched.contact.tolist() == want_contact


@pytest.mark.parametrize("name", [n for n in BROKEN if n != "valid"])
def test_concrete_validation_rejects_what_check_rejects(name):
    grasp = BROKEN[name][0]
    fields = grasp.to_numpy()
    with pytest.raises(GraspValueError) as err:
        jaxgrasp.Grasp.create(**fields)
    assert "\n" not in str(err.value)


def test_raise_if_invalid_is_one_line_naming_grasp_contact_and_rule():
    assert jaxgrasp.check(CUBE).raise_if_invalid().valid
    with pytest.raises(ValueError, match=r"^grasp 1, contact 1: friction must be > 0 .*'friction'\)$"):
        jaxgrasp.check(_batch()).raise_if_invalid()
    with pytest.raises(ValueError, match=r"^grasp: .*NaN.*'not_finite'"):
        jaxgrasp.check(CUBE.replace(mass=jnp.nan)).raise_if_invalid()


def test_check_a_grasp_with_a_scalar_per_contact_field_and_shared_fields():
    batch = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), CUBE).replace(friction=-0.5, gravity=CUBE.gravity)
    got = jaxgrasp.check(batch)
    assert got.reason.tolist() == [CheckReason.FRICTION] * 2 and got.contact.tolist() == [0, 0]
    with pytest.raises(GraspValueError, match="check needs a jaxgrasp.Grasp"):
        jaxgrasp.check({"positions": np.zeros((2, 3))})
