"""What RoboSim's operators and built-in functions compute, and how each target spells them: one table
shared by every evaluator (constants, the interpreter, the mapping runtime, compiled closures) and the
C generator, so that they cannot disagree.

Integers follow C's int64, as the generated code does: `/` truncates toward zero and `%` takes the
sign of the dividend; division or remainder by zero and results outside int64 are errors. Reals
follow IEEE 754. `\\/`, `/\\` and `=>` short-circuit (evaluators call `short_circuit`). Vectors and
matrices add and subtract elementwise, scale by a number and multiply as matrices; sequences
concatenate with `cat` (or `^`); `in` tests membership of a set, a sequence or an interval.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Callable

from .values import (
    EvalError, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue, bounded, checked, is_int,
)

SHORT_CIRCUIT = ("\\/", "/\\", "=>")


# ---- scalar arithmetic with C's integer semantics ----

def _num(x, loc):
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise EvalError("type", f"expected a number, got {x!r}", loc)
    return x


def divide(a, b, loc=None):
    if is_int(a) and is_int(b):
        if b == 0:
            raise EvalError("division", "division by zero", loc)
        q = abs(a) // abs(b)
        return checked(q if (a >= 0) == (b >= 0) else -q, loc)
    a, b = float(a), float(b)
    if b == 0.0:
        return math.nan if a == 0.0 or math.isnan(a) else math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def remainder(a, b, loc=None):
    if is_int(a) and is_int(b):
        if b == 0:
            raise EvalError("division", "remainder of a division by zero", loc)
        return a - b * divide(a, b, loc)
    b = float(b)
    if b == 0.0:
        return math.nan
    return math.fmod(float(a), b)


def _scalar(op: Callable):
    def run(a, b, loc=None):
        r = op(_num(a, loc), _num(b, loc))
        return checked(r, loc) if is_int(r) else r
    return run


_add, _sub, _mul = _scalar(operator.add), _scalar(operator.sub), _scalar(operator.mul)


def _elementwise(op, a, b, loc):
    if len(a) != len(b):
        raise EvalError("type", "operands of different sizes", loc)
    return type(a)(op(x, y, loc) for x, y in zip(a, b))


def add(a, b, loc=None):
    if isinstance(a, (VectorValue, MatrixValue)):
        return _elementwise(add, a, b, loc)
    return _add(a, b, loc)


def subtract(a, b, loc=None):
    if isinstance(a, (VectorValue, MatrixValue)):
        return _elementwise(subtract, a, b, loc)
    return _sub(a, b, loc)


def multiply(a, b, loc=None):
    if isinstance(a, MatrixValue) and isinstance(b, MatrixValue):
        columns = list(zip(*b))
        return MatrixValue(VectorValue(dot(row, col, loc) for col in columns) for row in a)
    if isinstance(a, MatrixValue) and isinstance(b, VectorValue):
        return VectorValue(dot(row, b, loc) for row in a)
    if isinstance(a, (VectorValue, MatrixValue)):
        return type(a)(multiply(x, b, loc) for x in a)
    if isinstance(b, (VectorValue, MatrixValue)):
        return type(b)(multiply(a, y, loc) for y in b)
    return _mul(a, b, loc)


def dot(a, b, loc=None):
    total = 0
    for x, y in zip(a, b):
        total = add(total, multiply(x, y, loc), loc)
    return total


def div(a, b, loc=None):
    if isinstance(a, (VectorValue, MatrixValue)):
        return type(a)(div(x, b, loc) for x in a)
    return divide(_num(a, loc), _num(b, loc), loc)


def negate(a, loc=None):
    if isinstance(a, (VectorValue, MatrixValue)):
        return type(a)(negate(x, loc) for x in a)
    a = _num(a, loc)
    return checked(-a, loc) if is_int(a) else -a


def concatenate(a, b, loc=None):
    return bounded(SeqValue(tuple(a) + tuple(b)), loc)


def member(x, collection, loc=None) -> bool:
    if isinstance(collection, Interval):
        return collection.contains(x)
    if isinstance(collection, dict):
        raise EvalError("type", "'in' needs a set or a sequence", loc)
    return x in collection


def equal(a, b, loc=None) -> bool:
    return a == b


def unequal(a, b, loc=None) -> bool:
    return a != b


def _compare(op):
    def run(a, b, loc=None):
        return op(_num(a, loc), _num(b, loc))
    return run


def short_circuit(op: str, left, right):
    """`\\/`, `/\\` or `=>`, with `right` a thunk evaluated only when it decides the result."""
    if op == "\\/":
        return bool(left) or bool(right())
    if op == "/\\":
        return bool(left) and bool(right())
    return (not left) or bool(right())


@dataclass(frozen=True)
class Interval:
    """`[a, b]`, `(a, b]`, ...: a set of numbers, only ever tested with `in`."""

    low: float
    high: float
    low_closed: bool
    high_closed: bool

    def contains(self, x) -> bool:
        above = x >= self.low if self.low_closed else x > self.low
        below = x <= self.high if self.high_closed else x < self.high
        return above and below


@dataclass(frozen=True)
class Operator:
    """A binary operator: its Python meaning, and its C spelling for reals and booleans (`c`) and for
    integers (`c_int`, a call of a checking helper when the operation can fail)."""

    symbol: str
    python: Callable
    c: str
    c_int: str
    fails: bool = False  # on integers: division by zero or overflow


BINARY: dict[str, Operator] = {op.symbol: op for op in (
    Operator("+", add, "({a} + {b})", "ck_add(M, {a}, {b}, {at})", True),
    Operator("-", subtract, "({a} - {b})", "ck_sub(M, {a}, {b}, {at})", True),
    Operator("*", multiply, "({a} * {b})", "ck_mul(M, {a}, {b}, {at})", True),
    Operator("/", div, "({a} / {b})", "ck_div(M, {a}, {b}, {at})", True),
    Operator("%", remainder, "fmod({a}, {b})", "ck_mod(M, {a}, {b}, {at})", True),
    Operator("==", equal, "({a} == {b})", "({a} == {b})"),
    Operator("!=", unequal, "({a} != {b})", "({a} != {b})"),
    Operator("<", _compare(operator.lt), "({a} < {b})", "({a} < {b})"),
    Operator("<=", _compare(operator.le), "({a} <= {b})", "({a} <= {b})"),
    Operator(">", _compare(operator.gt), "({a} > {b})", "({a} > {b})"),
    Operator(">=", _compare(operator.ge), "({a} >= {b})", "({a} >= {b})"),
    Operator("iff", lambda a, b, loc=None: bool(a) == bool(b), "(!{a} == !{b})", "(!{a} == !{b})"),
    Operator("\\/", lambda a, b, loc=None: bool(a) or bool(b), "({a} || {b})", "({a} || {b})"),
    Operator("/\\", lambda a, b, loc=None: bool(a) and bool(b), "({a} && {b})", "({a} && {b})"),
    Operator("=>", lambda a, b, loc=None: (not a) or bool(b), "(!{a} || {b})", "(!{a} || {b})"),
    Operator("in", member, "", ""),
    Operator("cat", concatenate, "", ""),
)}

UNARY_C = {"-": ("(-{a})", "ck_neg(M, {a}, {at})"), "not": ("(!{a})", "(!{a})")}


def binary(op: str, a, b, loc=None):
    """The value of `a op b` (KeyError if op is not a binary operator)."""
    return BINARY[op].python(a, b, loc)


# ---- built-in functions ----

def _real(f):
    def run(*args):
        return f(*(float(a) for a in args))
    return run


def _math(f):
    """A libm function: a domain error gives NaN, as C's libm does, rather than an exception."""
    def run(*args):
        try:
            return f(*(float(a) for a in args))
        except (ValueError, OverflowError):
            return math.nan
    return run


