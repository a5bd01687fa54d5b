"""Input files built to hurt (issue 40, items 3, 4 and 6): special files, files over their
size cap, corrupt and lying ``.npz`` files, meshes outside the naming file's folder or
not meshes at all, ``.jsonl`` lines holding U+2028 / U+0085, and the batch resume key
over every mesh a dataset names.

Each is a one-line :class:`~jaxgrasp.GraspValueError` (a whole-file problem) or an
invalid row (a dataset line), and on the command line one line with exit status 2. The
loaders run in-process; the command line runs in-process too (``run_cli``), and only
where it stops before compiling anything, so this file runs in a few seconds.
"""

from __future__ import annotations

import io
import json
import os
import time
import zipfile

import numpy as np
import pytest
import trimesh

import jaxgrasp
from jaxgrasp import GraspValueError, load_dataset
from jaxgrasp.io import _grasp_file

FINGERTIP = {"radius": 0.025, "young_modulus": 6e5, "friction": 0.5, "max_force": 15.0}


def grasp_dict(mesh: str | None = None, deformation: float = 0.002) -> dict:
    """The cube of the paper as grasp-file data; with ``mesh``, on that mesh (a 0.1 m box)."""
    contacts = [
        {"position": [0.05, 0.0, 0.0], "initial_deformation": deformation},
        {"position": [-0.05, 0.0, 0.0], "initial_deformation": deformation},
    ]
    if mesh is None:
        contacts[0]["normal"], contacts[1]["normal"] = [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]
        return {"fingertip": FINGERTIP, "contacts": contacts}
    return {"fingertip": FINGERTIP, "object": {"mesh": mesh}, "contacts": contacts}


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """``(data, outside)``: two sibling folders, each with ``cube.stl`` (a 0.1 m box, m)."""
    root = tmp_path_factory.mktemp("hostile")
    data, outside = root / "data", root / "outside"
    for folder in (data, outside):
        folder.mkdir()
        trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(folder / "cube.stl")
    return data, outside


def one_line(exc_info) -> str:
    text = str(exc_info.value)
    assert "\n" not in text, text
    return text


def write_jsonl(path, rows) -> None:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")


# --------------------------------------------------------------------------- special files and caps


def test_dev_zero_as_a_grasp_file_is_one_line_exit_2(tmp_path, run_cli):
    link = tmp_path / "cube.toml"
    link.symlink_to("/dev/zero")
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.load(link)
    assert "is a character device, not a regular grasp file" in one_line(info)
    rc, out, err = run_cli(["evaluate", link])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {link}: is a character device") and "Traceback" not in err


def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "set.jsonl"
    os.mkfifo(fifo)  # nobody writes to it: opening it to read would wait for ever
    with pytest.raises(GraspValueError) as info:
        load_dataset(fifo)
    assert "is a FIFO (named pipe), not a regular dataset" in one_line(info)


def test_files_over_their_cap_are_refused_before_reading(tmp_path, monkeypatch):
    path = tmp_path / "cube.json"
    path.write_text(json.dumps(grasp_dict()))
    assert jaxgrasp.load(path).num_contacts == 2
    monkeypatch.setattr(_grasp_file, "MAX_GRASP_FILE_BYTES", 100)
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.load(path)
    assert "more than the 9.537e-05 MiB read at most" in one_line(info)


# --------------------------------------------------------------------------- .npz


def _cube_arrays(b: int) -> dict[str, np.ndarray]:
    return {
        "positions": np.tile([[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]], (b, 1, 1)),
        "normals": np.tile([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], (b, 1, 1)),
        "initial_deformation": np.full(b, 0.002), "radius": 0.025, "young_modulus": 6e5,
        "friction": 0.5, "max_force": 15.0,
    }


def _npy_header(shape, dtype="<f8") -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buf.getvalue()  # magic, length and header


