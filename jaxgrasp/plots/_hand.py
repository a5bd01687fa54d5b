"""Pictures of a hand's grasp: the hand's links with the object and the way the grasp fails.

`hand_scene` adds the hand's geoms (capsules, spheres, cylinders and boxes, the
fingertips' own capsules among them; mesh geoms are left out) near the object to the
`GraspScene` of its grasp, in the object's mesh frame;
`plot_hand_grasp` draws it with `draw_scene`: the object, the
ghost at the least-energy pose of the limiting boundary, each active contact's fingertip
hemisphere as the paper models it (pressed in along the normal) and the hand's links as
they are, so that each fingertip's tilt from the paper's assumption can be seen (the
title states it).
"""

from __future__ import annotations

import numpy as np

from jaxgrasp.plots._scene import GraspScene, Part, grasp_scene

__all__ = ["hand_scene", "plot_hand_grasp", "LINK_COLOR", "link_meshes"]

LINK_COLOR = (0.42, 0.47, 0.55, 0.30)
"""RGBA of the hand's links."""

_SPHERE, _CAPSULE, _CYLINDER, _BOX = 2, 3, 5, 6  # mujoco.mjtGeom


def _geom_mesh(kind: int, size: np.ndarray):
    """A ``trimesh.Trimesh`` of a MuJoCo geom in its own frame (``None`` for other kinds)."""
    import trimesh

    if kind == _CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[12, 12])
    if kind == _CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=16)
    if kind == _BOX:
        return trimesh.creation.box(extents=2 * size[:3])
    if kind == _SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    return None


def link_meshes(hand_grasp, reach: float | None = None) -> list:
    """``[(name, mesh)]``: the hand's geoms as meshes in the object's mesh frame (m), those
    whose centre lies within ``reach`` (m; default: the object's size plus 40 mm) of
    the object's centre of mass."""
    hand = hand_grasp.hand
    tree = hand.tree
    xpos, xmat = (np.asarray(a) for a in hand.geom_frames(np.asarray(hand_grasp.qpos), np.asarray(hand_grasp.wrist)))
    xpos_m = hand_grasp.to_mesh_frame(xpos)
    rot_m = hand_grasp.to_mesh_frame(np.zeros(3))  # the world's origin in the mesh frame
    com = np.asarray(hand_grasp.center_of_mass)
    size = float(np.ptp(hand_grasp.mesh.vertices, axis=0).max())
    reach = size + 0.04 if reach is None else reach
    out = []
    for g in range(len(tree.geom_body)):
        mesh = _geom_mesh(int(tree.geom_type[g]), tree.geom_size[g])
        if mesh is None or np.linalg.norm(xpos_m[g] - com) > reach:
            continue
        axes_m = hand_grasp.to_mesh_frame(xmat[g].T) - rot_m  # the geom's axes (rows), mesh frame
        mesh.vertices = mesh.vertices @ axes_m + xpos_m[g]
        out.append((tree.geom_names[g] or f"geom {g}", mesh))
    return out


def hand_scene(hand_grasp, result, *, magnification: float | None = None) -> GraspScene:
    """The `GraspScene` of a [`HandGrasp`][jaxgrasp.hands.HandGrasp]'s
    active contacts and its [`Evaluation`][jaxgrasp.Evaluation] ``result`` (of its grasp,
    ``hand_grasp.grasp``, mask and all), with the hand's links added as parts of role
    ``"link"``. Contact ``k`` is fingertip ``k`` (in the order the hand lists them,
    touching or not) in the parts' names, the labels and the limiting contact, each
    labelled with its fingertip's name."""
    import dataclasses

    scene = grasp_scene(hand_grasp.mesh_grasp(), result, magnification=magnification,
                        names=hand_grasp.hand.fingertip_names)
    links = tuple(Part(f"link {name}", "link", mesh, LINK_COLOR) for name, mesh in link_meshes(hand_grasp))
    return dataclasses.replace(scene, parts=scene.parts[:1] + links + scene.parts[1:])


def _tilt_line(hand_grasp) -> str:
    """``fingertip tilt from the paper's assumption: 0 robot0:C_ffdistal 12 deg, 4
    robot0:C_thdistal 31 deg; not in contact: 1, 2, 3`` (fingertip numbers = contact numbers)."""
    tilt = np.degrees(np.asarray(hand_grasp.tilt))
    active = np.asarray(hand_grasp.active)
    names = hand_grasp.hand.fingertip_names
    on = ", ".join(f"{k} {n} {t:.0f} deg" for k, (n, t, a) in enumerate(zip(names, tilt, active)) if a)
    off = [str(k) for k, a in enumerate(active) if not a]
    return "fingertip tilt from the paper's assumption: " + on + (f"; not in contact: {', '.join(off)}" if off else "")


def plot_hand_grasp(hand_grasp, path=None, *, result=None, magnification=None, title=None, view=(22.0, -58.0)):
    """A 3-D picture of a hand's grasp (a [`HandGrasp`][jaxgrasp.hands.HandGrasp]): the object,
    the hand's links, the modelled fingertips, and the object at the least-energy pose of
    the limiting boundary (the ghost, its motion magnified). Axes in mm, mesh frame.

    Args:
        hand_grasp: the [`HandGrasp`][jaxgrasp.hands.HandGrasp] (at least 2 active contacts).
        path: where to save the figure (PNG, ...); ``None`` returns it open.
        result: the [`Evaluation`][jaxgrasp.Evaluation] of ``hand_grasp.grasp`` (its contact
            ``k`` fingertip ``k``; default: evaluated here).
        magnification, title, view: as for `jaxgrasp.plots.plot_grasp`.

    Returns:
        The matplotlib ``Figure``.
    """
    from matplotlib.patches import Patch

    from jaxgrasp.plots._plots import _grasp_title, _save, draw_scene, plain_text

    if result is None:
        from jaxgrasp.engine import evaluate

        result = evaluate(hand_grasp.grasp)
    scene = hand_scene(hand_grasp, result, magnification=magnification)
    head = plain_text(title) if title else _grasp_title(scene)
    fig = draw_scene(scene, title=head + "\n" + _tilt_line(hand_grasp), view=view)
    fig.legend(handles=[Patch(color=LINK_COLOR, label="hand links (collision geoms)")], loc="upper right", bbox_to_anchor=(0.99, 0.86),
               fontsize=8, frameon=False)
    return _save(fig, path)