def _floor(x):
    if not math.isfinite(x):
        raise EvalError("domain", f"floor of {x}")
    return checked(math.floor(x))


def _ceil(x):
    if not math.isfinite(x):
        raise EvalError("domain", f"ceil of {x}")
    return checked(math.ceil(x))


def _abs(x):
    return abs(float(x))


def _minmax(f):
    def run(a, b):
        a, b = float(a), float(b)
        if math.isnan(a):
            return b
        if math.isnan(b):
            return a
        return f(a, b)  # the first of equal ones (0.0 and -0.0): C's ck_min/ck_max, not fmin/fmax
    return run


MATH = {
    "sqrt": _math(math.sqrt), "sin": _math(math.sin), "cos": _math(math.cos), "tan": _math(math.tan),
    "asin": _math(math.asin), "acos": _math(math.acos), "atan": _math(math.atan), "atan2": _math(math.atan2),
    "exp": _math(math.exp), "log": _math(math.log), "abs": _abs, "min": _minmax(min), "max": _minmax(max),
    "pow": _math(math.pow), "floor": _floor, "ceil": _ceil,
}

#: C spelling of the math functions (all on reals)
C_MATH = {"sqrt": "sqrt", "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
          "atan2": "atan2", "exp": "exp", "log": "log", "abs": "fabs", "min": "ck_min", "max": "ck_max", "pow": "pow",
          "floor": "ck_floor", "ceil": "ck_ceil"}


