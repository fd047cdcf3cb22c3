"""Turn a Lark parse tree into the typed model (dataclasses), recording where each element was written.

Block contents arrive as a flat list of item objects; containers sort them by type. Small private
classes tag items that have no model class of their own (a cycleDef, an exec flag, an equation).
"""

from __future__ import annotations

from lark import Token, v_args

from ..diagnostics import Diagnostics, Location
from . import syntax as s
from .declarations import (
    ClockDecl, EnumDecl, EnumLiteral, EventDecl, FunctionDecl, Import, OperationSig, Param,
    PrimitiveDecl, RecordDecl, SourceFile, VarDecl,
)
from .dmodel_elements import (
    Communication, Connection, Controller, Final, ForeignComponent, Initial, Interface, InterfaceUse, Junction,
    MachineRef, Module,
    OperationDef, OperationRef, PlatformRef, ProbabilisticJunction, RoboticPlatform, State, StateMachine, Transition,
)
from .build_items import _Args, _Group, _Params, _Tagged, _flatten, _ident, _of, _string, _tagged
from .builder_pmodel import PModelBuilder
from .robotool_forms import ARITHMETIC, RoboToolForms


_NODES = (State, Initial, Junction, Final, ProbabilisticJunction)
_ORDERINGS = frozenset(("<", "<=", ">", ">="))


