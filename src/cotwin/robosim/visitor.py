"""The one way to walk an expression tree: a visitor that picks its handler by the node's class.

A subclass defines `visit_<NodeClass>` methods (`visit_Binary`, `visit_Name`, ...); `visit(node)`
finds the handler through a per-class table built once, so that adding a construct means adding one
method per target, and a target that lacks it reports the construct as unsupported.
"""

from __future__ import annotations

from typing import Any, Callable

from . import syntax as s

#: every expression node class
EXPR_CLASSES = tuple(getattr(s.Expr, "__args__", ()))


class ExprVisitor:
    _tables: dict[type, dict[type, Callable]] = {}

    @classmethod
    def _table(cls) -> dict[type, Callable]:
        table = ExprVisitor._tables.get(cls)
        if table is None:
            table = {}
            for node_class in EXPR_CLASSES:
                handler = getattr(cls, "visit_" + node_class.__name__, None)
                table[node_class] = handler if handler is not None else cls.unsupported
            ExprVisitor._tables[cls] = table
        return table

    def visit(self, node) -> Any:
        try:
            handler = self._table()[type(node)]
        except KeyError:
            return self.unsupported(node)
        return handler(self, node)

    def unsupported(self, node) -> Any:
        raise NotImplementedError(f"{type(self).__name__} cannot handle {type(node).__name__}")


def describe(node) -> str:
    """A user's name for an expression construct (for 'not supported' messages)."""
    return _DESCRIPTIONS.get(type(node), type(node).__name__)


_DESCRIPTIONS = {
    s.Quantified: "a quantifier", s.LetExpr: "a let expression", s.SetComprehension: "a set comprehension",
    s.MatrixExpr: "a matrix", s.SetExpr: "a set", s.SeqExpr: "a sequence", s.RecordExpr: "a record literal",
    s.RangeExpr: "an interval", s.TypeTest: "a type test", s.SinceEntryExpr: "sinceEntry", s.SinceExpr: "since",
    s.CycleExpr: "cycle", s.SetRangeExpr: "a set range", s.Call: "a function call", s.TupleExpr: "a tuple",
    s.VectorExpr: "a vector", s.IndexAccess: "indexing", s.FieldAccess: "a field selection",
    s.EventTest: "an event test", s.Name: "a name", s.Literal: "a literal",
}