def _set(values, loc=None):
    return bounded(SetValue(values), loc)


def _seq_only(s, name):
    if isinstance(s, SetValue):
        raise EvalError("type", f"{name} needs a sequence")
    return s


def _nonempty(s, name):
    if not s:
        raise EvalError("domain", f"{name} of an empty sequence")
    return s


TOOLKIT = {
    # set_toolkit
    "union": lambda a, b: _set(a | b), "inter": lambda a, b: _set(a & b), "diff": lambda a, b: _set(a - b),
    "symetric_diff": lambda a, b: _set(a ^ b), "notin": lambda x, s: x not in s,
    "subseteq": lambda a, b: set(a) <= set(b), "subset": lambda a, b: set(a) < set(b),
    "Union": lambda A: _set(frozenset().union(*A)),
    "Inter": lambda A: _set(frozenset.intersection(*A) if A else frozenset()),
    # sequence_toolkit
    "size": lambda s: len(s), "concat": lambda a, b: concatenate(a, b),
    "head": lambda s: _nonempty(_seq_only(s, "head"), "head")[0],
    "last": lambda s: _nonempty(_seq_only(s, "last"), "last")[-1],
    "tail": lambda s: SeqValue(_nonempty(_seq_only(s, "tail"), "tail")[1:]),
    "front": lambda s: SeqValue(_nonempty(_seq_only(s, "front"), "front")[:-1]),
    "reverse": lambda s: SeqValue(reversed(_seq_only(s, "reverse"))),
    "isNonEmpty": lambda s: len(s) > 0,
    "prefix": lambda s, t: tuple(t[:len(s)]) == tuple(s),
    "suffix": lambda s, t: len(s) <= len(t) and tuple(t[len(t) - len(s):]) == tuple(s),
}


def transpose(m, loc=None):
    return MatrixValue(VectorValue(col) for col in zip(*m))


def inverse(m, loc=None):
    """Gauss-Jordan elimination with partial pivoting; a singular matrix is an error."""
    n = len(m)
    a = [[float(x) for x in row] + [1.0 if i == j else 0.0 for j in range(n)] for i, row in enumerate(m)]
    for col in range(n):
        pivot = max(range(col, n), key=lambda r: abs(a[r][col]))
        if a[pivot][col] == 0.0:
            raise EvalError("domain", "inverse of a singular matrix", loc)
        a[col], a[pivot] = a[pivot], a[col]
        p = a[col][col]
        a[col] = [x / p for x in a[col]]
        for r in range(n):
            if r != col and a[r][col] != 0.0:
                f = a[r][col]
                a[r] = [x - f * y for x, y in zip(a[r], a[col])]
    return MatrixValue(VectorValue(row[n:]) for row in a)


#: RoboChart's matrix forms written like calls (builder.call_expr makes them Unary nodes)
MATRIX_UNARY = {"transpose": transpose, "inverse": inverse}

#: where each built-in package's functions come from
BUILTIN_PACKAGES = {
    ("Mathematics",): {**MATH, "random": None},
    ("physmod", "math"): MATH,
    ("set_toolkit",): TOOLKIT,
    ("sequence_toolkit",): TOOLKIT,
}


def tuple_item(value, index: int, loc=None):
    """The index-th (from 1) component of a product value."""
    if not isinstance(value, TupleValue) or not 1 <= index <= len(value):
        raise EvalError("index", f"tuple index {index} out of range", loc)
    return value[index - 1]
