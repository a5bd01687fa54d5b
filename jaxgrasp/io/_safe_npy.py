"""Reading ``.npy`` files that may be hostile, pickled object arrays included, without running their code.

The field's grasp datasets (DexGraspNet, DexGraspBench) are ``.npy`` files of *object*
arrays: NumPy pickles them, and ``numpy.load(..., allow_pickle=True)`` runs whatever a
pickle names (``os.system`` included). `load_npy` reads such a file in three steps, each
refusing in one line that names the file:

1. **The bytes**, through `read_input` (a regular file under ``max_bytes``, opened
   non-blocking), and **the header**, parsed here: NumPy's magic, version 1 to 3, a header
   of at most `MAX_HEADER_BYTES` holding ``descr``, ``fortran_order`` and ``shape``.
2. **A numeric array** (booleans, integers, floats, complex numbers, or fixed-length
   strings) is read from its bytes, which must be exactly as many as the header declares
   (a truncated file, or a header declaring a huge array, is refused before anything is
   allocated).
3. **An object array** is unpickled by a restricted ``pickle.Unpickler`` whose
   ``find_class`` admits only the four globals NumPy's pickles of arrays, dtypes and
   scalars name (`ADMITTED_GLOBALS`, in ``numpy.core`` as NumPy 1 writes it and in
   ``numpy._core`` as NumPy 2 does; checked with ``pickletools.dis`` on DexGraspNet's and
   DexGraspBench's files). Even these are not NumPy's functions: each stands for an inert
   record, so that nothing of NumPy runs on the pickle's unchecked arguments (NumPy's own
   ``ndarray.__setstate__`` crashes the interpreter on an object array whose shape exceeds
   its list). Once the pickle is read, the records are checked and turned into arrays,
   dtypes and scalars, walking the result: admitted are NumPy arrays of the kinds above
   or of objects (each element admitted in turn), NumPy scalars, ``None``, booleans,
   numbers, strings, lists, tuples and dicts with string keys, at most `MAX_DEPTH`
   levels deep and no more items than the pickle has bytes (a pickle that refers to one
   list many times cannot make the walk long). Anything else (a set, bytes, a global
   such as ``os.system``, a structured dtype) is refused with what it was.
"""

from __future__ import annotations

import ast
import io
import math
import os
import pickle
import re

import numpy as np

from jaxgrasp.io._inputs import read_input
from jaxgrasp.model import GraspValueError

__all__ = ["load_npy", "ADMITTED_GLOBALS", "MAX_DEPTH", "MAX_HEADER_BYTES"]

MAX_HEADER_BYTES = 10_000
"""Longest ``.npy`` header read, bytes (NumPy's own default ``max_header_size``)."""

MAX_DEPTH = 32
"""Deepest nesting of containers read from a pickle (DexGraspNet's files nest 3 deep)."""

ADMITTED_GLOBALS = tuple(
    (package + ".multiarray", name) for package in ("numpy.core", "numpy._core") for name in ("_reconstruct", "scalar")
) + (("numpy", "ndarray"), ("numpy", "dtype"))
"""The only globals a pickled ``.npy`` may name: what NumPy 1 and 2 write for arrays,
dtypes and scalars (protocols 2 to 4; protocol 5's out-of-band buffers are refused)."""

_MAGIC = b"\x93NUMPY"
_DESCR = re.compile(r"[<>|=]?(?:b1|\?|[iu][1248]|f(?:2|4|8|12|16)|c(?:8|16|24|32)|O[48]?|U[1-9]\d{0,7})")
"""The dtypes read: bool, integers, floats, complex, objects, strings (no structures, voids,
dates or byte strings)."""


class _Refused(Exception):
    """What a pickle holds that is not read (the message says what), caught by `load_npy`."""


class _Token:
    """``numpy.ndarray`` as a pickle names it: only `_reconstruct`'s first argument,
    never called (calling NumPy's class would allocate any shape the pickle asks for)."""

    __slots__ = ()


