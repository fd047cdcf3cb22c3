"""Evaluate constant expressions: p-model dimensions (`0.15/2`, `PI/2`), limits, mapping constants.

Values are Python ints, floats, bools, strings and tuples (for `(|0,0,1|)` vectors). Names resolve
through an environment of constant declarations, each evaluated once, with cycles reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..diagnostics import Diagnostics
from . import syntax as s
from .operators import MATH, binary

#: unit -> factor to SI
UNITS = {"kg": 1.0, "g": 1e-3, "m": 1.0, "cm": 1e-2, "mm": 1e-3, "rad": 1.0, "deg": math.pi / 180, "s": 1.0}

class ConstError(Exception):
    def __init__(self, loc, message: str):
        super().__init__(message)
        self.loc = loc
        self.message = message


@dataclass
class ConstEnv:
    """Named constant expressions, with an outer environment (p-model inside file scope)."""

    definitions: dict[str, s.Expr] = field(default_factory=dict)
    outer: "ConstEnv | None" = None
    _values: dict[str, object] = field(default_factory=dict)
    _active: set[str] = field(default_factory=set)

    def lookup(self, name: str):
        env = self
        while env is not None:
            if name in env.definitions:
                return env
            env = env.outer
        return None

    def value(self, name: str, loc) -> object:
        env = self.lookup(name)
        if env is None:
            raise ConstError(loc, f"unknown constant '{name}'")
        if name in env._values:
            return env._values[name]
        if name in env._active:
            raise ConstError(loc, f"constant '{name}' is defined in terms of itself")
        env._active.add(name)
        try:
            result = evaluate(env.definitions[name], env)
        finally:
            env._active.discard(name)
        env._values[name] = result
        return result


def _num(value, loc) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConstError(loc, f"expected a number, got {value!r}")
    return value


def evaluate(expr: s.Expr, env: ConstEnv) -> object:
    """The value of a constant expression, or ConstError with the offending location."""
    if isinstance(expr, s.Literal):
        return expr.value
    if isinstance(expr, s.Name):
        if len(expr.name.parts) != 1:
            raise ConstError(expr.loc, f"'{expr.name}' is not a constant")
        return env.value(expr.name.last, expr.loc)
    if isinstance(expr, s.Unary):
        value = evaluate(expr.operand, env)
        if expr.op == "-":
            return -_num(value, expr.loc)
        if not isinstance(value, bool):
            raise ConstError(expr.loc, "'not' needs a boolean")
        return not value
    if isinstance(expr, s.Binary):
        return _binary(expr, evaluate(expr.left, env), evaluate(expr.right, env))
    if isinstance(expr, (s.TupleExpr, s.VectorExpr)):
        return tuple(evaluate(i, env) for i in expr.items)
    if isinstance(expr, s.IfExpr):
        return evaluate(expr.then if evaluate(expr.condition, env) else expr.otherwise, env)
    if isinstance(expr, s.Call) and isinstance(expr.function, s.Name) and expr.function.name.last in MATH:
        args = [_num(evaluate(a, env), a.loc) for a in expr.args]
        try:
            return MATH[expr.function.name.last](*args)
        except (ValueError, TypeError) as err:
            raise ConstError(expr.loc, f"cannot evaluate {expr.function.name.last}: {err}") from None
    raise ConstError(expr.loc, "not a constant expression")


def _binary(expr: s.Binary, left, right):
    op, loc = expr.op, expr.loc
    if op in ("\\/", "/\\", "=>", "iff"):
        if not isinstance(left, bool) or not isinstance(right, bool):
            raise ConstError(loc, f"'{op}' needs booleans")
        return {"\\/": left or right, "/\\": left and right, "=>": (not left) or right, "iff": left == right}[op]
    if op in ("==", "!="):
        return binary(op, left, right)
    a, b = _num(left, expr.left.loc), _num(right, expr.right.loc)
    try:
        return binary(op, a, b)
    except ZeroDivisionError:
        raise ConstError(expr.right.loc, "division by zero") from None
    except KeyError:
        raise ConstError(loc, f"operator '{op}' is not allowed in a constant") from None


def const_env(declarations, outer: ConstEnv | None = None) -> ConstEnv:
    """An environment from `const` declarations with a value (those without one are parameters)."""
    return ConstEnv({d.name: d.init for d in declarations if d.init is not None}, outer)


def try_evaluate(expr: s.Expr, env: ConstEnv, diag: Diagnostics | None, what: str = "") -> object | None:
    """Evaluate, reporting a failure as an error finding instead of raising."""
    try:
        return evaluate(expr, env)
    except ConstError as err:
        if diag is not None:
            diag.error(err.loc, err.message + (f" (in {what})" if what else ""))
        return None
    except (OverflowError, RecursionError):
        if diag is not None:
            diag.error(expr.loc, "constant expression cannot be evaluated" + (f" (in {what})" if what else ""))
        return None
