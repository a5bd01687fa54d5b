"""Hand candidates for planning: wrist poses around the object, pre-shapes, fingers closed onto it.

A candidate starts as a wrist pose and a pre-shape (`hand_starts`): the hand's grasp
centre (the mean of its fingertip centres at the half-closed configuration, in the hand's
model frame) on the object's centre of mass, its palm on the side of a random approach
direction, a random roll about it, and joints drawn in the open half of their ranges.

Closing (`close_hands`) moves the joints and the wrist together by ``steps`` steps of
Adam on a smooth surrogate of what the paper's model needs of a grasp, every candidate
at once (``jit(vmap(scan))``):

* **press**: each fingertip's centre at ``r - dr*`` from the surface (its target
  deformation ``dr*``, drawn per candidate within the force limit: eq. 4),
  ``((d - (r - dr*)) / 1 mm)^2`` summed over fingertips;
* **face**: each fingertip's cap turned towards the surface, ``1 - cos(tilt)``;
* **balance**: the fingertips' squeezes (eq. 4's ``pi E dr^2`` along the inward normals, at
  the current ``dr``) summing to no force and no torque about the centre of mass, each
  over the total squeeze (and the object's size for the torque);
* **clear**: the hand's other links (`jaxgrasp.hands.link_samples`) out of the object,
  ``(max(depth + 0.5 mm, 0) / 1 mm)^2``, read from a [`DistanceGrid`][jaxgrasp.surface.DistanceGrid]
  of the object (the exact search for a few hundred samples at every step is what the
  grid saves); the fingertips read the exact surface;
* **apart**: the hand's own links out of each other (the pairs MuJoCo would collide,
  [`Hand.self_overlap`][jaxgrasp.Hand.self_overlap]), ``(max(overlap + 0.5 mm, 0) / 1 mm)^2``.

The joints are ``hand.project_joints`` of the search's variables (the limits and the
model's couplings, `jaxgrasp.hands._couplings`), so every iterate is one the hand can hold.
The surrogate only finds starts: the grasps are then evaluated and refined on the exact
surface with the paper's value.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["CloseSettings", "hand_starts", "close_hands", "palm_body", "unpack"]

_TRANSLATION_UNIT = 0.01  # m per unit of the wrist's translation variables: steps in cm, like the angles' in rad


@dataclasses.dataclass(frozen=True)
class CloseSettings:
    """The closing search's weights and steps (module notes); hashable, part of its
    compiled program's key.

    Attributes:
        steps: Adam steps. rate_joints, rate_translation, rate_rotation: Adam's step
            sizes for the joints' unit-range variables, the wrist translation (cm) and
            its rotation vector (rad).
        press, face, balance, clear, apart: the terms' weights.
        clearance: m, how far out of the object the links, and apart the hand's own
            colliding links, are pushed.
        band: m, the width of each fingertip's band of deformations ``[dr*, dr* + band]``.
        unit: m, the length the press and clear terms are measured in.
    """

    steps: int = 150
    rate_joints: float = 0.02
    rate_translation: float = 0.05
    rate_rotation: float = 0.02
    press: float = 1.0
    face: float = 5.0
    balance: float = 20.0
    clear: float = 10.0
    apart: float = 10.0
    clearance: float = 0.5e-3
    band: float = 1.5e-3
    unit: float = 1e-3


def palm_body(hand) -> int:
    """The body the fingertips' chains share last (the palm of a hand): the deepest
    common ancestor of the fingertips' bodies."""
    parent = hand.tree.body_parent

    def chain(body):
        out = []
        while body >= 0:
            out.append(int(body))
            body = parent[body]
        return out[::-1]

    chains = [chain(b) for b in hand.fingertip_body]
    common = 0
    for k in range(min(len(c) for c in chains)):
        if len({c[k] for c in chains}) == 1:
            common = chains[0][k]
    return common


