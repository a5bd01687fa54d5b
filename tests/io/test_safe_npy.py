"""``jaxgrasp.io.load_npy`` (issue 66, item 3): ``.npy`` files as NumPy writes them, pickled
object arrays included, read as ``numpy.load`` reads them; hostile ones refused in one line
naming the file, without running anything they name and without allocating what they declare.
"""

from __future__ import annotations

import io
import pickle
import pickletools
import struct
import time

import numpy as np
import pytest

from jaxgrasp import GraspValueError
from jaxgrasp.io import load_npy
from jaxgrasp.io._safe_npy import ADMITTED_GLOBALS, MAX_DEPTH

CAP = 2**24


def same(x, y) -> bool:
    """Deep equality of what ``load_npy`` and ``numpy.load`` give, types and dtypes included."""
    if type(x) is not type(y):
        return False
    if isinstance(x, np.ndarray):
        if x.dtype != y.dtype or x.shape != y.shape:
            return False
        return all(map(same, x.ravel(), y.ravel())) if x.dtype == object else np.array_equal(x, y)
    if isinstance(x, dict):
        return list(x) == list(y) and all(same(x[k], y[k]) for k in x)
    if isinstance(x, (list, tuple)):
        return len(x) == len(y) and all(map(same, x, y))
    if isinstance(x, np.generic):
        return x.dtype == y.dtype and x == y
    return x == y


def objects(*items) -> np.ndarray:
    out = np.empty(len(items), dtype=object)
    for i, item in enumerate(items):
        out[i] = item
    return out


def saved(array) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


def npy(payload: bytes, shape=(), descr="|O") -> bytes:
    """A ``.npy`` file: a version 1.0 header, then ``payload`` as it is."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
    return buf.getvalue() + payload


def globals_named(raw: bytes) -> set:
    """``(module, name)`` of every global a ``.npy`` file's pickle names (``GLOBAL`` and
    ``STACK_GLOBAL``, the latter's strings tracked through the memo)."""
    found, strings, memo = set(), [], {}
    for op, arg, _ in pickletools.genops(raw[raw.index(b"\n") + 1:]):
        if op.name == "GLOBAL":
            found.add(tuple(arg.split(" ")))
        elif "UNICODE" in op.name:
            strings.append(arg)
        elif op.name == "MEMOIZE":
            memo[len(memo)] = strings[-1] if strings else None
        elif op.name in ("BINGET", "LONG_BINGET", "GET"):
            strings.append(memo.get(int(arg)))
        elif op.name == "STACK_GLOBAL":
            found.add((strings[-2], strings[-1]))
    return found


DEXGRASPNET_LIKE = objects(
    {"scale": np.float64(0.06), "qpos": {"WRJTx": 0.01, "WRJRx": 1.5, "robot0:FFJ3": -0.03}},
    {"scale": np.float64(0.08), "qpos": {"WRJTx": -0.02, "WRJRx": 0.1, "robot0:FFJ3": 0.2}, "energy": 3.5},
)
DEXGRASPBENCH_LIKE = np.array({
    "obj_path": "assets/object/bottle", "obj_scale": np.float64(0.06), "obj_pose": np.array([0, 0, 0, 1.0, 0, 0, 0]),
    "grasp_qpos": np.arange(29, dtype=np.float32), "pregrasp_qpos": np.ones(29), "squeeze_qpos": np.zeros(29),
}, dtype=object)
KINDS = {
    "floats": np.arange(12.0).reshape(3, 4),
    "fortran int8": np.asfortranarray(np.arange(6, dtype=np.int8).reshape(2, 3)),
    "strings": np.array(["ab", "c"]),
    "bool scalar": np.array(True),
    "empty": np.zeros((0, 3)),
    "complex": np.array([1 + 2j]),
    "dexgraspnet-like": DEXGRASPNET_LIKE,
    "dexgraspbench-like": DEXGRASPBENCH_LIKE,
    "everything admitted": np.array({
        "list": [1, 2, (3, "x")], "strings": np.array(["ab", "c"]), "fortran": np.asfortranarray(np.ones((2, 3))),
        "bool": np.bool_(True), "complex64": np.complex64(1 + 2j), "int16": np.int16(-3),
        "big-endian": np.arange(3, dtype=">i4"),
        "objects": objects(None, {"k": 1.5}), "str_": np.str_("hé"), "none": None, "nested": [[[{"a": [1.0]}]]],
    }, dtype=object),
}


