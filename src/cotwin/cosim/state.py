"""Saved states of units and executions as bytes: plain data (None, Booleans, numbers, strings, bytes,
tuples, lists, dicts, sets, numpy scalars and arrays of numbers, and RoboSim's own values: vectors,
matrices, tuples, sequences, sets and frozen records, as the d-model and the mapping hold them; an
enumeration literal is its index, a boolean a bool) behind a header naming its kind.

A state is written with pickle, but read back by an unpickler that refuses every class and function
but numpy's constructors of numeric scalars and arrays and those value classes (tuple and frozenset
subclasses without code of their own), so that state bytes from elsewhere (a file, another process)
can never run code; anything else is an error naming the class, as is a state of another kind.
"""

from __future__ import annotations

import io
import pickle

from ..diagnostics import CotwinError

MAGIC = b"cotwin-state 1\n"


class StateError(CotwinError):
    """Bytes that are not a cotwin state of the expected kind."""


_NUMPY = {(core, name) for core in ("numpy._core.multiarray", "numpy.core.multiarray") for name in ("scalar",)} | \
    {(core, "_frombuffer") for core in ("numpy._core.numeric", "numpy.core.numeric")} | {("numpy", "dtype")}


_VALUES = {("cotwin.robosim.values", name) for name in
           ("VectorValue", "MatrixValue", "TupleValue", "SeqValue", "SetValue", "FrozenRecord")}


class _PlainUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        if (module, name) in _NUMPY or (module, name) in _VALUES:
            return super().find_class(module, name)
        raise StateError(f"a saved state holds only plain data, not {module}.{name}")


def pack(kind: str, data: object) -> bytes:
    """The state `data` (plain data) of a `kind` of unit as bytes."""
    return MAGIC + pickle.dumps((kind, data), protocol=5)


def unpack(blob: bytes | bytearray | memoryview, kind: str) -> object:
    """The plain data packed as `kind`, or StateError saying why the bytes are not such a state."""
    blob = bytes(blob)
    if not blob.startswith(MAGIC):
        raise StateError(f"not a cotwin state (expected a state of a {kind})")
    try:
        found, data = _PlainUnpickler(io.BytesIO(blob[len(MAGIC):])).load()
    except StateError:
        raise
    except Exception as err:  # noqa: BLE001 - truncated or corrupted bytes raise many kinds
        raise StateError(f"a damaged cotwin state ({type(err).__name__}: {err})") from None
    if found != kind:
        raise StateError(f"a state of a {found}, not of a {kind}")
    return data
