"""The grasp: a pytree of every physical parameter, in SI units.

A [`Grasp`][jaxgrasp.Grasp] holds ``N >= 2`` contacts between soft hemispherical fingertips and a
rigid object. Every field is an array, so a grasp can be passed through ``jax.jit``,
``jax.vmap`` (add a leading batch axis to any field) and ``jax.grad``.

Frames and conventions (paper, Sec. V): the object frame has its origin at the object's
centre of mass; contact positions and outward surface normals are given in that frame.
In the initial grasping state each fingertip is pressed ``initial_deformation`` into its
contact surface along the normal.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrasp.model._fields import DEFAULT_GRAVITY, DEFAULT_MASS, FIELDS

__all__ = ["Grasp", "stack"]

_PER_CONTACT = tuple(f.name for f in FIELDS if f.per_contact)  # fields with one entry per contact


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Grasp:
    """All parameters of one grasp (SI units). Build it with [`Grasp.create`][jaxgrasp.Grasp.create].

    The fields, their units, shapes and allowed ranges are listed once, in
    `jaxgrasp.model.FIELDS`; in short:

    Attributes:
        positions: ``(N, 3)`` contact positions, m, object frame (origin at the centre of mass).
        normals: ``(N, 3)`` outward surface normals at the contacts (need not be unit length;
            the model normalises them).
        initial_deformation: ``(N,)`` fingertip deformation in the initial state, m, in
            ``(0, radius)``.
        radius: ``(N,)`` fingertip hemisphere radius, m.
        young_modulus: ``(N,)`` Young's modulus of the fingertip material, Pa.
        friction: ``(N,)`` static friction coefficient, dimensionless.
        max_force: ``(N,)`` upper limit of the normal contact force, N.
        mass: ``()`` object mass, kg.
        gravity: ``(3,)`` gravitational acceleration, m/s^2, object frame.
        active: ``None`` (every contact is there) or ``(N,)`` bool: the contacts the
            grasp has. An inactive contact has no energy, no constraint and no boundary
            problem (its boundaries are reported ``no_start`` with energy ``+inf`` and are
            never limiting); its other fields must still hold valid numbers. Padding a
            grasp with inactive contacts changes none of its results, so grasps with
            different contact counts can share one batch and one compilation
            ([`stack`][jaxgrasp.stack]). With a mask, ``jax.grad`` over the whole grasp needs
            ``allow_int=True`` (the mask is not differentiable).

    Any field may carry extra leading batch axes for ``jax.vmap``.
    """

    positions: jax.Array | np.ndarray
    normals: jax.Array | np.ndarray
    initial_deformation: jax.Array | np.ndarray
    radius: jax.Array | np.ndarray
    young_modulus: jax.Array | np.ndarray
    friction: jax.Array | np.ndarray
    max_force: jax.Array | np.ndarray
    mass: jax.Array | np.ndarray
    gravity: jax.Array | np.ndarray
    active: jax.Array | np.ndarray | None = None

    @property
    def num_contacts(self) -> int:
        """Number of contacts ``N`` (static)."""
        return int(jnp.shape(self.positions)[-2])

    @classmethod
    def create(
        cls,
        positions,
        normals,
        initial_deformation,
        *,
        radius,
        young_modulus,
        friction,
        max_force,
        mass=DEFAULT_MASS,
        gravity=DEFAULT_GRAVITY,
        dtype=None,
        active=None,
    ) -> "Grasp":
        """Build a validated grasp, broadcasting per-fingertip scalars to all contacts.

        Every field is validated in float64 and stored as ``dtype``: by default float64
        whatever the inputs' dtypes (float32 where JAX's x64 mode is off), so float32
        arrays passed in become float64; give ``dtype=jnp.float32`` for a float32 grasp
        (screening, see the Precision section of ``docs/guide/grasp-files.md``).

        Args:
            positions: ``(N, 3)`` contact positions, m.
            normals: ``(N, 3)`` outward normals (normalised here).
            initial_deformation: scalar or ``(N,)``, m.
            radius, young_modulus, friction, max_force: scalar (same for every contact)
                or ``(N,)``; units m, Pa, -, N.
            mass: kg (default 0).
            gravity: ``(3,)`` m/s^2 (default ``(0, 0, -9.81)``).
            dtype: ``None`` (float64) or ``jnp.float32`` / ``jnp.float64`` (or their
                names): the dtype of every field.
            active: ``None`` (every contact) or ``(N,)`` bool, the contacts the grasp
                has (at least 2); the inactive ones must hold valid values too.

        Raises:
            GraspValueError: a field is malformed, or ``dtype`` is not float32 or float64
                (float64 also needs JAX's x64 mode); the message names the field and value.
        """
        from jaxgrasp.model._validation import check_grasp_inputs

        fields = check_grasp_inputs(
            positions=positions,
            normals=normals,
            initial_deformation=initial_deformation,
            radius=radius,
            young_modulus=young_modulus,
            friction=friction,
            max_force=max_force,
            mass=mass,
            gravity=gravity,
            active=active,
        )
        dtype = _field_dtype(dtype)
        mask = fields.pop("active", None)
        grasp = cls(**{k: jnp.asarray(v, dtype=dtype) for k, v in fields.items()})
        return grasp if mask is None else grasp.replace(active=jnp.asarray(mask, dtype=bool))

    def astype(self, dtype) -> "Grasp":
        """The same grasp with every field cast to ``dtype`` (``jnp.float32`` or ``jnp.float64``)."""
        dtype = _field_dtype(dtype)
        cast = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype=dtype), self.replace(active=None))
        return cast.replace(active=self.active)

    def replace(self, **changes) -> "Grasp":
        """Return a copy with some fields replaced (no validation: for traced values)."""
        return dataclasses.replace(self, **changes)

    def to_numpy(self) -> dict[str, np.ndarray]:
        """Fields as a dict of NumPy arrays (for files and reports); ``active`` only where
        the grasp has a mask."""
        fields = [f.name for f in dataclasses.fields(self)]
        return {n: np.asarray(getattr(self, n)) for n in fields if n != "active" or self.active is not None}

    def to_numpy_batch(self) -> dict[str, np.ndarray]:
        """The fields of a batched grasp (``positions (B, N, 3)``) as NumPy arrays, each
        with that leading ``B`` axis: a field given once for the whole batch (no batch
        axis, e.g. ``gravity (3,)``) is broadcast to it."""
        raw = self.to_numpy()
        b = raw["positions"].shape[0]
        ndim = {**{f.name: f.ndim for f in FIELDS}, "active": 1}  # axes of one grasp's field
        return {k: a if a.ndim > ndim[k] else np.broadcast_to(a, (b, *a.shape)) for k, a in raw.items()}

    def compact(self) -> "Grasp":
        """The same grasp with only its active contacts and no mask (concrete, unbatched)."""
        if self.active is None:
            return self
        keep = np.asarray(self.active, dtype=bool)
        if keep.ndim != 1:
            raise ValueError(f"compact() needs one grasp (active of shape (N,)), got {keep.shape}")
        per_contact = {n: jnp.asarray(getattr(self, n)) for n in _PER_CONTACT}
        return self.replace(active=None, **{n: a if a.ndim == 0 else a[keep] for n, a in per_contact.items()})


def stack(grasps, num_contacts: int | None = None) -> Grasp:
    """Stack grasps with any numbers of contacts into one batched [`Grasp`][jaxgrasp.Grasp].

    Each grasp is padded to the largest contact count ``N`` with inactive contacts that
    repeat its last active contact (valid numbers, masked out), so the batch has
    ``positions (B, N, 3)``, per-contact fields ``(B, N)``, ``mass (B,)``, ``gravity
    (B, 3)`` and ``active (B, N)``, and ``jax.vmap(jaxgrasp.evaluate)`` of it gives every
    grasp's own result (boundaries of padding contacts ``no_start``) with one compilation.

    Args:
        grasps: a non-empty sequence of unbatched grasps (a grasp with a mask is compacted
            first).
        num_contacts: pad to at least this many contacts (a fixed ``N``, so that batches
            of different sets share one compilation); default the largest count.
    """
    items = [g.compact() for g in grasps]
    if not items:
        raise ValueError("stack needs at least one grasp")
    n = max([g.num_contacts for g in items] + [int(num_contacts or 0)])
    fields = [f.name for f in dataclasses.fields(Grasp) if f.name != "active"]
    out = {name: [] for name in fields}
    active = []
    for g in items:  # on the host, in NumPy: thousands of grasps, a few fields each
        k = g.num_contacts
        pad = np.concatenate([np.arange(k), np.full(n - k, k - 1)]).astype(int)
        for name in fields:
            a = np.asarray(getattr(g, name))
            if name in _PER_CONTACT:  # a scalar stands for every contact
                a = np.broadcast_to(a, (k,)) if a.ndim == 0 else a
                a = a[pad]
            out[name].append(a)
        active.append(np.arange(n) < k)
    return Grasp(**{name: jnp.asarray(np.stack(v)) for name, v in out.items()}, active=jnp.asarray(np.stack(active)))


def _field_dtype(dtype) -> np.dtype:
    """The dtype of a grasp's fields: float64 for ``None`` (float32 where x64 is off)."""
    from jaxgrasp.model._validation import GraspValueError

    if dtype is None:
        return jax.dtypes.canonicalize_dtype(jnp.float64)
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise GraspValueError(f"dtype must be float32 or float64, got {dtype!r}") from None
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise GraspValueError(f"dtype must be float32 or float64, got {dt}")
    if dt == np.float64 and not jax.config.jax_enable_x64:
        raise GraspValueError("dtype float64 needs JAX's x64 mode, which JAX_ENABLE_X64=0 switched off")
    return dt