_NDARRAY = _Token()


class _DtypeRecord:
    """A pickled ``numpy.dtype(spec, align, copy)`` and its state, checked by `_resolve_dtype`."""

    __slots__ = ("spec", "state")

    def __init__(self, spec):
        self.spec, self.state = spec, None

    def __setstate__(self, state):
        if self.state is not None:
            raise _Refused("refuses a dtype whose state is set twice")
        self.state = state


class _ArrayRecord:
    """A pickled array, ``_reconstruct(ndarray, (0,), b"b")`` then ``__setstate__``."""

    __slots__ = ("state",)

    def __init__(self):
        self.state = None

    def __setstate__(self, state):
        if self.state is not None:
            raise _Refused("refuses an array whose state is set twice")
        self.state = state


class _ScalarRecord:
    """A pickled NumPy scalar, ``scalar(dtype, payload)``."""

    __slots__ = ("dtype", "payload")

    def __init__(self, dtype, payload):
        self.dtype, self.payload = dtype, payload


def _reconstruct(cls, shape, code):
    if cls is not _NDARRAY or shape != (0,) or code not in (b"b", "b"):
        raise _Refused("refuses a call of _reconstruct other than NumPy's for an array")
    return _ArrayRecord()


def _dtype(spec, align=False, copy=False):
    if not isinstance(spec, str) or align is not False:
        raise _Refused(f"refuses a pickled dtype {_short(spec)}")
    return _DtypeRecord(spec)


def _scalar(dtype, payload=None):
    if not isinstance(dtype, _DtypeRecord):
        raise _Refused("refuses a call of scalar without a dtype")
    return _ScalarRecord(dtype, payload)


_ADMITTED = {key: (_reconstruct if key[1] == "_reconstruct" else _scalar) for key in ADMITTED_GLOBALS[:4]}
_ADMITTED.update({("numpy", "ndarray"): _NDARRAY, ("numpy", "dtype"): _dtype})


class _Unpickler(pickle.Unpickler):
    """``find_class`` admits `ADMITTED_GLOBALS` alone, each as its inert stand-in."""

    def find_class(self, module, name):
        found = _ADMITTED.get((module, name))
        if found is None:
            raise _Refused(f"refuses pickled global {module}.{name}")
        return found

    def persistent_load(self, pid):
        raise _Refused("refuses a pickled persistent id")


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ----------------------------------------------------------------------------- the header
def _header(raw: bytes) -> tuple[np.dtype, tuple, bool, int]:
    """``(dtype, shape, fortran_order, data offset)`` of a ``.npy`` file's bytes; raises
    `_Refused` (the message completes "PATH: ...")."""
    if raw[:6] != _MAGIC or len(raw) < 10:
        raise _Refused("is not a .npy file (no NumPy magic)")
    major = raw[6]
    if major not in (1, 2, 3):
        raise _Refused(f"is a .npy file of format version {major}.{raw[7]}; versions 1 to 3 are read")
    size_bytes = 2 if major == 1 else 4
    start = 8 + size_bytes
    length = int.from_bytes(raw[8:start], "little")
    if length > MAX_HEADER_BYTES:
        raise _Refused(f"has a header of {length} bytes, more than the {MAX_HEADER_BYTES} read")
    if len(raw) < start + length:
        raise _Refused("is truncated inside its header")
    try:
        text = raw[start:start + length].decode("utf-8" if major == 3 else "latin-1")
        header = ast.literal_eval(text)
    except (ValueError, SyntaxError, MemoryError, RecursionError, UnicodeDecodeError):
        raise _Refused("has a malformed header") from None
    return (*_checked_header(header), start + length)


def _checked_header(header) -> tuple[np.dtype, tuple, bool]:
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise _Refused("has a header without exactly descr, fortran_order and shape")
    shape, fortran = header["shape"], header["fortran_order"]
    if not isinstance(shape, tuple) or not all(type(n) is int and n >= 0 for n in shape) or type(fortran) is not bool:
        raise _Refused(f"has a malformed shape or order in its header ({_short(shape)})")
    return _header_dtype(header["descr"]), shape, fortran


