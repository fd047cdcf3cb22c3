"""The mapping's input events as generated Python: each event's whole definition (its local `var`s, the
value it carries, its equations and predicates) becomes the source of one function, compiled once with
`compile()` when the mapping is made, instead of a tree of closures walked per step.

Why: the event report runs every event's definition after every step; at 1 kHz the closures' calls and
dict look-ups were a third of a step's time (issue 23). The generated code computes the same values with
the same operators (cotwin.robosim.operators, called where a value is not a plain float) and raises the
same located errors as `_Env.eval`; forms it does not spell fall back to the compiled closure of that
sub-expression (`_MappingCompiler`), so every mapping still runs. The source is deterministic (a function
of the mapping model alone) and kept in `source` for inspection and tests.
"""

from __future__ import annotations

import math
from typing import Callable

from .. import memo
from ..diagnostics import CotwinError, placed
from ..robosim import syntax as s
from ..robosim.evaluator import _call_name, index
from ..robosim.operators import BINARY, MATH, MATRIX_UNARY, negate
from ..robosim.values import (EvalError, FrozenRecord, MatrixValue, SeqValue, TupleValue, VectorValue, checked,
                              is_int)

_TUPLES = frozenset((tuple, VectorValue, MatrixValue, TupleValue, SeqValue, FrozenRecord))  # index reads these
_FLOAT_FAST = {"+": "+", "-": "-", "*": "*", "<": "<", "<=": "<=", ">": ">", ">=": ">="}  # float op float: Python's
_CAUGHT = (TypeError, ValueError, AttributeError, KeyError, IndexError)  # as _Env.eval turns them into errors


def _call(function, values: tuple, name: str, loc):
    """A registry function applied as the compiled closures apply it (errors located, int results checked)."""
    try:
        result = function(*values)
    except EvalError as err:
        raise EvalError(err.kind, f"{name}: {err.message}", err.loc or loc) from None
    except CotwinError as err:  # a function's own error (the IK's) names no place: its call is it
        raise placed(err, loc) from None
    except (TypeError, ValueError, OverflowError, ZeroDivisionError) as err:
        raise EvalError("domain", f"cannot evaluate {name}: {err}", loc) from None
    return checked(result, loc) if is_int(result) else result


class _Source:
    """Spells expressions as Python source over: `S` the local scope (a dict, as the closures see it), `V` the
    mapping's variables, `RT` the runtime (sensor readings), and constants bound by name in `names`."""

    def __init__(self, runtime, compiler):
        self.rt = runtime
        self.compiler = compiler  # _MappingCompiler: closures for the forms not spelt here
        self.names: dict[str, object] = {}
        self.temps = 0

    def bind(self, value, prefix: str = "_k") -> str:
        name = f"{prefix}{len(self.names)}"
        self.names[name] = value
        return name

    def temp(self) -> str:
        self.temps += 1
        return f"_t{self.temps}"

    def closure(self, e: s.Expr) -> str:
        """Fallback: the compiled closure of `e`, called with the scope dict."""
        return f"{self.bind(self.compiler.compile(e), '_c')}(S)"

    def expr(self, e: s.Expr, local: set[str]) -> str:
        method = getattr(self, f"_{type(e).__name__}", None)
        return method(e, local) if method is not None else self.closure(e)

    def _Literal(self, e: s.Literal, local):
        return self.bind(e.value)

    def _Name(self, e: s.Name, local):
        if len(e.name.parts) > 1:
            try:
                return self.bind(self.rt.enum_value(e.name))
            except CotwinError:
                return self.closure(e)  # an unknown name fails when evaluated, as before
        n = e.name.last
        if n in local:
            return f"S[{n!r}]"
        return f"(V[{n!r}] if {n!r} in V else _noval({n!r}, {self.bind(e.loc, '_l')}))"

    def _FieldAccess(self, e: s.FieldAccess, local):
        from .runtime import _MappingNames

        key = _MappingNames.sensor_key(e)
        if key is None:
            return self.closure(e)
        r = self.temp()
        return (f"({r}[{key!r}] if ({r} := RT._readings) is not None and {key!r} in {r} "
                f"else _sensor({key!r}, {self.bind(e.loc, '_l')}))")

    def _IndexAccess(self, e: s.IndexAccess, local):
        base, loc = self.expr(e.base, local), self.bind(e.loc, "_l")
        b = self.temp()
        if isinstance(e.index, s.Literal) and is_int(e.index.value) and e.index.value >= 0:
            k = e.index.value
            return f"({b}[{k}] if ({b} := {base}).__class__ in _TUPLES and len({b}) > {k} else _index({b}, {k}, {loc}, 0))"
        return f"_index({base}, {self.expr(e.index, local)}, {loc}, 0)"

    def _Unary(self, e: s.Unary, local):
        operand = self.expr(e.operand, local)
        if e.op == "not":
            return f"(not {operand})"
        loc = self.bind(e.loc, "_l")
        if e.op in MATRIX_UNARY:
            return f"{self.bind(MATRIX_UNARY[e.op], '_f')}({operand}, {loc})"
        t = self.temp()
        return f"(-{t} if ({t} := {operand}).__class__ is float else _negate({t}, {loc}))"

    def _Binary(self, e: s.Binary, local):
        left, right = self.expr(e.left, local), self.expr(e.right, local)
        if e.op == "/\\":
            return f"(bool({left}) and bool({right}))"
        if e.op == "\\/":
            return f"(bool({left}) or bool({right}))"
        if e.op == "=>":
            return f"((not {left}) or bool({right}))"
        if e.op in ("==", "!="):  # operators.equal / unequal: Python's, whatever the values
            return f"({left} {e.op} {right})"
        operator = BINARY.get(e.op)
        if operator is None:
            return self.closure(e)
        run, loc = self.bind(operator.python, "_f"), self.bind(e.loc, "_l")
        if e.op in _FLOAT_FAST:
            a, b = self.temp(), self.temp()
            return (f"(({a} {_FLOAT_FAST[e.op]} {b}) if (({a} := {left}).__class__ is float) & "
                    f"(({b} := {right}).__class__ is float) else {run}({a}, {b}, {loc}))")
        return f"{run}({left}, {right}, {loc})"

    def _Call(self, e: s.Call, local):
        name = e.function.name.last if isinstance(e.function, s.Name) else None
        function = self.rt.functions.get(name) if name is not None else None
        if function is None:
            return self.closure(e)  # an unknown function fails when called, as before
        args = [self.expr(a, local) for a in e.args]
        f, label, loc = self.bind(function, "_f"), self.bind(_call_name(e), "_n"), self.bind(e.loc, "_l")
        generic = f"_call({f}, ({', '.join(args)}{',' if len(args) == 1 else ''}), {label}, {loc})"
        if function is MATH["abs"] and len(args) == 1:
            t = self.temp()
            return f"(abs({t}) if ({t} := {args[0]}).__class__ is float else _call({f}, ({t},), {label}, {loc}))"
        return generic


