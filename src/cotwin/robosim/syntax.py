"""Locations, names, type references, expressions and statements shared by all RoboSim notations.

Expressions and statements are immutable trees; every node carries the location of its first token
so that later stages (type checking, code generation, verification) can report where a problem is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Union

from ..diagnostics import Location


NOWHERE = Location("<builtin>", 0, 0)


@dataclass(frozen=True)
class QName:
    """A possibly qualified name `a::b::c` as written, with where it was written."""

    parts: tuple[str, ...]
    loc: Location = field(default=NOWHERE, compare=False)

    @property
    def last(self) -> str:
        return self.parts[-1]

    def __str__(self) -> str:
        return "::".join(self.parts)


# ---- type references (as written; resolved to semantic types by cotwin.robosim.types) ----


@dataclass(frozen=True)
class NamedType:
    name: QName
    loc: Location


@dataclass(frozen=True)
class VectorType:
    element: "TypeRef"
    size: "Expr"
    loc: Location


@dataclass(frozen=True)
class MatrixType:
    element: "TypeRef"
    rows: "Expr"
    columns: "Expr"
    loc: Location


@dataclass(frozen=True)
class CollectionType:
    kind: str  # "Set" | "Seq"
    element: "TypeRef"
    loc: Location


@dataclass(frozen=True)
class ProductType:
    items: tuple["TypeRef", ...]
    loc: Location


@dataclass(frozen=True)
class FunctionType:
    argument: "TypeRef"
    result: "TypeRef"
    loc: Location


TypeRef = Union[NamedType, VectorType, MatrixType, CollectionType, ProductType, FunctionType]


# ---- expressions --------------------------------------------------------------------------


@dataclass(frozen=True)
class Literal:
    value: object  # int | float | bool | str
    loc: Location


@dataclass(frozen=True)
class Name:
    """A reference to a variable, constant, parameter, enumeration literal or sensor port."""

    name: QName
    loc: Location


@dataclass(frozen=True)
class EventTest:
    """`$e` (did e arrive in this cycle?), `$e?x` (and bind its value to x when taken), `$e?x:p`
    (and the bound value satisfies p), `$e.v` (and its value is v). On a variable, `$v` is its value."""

    event: QName
    bind: str | None
    loc: Location
    predicate: "Expr | None" = None
    value: "Expr | None" = None


@dataclass(frozen=True)
class Unary:
    op: str  # "-" | "not"
    operand: "Expr"
    loc: Location


@dataclass(frozen=True)
class Binary:
    op: str  # iff => \/ /\ == != < <= > >= in + - * / %
    left: "Expr"
    right: "Expr"
    loc: Location


@dataclass(frozen=True)
class FieldAccess:
    base: "Expr"
    field: str
    loc: Location


@dataclass(frozen=True)
class IndexAccess:
    base: "Expr"
    index: "Expr"
    loc: Location


@dataclass(frozen=True)
class Call:
    function: "Expr"
    args: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class IfExpr:
    condition: "Expr"
    then: "Expr"
    otherwise: "Expr"
    loc: Location


@dataclass(frozen=True)
class LetExpr:
    bindings: tuple[tuple[str, "Expr"], ...]
    body: "Expr"
    loc: Location


@dataclass(frozen=True)
class Quantified:
    """`forall`, `exists`, `exists1`, `lambda` or `the` (definite description), with binders, an
    optional such-that predicate (`| p`) and a body (`@ e`)."""

    kind: str  # forall | exists | exists1 | lambda | the
    binders: tuple[tuple[str, TypeRef], ...]
    body: "Expr"
    loc: Location
    such_that: "Expr | None" = None


@dataclass(frozen=True)
class TupleExpr:
    """`(| a, b |)`: a tuple, also used for axis vectors in p-models."""

    items: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class VectorExpr:
    """`[| a, b |]`: a vector literal."""

    items: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class CycleExpr:
    loc: Location


@dataclass(frozen=True)
class SinceExpr:
    """`since(C)`: cycles since clock C was last reset (or since the machine started)."""

    clock: str
    loc: Location


@dataclass(frozen=True)
class SinceEntryExpr:
    """`sinceEntry(S)`: cycles since state S was last entered."""

    state: QName
    loc: Location


@dataclass(frozen=True)
class SetExpr:
    """`{a, b}` (and `{}`)."""

    items: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class SetRangeExpr:
    """`{a to b}`: the integers from a to b."""

    start: "Expr"
    end: "Expr"
    loc: Location


@dataclass(frozen=True)
class SeqExpr:
    """`<a, b>` (and `<>`)."""

    items: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class SetComprehension:
    """`{x: T | p @ e}`: the values of e for the x of type T satisfying p."""

    binders: tuple[tuple[str, TypeRef], ...]
    predicate: "Expr | None"
    body: "Expr | None"
    loc: Location


@dataclass(frozen=True)
class MatrixExpr:
    """`[|a, b; c, d|]`: rows of equal length."""

    rows: tuple[tuple["Expr", ...], ...]
    loc: Location


@dataclass(frozen=True)
class RecordExpr:
    """`R(| f = e, ... |)`: a record value."""

    record: QName
    fields: tuple[tuple[str, "Expr", Location], ...]
    loc: Location


@dataclass(frozen=True)
class RangeExpr:
    """`[a, b]`, `[a, b)`, `(a, b]`, `(a, b)`: an interval."""

    low: "Expr"
    high: "Expr"
    low_closed: bool
    high_closed: bool
    loc: Location


@dataclass(frozen=True)
class TypeTest:
    """`e as T` (a cast) or `e is T` (a type test)."""

    expr: "Expr"
    type: TypeRef
    kind: str  # as | is
    loc: Location


Expr = Union[
    Literal, Name, EventTest, Unary, Binary, FieldAccess, IndexAccess, Call, IfExpr, LetExpr,
    Quantified, TupleExpr, VectorExpr, CycleExpr, SinceExpr, SinceEntryExpr, SetExpr, SetRangeExpr,
    SeqExpr, SetComprehension, MatrixExpr, RecordExpr, RangeExpr, TypeTest,
]


# ---- statements ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Sequence:
    statements: tuple["Stmt", ...]
    loc: Location


@dataclass(frozen=True)
class Exec:
    """Ends the current cycle; the rest of the statement runs in the next one."""

    loc: Location


@dataclass(frozen=True)
class Skip:
    loc: Location


@dataclass(frozen=True)
class Send:
    """`$e` or `$e!v`: an output event of this cycle."""

    event: QName
    value: "Expr | None"
    loc: Location


@dataclass(frozen=True)
class PlatformCall:
    """`$op(args)`: a call of a platform operation, an output of this cycle."""

    operation: QName
    args: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class CallStmt:
    """`op(args)`: a call of an operation defined in the controller."""

    operation: QName
    args: tuple["Expr", ...]
    loc: Location


@dataclass(frozen=True)
class Assign:
    target: "Expr"  # Name, FieldAccess or IndexAccess rooted in a Name
    value: "Expr"
    loc: Location


@dataclass(frozen=True)
class IfStmt:
    condition: "Expr"
    then: "Stmt"
    otherwise: "Stmt | None"
    loc: Location


@dataclass(frozen=True)
class ClockReset:
    clock: str
    loc: Location


@dataclass(frozen=True)
class Wait:
    """RoboChart's `wait(d)` (in .rct files; no RoboSim meaning)."""

    duration: "Expr"
    loc: Location


