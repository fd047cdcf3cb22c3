"""Saved states of units and executions as bytes that can neither run code nor corrupt memory when read.

A state is a versioned header, its structure as JSON, and its binary parts as raw bytes after it:

    b"cotwin-state 2\\n" | JSON length (8 bytes, little-endian) | JSON | blob 0 | blob 1 | ...

The JSON is `{"kind": K, "blobs": [length, ...], "data": D}`. D is plain data: JSON's own values (None,
Booleans, integers, finite floats, strings, lists, objects with string keys) and tagged objects for the
rest: `{"$float": "nan" | "inf" | "-inf"}`, `{"$tuple": [...]}`, `{"$set": [...]}`, `{"$frozenset": [...]}`,
`{"$dict": [[key, value], ...]}` (keys that are not strings), `{"$bytes": k}` (blob k),
`{"$array": k, "dtype": "<f8", "shape": [...]}` and `{"$scalar": k, "dtype": ...}` (numbers only: Booleans,
integers and floats of fixed sizes, read with numpy.frombuffer) and `{"$value": "VectorValue", "items": [...]}`
(RoboSim's values as the d-model and the mapping hold them: vectors, matrices, tuples, sequences, sets,
frozen records). Reading builds only these types from fixed tables (no name in the bytes is ever looked up
as a class or a function), checks every length and index against the bytes there are and bounds the
nesting, so that any bytes are either such data or a StateError saying why not.

What the data means is checked by whoever restores it, against the models it restores into (the unit
names, the FMU's identity, sizes, finite times ...), with the checks below (`fields`, `finite`, `like`...),
each naming the place in the state that is wrong; an FMU checks its own serialised state itself.
"""

from __future__ import annotations

import json
import math
import operator
import re

import numpy as np

from ..plaindata import StateError, count, fields, finite, like, of_type, port_value  # noqa: F401 - the checks of a state
from ..robosim.values import CAPACITY, FrozenRecord, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue

MAGIC = b"cotwin-state 2\n"
OLD_MAGIC = b"cotwin-state 1\n"  # cotwin's earlier pickled states: refused, never unpickled
MAX_JSON = 1 << 28  # bytes of a state's JSON part
MAX_DEPTH = 64  # nesting of a state's data
MAX_DIMENSIONS = 8  # of an array

_VALUES = {cls.__name__: cls for cls in (VectorValue, MatrixValue, TupleValue, SeqValue, SetValue, FrozenRecord)}
_DTYPES = {name: np.dtype(name) for name in
           ("|b1", "|i1", "|u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f4", "<f8")}
_CONSTANTS = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
_SCALARS = frozenset((str, int, bool, type(None)))
_KEPT = lambda v: v.__class__ in _SCALARS or (v.__class__ is float and v - v == 0.0)  # noqa: E731 - saved as they are
_STR = {str}
_TAGGED = operator.methodcaller("startswith", "$")  # a key spelt like a tag: the dict is saved as pairs
_LEAVES = frozenset((str, int, bool, type(None)))  # read as they are (a float only when finite)
_SHAPES = {"$float": {"$float"}, "$tuple": {"$tuple"}, "$set": {"$set"}, "$frozenset": {"$frozenset"},
           "$dict": {"$dict"}, "$bytes": {"$bytes"}, "$array": {"$array", "dtype", "shape"},
           "$scalar": {"$scalar", "dtype"}, "$value": {"$value", "items"}}  # a tagged entry's keys, by its tag
_MADE = {"$tuple": tuple, "$set": set, "$frozenset": frozenset}


# ---- writing ----