def event_source(event, compiler) -> tuple[str, dict[str, object]]:
    """The source of `occurs()` for this InputEvent and the names it reads (see the module doc)."""
    rt, model = event.runtime, event.model
    spell = _Source(rt, compiler)
    locs: list[object] = []
    lines = ["def occurs():", "    V = RT.variables", "    S = {}", "    at = 0", "    try:"]
    local: set[str] = set()

    def at(e: s.Expr) -> None:
        lines.append(f"        at = {len(locs)}")
        locs.append(e.loc)

    for var in model.variables:
        if var.init is not None:
            at(var.init)
            lines.append(f"        S[{var.name!r}] = {spell.expr(var.init, local)}")
            local.add(var.name)
    if event.definition is not None:
        at(event.definition)
        lines.append(f"        value = {spell.expr(event.definition, local)}")
        lines.append("        if isinstance(value, float) and not _isfinite(value):")
        lines.append("            return False")
        lines.append(f"        S[{model.bind!r}] = value")
        lines.append("        EVENT.value = value")
        local.add(model.bind)
    elif not event.conditions:
        lines.append("        return False")
    for condition in event.conditions:
        at(condition)
        lines.append(f"        if not {spell.expr(condition, local)}:")
        lines.append("            return False")
    lines.append("        return True")
    lines += ["    except _EvalError as err:",
              "        raise _CotwinError(f'{err.loc or _LOCS[at]}: {err.message}') from None",
              "    except _CAUGHT as err:",
              "        raise _CotwinError(f'{_LOCS[at]}: the expression cannot be evaluated: {err}') from None"]
    names = {**spell.names, "_LOCS": tuple(locs)}
    return "\n".join(lines) + "\n", names


def compile_event(event, compiler) -> Callable[[], bool]:
    """The event's `occurs` as one generated function (its source in `occurs.source`)."""
    rt = event.runtime
    source, names = event_source(event, compiler)
    namespace = {"RT": rt, "EVENT": event, "_TUPLES": _TUPLES, "_index": index, "_negate": negate, "_call": _call,
                 "_isfinite": math.isfinite, "_EvalError": EvalError, "_CotwinError": CotwinError, "_CAUGHT": _CAUGHT,
                 "_sensor": rt.sensor, "_noval": _no_value, "__builtins__": __builtins__, **names}
    code = memo.code(source, f"<mapping {rt.model.name}: input event {event.name}>")
    exec(code, namespace)  # noqa: S102 - source generated above from the checked mapping model
    occurs = namespace["occurs"]
    occurs.source = source
    return occurs


def _no_value(name: str, loc):
    raise CotwinError(f"{loc}: '{name}' has no value")
