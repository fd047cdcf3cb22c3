"""Generate readable, deterministic C99 for a module: `model_init()` and `model_step()` (one cycle).

The code follows the reference interpreter step for step: a block `<B>_S_n` settles node n of body B
(the machine, or an operation it calls: chooses a transition, outermost ancestor first, source
order), a block `<B>_T_e` completes edge e (exit to the common container through the body's EXIT
block, action, entries down to the target), every `exec` stores a resume point and returns, and a
call of an operation stores where to return and jumps to the operation's start. No threads, no I/O:
the FMI wrapper (fmu.py) calls these functions.

The generated C never traps: integer arithmetic is checked (division and remainder by zero, results
outside int64), indices are checked against their bounds, sets and sequences against their
capacity. A failure makes the step return 1 with `M->message` saying where, e.g.
`arm.rst:57:9: division by zero in state Requested (cycle 4)`, the same text the interpreter reports but
for the file, which is named relative to the project (so that the code does not depend on where it is).
Expressions whose evaluation can fail are evaluated into temporaries in the interpreter's order
(left to right, conditional parts only when reached), so that the first failure is the same one.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..diagnostics import CotwinError
from ..robosim import functions as fns
from ..robosim import syntax as s
from ..robosim.declarations import EnumDecl
from ..robosim.dmodel_elements import Final, Initial, Junction, State
from ..robosim.operators import BINARY, C_MATH, SHORT_CIRCUIT, UNARY_C
from ..robosim.types import (
    BOOL, INT, NAT, REAL, UNKNOWN, CollectionTy, EnumTy, MatrixTy, RecordTy, TupleTy, Ty, TypeResolver, VectorTy,
    join,
)
from ..robosim.values import CAPACITY, FrozenRecord, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue
from ..robosim.visitor import ExprVisitor, describe
from . import cnames
from .cdata import CTypes, is_intlike, is_scalar
from .cnames import c_comment, c_string, ident
from .interpreter import MAX_STEPS, choice_groups, lca_index, shared_port_message
from .program import (
    Body, MachineInstance, OperationInstance, Program, beyond_int32_message, node_description, state_index,
)


def c_real(value: float) -> str:
    text = repr(float(value))
    if text in ("inf", "-inf", "nan"):
        return {"inf": "INFINITY", "-inf": "(-INFINITY)", "nan": "NAN"}[text]
    return text if any(ch in text for ch in ".e") else text + ".0"


def c_literal(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        if value == -(2 ** 63):
            return "INT64_MIN"
        return f"INT64_C({value})"
    if isinstance(value, float):
        return c_real(value)
    raise CotwinError(f"value {value!r} cannot be written in C")


class _Lines:
    def __init__(self, depth: int = 0) -> None:
        self.lines: list[str] = []
        self.depth = depth

    def __call__(self, text: str = "") -> None:
        self.lines.append(("    " * self.depth + text) if text else "")

    def label(self, name: str) -> None:
        self.lines.append(f"{name}:;")

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


class Context:
    """Where code runs: a machine instance, the body (machine or operation) whose names are in scope,
    and names bound by let, quantifiers and inlined function definitions."""

    def __init__(self, gen: "CGenerator", m: MachineInstance, body: Body, frame: int):
        self.gen = gen
        self.m = m
        self.body = body
        self.frame = frame  # -1: the machine's own frame; k: operation frame k
        self.bound: dict[str, tuple[str, Ty]] = {}
        self.in_init = False

    @property
    def f(self) -> str:
        """The C prefix of the body's frame: `s->` or `s->o2.`."""
        return "s->" if self.frame < 0 else f"s->o{self.frame}."

    def name(self, name: str, loc) -> tuple[str, Ty]:
        if name in self.bound:
            return self.bound[name]
        body, m = self.body, self.m
        if self.frame >= 0:
            if any(n == name for n, _, _ in body.variables) or any(n == name for n, _ in body.params):
                return f"s->o{self.frame}.{ident(name)}", body.types[name]
            if name in body.constants:
                return self.gen.value(body.constants[name], body.types[name]), body.types[name]
            holder = body.bindings.get(name, -1)
            if holder >= 0:
                return Context(self.gen, m, m.frames[holder], holder).name(name, loc)
        if any(n == name for n, _, _ in m.variables):
            return f"s->{ident(name)}", m.types[name]
        if name in m.constants:
            return self.gen.value(m.constants[name], m.types[name]), m.types[name]
        if name in m.parameters:
            return f"s->par.{ident(name)}", m.types[name]
        raise CotwinError(f"{loc}: '{name}' has no value in the generated C")

    def clock(self, clock: str) -> str:
        if self.frame >= 0 and clock in self.body.clocks:
            return f"s->o{self.frame}.clk.{ident(clock)}"
        return f"s->clk.{ident(clock)}"