@dataclass(frozen=True)
class Receive:
    """RoboChart's `e?x` input communication as an action (in .rct files)."""

    event: QName
    target: "Expr"
    loc: Location


@dataclass(frozen=True)
class Timed:
    """RoboChart's `s <{ d }`: s with a deadline (in .rct files)."""

    stmt: "Stmt"
    deadline: "Expr"
    loc: Location


Stmt = Union[Sequence, Exec, Skip, Send, PlatformCall, CallStmt, Assign, IfStmt, ClockReset, Wait, Receive, Timed]


def root_name(target: Expr) -> Name | None:
    """The variable an assignment target `x.f[i]` writes to."""
    while isinstance(target, (FieldAccess, IndexAccess)):
        target = target.base
    return target if isinstance(target, Name) else None


_CHILDREN = {
    Unary: lambda e: (e.operand,),
    Binary: lambda e: (e.left, e.right),
    FieldAccess: lambda e: (e.base,),
    IndexAccess: lambda e: (e.base, e.index),
    Call: lambda e: (e.function, *e.args),
    IfExpr: lambda e: (e.condition, e.then, e.otherwise),
    LetExpr: lambda e: (*(value for _, value in e.bindings), e.body),
    Quantified: lambda e: tuple(x for x in (e.such_that, e.body) if x is not None),
    TupleExpr: lambda e: e.items,
    VectorExpr: lambda e: e.items,
    SetExpr: lambda e: e.items,
    SeqExpr: lambda e: e.items,
    SetRangeExpr: lambda e: (e.start, e.end),
    SetComprehension: lambda e: tuple(x for x in (e.predicate, e.body) if x is not None),
    MatrixExpr: lambda e: tuple(x for row in e.rows for x in row),
    RecordExpr: lambda e: tuple(value for _, value, _ in e.fields),
    RangeExpr: lambda e: (e.low, e.high),
    TypeTest: lambda e: (e.expr,),
    EventTest: lambda e: tuple(x for x in (e.predicate, e.value) if x is not None),
}