def _shape_frames(hand, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (B, 3), palm (B, 3))`` m, the hand's model frame: the mean fingertip centre
    and the palm body's origin at the pre-shapes ``u`` ``(B, J)`` (fractions of the ranges)."""
    centre, origin = _shape_frames_function(hand)(jnp.asarray(u))
    return np.array(centre), np.array(origin)


@lru_cache(maxsize=8)
def _shape_frames_function(hand):
    """`_shape_frames`' compiled function, one per hand (jitted anew at every call, it was
    compiled again for every plan)."""
    lo, hi = _limits(hand)
    palm = palm_body(hand)

    def one(v):
        q = hand.project_joints(jnp.asarray(lo) + jnp.asarray(hi - lo) * v)
        return hand.fingertip_centers(q).mean(0), hand.body_frames(q)[0][palm]

    return jax.jit(jax.vmap(one))


def _limits(hand) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` ``(J,)``: the joint limits, an unlimited joint held in ``[-pi, pi]``."""
    lo = np.where(np.isfinite(hand.lower), hand.lower, -np.pi)
    hi = np.where(np.isfinite(hand.upper), hand.upper, np.pi)
    return lo, hi


def _rotation_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation vector of the smallest rotation taking unit ``a`` to unit ``b``."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.zeros(3)
        other = np.eye(3)[int(np.argmin(np.abs(a)))]
        axis = np.cross(a, other)
        return np.pi * axis / np.linalg.norm(axis)
    return axis / s * np.arctan2(s, c)


def hand_starts(hand, center_of_mass, count: int, rng, open_range=(0.15, 0.5)):
    """``x0 (count, J + 6)``: the search's start variables (joints as fractions of their
    ranges, drawn in ``open_range``; the wrist translation in cm and rotation vector, rad),
    from the generator ``rng``: each pre-shape's mean fingertip centre on the centre of
    mass, the way from its palm to that centre along ``-approach`` (a random unit direction,
    mesh frame, from the object towards the palm), a random roll about it."""
    from scipy.spatial.transform import Rotation

    j = hand.num_joints
    u = rng.uniform(*open_range, size=(count, j))
    centre, palm = _shape_frames(hand, u)
    inward = centre - palm
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)  # the way each pre-shape closes, model frame
    approach = rng.normal(size=(count, 3))
    approach /= np.linalg.norm(approach, axis=1, keepdims=True)
    x0 = np.empty((count, j + 6))
    for b in range(count):
        rot = Rotation.from_rotvec(approach[b] * rng.uniform(-np.pi, np.pi)) * Rotation.from_rotvec(
            _rotation_to(inward[b], -approach[b]))
        x0[b, :j] = u[b]
        x0[b, j:j + 3] = (np.asarray(center_of_mass) - rot.apply(centre[b])) / _TRANSLATION_UNIT
        x0[b, j + 3:] = rot.as_rotvec()
    return x0


def unpack(hand, x):
    """``(qpos (..., J), wrist (..., 6))`` of the search's variables ``x`` (..., J + 6):
    the joints projected onto the limits and couplings. Traceable."""
    lo, hi = _limits(hand)
    j = hand.num_joints
    q = hand.project_joints(jnp.asarray(lo) + jnp.asarray(hi - lo) * jnp.clip(x[..., :j], 0.0, 1.0))
    wrist = jnp.concatenate([x[..., j:j + 3] * _TRANSLATION_UNIT, x[..., j + 3:]], axis=-1)
    return q, wrist


def _terms(hand, s: CloseSettings, x, target_dr, data):
    """``(5,)`` the press, face, balance, clear and apart terms at ``x`` (module notes)."""
    q, wrist = unpack(hand, x)
    centers, axes = hand.fingertip_frames(q, wrist)
    hit = data["surface"].closest(centers)
    r = jnp.asarray(hand.radius)
    # the band [dr*, dr* + width]: within it each fingertip's depth is left to the balance
    reach = r - hit.signed_distance
    press = jnp.sum(((jnp.maximum(target_dr - reach, 0.0) + jnp.maximum(reach - target_dr - s.band, 0.0)) / s.unit) ** 2)
    face = jnp.sum(1.0 + jnp.sum(axes * hit.normal, axis=-1))
    dr = jnp.clip(r - hit.signed_distance, 0.0, r)
    squeeze = jnp.pi * data["young_modulus"] * dr**2  # eq. 4, N
    push = -squeeze[:, None] * hit.normal
    total = jnp.sum(squeeze) + 1e-3
    torque = jnp.cross(hit.point - data["center_of_mass"], push)
    balance = (jnp.sum(jnp.sum(push, 0) ** 2) + jnp.sum(jnp.sum(torque, 0) ** 2) / data["size"] ** 2) / total**2
    depth = jnp.asarray(hand.link_points[2]) - data["grid"](hand.link_positions(q, wrist))
    clear = jnp.sum((jnp.maximum(depth + s.clearance, 0.0) / s.unit) ** 2)
    apart = jnp.sum((jnp.maximum(hand.self_overlap(q) + s.clearance, 0.0) / s.unit) ** 2)
    return jnp.stack([press, face, balance, clear, apart])


def _close_one(hand, s: CloseSettings, x0, target_dr, data):
    """``(x, terms (5,))``: one candidate after ``s.steps`` Adam steps (module notes)."""
    j = hand.num_joints
    weights = jnp.asarray([s.press, s.face, s.balance, s.clear, s.apart])
    rate = jnp.concatenate([jnp.full(j, s.rate_joints), jnp.full(3, s.rate_translation), jnp.full(3, s.rate_rotation)])

    def loss(x):
        terms = _terms(hand, s, x, target_dr, data)
        return jnp.sum(weights * terms), terms

    def step(carry, i):
        x, m, v = carry
        (_, terms), g = jax.value_and_grad(loss, has_aux=True)(x)
        g = jnp.where(jnp.isfinite(g), g, 0.0)  # a fingertip exactly on an edge of the mesh: no direction
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        # Adam moves each variable by about its rate per step whatever the gradient: the
        # rates decay (cosine, to 1/20) so the last steps place fingertips to a fraction of a mm
        decay = 0.05 + 0.475 * (1.0 + jnp.cos(jnp.pi * i / s.steps))
        x = x - decay * rate * (m / (1 - 0.9 ** (i + 1))) / (jnp.sqrt(v / (1 - 0.999 ** (i + 1))) + 1e-8)
        return (x.at[:j].set(jnp.clip(x[:j], 0.0, 1.0)), m, v), terms

    zeros = jnp.zeros_like(x0)
    (x, _, _), _ = jax.lax.scan(step, (x0, zeros, zeros), jnp.arange(s.steps))
    return x, loss(x)[1]


def close_hands(hand, settings: CloseSettings, x0, target_dr, data):
    """``(x (B, J + 6), terms (B, 5))``: the candidates ``x0`` (B, J + 6) closed onto the
    object, each towards its target deformations ``target_dr`` ``(B, F)`` m (module
    notes). ``data``: ``surface`` (mesh frame), ``grid`` (its `DistanceGrid`),
    ``center_of_mass`` ``(3,)`` m, ``young_modulus`` ``(F,)`` Pa and ``size`` m (the
    object's half diagonal). Compiled once per hand, settings and shapes (the executable
    store keeps it)."""
    from jaxgrasp.engine import COMPILER_OPTIONS, StoredFunction

    leaf = jax.tree_util.tree_structure(0.0)
    fn = StoredFunction(jax.vmap(lambda x, t, d: _close_one(hand, settings, x, t, d), in_axes=(0, 0, None)),
                        (hand.digest(), settings), jax.tree_util.treedef_tuple((leaf, leaf)), name="hand-close",
                        compiler_options=COMPILER_OPTIONS, what=f"closing {hand.num_fingertips} fingertips onto an object")
    return fn(jnp.asarray(x0), jnp.asarray(target_dr), data)
