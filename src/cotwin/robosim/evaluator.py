"""Evaluation of expressions to Python values (values.py), in two forms built on one visitor and one
operator table (operators.py): `Evaluator` interprets a tree, `ClosureCompiler` turns it into a
Python closure once and then runs it many times. They differ from one use to another (constants,
the d-model interpreter, the mapping runtime) only in how they look names up: subclasses override
the hooks `name`, `dollar`, `function`, `since`, `since_entry`, `cycle` and `field`.

Every failure is an EvalError with the location of the offending node.
"""

from __future__ import annotations

from typing import Callable

from ..diagnostics import CotwinError, placed
from . import syntax as s
from .operators import BINARY, MATRIX_UNARY, SHORT_CIRCUIT, Interval, negate, short_circuit, tuple_item
from .values import (
    EvalError, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue, bounded, checked, elements, freeze,
    is_int,
)
from .visitor import ExprVisitor, describe


def index(base, position, loc, first: int = 1):
    """base[position] for a vector, sequence, tuple or matrix (a row), counting from `first`."""
    if not is_int(position):
        raise EvalError("type", f"index {position!r} is not an integer", loc)
    if isinstance(base, tuple) and not isinstance(base, SetValue):
        k = position - first
        if 0 <= k < len(base):
            return base[k]
        raise EvalError("index", f"index {position} out of range {first}..{len(base) + first - 1}", loc)
    raise EvalError("type", f"cannot index {base!r}", loc)


def replace_at(base, position, value, loc, first: int = 1):
    """A copy of base with its element at `position` replaced (assignment `v[i] = x`)."""
    index(base, position, loc, first)
    k = position - first
    return type(base)((*base[:k], value, *base[k + 1:]))


def unsupported(node, why: str = "") -> EvalError:
    return EvalError("unsupported", f"{describe(node)} cannot be evaluated{why}", node.loc)


