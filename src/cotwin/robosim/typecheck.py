"""Type checking of expressions and statements against a scope, reporting every mismatch with its place.

Every expression's type is recorded in the project's readings (readings.py), so that the evaluators
and the C generator use the types the checker found. Where RoboTool's notation lets a model be
defective but cotwin can still read it, the checker warns and records the reading.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from ..diagnostics import Diagnostics, Location
from . import functions as fns
from . import syntax as s
from .declarations import EnumDecl, FunctionDecl, OperationSig, Param, RecordDecl, VarDecl
from .readings import Readings
from .types import (
    BOOL, INT, NAT, REAL, STRING, UNKNOWN, CollectionTy, DeviceTy, EnumTy, FuncTy, MatrixTy, RecordTy, TupleTy,
    Ty, TypeResolver, TypeVar, VectorTy, assignable, comparable, is_numeric, join,
)
from .visitor import ExprVisitor


@dataclass(frozen=True)
class Symbol:
    name: str
    kind: str  # var | const | param | port | binding
    ty: Ty
    loc: Location
    decl: object = None  # the VarDecl, for constants a model assigns

    @property
    def writable(self) -> bool:
        return self.kind in ("var", "port")


@dataclass
class Scope:
    symbols: dict[str, Symbol] = field(default_factory=dict)
    outer: "Scope | None" = None

    def lookup(self, name: str) -> Symbol | None:
        scope = self
        while scope is not None:
            if name in scope.symbols:
                return scope.symbols[name]
            scope = scope.outer
        return None

    def child(self, symbols: dict[str, Symbol] | None = None) -> "Scope":
        return Scope(dict(symbols or {}), self)


@dataclass(frozen=True)
class Stray:
    """A name a let (or `the`) binds, used past the end of that binder's body: RoboChart's let and `the` bind
    tighter than a comparison or a logical operator, so in `let x == 1 @ y == x` the second x is outside
    the let and RoboTool does not resolve it (the let's body is `y`)."""

    symbol: Symbol
    binder: object  # the s.LetExpr or s.Quantified
    op: str  # the operator before which the binder's body ended


def ended_binder(name: str, left: s.Expr, op: str, types: dict[int, Ty], resolve) -> Stray | None:
    """The let or `the` binding `name` written in `left` outside brackets (`$go /\\ let m == n @ m > 0`), whose
    body has ended by the end of `left` (where cotwin once read it as reaching to the end of the expression);
    the textually last such binder, None if none. `types` holds the checked types of the bound values."""
    found = None
    pending: list[tuple[s.Expr, str]] = [(left, op)]  # a walk in textual order, without recursion
    while pending:
        node, after = pending.pop()
        if isinstance(node, s.Binary):
            pending += [(node.right, after), (node.left, node.op)]
        elif isinstance(node, s.Unary):
            pending.append((node.operand, after))
        elif isinstance(node, s.LetExpr):
            for bound, value in node.bindings:
                if bound == name:
                    found = Stray(Symbol(bound, "binding", types.get(id(value), UNKNOWN), value.loc), node, after)
            pending.append((node.body, after))
        elif isinstance(node, s.Quantified) and node.kind == "the":
            for bound, type_ref in node.binders:
                if bound == name:
                    found = Stray(Symbol(bound, "binding", resolve(type_ref), node.loc), node, after)
            pending.append((node.body, after))
    return found


_LOGICAL = ("\\/", "/\\", "=>", "iff")
_ORDER = ("<", "<=", ">", ">=")


def _arithmetic(op: str, left: Ty, right: Ty) -> Ty | None:
    """The type of a numeric, vector or matrix operation, None if the operands do not fit it."""
    if is_numeric(left) and is_numeric(right):
        if UNKNOWN in (left, right):
            return UNKNOWN
        if REAL in (left, right):
            return REAL
        if op == "-" or INT in (left, right):
            return INT
        return NAT
    shaped = (VectorTy, MatrixTy)
    if op in ("+", "-") and isinstance(left, shaped) and type(left) is type(right) and comparable(left, right):
        element = _arithmetic(op, left.element, right.element) or UNKNOWN
        if isinstance(left, VectorTy):
            return VectorTy(_widen(element), left.size if left.size is not None else right.size)
        return MatrixTy(_widen(element), left.rows, left.columns)
    if op in ("*", "/") and isinstance(left, shaped) and is_numeric(right):
        element = _widen(_arithmetic(op, left.element, right) or UNKNOWN)
        return VectorTy(element, left.size) if isinstance(left, VectorTy) else MatrixTy(element, left.rows, left.columns)
    if op == "*" and is_numeric(left) and isinstance(right, shaped):
        element = _widen(_arithmetic(op, left, right.element) or UNKNOWN)
        return VectorTy(element, right.size) if isinstance(right, VectorTy) else MatrixTy(element, right.rows, right.columns)
    if op == "*" and isinstance(left, MatrixTy) and isinstance(right, VectorTy):
        return VectorTy(_widen(_arithmetic(op, left.element, right.element) or UNKNOWN), left.rows)
    if op == "*" and isinstance(left, MatrixTy) and isinstance(right, MatrixTy):
        return MatrixTy(_widen(_arithmetic(op, left.element, right.element) or UNKNOWN), left.rows, right.columns)
    return None


def _widen(ty: Ty) -> Ty:
    return INT if ty == NAT else ty


class ExprChecker(ExprVisitor):
    """Types expressions in one context: a scope, the visible functions, the input events, clocks."""

    def __init__(
        self,
        resolver: TypeResolver,
        diag: Diagnostics,
        scope: Scope,
        functions: dict[str, FunctionDecl],
        events: dict[str, Ty | None] | None = None,
        qualified: Callable[[s.QName], Ty | None] | None = None,
        clocks: set[str] | frozenset[str] = frozenset(),
        states: set[str] | frozenset[str] | None = None,
        first_index: int = 1,
    ):
        """`first_index`: the index of a vector's first element where the expressions are evaluated (RoboChart's 1;
        a platform mapping's 0, as cotwin.mapping.runtime evaluates it)."""
        self.resolver = resolver
        self.diag = diag
        self.scope = scope
        self.functions = functions
        self.events = events
        self.qualified = qualified
        self.clocks = clocks
        self.states = states
        self.first_index = first_index
        self.readings: Readings = getattr(resolver.project, "readings", None) or Readings()
        #: the left operands of the binary operators whose right operand is being checked, innermost first, as
        #: (left, operator, outer) links: a let or `the` in one has ended, and RoboTool leaves its names unresolved
        self.lefts: tuple | None = None
        #: True where the expressions are only checked, never evaluated (pre/postconditions): a stray name is a
        #: warning and read as the binder's (published mappings write IK postconditions so)
        self.strays_read = False
        self._strays_said: set[int] = set()

    def with_scope(self, scope: Scope) -> "ExprChecker":
        inner = ExprChecker(self.resolver, self.diag, scope, self.functions, self.events, self.qualified,
                            self.clocks, self.states, self.first_index)
        inner.lefts, inner.strays_read, inner._strays_said = self.lefts, self.strays_read, self._strays_said
        return inner

    @property
    def project(self):
        return self.resolver.project

    @property
    def source(self):
        return self.resolver.source

    # ---- entry points ----
    def condition(self, expr: s.Expr, what: str) -> None:
        ty = self.check(expr)
        if not assignable(BOOL, ty):
            self.diag.error(expr.loc, f"{what} must be boolean, not {ty}")

    def expect(self, expr: s.Expr, expected: Ty, what: str) -> Ty:
        ty = self.check(expr, expected)
        if not assignable(expected, ty):
            self.diag.error(expr.loc, f"{what}: expected {expected}, got {ty}")
        return ty

    def check(self, expr: s.Expr, expected: Ty | None = None) -> Ty:
        self.expected = expected
        ty = self.visit(expr)
        self.readings.types[id(expr)] = ty
        return ty

    def unsupported(self, node) -> Ty:
        self.diag.error(node.loc, f"{type(node).__name__} is not allowed here")
        return UNKNOWN

    # ---- atoms ----
    def visit_Literal(self, e: s.Literal) -> Ty:
        if isinstance(e.value, bool):
            return BOOL
        if isinstance(e.value, int):
            return NAT if e.value >= 0 else INT
        if isinstance(e.value, float):
            return REAL
        return STRING

    def visit_Name(self, e: s.Name) -> Ty:
        name = e.name
        if len(name.parts) == 1:
            symbol = self.scope.lookup(name.last)
            if symbol is not None:
                return symbol.ty
            fn = self.functions.get(name.last)
            if fn is not None:
                return self._function_type(fn)
            stray = self._ended_binder(name.last)
            if stray is not None:
                return self._stray(e, stray)
            if name.last in ("to", "from"):
                self.diag.error(e.loc, f"'{name}' is RoboChart's {name.last.capitalize()}Exp (RoboSim inherits it as an "
                                       "expression) but has no value: RoboTool reads it and gives it no type (its type "
                                       "provider has no case for it), and cotwin cannot evaluate it")
                return UNKNOWN
            self.diag.error(e.loc, f"unknown name '{name}'")
            return UNKNOWN
        enum = self.enum_literal(name)
        if enum is not None:
            return enum
        fn = self.project.lookup("function", name, self.source)
        if fn is not None:
            return self._function_type(fn)
        if self.qualified is not None:
            ty = self.qualified(name)
            if ty is not None:
                return ty
        self.diag.error(e.loc, f"unknown name '{name}'")
        return UNKNOWN

    def _ended_binder(self, name: str) -> Stray | None:
        """The nearest let or `the` before this place that binds `name` and has ended (see `lefts`)."""
        link = self.lefts
        while link is not None:
            left, op, link = link
            found = ended_binder(name, left, op, self.readings.types, self.resolver.resolve)
            if found is not None:
                return found
        return None

    def _stray(self, e: s.Name, stray: Stray) -> Ty:
        """A name only a binder that ended before it binds: an error saying where the body ended (once per
        binder); in a pre/postcondition a warning, the name read as the binder's."""
        if id(stray.binder) not in self._strays_said:
            self._strays_said.add(id(stray.binder))
            word = "let" if isinstance(stray.binder, s.LetExpr) else "the"
            kind = "let" if word == "let" else "'the'"
            message = (f"'{e.name}' is bound by the {kind} at line {stray.binder.loc.line}, whose body ends before "
                       f"'{stray.op}' (a {kind} binds tighter than a comparison or a logical operator, as in RoboChart; "
                       f"RoboTool does not resolve '{e.name}' here): to bind it, put the body in parentheses, "
                       f"'{word} ... @ (... {stray.op} ...)'")
            if self.strays_read:
                self.diag.warning(e.loc, message + f"; cotwin reads it as the {kind}'s in this pre/postcondition")
            else:
                self.diag.error(e.loc, message)
        return stray.symbol.ty if self.strays_read else UNKNOWN

    def enum_literal(self, name: s.QName) -> Ty | None:
        decl = self.project.lookup("type", s.QName(name.parts[:-1], name.loc), self.source)
        if isinstance(decl, EnumDecl):
            if decl.literal(name.last) is None:
                self.diag.error(name.loc, f"enumeration '{decl.name}' has no literal '{name.last}'")
            return EnumTy(decl)
        return None

    def _function_type(self, fn: FunctionDecl) -> FuncTy:
        return FuncTy(tuple(self.resolver.resolve(p.type) for p in fn.params), self.resolver.resolve(fn.result))

    def visit_EventTest(self, e: s.EventTest) -> Ty:
        name = e.event.last
        if self.events is not None and name in self.events and len(e.event.parts) == 1:
            return self._event_test(e, self.events[name])
        symbol = self.scope.lookup(name) if len(e.event.parts) == 1 else None
        if symbol is not None and e.bind is None and e.predicate is None and e.value is None:
            return symbol.ty  # `$v`: the value of (required) variable v
        if symbol is not None and (field := s.dollar_field(e)) is not None:
            return self._field(symbol.ty, field, e.value.loc)  # `$p.f`: RoboSim reads p's field f
        if symbol is not None and e.value is not None and e.bind is None:
            self.diag.error(e.value.loc, f"'${name}.': '{name}' is not an input event but a name with a value, and "
                                         f"after '${name}.' RoboSim reads the name of a field of its type")
            return UNKNOWN
        if self.events is None:
            self.diag.error(e.loc, f"'${e.event}' tests an input event; not allowed here")
        elif len(e.event.parts) > 1 and (name in self.events or self.scope.lookup(name) is not None):
            self.diag.error(e.event.loc, f"'${e.event}': RoboTool resolves the name after '$' by its simple name among "
                                         "the machine's events and variables (RoboSim's scope offers no qualified "
                                         f"name there): write '${name}'")
        else:
            self.diag.error(e.event.loc, f"unknown input event '{e.event}'")
        return BOOL

    def _event_test(self, e: s.EventTest, event_ty: Ty | None) -> Ty:
        name = e.event.last
        if e.bind is not None:
            if event_ty is None:
                self.diag.error(e.loc, f"event '{name}' carries no value, so '?{e.bind}' binds nothing")
            else:
                symbol = self.scope.lookup(e.bind)
                if symbol is None:
                    self.diag.error(e.loc, f"unknown variable '{e.bind}' in '${name}?{e.bind}'")
                elif not symbol.writable:
                    self.diag.error(e.loc, f"'{e.bind}' is a {symbol.kind}; '?{e.bind}' needs a variable")
                elif not assignable(symbol.ty, event_ty):
                    self.diag.error(e.loc, f"event '{name}' carries {event_ty} but '{e.bind}' is {symbol.ty}")
            if e.predicate is not None:
                self.condition(e.predicate, f"predicate of '${name}?{e.bind}'")
        if e.value is not None:
            if event_ty is None:
                self.diag.error(e.loc, f"event '{name}' carries no value to compare with")
                self.check(e.value)
            else:
                self.expect(e.value, event_ty, f"value of event '{name}'")
        return BOOL

    def visit_CycleExpr(self, e: s.CycleExpr) -> Ty:
        return NAT

    def visit_SinceExpr(self, e: s.SinceExpr) -> Ty:
        if e.clock not in self.clocks:
            self.diag.error(e.loc, f"unknown clock '{e.clock}'")
        return NAT

    def visit_SinceEntryExpr(self, e: s.SinceEntryExpr) -> Ty:
        if self.states is not None and ".".join(e.state.parts) not in self.states and e.state.last not in self.states:
            self.diag.error(e.loc, f"sinceEntry: '{e.state}' is not a state of this state machine")
        return NAT

    # ---- operators ----
    def visit_Unary(self, e: s.Unary) -> Ty:
        ty = self.check(e.operand)
        if e.op in ("transpose", "inverse"):
            if isinstance(ty, MatrixTy):
                if e.op == "inverse":
                    if ty.rows != ty.columns:
                        self.diag.error(e.loc, f"inverse needs a square matrix, not {ty}")
                    return MatrixTy(REAL, ty.rows, ty.columns)
                return MatrixTy(ty.element, ty.columns, ty.rows)
            if ty != UNKNOWN:
                self.diag.error(e.loc, f"{e.op} needs a matrix, not {ty}")
            return UNKNOWN
        if e.op == "not":
            if not assignable(BOOL, ty):
                self.diag.error(e.loc, f"'not' needs a boolean, not {ty}")
            return BOOL
        if isinstance(ty, (VectorTy, MatrixTy)):
            return ty
        if not is_numeric(ty):
            self.diag.error(e.loc, f"'-' needs a number, not {ty}")
            return UNKNOWN
        return INT if ty == NAT else ty

    def visit_Binary(self, e: s.Binary) -> Ty:
        left = self.check(e.left)
        outer, self.lefts = self.lefts, (e.left, e.op, self.lefts)
        try:
            right = self.check(e.right)
        finally:
            self.lefts = outer
        if e.op in _LOGICAL:
            for side, ty in ((e.left, left), (e.right, right)):
                if not assignable(BOOL, ty):
                    self.diag.error(side.loc, f"'{e.op}' needs booleans, not {ty}")
            return BOOL
        if e.op in ("==", "!="):
            if not comparable(left, right):
                self.diag.error(e.loc, f"cannot compare {left} with {right}")
            return BOOL
        if e.op == "in":
            if isinstance(right, CollectionTy):
                if not comparable(right.element, left):
                    self.diag.error(e.loc, f"{left} cannot be in {right}")
            elif right != UNKNOWN:
                self.diag.error(e.right.loc, f"'in' needs a set or a sequence, not {right}")
            return BOOL
        if e.op == "cat":
            if isinstance(left, CollectionTy) and isinstance(right, CollectionTy) and left.kind == right.kind == "Seq":
                if not comparable(left.element, right.element):
                    self.diag.error(e.loc, f"cannot concatenate {left} and {right}")
                return CollectionTy("Seq", join(left.element, right.element))
            if UNKNOWN not in (left, right):
                self.diag.error(e.loc, f"'cat' needs sequences, not {left} and {right}")
            return CollectionTy("Seq", UNKNOWN)
        if e.op in _ORDER:
            for side, ty in ((e.left, left), (e.right, right)):
                if not is_numeric(ty):
                    self.diag.error(side.loc, f"'{e.op}' needs numbers, not {ty}")
            return BOOL
        result = _arithmetic(e.op, left, right)
        if result is None:
            if e.op == "%" or not (isinstance(left, (VectorTy, MatrixTy)) or isinstance(right, (VectorTy, MatrixTy))):
                for side, ty in ((e.left, left), (e.right, right)):
                    if not is_numeric(ty):
                        self.diag.error(side.loc, f"'{e.op}' needs numbers, not {ty}")
                        break
            else:
                self.diag.error(e.loc, f"'{e.op}' cannot combine {left} and {right}")
            return UNKNOWN
        if e.op == "%" and not is_numeric(result):
            self.diag.error(e.loc, f"'%' needs numbers, not {left} and {right}")
            return UNKNOWN
        return result

    # ---- selections ----
    def visit_FieldAccess(self, e: s.FieldAccess) -> Ty:
        return self._field(self.check(e.base), e.field, e.loc)

    def _field(self, base: Ty, field: str, loc: Location) -> Ty:
        """The type of field `field` of a value of type `base` (a record's field, a device's port)."""
        if base == UNKNOWN:
            return UNKNOWN
        if isinstance(base, RecordTy):
            f = base.decl.field(field)
            if f is None:
                self.diag.error(loc, f"record '{base.decl.name}' has no field '{field}'")
                return UNKNOWN
            return self.resolver.resolve(f.type)
        if isinstance(base, DeviceTy):
            port = base.device.port(field)
            if port is None:
                self.diag.error(loc, f"{base.device.kind} '{base.device.name}' has no port '{field}'")
                return UNKNOWN
            return self.resolver.resolve(port.type)
        self.diag.error(loc, f"'.{field}' on a value of type {base}")
        return UNKNOWN

    def visit_IndexAccess(self, e: s.IndexAccess) -> Ty:
        base = self.check(e.base)
        if isinstance(base, TupleTy):
            self.check(e.index)
            if not (isinstance(e.index, s.Literal) and isinstance(e.index.value, int)
                    and not isinstance(e.index.value, bool)):
                self.diag.error(e.index.loc, "a tuple is indexed by a number literal")
                return UNKNOWN
            if not 1 <= e.index.value <= len(base.items):
                self.diag.error(e.index.loc, f"tuple index out of range ({e.index.value} out of {len(base.items)})")
                return UNKNOWN
            return base.items[e.index.value - 1]
        self.expect(e.index, INT, "index")
        if isinstance(base, VectorTy):
            self._constant_index(e, base.size)
            return base.element
        if isinstance(base, CollectionTy) and base.kind == "Seq":
            return base.element
        if isinstance(base, MatrixTy):
            self._constant_index(e, base.rows)
            return VectorTy(base.element, base.columns)
        if base != UNKNOWN:
            self.diag.error(e.loc, f"cannot index a value of type {base}")
        return UNKNOWN

    def _constant_index(self, e: s.IndexAccess, size: int | None) -> None:
        if isinstance(e.index, s.Literal) and isinstance(e.index.value, int) and size is not None:
            k, first = e.index.value, self.first_index
            # (an index 0 where vectors count from 1 is check_dmodel's: a statement may be written 0-based)
            if k > size + first - 1 or first == 0 and k < 0:
                self.diag.warning(e.index.loc, f"index {k} is out of range {first}..{size + first - 1}: evaluating "
                                               "it is an error")

    # ---- calls ----
    def visit_Call(self, e: s.Call) -> Ty:
        expected = self.expected
        args = [self.check(a) for a in e.args]
        if isinstance(e.function, s.Name) and len(e.function.name.parts) > 1:
            enum = self.enum_literal(e.function.name)
            if enum is not None:
                return enum
        fn = self._callee(e, args, expected)
        if fn is None:
            ty = self.check(e.function) if not isinstance(e.function, s.Name) else UNKNOWN
            if isinstance(ty, FuncTy):
                self._arguments_against(e, args, list(ty.params), ty.result)
                return ty.result
            return UNKNOWN
        params = [self.resolver.resolve(p.type) for p in fn.params]
        result = self.resolver.resolve(fn.result)
        return self._arguments_against(e, args, params, result)

    def _callee(self, e: s.Call, args: list[Ty], expected: Ty | None) -> FunctionDecl | None:
        if not isinstance(e.function, s.Name):
            return None
        name = e.function.name
        symbol = self.scope.lookup(name.last) if len(name.parts) == 1 else None
        if symbol is not None and isinstance(symbol.ty, FuncTy):
            return None
        fn = self.functions.get(name.last) if len(name.parts) == 1 else self.project.lookup("function", name, self.source)
        if fn is not None:
            if not fn.postconditions and not fn.preconditions and not fns.in_library(self.project, fn):
                builtin = fns.substitute(self.project, fn.name, len(args))
                if builtin is not None:
                    where = "::".join(fns.package_of(self.project, builtin) or ())
                    if len(fn.params) != len(args):
                        self.diag.warning(
                            e.loc, f"function '{fn.name}' is declared with {len(fn.params)} parameter(s) and no "
                                   f"definition but called with {len(args)}: read as {where}::{fn.name}")
                    else:
                        self.diag.warning(fn.loc, f"function '{fn.name}' is declared without a definition: read as "
                                                  f"{where}::{fn.name}")
                    self.readings.call_targets[id(e)] = builtin
                    return builtin
            return fn
        implicit = self.readings.implicit_functions.get((getattr(self.source, "path", ""), name.last))
        if implicit is not None:
            return implicit
        missing = [imp for imp in (self.source.imports if self.source is not None else ())
                   if imp.wildcard and imp.name.parts in fns.SUBSTITUTE_PACKAGES
                   and imp.name.parts not in getattr(self.project, "namespaces", ())]
        if missing and len(name.parts) == 1:
            result = expected if expected is not None and expected != UNKNOWN else REAL
            decl = FunctionDecl(name.last, tuple(Param(f"x{i + 1}", _type_ref(t, e.loc), e.loc) for i, t in enumerate(args)),
                                _type_ref(result, e.loc), (), (), e.loc)
            self.readings.implicit_functions[(self.source.path, name.last)] = decl
            self.diag.warning(
                e.loc, f"unknown function '{name}' (the file imports {missing[0].name}::*, which the project "
                       f"does not contain, and cotwin's {missing[0].name} has no '{name}'): read as an "
                       f"uninterpreted function of type ({', '.join(map(str, args))}) -> {result}")
            return decl
        hint = self.project.elsewhere("function", name)
        extra = f" (there is {', '.join(hint)}: import its package or qualify the name)" if hint else ""
        self.diag.error(e.function.loc, f"unknown function '{name}'{extra}")
        return None

    def _arguments_against(self, e: s.Call, args: list[Ty], params: list[Ty], result: Ty) -> Ty:
        if len(args) != len(params):
            self.diag.error(e.loc, f"expected {len(params)} argument(s), got {len(args)}")
            return _instantiate(result, {})
        bindings: dict[str, Ty] = {}
        for i, (arg, param, node) in enumerate(zip(args, params, e.args)):
            if not _unify(param, arg, bindings):
                self.diag.error(node.loc, f"argument {i + 1}: expected {_instantiate(param, bindings)}, got {arg}")
        return _instantiate(result, bindings)

    # ---- compound expressions ----
    def visit_IfExpr(self, e: s.IfExpr) -> Ty:
        self.condition(e.condition, "'if' condition")
        a, b = self.check(e.then), self.check(e.otherwise)
        if not comparable(a, b):
            self.diag.error(e.loc, f"branches of 'if' have types {a} and {b}")
        return a if assignable(a, b) else b

    def visit_LetExpr(self, e: s.LetExpr) -> Ty:
        scope = self.scope.child()
        inner = self.with_scope(scope)
        for name, value in e.bindings:
            scope.symbols[name] = Symbol(name, "binding", inner.check(value), value.loc)
        return inner.check(e.body)

    def _binders(self, binders, loc) -> dict[str, Symbol]:
        return {n: Symbol(n, "binding", self.resolver.resolve(t), loc) for n, t in binders}

    def visit_Quantified(self, e: s.Quantified) -> Ty:
        symbols = self._binders(e.binders, e.loc)
        inner = self.with_scope(self.scope.child(symbols))
        if e.such_that is not None:
            inner.condition(e.such_that, f"'|' predicate of '{e.kind}'")
        body = inner.check(e.body)
        if e.kind == "lambda":
            return FuncTy(tuple(sym.ty for sym in symbols.values()), body)
        if e.kind == "the":
            return body
        if not assignable(BOOL, body):
            self.diag.error(e.body.loc, f"'{e.kind}' needs a boolean body, not {body}")
        return BOOL

    def visit_SetComprehension(self, e: s.SetComprehension) -> Ty:
        symbols = self._binders(e.binders, e.loc)
        inner = self.with_scope(self.scope.child(symbols))
        if e.predicate is not None:
            inner.condition(e.predicate, "'|' predicate of a set comprehension")
        if e.body is not None:
            return CollectionTy("Set", inner.check(e.body))
        types = [sym.ty for sym in symbols.values()]
        return CollectionTy("Set", types[0] if len(types) == 1 else TupleTy(tuple(types)))

    def _elements(self, items) -> Ty:
        element: Ty = UNKNOWN
        types = [self.check(i) for i in items]
        for item, ty in zip(items, types):
            if not comparable(element, ty):
                self.diag.error(item.loc, f"element of type {ty} among elements of type {element}")
            else:
                element = join(element, ty) if element != UNKNOWN else ty
        return element

    def visit_TupleExpr(self, e: s.TupleExpr) -> Ty:
        return TupleTy(tuple(self.check(i) for i in e.items))

    def visit_VectorExpr(self, e: s.VectorExpr) -> Ty:
        items = [self.check(i) for i in e.items]
        element = REAL if REAL in items else (items[0] if items else UNKNOWN)
        for item, ty in zip(e.items, items):
            if not assignable(element, ty):
                self.diag.error(item.loc, f"vector element of type {ty} among {element}")
        return VectorTy(element, len(items))

    def visit_MatrixExpr(self, e: s.MatrixExpr) -> Ty:
        widths = {len(row) for row in e.rows}
        if len(widths) > 1:
            self.diag.error(e.loc, f"matrix rows have different lengths ({', '.join(str(len(r)) for r in e.rows)})")
        element = self._elements([x for row in e.rows for x in row])
        return MatrixTy(element, len(e.rows), max(widths))

    def visit_SetExpr(self, e: s.SetExpr) -> Ty:
        return CollectionTy("Set", self._elements(e.items))

    def visit_SeqExpr(self, e: s.SeqExpr) -> Ty:
        return CollectionTy("Seq", self._elements(e.items))

    def visit_SetRangeExpr(self, e: s.SetRangeExpr) -> Ty:
        self.expect(e.start, INT, "start of a set range")
        self.expect(e.end, INT, "end of a set range")
        return CollectionTy("Set", INT)

    def visit_RangeExpr(self, e: s.RangeExpr) -> Ty:
        low, high = self.check(e.low), self.check(e.high)
        for side, ty in ((e.low, low), (e.high, high)):
            if not is_numeric(ty):
                self.diag.error(side.loc, f"interval bounds are numbers, not {ty}")
        return CollectionTy("Set", join(low, high))

    def visit_RecordExpr(self, e: s.RecordExpr) -> Ty:
        decl = self.project.lookup("type", e.record, self.source)
        if not isinstance(decl, RecordDecl):
            self.diag.error(e.record.loc, f"unknown record type '{e.record}'")
            for _, value, _ in e.fields:
                self.check(value)
            return UNKNOWN
        given = set()
        for name, value, loc in e.fields:
            f = decl.field(name)
            if f is None:
                self.diag.error(loc, f"record '{decl.name}' has no field '{name}'")
                self.check(value)
                continue
            given.add(name)
            self.expect(value, self.resolver.resolve(f.type), f"field '{name}' of {decl.name}")
        missing = [f.name for f in decl.fields if f.name not in given]
        if missing:
            self.diag.error(e.loc, f"record '{decl.name}' literal leaves out {', '.join(missing)}")
        return RecordTy(decl)

    def visit_TypeTest(self, e: s.TypeTest) -> Ty:
        value = self.check(e.expr)
        target = self.resolver.resolve(e.type)
        if e.kind == "is":
            return BOOL
        if not (comparable(target, value) or (is_numeric(target) and is_numeric(value))):
            self.diag.error(e.loc, f"a value of type {value} cannot be cast as {target}")
        return target

    # ---- statements ----
    def statement(
        self,
        stmt: s.Stmt | None,
        operations: dict[str, OperationSig | None],
        outputs: dict[str, Ty | None],
        local_operations: dict[str, tuple[Ty, ...]] | None = None,
    ) -> None:
        """Check an action: assignments, platform calls `$op(...)`, software operation calls `op(...)`,
        output events `$e!v`."""
        for st in s.statements(stmt):
            self._statement(st, operations, outputs, local_operations)

    def _statement(self, stmt, operations, outputs, local_operations) -> None:
        if isinstance(stmt, s.IfStmt):
            self.condition(stmt.condition, "'if' condition")
        elif isinstance(stmt, s.Assign):
            self.assignment(stmt.target, stmt.value)
        elif isinstance(stmt, s.PlatformCall):
            name = stmt.operation.last
            if name not in operations:
                self.diag.error(stmt.operation.loc, f"unknown operation '{stmt.operation}' (not required here)")
                for a in stmt.args:
                    self.check(a)
                return
            sig = operations[name]
            if sig is not None:
                self._arguments(stmt, stmt.args, [self.resolver.resolve(p.type) for p in sig.params], name)
        elif isinstance(stmt, s.CallStmt):
            name = stmt.operation.last
            if local_operations is not None and name in local_operations:
                self._arguments(stmt, stmt.args, list(local_operations[name]), name)
            elif name in operations and operations[name] is not None:
                sig = operations[name]
                self._arguments(stmt, stmt.args, [self.resolver.resolve(p.type) for p in sig.params], name)
            else:
                self.diag.error(stmt.operation.loc, f"unknown operation '{stmt.operation}'")
                for a in stmt.args:
                    self.check(a)
        elif isinstance(stmt, s.Send):
            name = stmt.event.last
            if name not in outputs:
                self._unknown_output(stmt)
                return
            ty = outputs[name]
            if ty is None and stmt.value is not None:
                self.diag.error(stmt.loc, f"event '{name}' carries no value")
            elif ty is not None and stmt.value is None:
                self.diag.error(stmt.loc, f"event '{name}' carries {ty}: write ${name}!value")
            elif ty is not None:
                self.expect(stmt.value, ty, f"value of event '{name}'")
        elif isinstance(stmt, s.ClockReset):
            if stmt.clock not in self.clocks:
                self.diag.error(stmt.loc, f"unknown clock '{stmt.clock}'")
        elif isinstance(stmt, s.Wait):
            self.expect(stmt.duration, INT, "wait duration")
        elif isinstance(stmt, s.Timed):
            self.check(stmt.deadline)
        elif isinstance(stmt, s.Receive):
            self.check(stmt.target)

    def _unknown_output(self, stmt: s.Send) -> None:
        """One error for a send on no output event: a variable's name in the event's place (`p.f` alone, read as
        `$e.v`, sending f on p) says so, its field not called an unknown name besides."""
        symbol = self.scope.lookup(stmt.event.last) if len(stmt.event.parts) == 1 else None
        if symbol is not None:
            self.diag.error(stmt.event.loc, f"'{stmt.event}' is not an output event but a name with a value: "
                                            f"'{stmt.event}.v' alone is no statement (RoboSim's `$e.v` sends v on "
                                            f"event e); assign it ('{stmt.event}.v = e') or send it ('$e!{stmt.event}')")
            return
        self.diag.error(stmt.event.loc, f"unknown output event '{stmt.event}'")
        if stmt.value is not None:
            self.check(stmt.value)

    def _arguments(self, stmt, args, params: list[Ty], name: str) -> None:
        if len(args) != len(params):
            self.diag.error(stmt.loc, f"'{name}' takes {len(params)} argument(s), got {len(args)}")
        for i, (arg, param) in enumerate(zip(args, params)):
            self.expect(arg, param, f"argument {i + 1} of '{name}'")
        for arg in args[len(params):]:
            self.check(arg)

    def assignment(self, target: s.Expr, value: s.Expr) -> None:
        root = s.root_name(target)
        if root is None:
            self.diag.error(target.loc, "cannot assign to this expression")
            self.check(value)
            return
        symbol = self.scope.lookup(root.name.last) if len(root.name.parts) == 1 else None
        if symbol is not None and not symbol.writable:
            decl = symbol.decl
            if symbol.kind == "const" and isinstance(decl, VarDecl) and decl.init is not None:
                self.diag.warning(root.loc, f"'{root.name}' is a constant but is assigned: read as a variable "
                                            f"initialised to its constant value")
                self.readings.assigned_constants.add(id(decl))
            else:
                self.diag.error(root.loc, f"cannot assign to {symbol.kind} '{root.name}'")
        target_ty = self.check(target)
        self.expect(value, target_ty, f"assignment to '{root.name}'")


# ---- generic functions: ?X type parameters ----

def _unify(param: Ty, arg: Ty, bindings: dict[str, Ty]) -> bool:
    """Does an argument of type `arg` fit a parameter of type `param`, binding its ?X parameters?"""
    if isinstance(param, TypeVar):
        bound = bindings.get(param.name)
        if bound is None or bound == UNKNOWN:
            bindings[param.name] = arg
            return True
        if assignable(bound, arg):
            return True
        if assignable(arg, bound):
            bindings[param.name] = arg
            return True
        return False
    if isinstance(param, CollectionTy) and isinstance(arg, CollectionTy):
        if param.kind == "Set" and arg.kind == "Seq" and isinstance(param.element, TypeVar):
            return _unify(param.element, arg.element, bindings)  # size, dom... of a sequence
        return param.kind == arg.kind and _unify(param.element, arg.element, bindings)
    if isinstance(param, TupleTy) and isinstance(arg, TupleTy):
        return len(param.items) == len(arg.items) and all(_unify(p, a, bindings) for p, a in zip(param.items, arg.items))
    if isinstance(param, VectorTy) and isinstance(arg, VectorTy):
        return _unify(param.element, arg.element, bindings)
    if isinstance(param, MatrixTy) and isinstance(arg, MatrixTy):
        return _unify(param.element, arg.element, bindings)
    return assignable(param, arg)


def _instantiate(ty: Ty, bindings: dict[str, Ty]) -> Ty:
    if isinstance(ty, TypeVar):
        return bindings.get(ty.name, UNKNOWN)
    if isinstance(ty, CollectionTy):
        return CollectionTy(ty.kind, _instantiate(ty.element, bindings))
    if isinstance(ty, TupleTy):
        return TupleTy(tuple(_instantiate(i, bindings) for i in ty.items))
    if isinstance(ty, VectorTy):
        return VectorTy(_instantiate(ty.element, bindings), ty.size)
    if isinstance(ty, MatrixTy):
        if ty.rows is None and ty.columns is None and isinstance(ty.element, TypeVar):
            return MatrixTy(_instantiate(ty.element, bindings), None, None)
        return MatrixTy(_instantiate(ty.element, bindings), ty.rows, ty.columns)
    return ty


def _type_ref(ty: Ty, loc: Location) -> s.TypeRef:
    """A written type for a semantic one (for functions the checker synthesises)."""
    if isinstance(ty, (EnumTy, RecordTy)):
        return s.NamedType(s.QName((ty.decl.name,), loc), loc)
    if isinstance(ty, CollectionTy):
        return s.CollectionType(ty.kind, _type_ref(ty.element, loc), loc)
    if isinstance(ty, TupleTy):
        return s.ProductType(tuple(_type_ref(i, loc) for i in ty.items), loc)
    if isinstance(ty, VectorTy):
        return s.VectorType(_type_ref(ty.element, loc), s.Literal(ty.size or 0, loc), loc)
    name = str(ty) if str(ty) in ("int", "nat", "real", "boolean", "string") else "real"
    return s.NamedType(s.QName((name,), loc), loc)
