"""A hand's MJCF file and every file it names, read and checked by jaxgrasp before MuJoCo sees them.

MuJoCo's compiler opens whatever a model names (``<include file>``, ``meshdir``, a mesh's
``file``), wherever it lies, and blocks on a FIFO; ``<replicate count>`` and a few other
counts make models that compile for hours. So jaxgrasp reads a hand file itself
(`checked_mjcf`) and gives MuJoCo only checked text and bytes
(``MjModel.from_xml_string(xml, assets)``, every file it needs in ``assets``): MuJoCo
opens no file. The rules, each broken in one line naming the hand file, the name written
in it and the rule (never the content of a file outside the allowed folders, none of
which is read):

* **Where.** Every path a hand file names resolves, after symlinks, inside the hand
  file's folder or a folder the user allows (``allowed_dirs=``, ``--allow-dir DIR``: the
  rule of grasp files, `jaxgrasp.io.confine`). Paths are resolved as MuJoCo does: an
  include relative to the main file's folder, else to the including file's; a mesh, skin
  or flex file relative to ``meshdir`` (a texture to ``texturedir``; ``assetdir`` sets
  both; the last ``<compiler>`` wins) under the main file's folder, else to the folder of
  the file naming it. Each path is checked as written (lexically) before anything is
  looked up, then after symlinks.
* **What.** Only regular files are read (no FIFO, device or folder; opened without
  blocking), each under its cap (`MAX_MJCF_BYTES` per XML file,
  `MAX_HAND_ASSET_BYTES` per mesh), all together under `MAX_HAND_FILES_BYTES`; XML
  as UTF-8 without ``<!DOCTYPE``/``<!ENTITY`` (no entity expansion); an include at most
  once; meshes as STL, OBJ or MSH, skins as SKN.
* **How big**, counted before compiling, with every ``<replicate count>`` multiplied out:
  `MAX_MJCF_DEPTH` levels of nesting, `MAX_MJCF_ELEMENTS` elements,
  `MAX_MJCF_BODIES` bodies (a flexcomp's ``count`` included), `MAX_MJCF_USER`
  keyframes, user fields and custom numbers, builtin mesh parameters at most
  `MAX_BUILTIN_PARAM`.
* **Not handed to MuJoCo**, as a hand's kinematics never uses them: textures become flat
  8 x 8 ones (their files are checked to lie in the folder but never read: no image is
  decoded), actuator length ranges are not computed (``lengthrange mode="none"``: MuJoCo
  would simulate to find them), and ``<size>``'s simulation-memory entries are dropped.
* **Refused:** height-field files, ``<model>`` assets (a second MJCF), plugins, a root
  other than ``<mujoco>``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import re
import xml.etree.ElementTree as ET
from xml.parsers import expat

from jaxgrasp.io import check_path_text, read_input
from jaxgrasp.model import GraspValueError

__all__ = [
    "MAX_BUILTIN_PARAM",
    "MAX_HAND_ASSET_BYTES",
    "MAX_HAND_FILES_BYTES",
    "MAX_MJCF_BODIES",
    "MAX_MJCF_BYTES",
    "MAX_MJCF_DEPTH",
    "MAX_MJCF_ELEMENTS",
    "MAX_MJCF_USER",
    "HandSource",
    "open_hand_file",
    "check_mjcf",
    "checked_mjcf",
]

MAX_MJCF_BYTES = 16 * 2**20
"""Largest XML file of a hand read (the main file or an include), bytes (16 MiB)."""
MAX_HAND_ASSET_BYTES = 32 * 2**20
"""Largest mesh, skin or flex file of a hand read, bytes (32 MiB: an OBJ of about 800,000
triangles; MuJoCo reads at most 200,000 from an STL)."""
MAX_HAND_FILES_BYTES = 64 * 2**20
"""Most bytes read for one hand, all its files together (64 MiB: what MuJoCo compiles
within a minute on a slow machine, see ``docs/guide/hands.md``)."""
MAX_MJCF_DEPTH = 100
"""Deepest nesting of elements (the Shadow hand's is 14)."""
MAX_MJCF_ELEMENTS = 100_000
"""Most elements of a hand, replicates multiplied out (the Shadow hand has about 600)."""
MAX_MJCF_BODIES = 2_000
"""Most bodies of a hand, replicates and flexcomp counts multiplied out (the Shadow hand
has 31; MuJoCo's compiling time grows more than linearly with the bodies, see
``docs/guide/hands.md``)."""
MAX_MJCF_USER = 1_000
"""Most keyframes (``<size nkey>``), user numbers per element (``nuser_*``), and numbers
of a ``<custom><numeric size>``."""
MAX_BUILTIN_PARAM = 200
"""Largest parameter of a builtin mesh (its resolution: 200 makes 40,000 vertices)."""

_MESH_SUFFIXES = {"mesh": (".stl", ".obj", ".msh"), "flexcomp": (".stl", ".obj", ".msh"), "skin": (".skn",)}
_CONTENT_TYPES = ("model/stl", "model/obj", "model/vnd.mujoco.msh")
_REFUSED = {"model": "a <model> asset (a second MJCF)", "plugin": "a plugin", "extension": "a plugin extension",
            "instance": "a plugin instance"}
_SIM_MEMORY = ("memory", "nstack", "njmax", "nconmax", "nuserdata")  # MjData's, never made for a hand
_DECLARATION = re.compile(r"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


@dataclasses.dataclass
class _Files:
    """What one hand's files have been so far: where they may be, and what was read."""

    given: str  # the hand file as the user gave it, for messages
    main_dir: str  # its folder as given (absolute): MuJoCo's base for relative names
    lexical: tuple  # folders a path as written may be in (abspath and realpath of main_dir, allowed)
    real: tuple  # folders a path may lead to after symlinks
    total: int = 0
    included: set = dataclasses.field(default_factory=set)
    assets: dict = dataclasses.field(default_factory=dict)  # name given to MuJoCo -> bytes
    names: dict = dataclasses.field(default_factory=dict)  # name given to MuJoCo -> name written in the file
    lines: dict = dataclasses.field(default_factory=dict)  # element -> (file as written, line): for messages

    def refuse(self, text: str):
        raise GraspValueError(f"hand file {self.given!r}: {text}")


@dataclasses.dataclass
class _Census:
    """Counts and elements gathered on the walk over the expanded tree."""

    elements: int = 0
    bodies: int = 0
    compilers: list = dataclasses.field(default_factory=list)
    files: list = dataclasses.field(default_factory=list)  # (element, folder of the XML file naming it)
    textures: list = dataclasses.field(default_factory=list)
    sizes: list = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class HandSource:
    """A hand file, checked: what MuJoCo is given, and what explains its refusals.

    Attributes:
        kind: ``"mjcf"`` or ``"urdf"``.
        xml: the text MuJoCo compiles (includes expanded, file names replaced).
        assets: ``{name: bytes}``, every file MuJoCo needs.
        names: each asset's name -> the name written in the hand file.
        root: the element tree of ``xml``.
        lines: element -> ``(file as written, line)`` where it was written.
    """

    kind: str
    xml: str
    assets: dict
    names: dict
    root: object
    lines: dict


def open_hand_file(path, allowed=()) -> tuple:
    """``(root, files)``: the hand file ``path`` read and parsed (module notes), and the
    record of its files to check the rest against. ``allowed``: more folders the hand's
    files may be in (`jaxgrasp.io.allowed_folders`, real paths)."""
    given = check_path_text(path, "hand file")
    main_dir = os.path.dirname(os.path.abspath(given))
    files = _Files(given, main_dir, (main_dir, os.path.realpath(main_dir), *allowed),
                   (os.path.realpath(main_dir), *allowed))
    return _parse(_read(files, given, "hand file", MAX_MJCF_BYTES), given, files), files


def check_mjcf(root, files: _Files) -> HandSource:
    """The MJCF hand file of ``root`` (`open_hand_file`) after the module's checks: its
    includes expanded, its file names replaced by those of the assets."""
    census = _walk(root, files)
    meshdir, texturedir, strip = _compiler_dirs(census.compilers)
    _limit_size(census, files)
    for el, src in census.files:
        _asset(el, src, meshdir, texturedir, strip, files)
    for el in census.textures:
        _flat_texture(el)
    root.append(ET.fromstring('<compiler><lengthrange mode="none"/></compiler>'))
    return HandSource("mjcf", ET.tostring(root, encoding="unicode"), files.assets, files.names, root, files.lines)


def checked_mjcf(path, allowed=()) -> tuple[str, dict, dict]:
    """``(xml, assets, names)`` of the MJCF hand file ``path`` (module notes): its
    includes expanded, its file names replaced by those of ``assets``; ``names`` maps each
    asset's name back to the name written in the hand file (for MuJoCo's messages)."""
    root, files = open_hand_file(path, allowed)
    if root.tag != "mujoco":
        files.refuse(f"its root element is <{root.tag}>, not <mujoco>: an MJCF file")
    source = check_mjcf(root, files)
    return source.xml, source.assets, source.names


def _read(files: _Files, where: str, what: str, cap: int) -> bytes:
    """The bytes of the regular file ``where`` (`jaxgrasp.io.read_input`), counted in the total."""
    raw = read_input(where, cap, what)
    files.total += len(raw)
    if files.total > MAX_HAND_FILES_BYTES:
        files.refuse(f"its files hold more than the {MAX_HAND_FILES_BYTES / 2**20:g} MiB read at most for one hand "
                     "(all files together)")
    return raw


def _parse(raw: bytes, where: str, files: _Files):
    """The root element of the XML ``raw`` (UTF-8, no DOCTYPE or entity declarations),
    each element's line noted in ``files.lines``."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        files.refuse(f"{where!r} is not UTF-8 text")
    if _DECLARATION.search(text):
        files.refuse(f"{where!r} declares a DOCTYPE or entities; a hand file needs neither (refused: entity bombs)")
    builder, parser = ET.TreeBuilder(), expat.ParserCreate("utf-8")  # no namespaces: a tag is as written
    parser.buffer_text = True

    def start(tag, attrs):
        files.lines[builder.start(tag, attrs)] = (where, parser.CurrentLineNumber)

    parser.StartElementHandler, parser.EndElementHandler, parser.CharacterDataHandler = start, builder.end, builder.data
    try:
        parser.Parse(text.encode("utf-8"), True)
    except expat.ExpatError as exc:
        files.refuse(f"{where!r} is not well-formed XML ({exc})")
    return builder.close()


def _within(path: str, folders) -> bool:
    return any(os.path.commonpath([path, f]) == f for f in folders)


def _confined(files: _Files, candidate: str, name: str, kind: str) -> str:
    """The real path of ``candidate`` (the file ``name`` as written, resolved), inside the
    allowed folders as written and after symlinks."""
    lexical = os.path.normpath(os.path.abspath(candidate))
    real = os.path.realpath(lexical) if _within(lexical, files.lexical) else None
    if real is None or not _within(real, files.real):
        files.refuse(f"{kind} {name!r} is outside the hand file's folder {files.real[0]!r}; pass --allow-dir DIR "
                     "(Python: allowed_dirs=) to allow it")
    return real


def _find(files: _Files, candidates, name: str, kind: str):
    """The real path of the first of ``candidates`` that exists (each checked with
    `_confined` before it is looked up); a one-line error if none does."""
    for c in candidates:
        real = _confined(files, c, name, kind)
        if os.path.lexists(real):
            return real
    looked = os.path.relpath(os.path.normpath(os.path.abspath(candidates[0])), files.main_dir) if candidates else name
    files.refuse(f"{kind} {name!r}: no such file (looked for {looked!r} from the hand file's folder)")


def _include(el, src: str, files: _Files):
    """``(root, folder)`` of the file an ``<include>`` names, read and parsed."""
    name = check_path_text(el.get("file", ""), "include")
    if not name:
        files.refuse("an <include> has no file")
    if len(files.included) >= 1000:
        files.refuse("it includes more than 1000 files")
    candidates = [os.path.join(files.main_dir, name)] + ([os.path.join(src, name)] if src != files.main_dir else [])
    real = _find(files, candidates, name, "include")
    if real in files.included:
        files.refuse(f"include {name!r} is included twice (MuJoCo refuses it too)")
    files.included.add(real)
    return _parse(_read(files, real, "included MJCF file", MAX_MJCF_BYTES), name, files), os.path.dirname(real)


def _children(el, src: str, files: _Files) -> list:
    """``[(child, folder of its file)]`` of ``el``, its ``<include>`` children replaced by
    the content of the files they name (in place, nested includes too)."""
    work, i, changed = [(c, src) for c in el], 0, False
    while i < len(work):
        child, s = work[i]
        if child.tag == "include":
            root, folder = _include(child, s, files)
            work[i:i + 1] = [(c, folder) for c in root]
            changed = True
        else:
            i += 1
    if changed:
        el[:] = [c for c, _ in work]
    return work


def _whole(el, attr: str, files: _Files, default: str = "1") -> list:
    """The whole numbers of ``el``'s attribute ``attr`` (space separated)."""
    text = el.get(attr, default)
    try:
        return [int(v) for v in text.split()]
    except ValueError:
        files.refuse(f"<{el.tag}> {attr}={text[:40]!r} is not whole numbers")


def _walk(root, files: _Files) -> _Census:
    """Expand the includes of the tree at ``root`` and count it (module notes), depth first."""
    census, stack = _Census(), [(root, 1, files.main_dir, 1)]
    while stack:
        el, depth, src, factor = stack.pop()
        if depth > MAX_MJCF_DEPTH:
            files.refuse(f"its elements nest deeper than {MAX_MJCF_DEPTH} levels")
        census.elements += factor
        if census.elements > MAX_MJCF_ELEMENTS:
            files.refuse(f"it makes more than {MAX_MJCF_ELEMENTS} elements (replicate counts multiplied out)")
        _note(el, src, factor, census, files)
        inner = factor * max(_whole(el, "count", files)[0], 0) if el.tag == "replicate" else factor
        stack.extend((c, depth + 1, s, inner) for c, s in reversed(_children(el, src, files)))
    return census


def _note(el, src: str, factor: int, census: _Census, files: _Files) -> None:
    """Count ``el`` and keep it where the later checks need it."""
    tag = el.tag
    if tag in _REFUSED:
        files.refuse(f"it holds {_REFUSED[tag]} (<{tag}>), which jaxgrasp does not give MuJoCo for a hand")
    if tag == "body" or tag == "flexcomp":
        n = 1
        for c in _whole(el, "count", files) if tag == "flexcomp" else [1]:
            n *= max(c, 1)
        census.bodies += factor * n
        if census.bodies > MAX_MJCF_BODIES:
            files.refuse(f"it makes more than {MAX_MJCF_BODIES} bodies (replicate and flexcomp counts multiplied out)")
    if tag == "hfield" and el.get("file") is not None:
        files.refuse("it reads a height field from a file, which jaxgrasp does not for a hand")
    points = _product(_whole(el, "nrow", files, "0") + _whole(el, "ncol", files, "0")) if tag == "hfield" else 0
    if points * factor > MAX_MJCF_ELEMENTS:
        files.refuse(f"a height field holds more than {MAX_MJCF_ELEMENTS} points")
    if tag == "mesh" and el.get("builtin") is not None:
        _builtin_params(el, files)
    census.compilers += [el] if tag == "compiler" else []
    census.textures += [el] if tag == "texture" else []
    census.sizes += [el] if tag in ("size", "numeric") else []
    if any(k.startswith("file") for k in el.attrib) and tag != "include":
        census.files.append((el, src))


def _product(values) -> int:
    out = 1
    for v in values:
        out *= max(v, 0)
    return out


def _builtin_params(el, files: _Files) -> None:
    """A builtin mesh's parameters, each at most `MAX_BUILTIN_PARAM` (its resolution)."""
    try:
        params = [float(v) for v in el.get("params", "").split()]
    except ValueError:
        files.refuse(f"a builtin mesh's params={el.get('params')[:40]!r} are not numbers")
    if any(not abs(p) <= MAX_BUILTIN_PARAM for p in params):
        files.refuse(f"a builtin mesh has a parameter above {MAX_BUILTIN_PARAM} (its resolution: too many vertices)")


def _compiler_dirs(compilers) -> tuple[str, str, bool]:
    """``(meshdir, texturedir, strippath)`` as MuJoCo reads them (the last ``<compiler>``
    wins; in one, ``meshdir``/``texturedir`` over ``assetdir``), removed from the
    compilers (the assets get flat names), with their ``lengthrange`` elements."""
    meshdir = texturedir = ""
    strip = False
    for c in compilers:
        if c.get("assetdir") is not None:
            meshdir = texturedir = c.get("assetdir")
        meshdir, texturedir = c.get("meshdir", meshdir), c.get("texturedir", texturedir)
        strip = c.get("strippath", "true" if strip else "false").strip().lower() == "true"
        for key in ("assetdir", "meshdir", "texturedir", "strippath"):
            c.attrib.pop(key, None)
        for lr in c.findall("lengthrange"):
            c.remove(lr)
    return meshdir, texturedir, strip


def _limit_size(census: _Census, files: _Files) -> None:
    """``<size>``: simulation memory dropped, keyframes and user numbers capped; ``<numeric size>`` capped."""
    for el in census.sizes:
        for key in list(el.attrib):
            if key in _SIM_MEMORY and el.tag == "size":
                del el.attrib[key]
            elif (key in ("nkey", "size") or key.startswith("nuser_")) and max(_whole(el, key, files)) > MAX_MJCF_USER:
                files.refuse(f"<{el.tag}> {key} is above {MAX_MJCF_USER}")


def _asset(el, src: str, meshdir: str, texturedir: str, strip: bool, files: _Files) -> None:
    """Read the file a mesh, skin or flexcomp names and give MuJoCo its bytes under a name
    of their digest; check a texture's files lie in the folder (never read); refuse others."""
    tag = el.tag
    keys = [k for k in el.attrib if k.startswith("file")]
    if not (tag == "texture" or tag in _MESH_SUFFIXES and keys == ["file"]):
        files.refuse(f"<{tag}> {keys[0]}=...: jaxgrasp reads no such file for a hand")
    for key in keys:
        name = check_path_text(el.get(key), f"<{tag}> {key}")
        written = os.path.basename(name) if strip else name
        folder = texturedir if tag == "texture" else meshdir
        candidates = [os.path.join(files.main_dir, folder, written)]
        candidates += [os.path.join(src, written)] if src != files.main_dir and not os.path.isabs(written) else []
        if tag == "texture":
            for c in candidates:
                _confined(files, c, name, f"<{tag}> {key}")
            continue
        _asset_file(el, name, written, candidates, files)


def _asset_file(el, name: str, written: str, candidates, files: _Files) -> None:
    tag = el.tag
    if el.get("content_type", _CONTENT_TYPES[0]) not in _CONTENT_TYPES:
        files.refuse(f"<{tag}> content_type {el.get('content_type')[:40]!r} is not one of {', '.join(_CONTENT_TYPES)}")
    el.set("file", read_mesh(files, name, written, candidates, _MESH_SUFFIXES[tag], f"<{tag}> file"))


def read_mesh(files: _Files, name: str, written: str, candidates, suffixes, kind: str) -> str:
    """The name MuJoCo gets for the mesh ``name`` (as written; ``written``: after
    ``strippath``), read from the first of ``candidates`` that exists (`_find`): a
    name of its digest, ``files.assets`` holding its bytes."""
    suffix = os.path.splitext(written)[1].lower()
    if suffix not in suffixes:
        files.refuse(f"{kind} {name!r} is not {' or '.join(suffixes)} (the mesh formats MuJoCo reads; convert it)")
    raw = _read(files, _find(files, candidates, name, kind), "mesh file of the hand", MAX_HAND_ASSET_BYTES)
    vfs = hashlib.sha256(raw).hexdigest()[:32] + suffix  # one name per content: MuJoCo caches meshes by name
    files.assets[vfs], files.names[vfs] = raw, name
    return vfs


def _flat_texture(el) -> None:
    """A texture MuJoCo makes without reading or decoding anything: flat, 8 x 8."""
    keep = {k: el.get(k) for k in ("name", "type") if el.get(k) is not None}
    el.attrib.clear()
    el.attrib.update(keep, builtin="flat", width="8", height="8")