class CExpr(ExprVisitor):
    """Translates one expression to C text, writing the statements it needs first (temporaries of
    failable operations, branches of short-circuit and conditional forms) to `out`."""

    def __init__(self, ctx: Context, out: _Lines):
        self.ctx = ctx
        self.gen = ctx.gen
        self.types = ctx.gen.types
        self.out = out

    # ---- helpers ----
    def ty(self, e) -> Ty:
        ty = self.gen.program.type_of(e)
        if ty is None or ty == UNKNOWN:
            if isinstance(e, s.Name) and len(e.name.parts) == 1:
                return self.ctx.name(e.name.last, e.loc)[1]
            raise CotwinError(f"{e.loc}: the C generator does not know the type of {describe(e)}")
        return ty

    def temp(self, c_type: str, value: str | None = None, fails: bool = False) -> str:
        name = self.gen.fresh()
        self.out(f"{c_type} {name}" + (f" = {value};" if value is not None else ";"))
        if fails:
            self.out(self.gen.bail)
        return name

    def failable(self, c_type: str, value: str) -> str:
        return self.temp(c_type, value, fails=True)

    def at(self, loc) -> int:
        return self.gen.location(loc)

    def emit(self, e: s.Expr, want: Ty | None = None) -> str:
        value = self.visit(e)
        if want is not None:
            return self.types.convert(value, self.ty(e), want)
        return value

    def captured(self, e: s.Expr, want: Ty | None = None) -> tuple[list[str], str]:
        """Translate e into a separate buffer: (its statements, its value)."""
        saved = self.out
        self.out = _Lines(saved.depth + 1)
        try:
            value = self.emit(e, want)
            return self.out.lines, value
        finally:
            self.out = saved

    def unsupported(self, node):
        raise CotwinError(f"{node.loc}: {describe(node)} is not supported by the C generator")

    # ---- atoms ----
    def visit_Literal(self, e: s.Literal) -> str:
        return c_literal(e.value)

    def visit_Name(self, e: s.Name) -> str:
        if len(e.name.parts) > 1:
            decl = self.gen.program.project.lookup("type", s.QName(e.name.parts[:-1]), self.ctx.body.source)
            if not isinstance(decl, EnumDecl) or decl.literal(e.name.last) is None:
                raise CotwinError(f"{e.loc}: unknown name '{e.name}'")
            index = [lit.name for lit in decl.literals].index(e.name.last)
            return f"INT64_C({index}) /* {c_comment(str(e.name))} */"
        return self.ctx.name(e.name.last, e.loc)[0]

    def visit_EventTest(self, e: s.EventTest) -> str:
        name = e.event.last
        if name not in self.ctx.m.inputs:  # `$v`, `$v.f`: the variable's value, its field f
            field = s.dollar_field(e)
            value, ty = self.ctx.name(name, e.loc)
            if field is None:
                return value
            base = self.temp(self.types.c(ty), value) if value.startswith("(") else value
            return f"{base}.{ident(field)}"
        flag = f"in->{ident(name)}.on"
        value = f"in->{ident(name)}.v"
        event_ty = self.ctx.m.inputs[name]
        conditions = []
        if e.value is not None:
            lines, v = self.captured(e.value, event_ty)
            conditions.append((lines, self.types.eq(event_ty, value, v)))
        if e.bind is not None and e.predicate is not None:
            saved = dict(self.ctx.bound)
            self.ctx.bound[e.bind] = (value, event_ty)
            try:
                conditions.append(self.captured(e.predicate))
            finally:
                self.ctx.bound = saved
        if not conditions:
            return flag
        result = self.temp("bool", flag)
        for lines, cond in conditions:
            self.out(f"if ({result}) {{")
            self.out.lines.extend(lines)
            self.out(f"    {result} = {cond};")
            self.out("}")
        return result

    def visit_CycleExpr(self, e: s.CycleExpr) -> str:
        return "M->cycle"

    def visit_SinceExpr(self, e: s.SinceExpr) -> str:
        return self.ctx.clock(e.clock)

    def visit_SinceEntryExpr(self, e: s.SinceEntryExpr) -> str:
        index = state_index(self.ctx.body.graph, e.state)
        counter = f"{self.ctx.f}ent{index}"
        return f"({counter} < 0 ? M->cycle - 1 : {counter})"

    # ---- operators ----
    def visit_Unary(self, e: s.Unary) -> str:
        a = self.emit(e.operand)
        if e.op == "not":
            return f"(!{a})"
        ty = self.ty(e.operand)
        if e.op == "transpose":
            return f"{self.types.transpose(ty)}({a})"
        if e.op == "inverse":
            raise CotwinError(f"{e.loc}: inverse is not supported by the C generator")
        if isinstance(ty, (VectorTy, MatrixTy)):
            return self.failable(self.types.c(ty), f"{self.types.scale(ty, None, 'neg')}(M, {a}, {self.at(e.loc)})")
        if is_intlike(ty):
            return self.failable("int64_t", UNARY_C["-"][1].format(a=a, at=self.at(e.loc)))
        return UNARY_C["-"][0].format(a=a)

    def visit_Binary(self, e: s.Binary) -> str:
        op = e.op
        if op in SHORT_CIRCUIT:
            return self._short_circuit(e)
        if op == "in":
            return self._membership(e)
        left_ty, right_ty = self.ty(e.left), self.ty(e.right)
        if op in ("==", "!="):
            common = join(left_ty, right_ty)
            if common == UNKNOWN:
                common = left_ty
            a, b = self.emit(e.left, common), self.emit(e.right, common)
            test = self.types.eq(common, a, b)
            return test if op == "==" else f"(!{test})"
        a, b = self.emit(e.left), self.emit(e.right)
        if op == "cat":
            seq = self.ty(e)
            a = self.types.convert(a, left_ty, seq)
            b = self.types.convert(b, right_ty, seq)
            return self.failable(self.types.c(seq), f"{self.types.seq_op(seq, 'cat')}(M, {a}, {b}, {self.at(e.loc)})")
        result = self.ty(e)
        shaped = (VectorTy, MatrixTy)
        if isinstance(result, shaped) or isinstance(left_ty, shaped) or isinstance(right_ty, shaped):
            return self._shaped(e, a, b, left_ty, right_ty, result)
        operator = BINARY[op]
        if is_intlike(left_ty) and is_intlike(right_ty) and op in ("+", "-", "*", "/", "%"):
            return self.failable("int64_t", operator.c_int.format(a=a, b=b, at=self.at(e.loc)))
        if op == "%":
            return operator.c.format(a=f"(double){a}", b=f"(double){b}")
        if op == "/":
            return f"((double){a} / (double){b})"
        return operator.c.format(a=a, b=b)

    def _shaped(self, e, a, b, left_ty, right_ty, result) -> str:
        at = self.at(e.loc)
        c = self.types.c(result)
        if e.op in ("+", "-"):
            a = self.types.convert(a, left_ty, result)
            b = self.types.convert(b, right_ty, result)
            return self.failable(c, f"{self.types.elementwise(result, e.op)}(M, {a}, {b}, {at})")
        if e.op == "*" and isinstance(left_ty, MatrixTy) and isinstance(right_ty, (MatrixTy, VectorTy)):
            return self.failable(c, f"{self.types.product(left_ty, right_ty, result)}(M, {a}, {b}, {at})")
        if isinstance(left_ty, (VectorTy, MatrixTy)):
            shaped, scalar, k, shaped_value = left_ty, right_ty, b, a
        else:
            shaped, scalar, k, shaped_value = right_ty, left_ty, a, b
        shaped_value = self.types.convert(shaped_value, shaped, result)
        return self.failable(c, f"{self.types.scale(result, scalar, e.op)}(M, {shaped_value}, {k}, {at})")

    def _short_circuit(self, e: s.Binary) -> str:
        a = self.emit(e.left)
        lines, b = self.captured(e.right)
        if not lines:
            return BINARY[e.op].c.format(a=a, b=b)
        left = self.temp("bool", f"!!({a})")
        # the value when the right side is not reached; and when it is
        result = self.temp("bool", f"!{left}" if e.op == "=>" else left)
        self.out(f"if ({'!' if e.op == chr(92) + '/' else ''}{left}) {{")
        self.out.lines.extend(lines)
        self.out(f"    {result} = !!({b});")
        self.out("}")
        return result

    def _membership(self, e: s.Binary) -> str:
        if isinstance(e.right, s.RangeExpr):
            x = self.emit(e.left)
            r = e.right
            low, high = self.emit(r.low), self.emit(r.high)
            x_ = self.temp(self.types.c(self.ty(e.left)), x)
            low_test = f"{x_} >= {low}" if r.low_closed else f"{x_} > {low}"
            high_test = f"{x_} <= {high}" if r.high_closed else f"{x_} < {high}"
            return f"({low_test} && {high_test})"
        coll = self.ty(e.right)
        x = self.emit(e.left, coll.element)
        c = self.emit(e.right)
        return f"{self.types.set_has(coll)}({c}, {x})"

    # ---- selections ----
    def visit_FieldAccess(self, e: s.FieldAccess) -> str:
        return f"{self._lvalue_base(e.base)}.{ident(e.field)}"

    def _lvalue_base(self, base: s.Expr) -> str:
        value = self.emit(base)
        if isinstance(base, (s.Name, s.FieldAccess, s.IndexAccess)) and not value.startswith("("):
            return value
        return self.temp(self.types.c(self.ty(base)), value)

    def visit_IndexAccess(self, e: s.IndexAccess) -> str:
        base_ty = self.ty(e.base)
        if isinstance(base_ty, TupleTy):
            return f"{self._lvalue_base(e.base)}.i{e.index.value}"
        base = self._lvalue_base(e.base)
        index = self.emit(e.index)
        return f"{base}.v[{self.checked_index(e, index, base, base_ty)}]"

    def checked_index(self, e: s.IndexAccess, index: str, base: str, base_ty: Ty) -> str:
        first = self.gen.program.readings.first_index.get(id(e), 1)
        if isinstance(base_ty, VectorTy):
            size = str(base_ty.size)
        elif isinstance(base_ty, MatrixTy):
            size = str(base_ty.rows)
        else:
            size = f"{base}.n"
        return self.failable("int64_t", f"ck_index(M, {index}, {first}, {size}, {self.at(e.loc)})")

    # ---- calls ----
    def visit_Call(self, e: s.Call) -> str:
        project = self.gen.program.project
        fn = fns.target(project, e, self.ctx.body.source)
        if fn is None:
            raise CotwinError(f"{e.loc}: '{e.function}' cannot be called in the generated C")
        name = fn.name
        impl = fns.builtin(project, fn)
        arg_types = [self.ty(a) for a in e.args]
        if impl is not None:
            args = [self.emit(a) for a in e.args]
            return self._builtin(e, name, args, arg_types)
        definition = fns.definition(fn)
        resolver = TypeResolver(project, project.file_of(fn) or self.ctx.body.source, self.gen.diag)
        result = resolver.resolve(fn.result)
        if definition is None:  # uninterpreted: the next value of the random source
            for a in e.args:
                self.emit(a)
            return self.temp(self.types.c(result), self._random(result))
        params = [(p.name, resolver.resolve(p.type)) for p in fn.params]
        values = []
        for (pname, pty), arg in zip(params, e.args):
            values.append((pname, self.temp(self.types.c(pty), self.emit(arg, pty)), pty))
        saved = self.ctx.bound
        self.ctx.bound = {pname: (tmp, pty) for pname, tmp, pty in values}
        try:
            value = self.emit(definition, result)
        finally:
            self.ctx.bound = saved
        return value

    def _random(self, ty: Ty) -> str:
        if ty == REAL:
            return "rng_real(M)"
        if ty == BOOL:
            return "((rng_next(M) >> 63) != 0)"
        if ty in (INT, NAT):
            return "((int64_t)(rng_next(M) >> 63))"
        if isinstance(ty, EnumTy):
            return f"((int64_t)(rng_next(M) % {len(ty.decl.literals)}u))"
        raise CotwinError(f"no random value of type {ty}")

    def _builtin(self, e: s.Call, name: str, args: list[str], types: list[Ty]) -> str:
        at = self.at(e.loc)
        result = self.ty(e)
        if name == "random":
            return self.temp("double", "rng_real(M)")
        if name in C_MATH:
            reals = [f"(double){a}" for a in args]
            if name in ("floor", "ceil"):
                return self.failable("int64_t", f"ck_{name}(M, {reals[0]}, {at})")
            return f"{C_MATH[name]}({', '.join(reals)})"
        coll = types[0] if types and isinstance(types[0], CollectionTy) else None
        if name == "size":
            return f"((int64_t){self._tmp(args[0], types[0])}.n)"
        if name == "isNonEmpty":
            return f"({self._tmp(args[0], types[0])}.n > 0)"
        if name in ("union", "inter", "diff", "symetric_diff"):
            ty = result
            a = self.types.convert(args[0], types[0], ty)
            b = self.types.convert(args[1], types[1], ty)
            return self.failable(self.types.c(ty), f"{self.types.set_op(ty, name)}(M, {a}, {b}, {at})")
        if name in ("subseteq", "subset"):
            ty = join(types[0], types[1])
            a, b = self.types.convert(args[0], types[0], ty), self.types.convert(args[1], types[1], ty)
            test = f"{self.types.subseteq(ty)}({a}, {b})"
            if name == "subset":
                return f"({test} && !{self.types.eq(ty, a, b)})"
            return test
        if name == "notin":
            element = types[1].element
            return f"(!{self.types.set_has(types[1])}({args[1]}, {self.types.convert(args[0], types[0], element)}))"
        if name in ("Union", "Inter"):
            return self.failable(self.types.c(result), f"{self.types.big_op(coll, name)}(M, {args[0]}, {at})")
        if name == "concat":
            ty = result
            a, b = self.types.convert(args[0], types[0], ty), self.types.convert(args[1], types[1], ty)
            return self.failable(self.types.c(ty), f"{self.types.seq_op(ty, 'cat')}(M, {a}, {b}, {at})")
        if name in ("head", "last", "tail", "front"):
            return self.failable(self.types.c(result), f"{self.types.seq_op(coll, name)}(M, {args[0]}, {at})")
        if name == "reverse":
            return f"{self.types.seq_op(coll, 'reverse')}({args[0]})"
        if name in ("prefix", "suffix"):
            ty = join(types[0], types[1])
            a, b = self.types.convert(args[0], types[0], ty), self.types.convert(args[1], types[1], ty)
            return f"{self.types.seq_op(ty, name)}({a}, {b})"
        raise CotwinError(f"{e.loc}: function '{name}' is not supported by the C generator")

    def _tmp(self, value: str, ty: Ty) -> str:
        if value.startswith("(") or "(" in value:
            return self.temp(self.types.c(ty), value)
        return value

    # ---- compound forms ----
    def visit_IfExpr(self, e: s.IfExpr) -> str:
        ty = self.ty(e)
        condition = self.emit(e.condition)
        then_lines, then = self.captured(e.then, ty)
        else_lines, otherwise = self.captured(e.otherwise, ty)
        if not then_lines and not else_lines:
            return f"({condition} ? {then} : {otherwise})"
        result = self.temp(self.types.c(ty))
        self.out(f"if ({condition}) {{")
        self.out.lines.extend(then_lines)
        self.out(f"    {result} = {then};")
        self.out("} else {")
        self.out.lines.extend(else_lines)
        self.out(f"    {result} = {otherwise};")
        self.out("}")
        return result

    def visit_LetExpr(self, e: s.LetExpr) -> str:
        saved = dict(self.ctx.bound)
        try:
            for name, value in e.bindings:
                ty = self.ty(value)
                self.ctx.bound[name] = (self.temp(self.types.c(ty), self.emit(value)), ty)
            return self.emit(e.body)
        finally:
            self.ctx.bound = saved

    def visit_TypeTest(self, e: s.TypeTest) -> str:
        return self.emit(e.expr, self.ty(e))

    def visit_TupleExpr(self, e: s.TupleExpr) -> str:
        ty = self.ty(e)
        items = [self.emit(i, t) for i, t in zip(e.items, ty.items)]
        return f"(({self.types.c(ty)}){{{', '.join(items)}}})"

    def visit_VectorExpr(self, e: s.VectorExpr) -> str:
        ty = self.ty(e)
        items = [self.emit(i, ty.element) for i in e.items]
        return f"(({self.types.c(ty)}){{{{{', '.join(items)}}}}})"

    def visit_MatrixExpr(self, e: s.MatrixExpr) -> str:
        ty = self.ty(e)
        rows = ["{{" + ", ".join(self.emit(i, ty.element) for i in row) + "}}" for row in e.rows]
        return f"(({self.types.c(ty)}){{{{{', '.join(rows)}}}}})"

    def visit_RecordExpr(self, e: s.RecordExpr) -> str:
        ty = self.ty(e)
        fields = dict(self.types.field_types(ty))
        values = [(name, self.emit(value, fields[name])) for name, value, _ in e.fields]
        return f"(({self.types.c(ty)}){{{', '.join(f'.{ident(n)} = {v}' for n, v in values)}}})"

    def visit_SetExpr(self, e: s.SetExpr) -> str:
        return self._collection(e, e.items)

    def visit_SeqExpr(self, e: s.SeqExpr) -> str:
        return self._collection(e, e.items)

    def _collection(self, e, items) -> str:
        ty = self.ty(e)
        c = self.types.c(ty)
        result = self.temp(c, f"(({c}){{0}})")
        add = self.types.add(ty) if items else None
        for item in items:
            value = self.emit(item, ty.element)
            self.out(f"{result} = {add}(M, {result}, {value}, {self.at(e.loc)});")
            self.out(self.gen.bail)
        return result

    def visit_SetRangeExpr(self, e: s.SetRangeExpr) -> str:
        low, high = self.emit(e.start), self.emit(e.end)
        c = self.types.c(CollectionTy("Set", INT))
        return self.failable(c, f"{self.types.set_range()}(M, {low}, {high}, {self.at(e.loc)})")

    # quantifiers and comprehensions: loops over the binders' finite ranges
    def _loops(self, binders, such_that, body_fn, node) -> None:
        """Open one loop per binder (over `x in S` or a finite type), test `such_that`, run body_fn."""
        bounded = {}
        for conjunct in s.conjuncts(such_that):
            if (isinstance(conjunct, s.Binary) and conjunct.op == "in" and isinstance(conjunct.left, s.Name)
                    and not isinstance(conjunct.right, s.RangeExpr)):
                bounded.setdefault(conjunct.left.name.last, conjunct.right)
        saved = dict(self.ctx.bound)
        opened = 0
        try:
            for name, ref in binders:
                ty = self.ctx.body.resolver.resolve(ref)
                var = self.gen.fresh()
                if name in bounded:
                    coll_ty = self.ty(bounded[name])
                    coll = self.temp(self.types.c(coll_ty), self.emit(bounded[name]))
                    k = self.gen.fresh()
                    self.out(f"for (int {k} = 0; {k} < {coll}.n; {k}++) {{")
                    self.out.depth += 1
                    self.out(f"{self.types.c(coll_ty.element)} {var} = {coll}.v[{k}];")
                    self.ctx.bound[name] = (var, coll_ty.element)
                elif ty == BOOL:
                    k = self.gen.fresh()
                    self.out(f"for (int {k} = 0; {k} < 2; {k}++) {{")
                    self.out.depth += 1
                    self.out(f"bool {var} = {k} != 0;")
                    self.ctx.bound[name] = (var, BOOL)
                elif isinstance(ty, EnumTy):
                    self.out(f"for (int64_t {var} = 0; {var} < {len(ty.decl.literals)}; {var}++) {{")
                    self.out.depth += 1
                    self.ctx.bound[name] = (var, ty)
                else:
                    raise CotwinError(f"{node.loc}: {describe(node)} over all values of {ty} is not supported")
                opened += 1
            if such_that is not None:
                lines, test = self.captured(such_that)
                self.out.lines.extend(_dedent(lines))
                self.out(f"if (!({test})) continue;")
            body_fn()
        finally:
            for _ in range(opened):
                self.out.depth -= 1
                self.out("}")
            self.ctx.bound = saved

    def visit_Quantified(self, e: s.Quantified) -> str:
        if e.kind == "lambda":
            self.unsupported(e)
        if e.kind == "the":
            ty = self.ty(e)
            count = self.temp("int", "0")
            found = self.temp(self.types.c(ty), self.types.default(ty))
        else:
            count = self.temp("int", "0")
            found = None
        result = self.temp("bool", "true" if e.kind == "forall" else "false")
        done = self.gen.fresh()

        def body():
            lines, value = self.captured(e.body, self.ty(e) if e.kind == "the" else None)
            self.out.lines.extend(_dedent(lines))
            if e.kind == "forall":
                self.out(f"if (!({value})) {{ {result} = false; goto {done}_end; }}")
            elif e.kind == "exists":
                self.out(f"if ({value}) {{ {result} = true; goto {done}_end; }}")
            elif e.kind == "exists1":
                self.out(f"if ({value}) {count}++;")
            else:
                self.out(f"{count}++; {found} = {value};")

        self._loops(e.binders, e.such_that, body, e)
        self.out.label(f"{done}_end")
        if e.kind == "exists1":
            return f"({count} == 1)"
        if e.kind == "the":
            self.out(f"if ({count} != 1) {{ fail_atf(M, {self.at(e.loc)}, \"'the' found %d values, not exactly one\", "
                     f"{count}); return 1; }}")
            return found
        return result

    def visit_SetComprehension(self, e: s.SetComprehension) -> str:
        ty = self.ty(e)
        c = self.types.c(ty)
        result = self.temp(c, f"(({c}){{0}})")
        add = self.types.add(ty)

        def body():
            if e.body is not None:
                lines, value = self.captured(e.body, ty.element)
                self.out.lines.extend(_dedent(lines))
            elif len(e.binders) == 1:
                value = self.ctx.bound[e.binders[0][0]][0]
            else:
                value = f"(({self.types.c(ty.element)}){{{', '.join(self.ctx.bound[n][0] for n, _ in e.binders)}}})"
            self.out(f"{result} = {add}(M, {result}, {value}, {self.at(e.loc)});")
            self.out(self.gen.bail)

        self._loops(e.binders, e.predicate, body, e)
        return result


