"""Forms cotwin reads in .rst/.rct files that RoboTool's grammar refuses, each a located warning saying how to
write it so that both read it (a model written for cotwin should load in RoboTool; models that run keep running).

RoboChart.xtext (inherited by RoboSim.xtext) has, tightest first: Atomic, CallExp = Atomic ('(' args ')')?,
ArrayExp = CallExp ('[' args ']')?, Selection = ArrayExp ('.' member)*, Neg, CatExp, MultDivMod, PlusMinus,
TypedExpression, IfExpression (between TypedExpression and LetExpression), ...; RoboSim's OutputCommunication
`'$' event ('!'|'.') value=CallExp`; and the type keywords `'Set('` and `'Seq('` are single tokens. Parentheses
(ParExp, an Atomic) make any of these an Atomic, so each fix is a pair of parentheses.
"""

from __future__ import annotations

from ..diagnostics import Diagnostics, Location
from . import syntax as s

#: binary operators of RoboChart's PlusMinus, MultDivMod and CatExp levels (whose operands are no IfExpression)
ARITHMETIC = frozenset(("+", "-", "*", "/", "%", "cat"))

#: values RoboTool's CallExp cannot be without parentheses (each is a level looser than CallExp)
_LOOSER_THAN_CALL = (s.Binary, s.Unary, s.FieldAccess, s.IndexAccess, s.IfExpr, s.LetExpr, s.Quantified, s.TypeTest)


class RoboToolForms:
    """Warnings at forms RoboTool refuses, for one file. The parse tree keeps no parentheses, so the builder
    reports each parenthesised expression here (`parenthesised`) before its enclosing form is checked."""

    def __init__(self, diag: Diagnostics, text: str, active: bool):
        self.diag = diag
        self.text = text
        self.active = active  # .rst and .rct files: p-models follow physmod's own grammar
        self._parenthesised: dict[int, s.Expr] = {}  # by id; the value keeps the node (and so its id) alive

    def parenthesised(self, e: s.Expr) -> s.Expr:
        """`(e)`: an Atomic (RoboChart's ParExp) wherever it is written."""
        self._parenthesised[id(e)] = e
        return e

    def _bare(self, e, kinds) -> bool:
        return self.active and isinstance(e, kinds) and id(e) not in self._parenthesised

    def if_operand(self, e: s.Expr, of: str) -> None:
        """An `if ... end` written as an operand of arithmetic, of `-`, of a selection, a call or a cast."""
        if self._bare(e, s.IfExpr):
            self.diag.warning(e.loc, f"RoboTool refuses 'if ... end' as an operand of {of} (RoboChart's IfExpression "
                                     "is an operand of a comparison or of a logical operator, looser than arithmetic): "
                                     "write it in parentheses, '(if ... end)', so that both read it")

    def indexed(self, base: s.Expr, loc: Location) -> None:
        """`a.b[i]` or `a[i][j]`: RoboChart's ArrayExp indexes a CallExp once, before any `.field`."""
        if self._bare(base, s.FieldAccess):
            self.diag.warning(loc, "RoboTool refuses an index after a field ('a.b[i]': RoboChart's ArrayExp indexes a "
                                   "name, a call or a parenthesised expression, before any '.field'): write '(a.b)[i]' "
                                   "so that both read it")
        elif self._bare(base, s.IndexAccess):
            self.diag.warning(loc, "RoboTool refuses an index of an index ('a[i][j]': RoboChart's ArrayExp indexes "
                                   "once): write 'a[i, j]' or '(a[i])[j]' so that both read it")
        else:
            self.if_operand(base, "an index")

    def called(self, function: s.Expr, loc: Location) -> None:
        """`f(x)(y)`, `a[i](x)`, `a.f(x)`: RoboChart's CallExp calls an Atomic (a name or a parenthesised one)."""
        if self._bare(function, (s.Call, s.IndexAccess, s.FieldAccess)):
            written = {s.Call: "f(x)(y)", s.IndexAccess: "a[i](x)", s.FieldAccess: "a.f(x)"}[type(function)]
            fixed = {s.Call: "(f(x))(y)", s.IndexAccess: "(a[i])(x)", s.FieldAccess: "(a.f)(x)"}[type(function)]
            self.diag.warning(loc, f"RoboTool refuses a call of a call, an index or a field ('{written}': RoboChart's "
                                   f"CallExp calls a name or a parenthesised expression): write '{fixed}' so that both "
                                   "read it")
        else:
            self.if_operand(function, "a call")

    def sent(self, event: str, mark: str, value: s.Expr | None) -> None:
        """`$e!v` (RoboSim's OutputCommunication) or `e!v` (RoboChart's Communication): v is a CallExp there."""
        if value is None or not self._bare(value, _LOOSER_THAN_CALL):
            return
        if isinstance(value, s.Unary) and value.op in ("transpose", "inverse"):
            return  # RoboChart's VectorOrMatrixExp, an Atomic
        self.diag.warning(_start(value), f"RoboTool refuses this value after '{event}{mark}' (the value of an output is a "
                                     "name, a literal, a call or a parenthesised expression: RoboChart's CallExp): "
                                     f"write '{event}{mark}(...)' so that both read it")

    def collection_type(self, kind: str, start: int | None, loc: Location) -> None:
        """`Set (T)`: RoboChart's keywords are `Set(` and `Seq(`, one token each, so no space is read in them."""
        if not self.active or start is None or self.text.startswith(kind + "(", start):
            return
        self.diag.warning(loc, f"RoboTool refuses '{kind}' apart from its '(' (RoboChart's type keyword is '{kind}(', "
                               f"one token): write '{kind}(T)' so that both read it")


def _start(e: s.Expr) -> Location:
    """Where an expression begins (a field access is located at its field's name)."""
    while isinstance(e, s.FieldAccess):
        e = e.base
    return e.loc