def test_npz_with_zero_grasps(tmp_path):
    path = tmp_path / "empty.npz"
    np.savez(path, **{**_cube_arrays(0), "initial_deformation": np.zeros(0)})
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert one_line(info) == f"{path}: no grasps (positions has shape (0, 2, 3))"


def test_truncated_npz(tmp_path):
    path = tmp_path / "cut.npz"
    np.savez(path, **_cube_arrays(50))
    path.write_bytes(path.read_bytes()[:-700])  # the zip's directory and part of an array gone
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert one_line(info).startswith(f"{path}: not a readable .npz file (")


def test_npy_header_claiming_21_tib_is_refused_before_allocating(tmp_path):
    """positions.npy's header says (10**12, 3) float64 (21.8 TiB) but holds 48 bytes: the
    loader must compare before allocating (a MemoryError or a killed process otherwise)."""
    path = tmp_path / "liar.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("positions.npy", _npy_header((10**12, 3)) + np.zeros(6).tobytes())
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    text = one_line(info)
    assert "array 'positions' claims shape (1000000000000, 3) of float64 (21.8 TiB)" in text, text


def test_zip_directory_declaring_more_than_the_cap(tmp_path):
    """A member whose central-directory entry declares ~4 GiB uncompressed (a zip bomb's
    claim): refused from the directory alone, before any member is read."""
    path = tmp_path / "bomb.npz"
    np.savez(path, **_cube_arrays(4))
    raw = bytearray(path.read_bytes())
    entry = raw.index(b"PK\x01\x02")  # the first central-directory entry
    raw[entry + 24 : entry + 28] = (0xFFFFFFF0).to_bytes(4, "little")  # its uncompressed size
    path.write_bytes(bytes(raw))
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert "its arrays declare 4096 MiB uncompressed, more than the 1024 MiB read at most" in one_line(info)


def test_npz_with_a_pickled_array_is_refused(tmp_path):
    path = tmp_path / "pickle.npz"
    np.savez(path, **{**_cube_arrays(2), "mass": np.array([{"x": 1}, None], dtype=object)})
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert "array 'mass' holds Python objects, which are not read (no pickles)" in one_line(info)


# --------------------------------------------------------------------------- .jsonl lines


@pytest.mark.parametrize("char", ["\u2028", "\u0085"])
def test_jsonl_splits_on_newline_only(tmp_path, char):
    """A raw U+2028 or U+0085 inside a JSON string (valid JSON) is part of its line:
    ``str.splitlines`` broke such a line in two and shifted every later line number."""
    odd = grasp_dict()
    odd["fingertip"] = {**FINGERTIP, f"note{char}": 1.0}  # an unknown key: the row is invalid, as one row
    lines = [json.dumps(grasp_dict()), json.dumps(odd, ensure_ascii=False), "{broken", json.dumps(grasp_dict())]
    path = tmp_path / "set.jsonl"
    path.write_bytes(("\n".join(lines) + "\n").encode("utf-8"))
    assert char.encode("utf-8") in path.read_bytes()
    got = load_dataset(path)
    assert len(got) == 4 and got.valid.tolist() == [True, False, False, True]
    assert got.errors[1].startswith("grasp 1 (line 2): unknown key"), got.errors[1]
    assert got.errors[2].startswith("grasp 2 (line 3): malformed JSON"), got.errors[2]


def test_loading_holds_columns_not_a_jax_grasp_per_row(tmp_path):
    path = tmp_path / "set.npz"
    np.savez(path, **_cube_arrays(200))
    got = load_dataset(path)
    columns = got.columns()
    per_grasp = sum(a.nbytes for a in columns.fields.values()) / len(got)
    assert per_grasp <= 26 * 8  # 2 contacts: 26 float64 numbers, no JAX array per field
    assert isinstance(got.grasps, jaxgrasp.io._dataset.GraspRows)
    np.testing.assert_array_equal(got.grasps[199].positions, _cube_arrays(1)["positions"][0])


# --------------------------------------------------------------------------- meshes stay in their folder