def sub_expressions(expr: Expr):
    """Direct children of an expression, for generic walks."""
    children = _CHILDREN.get(type(expr))
    return children(expr) if children is not None else ()


def walk(expr: Expr):
    """Every node of an expression tree, pre-order."""
    stack = [expr]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(sub_expressions(node)))


def statements(stmt: "Stmt | None"):
    """Every statement of an action tree, pre-order (sequences, branches and timed bodies opened)."""
    stack = [stmt] if stmt is not None else []
    while stack:
        node = stack.pop()
        yield node
        if isinstance(node, Sequence):
            stack.extend(reversed(node.statements))
        elif isinstance(node, IfStmt):
            stack.extend(x for x in (node.otherwise, node.then) if x is not None)
        elif isinstance(node, Timed):
            stack.append(node.stmt)


def statement_expressions(stmt: "Stmt"):
    """The expressions a single statement (not its sub-statements) evaluates."""
    if isinstance(stmt, Assign):
        return (stmt.target, stmt.value)
    if isinstance(stmt, (PlatformCall, CallStmt)):
        return stmt.args
    if isinstance(stmt, Send):
        return (stmt.value,) if stmt.value is not None else ()
    if isinstance(stmt, IfStmt):
        return (stmt.condition,)
    if isinstance(stmt, Wait):
        return (stmt.duration,)
    if isinstance(stmt, Receive):
        return (stmt.target,)
    if isinstance(stmt, Timed):
        return (stmt.deadline,)
    return ()


def conjuncts(e) -> list:
    """The conjuncts of a predicate (`a /\\ b /\\ c` gives [a, b, c]; None gives [])."""
    if e is None:
        return []
    if isinstance(e, Binary) and e.op == "/\\":
        return conjuncts(e.left) + conjuncts(e.right)
    return [e]


def dollar_field(e: EventTest) -> str | None:
    """The field f of `$v.f` (RoboSim's SimRefExp on a variable v: its scope reads the name after '.' among
    the fields of v's type, and its type is the field's), None for any other `$` form."""
    if e.bind is None and e.predicate is None and isinstance(e.value, Name) and len(e.value.name.parts) == 1:
        return e.value.name.last
    return None
