"""Inactive contacts (``Grasp.active``) and :func:`jaxgrasp.stack` (issue 12, part 1).

Padding a grasp with inactive contacts must change nothing: same value, status, limiting
boundary (renumbered), equilibrium energy and pose to 1e-12, with the padding contacts
placed first, last or in between, holding copies of a real contact or unrelated valid
values. Every padded grasp here has N = 5 and a contact mask: they run through the
session's ``evaluate_many`` (``jit(vmap(evaluate))``, its masked N = 5 executable: one
compilation), as do the references, the unpadded grasps (its N = 2, 3, 4 executables,
shared with other modules).
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrasp
from jaxgrasp import Grasp, GraspValueError, stack
from jaxgrasp.model._fields import FIELDS, NAMES
from jaxgrasp.solver._status import LaneStatus

ROOT = Path(__file__).resolve().parents[2]
N_PAD = 5
PER_CONTACT = [f.name for f in FIELDS if f.per_contact]

# an unrelated but valid contact (different place, stiffness, friction, limit)
STRANGER = dict(
    positions=[0.3, -0.2, 0.1], normals=[0.0, 0.6, 0.8], initial_deformation=0.004, radius=0.01,
    young_modulus=9e6, friction=0.1, max_force=1.0,
)


def _bases() -> dict[str, Grasp]:
    return {
        "cube": jaxgrasp.presets.cube(young_modulus=6e5, initial_deformation=0.002),
        "cube_unstable": jaxgrasp.presets.cube(young_modulus=1e6, initial_deformation=4.5e-3),
        "prism_mass": jaxgrasp.presets.prism(mass=0.1),
        "four_finger": jaxgrasp.load(ROOT / "examples" / "four_finger.json"),
    }


def _pad(g: Grasp, slots: list[int], filler: str) -> Grasp:
    """``g`` with N_PAD contacts: its own at the positions ``slots`` (in order), inactive
    contacts elsewhere holding a copy of contact 0 (``filler='copy'``) or STRANGER."""
    f = g.to_numpy()
    out = {n: np.zeros((N_PAD, 3) if n in ("positions", "normals") else (N_PAD,)) for n in PER_CONTACT}
    active = np.zeros(N_PAD, dtype=bool)
    active[slots] = True
    for n in PER_CONTACT:
        fill = f[n][0] if filler == "copy" else np.asarray(STRANGER[n], dtype=np.float64)
        out[n][~active] = fill
        out[n][slots] = f[n]
    return Grasp.create(**out, mass=f["mass"], gravity=f["gravity"], active=active)


def _cases():
    """(base name, slots of its contacts, filler) for several placements."""
    cases = []
    for name, g in _bases().items():
        n = g.num_contacts
        cases.append((name, list(range(N_PAD - n, N_PAD)), "copy"))  # inactive first
        cases.append((name, list(range(n)), "stranger"))  # inactive last
        between = [0] + list(range(N_PAD - n + 1, N_PAD))  # inactive in between
        cases.append((name, between, "stranger" if n % 2 else "copy"))
    return cases


@pytest.fixture(scope="module")
def padded_results(evaluate_many):
    bases = _bases()
    cases = _cases()
    padded = [_pad(bases[name], slots, filler) for name, slots, filler in cases]
    stacked = stack([bases["cube"], bases["prism_mass"], bases["four_finger"], _pad(bases["cube"], [0, 4], "stranger")], num_contacts=N_PAD)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *padded)
    # stack() pads to num_contacts: the same shapes, one compilation
    assert stacked.positions.shape == (4, N_PAD, 3)
    both = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), batch, stacked)
    # evaluate_many is jax.jit(jax.vmap(jaxgrasp.evaluate)), one executable per N and mask
    res = evaluate_many([jax.tree_util.tree_map(lambda a, i=i: a[i], both) for i in range(len(cases) + 4)])
    res = jax.tree_util.tree_map(lambda *a: np.stack(a), *res)
    refs = dict(zip(bases, evaluate_many(list(bases.values()))))
    return cases, res, refs, stacked


def _close(a, b, scale):
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * scale)


def test_padding_changes_nothing(padded_results):
    cases, res, refs, _ = padded_results
    for i, (name, slots, filler) in enumerate(cases):
        ref = refs[name]
        got = jax.tree_util.tree_map(lambda a: a[i], res)
        scale = abs(float(ref.equilibrium_energy))
        where = f"{name} slots={slots} {filler}"
        assert int(got.status) == int(ref.status), where
        assert int(got.limiting_kind) == int(ref.limiting_kind), where
        lim = int(ref.limiting_contact)
        assert int(got.limiting_contact) == (slots[lim] if lim >= 0 else -1), where
        _close(got.value, ref.value, scale)
        _close(got.equilibrium_energy, ref.equilibrium_energy, scale)
        _close(got.equilibrium_translation, ref.equilibrium_translation, 1e-3)
        _close(got.equilibrium_rotation, ref.equilibrium_rotation, 1e-3)
        # the real contacts' boundaries, renumbered; the padding's: not started, +inf
        np.testing.assert_array_equal(got.boundary_status[:, slots], ref.boundary_status, err_msg=where)
        finite = np.isfinite(ref.boundary_energy)
        np.testing.assert_array_equal(np.isfinite(got.boundary_energy[:, slots]), finite, err_msg=where)
        _close(got.boundary_energy[:, slots][finite], ref.boundary_energy[finite], scale)
        pad = np.setdiff1d(np.arange(N_PAD), slots)
        assert (got.boundary_status[:, pad] == LaneStatus.NO_START).all(), where
        assert np.isposinf(got.boundary_energy[:, pad]).all(), where


def test_stack_pads_and_evaluates_each_grasp(padded_results):
    cases, res, refs, stacked = padded_results
    k = len(cases)
    np.testing.assert_array_equal(np.asarray(stacked.active).sum(axis=1), [2, 3, 4, 2])
    for j, name in enumerate(["cube", "prism_mass", "four_finger"]):
        ref = refs[name]
        assert int(res.status[k + j]) == int(ref.status)
        assert int(res.limiting_contact[k + j]) == int(ref.limiting_contact)
        _close(res.value[k + j], ref.value, abs(float(ref.equilibrium_energy)))
    # a grasp that has a mask is compacted, then padded again at the end
    _close(res.value[k + 3], refs["cube"].value, abs(float(refs["cube"].equilibrium_energy)))
    np.testing.assert_array_equal(np.asarray(stacked.positions)[0, 2:], np.repeat(np.asarray(stacked.positions)[0, 1:2], N_PAD - 2, 0))


def test_active_is_validated():
    base = _pad(_bases()["cube"], [0, 1], "copy").to_numpy()
    fields = {n: base[n] for n in NAMES}
    with pytest.raises(GraspValueError, match="active must be booleans"):
        Grasp.create(**fields, active=[1, 1, 0, 0, 0])
    with pytest.raises(GraspValueError, match=r"active must have shape \(5,\)"):
        Grasp.create(**fields, active=[True, True])
    with pytest.raises(GraspValueError, match="at least 2 contacts, got 1"):
        Grasp.create(**fields, active=[True, False, False, False, False])
    # the inactive copies coincide with contact 0: fine while inactive, an error when active
    with pytest.raises(GraspValueError, match="coincide|same position|distinct"):
        Grasp.create(**fields)
    bad = dict(fields, friction=np.array([0.5, 0.5, -1.0, 0.5, 0.5]))
    with pytest.raises(GraspValueError, match="friction"):  # inactive values must be valid too
        Grasp.create(**bad, active=[True, True, False, False, False])


def test_compact_files_and_sweep_see_the_active_contacts(tmp_path):
    cube = _bases()["cube"]
    padded = _pad(cube, [1, 3], "stranger")
    compact = padded.compact()
    for n in NAMES:
        np.testing.assert_array_equal(np.asarray(getattr(compact, n)), np.asarray(getattr(cube, n)), err_msg=n)
    assert compact.active is None
    assert jaxgrasp.io.grasp_to_dict(padded) == jaxgrasp.io.grasp_to_dict(cube)
    jaxgrasp.save_dataset(tmp_path / "s.npz", stack([cube, jaxgrasp.presets.prism()]))
    got = jaxgrasp.load_dataset(tmp_path / "s.npz")
    assert got.num_contacts.tolist() == [2, 3]
    with pytest.raises(GraspValueError, match=r"sweep grasp.compact\(\)"):
        jaxgrasp.sweep(padded, mass=[0.0, 0.1])


@pytest.mark.slow  # compiles evaluators of its own
def test_scalar_per_contact_fields_stand_for_every_contact():
    """A per-contact field set to a scalar by ``Grasp.replace`` (``Grasp.create`` broadcasts
    it itself) means that value at every contact: ``evaluate``, ``stack`` and
    ``evaluate_batch`` (which stacks grasps with different field shapes) give what the
    ``(N,)`` field gives. They raised IndexError / numpy's 'all input arrays must have the
    same shape' before."""
    cube = _bases()["cube"]
    scalar, full = cube.replace(young_modulus=8e5), cube.replace(young_modulus=np.full(2, 8e5))
    assert float(jaxgrasp.evaluate(scalar).value) == float(jaxgrasp.evaluate(full).value)
    stacked = stack([scalar, jaxgrasp.presets.prism()])
    np.testing.assert_array_equal(np.asarray(stacked.young_modulus)[0], [8e5, 8e5, 8e5])
    masked = _pad(cube, [0, 2], "stranger").replace(friction=0.4)
    np.testing.assert_array_equal(np.asarray(masked.compact().friction), 0.4)
    got = jaxgrasp.evaluate_batch([cube, scalar, full]).evaluation
    assert got.value[1] == got.value[2] == float(jaxgrasp.evaluate(full).value)
    assert got.value[0] != got.value[1]


@pytest.mark.slow  # compiles evaluators of its own
def test_grasp_without_active_contacts_solves_nothing():
    """The batch engine stands in for an invalid grasp, and pads its last chunk, with a
    grasp that has no active contact. Its energy would be the weight's alone, unbounded
    below: its equilibrium lane ran the whole step budget (300 steps, checked) while the
    rest of the chunk waited. It now has no lane at all."""
    from jaxgrasp.engine._evaluate import solve_problems

    g = jaxgrasp.presets.cube(mass=0.05).replace(active=jnp.array([False, False]))
    p = solve_problems(g, settle=False)
    assert int(p.equilibrium.status) == LaneStatus.NO_START and int(p.equilibrium.steps) == 0
    assert not np.any(np.asarray(p.found)) and int(np.sum(np.asarray(p.boundary.steps))) == 0