def test_dataset_row_naming_a_mesh_outside_is_an_invalid_row(folders, tmp_path):
    data, outside = folders
    link = data / "linked.stl"
    if not link.exists():
        link.symlink_to(outside / "cube.stl")  # inside by name, outside after symlinks
    path = data / "set.jsonl"
    write_jsonl(path, [grasp_dict("cube.stl"), grasp_dict("../outside/cube.stl"), grasp_dict("linked.stl"),
                       grasp_dict(str(outside / "cube.stl"))])
    got = load_dataset(path)
    assert got.valid.tolist() == [True, False, False, False]
    for i in (1, 2, 3):
        assert f"grasp {i} (line {i + 1}): mesh path " in got.errors[i]
        assert f"is outside the dataset's folder {str(data.resolve())!r}" in got.errors[i]
        assert got.errors[i].endswith("pass --allow-dir DIR (Python: allowed_dirs=) to allow it")
    allowed = load_dataset(path, allowed_dirs=[outside])
    assert allowed.valid.all(), allowed.errors
    assert set(allowed.mesh_sha256) == {str((data / "cube.stl").resolve()), str((outside / "cube.stl").resolve())}


@pytest.mark.parametrize(
    "name, message",
    [
        ("/etc/passwd", "mesh path '/etc/passwd' is not a mesh file: the formats read are .stl, .obj, .ply"),
        ("parts.zip", "mesh path 'parts.zip' is not a mesh file"),
        ("scene.gltf", "mesh path 'scene.gltf' is not a mesh file"),
    ],
)
def test_only_mesh_formats_are_read(folders, name, message):
    data, _ = folders
    with pytest.raises(GraspValueError) as info:
        _grasp_file.grasp_from_dict(grasp_dict(name), source="g.json", base=data)
    assert one_line(info).startswith(f"g.json: {message}")


def test_a_fifo_named_as_a_mesh_is_an_invalid_row(folders):
    data, _ = folders
    fifo = data / "pipe.stl"
    if not fifo.exists():
        os.mkfifo(fifo)
    path = data / "fifo.jsonl"
    write_jsonl(path, [grasp_dict("pipe.stl"), grasp_dict("cube.stl")])
    got = load_dataset(path)
    assert got.valid.tolist() == [False, True]
    assert "pipe.stl': is a FIFO (named pipe), not a regular mesh" in got.errors[0], got.errors[0]


def test_grasp_file_naming_a_mesh_outside(folders, run_cli):
    from jaxgrasp.cli import build_parser
    from jaxgrasp.cli._common import load_grasp

    data, outside = folders
    path = data / "away.json"
    path.write_text(json.dumps(grasp_dict("../outside/cube.stl")))
    rc, out, err = run_cli(["evaluate", path])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {path}: mesh path '../outside/cube.stl' is outside the grasp file's folder")
    args = build_parser().parse_args(["evaluate", str(path), "--allow-dir", str(outside)])
    grasp = load_grasp(args)  # the option reaches the loader (nothing evaluated here)
    np.testing.assert_allclose(np.asarray(grasp.positions), [[0.05, 0, 0], [-0.05, 0, 0]], atol=1e-12)
    with pytest.raises(GraspValueError, match="allowed folder .* is not a folder"):
        jaxgrasp.load(path, allowed_dirs=[data / "missing"])


# --------------------------------------------------------------------------- resume key


def test_editing_a_named_mesh_refuses_resume(tmp_path, run_cli):
    from jaxgrasp.cli._batch import PARTIAL_NAME, resume_key
    from jaxgrasp.engine._checkpoint import BatchCheckpoint

    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "cube.stl")
    path = tmp_path / "set.jsonl"
    write_jsonl(path, [grasp_dict("cube.stl"), grasp_dict("cube.stl", 0.003)])
    before = load_dataset(path)
    assert resume_key(before) != before.source_sha256  # the mesh is in the key
    out = tmp_path / "out"
    out.mkdir()
    BatchCheckpoint(out / PARTIAL_NAME, str(path), resume_key(before), 2, 2).start()  # an unfinished run
    trimesh.creation.box(extents=(0.1, 0.1, 0.12)).export(tmp_path / "cube.stl")  # same dataset bytes
    after = load_dataset(path)
    assert after.source_sha256 == before.source_sha256 and resume_key(after) != resume_key(before)
    rc, stdout, err = run_cli(["batch", path, "--out", out, "--resume"])
    assert rc == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith("jaxgrasp: error: --resume: ") and "was made from other input" in err, err


