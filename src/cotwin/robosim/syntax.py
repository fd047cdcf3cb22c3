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
    """`$e` (did e arrive in this cycle?) or `$e?x` (and bind its value to x when taken)."""

    event: QName
    bind: str | None
    loc: Location


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
    kind: str  # forall | exists | lambda
    binders: tuple[tuple[str, TypeRef], ...]
    body: "Expr"
    loc: Location


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
    clock: str
    loc: Location


Expr = Union[
    Literal, Name, EventTest, Unary, Binary, FieldAccess, IndexAccess, Call, IfExpr, LetExpr,
    Quantified, TupleExpr, VectorExpr, CycleExpr, SinceExpr,
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


Stmt = Union[Sequence, Exec, Skip, Send, PlatformCall, CallStmt, Assign, IfStmt, ClockReset]


def root_name(target: Expr) -> Name | None:
    """The variable an assignment target `x.f[i]` writes to."""
    while isinstance(target, (FieldAccess, IndexAccess)):
        target = target.base
    return target if isinstance(target, Name) else None


def sub_expressions(expr: Expr):
    """Direct children of an expression, for generic walks."""
    if isinstance(expr, (Unary,)):
        return (expr.operand,)
    if isinstance(expr, Binary):
        return (expr.left, expr.right)
    if isinstance(expr, FieldAccess):
        return (expr.base,)
    if isinstance(expr, IndexAccess):
        return (expr.base, expr.index)
    if isinstance(expr, Call):
        return (expr.function, *expr.args)
    if isinstance(expr, IfExpr):
        return (expr.condition, expr.then, expr.otherwise)
    if isinstance(expr, LetExpr):
        return (*(value for _, value in expr.bindings), expr.body)
    if isinstance(expr, Quantified):
        return (expr.body,)
    if isinstance(expr, (TupleExpr, VectorExpr)):
        return expr.items
    return ()


def walk(expr: Expr):
    """Every node of an expression tree, pre-order."""
    stack = [expr]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(sub_expressions(node)))