def _header_dtype(descr) -> np.dtype:
    if not isinstance(descr, str) or not _DESCR.fullmatch(descr):
        raise _Refused(f"holds dtype {_short(descr)}; read are booleans, numbers, strings and objects")
    return np.dtype(descr)


def _numeric(raw: bytes, dtype: np.dtype, shape: tuple, fortran: bool, offset: int) -> np.ndarray:
    """The array of a numeric ``.npy`` file, its byte count checked before anything is allocated."""
    count = math.prod(shape)
    declared, held = count * dtype.itemsize, len(raw) - offset
    if declared != held:
        what = "is truncated: its header declares" if held < declared else "holds more than its header declares:"
        raise _Refused(f"{what} {declared} bytes of data, it holds {held}")
    flat = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
    return flat.reshape(shape, order="F" if fortran else "C").copy()


# ----------------------------------------------------------------------------- the pickle's records, checked
def _resolve_dtype(record: _DtypeRecord) -> np.dtype:
    """The dtype a pickled ``numpy.dtype(spec)`` and its state stand for, if it is one of
    the kinds read, byte order its only setting."""
    if not _DESCR.fullmatch(record.spec):
        raise _Refused(f"refuses pickled dtype {_short(record.spec)}; read are booleans, numbers, strings and objects")
    dtype, state = np.dtype(record.spec), record.state
    if state is None:
        return dtype
    ok = isinstance(state, tuple) and ((len(state) == 8 and state[0] == 3) or (len(state) == 9 and state[0] == 4))
    if not ok or state[1] not in ("<", ">", "|", "=") or state[2:5] != (None, None, None) \
            or state[5] not in (-1, dtype.itemsize) or (len(state) == 9 and state[8] is not None):
        raise _Refused(f"refuses a pickled dtype state {_short(state)} (a structure, a subarray or metadata)")
    return dtype.newbyteorder(state[1]) if state[1] in "<>" and dtype.byteorder != "|" else dtype


class _Walk:
    """Turns the unpickled records into arrays, dtypes and scalars, admitting only the
    values of the module doc; at most ``budget`` items in all."""

    def __init__(self, budget: int):
        self.left = budget

    def value(self, obj, depth: int = 0):
        self.left -= 1
        if self.left < 0:
            raise _Refused("refuses a pickle with more items than bytes (one container referred to again and again)")
        if depth > MAX_DEPTH:
            raise _Refused(f"refuses containers nested more than {MAX_DEPTH} deep")
        kind = type(obj)
        if obj is None or kind in (bool, int, float, complex, str):
            return obj
        if kind is _ArrayRecord:
            return self.array(obj, depth)
        if kind is _ScalarRecord:
            return self.scalar(obj, depth)
        if kind in (list, tuple):
            return kind(self.value(x, depth + 1) for x in obj)
        if kind is dict:
            bad = next((k for k in obj if type(k) is not str), None)
            if bad is not None:
                raise _Refused(f"refuses a dict key that is not a string ({type(bad).__name__})")
            return {k: self.value(v, depth + 1) for k, v in obj.items()}
        if kind in (_Token, _DtypeRecord):
            shown = "the class numpy.ndarray" if kind is _Token else "a dtype"
            raise _Refused(f"refuses {shown} pickled outside an array")
        raise _Refused(f"refuses a value of type {kind.__name__}")

    def scalar(self, record: _ScalarRecord, depth: int):
        dtype = _resolve_dtype(record.dtype)
        if dtype.kind == "O":
            return self.value(record.payload, depth + 1)
        if type(record.payload) is not bytes or len(record.payload) != dtype.itemsize:
            raise _Refused(f"refuses a pickled {dtype} scalar whose bytes are not {dtype.itemsize}")
        return np.frombuffer(record.payload, dtype=dtype, count=1)[0]

    def array(self, record: _ArrayRecord, depth: int) -> np.ndarray:
        state = record.state
        if isinstance(state, tuple) and len(state) == 5 and state[0] == 1:
            state = state[1:]
        if not isinstance(state, tuple) or len(state) != 4 or type(state[1]) is not _DtypeRecord:
            raise _Refused("refuses a pickled array without NumPy's state (shape, dtype, order, data)")
        shape, dtype, fortran, data = state[0], _resolve_dtype(state[1]), state[2], state[3]
        if type(shape) is not tuple or not all(type(n) is int and n >= 0 for n in shape) or type(fortran) is not bool:
            raise _Refused(f"refuses a pickled array of shape {_short(shape)}")
        count, order = math.prod(shape), "F" if fortran else "C"
        if dtype.kind != "O":
            if type(data) is not bytes or len(data) != count * dtype.itemsize:
                raise _Refused(f"refuses a pickled {dtype} array of shape {shape} whose bytes do not match it")
            flat = np.frombuffer(data, dtype=dtype, count=count)
            native = dtype.newbyteorder("=")  # as NumPy's own unpickling gives it
            return flat.reshape(shape, order=order).astype(native)
        if type(data) is not list or len(data) != count:
            raise _Refused(f"refuses a pickled object array of shape {shape} whose items do not match it")
        out = np.empty(count, dtype=object)
        for i, item in enumerate(data):
            out[i] = self.value(item, depth + 1)
        return out.reshape(shape, order=order)


