"""C representations of RoboSim types and the helper functions over them, generated on demand.

boolean -> bool; int, nat, enumerations -> int64_t; real -> double; a record -> a struct of its
fields; vector(T, n) -> struct { T v[n]; }; matrix(T, r, c) -> struct { vec_c v[r]; } (rows are
vectors); a product A * B -> struct { A i1; B i2; }; Set(T) and Seq(T) -> struct { int32_t n;
T v[CAPACITY]; } (a set keeps each element once, in insertion order). Values are passed and stored
by value (C copies structs), as the interpreter copies its values. Every helper that can fail
(overflow, capacity, an empty sequence) takes the Model and a location index and reports through
fail_at, like the checked integer operations.
"""

from __future__ import annotations

from ..diagnostics import CotwinError, Diagnostics
from ..robosim.types import (
    BOOL, INT, NAT, REAL, UNKNOWN, CollectionTy, EnumTy, MatrixTy, RecordTy, TupleTy, Ty, TypeResolver, VectorTy,
)
from ..robosim.values import CAPACITY
from .cnames import ident


def is_intlike(ty: Ty) -> bool:
    return ty in (INT, NAT) or isinstance(ty, EnumTy)


def is_scalar(ty: Ty) -> bool:
    return ty in (BOOL, INT, NAT, REAL) or isinstance(ty, EnumTy)


