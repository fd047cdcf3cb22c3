"""Type checking of expressions and statements against a scope, reporting every mismatch with its place."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from ..diagnostics import Diagnostics, Location
from . import syntax as s
from .declarations import EnumDecl, FunctionDecl, OperationSig
from .types import (
    BOOL, INT, NAT, REAL, STRING, UNKNOWN, CollectionTy, DeviceTy, EnumTy, FuncTy, RecordTy, TupleTy,
    Ty, TypeResolver, VectorTy, assignable, comparable, is_numeric,
)


@dataclass(frozen=True)
class Symbol:
    name: str
    kind: str  # var | const | param | port | binding
    ty: Ty
    loc: Location

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


_LOGICAL = ("\\/", "/\\", "=>", "iff")
_ORDER = ("<", "<=", ">", ">=")
_ARITH = ("+", "-", "*", "/", "%")


class ExprChecker:
    """Types expressions in one context. Hooks give the context's events and qualified names."""

    def __init__(
        self,
        resolver: TypeResolver,
        diag: Diagnostics,
        scope: Scope,
        functions: dict[str, FunctionDecl],
        events: dict[str, Ty | None] | None = None,
        qualified: Callable[[s.QName], Ty | None] | None = None,
        clocks: set[str] | frozenset[str] = frozenset(),
    ):
        self.resolver = resolver
        self.diag = diag
        self.scope = scope
        self.functions = functions
        self.events = events
        self.qualified = qualified
        self.clocks = clocks

    def with_scope(self, scope: Scope) -> "ExprChecker":
        return ExprChecker(self.resolver, self.diag, scope, self.functions, self.events, self.qualified, self.clocks)

    # ---- expressions ----
    def condition(self, expr: s.Expr, what: str) -> None:
        ty = self.check(expr)
        if not assignable(BOOL, ty):
            self.diag.error(expr.loc, f"{what} must be boolean, not {ty}")

    def expect(self, expr: s.Expr, expected: Ty, what: str) -> Ty:
        ty = self.check(expr)
        if not assignable(expected, ty):
            self.diag.error(expr.loc, f"{what}: expected {expected}, got {ty}")
        return ty

    def check(self, expr: s.Expr) -> Ty:
        method = getattr(self, "_" + type(expr).__name__)
        return method(expr)

    def _Literal(self, e: s.Literal) -> Ty:
        if isinstance(e.value, bool):
            return BOOL
        if isinstance(e.value, int):
            return NAT if e.value >= 0 else INT
        if isinstance(e.value, float):
            return REAL
        return STRING

    def _Name(self, e: s.Name) -> Ty:
        name = e.name
        if len(name.parts) == 1:
            symbol = self.scope.lookup(name.last)
            if symbol is not None:
                return symbol.ty
            fn = self.functions.get(name.last)
            if fn is not None:
                return self._function_type(fn)
            self.diag.error(e.loc, f"unknown name '{name}'")
            return UNKNOWN
        enum = self.enum_literal(name)
        if enum is not None:
            return enum
        if self.qualified is not None:
            ty = self.qualified(name)
            if ty is not None:
                return ty
        self.diag.error(e.loc, f"unknown name '{name}'")
        return UNKNOWN

    def enum_literal(self, name: s.QName) -> Ty | None:
        decl = self.resolver.project.lookup("type", s.QName(name.parts[:-1], name.loc), self.resolver.source)
        if isinstance(decl, EnumDecl):
            if decl.literal(name.last) is None:
                self.diag.error(name.loc, f"enumeration '{decl.name}' has no literal '{name.last}'")
            return EnumTy(decl)
        return None

    def _function_type(self, fn: FunctionDecl) -> FuncTy:
        return FuncTy(tuple(self.resolver.resolve(p.type) for p in fn.params), self.resolver.resolve(fn.result))

    def _EventTest(self, e: s.EventTest) -> Ty:
        if self.events is None:
            self.diag.error(e.loc, f"'${e.event}' tests an input event; not allowed here")
            return BOOL
        name = e.event.last
        if name not in self.events:
            self.diag.error(e.event.loc, f"unknown input event '{e.event}'")
            return BOOL
        event_ty = self.events[name]
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
                    self.diag.error(
                        e.loc, f"event '{name}' carries {event_ty} but '{e.bind}' is {symbol.ty}")
        return BOOL

    def _Unary(self, e: s.Unary) -> Ty:
        ty = self.check(e.operand)
        if e.op == "not":
            if not assignable(BOOL, ty):
                self.diag.error(e.loc, f"'not' needs a boolean, not {ty}")
            return BOOL
        if not is_numeric(ty):
            self.diag.error(e.loc, f"'-' needs a number, not {ty}")
            return UNKNOWN
        return INT if ty == NAT else ty

    def _Binary(self, e: s.Binary) -> Ty:
        left, right = self.check(e.left), self.check(e.right)
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
            if isinstance(right, CollectionTy) and not comparable(right.element, left):
                self.diag.error(e.loc, f"{left} cannot be in {right}")
            return BOOL
        for side, ty in ((e.left, left), (e.right, right)):
            if not is_numeric(ty):
                self.diag.error(side.loc, f"'{e.op}' needs numbers, not {ty}")
                return BOOL if e.op in _ORDER else UNKNOWN
        if e.op in _ORDER:
            return BOOL
        if UNKNOWN in (left, right):
            return UNKNOWN
        if REAL in (left, right):
            return REAL
        if e.op == "-" or INT in (left, right):
            return INT
        return NAT

    def _FieldAccess(self, e: s.FieldAccess) -> Ty:
        base = self.check(e.base)
        if base == UNKNOWN:
            return UNKNOWN
        if isinstance(base, RecordTy):
            f = base.decl.field(e.field)
            if f is None:
                self.diag.error(e.loc, f"record '{base.decl.name}' has no field '{e.field}'")
                return UNKNOWN
            return self.resolver.resolve(f.type)
        if isinstance(base, DeviceTy):
            port = base.device.port(e.field)
            if port is None:
                self.diag.error(e.loc, f"{base.device.kind} '{base.device.name}' has no port '{e.field}'")
                return UNKNOWN
            return self.resolver.resolve(port.type)
        self.diag.error(e.loc, f"'.{e.field}' on a value of type {base}")
        return UNKNOWN

    def _IndexAccess(self, e: s.IndexAccess) -> Ty:
        base = self.check(e.base)
        self.expect(e.index, INT, "index")
        if isinstance(base, (VectorTy, CollectionTy)):
            return base.element
        if base != UNKNOWN:
            self.diag.error(e.loc, f"cannot index a value of type {base}")
        return UNKNOWN

    def _Call(self, e: s.Call) -> Ty:
        if isinstance(e.function, s.Name) and len(e.function.name.parts) > 1:
            enum = self.enum_literal(e.function.name)
            if enum is not None:
                for a in e.args:
                    self.check(a)
                return enum
        fn = self.check(e.function)
        if fn == UNKNOWN:
            for a in e.args:
                self.check(a)
            return UNKNOWN
        if not isinstance(fn, FuncTy):
            self.diag.error(e.loc, f"cannot call a value of type {fn}")
            return UNKNOWN
        if len(e.args) != len(fn.params):
            self.diag.error(e.loc, f"expected {len(fn.params)} argument(s), got {len(e.args)}")
        for i, (arg, param) in enumerate(zip(e.args, fn.params)):
            self.expect(arg, param, f"argument {i + 1}")
        return fn.result

    def _IfExpr(self, e: s.IfExpr) -> Ty:
        self.condition(e.condition, "'if' condition")
        a, b = self.check(e.then), self.check(e.otherwise)
        if not comparable(a, b):
            self.diag.error(e.loc, f"branches of 'if' have types {a} and {b}")
        return a if assignable(a, b) else b

    def _LetExpr(self, e: s.LetExpr) -> Ty:
        scope = self.scope.child()
        inner = self.with_scope(scope)
        for name, value in e.bindings:
            scope.symbols[name] = Symbol(name, "binding", inner.check(value), value.loc)
        return inner.check(e.body)

    def _Quantified(self, e: s.Quantified) -> Ty:
        symbols = {n: Symbol(n, "binding", self.resolver.resolve(t), e.loc) for n, t in e.binders}
        body = self.with_scope(self.scope.child(symbols)).check(e.body)
        if e.kind == "lambda":
            return FuncTy(tuple(sym.ty for sym in symbols.values()), body)
        if not assignable(BOOL, body):
            self.diag.error(e.body.loc, f"'{e.kind}' needs a boolean body, not {body}")
        return BOOL

    def _TupleExpr(self, e: s.TupleExpr) -> Ty:
        return TupleTy(tuple(self.check(i) for i in e.items))

    def _VectorExpr(self, e: s.VectorExpr) -> Ty:
        items = [self.check(i) for i in e.items]
        element = REAL if REAL in items else (items[0] if items else UNKNOWN)
        for item, ty in zip(e.items, items):
            if not assignable(element, ty):
                self.diag.error(item.loc, f"vector element of type {ty} among {element}")
        return VectorTy(element, len(items))

    def _CycleExpr(self, e: s.CycleExpr) -> Ty:
        return NAT

    def _SinceExpr(self, e: s.SinceExpr) -> Ty:
        if e.clock not in self.clocks:
            self.diag.error(e.loc, f"unknown clock '{e.clock}'")
        return NAT

    # ---- statements ----
    def statement(
        self,
        stmt: s.Stmt | None,
        operations: dict[str, OperationSig | None],
        outputs: dict[str, Ty | None],
        local_operations: dict[str, tuple[Ty, ...]] | None = None,
    ) -> None:
        """Check an action: assignments, platform calls `$op(...)`, output events `$e!v`."""
        if stmt is None:
            return
        if isinstance(stmt, s.Sequence):
            for item in stmt.statements:
                self.statement(item, operations, outputs, local_operations)
        elif isinstance(stmt, s.IfStmt):
            self.condition(stmt.condition, "'if' condition")
            self.statement(stmt.then, operations, outputs, local_operations)
            self.statement(stmt.otherwise, operations, outputs, local_operations)
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
            if local_operations is None or name not in local_operations:
                self.diag.error(stmt.operation.loc, f"unknown operation '{stmt.operation}'")
                return
            self._arguments(stmt, stmt.args, list(local_operations[name]), name)
        elif isinstance(stmt, s.Send):
            name = stmt.event.last
            if name not in outputs:
                self.diag.error(stmt.event.loc, f"unknown output event '{stmt.event}'")
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
            self.diag.error(root.loc, f"cannot assign to {symbol.kind} '{root.name}'")
        target_ty = self.check(target)
        self.expect(value, target_ty, f"assignment to '{root.name}'")