class Evaluator(ExprVisitor):
    """Interprets expressions. `bound` holds names bound by let, quantifiers and comprehensions."""

    def __init__(self) -> None:
        self.bound: dict[str, object] = {}

    def evaluate(self, e: s.Expr):
        return self.visit(e)

    def visit(self, node):
        try:
            return super().visit(node)
        except (TypeError, ValueError, AttributeError, KeyError, IndexError) as err:
            # values of the wrong kind (a model the checker already rejected): a located error, not a crash
            raise EvalError("type", f"{describe(node)} cannot be evaluated: {err}", node.loc) from None

    def unsupported(self, node):
        raise unsupported(node)

    # ---- hooks: how names are looked up ----
    def name(self, e: s.Name):
        raise EvalError("name", f"'{e.name}' has no value here", e.loc)

    def dollar(self, e: s.EventTest):
        """`$v` on a name with a value (no input event where this evaluator runs: a mapping, a p-model) is v's
        value, `$v.f` its field f (RoboSim's SimRefExp on a variable)."""
        if e.bind is None and e.predicate is None and (e.value is None or s.dollar_field(e) is not None):
            return self.dollar_value(e, self.name(s.Name(e.event, e.loc)))
        raise EvalError("unsupported", f"'${e.event}' cannot be evaluated here", e.loc)

    def dollar_value(self, e: s.EventTest, value):
        """The value of `$v` (value) or of `$v.f` (its field f)."""
        field = s.dollar_field(e)
        if field is None:
            return value
        if isinstance(value, dict) and field in value:
            return value[field]
        raise EvalError("type", f"no field '{field}' in {value!r}", e.value.loc)

    def function(self, e: s.Call) -> Callable | None:
        return None

    def since(self, e: s.SinceExpr):
        raise unsupported(e, " here")

    def since_entry(self, e: s.SinceEntryExpr):
        raise unsupported(e, " here")

    def cycle(self, e: s.CycleExpr):
        raise unsupported(e, " here")

    def field(self, e: s.FieldAccess):
        """The value of `base.field`; overridden where a name path means something else (sensors)."""
        base = self.visit(e.base)
        if isinstance(base, dict) and e.field in base:
            return base[e.field]
        raise EvalError("type", f"no field '{e.field}' in {base!r}", e.loc)

    def first_index(self, e: s.IndexAccess) -> int:
        return 1

    def record(self, e: s.RecordExpr) -> dict:
        return {name: self.visit(value) for name, value, _ in e.fields}

    def domain(self, name: str, type_ref: s.TypeRef, node) -> list:
        """The values a bound name ranges over when nothing in the predicate bounds it."""
        raise unsupported(node, f": '{name}' ranges over an infinite type (bound it with '{name} in S')")

    # ---- the expression forms ----
    def visit_Literal(self, e: s.Literal):
        return e.value

    def visit_Name(self, e: s.Name):
        if len(e.name.parts) == 1 and e.name.last in self.bound:
            return self.bound[e.name.last]
        return self.name(e)

    def visit_EventTest(self, e: s.EventTest):
        return self.dollar(e)

    def visit_Unary(self, e: s.Unary):
        value = self.visit(e.operand)
        if e.op == "not":
            return not value
        if e.op in MATRIX_UNARY:
            return MATRIX_UNARY[e.op](value, e.loc)
        return negate(value, e.loc)

    def visit_Binary(self, e: s.Binary):
        left = self.visit(e.left)
        if e.op in SHORT_CIRCUIT:
            return short_circuit(e.op, left, lambda: self.visit(e.right))
        operator = BINARY.get(e.op)
        if operator is None:
            raise unsupported(e)
        return operator.python(left, self.visit(e.right), e.loc)

    def visit_FieldAccess(self, e: s.FieldAccess):
        return self.field(e)

    def visit_IndexAccess(self, e: s.IndexAccess):
        return index(self.visit(e.base), self.visit(e.index), e.loc, self.first_index(e))

    def visit_Call(self, e: s.Call):
        fn = self.function(e)
        if fn is None:
            raise unsupported(e, f": '{_call_name(e)}' has no executable definition")
        args = [self.visit(a) for a in e.args]
        try:
            result = fn(*args)
        except EvalError as err:
            raise EvalError(err.kind, f"{_call_name(e)}: {err.message}", err.loc or e.loc) from None
        except CotwinError as err:  # a function's own error (the IK's) names no place: its call is it
            raise placed(err, e.loc) from None
        except (TypeError, ValueError, OverflowError, ZeroDivisionError) as err:
            raise EvalError("domain", f"cannot evaluate {_call_name(e)}: {err}", e.loc) from None
        return checked(result, e.loc) if is_int(result) else result

    def visit_IfExpr(self, e: s.IfExpr):
        return self.visit(e.then if self.visit(e.condition) else e.otherwise)

    def visit_LetExpr(self, e: s.LetExpr):
        saved = dict(self.bound)
        try:
            for name, value in e.bindings:
                self.bound[name] = self.visit(value)
            return self.visit(e.body)
        finally:
            self.bound = saved

    def _bindings(self, binders, such_that, node):
        """Every assignment of values to the binders satisfying `such_that` (finite domains only)."""
        ranges = []
        for name, type_ref in binders:
            ranges.append((name, self._range_of(name, type_ref, such_that, node)))
        saved = dict(self.bound)

        def walk(k):
            if k == len(ranges):
                if such_that is None or self.visit(such_that):
                    yield dict(self.bound)
                return
            name, values = ranges[k]
            for v in values:
                self.bound[name] = v
                yield from walk(k + 1)

        try:
            yield from walk(0)
        finally:
            self.bound = saved

    def _range_of(self, name, type_ref, such_that, node) -> list:
        for conjunct in s.conjuncts(such_that):
            if (isinstance(conjunct, s.Binary) and conjunct.op == "in" and isinstance(conjunct.left, s.Name)
                    and conjunct.left.name.parts == (name,)):
                collection = self.visit(conjunct.right)
                if isinstance(collection, Interval):
                    break
                return elements(collection)
        return self.domain(name, type_ref, node)

    def visit_Quantified(self, e: s.Quantified):
        if e.kind == "lambda":
            raise unsupported(e)
        count = 0
        found = None
        for binding in self._bindings(e.binders, e.such_that, e):
            saved, self.bound = self.bound, binding
            try:
                value = self.visit(e.body)
            finally:
                self.bound = saved
            if e.kind == "the":
                count += 1
                found = value
                continue
            if e.kind == "forall" and not value:
                return False
            if e.kind in ("exists", "exists1") and value:
                count += 1
                if e.kind == "exists":
                    return True
        if e.kind == "forall":
            return True
        if e.kind == "exists":
            return False
        if e.kind == "exists1":
            return count == 1
        if count != 1:
            raise EvalError("domain", f"'the' found {count} values, not exactly one", e.loc)
        return found

    def visit_SetComprehension(self, e: s.SetComprehension):
        out = []
        for binding in self._bindings(e.binders, e.predicate, e):
            if e.body is None:
                out.append(binding[e.binders[0][0]] if len(e.binders) == 1 else TupleValue(binding.values()))
                continue
            saved, self.bound = self.bound, binding
            try:
                out.append(self.visit(e.body))
            finally:
                self.bound = saved
        return bounded(SetValue(freeze(v) for v in out), e.loc)

    def visit_TupleExpr(self, e: s.TupleExpr):
        return TupleValue(self.visit(i) for i in e.items)

    def visit_VectorExpr(self, e: s.VectorExpr):
        return VectorValue(self.visit(i) for i in e.items)

    def visit_MatrixExpr(self, e: s.MatrixExpr):
        return MatrixValue(VectorValue(self.visit(i) for i in row) for row in e.rows)

    def visit_SetExpr(self, e: s.SetExpr):
        return bounded(SetValue(freeze(self.visit(i)) for i in e.items), e.loc)

    def visit_SetRangeExpr(self, e: s.SetRangeExpr):
        low, high = self.visit(e.start), self.visit(e.end)
        if not (is_int(low) and is_int(high)):
            raise EvalError("type", "a set range needs integers", e.loc)
        if high - low + 1 > 10 ** 6:
            raise EvalError("capacity", f"set range of {high - low + 1} elements", e.loc)
        return bounded(SetValue(range(low, high + 1)), e.loc)

    def visit_SeqExpr(self, e: s.SeqExpr):
        return bounded(SeqValue(self.visit(i) for i in e.items), e.loc)

    def visit_RecordExpr(self, e: s.RecordExpr):
        return self.record(e)

    def visit_RangeExpr(self, e: s.RangeExpr):
        return Interval(self.visit(e.low), self.visit(e.high), e.low_closed, e.high_closed)

    def visit_TypeTest(self, e: s.TypeTest):
        if e.kind == "as":
            return self.visit(e.expr)
        raise unsupported(e)

    def visit_CycleExpr(self, e: s.CycleExpr):
        return self.cycle(e)

    def visit_SinceExpr(self, e: s.SinceExpr):
        return self.since(e)

    def visit_SinceEntryExpr(self, e: s.SinceEntryExpr):
        return self.since_entry(e)