@pytest.mark.parametrize("name", list(KINDS))
def test_reads_what_numpy_writes_as_numpy_reads_it(tmp_path, name):
    path = tmp_path / "a.npy"
    path.write_bytes(saved(KINDS[name]))
    got, want = load_npy(path, max_bytes=CAP), np.load(path, allow_pickle=True)
    assert same(got, want), (got, want)


def test_numpy_1_pickles_name_numpy_core(tmp_path):
    """NumPy 1 (DexGraspNet's files) names ``numpy.core.multiarray``; NumPy 2 ``numpy._core``.
    A protocol-3 pickle with the old names reads alike, and both sets are what is admitted."""
    raw = npy(pickle.dumps(DEXGRASPNET_LIKE, protocol=3), shape=(2,))
    old = raw.replace(b"numpy._core.multiarray\n", b"numpy.core.multiarray\n")
    assert old != raw and globals_named(old) == {("numpy.core.multiarray", "_reconstruct"), ("numpy", "ndarray"),
                                                ("numpy", "dtype"), ("numpy.core.multiarray", "scalar")}
    assert globals_named(saved(DEXGRASPNET_LIKE)) | globals_named(old) == set(ADMITTED_GLOBALS)
    (tmp_path / "old.npy").write_bytes(old)
    assert same(load_npy(tmp_path / "old.npy", max_bytes=CAP), DEXGRASPNET_LIKE)


def refused(tmp_path, raw: bytes, **kwargs) -> str:
    """The one-line message of reading ``raw`` as ``h.npy``, which must come within a second."""
    path = tmp_path / "h.npy"
    path.write_bytes(raw)
    start = time.perf_counter()
    with pytest.raises(GraspValueError) as info:
        load_npy(path, max_bytes=kwargs.get("max_bytes", CAP), what="test file")
    assert time.perf_counter() - start < 1.0
    text = str(info.value)
    assert "\n" not in text and text.startswith(f"{path}: the test file "), text
    return text


class _Runs:
    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def __reduce__(self):
        return self.fn, self.args


class Custom:
    pass


def test_pickled_code_is_refused_and_never_runs(tmp_path):
    marker = tmp_path / "ran"
    os_system = npy(b"cos\nsystem\n(S'touch " + str(marker).encode() + b"'\ntR.")
    assert "refuses pickled global os.system" in refused(tmp_path, os_system)
    evil_eval = _Runs(eval, f"open({str(marker)!r}, 'w')")
    assert "refuses pickled global builtins.eval" in refused(tmp_path, npy(pickle.dumps(evil_eval, protocol=4)))
    inside = saved(objects({"qpos": {"a": _Runs(eval, f"open({str(marker)!r}, 'w')")}}, 1.0))
    assert "refuses pickled global builtins.eval" in refused(tmp_path, inside)
    text = refused(tmp_path, npy(pickle.dumps(objects(Custom(), 1), protocol=4), shape=(2,)))
    assert f"refuses pickled global {__name__}.Custom" in text
    assert not marker.exists()


@pytest.mark.parametrize("value, says", [
    ({1, 2}, "refuses a value of type set"),
    (b"bytes", "refuses a value of type bytes"),
    ({1: 2.0}, "refuses a dict key that is not a string (int)"),
    (np.zeros(2, dtype=[("a", "f8")]), "refuses pickled dtype 'V8'"),
    (np.zeros(2, dtype="M8[s]"), "refuses pickled dtype 'M8'"),
    (np.dtype("f8"), "refuses a dtype pickled outside an array"),
])
def test_values_that_are_not_admitted(tmp_path, value, says):
    assert says in refused(tmp_path, saved(objects({"a": [value]}, 0)))