def _dedent(lines: list[str]) -> list[str]:
    return [line[4:] if line.startswith("    ") else line for line in lines]


def model_root(program: Program) -> Path:
    """The folder the model files' locations are written relative to in generated files when the caller
    names none: the deepest folder holding every model file of the project (the library's are not files)."""
    folders = [str(Path(f.path).resolve().parent) for f in program.project.files if not str(f.path).startswith("<")]
    return Path(os.path.commonpath(folders)) if folders else Path("/")


def portable_location(loc, root: Path) -> str:
    """`file:line:column` with the file relative to `root` (posix separators): the same text whatever the
    working directory and wherever the project lies, so that generated files never depend on either."""
    path = str(loc.path)
    if not path.startswith("<"):
        path = Path(os.path.relpath(Path(path).resolve(), root)).as_posix()
    return f"{path}:{loc.line}:{loc.column}"


class CGenerator:
    def __init__(self, program: Program, root: str | Path | None = None):
        self.program = program
        self.root = Path(root).resolve() if root is not None else model_root(program)
        self.types = CTypes(program.project)
        self.locations: list[str] = []
        self._location_index: dict[str, int] = {}
        self.counter = 0
        self.resume_count = 0
        self.resume_points: dict[int, list[int]] = {}  # machine -> the resume points of its cycle
        self.bail = "if (M->status) return 1;"
        from ..diagnostics import Diagnostics
        self.diag = Diagnostics()

    # ---- small services ----
    def fresh(self) -> str:
        self.counter += 1
        return f"t{self.counter}"

    def location(self, loc) -> int:
        text = portable_location(loc, self.root)
        if text not in self._location_index:
            self._location_index[text] = len(self.locations)
            self.locations.append(text)
        return self._location_index[text]

    def value(self, value, ty: Ty) -> str:
        """A constant as a C expression of type ty."""
        if is_scalar(ty):
            if ty == REAL:
                return c_real(float(value))
            return c_literal(value)
        c = self.types.c(ty)
        if isinstance(ty, RecordTy):
            fields = self.types.field_types(ty)
            if isinstance(value, FrozenRecord):
                value = dict(value)
            return f"(({c}){{{', '.join(f'.{ident(n)} = {self.value(value[n], t)}' for n, t in fields)}}})"
        if isinstance(ty, VectorTy):
            return f"(({c}){{{{{', '.join(self.value(v, ty.element) for v in value)}}}}})"
        if isinstance(ty, MatrixTy):
            rows = ["{{" + ", ".join(self.value(v, ty.element) for v in row) + "}}" for row in value]
            return f"(({c}){{{{{', '.join(rows)}}}}})"
        if isinstance(ty, TupleTy):
            return f"(({c}){{{', '.join(self.value(v, t) for v, t in zip(value, ty.items))}}})"
        if isinstance(ty, CollectionTy):
            items = [self.value(v, ty.element) for v in (sorted(value, key=repr) if isinstance(value, SetValue) else value)]
            return f"(({c}){{{len(items)}, {{{', '.join(items)}}}}})"
        raise CotwinError(f"constant {value!r} of type {ty} cannot be written in C")

    # ---- the whole file ----
    def generate(self) -> tuple[str, str]:
        p = self.program
        machines = []
        for m in p.machines:
            out = _Lines()
            self.machine_code(m, out)
            machines.append(out.text())
        step = _Lines()
        self.step_code(step)
        init = _Lines()
        self.init_code(init)
        check = _Lines()
        self.check_code(check)
        header = self.header()
        out = _Lines()
        out(f"/* Generated by cotwin from module {c_comment(p.module.name)}. Do not edit: regenerate from the model. */")
        for inc in ("math.h", "stdarg.h", "stdbool.h", "stdint.h", "stdio.h", "string.h"):
            out(f"#include <{inc}>")
        out('#include "model.h"')
        out()
        out(f"#define MAX_STEPS {MAX_STEPS}")
        out()
        out("/* where each checked operation is in the model, for error messages */")
        out(f"static const char *const LOC[] = {{{', '.join(c_string(loc) for loc in self.locations) or '0'}}};")
        out()
        out.lines.extend(_RUNTIME.strip("\n").split("\n"))
        out()
        for i, m in enumerate(p.machines):
            out(f"static const char *m{i}_where(const m{i}_State *s);")
        out()
        out("static const char *model_where(const Model *M) {")
        out("    switch (M->machine) {")
        for i in range(len(p.machines)):
            out(f"    case {i}: return m{i}_where(&M->m{i});")
        out("    default: return \"the module\";")
        out("    }")
        out("}")
        out()
        out.lines.extend(self.types.functions and "\n\n".join(self.types.functions).split("\n") or [])
        out()
        text = out.text() + "\n" + "\n".join(machines) + "\n" + step.text() + "\n" + init.text() + "\n" + check.text()
        return header, text

    def header(self) -> str:
        p = self.program
        out = _Lines()
        out(f"/* Generated by cotwin from module {c_comment(p.module.name)}: the data of one instance and its cycle. */")
        out("#ifndef COTWIN_MODEL_H")
        out("#define COTWIN_MODEL_H")
        out("#include <stdbool.h>")
        out("#include <stddef.h>")
        out("#include <stdint.h>")
        out()
        struct_lines = _Lines()
        for m in p.machines:
            self.machine_structs(m, struct_lines)
        model_lines = _Lines()
        self.model_struct(model_lines)
        out.lines.extend(self.types.typedefs)
        out()
        out.lines.extend(struct_lines.lines)
        out.lines.extend(model_lines.lines)
        out()
        out("int model_init(Model *M);    /* after parameters are set; 0 ok */")
        out("int model_step(Model *M);    /* one cycle; 0 ok, 1 error (M->message) */")
        out("int model_state(const Model *M, int machine);  /* index of the active leaf state, -1 if none */")
        out("int model_check(const Model *M, char *why, size_t size);  /* 1 if the bytes are a state it can run */")
        out()
        out("#endif")
        return out.text()

    # ---- data ----
    def _event_struct(self, ty: Ty | None) -> str:
        return "struct { bool on; }" if ty is None else f"struct {{ bool on; {self.types.c(ty)} v; }}"

    def _frame_members(self, body: Body, out: _Lines) -> None:
        for name, ty, _ in body.variables:
            out(f"    {self.types.c(ty)} {ident(name)};")
        if body.clocks:
            out(f"    struct {{ {' '.join(f'int64_t {ident(c)};' for c in body.clocks)} }} clk;")
        for k in sorted(body.entry_timers):
            out(f"    int64_t ent{k};  /* cycles since {c_comment(node_description(body.graph.nodes[k]))} was entered */")

    def machine_structs(self, m: MachineInstance, out: _Lines) -> None:
        i = m.index
        out(f"typedef struct {{  /* events arriving at machine {c_comment(m.name)} in one cycle */")
        for name, ty in m.inputs.items():
            out(f"    {self._event_struct(ty)} {ident(name)};")
        out("    char none;")
        out(f"}} m{i}_In;")
        out()
        for frame in m.frames:
            out(f"typedef struct {{  /* a call of operation {c_comment(frame.name)} */")
            out("    int active, xt, xr, ret;")
            for name, ty in frame.params:
                out(f"    {self.types.c(ty)} {ident(name)};")
            self._frame_members(frame, out)
            out(f"}} m{i}_O{frame.index};")
            out()
        out(f"typedef struct {{  /* state machine {c_comment(m.machine.name)} */")
        out("    int active;   /* node index, -1 before the start */")
        out("    int resume;   /* where the next cycle continues, 0 = start, -1 = terminated */")
        out("    int top;      /* the frame running: -1 the machine's own, k operation frame k */")
        out("    int xt, xr;   /* the exit in progress: up to which container, and where to go back */")
        self._frame_members(m, out)
        if m.parameters:
            out(f"    struct {{ {' '.join(f'{self.types.c(m.types[n])} {ident(n)};' for n in m.parameters)} }} par;")
        for frame in m.frames:
            out(f"    m{i}_O{frame.index} o{frame.index};")
        out(f"    m{i}_In in, next;")
        out(f"}} m{i}_State;")
        out()

    def model_struct(self, out: _Lines) -> None:
        p = self.program
        out("typedef struct {")
        out("    struct {  /* inputs from the platform: an event flag per cycle and its value */")
        for ev in p.inputs:
            out(f"        {self._event_struct(ev.ty)} {ident(ev.name)};")
        out("        char none;")
        out("    } in;")
        out("    struct {  /* operation calls of the last cycle, with their arguments */")
        for op in p.operations:
            members = "".join(f" {self.types.c(ty)} {ident(pname)};" for pname, ty in op.params)
            out(f"        struct {{ bool on;{members} }} {ident(op.name)};")
        out("        char none;")
        out("    } call;")
        out("    struct {  /* output events of the last cycle */")
        for ev in p.outputs:
            out(f"        {self._event_struct(ev.ty)} {ident(ev.name)};")
        out("        char none;")
        out("    } out;")
        for m in p.machines:
            out(f"    m{m.index}_State m{m.index};")
        out("    int64_t seed;            /* parameter of the pseudo-random source */")
        out("    uint64_t rng;")
        out("    int64_t cycle;")
        out("    int64_t nondeterminism;  /* cycles in which several transitions were enabled */")
        out("    int machine;             /* the machine running, for error messages */")
        out("    int status;              /* 0 ok, 1 model error (message) */")
        out("    char message[512];")
        out("} Model;")

    # ---- per machine ----
    def machine_code(self, m: MachineInstance, out: _Lines) -> None:
        i = m.index
        bodies: list[tuple[str, Body, int]] = [("B", m, -1)] + [(f"O{f.index}", f, f.index) for f in m.frames]
        out(f"/* ---- state machine {c_comment(m.machine.name)} ({c_comment(m.name)}) ---- */")
        for prefix, body, frame in bodies:
            graph = body.graph
            parents = ", ".join(str(n.parent.index if n.parent else -1) for n in graph.nodes) or "-1"
            opname = body.name if frame >= 0 else ""
            descs = ", ".join(c_string(node_description(n, opname)) for n in graph.nodes) or "0"
            out(f"static const int m{i}_{prefix}_parent[] = {{{parents}}};")
            out(f"static const char *const m{i}_{prefix}_desc[] = {{{descs}}};")
        out()
        out(f"static const char *m{i}_where(const m{i}_State *s) {{")
        start = c_string(f"state machine {m.machine.name}")  # starting, or between states
        out("    switch (s->top) {")
        for prefix, body, frame in bodies:
            active = "s->active" if frame < 0 else f"s->o{frame}.active"
            out(f"    case {frame}: return {active} < 0 ? {start} : m{i}_{prefix}_desc[{active}];")
        out(f"    default: return {start};")
        out("    }")
        out("}")
        out()
        out(f"static int m{i}_inside(const int *parent, int node, int container) {{")
        out("    if (node < 0 || node == container) return 0;")
        out("    for (node = parent[node]; node >= 0; node = parent[node])")
        out("        if (node == container) return 1;")
        out("    return 0;")
        out("}")
        out()
        out(f"static int m{i}_cycle(Model *M) {{")
        body_out = _Lines(1)
        self.resumes: list[tuple[int, str]] = []
        self.returns: dict[int, list[tuple[int, str]]] = {f.index: [] for f in m.frames}
        self.exits: dict[str, list[tuple[int, str]]] = {prefix: [] for prefix, _, _ in bodies}
        ctx = Context(self, m, m, -1)
        body_out.label("START")
        body_out("/* the first cycle: initial values, then the initial junction */")
        body_out("s->top = -1;")
        for name, ty, init in m.variables:
            if init is not None:
                value = CExpr(ctx, body_out).emit(init, ty)
                body_out(f"s->{ident(name)} = {value};")
        init = m.graph.initial_of(None)
        body_out(f"s->active = {init.index};")
        body_out(f"goto B_S_{init.index};")
        for prefix, body, frame in bodies:
            self.body_code(m, prefix, body, frame, body_out)
        body_out.label("FINAL")
        body_out("s->resume = -1;")
        body_out("return 0;")
        self.resume_points[i] = [number for number, _ in self.resumes]
        out(f"    m{i}_State *s = &M->m{i};")
        out(f"    m{i}_In *in = &s->in;")
        out("    long steps = 0;")
        out("    (void)in; (void)steps;")
        out(f"    M->machine = {i};")
        out("    switch (s->resume) {")
        out("    case 0: goto START;")
        out("    case -1: return 0;  /* terminated */")
        for number, label in self.resumes:
            out(f"    case {number}: goto {label};")
        out('    default: return fail(M, "corrupt resume point");')
        out("    }")
        out.lines.extend(body_out.lines)
        out("}")
        out()
        leaves = m.graph.leaves
        out(f"static int m{i}_leaf(int active) {{")
        out("    switch (active) {")
        for k, leaf in enumerate(leaves):
            out(f"    case {leaf.index}: return {k};")
        out("    default: return -1;")
        out("    }")
        out("}")

    def body_code(self, m: MachineInstance, prefix: str, body: Body, frame: int, out: _Lines) -> None:
        ctx = Context(self, m, body, frame)
        graph = body.graph
        f = ctx.f
        if frame >= 0:
            init = graph.initial_of(None)
            out.label(f"{prefix}_START")
            out(f"/* operation {c_comment(body.name)} starts */")
            out(f"{f}active = {init.index};")
            out(f"goto {prefix}_S_{init.index};")
        for n in graph.nodes:
            self.settle_block(ctx, prefix, n, out)
        for e in graph.edges:
            self.edge_block(ctx, prefix, e, out)
        # the exit block: exit states up to container xt, running exit actions, then go back
        out.label(f"{prefix}_EXIT")
        out(f"while ({f}active != {f}xt && {f}active >= 0) {{")
        out.depth += 1
        out(f"switch ({f}active) {{")
        for n in graph.nodes:
            if isinstance(n.node, State) and n.node.exit is not None:
                out(f"case {n.index}: /* exit {c_comment('.'.join(n.path))} */")
                out.depth += 1
                self.stmt(ctx, n.node.exit, out)
                out("break;")
                out.depth -= 1
        out("default: break;")
        out("}")
        out(f"{f}active = m{m.index}_{prefix}_parent[{f}active];")
        out.depth -= 1
        out("}")
        out(f"switch ({f}xr) {{")
        for number, label in self.exits[prefix]:
            out(f"case {number}: goto {label};")
        out("default: break;")
        out("}")
        out('return fail(M, "corrupt exit point");')
        if frame >= 0:
            out.label(f"{prefix}_RET")
            out(f"/* operation {c_comment(body.name)} returns */")
            out(f"switch ({f}ret) {{")
            for number, label in self.returns[frame]:
                out(f"case {number}: goto {label};")
            out("default: break;")
            out("}")
            out('return fail(M, "corrupt return point");')

    def resume_point(self, out: _Lines, then: str | None = None) -> None:
        self.resume_count += 1
        label = f"R{self.resume_count}"
        self.resumes.append((self.resume_count, label))
        out(f"s->resume = {self.resume_count};")
        out("return 0;")
        out.label(label)
        if then:
            out(then)

    def settle_block(self, ctx: Context, prefix: str, n, out: _Lines) -> None:
        m, f = ctx.m, ctx.f
        out.label(f"{prefix}_S_{n.index}")
        out(f"/* settle {c_comment('.'.join(n.path))} */")
        out(f'if (++steps > MAX_STEPS) return fail_loc(M, {self.location(m.machine.loc)}, '
            f'{c_string(f"divergence: no exec reached after {MAX_STEPS} steps in state machine {m.machine.name}")});')
        if isinstance(n.node, Final):
            out(f"{f}active = {n.index};")
            out("goto FINAL;" if ctx.frame < 0 else f"goto {prefix}_RET;")
            return
        if isinstance(n.node, State) and any(c.is_state or isinstance(c.node, Initial) for c in n.children):
            initial = ctx.body.graph.initial_of(n)
            if initial is not None:
                out(f"if (!m{m.index}_inside(m{m.index}_{prefix}_parent, {f}active, {n.index})) "
                    f"{{ {f}active = {initial.index}; goto {prefix}_S_{initial.index}; }}")
        for group in choice_groups(n):
            if not group.outgoing:
                continue
            out("{")
            out.depth += 1
            names = []
            guards = {}
            for e in group.outgoing:
                if e.transition.condition is not None:
                    value = CExpr(ctx, out).emit(e.transition.condition)
                    guards[e.index] = self._bool(out, value)
            for e in group.outgoing:
                out(f"bool g{e.index} = {self.guard(e, guards)};  /* {c_comment(e.transition.name)} */")
                names.append(f"g{e.index}")
            out(f"int enabled = {' + '.join(f'(int){g}' for g in names)};")
            out("if (enabled > 1) M->nondeterminism++;")
            for e in group.outgoing:
                out(f"if (g{e.index}) {{")
                out.depth += 1
                self.bind(ctx, e, out)
                if e.transition.is_exec:
                    self.resume_count += 1
                    self.resumes.append((self.resume_count, f"{prefix}_T_{e.index}"))
                    out(f"s->resume = {self.resume_count};  /* {c_comment(e.transition.name)} completes next cycle */")
                    out("return 0;")
                else:
                    out(f"goto {prefix}_T_{e.index};")
                out.depth -= 1
                out("}")
            out.depth -= 1
            out("}")
        if isinstance(n.node, State) and n.node.during is not None:
            self.stmt(ctx, n.node.during, out)
            self.resume_point(out, f"goto {prefix}_S_{n.index};")
            return
        what = "junction" if isinstance(n.node, (Junction, Initial)) else "state"
        out(f'return fail_loc(M, {self.location(n.node.loc)}, '
            f'{c_string(f"timelock: no transition enabled from {what} {n.name} in state machine {m.machine.name}")});')

    @staticmethod
    def _bool(out: _Lines, value: str) -> str:
        return value

    def guard(self, e, guards: dict[int, str]) -> str:
        t = e.transition
        if t.condition is not None:
            return guards[e.index]
        if not t.is_else:
            return "true"
        others = [self.guard(o, guards) for o in e.source.outgoing if o is not e and not o.transition.is_else]
        return f"!({' || '.join(others)})" if others else "true"

    def bind(self, ctx: Context, e, out: _Lines) -> None:
        if e.transition.condition is None:
            return
        for node in s.walk(e.transition.condition):
            if isinstance(node, s.EventTest) and node.bind is not None and node.event.last in ctx.m.inputs:
                target, ty = ctx.name(node.bind, node.loc)
                value = ctx.gen.types.convert(f"in->{ident(node.event.last)}.v", ctx.m.inputs[node.event.last], ty)
                out(f"if (in->{ident(node.event.last)}.on) {target} = {value};")

    def edge_block(self, ctx: Context, prefix: str, e, out: _Lines) -> None:
        t = e.transition
        f = ctx.f
        out.label(f"{prefix}_T_{e.index}")
        out(f"/* complete {c_comment(t.name)}: {c_comment('.'.join(e.source.path))} -> {c_comment('.'.join(e.target.path))} */")
        lca = lca_index(e)
        self.resume_count += 1
        back = f"{prefix}_X{self.resume_count}"
        self.exits[prefix].append((self.resume_count, back))
        out(f"{f}xt = {lca}; {f}xr = {self.resume_count}; goto {prefix}_EXIT;")
        out.label(back)
        if t.action is not None:
            self.stmt(ctx, t.action, out)
        path = []
        node = e.target
        while node is not None and node.index != lca:
            path.append(node)
            node = node.parent
        for n in reversed(path):
            out(f"{f}active = {n.index};")
            if isinstance(n.node, State):
                if n.index in ctx.body.entry_timers:
                    out(f"{f}ent{n.index} = 0;")
                if n.node.entry is not None:
                    out(f"/* entry {c_comment(n.name)} */")
                    self.stmt(ctx, n.node.entry, out)
        out(f"goto {prefix}_S_{e.target.index};")

    # ---- statements ----
    def stmt(self, ctx: Context, st: s.Stmt, out: _Lines) -> None:
        if isinstance(st, s.Sequence):
            for item in st.statements:
                self.stmt(ctx, item, out)
        elif isinstance(st, s.Exec):
            self.resume_point(out)
        elif isinstance(st, s.Skip):
            out(";")
        elif isinstance(st, s.IfStmt):
            condition = CExpr(ctx, out).emit(st.condition)
            out(f"if ({condition}) {{")
            out.depth += 1
            self.stmt(ctx, st.then, out)
            out.depth -= 1
            if st.otherwise is not None:
                out("} else {")
                out.depth += 1
                self.stmt(ctx, st.otherwise, out)
                out.depth -= 1
            out("}")
        elif isinstance(st, s.Assign):
            ty = self.program.type_of(st.target) or ctx.name(s.root_name(st.target).name.last, st.loc)[1]
            value = CExpr(ctx, out).emit(st.value, ty)
            value = self._hold(out, value, ty)
            target = self.lvalue(ctx, st.target, out)
            out(f"{target} = {value};")
        elif isinstance(st, s.PlatformCall):
            self.platform_call(ctx, st.operation.last, st.args, out, st.loc)
        elif isinstance(st, s.CallStmt):
            if st.operation.last in ctx.body.calls:
                self.call(ctx, st, out)
            else:
                self.platform_call(ctx, st.operation.last, st.args, out, st.loc)
        elif isinstance(st, s.Send):
            self.send(ctx, st, out)
        elif isinstance(st, s.ClockReset):
            out(f"{ctx.clock(st.clock)} = 0;")
        else:
            raise CotwinError(f"{st.loc}: {type(st).__name__} statements are not supported by the C generator")

    @staticmethod
    def _hold(out: _Lines, value: str, ty: Ty) -> str:
        """Values need no temporary before the target's indices: whatever in them can fail or draw a
        random number is already evaluated, in order, into temporaries."""
        return value

    def lvalue(self, ctx: Context, e: s.Expr, out: _Lines) -> str:
        if isinstance(e, s.Name):
            return ctx.name(e.name.last, e.loc)[0]
        if isinstance(e, s.FieldAccess):
            return f"{self.lvalue(ctx, e.base, out)}.{ident(e.field)}"
        if isinstance(e, s.IndexAccess):
            base = self.lvalue(ctx, e.base, out)
            base_ty = self.program.type_of(e.base)
            if isinstance(base_ty, TupleTy):
                return f"{base}.i{e.index.value}"
            cexpr = CExpr(ctx, out)
            index = cexpr.emit(e.index)
            return f"{base}.v[{cexpr.checked_index(e, index, base, base_ty)}]"
        raise CotwinError(f"{e.loc}: only variables, their fields and elements can be assigned")

    def repeated(self, flag: str, what: str, loc) -> str:
        return (f'if ({flag}) {{ fail_at(M, {self.location(loc)}, {c_string(what + " emitted twice in one cycle")}); '
                f'return 1; }}')

    def platform_call(self, ctx: Context, op: str, args, out: _Lines, loc=None) -> None:
        port = self.program.operation_port(op)
        if port is None:
            raise CotwinError(f"operation '{op}' is not an operation of the platform")
        values = [CExpr(ctx, out).emit(a, ty) for a, (_, ty) in zip(args, port.params)]
        held = [self._hold(out, v, ty) for v, (_, ty) in zip(values, port.params)]
        out(self.repeated(cnames.call_flag(op), f"operation {op!r}", loc))
        for other, shared in sorted(port.shares.items()):
            what = c_string(shared_port_message(other, op, shared))
            out(f"if ({cnames.call_flag(other)}) {{ fail_at(M, {self.location(loc)}, {what}); return 1; }}")
        for group, value in zip(port.arg_ports, held):
            self.fits_ports(group, value, loc, out)
        for (pname, _), value in zip(port.params, held):
            out(f"{cnames.call_arg(op, pname)} = {value};")
        out(f"{cnames.call_flag(op)} = true;")

    def fits_ports(self, group, value: str, loc, out: _Lines) -> None:
        """Fail where an integer sent through an FMI Integer port does not fit 32 bits (as the interpreter)."""
        for port, sc in group:
            if sc.ty in (INT, NAT):
                x = f"({value}){cnames.field_path(sc.path)}"
                text = c_string(beyond_int32_message(port, 0).replace(" = 0 ", " = %lld "))
                out(f"if ({x} < INT32_MIN || {x} > INT32_MAX) {{ fail_atf(M, {self.location(loc)}, {text}, "
                    f"(long long){x}); return 1; }}")

    def call(self, ctx: Context, st: s.CallStmt, out: _Lines) -> None:
        op: OperationInstance = ctx.body.calls[st.operation.last]
        k = op.index
        values = [CExpr(ctx, out).emit(a, ty) for a, (_, ty) in zip(st.args, op.params)]
        held = [self._hold(out, v, ty) for v, (_, ty) in zip(values, op.params)]
        out(f"/* call {c_comment(op.name)} */")
        out(f"s->o{k}.active = -1;")
        for (pname, _), value in zip(op.params, held):
            out(f"s->o{k}.{ident(pname)} = {value};")
        out(f"s->top = {k};")
        for c in op.clocks:
            out(f"s->o{k}.clk.{ident(c)} = 0;")
        for index in sorted(op.entry_timers):
            out(f"s->o{k}.ent{index} = -1;")
        inner = Context(self, ctx.m, op, k)
        for name, ty, init in op.variables:
            value = CExpr(inner, out).emit(init, ty) if init is not None else self.types.default(ty)
            out(f"s->o{k}.{ident(name)} = {value};")
        self.resume_count += 1
        back = f"C{self.resume_count}"
        self.returns[k].append((self.resume_count, back))
        out(f"s->o{k}.ret = {self.resume_count};")
        out(f"goto O{k}_START;")
        out.label(back)
        out(f"s->top = {ctx.frame};")

    def send(self, ctx: Context, st: s.Send, out: _Lines) -> None:
        name = st.event.last
        key = (ctx.m.index, name)
        ty = ctx.m.outputs.get(name)
        value = CExpr(ctx, out).emit(st.value, ty) if st.value is not None else None
        if value is not None:
            value = self._hold(out, value, ty)
        if key in self.program.output_routes:
            port = self.program.output_routes[key]
            out(self.repeated(cnames.out_flag(port), f"event {port!r}", st.loc))
            event = self.program.output_port(port)
            if value is not None and event is not None:
                self.fits_ports(event.value_ports, value, st.loc, out)
            if value is not None:
                out(f"{cnames.out_value(port)} = {value};")
            out(f"{cnames.out_flag(port)} = true;")
        for target, ev in self.program.internal_routes.get(key, ()):
            box = f"M->m{target}.next.{ident(ev)}"
            out(self.repeated(f"{box}.on", f"event {name!r}", st.loc))
            if value is not None:
                out(f"{box}.v = {value};")
            out(f"{box}.on = true;")

    # ---- module step and init ----
    def step_code(self, out: _Lines) -> None:
        p = self.program
        out("int model_step(Model *M) {")
        out("    if (M->status) return 1;")
        out("    M->cycle++;")
        for op in p.operations:
            out(f"    {cnames.call_flag(op.name)} = false;")
        for ev in p.outputs:
            out(f"    {cnames.out_flag(ev.name)} = false;")
        out("    /* this cycle's inbox: events delayed from other machines, then the platform's */")
        for m in p.machines:
            out(f"    M->m{m.index}.in = M->m{m.index}.next;")
            out(f"    memset(&M->m{m.index}.next, 0, sizeof M->m{m.index}.next);")
        for ev in p.inputs:
            for machine, name in p.input_routes.get(ev.name, ()):
                target = self.program.machines[machine]
                out(f"    if ({cnames.in_flag(ev.name)}) {{")
                out(f"        M->m{machine}.in.{ident(name)}.on = true;")
                if ev.ty is not None and target.inputs.get(name) is not None:
                    value = self.types.convert(cnames.in_value(ev.name), ev.ty, target.inputs[name])
                    out(f"        M->m{machine}.in.{ident(name)}.v = {value};")
                out("    }")
        out("    /* clocks and state-entry counters count the cycles (after a machine's first) */")
        for m in p.machines:
            i = m.index
            counters = [f"M->m{i}.clk.{ident(c)}++;" for c in m.clocks]
            counters += [f"if (M->m{i}.ent{k} >= 0) M->m{i}.ent{k}++;" for k in sorted(m.entry_timers)]
            for frame in m.frames:
                counters += [f"M->m{i}.o{frame.index}.clk.{ident(c)}++;" for c in frame.clocks]
                counters += [f"if (M->m{i}.o{frame.index}.ent{k} >= 0) M->m{i}.o{frame.index}.ent{k}++;"
                             for k in sorted(frame.entry_timers)]
            if counters:
                out(f"    if (M->m{i}.resume != 0) {{ {' '.join(counters)} }}")
        for m in p.machines:
            out(f"    if (m{m.index}_cycle(M)) return 1;")
        out("    return 0;")
        out("}")
        out()
        out("int model_state(const Model *M, int machine) {")
        out("    switch (machine) {")
        for m in p.machines:
            out(f"    case {m.index}: return m{m.index}_leaf(M->m{m.index}.active);")
        out("    default: return -1;")
        out("    }")
        out("}")

    def check_code(self, out: _Lines) -> None:
        """model_check: whether the bytes of a Model (a deserialised FMU state, which may come from anywhere)
        are a state this code can run without reading or writing outside the Model: node indices, frames
        and resume points in range, sets and sequences within their capacity, Booleans 0 or 1, the message
        terminated. The FMU refuses any other bytes (fmi2_wrapper.c)."""
        p = self.program
        checks: list[tuple[str, str]] = []  # (condition that must hold, what it is about)

        def value(ty, ref: str, what: str) -> None:
            condition = bool_ok(ref) if ty is None else self.types.check(ty, ref)
            if condition:
                checks.append((condition, f"{what} is malformed"))

        def bool_ok(ref: str) -> str:
            return f"bool_ok(&{ref})"

        def events(ref: str, inputs, what: str) -> None:
            for name, ty in inputs:
                value(None, f"{ref}.{ident(name)}.on", f"{what} {name}")
                if ty is not None:
                    value(ty, f"{ref}.{ident(name)}.v", f"{what} {name}'s value")

        def index(ref: str, low: int, high: int, what: str) -> None:
            checks.append((f"{ref} >= {low} && {ref} < {high}", f"{what} is out of range"))

        def body(ref: str, b, what: str) -> None:
            nodes = len(b.graph.nodes)
            index(f"{ref}.active", -1, nodes, f"{what}'s active state")
            index(f"{ref}.xt", -1, nodes, f"{what}'s exit")
            for name, ty, _ in b.variables:
                value(ty, f"{ref}.{ident(name)}", f"{what}'s variable {name}")

        events("M->in", [(ev.name, ev.ty) for ev in p.inputs], "input event")
        for op in p.operations:
            value(None, f"{cnames.call_flag(op.name)}", f"call of {op.name}")
            for pname, ty in op.params:
                value(ty, f"M->call.{ident(op.name)}.{ident(pname)}", f"argument {pname} of {op.name}")
        events("M->out", [(ev.name, ev.ty) for ev in p.outputs], "output event")
        for m in p.machines:
            ref, what = f"M->m{m.index}", f"machine {m.machine.name}"
            body(ref, m, what)
            index(f"{ref}.top", -1, len(m.frames), f"{what}'s running operation")
            for name in m.parameters:
                value(m.types[name], f"{ref}.par.{ident(name)}", f"{what}'s parameter {name}")
            for frame in m.frames:
                fref, fwhat = f"{ref}.o{frame.index}", f"{what}'s call of {frame.name}"
                body(fref, frame, fwhat)
                for name, ty in frame.params:
                    value(ty, f"{fref}.{ident(name)}", f"{fwhat}'s parameter {name}")
            for inbox in ("in", "next"):
                events(f"{ref}.{inbox}", list(m.inputs.items()), f"{what}'s event")
        out("/* 1 if the bytes of a Model (a deserialised FMU state, from anywhere) are a state this code can run")
        out("   without reading or writing outside the Model; else 0 and what is wrong in `why` */")
        out("int model_check(const Model *M, char *why, size_t size) {")
        for m in p.machines:
            points = " ".join(f"case {n}:" for n in [-1, 0, *self.resume_points.get(m.index, [])])
            out(f"    switch (M->m{m.index}.resume) {{ {points} break; default: "
                f"snprintf(why, size, \"machine %s: no resume point %d\", {c_string(m.machine.name)}, M->m{m.index}.resume); "
                "return 0; }")
        for condition, what in checks:
            out(f"    if (!({condition})) {{ snprintf(why, size, \"%s\", {c_string(what)}); return 0; }}")
        out(f"    if (M->machine < -1 || M->machine >= {max(1, len(p.machines))}) "
            '{ snprintf(why, size, "the running machine out of range"); return 0; }')
        out("    if (M->status != 0 && M->status != 1) { snprintf(why, size, \"status %d\", M->status); return 0; }")
        out("    if (M->cycle < 0 || M->nondeterminism < 0) { snprintf(why, size, \"a negative cycle count\"); return 0; }")
        out("    if (!memchr(M->message, 0, sizeof M->message)) { snprintf(why, size, \"an unterminated message\"); return 0; }")
        out("    return 1;")
        out("}")

    def init_code(self, out: _Lines) -> None:
        p = self.program
        out("int model_init(Model *M) {")
        out("    M->cycle = 0;")
        out("    M->nondeterminism = 0;")
        out("    M->status = 0;")
        out("    M->machine = -1;")
        out("    M->message[0] = '\\0';")
        out("    M->rng = (uint64_t)M->seed;")
        for m in p.machines:
            out("    {")
            out(f"        m{m.index}_State *s = &M->m{m.index};")
            out("        s->active = -1;")
            out("        s->resume = 0;")
            out("        s->top = -1;")
            out("        memset(&s->in, 0, sizeof s->in);")
            out("        memset(&s->next, 0, sizeof s->next);")
            for c in m.clocks:
                out(f"        s->clk.{ident(c)} = 0;")
            for k in sorted(m.entry_timers):
                out(f"        s->ent{k} = -1;")
            for name, ty, _ in m.variables:
                out(f"        s->{ident(name)} = {self.types.default(ty)};")
            out("    }")
        out("    return 0;")
        out("}")