def _call_name(e: s.Call) -> str:
    return str(e.function.name) if isinstance(e.function, s.Name) else "function"


class ClosureCompiler(ExprVisitor):
    """Compiles an expression once into a closure `f(env)`; `env` is whatever the hooks' closures
    read (a mapping scope, a machine state). Same operators, same errors as Evaluator; forms it does
    not compile fall back to a closure that runs an Evaluator made by `fallback(env)`."""

    def compile(self, e: s.Expr) -> Callable:
        return self.visit(e)

    def unsupported(self, node):
        def run(env, node=node):
            return self.fallback(env).visit(node)
        return run

    # ---- hooks ----
    def compile_name(self, e: s.Name) -> Callable:
        raise unsupported(e)

    def compile_call(self, e: s.Call) -> Callable | None:
        """A closure returning the Python function a call runs, or None if there is none."""
        return None

    def compile_field(self, e: s.FieldAccess) -> Callable | None:
        """A closure for `base.field` when it means something other than a record field."""
        return None

    def fallback(self, env) -> Evaluator:
        raise NotImplementedError

    # ---- forms ----
    def visit_Literal(self, e: s.Literal):
        value = e.value
        return lambda env: value

    def visit_Name(self, e: s.Name):
        return self.compile_name(e)

    def visit_Unary(self, e: s.Unary):
        operand = self.visit(e.operand)
        if e.op == "not":
            return lambda env: not operand(env)
        loc = e.loc
        run = MATRIX_UNARY.get(e.op, negate)
        return lambda env: run(operand(env), loc)

    def visit_Binary(self, e: s.Binary):
        left, right = self.visit(e.left), self.visit(e.right)
        if e.op == "/\\":
            return lambda env: bool(left(env)) and bool(right(env))
        if e.op == "\\/":
            return lambda env: bool(left(env)) or bool(right(env))
        if e.op == "=>":
            return lambda env: (not left(env)) or bool(right(env))
        operator = BINARY.get(e.op)
        if operator is None:
            return self.unsupported(e)
        run, loc = operator.python, e.loc
        return lambda env: run(left(env), right(env), loc)

    def visit_FieldAccess(self, e: s.FieldAccess):
        special = self.compile_field(e)
        if special is not None:
            return special
        base, name, loc = self.visit(e.base), e.field, e.loc

        def run(env):
            value = base(env)
            if isinstance(value, dict) and name in value:
                return value[name]
            raise EvalError("type", f"no field '{name}' in {value!r}", loc)
        return run

    def visit_IndexAccess(self, e: s.IndexAccess):
        base, position, loc = self.visit(e.base), self.visit(e.index), e.loc
        return lambda env: index(base(env), position(env), loc)

    def visit_Call(self, e: s.Call):
        fn = self.compile_call(e)
        if fn is None:
            return self.unsupported(e)
        args = [self.visit(a) for a in e.args]
        name, loc = _call_name(e), e.loc

        def run(env):
            f = fn(env)
            values = [a(env) for a in args]
            try:
                result = f(*values)
            except EvalError as err:
                raise EvalError(err.kind, f"{name}: {err.message}", err.loc or loc) from None
            except CotwinError as err:  # a function's own error (the IK's) names no place: its call is it
                raise placed(err, loc) from None
            except (TypeError, ValueError, OverflowError, ZeroDivisionError) as err:
                raise EvalError("domain", f"cannot evaluate {name}: {err}", loc) from None
            return checked(result, loc) if is_int(result) else result
        return run

    def visit_IfExpr(self, e: s.IfExpr):
        condition, then, otherwise = self.visit(e.condition), self.visit(e.then), self.visit(e.otherwise)
        return lambda env: then(env) if condition(env) else otherwise(env)

    def visit_TupleExpr(self, e: s.TupleExpr):
        items = [self.visit(i) for i in e.items]
        return lambda env: TupleValue(i(env) for i in items)

    def visit_VectorExpr(self, e: s.VectorExpr):
        items = [self.visit(i) for i in e.items]
        return lambda env: VectorValue(i(env) for i in items)

    def visit_SetExpr(self, e: s.SetExpr):
        items, loc = [self.visit(i) for i in e.items], e.loc
        return lambda env: bounded(SetValue(freeze(i(env)) for i in items), loc)

    def visit_SeqExpr(self, e: s.SeqExpr):
        items, loc = [self.visit(i) for i in e.items], e.loc
        return lambda env: bounded(SeqValue(i(env) for i in items), loc)


__all__ = ["ClosureCompiler", "Evaluator", "index", "replace_at", "tuple_item", "unsupported"]
