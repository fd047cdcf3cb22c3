"""Evaluate constant expressions: p-model dimensions (`0.15/2`, `PI/2`), limits, mapping constants,
d-model constants.

The expression core's Evaluator with names looked up in an environment of constant declarations,
each evaluated once, with cycles reported. Values are those of cotwin.robosim.values (`(|0,0,1|)`
is a TupleValue, a tuple).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..diagnostics import Diagnostics, PicklableError
from . import syntax as s
from .evaluator import Evaluator
from .operators import MATH
from .values import EvalError

#: unit -> factor to SI
UNITS = {"kg": 1.0, "g": 1e-3, "mg": 1e-6, "km": 1e3, "m": 1.0, "cm": 1e-2, "mm": 1e-3, "rad": 1.0,
         "deg": math.pi / 180, "s": 1.0, "ms": 1e-3}
# the unit names of RoboTool's `primitive unit` declarations that cotwin reads (SI: factor 1, degrees as `deg`)
UNITS.update({name: 1.0 for name in ("metre", "metres", "meter", "meters", "second", "seconds", "kilogram",
                                     "kilograms", "radian", "radians", "newton", "newtons")})
UNITS.update({"degree": UNITS["deg"], "degrees": UNITS["deg"]})


class ConstError(PicklableError):
    def __init__(self, loc, message: str):
        super().__init__(message)
        self.loc = loc
        self.message = message


class ParameterNumbering:
    """The values of parameters (constants and variables declared without a value), as RoboTool's SDF
    generator gives them: 1, 2, 3, ... in the order it first meets them (docs/pmodel-notation.md, 3)."""

    def __init__(self) -> None:
        self.given: dict[int, tuple[object, int]] = {}  # id(declaration) -> (declaration, value)

    def value(self, decl) -> int:
        if id(decl) not in self.given:
            self.given[id(decl)] = (decl, len(self.given) + 1)
        return self.given[id(decl)][1]


@dataclass
class ConstEnv:
    """Named constant expressions, with an outer environment (p-model inside file scope). `parameters` are
    declarations without a value: they take the value `numbering` gives them (the nearest one outwards)."""

    definitions: dict[str, s.Expr] = field(default_factory=dict)
    outer: "ConstEnv | None" = None
    _values: dict[str, object] = field(default_factory=dict)
    _active: set[str] = field(default_factory=set)
    #: enumeration literal (qualified name parts) -> index, for d-model constants
    enums: object = None
    parameters: dict[str, object] = field(default_factory=dict)
    numbering: ParameterNumbering | None = None

    def lookup(self, name: str):
        env = self
        while env is not None:
            if name in env.definitions or name in env.parameters:
                return env
            env = env.outer
        return None

    def _numbering(self) -> ParameterNumbering | None:
        env = self
        while env is not None:
            if env.numbering is not None:
                return env.numbering
            env = env.outer
        return None

    def value(self, name: str, loc) -> object:
        env = self.lookup(name)
        if env is None:
            raise ConstError(loc, f"unknown constant '{name}'")
        if name not in env.definitions:
            numbering = env._numbering()
            if numbering is None:
                raise ConstError(loc, f"constant '{name}' has no value")
            return numbering.value(env.parameters[name])
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


class ConstEvaluator(Evaluator):
    """Names are constants of the environment; calls are the built-in math functions."""

    def __init__(self, env: ConstEnv):
        super().__init__()
        self.env = env

    def name(self, e: s.Name):
        if len(e.name.parts) != 1:
            enums = self._enums()
            if enums is not None:
                value = enums(e.name)
                if value is not None:
                    return value
            raise ConstError(e.loc, f"'{e.name}' is not a constant")
        return self.env.value(e.name.last, e.loc)

    def _enums(self):
        env = self.env
        while env is not None:
            if env.enums is not None:
                return env.enums
            env = env.outer
        return None

    def function(self, e: s.Call):
        if isinstance(e.function, s.Name) and e.function.name.last in MATH:
            return MATH[e.function.name.last]
        return None

    def unsupported(self, node):
        raise ConstError(node.loc, "not a constant expression")

    def visit_Binary(self, e: s.Binary):
        if e.op != "^":
            return super().visit_Binary(e)
        # a power: p-models only (the builder reads RoboChart's `^` as `cat` in .rst/.rct files)
        a, b = self.visit(e.left), self.visit(e.right)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b)):
            raise ConstError(e.loc, "'^' needs numbers")
        try:
            value = float(a) ** b
        except (ZeroDivisionError, OverflowError):
            raise ConstError(e.loc, f"{a} ^ {b} cannot be evaluated") from None
        if isinstance(value, complex):
            raise ConstError(e.loc, f"{a} ^ {b} is not a real number")
        return value


def evaluate(expr: s.Expr, env: ConstEnv) -> object:
    """The value of a constant expression, or ConstError with the offending location."""
    try:
        return ConstEvaluator(env).visit(expr)
    except EvalError as err:
        raise ConstError(err.loc or expr.loc, _message(err)) from None


def _message(err: EvalError) -> str:
    if err.kind == "unsupported":
        return "not a constant expression"
    if err.kind == "type" and err.message.startswith("expected a number"):
        return err.message
    return err.message


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