class _Writer:
    def __init__(self) -> None:
        self.blobs: list[bytes] = []

    def blob(self, data: bytes) -> int:
        self.blobs.append(data)
        return len(self.blobs) - 1

    def encode(self, value, depth: int = 0):
        if depth > MAX_DEPTH:
            raise StateError(f"a state nested deeper than {MAX_DEPTH} levels cannot be saved")
        cls = value.__class__
        if cls is str or cls is int or cls is bool or value is None:  # the most common first: a state is mostly these
            return value
        if cls is float:
            return value if math.isfinite(value) else {"$float": repr(value)}
        if depth >= MAX_DEPTH:  # its items would be nested too deeply: each raises (an empty one is saved)
            kept = lambda v: False  # noqa: E731
        else:  # items saved as they are, without a call each: plain scalars and finite floats (v - v is 0.0)
            kept = _KEPT
        if cls is list:
            return [v if kept(v) else self.encode(v, depth + 1) for v in value]
        if cls is dict:
            if set(map(type, value)) <= _STR and not any(map(_TAGGED, value)):
                return {k: v if kept(v) else self.encode(v, depth + 1) for k, v in value.items()}
            return {"$dict": [[self.encode(k, depth + 1), self.encode(v, depth + 1)] for k, v in value.items()]}
        if cls is tuple:
            return {"$tuple": [v if kept(v) else self.encode(v, depth + 1) for v in value]}
        if isinstance(value, np.ndarray):
            array = self._numeric(value)
            return {"$array": self.blob(array.tobytes()), "dtype": array.dtype.str, "shape": list(array.shape)}
        if isinstance(value, np.generic):
            array = self._numeric(np.asarray(value))
            return {"$scalar": self.blob(array.tobytes()), "dtype": array.dtype.str}
        if cls in (bytes, bytearray, memoryview):
            return {"$bytes": self.blob(bytes(value))}
        if cls.__name__ in _VALUES and _VALUES[cls.__name__] is cls:
            return {"$value": cls.__name__, "items": self._items(value, depth, cls is SetValue)}
        if cls in (set, frozenset):
            return {"$set" if cls is set else "$frozenset": self._items(value, depth, True)}
        raise StateError(f"a state holds only plain data, not a {cls.__module__}.{cls.__qualname__}")

    def _items(self, values, depth: int, unordered: bool) -> list:
        items = [self.encode(v, depth + 1) for v in values]
        return sorted(items, key=lambda item: json.dumps(item, sort_keys=True)) if unordered else items

    @staticmethod
    def _numeric(array: np.ndarray) -> np.ndarray:
        array = np.ascontiguousarray(array)
        if array.dtype.byteorder == ">":
            array = array.astype(array.dtype.newbyteorder("<"))
        if array.dtype.str not in _DTYPES:
            raise StateError(f"a state holds arrays of numbers only, not of {array.dtype}")
        return array


def pack(kind: str, data: object) -> bytes:
    """The state `data` (plain data) of a `kind` of unit as bytes."""
    writer = _Writer()
    tree = writer.encode(data)
    head = json.dumps({"kind": kind, "blobs": [len(b) for b in writer.blobs], "data": tree},
                      separators=(",", ":"), allow_nan=False).encode("utf-8")
    return b"".join((MAGIC, len(head).to_bytes(8, "little"), head, *writer.blobs))


# ---- reading ----

def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")




class _Reader:
    def __init__(self, blobs: list[memoryview]):
        self.blobs = blobs

    def blob(self, index) -> memoryview:
        if index.__class__ is not int or not 0 <= index < len(self.blobs):
            raise StateError(f"a damaged cotwin state (it refers to binary part {index!r} of {len(self.blobs)})")
        return self.blobs[index]

    def decode(self, node, depth: int = 0):
        if depth > MAX_DEPTH:
            raise StateError(f"a damaged cotwin state (nested deeper than {MAX_DEPTH} levels)")
        cls = node.__class__
        if cls in _LEAVES:
            return node
        if cls is float:
            if node - node == 0.0:
                return node
            raise StateError(f"a damaged cotwin state ({node!r} is not a finite number)")  # 1e999 in the JSON
        # items read as they are, without a call each: plain scalars and finite floats (the writer's `_KEPT`),
        # unless they would lie deeper than the limit (then each raises, as before)
        inline = depth < MAX_DEPTH
        if cls is list:
            return [v if inline and (v.__class__ in _LEAVES or v.__class__ is float and v - v == 0.0)
                    else self.decode(v, depth + 1) for v in node]
        if node and min(node) < "%" and any(map(_TAGGED, node)):  # a tag's key sorts below "%": most keys do not
            return self._tagged(node, depth)
        return {k: v if inline and (v.__class__ in _LEAVES or v.__class__ is float and v - v == 0.0)
                else self.decode(v, depth + 1) for k, v in node.items()}

    def _tagged(self, node: dict, depth: int):
        tag = next(filter(_TAGGED, node))
        keys = _SHAPES.get(tag)
        if keys is None or node.keys() != keys:
            raise StateError(f"a damaged cotwin state (an entry {sorted(node)!r:.80} is not plain data)")
        body = node[tag]
        if tag == "$float":
            if body not in _CONSTANTS:
                raise StateError(f"a damaged cotwin state ({body!r:.40} is not nan, inf or -inf)")
            return _CONSTANTS[body]
        if tag == "$bytes":
            return bytes(self.blob(body))
        if tag in ("$array", "$scalar"):
            return self._array(node, tag)
        items = node["items"] if tag == "$value" else body
        if items.__class__ is not list:
            raise StateError(f"a damaged cotwin state ({tag} holds no list)")
        if tag == "$dict":
            if not all(p.__class__ is list and len(p) == 2 for p in items):
                raise StateError("a damaged cotwin state ($dict holds no [key, value] pairs)")
            out = {}
            inline = depth + 1 < MAX_DEPTH
            for key, value in items:
                if inline and key.__class__ is dict and len(key) == 1 and key.get("$tuple").__class__ is list and \
                        all(k.__class__ in _LEAVES for k in key["$tuple"]):  # (unit, port): a tuple of plain items
                    key = tuple(key["$tuple"])
                else:
                    key = self.decode(key, depth + 1)
                try:
                    out[key] = self.decode(value, depth + 1)
                except TypeError:  # an unhashable key (a list, a dict)
                    raise StateError(f"a damaged cotwin state (a key {key!r:.60} that cannot be a key)") from None
            return out
        inline = depth < MAX_DEPTH
        values = [v if inline and (v.__class__ in _LEAVES or v.__class__ is float and v - v == 0.0)
                  else self.decode(v, depth + 1) for v in items]
        try:
            if tag == "$value":
                kind = _VALUES.get(body) if body.__class__ is str else None
                if kind is None:
                    raise StateError(f"a damaged cotwin state ({body!r:.60} is not a RoboSim value)")
                if kind in (SeqValue, SetValue) and len(values) > CAPACITY:
                    raise StateError(f"a damaged cotwin state (a {body} of {len(values)} elements, more than {CAPACITY})")
                return kind(values)
            return _MADE[tag](values)
        except TypeError:  # unhashable elements of a set
            raise StateError(f"a damaged cotwin state (a {tag[1:]} of elements that cannot be in one)") from None

    def _array(self, node: dict, tag: str):
        dtype = _DTYPES.get(node["dtype"]) if node["dtype"].__class__ is str else None
        if dtype is None:
            raise StateError(f"a damaged cotwin state (arrays hold numbers, not {node['dtype']!r:.40})")
        shape = node.get("shape", [])
        if shape.__class__ is not list or len(shape) > MAX_DIMENSIONS or \
                not all(n.__class__ is int and 0 <= n < 1 << 40 for n in shape):
            raise StateError(f"a damaged cotwin state (an array of shape {shape!r:.60})")
        raw = self.blob(node[tag])
        if math.prod(shape) * dtype.itemsize != len(raw):
            raise StateError(f"a damaged cotwin state (an array of shape {shape} of {dtype} in {len(raw)} bytes)")
        array = np.frombuffer(raw, dtype=dtype).reshape(shape).copy()
        return array[()] if tag == "$scalar" else array


