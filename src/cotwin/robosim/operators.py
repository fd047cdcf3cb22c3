"""What RoboSim's operators and built-in functions compute, shared by every evaluator (constants, the
d-model interpreter, the mapping runtime) so that they cannot disagree.

Integers follow C, as the generated code does: `/` truncates toward zero and `%` takes the sign of
the dividend; integer division by zero is an error (ZeroDivisionError). Reals follow IEEE 754.
`\\/`, `/\\` and `=>` short-circuit: evaluate them with `short_circuit`.
"""

from __future__ import annotations

import math
import operator

MATH = {
    "sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
    "atan": math.atan, "atan2": math.atan2, "exp": math.exp, "log": math.log, "abs": abs, "min": min, "max": max,
    "pow": math.pow,
}

SHORT_CIRCUIT = ("\\/", "/\\", "=>")


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def divide(a, b):
    if _is_int(a) and _is_int(b):
        if b == 0:
            raise ZeroDivisionError("integer division by zero")
        q = abs(a) // abs(b)
        return q if (a >= 0) == (b >= 0) else -q
    a, b = float(a), float(b)
    if b == 0.0:
        return math.nan if a == 0.0 or math.isnan(a) else math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def remainder(a, b):
    if _is_int(a) and _is_int(b):
        if b == 0:
            raise ZeroDivisionError("integer remainder by zero")
        return a - b * divide(a, b)
    return math.fmod(float(a), float(b))


BINARY = {
    "+": operator.add, "-": operator.sub, "*": operator.mul, "/": divide, "%": remainder,
    "==": operator.eq, "!=": operator.ne, "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
    "iff": lambda a, b: bool(a) == bool(b),
}


def binary(op: str, a, b):
    """The value of `a op b` for an operator that needs both operands (KeyError if op is not one)."""
    return BINARY[op](a, b)


def short_circuit(op: str, left, right):
    """`\\/`, `/\\` or `=>`, with `right` a thunk evaluated only when it decides the result."""
    if op == "\\/":
        return bool(left) or bool(right())
    if op == "/\\":
        return bool(left) and bool(right())
    return (not left) or bool(right())