def test_out_of_band_and_persistent_pickles_are_refused(tmp_path):
    oob = pickle.dumps(np.arange(3.0), protocol=5)  # contiguous arrays at protocol 5 name numpy's _frombuffer
    assert "refuses pickled global numpy._core.numeric._frombuffer" in refused(tmp_path, npy(oob))
    assert "refuses a pickled persistent id" in refused(tmp_path, npy(b"\x80\x02X\x01\x00\x00\x00xQ."))


def test_nesting_and_shared_references_are_bounded(tmp_path):
    deep = 1.0
    for _ in range(MAX_DEPTH + 2):
        deep = [deep]
    assert f"nested more than {MAX_DEPTH} deep" in refused(tmp_path, saved(objects(deep, 0)))
    loop: list = []
    loop.append(loop)
    assert f"nested more than {MAX_DEPTH} deep" in refused(tmp_path, saved(objects(loop, 0)))
    shared = [1.0]
    for _ in range(24):  # 2**24 leaves in a pickle of a few hundred bytes
        shared = [shared, shared]
    assert "more items than bytes" in refused(tmp_path, saved(objects(shared, 0)))


class _ArrayState:
    """An array pickled as NumPy does, with any state (NumPy's own ``__setstate__`` crashes
    the interpreter on an object array whose shape exceeds its list)."""

    def __init__(self, state):
        self.state = state

    def __reduce__(self):
        from numpy._core.multiarray import _reconstruct

        return _reconstruct, (np.ndarray, (0,), b"b"), self.state


@pytest.mark.parametrize("state, says", [
    ((1, (10**9,), np.dtype("O"), False, [1.0]), "object array of shape (1000000000,) whose items do not match"),
    ((1, (3,), np.dtype("O"), False, [1.0] * 10), "object array of shape (3,) whose items do not match"),
    ((1, (3,), np.dtype("f8"), False, b"\0" * 8), "float64 array of shape (3,) whose bytes do not match"),
    ((1, (1,), np.dtype("f8"), False, [1.0]), "float64 array of shape (1,) whose bytes do not match"),
])
def test_array_states_that_do_not_match_are_refused(tmp_path, state, says):
    assert says in refused(tmp_path, npy(pickle.dumps(_ArrayState(state), protocol=4), shape=(1,)))


def test_malformed_truncated_and_lying_files(tmp_path):
    whole = saved(DEXGRASPNET_LIKE)
    assert "malformed or truncated pickle" in refused(tmp_path, whole[:-40])
    assert "is truncated inside its header" in refused(tmp_path, whole[:40])
    assert "not a .npy file" in refused(tmp_path, b"just some text, long enough")
    huge = refused(tmp_path, npy(b"\0" * 16, shape=(10**12,), descr="<f8"))
    assert "is truncated: its header declares 8000000000000 bytes of data, it holds 16" in huge
    assert "declares 1000000000000 objects" in refused(tmp_path, npy(pickle.dumps(1), shape=(10**12,)))
    assert "holds more than its header declares" in refused(tmp_path, saved(np.zeros(3)) + b"\0" * 8)
    assert "holds dtype [('a', '<f8')]; read are" in refused(tmp_path, saved(np.zeros(2, dtype=[("a", "f8")])))
    assert "pickles a list, not the array" in refused(tmp_path, npy(pickle.dumps([1.0], protocol=4)))
    big = npy(b"\x80\x04\x8e" + struct.pack("<Q", 2**62) + b"x")  # a bytes object of 4 EiB declared
    assert "malformed or truncated pickle (MemoryError" in refused(tmp_path, big)
    assert "not callable" in refused(tmp_path, npy(b"\x80\x02cnumpy\nndarray\nK\x05\x85R."))
    assert "more than the" in refused(tmp_path, whole, max_bytes=100)
