"""A hand's fingertips: each a hemisphere fixed to one of its bodies (links).

A fingertip is named in one of three ways (`resolve_fingertips`):

* **a geom** (its name): a sphere or a capsule geom. The hemisphere is the geom's end: a
  sphere's centre, or the centre of the capsule's end cap farther from its body's origin
  (the finger's last joint), with the geom's radius; its axis is the geom's ``z``
  turned towards that cap (``+z`` for a sphere). Only that geom belongs to the fingertip.
* **a body** (MJCF) **or link** (URDF) (its name, where no geom has that name) whose
  geoms include exactly one sphere or capsule: that geom's hemisphere, as above. URDF
  collision elements are often unnamed geoms in MuJoCo: naming the link is the way to
  reach them. All the body's geoms belong to the fingertip.
* **a link with a hemisphere** ``{"link": NAME, "center": (3,) m, "axis": (3,),
  "radius": m}``, centre and axis in the link's (body's) frame, the axis normalised: for
  hands whose fingertips are meshes. All the body's geoms belong to the fingertip.

Every fingertip becomes a `Fingertip`: its body, centre and unit axis in that body's
frame, and radius, computed once here, so that the world frames are one code path (the
body's frame, then the local offset: `jaxgrasp.hands.Hand.fingertip_frames`). The geoms
that belong to a fingertip are left out of the links that `tune_hand` keeps out of the
object.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from jaxgrasp.hands._kinematics import cap_offsets, quat_to_matrix
from jaxgrasp.hands._mjcf import CAPSULE, SPHERE, KinematicTree
from jaxgrasp.model import MAX_FINGERTIP_RADIUS, GraspValueError, as_float_array

__all__ = ["Fingertip", "resolve_fingertips"]

_HEMISPHERE_KEYS = ("link", "center", "axis", "radius")


@dataclasses.dataclass(frozen=True)
class Fingertip:
    """One fingertip (SI units).

    Attributes:
        name: the geom's or the link's name.
        body: index of the body it is fixed to.
        center: ``(3,)`` m, the hemisphere's centre in the body's frame.
        axis: ``(3,)`` unit, the way it points, in the body's frame.
        radius: m.
        geoms: indices of the geoms that belong to it.
    """

    name: str
    body: int
    center: np.ndarray
    axis: np.ndarray
    radius: float
    geoms: tuple


def resolve_fingertips(tree: KinematicTree, specs) -> tuple:
    """The `Fingertip` of each of ``specs`` (at least 2; module notes), in order.

    Raises:
        GraspValueError: fewer than 2, a spec of another kind, an unknown name (the
            message lists the choices), a geom that is not a sphere or capsule, a link
            without exactly one sphere or capsule, a bad hemisphere, a name given twice; one line.
    """
    if isinstance(specs, (str, Mapping)) or not isinstance(specs, Sequence) or len(specs) < 2 \
            or not all(isinstance(s, (str, Mapping)) for s in specs):
        raise GraspValueError("fingertips must be at least 2 geom or link names, or {link, center, axis, radius} "
                              f"tables, got {_short(specs)}")
    tips = tuple(_hemisphere(tree, s) if isinstance(s, Mapping) else _named(tree, s) for s in specs)
    names = [t.name for t in tips]
    twice = [n for n in names if names.count(n) > 1]
    if twice:
        raise GraspValueError(f"fingertips: {twice[0]!r} is given twice")
    return tips


def _named(tree: KinematicTree, name: str) -> Fingertip:
    """The fingertip of a geom called ``name``, else of the body called ``name``."""
    if name and name in tree.geom_names:
        g = tree.geom_names.index(name)
        if tree.geom_type[g] not in (SPHERE, CAPSULE):
            raise GraspValueError(f"fingertips: geom {name!r} is neither a sphere nor a capsule; name a sphere or "
                                  'capsule geom, or give {link = "...", center = [...], axis = [...], radius = ...}')
        return _of_geom(tree, g, name, (g,))
    b = _body(tree, name)
    own = [g for g in range(len(tree.geom_body)) if tree.geom_body[g] == b]
    round_ = [g for g in own if tree.geom_type[g] in (SPHERE, CAPSULE)]
    if len(round_) != 1:
        raise GraspValueError(
            f"fingertips: link {name!r} has {len(round_)} sphere or capsule geoms, not one; give its fingertip as "
            '{link = "...", center = [x, y, z], axis = [x, y, z], radius = r} (m, in the link\'s frame)')
    return _of_geom(tree, round_[0], name, tuple(own))


def _of_geom(tree: KinematicTree, g: int, name: str, geoms: tuple) -> Fingertip:
    """The hemisphere at the end of the sphere or capsule geom ``g``, in its body's frame."""
    offset = float(cap_offsets(tree, [g])[0])
    z = quat_to_matrix(tree.geom_quat[g])[:, 2]
    return Fingertip(name, int(tree.geom_body[g]), tree.geom_pos[g] + z * offset, z * (-1.0 if offset < 0 else 1.0),
                     float(tree.geom_size[g, 0]), geoms)


def _body(tree: KinematicTree, name: str) -> int:
    """The index of the body (link) called ``name``; a one-line error listing the choices otherwise."""
    if name and name in tree.body_names[1:]:
        return tree.body_names.index(name, 1)
    geoms = ", ".join(n for n in tree.geom_names if n) or "none"
    links = ", ".join(n for n in tree.body_names[1:] if n) or "none"
    raise GraspValueError(_short(f"fingertips: no geom or link named {name!r} in {tree.source}; its named geoms: "
                                 f"{geoms}; its links: {links}", 600))


def _hemisphere(tree: KinematicTree, spec: Mapping) -> Fingertip:
    """The fingertip ``{"link", "center", "axis", "radius"}``, checked."""
    keys = sorted(set(spec) ^ set(_HEMISPHERE_KEYS))
    if keys:
        raise GraspValueError(f"fingertips: a hemisphere fingertip has the keys {', '.join(_HEMISPHERE_KEYS)} "
                              f"(centre and axis in the link's frame, m), not {_short(dict(spec))}")
    if not isinstance(spec["link"], str):
        raise GraspValueError(f"fingertips: link = {_short(spec['link'])} must be a link name")
    link = spec["link"]
    b = _body(tree, link)
    center = _vector(spec["center"], f"fingertip {link!r}: center", "m, in the link's frame")
    axis = _vector(spec["axis"], f"fingertip {link!r}: axis", "the direction the fingertip points, in the link's frame")
    if not np.linalg.norm(axis) > 1e-9:
        raise GraspValueError(f"fingertip {link!r}: axis = {axis.tolist()} has no direction")
    radius = as_float_array(f"fingertip {link!r}: radius", spec["radius"])
    if radius.shape != () or not 0.0 < float(radius) <= MAX_FINGERTIP_RADIUS:
        raise GraspValueError(f"fingertip {link!r}: radius = {_short(spec['radius'])} must be one number in "
                              f"(0, {MAX_FINGERTIP_RADIUS:g}] m")
    own = tuple(g for g in range(len(tree.geom_body)) if tree.geom_body[g] == b)
    return Fingertip(link, b, center, axis / np.linalg.norm(axis), float(radius), own)


def _vector(value, name: str, what: str) -> np.ndarray:
    q = as_float_array(name, value)
    if q.shape != (3,) or not np.all(np.isfinite(q)):
        raise GraspValueError(f"{name} must be 3 finite numbers ({what}), got {_short(value)}")
    return q


def _short(value, limit: int = 80) -> str:
    """``repr(value)`` (a string as it is), at most ``limit`` characters."""
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."