def unpack(blob: bytes | bytearray | memoryview, kind: str) -> object:
    """The plain data packed as `kind`, or StateError saying why the bytes are not such a state."""
    return unpacked(blob, (kind,))[1]


def unpacked(blob: bytes | bytearray | memoryview, kinds: tuple[str, ...]) -> tuple[str, object]:
    """The kind (one of `kinds`) and the plain data of a state, or StateError saying why the bytes are not a
    state of one of them: for a reader that takes several (the d-model's state, FMI 2.0's or FMI 3.0's)."""
    kind = " or ".join(kinds)
    view = memoryview(bytes(blob))
    if bytes(view[:len(OLD_MAGIC)]) == OLD_MAGIC:
        raise StateError(f"a state saved by an earlier cotwin (a pickle, which this cotwin never reads: it could "
                         f"run code); save the {kind}'s state again with this cotwin")
    if bytes(view[:len(MAGIC)]) != MAGIC:
        other = re.match(rb"cotwin-state ([0-9]{1,9})\n", bytes(view[:32]))
        if other:  # a header of this format, of a version this cotwin does not read
            raise StateError(f"a cotwin state of an unsupported version {int(other[1])} (this cotwin reads version "
                             f"{MAGIC.split()[1].decode()}; expected a state of a {kind})")
        raise StateError(f"not a cotwin state (expected a state of a {kind})")
    at = len(MAGIC) + 8
    if len(view) < at:
        raise StateError("a damaged cotwin state (it ends within its header)")
    size = int.from_bytes(view[len(MAGIC):at], "little")
    if size > min(MAX_JSON, len(view) - at):
        raise StateError(f"a damaged cotwin state (its structure claims {size} bytes, {max(0, len(view) - at)} follow)")
    try:
        # floats parsed by json's C, each checked finite where it is read (_Reader.decode: 1e999 is inf)
        head = json.loads(bytes(view[at:at + size]).decode("utf-8"), parse_constant=_refuse_constant)
    except RecursionError:
        raise StateError("a damaged cotwin state (its structure is nested too deeply)") from None
    except ValueError as err:  # bad UTF-8 or JSON
        raise StateError(f"a damaged cotwin state ({err})") from None
    if head.__class__ is not dict or set(head) != {"kind", "blobs", "data"} or head["blobs"].__class__ is not list \
            or not all(n.__class__ is int and n >= 0 for n in head["blobs"]):
        raise StateError("a damaged cotwin state (its structure is not {kind, blobs, data})")
    at += size
    if sum(head["blobs"]) != len(view) - at:
        raise StateError(f"a damaged cotwin state (binary parts of {sum(head['blobs'])} bytes, {len(view) - at} follow)")
    blobs = []
    for n in head["blobs"]:
        blobs.append(view[at:at + n])
        at += n
    if head["kind"] not in kinds:
        raise StateError(f"a state of a {str(head['kind'])[:60]}, not of a {kind}")
    return head["kind"], _Reader(blobs).decode(head["data"])
