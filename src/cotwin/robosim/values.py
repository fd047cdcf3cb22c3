"""Run-time values of RoboSim expressions, shared by every evaluator (constants, interpreter, mapping).

boolean -> bool; int, nat -> int (kept within C's int64: a result outside is an overflow error);
real -> float; enumeration -> the literal's index; record -> dict (field -> value); vector ->
VectorValue, matrix -> MatrixValue (a tuple of row tuples), product -> TupleValue, Seq -> SeqValue
(tuple subclasses, so that `+` on two of them cannot silently concatenate), Set -> SetValue (a
frozenset). Sets and sequences hold at most CAPACITY elements, the bound the generated C uses.
"""

from __future__ import annotations

from ..diagnostics import PicklableError

INT64_MIN = -(2 ** 63)
INT64_MAX = 2 ** 63 - 1
CAPACITY = 32  # elements of an executable Set or Seq


class EvalError(PicklableError):
    """An expression cannot be evaluated: `kind` says why (division, overflow, index, capacity,
    unsupported, name, domain), `loc` where."""

    def __init__(self, kind: str, message: str, loc=None):
        super().__init__(message)
        self.kind = kind
        self.message = message
        self.loc = loc


class VectorValue(tuple):
    """`vector(T, n)`: indexed from 1."""

    def __repr__(self) -> str:
        return "[|" + ", ".join(map(show, self)) + "|]"


class MatrixValue(tuple):
    """`matrix(T, r, c)`: a tuple of rows (VectorValue), indexed m[i, j] from 1."""

    def __repr__(self) -> str:
        return "[|" + "; ".join(", ".join(map(show, row)) for row in self) + "|]"


class TupleValue(tuple):
    """A value of a product type `A * B`: `(|a, b|)`, indexed from 1."""

    def __repr__(self) -> str:
        return "(|" + ", ".join(map(show, self)) + "|)"


class SeqValue(tuple):
    """`Seq(T)`: `<a, b>`, indexed from 1."""

    def __repr__(self) -> str:
        return "<" + ", ".join(map(show, self)) + ">"


class SetValue(frozenset):
    """`Set(T)`: `{a, b}`."""

    def __repr__(self) -> str:
        return "{" + ", ".join(sorted(map(show, self))) + "}"


class FrozenRecord(tuple):
    """A record inside a set or a snapshot: its (field, value) pairs, hashable."""


def freeze(value):
    """A hashable form of a value (records are dicts while running)."""
    if isinstance(value, dict):
        return FrozenRecord((k, freeze(v)) for k, v in value.items())
    if isinstance(value, tuple) and not isinstance(value, FrozenRecord):
        return type(value)(freeze(v) for v in value)
    return value


def thaw(value):
    if isinstance(value, FrozenRecord):
        return {k: thaw(v) for k, v in value}
    if isinstance(value, SetValue):
        return value
    if isinstance(value, tuple):
        return type(value)(thaw(v) for v in value)
    return value


def copy(value):
    """A copy that shares nothing mutable (records are the only mutable values)."""
    if isinstance(value, dict):
        return {k: copy(v) for k, v in value.items()}
    if isinstance(value, tuple) and not isinstance(value, FrozenRecord) and any(isinstance(v, (dict, tuple)) for v in value):
        return type(value)(copy(v) for v in value)
    return value


def is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def checked(value: int, loc=None) -> int:
    """An int result kept within int64, as the generated C keeps it."""
    if value < INT64_MIN or value > INT64_MAX:
        raise EvalError("overflow", "integer overflow", loc)
    return value


def bounded(value, loc=None):
    """A Set or Seq within cotwin's capacity."""
    if len(value) > CAPACITY:
        kind = "set" if isinstance(value, SetValue) else "sequence"
        raise EvalError("capacity", f"{kind} exceeds cotwin's bound of {CAPACITY} elements", loc)
    return value


def show(value) -> str:
    """A value as the model would write it (outputs, traces, messages)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}={show(v)}" for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (VectorValue, MatrixValue, TupleValue, SeqValue, SetValue)):
        return repr(value)
    return str(value)


def canonical(value):
    """A sort key that orders any two values of one type (set iteration follows it)."""
    if isinstance(value, dict):
        return tuple(canonical(v) for v in value.values())
    if isinstance(value, FrozenRecord):
        return tuple(canonical(v) for _, v in value)
    if isinstance(value, SetValue):
        return tuple(sorted(canonical(v) for v in value))
    if isinstance(value, tuple):
        return tuple(canonical(v) for v in value)
    return value


def elements(collection) -> list:
    """The elements of a Set (in canonical order) or a Seq/vector (in order)."""
    if isinstance(collection, SetValue):
        return sorted(collection, key=canonical)
    return list(collection)