class CTypes:
    """Type names and helper functions, each emitted once, dependencies first."""

    def __init__(self, project):
        self.project = project
        self.names: dict[Ty, str] = {}
        self.typedefs: list[str] = []
        self.functions: list[str] = []
        self._helpers: set[str] = set()
        self._checks: dict[str, str | None] = {}  # ok_<type> -> its name, None when any bytes are a value
        self._record_names: dict[str, int] = {}
        self._defined: set[str] = set()

    # ---- types ----
    def field_types(self, ty: RecordTy) -> list[tuple[str, Ty]]:
        resolver = TypeResolver(self.project, self.project.file_of(ty.decl), Diagnostics())
        return [(f.name, resolver.resolve(f.type)) for f in ty.decl.fields]

    def c(self, ty: Ty) -> str:
        if ty == BOOL:
            return "bool"
        if ty == REAL:
            return "double"
        if is_intlike(ty):
            return "int64_t"
        if ty in self.names:
            return self.names[ty]
        if isinstance(ty, RecordTy):
            fields = [(ident(n), self.c(t)) for n, t in self.field_types(ty)]
            count = self._record_names.get(ty.decl.name, 0)
            self._record_names[ty.decl.name] = count + 1
            name = f"rec_{ty.decl.name}" + (f"_{count + 1}" if count else "")
            body = "".join(f" {t} {n};" for n, t in fields)
        elif isinstance(ty, VectorTy):
            element = self.c(ty.element)
            name = f"vec{ty.size}_{self.short(ty.element)}"
            body = f" {element} v[{ty.size}];"
        elif isinstance(ty, MatrixTy):
            row = self.c(VectorTy(ty.element, ty.columns))
            name = f"mat{ty.rows}x{ty.columns}_{self.short(ty.element)}"
            body = f" {row} v[{ty.rows}];"
        elif isinstance(ty, TupleTy):
            items = [self.c(i) for i in ty.items]
            name = "tup_" + "_".join(self.short(i) for i in ty.items)
            body = "".join(f" {t} i{k + 1};" for k, t in enumerate(items))
        elif isinstance(ty, CollectionTy):
            element = self.c(ty.element)
            name = f"{ty.kind.lower()}_{self.short(ty.element)}"
            body = f" int32_t n; {element} v[{CAPACITY}];"
        else:
            raise CotwinError(f"values of type {ty} cannot be held by the generated C")
        self.names[ty] = name
        if name not in self._defined:  # int and nat elements share one representation
            self._defined.add(name)
            self.typedefs.append(f"typedef struct {name} {{{body} }} {name};")
        return name

    def short(self, ty: Ty) -> str:
        if ty == BOOL:
            return "b"
        if ty == REAL:
            return "r"
        if is_intlike(ty):
            return "i"
        return self.c(ty)

    def default(self, ty: Ty) -> str:
        """A C expression for the zero value of a type (0, 0.0, false, {0})."""
        if ty == BOOL:
            return "false"
        if ty == REAL:
            return "0.0"
        if is_intlike(ty):
            return "INT64_C(0)"
        return f"(({self.c(ty)}){{0}})"

    # ---- checks of untrusted bytes (a deserialised state) ----
    def check(self, ty: Ty, ref: str) -> str | None:
        """A C condition, true when the value at `ref` (an lvalue of type `ty` read from bytes of unknown
        origin) is one the generated code can run: every Boolean 0 or 1 and every set and sequence within
        its capacity, at any depth; None when any bytes are (numbers)."""
        if ty == BOOL:
            return f"bool_ok(&{ref})"
        if is_scalar(ty) or ty == UNKNOWN:
            return None
        name = self.check_function(ty)
        return f"{name}(&{ref})" if name else None

    def check_function(self, ty: Ty) -> str | None:
        t = self.c(ty)
        name = f"ok_{t}"
        if name in self._checks:
            return self._checks[name]
        self._checks[name] = None  # filled below; a type does not contain itself
        if isinstance(ty, RecordTy):
            parts = [self.check(ft, f"v->{ident(n)}") for n, ft in self.field_types(ty)]
            lines = [f"    if (!({c})) return false;" for c in parts if c]
        elif isinstance(ty, (VectorTy, MatrixTy)):
            element = ty.element if isinstance(ty, VectorTy) else VectorTy(ty.element, ty.columns)
            size = ty.size if isinstance(ty, VectorTy) else ty.rows
            inner = self.check(element, "v->v[k]")
            lines = [f"    for (int k = 0; k < {size}; k++) if (!({inner})) return false;"] if inner else []
        elif isinstance(ty, TupleTy):
            parts = [self.check(it, f"v->i{k + 1}") for k, it in enumerate(ty.items)]
            lines = [f"    if (!({c})) return false;" for c in parts if c]
        else:  # a set or sequence
            inner = self.check(ty.element, "v->v[k]")
            lines = [f"    if (v->n < 0 || v->n > {CAPACITY}) return false;"]
            if inner:
                lines.append(f"    for (int k = 0; k < v->n; k++) if (!({inner})) return false;")
        if not lines:
            return None
        self._checks[name] = name
        self.functions.append(f"static bool {name}(const {t} *v) {{\n" + "\n".join(lines) + "\n    return true;\n}")
        return name

    # ---- equality ----
    def eq(self, ty: Ty, a: str, b: str) -> str:
        if is_scalar(ty) or ty == UNKNOWN:
            return f"({a} == {b})"
        return f"{self.eq_function(ty)}({a}, {b})"

    def eq_function(self, ty: Ty) -> str:
        t = self.c(ty)
        name = f"eq_{t}"
        if name in self._helpers:
            return name
        self._helpers.add(name)
        if isinstance(ty, RecordTy):
            parts = [self.eq(ft, f"a.{ident(n)}", f"b.{ident(n)}") for n, ft in self.field_types(ty)]
            body = f"    return {' && '.join(parts) or 'true'};"
        elif isinstance(ty, VectorTy):
            body = (f"    for (int k = 0; k < {ty.size}; k++) if (!{self.eq(ty.element, 'a.v[k]', 'b.v[k]')}) return false;\n"
                    "    return true;")
        elif isinstance(ty, MatrixTy):
            row = VectorTy(ty.element, ty.columns)
            body = (f"    for (int k = 0; k < {ty.rows}; k++) if (!{self.eq(row, 'a.v[k]', 'b.v[k]')}) return false;\n"
                    "    return true;")
        elif isinstance(ty, TupleTy):
            parts = [self.eq(it, f"a.i{k + 1}", f"b.i{k + 1}") for k, it in enumerate(ty.items)]
            body = f"    return {' && '.join(parts)};"
        elif isinstance(ty, CollectionTy) and ty.kind == "Seq":
            body = ("    if (a.n != b.n) return false;\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{self.eq(ty.element, 'a.v[k]', 'b.v[k]')}) return false;\n"
                    "    return true;")
        else:  # a set: same elements
            has = self.set_has(ty)
            body = ("    if (a.n != b.n) return false;\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{has}(b, a.v[k])) return false;\n"
                    "    return true;")
        self.functions.append(f"static bool {name}({t} a, {t} b) {{\n{body}\n}}")
        return name

    def _helper(self, name: str, code: str) -> str:
        if name not in self._helpers:
            self._helpers.add(name)
            self.functions.append(code)
        return name

    # ---- sets and sequences ----
    def set_has(self, ty: CollectionTy) -> str:
        t = self.c(ty)
        e = self.c(ty.element)
        name = f"has_{t}"
        if name in self._helpers:
            return name
        test = self.eq(ty.element, "s.v[k]", "x")
        return self._helper(name, f"static bool {name}({t} s, {e} x) {{\n"
                                  f"    for (int k = 0; k < s.n; k++) if ({test}) return true;\n"
                                  "    return false;\n}")

    def add(self, ty: CollectionTy) -> str:
        """Append an element (to a set: unless it is there), failing beyond the capacity."""
        t = self.c(ty)
        e = self.c(ty.element)
        name = f"add_{t}"
        if name in self._helpers:
            return name
        kind = "set" if ty.kind == "Set" else "sequence"
        guard = f"    if ({self.set_has(ty)}(s, x)) return s;\n" if ty.kind == "Set" else ""
        return self._helper(name, f"static {t} {name}(Model *M, {t} s, {e} x, int at) {{\n{guard}"
                                  f"    if (s.n >= {CAPACITY}) {{ fail_at(M, at, \"{kind} exceeds cotwin's bound of "
                                  f"{CAPACITY} elements\"); return s; }}\n"
                                  "    s.v[s.n++] = x;\n    return s;\n}")

    def set_op(self, ty: CollectionTy, op: str) -> str:
        """union, inter, diff, symetric_diff."""
        t = self.c(ty)
        name = f"{op}_{t}"
        if name in self._helpers:
            return name
        has, add = self.set_has(ty), self.add(ty)
        if op == "union":
            body = ("    for (int k = 0; k < b.n && !M->status; k++) a = " + add + "(M, a, b.v[k], at);\n    return a;")
        elif op == "inter":
            body = (f"    {t} r = {{0}};\n"
                    f"    for (int k = 0; k < a.n; k++) if ({has}(b, a.v[k])) r.v[r.n++] = a.v[k];\n    return r;")
        elif op == "diff":
            body = (f"    {t} r = {{0}};\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{has}(b, a.v[k])) r.v[r.n++] = a.v[k];\n    return r;")
        else:  # symetric difference
            body = (f"    {t} r = {{0}};\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{has}(b, a.v[k])) r.v[r.n++] = a.v[k];\n"
                    f"    for (int k = 0; k < b.n && !M->status; k++) if (!{has}(a, b.v[k])) r = {add}(M, r, b.v[k], at);\n"
                    "    return r;")
        return self._helper(name, f"static {t} {name}(Model *M, {t} a, {t} b, int at) {{\n"
                                  "    (void)M; (void)at;\n" + body + "\n}")

    def subseteq(self, ty: CollectionTy) -> str:
        t = self.c(ty)
        name = f"subseteq_{t}"
        if name in self._helpers:
            return name
        has = self.set_has(ty)
        return self._helper(name, f"static bool {name}({t} a, {t} b) {{\n"
                                  f"    for (int k = 0; k < a.n; k++) if (!{has}(b, a.v[k])) return false;\n"
                                  "    return true;\n}")

    def set_range(self) -> str:
        ty = CollectionTy("Set", INT)
        t = self.c(ty)
        add = self.add(ty)
        return self._helper(f"range_{t}", f"static {t} range_{t}(Model *M, int64_t lo, int64_t hi, int at) {{\n"
                                          f"    {t} r = {{0}};\n"
                                          f"    for (int64_t k = lo; k <= hi && !M->status; k++) r = {add}(M, r, k, at);\n"
                                          "    return r;\n}")

    def seq_op(self, ty: CollectionTy, op: str) -> str:
        """cat, head, last, tail, front, reverse, prefix, suffix."""
        t = self.c(ty)
        e = self.c(ty.element)
        name = f"{op}_{t}"
        if name in self._helpers:
            return name
        empty = (f"    if (s.n == 0) {{ fail_at(M, at, \"{op}: {op} of an empty sequence\"); return "
                 f"{self.default(ty.element) if op in ('head', 'last') else 's'}; }}\n")
        if op == "cat":
            add = self.add(ty)
            code = (f"static {t} {name}(Model *M, {t} a, {t} b, int at) {{\n"
                    f"    for (int k = 0; k < b.n && !M->status; k++) a = {add}(M, a, b.v[k], at);\n    return a;\n}}")
        elif op in ("head", "last"):
            code = (f"static {e} {name}(Model *M, {t} s, int at) {{\n{empty}"
                    f"    return s.v[{'0' if op == 'head' else 's.n - 1'}];\n}}")
        elif op in ("tail", "front"):
            shift = ("    for (int k = 1; k < s.n; k++) s.v[k - 1] = s.v[k];\n" if op == "tail" else "")
            code = f"static {t} {name}(Model *M, {t} s, int at) {{\n{empty}{shift}    s.n--;\n    return s;\n}}"
        elif op == "reverse":
            code = (f"static {t} {name}({t} s) {{\n    {t} r = s;\n"
                    "    for (int k = 0; k < s.n; k++) r.v[k] = s.v[s.n - 1 - k];\n    return r;\n}")
        elif op == "prefix":
            code = (f"static bool {name}({t} a, {t} b) {{\n    if (a.n > b.n) return false;\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{self.eq(ty.element, 'a.v[k]', 'b.v[k]')}) return false;\n"
                    "    return true;\n}")
        elif op == "suffix":
            code = (f"static bool {name}({t} a, {t} b) {{\n    if (a.n > b.n) return false;\n"
                    f"    for (int k = 0; k < a.n; k++) if (!{self.eq(ty.element, 'a.v[k]', 'b.v[b.n - a.n + k]')}) return false;\n"
                    "    return true;\n}")
        else:  # pragma: no cover
            raise CotwinError(f"no sequence operation {op}")
        return self._helper(name, code)

    def big_op(self, ty: CollectionTy, op: str) -> str:
        """Union / Inter of a set of sets."""
        inner = ty.element
        t, it = self.c(ty), self.c(inner)
        name = f"{op}_{t}"
        if name in self._helpers:
            return name
        if op == "Union":
            union = self.set_op(inner, "union")
            body = (f"    {it} r = {{0}};\n"
                    f"    for (int k = 0; k < A.n && !M->status; k++) r = {union}(M, r, A.v[k], at);\n    return r;")
        else:
            inter = self.set_op(inner, "inter")
            body = (f"    {it} r = {{0}};\n    if (A.n == 0) return r;\n    r = A.v[0];\n"
                    f"    for (int k = 1; k < A.n; k++) r = {inter}(M, r, A.v[k], at);\n    return r;")
        return self._helper(name, f"static {it} {name}(Model *M, {t} A, int at) {{\n    (void)at;\n{body}\n}}")

    # ---- vectors and matrices ----
    def elementwise(self, ty: Ty, op: str) -> str:
        """a op b for two vectors or matrices of one type (+, -), with integer checks."""
        t = self.c(ty)
        name = f"{'add' if op == '+' else 'sub'}_{t}"
        if name in self._helpers:
            return name
        if isinstance(ty, MatrixTy):
            row = VectorTy(ty.element, ty.columns)
            inner = self.elementwise(row, op)
            loop = f"    for (int k = 0; k < {ty.rows}; k++) a.v[k] = {inner}(M, a.v[k], b.v[k], at);\n"
        else:
            cell = (f"ck_{'add' if op == '+' else 'sub'}(M, a.v[k], b.v[k], at)" if is_intlike(ty.element)
                    else f"a.v[k] {op} b.v[k]")
            loop = f"    for (int k = 0; k < {ty.size}; k++) a.v[k] = {cell};\n"
        return self._helper(name, f"static {t} {name}(Model *M, {t} a, {t} b, int at) {{\n    (void)M; (void)at;\n"
                                  f"{loop}    return a;\n}}")

    def scale(self, ty: Ty, scalar: Ty, op: str) -> str:
        """v * k (and k * v), v / k, -v for a vector or matrix v."""
        t = self.c(ty)
        k = self.c(scalar) if scalar is not None else "int64_t"
        name = f"{ {'*': 'mul', '/': 'div', 'neg': 'neg'}[op] }_{t}_{self.short(scalar) if scalar is not None else 'x'}"
        if name in self._helpers:
            return name
        if isinstance(ty, MatrixTy):
            row = VectorTy(ty.element, ty.columns)
            inner = self.scale(row, scalar, op)
            extra = ", x" if op != "neg" else ""
            loop = f"    for (int j = 0; j < {ty.rows}; j++) a.v[j] = {inner}(M, a.v[j]{extra}, at);\n"
        else:
            ints = is_intlike(ty.element) and (scalar is None or is_intlike(scalar))
            if op == "neg":
                cell = "ck_neg(M, a.v[j], at)" if ints else "-a.v[j]"
            elif op == "*":
                cell = "ck_mul(M, a.v[j], x, at)" if ints else "a.v[j] * x"
            else:
                cell = "ck_div(M, a.v[j], x, at)" if ints else "a.v[j] / (double)x"
            loop = f"    for (int j = 0; j < {ty.size}; j++) a.v[j] = {cell};\n"
        param = f", {k} x" if op != "neg" else ""
        return self._helper(name, f"static {t} {name}(Model *M, {t} a{param}, int at) {{\n    (void)M; (void)at;\n"
                                  f"{loop}    return a;\n}}")

    def product(self, left: MatrixTy, right: Ty, result: Ty) -> str:
        """Matrix times matrix or vector (sums of products, in order, as the interpreter adds them)."""
        a, b, r = self.c(left), self.c(right), self.c(result)
        name = f"prod_{a}_{b}"
        if name in self._helpers:
            return name
        ints = is_intlike(left.element) and is_intlike(right.element)
        zero = "INT64_C(0)" if ints else "0.0"
        if isinstance(right, VectorTy):
            acc = ("s = ck_add(M, s, ck_mul(M, a.v[i].v[k], b.v[k], at), at);" if ints
                   else "s = s + a.v[i].v[k] * b.v[k];")
            body = (f"    {r} r = {{0}};\n    for (int i = 0; i < {left.rows}; i++) {{\n"
                    f"        {self.c(result.element)} s = {zero};\n"
                    f"        for (int k = 0; k < {left.columns}; k++) {acc}\n        r.v[i] = s;\n    }}\n    return r;")
        else:
            acc = ("s = ck_add(M, s, ck_mul(M, a.v[i].v[k], b.v[k].v[j], at), at);" if ints
                   else "s = s + a.v[i].v[k] * b.v[k].v[j];")
            body = (f"    {r} r = {{0}};\n    for (int i = 0; i < {left.rows}; i++)\n"
                    f"        for (int j = 0; j < {right.columns}; j++) {{\n"
                    f"            {self.c(result.element)} s = {zero};\n"
                    f"            for (int k = 0; k < {left.columns}; k++) {acc}\n            r.v[i].v[j] = s;\n        }}\n"
                    "    return r;")
        return self._helper(name, f"static {r} {name}(Model *M, {a} a, {b} b, int at) {{\n    (void)M; (void)at;\n"
                                  f"{body}\n}}")

    def transpose(self, ty: MatrixTy) -> str:
        out = MatrixTy(ty.element, ty.columns, ty.rows)
        a, r = self.c(ty), self.c(out)
        return self._helper(f"transpose_{a}", f"static {r} transpose_{a}({a} a) {{\n    {r} r;\n"
                                              f"    for (int i = 0; i < {ty.rows}; i++)\n"
                                              f"        for (int j = 0; j < {ty.columns}; j++) r.v[j].v[i] = a.v[i].v[j];\n"
                                              "    return r;\n}")

    # ---- conversions (an int-valued structure where a real-valued one is expected) ----
    def convert(self, value: str, source: Ty, target: Ty) -> str:
        if target is None or source is None or target == UNKNOWN or source == UNKNOWN:
            return value
        if is_scalar(target) or is_scalar(source):
            if target == REAL and is_intlike(source):
                return f"((double){value})"
            return value
        if self.c(source) == self.c(target):
            return value
        s, t = self.c(source), self.c(target)
        name = f"conv_{s}_to_{t}"
        if name not in self._helpers:
            if isinstance(target, VectorTy):
                body = (f"    for (int k = 0; k < {target.size}; k++) r.v[k] = "
                        f"{self.convert('a.v[k]', source.element, target.element)};\n")
            elif isinstance(target, MatrixTy):
                row_s, row_t = VectorTy(source.element, source.columns), VectorTy(target.element, target.columns)
                body = (f"    for (int k = 0; k < {target.rows}; k++) r.v[k] = "
                        f"{self.convert('a.v[k]', row_s, row_t)};\n")
            elif isinstance(target, TupleTy):
                body = "".join(f"    r.i{k + 1} = {self.convert(f'a.i{k + 1}', si, ti)};\n"
                               for k, (si, ti) in enumerate(zip(source.items, target.items)))
            elif isinstance(target, CollectionTy):
                body = ("    r.n = a.n;\n"
                        f"    for (int k = 0; k < a.n; k++) r.v[k] = {self.convert('a.v[k]', source.element, target.element)};\n")
            elif isinstance(target, RecordTy):
                body = "".join(f"    r.{ident(n)} = a.{ident(n)};\n" for n, _ in self.field_types(target))
            else:  # pragma: no cover
                body = ""
            self._helper(name, f"static {t} {name}({s} a) {{\n    {t} r = {{0}};\n{body}    return r;\n}}")
        return f"{name}({value})"