_RUNTIME = r"""
/* a Boolean read from bytes of unknown origin is 0 or 1 (any other byte is undefined behaviour in C) */
static bool bool_ok(const bool *b) {
    unsigned char c;
    memcpy(&c, b, 1);
    return c <= 1;
}

static int fail(Model *M, const char *message) {
    if (M->status) return 1;
    M->status = 1;
    snprintf(M->message, sizeof M->message, "%s (cycle %lld)", message, (long long)M->cycle);
    return 1;
}

static const char *model_where(const Model *M);

/* A located structural error (timelock, divergence): "<file>:<line>:<col>: <what> (cycle N)". */
static int fail_loc(Model *M, int at, const char *what) {
    if (M->status) return 1;
    M->status = 1;
    snprintf(M->message, sizeof M->message, "%s: %s (cycle %lld)", LOC[at], what, (long long)M->cycle);
    return 1;
}

/* A located run-time error: "<file>:<line>:<col>: <what> in <state> (cycle N)"; the first one wins. */
static void fail_atf(Model *M, int at, const char *format, ...) {
    char what[256];
    va_list args;
    if (M->status) return;
    va_start(args, format);
    vsnprintf(what, sizeof what, format, args);
    va_end(args);
    M->status = 1;
    snprintf(M->message, sizeof M->message, "%s: %s in %s (cycle %lld)", LOC[at], what, model_where(M),
             (long long)M->cycle);
}

static void fail_at(Model *M, int at, const char *what) { fail_atf(M, at, "%s", what); }

/* int64 arithmetic that reports division by zero and overflow instead of trapping */
static int64_t ck_add(Model *M, int64_t a, int64_t b, int at) {
    int64_t r;
    if (__builtin_add_overflow(a, b, &r)) { fail_at(M, at, "integer overflow"); return 0; }
    return r;
}
static int64_t ck_sub(Model *M, int64_t a, int64_t b, int at) {
    int64_t r;
    if (__builtin_sub_overflow(a, b, &r)) { fail_at(M, at, "integer overflow"); return 0; }
    return r;
}
static int64_t ck_mul(Model *M, int64_t a, int64_t b, int at) {
    int64_t r;
    if (__builtin_mul_overflow(a, b, &r)) { fail_at(M, at, "integer overflow"); return 0; }
    return r;
}
static int64_t ck_div(Model *M, int64_t a, int64_t b, int at) {
    if (b == 0) { fail_at(M, at, "division by zero"); return 0; }
    if (a == INT64_MIN && b == -1) { fail_at(M, at, "integer overflow"); return 0; }
    return a / b;
}
static int64_t ck_mod(Model *M, int64_t a, int64_t b, int at) {
    if (b == 0) { fail_at(M, at, "remainder of a division by zero"); return 0; }
    if (a == INT64_MIN && b == -1) { fail_at(M, at, "integer overflow"); return 0; }
    return a % b;
}
static int64_t ck_neg(Model *M, int64_t a, int at) {
    if (a == INT64_MIN) { fail_at(M, at, "integer overflow"); return 0; }
    return -a;
}
/* min/max as the interpreter's: NaN skipped, the first of equal ones (fmin(0.0, -0.0) may give either zero) */
static double ck_min(double a, double b) { return isnan(a) ? b : isnan(b) ? a : (b < a ? b : a); }
static double ck_max(double a, double b) { return isnan(a) ? b : isnan(b) ? a : (b > a ? b : a); }
static const char *real_text(double x) { return isnan(x) ? "nan" : x > 0 ? "inf" : "-inf"; }
static int64_t ck_floor(Model *M, double x, int at) {
    if (!isfinite(x)) { fail_atf(M, at, "floor: floor of %s", real_text(x)); return 0; }
    x = floor(x);
    if (x < -9223372036854775808.0 || x >= 9223372036854775808.0) { fail_at(M, at, "floor: integer overflow"); return 0; }
    return (int64_t)x;
}
static int64_t ck_ceil(Model *M, double x, int at) {
    if (!isfinite(x)) { fail_atf(M, at, "ceil: ceil of %s", real_text(x)); return 0; }
    x = ceil(x);
    if (x < -9223372036854775808.0 || x >= 9223372036854775808.0) { fail_at(M, at, "ceil: integer overflow"); return 0; }
    return (int64_t)x;
}
/* the zero-based position of index i (counting from `first`) in n elements */
static int64_t ck_index(Model *M, int64_t i, int first, int64_t n, int at) {
    if (i - first < 0 || i - first >= n) { fail_atf(M, at, "index %lld out of range %lld..%lld", (long long)i, (long long)first, (long long)(n + first - 1)); return 0; }
    return i - first;
}

/* splitmix64: the seedable pseudo-random source (uninterpreted functions, Mathematics::random) */
static uint64_t rng_next(Model *M) {
    uint64_t z = (M->rng += UINT64_C(0x9E3779B97F4A7C15));
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}
static double rng_real(Model *M) { return (double)(rng_next(M) >> 11) * (1.0 / 9007199254740992.0); }
"""


def generate_c(program: Program, root: str | Path | None = None) -> dict[str, str]:
    """The generated sources: {file name: text}; model locations relative to `root` (default: model_root)."""
    header, source = CGenerator(program, root).generate()
    return {"model.h": header, "model.c": source}


__all__ = ["CGenerator", "c_literal", "c_real", "generate_c", "CAPACITY", "MatrixValue", "SeqValue", "TupleValue",
           "VectorValue"]