# ----------------------------------------------------------------------------- the file
def _unpickled(payload: bytes, shape: tuple) -> np.ndarray:
    """The object array a ``.npy`` file's pickle holds, of the header's ``shape``."""
    try:
        found = _Unpickler(io.BytesIO(payload)).load()
    except _Refused:
        raise
    except Exception as exc:  # noqa: BLE001  anything a malformed pickle raises: nothing but the stand-ins above has run
        detail = (str(exc).splitlines() or [""])[0][:100]
        raise _Refused(f"holds a malformed or truncated pickle ({type(exc).__name__}: {detail})") from None
    if type(found) is not _ArrayRecord:
        raise _Refused(f"pickles a {type(found).__name__}, not the array its header declares")
    array = _Walk(len(payload)).array(found, 0)
    if array.dtype.kind != "O" or array.shape != shape:
        raise _Refused(f"pickles an array of shape {array.shape}, not the object array of shape {shape} "
                       "its header declares")
    return array


def load_npy(path: str | os.PathLike, *, max_bytes: int, what: str = "file") -> np.ndarray:
    """The array a ``.npy`` file holds, read without running any code it names (module doc).

    Args:
        path: the file.
        max_bytes: the most bytes it may hold (`read_input`'s cap).
        what: the kind of file, for messages (``"DexGraspNet file"``).

    Returns:
        A numeric, boolean or string array as ``numpy.load`` gives it, or an object array whose
        elements are ``None``, booleans, numbers, strings, NumPy scalars and arrays, and
        lists, tuples and dicts (string keys) of them.

    Raises:
        GraspValueError: one line naming the file: unreadable, larger than ``max_bytes``,
            not a ``.npy`` file, truncated, declaring more data than it holds, or holding a
            dtype, a pickled global or a value that is not read (named in the message).
    """
    raw = read_input(path, max_bytes, what)
    try:
        dtype, shape, fortran, offset = _header(raw)
        if dtype.kind != "O":
            return _numeric(raw, dtype, shape, fortran, offset)
        if math.prod(shape) > len(raw) - offset:
            raise _Refused(f"declares {math.prod(shape)} objects, more than its {len(raw) - offset} bytes can hold")
        return _unpickled(raw[offset:], shape)
    except _Refused as exc:
        pickled = str(exc).startswith("refuses")
        note = "; a pickled .npy is read only if it holds arrays, numbers, strings, lists, tuples and dicts"
        note = note if pickled else ""
        raise GraspValueError(f"{os.fspath(path)}: the {what} {exc}{note}") from None
