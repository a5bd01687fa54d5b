"""A hand's URDF file and the meshes it names, read and checked by jaxgrasp before MuJoCo sees them.

MuJoCo compiles URDF as it compiles MJCF; jaxgrasp reads the file as it reads an MJCF
file (`jaxgrasp.hands._mjcf_files`: UTF-8 without ``<!DOCTYPE``/``<!ENTITY``, regular
files under their caps, the same size caps with links counted as bodies) and gives
MuJoCo the checked text with each mesh as bytes. What is particular to URDF:

* **Collision meshes only.** ``<visual>`` elements are removed before MuJoCo sees the
  file (their meshes, often COLLADA, are never read); a ``<collision>`` mesh must be STL,
  OBJ or MSH (MuJoCo's formats: convert a ``.dae``). A mesh's ``filename`` resolves as
  ROS users expect: ``package://PKG/rel/path`` in the nearest folder named ``PKG`` that is
  the URDF's folder or one of its ancestors, else in an allowed folder named ``PKG`` or
  holding a folder ``PKG``; ``file:///abs/path`` and an absolute path as they are; any
  other path relative to the URDF's folder. Wherever it resolves, the mesh must lie in
  the URDF's folder or an allowed one after symlinks (a ``package://`` mesh of the
  usual layout, ``PKG/urdf/hand.urdf`` beside ``PKG/meshes/``, needs ``--allow-dir PKG``).
* **Links keep their names.** jaxgrasp replaces the file's own ``<mujoco>`` element by
  one whose ``<compiler>`` keeps links joined by fixed joints as bodies of their own
  (``fusestatic="false"``: MuJoCo would fuse them, and their names with them), drops
  visual geoms, and bounds masses and inertias from below (``boundmass``,
  ``boundinertia``, ``balanceinertia``: a massless link compiles; the kinematics never
  use masses).
* **Joints.** ``revolute`` and ``continuous`` become hinges, ``prismatic`` slides,
  ``fixed`` none; ``floating`` and ``planar`` are refused (give the hand's pose as the
  wrist). A ``<mimic>`` joint stays a joint of its own in ``qpos``: MuJoCo turns the
  relation into an equality constraint, which the kinematics do not apply (set the
  mimic joint's position to ``multiplier * q + offset`` yourself).
* **Refused:** a xacro file (run ``xacro`` first), a mesh under another scheme
  (``http://``, ``model://``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

from jaxgrasp.hands._mjcf_files import (
    MAX_MJCF_BODIES,
    MAX_MJCF_DEPTH,
    MAX_MJCF_ELEMENTS,
    HandSource,
    _confined,
    _Files,
    _within,
    read_mesh,
)
from jaxgrasp.io import check_path_text

__all__ = ["check_urdf", "URDF_COMPILER"]

URDF_COMPILER = ('<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false" balanceinertia="true" '
                 'boundmass="1e-6" boundinertia="1e-12"/></mujoco>')
"""The ``<mujoco>`` element jaxgrasp gives every URDF hand file (module notes)."""

_JOINTS = ("revolute", "continuous", "prismatic", "fixed")
_MESH_SUFFIXES = (".stl", ".obj", ".msh")


def check_urdf(root, files: _Files) -> HandSource:
    """The URDF hand file of ``root`` (`jaxgrasp.hands._mjcf_files.open_hand_file`) after
    the module's checks: visual elements and the file's ``<mujoco>`` removed, every
    collision mesh read and renamed, jaxgrasp's compiler settings added.

    Raises:
        GraspValueError: a rule of the module notes or of `jaxgrasp.hands._mjcf_files`
            broken; one line.
    """
    _census(root, files)
    for parent in [root, *root.iter("link")]:
        for el in [c for c in parent if c.tag in ("visual", "mujoco")]:
            parent.remove(el)
    for joint in root.findall("joint"):
        _check_joint(joint, files)
    for collision in root.iter("collision"):
        for mesh in collision.iter("mesh"):
            mesh.set("filename", _mesh(mesh, files))
    root.append(ET.fromstring(URDF_COMPILER))
    return HandSource("urdf", ET.tostring(root, encoding="unicode"), files.assets, files.names, root, files.lines)


def _census(root, files: _Files) -> None:
    """Nesting, elements and links under the caps of MJCF; no xacro."""
    elements = links = 0
    stack = [(root, 1)]
    while stack:
        el, depth = stack.pop()
        if depth > MAX_MJCF_DEPTH:
            files.refuse(f"its elements nest deeper than {MAX_MJCF_DEPTH} levels")
        if ":" in el.tag:
            files.refuse(f"it holds <{el.tag[:40]}>: a xacro file; run xacro to make the URDF first")
        elements += 1
        links += el.tag == "link"
        if elements > MAX_MJCF_ELEMENTS or links > MAX_MJCF_BODIES:
            files.refuse(f"it has more than {MAX_MJCF_ELEMENTS} elements or {MAX_MJCF_BODIES} links")
        stack.extend((c, depth + 1) for c in el)


def _check_joint(joint, files: _Files) -> None:
    kind, name = joint.get("type", ""), joint.get("name", "")
    if kind in ("floating", "planar"):
        files.refuse(f"joint {name[:80]!r} is {kind}; a hand's joints are revolute, continuous, prismatic or fixed "
                     "(give the hand's pose as the wrist instead)")
    if kind not in _JOINTS:
        files.refuse(f"joint {name[:80]!r} has type {kind[:40]!r}, not one of {', '.join(_JOINTS)}")


def _mesh(mesh, files: _Files) -> str:
    """The name MuJoCo gets for a collision mesh, its file read (module notes)."""
    name = check_path_text(mesh.get("filename", ""), "<mesh> filename")
    if not name:
        files.refuse("a collision <mesh> has no filename")
    if name.startswith("package://"):
        candidates = _package(name, files)
    elif name.startswith("file://"):
        candidates = [name[len("file://"):]]
        if not os.path.isabs(candidates[0]):
            files.refuse(f"<mesh> filename {name!r}: a file:// path must be absolute (file:///...)")
    elif "://" in name:
        files.refuse(f"<mesh> filename {name!r}: jaxgrasp reads package://, file:// or plain paths only")
    else:
        candidates = [os.path.join(files.main_dir, name)]
    return read_mesh(files, name, name, candidates, _MESH_SUFFIXES, "<mesh> filename")


def _package(name: str, files: _Files) -> list:
    """Where ``package://PKG/rel`` may be (module notes), those inside the allowed
    folders as written; a one-line error if none is."""
    pkg, _, rel = name[len("package://"):].partition("/")
    if not pkg or not rel or pkg in (".", ".."):
        files.refuse(f"<mesh> filename {name!r} is not package://PACKAGE/path")
    folders, here = [], files.main_dir
    while True:
        if os.path.basename(here) == pkg:
            folders.append(here)
        if os.path.dirname(here) == here:
            break
        here = os.path.dirname(here)
    for allowed in files.real[1:]:
        folders += [allowed] if os.path.basename(allowed) == pkg else []
        folders += [os.path.join(allowed, pkg)] if os.path.isdir(os.path.join(allowed, pkg)) else []
    candidates = [os.path.join(f, rel) for f in folders]
    inside = [c for c in candidates if _within(os.path.normpath(c), files.lexical)]
    if candidates and not inside:
        _confined(files, candidates[0], name, "<mesh> filename")  # refuses: outside
    if not inside:
        files.refuse(f"<mesh> filename {name!r}: no folder named {pkg[:80]!r} is the URDF's folder, one of its "
                     "ancestors, or in an allowed folder (--allow-dir DIR)")
    return inside