def test_batch_allow_dir_reaches_the_dataset(folders, tmp_path, run_cli):
    """``jaxgrasp batch --allow-dir``: without it the only row (a mesh outside) is invalid;
    with it the row is read and the run goes on to the checkpoint (a stale one here, so
    that it stops there, before compiling)."""
    from jaxgrasp.engine._checkpoint import BatchCheckpoint

    data, outside = folders
    path = data / "away.jsonl"
    write_jsonl(path, [grasp_dict("../outside/cube.stl")])
    rc, _, err = run_cli(["batch", path, "--out", tmp_path / "o"])
    assert rc == 2 and err.count("\n") == 1, err
    assert "no valid grasp (1 invalid; first: grasp 0 (line 1): mesh path '../outside/cube.stl' is outside" in err, err
    (tmp_path / "o" / "results.partial").mkdir(parents=True)
    BatchCheckpoint(tmp_path / "o" / "results.partial", "other.jsonl", "0" * 64, 1, 2).start()
    rc, _, err = run_cli(["batch", path, "--out", tmp_path / "o", "--allow-dir", outside, "--resume"])
    assert rc == 2 and "was made from other input (other.jsonl" in err and err.count("\n") == 1, err


# --------------------------------------------------------------------------- huge and NaN vertices


@pytest.mark.parametrize(
    "coordinate, message",
    [("1e300", "huge.obj' has a vertex at (1e+300, 0, 0) m, beyond the largest coordinate 1000 m"),
     ("nan", "huge.obj' has NaN vertex coordinates (3 of its 4 vertices")],
    ids=["1e300", "nan"],
)
def test_huge_or_nan_mesh_is_one_line_in_every_command(tmp_path, run_cli, coordinate, message):
    """A tetrahedron with vertices at 1e300 m ended ``plan``, ``evaluate`` and ``show`` with an
    OverflowError traceback; one with NaN vertices was called not watertight (or faceless)."""
    (tmp_path / "huge.obj").write_text(
        f"v 0 0 0\nv {coordinate} 0 0\nv 0 {coordinate} 0\nv 0 0 {coordinate}\n"
        "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    grasp = tmp_path / "mesh_huge.json"
    grasp.write_text(json.dumps(grasp_dict("huge.obj")))
    for argv in (["plan", tmp_path / "huge.obj", "--out", tmp_path / "po"], ["evaluate", grasp],
                 ["show", grasp, "--out", tmp_path / "x.png"]):
        rc, out, err = run_cli(argv)
        assert rc == 2 and out == "" and err.count("\n") == 1 and message in err, (argv[0], err)
    assert not (tmp_path / "po").exists() and not (tmp_path / "x.png").exists()


# --------------------------------------------------------------------------- issue 65: more bounds


def _flag_encrypted(raw: bytes) -> bytes:
    """The zip ``raw`` with every member flagged encrypted (general-purpose flag bit 0, in
    its local header and its central-directory entry), its bytes otherwise as they were."""
    out = bytearray(raw)
    for signature, flags_at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        at = out.find(signature)
        while at >= 0:
            out[at + flags_at] |= 1
            at = out.find(signature, at + 1)
    return bytes(out)


def test_npz_with_an_encrypted_member_is_one_line_exit_2(tmp_path, run_cli):
    """zipfile raised RuntimeError ("password required") through the loader: a traceback."""
    path = tmp_path / "locked.npz"
    np.savez(path, **_cube_arrays(3))
    path.write_bytes(_flag_encrypted(path.read_bytes()))
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert one_line(info).startswith(f"{path}: array 'positions' is encrypted; save the dataset with numpy.savez")
    rc, out, err = run_cli(["batch", path, "--out", tmp_path / "o"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and "is encrypted" in err and "Traceback" not in err, err


def test_npz_listing_more_members_than_arrays_is_refused_from_its_last_record(tmp_path, monkeypatch):
    """The member count comes from the zip's end record, before zipfile builds an object
    per member (a 1 GiB file could list 20 million)."""
    path = tmp_path / "many.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for i in range(65):
            zf.writestr(f"a{i}.npy", b"")
    monkeypatch.setattr(zipfile, "ZipFile", None)  # never reached
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert one_line(info).startswith(f"{path}: the zip lists 65 members; a dataset .npz holds at most 10 arrays")


def test_npz_member_of_an_unknown_name_is_refused_before_it_is_decompressed(tmp_path, monkeypatch):
    path = tmp_path / "extra.npz"
    np.savez_compressed(path, **_cube_arrays(2), extra=np.zeros(3))
    monkeypatch.setattr(zipfile.ZipFile, "open", None)  # no member is opened
    with pytest.raises(GraspValueError) as info:
        load_dataset(path)
    assert one_line(info).startswith(f"{path}: unknown array 'extra'; arrays are named positions, normals")


def _many_contacts(n: int) -> dict:
    v = np.random.default_rng(0).normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return {"fingertip": FINGERTIP, "contacts": [
        {"position": (0.05 * u).tolist(), "normal": u.tolist(), "initial_deformation": 1e-3} for u in v]}


def test_rows_of_more_contacts_than_the_cap_are_invalid_rows(tmp_path, run_cli):
    """A 300-contact row padded an 11-row batch to 300 contacts (minutes); now it is an
    invalid row naming the cap, and a grasp file of 33 contacts is refused in one line."""
    from jaxgrasp.model import MAX_CONTACTS

    path = tmp_path / "set.jsonl"
    write_jsonl(path, [grasp_dict(), _many_contacts(300), _many_contacts(MAX_CONTACTS)])
    got = load_dataset(path)
    assert got.valid.tolist() == [True, False, True] and got.num_contacts.tolist() == [2, 0, MAX_CONTACTS]
    assert got.errors[1].startswith(f"grasp 1 (line 2): 300 contacts, more than the {MAX_CONTACTS} one grasp may have")
    rc, out, err = run_cli(["batch", path, "--strict", "--out", tmp_path / "o"])
    assert rc == 2 and out == "" and err.count("\n") == 1 and "300 contacts, more than the 32" in err, err
    big = tmp_path / "big.json"
    big.write_text(json.dumps(_many_contacts(MAX_CONTACTS + 1)))
    rc, out, err = run_cli(["evaluate", big])
    assert rc == 2 and out == "" and err.count("\n") == 1 and "33 contacts, more than the 32" in err, err
    arrays = _cube_arrays(2)
    wide = {**arrays, "positions": np.zeros((2, 40, 3)), "normals": np.ones((2, 40, 3)),
            "active": np.zeros((2, 40), bool)}
    wide["positions"][:, :2], wide["normals"][:, :2], wide["active"][:, :2] = arrays["positions"], arrays["normals"], True
    wide["initial_deformation"] = np.full(2, 0.002)
    np.savez(tmp_path / "wide.npz", **wide)  # 40 columns, 2 active contacts a row: valid
    assert load_dataset(tmp_path / "wide.npz").num_contacts.tolist() == [2, 2]


def test_mesh_names_with_a_nul_byte_are_one_line(folders, tmp_path, run_cli):
    """os.path.realpath raised ValueError ("embedded null byte") through every loader."""
    from jaxgrasp.io import load_mesh

    data, _ = folders
    with pytest.raises(GraspValueError) as info:
        load_mesh(str(data / "cube\x00.stl"))
    assert "holds a NUL byte, which no file name can hold" in one_line(info)
    path = data / "nul.json"
    path.write_text(json.dumps(grasp_dict("cube\u0000.stl")))
    rc, out, err = run_cli(["evaluate", path])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {path}: mesh path 'cube\\x00.stl' holds a NUL byte"), err
    rows = data / "nul.jsonl"
    write_jsonl(rows, [grasp_dict("cube\u0000.stl"), grasp_dict("cube.stl")])
    got = load_dataset(rows)
    assert got.valid.tolist() == [False, True] and "holds a NUL byte" in got.errors[0], got.errors
    with pytest.raises(GraspValueError) as info:
        jaxgrasp.load(str(tmp_path / "a\x00.toml"))
    assert "holds a NUL byte" in one_line(info)


def _glb_with(update) -> bytes:
    """A 0.1 m box as GLB, its JSON chunk changed by ``update(header)``."""
    import struct

    glb = trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(file_type="glb")
    length, _ = struct.unpack_from("<II", glb, 12)
    header = json.loads(glb[20:20 + length])
    update(header)
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + glb[20 + length:]
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def _textured(header) -> None:
    header["images"] = [{"uri": "data:image/png;base64,iVBORw0KGgo="}]  # a PNG signature, then nothing
    header["textures"] = [{"source": 0}]
    header["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    for mesh in header["meshes"]:
        for primitive in mesh["primitives"]:
            primitive["material"] = 0


def test_glb_textures_are_never_decoded(tmp_path, monkeypatch):
    """A 3 MB GLB with large embedded textures was killed at 7 GB: the mesh is read for its
    geometry alone, and no image is opened."""
    import PIL.Image

    from jaxgrasp.io import load_mesh

    opened = []
    monkeypatch.setattr(PIL.Image, "open", lambda *a, **k: opened.append(a))
    path = tmp_path / "textured.glb"
    path.write_bytes(_glb_with(_textured))
    mesh = load_mesh(path)
    assert len(mesh.faces) == 12 and opened == []


def test_glb_accessors_declaring_gigabytes_are_refused_before_decoding(tmp_path, run_cli, monkeypatch):
    """An accessor without data is allocated by its count: a 1 KB file asked for 112 GiB."""
    def bomb(header):
        header["accessors"].append({"componentType": 5126, "count": 10**10, "type": "VEC3"})

    path = tmp_path / "bomb.glb"
    path.write_bytes(_glb_with(bomb))
    monkeypatch.setattr(trimesh, "load", None)  # never reached
    t0 = time.perf_counter()
    rc, out, err = run_cli(["plan", path, "--out", tmp_path / "o"])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert "bomb.glb': its accessors declare 114,441 MiB of geometry, more than the 1,024 MiB read at most" in err
    assert time.perf_counter() - t0 < 60 and not (tmp_path / "o").exists()


def test_meshes_over_the_face_cap_are_refused(tmp_path, monkeypatch):
    """An OBJ by its face lines, before it is parsed; any mesh by its faces once read."""
    from jaxgrasp.io import _mesh, load_mesh

    monkeypatch.setattr(_mesh, "MAX_MESH_FACES", 10)
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    box.export(tmp_path / "box.obj")
    box.export(tmp_path / "box.stl")
    monkeypatch.setattr(trimesh, "load", None)  # the OBJ is refused before trimesh sees it
    with pytest.raises(GraspValueError) as info:
        load_mesh(tmp_path / "box.obj")
    assert one_line(info).startswith(f"mesh '{tmp_path / 'box.obj'}' declares 12 faces, more than the 10 read at most")
    monkeypatch.undo()
    monkeypatch.setattr(_mesh, "MAX_MESH_FACES", 10)
    with pytest.raises(GraspValueError) as info:
        load_mesh(tmp_path / "box.stl")
    assert one_line(info).startswith(f"mesh '{tmp_path / 'box.stl'}' has 12 faces, more than the 10 read at most")
