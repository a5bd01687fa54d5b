"""A chunk moved between the batch's contact width and a segment's own
(`Segment`): its grasps' fields narrowed to the segment's
width on the way in, their results widened back to the batch's on the way out, laid out
as the batch's program lays out an inactive contact ([`Evaluation`][jaxgrasp.Evaluation])."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from jaxgrasp.model import FIELD
from jaxgrasp.solver import LaneStatus

__all__ = ["contact_slots", "narrow", "widen"]


def contact_slots(active: np.ndarray | None, width: int, rows: int) -> np.ndarray:
    """``(rows, width)`` the batch's contacts that a segment of ``width`` keeps for each
    grasp: every contact in its place where ``width`` is the batch's ``N`` (the program
    takes the mask as it is), else its active contacts first, in order, then inactive
    ones (``active`` ``(rows, N)``; ``None``: every contact of ``N = width`` active)."""
    if active is None or width == active.shape[1]:
        return np.broadcast_to(np.arange(width), (rows, width))
    return np.argsort(~active, axis=1, kind="stable")[:, :width]


def narrow(fields: Mapping[str, np.ndarray], slots: np.ndarray, masked: bool) -> dict[str, np.ndarray]:
    """The grasp ``fields`` of a chunk (leading axis ``B``, contacts ``N``) with only the
    contacts ``slots`` ``(B, width)``; ``active`` ``(B, width)`` where ``masked`` (from
    ``fields``' own, or every contact where it has none), dropped otherwise."""
    out = {}
    for name, a in fields.items():
        if name == "active":
            continue
        out[name] = np.take_along_axis(a, slots if a.ndim == 2 else slots[..., None], axis=1) if (
            FIELD[name].per_contact) else a
    if masked:
        active = fields.get("active")
        out["active"] = np.ones(slots.shape, bool) if active is None else np.take_along_axis(active, slots, axis=1)
    return out


def widen(results: Mapping[str, np.ndarray], slots: np.ndarray, n_contacts: int) -> dict[str, np.ndarray]:
    """A chunk's [`Evaluation`][jaxgrasp.Evaluation] fields (leading axis ``B``) from a program
    of ``width`` contacts, laid out for ``n_contacts >= width``: contact ``j`` of the
    segment becomes the batch's ``slots[:, j]``; the batch's other contacts hold what an
    inactive one does (boundary energy ``+inf``, the equilibrium pose, status
    ``NO_START``, margins 1, KKT rows NaN, 0 steps); ``limiting_contact`` is renumbered.
    Only the fields in ``results`` are laid out (a boundary pose needs its equilibrium's).
    """
    b, width = slots.shape
    if width == n_contacts and np.array_equal(slots, np.broadcast_to(np.arange(width), slots.shape)):
        return dict(results)
    out = dict(results)
    rows = np.arange(b)[:, None]

    def per_contact(name, fill):
        # (B, rows, width, ...) -> (B, rows, n_contacts, ...): every per-contact field has
        # its contacts on axis 2 (rows: 2 boundary kinds, or 3 margin rows)
        a = np.asarray(results[name])
        wide = np.empty((b, a.shape[1], n_contacts, *a.shape[3:]), dtype=a.dtype)
        wide[...] = fill
        for r in range(a.shape[1]):
            wide[rows, r, slots] = a[:, r]
        return wide

    fills = {"boundary_energy": np.inf, "boundary_status": LaneStatus.NO_START, "equilibrium_margins": 1.0}
    for name, fill in fills.items():
        if name in results:
            out[name] = per_contact(name, fill)
    for name, pose in (("boundary_translation", "equilibrium_translation"),
                       ("boundary_rotation", "equilibrium_rotation")):
        if name in results:
            out[name] = per_contact(name, np.asarray(results[pose])[:, None, None, :])
    # kkt and steps: row 0 the equilibrium, row 1 + kind * N + contact a boundary problem
    for name, fill in (("kkt", np.nan), ("steps", 0)):
        if name not in results:
            continue
        a = np.asarray(results[name])
        wide = np.empty((b, 1 + 2 * n_contacts, *a.shape[2:]), dtype=a.dtype)
        wide[...] = fill
        wide[:, 0] = a[:, 0]
        for kind in range(2):
            wide[rows, 1 + kind * n_contacts + slots] = a[:, 1 + kind * width : 1 + (kind + 1) * width]
        out[name] = wide
    if "limiting_contact" in results:
        limit = np.asarray(results["limiting_contact"])
        picked = np.take_along_axis(slots, np.clip(limit, 0, width - 1)[:, None], axis=1)[:, 0]
        out["limiting_contact"] = np.where(limit >= 0, picked, limit).astype(limit.dtype)
    return out