@v_args(meta=True, inline=True)
class Builder(PModelBuilder):
    def __init__(self, path: str, notation: str, diagnostics: Diagnostics, text: str = ""):
        super().__init__()
        self.path = path
        self.notation = notation
        self.diag = diagnostics
        self.text = text
        #: warnings at forms RoboTool's grammar refuses (d-models and RoboChart files: see robotool_forms)
        self.forms = RoboToolForms(diagnostics, text, notation in ("rst", "rct"))

    # ---- helpers ----
    def _loc(self, meta) -> Location:
        if getattr(meta, "empty", True):
            return Location(self.path, 1, 1)
        return Location(self.path, meta.line, meta.column)

    def _tok_loc(self, token: Token) -> Location:
        return Location(self.path, token.line or 1, token.column or 1)

    def _single(self, items: list[_Tagged], what: str, where: str):
        """The one item of a kind allowed once in a block (later ones are reported)."""
        for extra in items[1:]:
            self.diag.error(extra.loc, f"{what} given more than once in {where}")
        return items[0].value if items else None

    # ---- names, imports, types ----
    def qn(self, meta, *ids):
        return s.QName(tuple(_ident(i) for i in ids), self._tok_loc(ids[0]))

    def import_decl(self, meta, name, wildcard=None):
        return Import(name, wildcard is not None, self._loc(meta))

    def named_type(self, meta, name):
        return s.NamedType(name, name.loc)

    def vector_type(self, meta, element, size):
        return s.VectorType(element, size, self._loc(meta))

    def matrix_type(self, meta, element, rows, columns):
        return s.MatrixType(element, rows, columns, self._loc(meta))

    def set_type(self, meta, element):
        self.forms.collection_type("Set", getattr(meta, "start_pos", None), self._loc(meta))
        return s.CollectionType("Set", element, self._loc(meta))

    def seq_type(self, meta, element):
        self.forms.collection_type("Seq", getattr(meta, "start_pos", None), self._loc(meta))
        return s.CollectionType("Seq", element, self._loc(meta))

    def product_type(self, meta, *items):
        return s.ProductType(tuple(i for i in items if not isinstance(i, Token)), self._loc(meta))

    def function_type(self, meta, argument, result):
        return s.FunctionType(argument, result, self._loc(meta))

    def relation_type(self, meta, domain, range_):
        """`A <-> B` is read as Set(A * B), as in Z."""
        loc = self._loc(meta)
        return s.CollectionType("Set", s.ProductType((domain, range_), loc), loc)

    def any_type(self, meta, name):
        """`?X`: a type parameter of a generic (toolkit) function."""
        loc = self._tok_loc(name)
        return s.NamedType(s.QName(("?" + _ident(name),), loc), loc)

    def diagram(self, meta, name):
        return _Tagged("diagram", _ident(name), self._loc(meta))

    # ---- declarations ----
    def var_kind(self, meta, token):
        return str(token)

    quant_kind = var_kind

    def var_item(self, meta, name, type_, init=None):
        return (_ident(name), type_, init, self._tok_loc(name))

    def var_list(self, meta, kind, *items):
        return _Group(VarDecl(n, t, i, kind, loc) for n, t, i, loc in items)


    def param(self, meta, name, type_):
        return Param(_ident(name), type_, self._tok_loc(name))

    field = param

    def params(self, meta, *items):
        return _Params(items)

    def primitive_type(self, meta, name):
        return PrimitiveDecl(_ident(name), self._tok_loc(name))

    def record_type(self, meta, name, *fields):
        return RecordDecl(_ident(name), tuple(fields), self._tok_loc(name))

    def enum_literal(self, meta, name, *types):
        return EnumLiteral(_ident(name), tuple(types), self._tok_loc(name))

    def enum_type(self, meta, name, *literals):
        return EnumDecl(_ident(name), tuple(literals), self._tok_loc(name))

    def precondition(self, meta, expr):
        return _Tagged("pre", expr, self._loc(meta))

    def postcondition(self, meta, expr):
        return _Tagged("post", expr, self._loc(meta))

    def function(self, meta, name, *rest):
        params = next((r for r in rest if isinstance(r, _Params)), _Params())
        others = [r for r in rest if not isinstance(r, (_Params, _Tagged))]
        return FunctionDecl(
            _ident(name), tuple(params), others[0],
            tuple(t.value for t in _tagged(rest, "pre")), tuple(t.value for t in _tagged(rest, "post")),
            self._tok_loc(name),
        )

    # ---- expressions ----
    def binary(self, meta, left, op, right):
        """`^` is RoboChart's concatenation in .rst/.rct files and a power in p-models (RoboTool's physmod)."""
        text = "cat" if op.type == "CAT" or (op.type == "CARET" and self.notation != "pm") else str(op)
        if text in ARITHMETIC:
            self.forms.if_operand(left, f"'{op}'")
            self.forms.if_operand(right, f"'{op}'")
        return s.Binary(text, left, right, self._loc(meta))

    def compare_op(self, meta, token):
        return str(token)

    def comparison_chain(self, meta, first, *rest):
        """`a < b <= c` reads as `a < b /\\ b <= c` (Z's chained relations: RoboChart's left-nested reading
        would compare a boolean with a number); a chain with `==`, `!=` or `in` nests to the left as
        RoboChart.xtext's Comp does (`b1 == b2 == b3` is `(b1 == b2) == b3`, well typed there)."""
        pairs = list(zip(rest[0::2], rest[1::2]))
        if any(op not in _ORDERINGS for op, _ in pairs):
            result = first
            for op, right in pairs:
                result = s.Binary(op, result, right, first.loc)
            return result
        result = None
        left = first
        for op, right in pairs:
            comparison = s.Binary(op, left, right, left.loc)
            result = comparison if result is None else s.Binary("/\\", result, comparison, result.loc)
            left = right
        return result

    def as_expr(self, meta, expr, type_):
        self.forms.if_operand(expr, "'as'")
        return s.TypeTest(expr, type_, "as", self._loc(meta))

    def is_expr(self, meta, expr, type_):
        self.forms.if_operand(expr, "'is'")
        return s.TypeTest(expr, type_, "is", self._loc(meta))

    def dollar_expr(self, meta, name, suffix=None):
        if suffix is None:
            return s.EventTest(name, None, self._loc(meta))
        kind, value, extra = suffix
        if kind == "bind":
            return s.EventTest(name, value.last, self._loc(meta), predicate=extra)
        return s.EventTest(name, None, self._loc(meta), value=value)

    def dollar_bind(self, meta, name, predicate=None):
        self.forms.if_operand(predicate, "a '$e?x:' predicate (a CallExp in RoboSim's SimRefExp)")
        return ("bind", name, predicate)

    def dollar_value(self, meta, value):
        self.forms.if_operand(value, "'$e.' (a CallExp in RoboSim's SimRefExp)")
        return ("value", value, None)

    def such_that(self, meta, expr):
        return _Tagged("such", expr, self._loc(meta))

    def record_expr(self, meta, name, fields):
        return s.RecordExpr(name, tuple(fields), self._loc(meta))

    def field_defs(self, meta, *items):
        return _Args(items)

    def field_def(self, meta, name, value):
        return (_ident(name), value, self._tok_loc(name))

    def matrix_expr(self, meta, *rows):
        if len(rows) == 1:
            return s.VectorExpr(tuple(rows[0]), self._loc(meta))
        return s.MatrixExpr(tuple(tuple(r) for r in rows), self._loc(meta))

    def set_expr(self, meta, args=()):
        return s.SetExpr(tuple(args), self._loc(meta))

    def set_range_expr(self, meta, start, end):
        return s.SetRangeExpr(start, end, self._loc(meta))

    def set_comprehension(self, meta, *items):
        binders = tuple(i for i in items if isinstance(i, tuple) and not isinstance(i, _Args))
        such = next((i.value for i in items if isinstance(i, _Tagged)), None)
        body = next((i for i in items if not isinstance(i, (tuple, _Tagged))), None)
        return s.SetComprehension(binders, such, body, self._loc(meta))

    def seq_expr(self, meta, *items):
        values = tuple(i for i in items if not isinstance(i, Token))
        for value in values:
            self.forms.if_operand(value, "a sequence '<...>'")
        return s.SeqExpr(values, self._loc(meta))

    def closed_range(self, meta, low, high, close):
        return s.RangeExpr(low, high, True, str(close) == "]", self._loc(meta))

    def open_range(self, meta, low, high, close):
        return s.RangeExpr(low, high, False, str(close) == "]", self._loc(meta))

    def not_expr(self, meta, operand):
        return s.Unary("not", operand, self._loc(meta))

    def neg_expr(self, meta, _minus, operand):
        self.forms.if_operand(operand, "'-'")
        return s.Unary("-", operand, self._loc(meta))

    def field_expr(self, meta, base, name):
        self.forms.if_operand(base, "a selection '.'")
        return s.FieldAccess(base, _ident(name), self._tok_loc(name))

    def index_expr(self, meta, base, indices):
        """`m[i, j]` is `m[i][j]`."""
        self.forms.indexed(base, self._loc(meta))
        for index in indices:
            base = s.IndexAccess(base, index, self._loc(meta))
        return base

    def call_expr(self, meta, function, args=()):
        """Calls, and RoboChart's built-in forms written like calls: sinceEntry(S), transpose(m), inverse(m)."""
        args = tuple(args)
        self.forms.called(function, self._loc(meta))
        if isinstance(function, s.Name) and len(function.name.parts) == 1 and len(args) == 1:
            name = function.name.last
            if name == "sinceEntry" and isinstance(args[0], s.Name):
                return s.SinceEntryExpr(args[0].name, self._loc(meta))
            if name in ("transpose", "inverse"):
                return s.Unary(name, args[0], self._loc(meta))
        return s.Call(function, args, self._loc(meta))

    def int_lit(self, meta, token):
        return s.Literal(int(token), self._tok_loc(token))

    def real_lit(self, meta, token):
        return s.Literal(float(token), self._tok_loc(token))

    def string_lit(self, meta, token):
        return s.Literal(_string(token), self._tok_loc(token))

    def bool_lit(self, meta, token):
        return s.Literal(str(token) == "true", self._tok_loc(token))

    def name_expr(self, meta, name):
        return s.Name(name, name.loc)

    def event_expr(self, meta, name):
        return s.EventTest(name, None, self._loc(meta))

    def event_bind_expr(self, meta, name, bind):
        return s.EventTest(name, _ident(bind), self._loc(meta))

    def cycle_expr(self, meta):
        return s.CycleExpr(self._loc(meta))

    def since_expr(self, meta, clock):
        return s.SinceExpr(_ident(clock), self._loc(meta))

    def tuple_expr(self, meta, args=()):
        return s.TupleExpr(tuple(args), self._loc(meta))

    def vector_expr(self, meta, args):
        return s.VectorExpr(tuple(args), self._loc(meta))

    def if_expr(self, meta, condition, then, otherwise):
        return s.IfExpr(condition, then, otherwise, self._loc(meta))

    def paren_expr(self, meta, expr):
        """`(e)`: e itself (its parentheses recorded: RoboTool reads a parenthesised expression as an Atomic)."""
        return self.forms.parenthesised(expr)

    def args(self, meta, *items):
        return _Args(items)

    def binder(self, meta, name, type_):
        return (_ident(name), type_)

    def quantified(self, meta, kind, *rest):
        binders = tuple(r for r in rest[:-1] if not isinstance(r, _Tagged))
        such = next((r.value for r in rest[:-1] if isinstance(r, _Tagged)), None)
        return s.Quantified(kind, binders, rest[-1], self._loc(meta), such)

    def definite_description(self, meta, *rest):
        """`the x: T | p @ e` (RoboChart's DefiniteDescription, a level of its own: see common.lark)."""
        return self.quantified(meta, "the", *rest)

    def let_binding(self, meta, name, _eq, value):
        return (_ident(name), value)

    def let_expr(self, meta, *rest):
        return s.LetExpr(tuple(rest[:-1]), rest[-1], self._loc(meta))

    # ---- statements ----
    def stmt(self, meta, *basics):
        if len(basics) == 1:
            return basics[0]
        return s.Sequence(tuple(basics), self._loc(meta))

    def deadline_stmt(self, meta, stmt, deadline):
        return s.Timed(stmt, deadline, self._loc(meta))

    def wait_stmt(self, meta, duration):
        return s.Wait(duration, self._loc(meta))

    def receive_stmt(self, meta, event, target):
        return s.Receive(event, target, self._loc(meta))

    def exec_stmt(self, meta):
        return s.Exec(self._loc(meta))

    def skip_stmt(self, meta):
        return s.Skip(self._loc(meta))

    def send_stmt(self, meta, event, value=None):
        self.forms.sent(self._written_event(meta, event), "!", value)
        return s.Send(event, value, self._loc(meta))

    def _written_event(self, meta, event) -> str:
        """The event of a send as written, `$e` (RoboSim's OutputCommunication) or `e` (RoboChart's)."""
        start = getattr(meta, "start_pos", None)
        head = self.text[start:start + 80].lstrip() if start is not None else ""
        head = head.removeprefix("send").lstrip() if head.startswith("send") and not head[4:5].isalnum() else head
        return "$" * head.startswith("$") + str(event)

    def platform_call_stmt(self, meta, operation, args=()):
        return s.PlatformCall(operation, tuple(args), self._loc(meta))

    def call_stmt(self, meta, operation, args=()):
        return s.CallStmt(operation, tuple(args), self._loc(meta))

    def assign_stmt(self, meta, target, value):
        return s.Assign(target, value, self._loc(meta))

    def if_stmt(self, meta, condition, then, otherwise=None):
        return s.IfStmt(condition, then, otherwise, self._loc(meta))

    def clock_reset_stmt(self, meta, clock):
        return s.ClockReset(_ident(clock), self._loc(meta))

    def field_suffix(self, meta, name):
        return ("field", _ident(name), self._tok_loc(name))

    def index_suffix(self, meta, indices):
        return ("index", tuple(indices), self._loc(meta))

    def lvalue(self, meta, *items):
        """A variable with field and index selections; `$v` names the same variable as `v`."""
        name = items[1] if items[0].type == "DOLLAR" else items[0]
        suffixes = items[2:] if items[0].type == "DOLLAR" else items[1:]
        loc = self._tok_loc(name)
        return self._selected(s.Name(s.QName((_ident(name),), loc), loc), suffixes)

    @staticmethod
    def _selected(target: s.Expr, suffixes) -> s.Expr:
        """`target` with its field and index selections applied, in order."""
        for kind, value, where in suffixes:
            if kind == "field":
                target = s.FieldAccess(target, value, where)
            elif kind == "qualified":
                target = s.FieldAccess(target, "::".join(value), where)
            else:
                for index in value:
                    target = s.IndexAccess(target, index, where)
        return target

    def dot_value_send(self, meta, *items):
        """`$e.3`, `e.(x + 1)`: RoboSim's output `$e.v` (RoboChart's synchronisation `e.v`), read as `$e!v`."""
        event = next(i for i in items if isinstance(i, Token) and i.type == "ID")
        self.forms.sent(self._written_event(meta, _ident(event)), ".", items[-1])
        return s.Send(s.QName((_ident(event),), self._tok_loc(event)), items[-1], self._loc(meta))

    def dot_call_send(self, meta, *items):
        """`$e.f(x)`: RoboSim's output `$e.v` whose value is a call (a CallExp), read as `$e!f(x)`."""
        event = next(i for i in items if isinstance(i, Token) and i.type == "ID")
        function = next(i for i in items if isinstance(i, s.QName))
        args = next((i for i in items if isinstance(i, _Args)), ())
        call = self.call_expr(meta, s.Name(function, function.loc), args)
        return s.Send(s.QName((_ident(event),), self._tok_loc(event)), call, self._loc(meta))

    def dot_send(self, meta, *items):
        """`$e.x.f[1]`, `e.E::lit`: RoboSim's output `$e.v` (RoboChart's `e.v`) with a value written as a name."""
        event = next(i for i in items if isinstance(i, Token) and i.type == "ID")
        suffixes = [i for i in items if not isinstance(i, Token)]
        kind, first, where = suffixes[0]
        if kind == "index":
            name = "$" * any(isinstance(i, Token) and i.type == "DOLLAR" for i in items) + _ident(event)
            self.diag.error(self._loc(meta), f"'{name}[...]' is not a statement: assign it ('{name}[i] = e')")
            return s.Skip(self._loc(meta))
        parts = first if kind == "qualified" else (first,)
        value = self._selected(s.Name(s.QName(parts, where), where), suffixes[1:])
        self.forms.sent(self._written_event(meta, _ident(event)), ".", value)
        return s.Send(s.QName((_ident(event),), self._tok_loc(event)), value, self._loc(meta))

    def qualified_suffix(self, meta, *names):
        return ("qualified", tuple(_ident(n) for n in names), self._tok_loc(names[0]))

    # ---- d-model ----
    def rst_file(self, meta, *items):
        return self._source(items)

    rct_file = rst_file

    def _source(self, items) -> SourceFile:
        items = _flatten(i for i in items if i is not None)
        package = next((i.value for i in _tagged(items, "package")), None)
        return SourceFile(
            self.path, self.notation, package, list(_of(items, Import)),
            [i for i in items if not isinstance(i, (Import, _Tagged))],
        )

    def package(self, meta, name):
        return _Tagged("package", name, self._loc(meta))

    def op_sig(self, meta, name, *rest):
        params = next((r for r in rest if isinstance(r, _Params)), ())
        terminates = any(isinstance(r, _Tagged) and r.tag == "terminates" for r in rest)
        return OperationSig(_ident(name), tuple(params), self._tok_loc(name), terminates)

    def terminates_flag(self, meta):
        return _Tagged("terminates", True, self._loc(meta))

    terminates = terminates_flag

    def precondition_item(self, meta, expr):
        return _Tagged("pre", expr, self._loc(meta))

    def postcondition_item(self, meta, expr):
        return _Tagged("post", expr, self._loc(meta))

    def event(self, meta, *items):
        broadcast = isinstance(items[0], Token) and items[0].type == "BROADCAST"
        name, *rest = items[1:] if broadcast else items
        return EventDecl(_ident(name), rest[0] if rest else None, self._tok_loc(name), broadcast)

    def clock(self, meta, name):
        return ClockDecl(_ident(name), self._tok_loc(name))

    def uses(self, meta, name):
        return InterfaceUse("uses", name, self._loc(meta))

    def provides(self, meta, name):
        return InterfaceUse("provides", name, self._loc(meta))

    def requires(self, meta, name):
        return InterfaceUse("requires", name, self._loc(meta))

    def cycle_def(self, meta, expr):
        return _Tagged("cycleDef", expr, self._loc(meta))

    def interface(self, meta, name, *items):
        items = _flatten(items)
        return Interface(_ident(name), _of(items, OperationSig), _of(items, EventDecl), _of(items, VarDecl),
                         _of(items, ClockDecl), self._tok_loc(name))

    def platform(self, meta, name, *items):
        items = _flatten(items)
        return RoboticPlatform(_ident(name), _of(items, InterfaceUse), _of(items, VarDecl),
                               _of(items, OperationSig), _of(items, EventDecl), self._tok_loc(name),
                               _of(items, ClockDecl))

    def rref(self, meta, name, target):
        return PlatformRef(_ident(name), target, self._tok_loc(name))

    def cref(self, meta, name, target):
        return _Tagged("cref", MachineRef(_ident(name), target, self._tok_loc(name)), self._loc(meta))

    def opref(self, meta, name, target):
        return OperationRef(_ident(name), target, self._tok_loc(name))

    def module(self, meta, name, *items):
        where = f"module {name}"
        platforms = [*_of(items, RoboticPlatform), *_of(items, PlatformRef)]
        for extra in platforms[1:]:
            self.diag.error(extra.loc, f"more than one robotic platform in {where}")
        platform = platforms[0] if platforms else None
        for foreign in _of(items, ForeignComponent):
            self.diag.error(foreign.loc, f"{foreign.name} in {where} is a RoboChart {foreign.kind}: RoboTool reads it, "
                                         "and cotwin cannot run it (it has no state machine to simulate)")
        return Module(_ident(name), self._single(_tagged(items, "cycleDef"), "cycleDef", where),
                      platform if isinstance(platform, RoboticPlatform) else None, _of(items, Controller),
                      tuple(t.value for t in _tagged(items, "cref")), _of(items, Connection), self._tok_loc(name),
                      platform if isinstance(platform, PlatformRef) else None, _of(items, StateMachine),
                      _of(items, MachineRef), _of(_flatten(items), VarDecl))

    def async_flag(self, meta):
        return _Tagged("async", True, self._loc(meta))

    def mult_flag(self, meta):
        return _Tagged("mult", True, self._loc(meta))

    def connection(self, meta, source, source_event, target, target_event, *flags):
        return Connection(_ident(source), _ident(source_event), _ident(target), _ident(target_event),
                          bool(_tagged(flags, "async")), self._loc(meta), bool(_tagged(flags, "mult")))

    def controller(self, meta, name, *items):
        items = _flatten(items)
        machines = _of(items, StateMachine)
        return Controller(
            _ident(name), self._single(_tagged(items, "cycleDef"), "cycleDef", f"controller {name}"),
            _of(items, InterfaceUse), _of(items, VarDecl), _of(items, EventDecl),
            tuple(m for m in machines if isinstance(m, OperationDef)),
            tuple(m for m in machines if not isinstance(m, OperationDef)),
            _of(items, MachineRef), _of(items, Connection), self._tok_loc(name),
            _of(items, OperationRef), _of(items, ClockDecl),
        )

    def general_controller(self, meta, name, *_items):
        return ForeignComponent(_ident(name), "general controller", self._tok_loc(name))

    def ann_controller(self, meta, name, *_items):
        return ForeignComponent(_ident(name), "ANN controller", self._tok_loc(name))

    def general_operation(self, meta, name, *_items):
        return ForeignComponent(_ident(name), "general operation", self._tok_loc(name))

    def ann_operation(self, meta, name, *_items):
        return ForeignComponent(_ident(name), "ANN operation", self._tok_loc(name))

    def input_context(self, meta, *items):
        return _Tagged("input", tuple(items), self._loc(meta))

    def output_context(self, meta, *items):
        return _Tagged("output", tuple(items), self._loc(meta))

    def _machine(self, cls, name, items, params=(), **extra):
        items = _flatten(items)
        where = f"state machine {name}"
        inputs = tuple(x for t in _tagged(items, "input") for x in t.value)
        outputs = tuple(x for t in _tagged(items, "output") for x in t.value)
        nodes = tuple(i for i in items if isinstance(i, _NODES))
        return cls(
            _ident(name), self._single(_tagged(items, "cycleDef"), "cycleDef", where),
            _of(items, InterfaceUse), inputs, outputs, _of(items, VarDecl), _of(items, ClockDecl),
            nodes, _of(items, Transition), self._tok_loc(name), tuple(params), _of(items, EventDecl), **extra,
        )

    def stm(self, meta, name, *items):
        return self._machine(StateMachine, name, items)

    def operation_def(self, meta, name, *items):
        params = next((i for i in items if isinstance(i, _Params)), ())
        rest = [i for i in items if not isinstance(i, _Params)]
        return self._machine(
            OperationDef, name, rest, params, terminates=bool(_tagged(rest, "terminates")),
            preconditions=tuple(t.value for t in _tagged(rest, "pre")),
            postconditions=tuple(t.value for t in _tagged(rest, "post")),
        )

    def state(self, meta, name, *items):
        where = f"state {name}"
        return State(
            _ident(name), tuple(i for i in items if isinstance(i, _NODES)),
            _of(items, Transition), self._single(_tagged(items, "entry"), "entry action", where),
            self._single(_tagged(items, "during"), "during action", where),
            self._single(_tagged(items, "exit"), "exit action", where), self._tok_loc(name),
        )

    def entry_action(self, meta, stmt):
        return _Tagged("entry", stmt, self._loc(meta))

    def during_action(self, meta, stmt):
        return _Tagged("during", stmt, self._loc(meta))

    def exit_action(self, meta, stmt):
        return _Tagged("exit", stmt, self._loc(meta))

    def initial(self, meta, name):
        return Initial(_ident(name), self._tok_loc(name))

    def junction(self, meta, name):
        return Junction(_ident(name), self._tok_loc(name))

    def final(self, meta, name):
        return Final(_ident(name), self._tok_loc(name))

    def probabilistic(self, meta, name):
        return ProbabilisticJunction(_ident(name), self._tok_loc(name))

    def exec_flag(self, meta):
        return _Tagged("exec", True, self._loc(meta))

    def clock_reset(self, meta, name):
        return _Tagged("reset", _ident(name), self._loc(meta))

    def condition(self, meta, expr):
        return _Tagged("condition", expr, self._loc(meta))

    def else_condition(self, meta):
        return _Tagged("else", None, self._loc(meta))

    def action(self, meta, stmt):
        return _Tagged("action", stmt, self._loc(meta))

    def trigger(self, meta, communication):
        return _Tagged("trigger", communication, self._loc(meta))

    def probability(self, meta, expr):
        return _Tagged("probability", expr, self._loc(meta))

    def deadline(self, meta, expr):
        return _Tagged("deadline", expr, self._loc(meta))

    def communication(self, meta, event, *rest):
        guard = next((r.value for r in rest if isinstance(r, _Tagged) and r.tag == "guard"), None)
        kind, value = next(((r.tag, r.value) for r in rest if isinstance(r, _Tagged) and r.tag != "guard"),
                           ("simple", None))
        return Communication(_ident(event), kind, value, guard, self._tok_loc(event))

    def trigger_guard(self, meta, *items):
        """`[| p |]`; `[| s = from | p |]` binds the sender s, which cotwin, not running RoboChart triggers, drops."""
        expr = next((i for i in items if not isinstance(i, Token)), None)
        return _Tagged("guard", expr, self._loc(meta))

    def comm_input(self, meta, name):
        return _Tagged("input", name, self._loc(meta))

    def comm_output(self, meta, value):
        return _Tagged("output", value, self._loc(meta))

    def comm_sync(self, meta, value):
        return _Tagged("sync", value, self._loc(meta))

    def transition(self, meta, name, source, target, *items):
        condition = _tagged(items, "condition")
        actions = _tagged(items, "action")
        trigger = _tagged(items, "trigger")
        probability = _tagged(items, "probability")
        deadline = _tagged(items, "deadline")
        return Transition(
            _ident(name), _ident(source), _ident(target), bool(_tagged(items, "exec")),
            tuple(t.value for t in _tagged(items, "reset")), condition[0].value if condition else None,
            bool(_tagged(items, "else")), actions[0].value if actions else None, self._tok_loc(name),
            self._tok_loc(source), self._tok_loc(target), trigger[0].value if trigger else None,
            probability[0].value if probability else None, deadline[0].value if deadline else None,
        )

    def sref(self, meta, name, target, *items):
        if self.notation in ("rst", "rct"):
            return MachineRef(_ident(name), target, self._tok_loc(name))
        return self._pm_device_ref("sref", name, target, items)
