"""A mapping's quiet step in C, for the native loop (cotwin.cosim.native, issue 23).

A quiet step runs no operation: the platform moves for h (the endpoint's control loop, cotwin.mapping.native,
and MuJoCo's mj_step), the mirrored variables take the joints' positions and velocities, and the report
decides which input events occur (`Mapping.report` with nothing asked: an observation whenever its
definition holds, an answer when it comes to hold). This module spells that as C: every input event's
definition becomes a C function over the mapping's variables (`V`, doubles) and the simulator's sensor data,
with the same operators on the same doubles, so it decides what the generated Python decides
(cotwin.mapping.generated). A definition with a form it does not spell (a function other than abs, a
division, a value the event carries, ...) makes the whole mapping `unsupported`: the step then stays in
Python.
"""

from __future__ import annotations

from ..diagnostics import CotwinError
from ..robosim import syntax as s
from ..robosim.operators import MATH
from .runtime import Mapping, _MappingNames


#: cotwin's math functions (cotwin.robosim.operators.MATH) in C, giving what they give: a domain error or an
#: overflow NaN (Python raises, MATH returns NaN), min and max ignoring a NaN and otherwise Python's (the first
#: of two equals: -0.0 and 0.0 keep their order): name -> (C function, arguments)
C_FUNCTIONS = {"abs": ("fabs", 1), "min": ("m_min", 2), "max": ("m_max", 2), "sqrt": ("m_sqrt", 1), "sin": ("m_sin", 1),
               "cos": ("m_cos", 1), "tan": ("m_tan", 1), "asin": ("m_asin", 1), "acos": ("m_acos", 1),
               "atan": ("atan", 1), "atan2": ("atan2", 2), "exp": ("m_exp", 1), "log": ("m_log", 1)}
C_MATH = r"""
static double m_sqrt(double x) { return x < 0 ? NAN : sqrt(x); }
static double m_sin(double x) { return isinf(x) ? NAN : sin(x); }
static double m_cos(double x) { return isinf(x) ? NAN : cos(x); }
static double m_tan(double x) { return isinf(x) ? NAN : tan(x); }
static double m_asin(double x) { return (x < -1 || x > 1) ? NAN : asin(x); }
static double m_acos(double x) { return (x < -1 || x > 1) ? NAN : acos(x); }
static double m_exp(double x) { double r = exp(x); return (isinf(r) && isfinite(x)) ? NAN : r; }
static double m_log(double x) { return x <= 0 ? NAN : log(x); }
static double m_min(double a, double b) { return isnan(a) ? b : isnan(b) ? a : (b < a ? b : a); }
static double m_max(double a, double b) { return isnan(a) ? b : isnan(b) ? a : (b > a ? b : a); }
"""

MAX_PHYSICS = 20000  # physics steps of one native segment at most (Ctrl-C is heard between segments)


class Unsupported(Exception):
    """A form the C spelling does not cover (the reason)."""


class EventsInC:
    """The C of a mapping's input events: `source` defines `static void {prefix}events(const double *V,
    const double *SD, int *occ)`; `variables` lists what V holds (name or (name, index)) and `sensors` the
    sensor data indices, both fixed by the mapping and the simulator."""

    def __init__(self, mapping: Mapping, sensor_address: dict[str, int], prefix: str):
        self.mapping = mapping
        self.sensor_address = sensor_address
        self.variables: list = []
        self.prefix = prefix
        functions = []
        for k, event in enumerate(mapping.events.values()):
            if event.definition is not None:
                raise Unsupported(f"input event {event.name} carries a value")
            functions.append(self._event(k, event))
        calls = "\n".join(f"    occ[{k}] = {prefix}event{k}(V, SD);" for k in range(len(functions)))
        self.source = C_MATH + "\n".join(functions) + (f"\nstatic void {prefix}events(const double *V, const double *SD, int *occ) {{\n"
                                              f"{calls}\n}}\n")

    def slot(self, key) -> int:
        if key not in self.variables:
            self.variables.append(key)
        return self.variables.index(key)

    def _event(self, k: int, event) -> str:
        lines = [f"static int {self.prefix}event{k}(const double *V, const double *SD) {{"]
        local: set[str] = set()
        for var in event.model.variables:
            if var.init is not None:
                lines.append(f"    double L_{var.name} = {self.expr(var.init, local)};")
                local.add(var.name)
        if not event.conditions:
            lines.append("    return 0;")
        for condition in event.conditions:
            lines.append(f"    if (!({self.expr(condition, local)})) return 0;")
        if event.conditions:
            lines.append("    return 1;")
        lines.append("}")
        return "\n".join(lines)

    def expr(self, e: s.Expr, local: set[str]) -> str:
        method = getattr(self, f"_{type(e).__name__}", None)
        if method is None:
            raise Unsupported(f"{type(e).__name__} at {e.loc}")
        return method(e, local)

    def _Literal(self, e: s.Literal, local) -> str:
        value = e.value
        if value is True or value is False:
            return "1.0" if value else "0.0"
        if value.__class__ in (int, float):
            if value.__class__ is int and abs(value) > 2 ** 53:
                raise Unsupported(f"an integer beyond a double's at {e.loc}")
            return f"({float(value).hex()})" if value == value and abs(value) != float("inf") else _special(float(value))
        raise Unsupported(f"a literal {value!r:.20} at {e.loc}")

    def _Name(self, e: s.Name, local) -> str:
        if len(e.name.parts) > 1:
            try:
                return f"({float(self.mapping.enum_value(e.name)).hex()})"
            except CotwinError:
                raise Unsupported(f"the name {e.name} at {e.loc}") from None
        n = e.name.last
        if n in local:
            return f"L_{n}"
        if n not in self.mapping.declared:
            raise Unsupported(f"the name {n} at {e.loc}")
        return f"V[{self.slot(n)}]"

    def _FieldAccess(self, e: s.FieldAccess, local) -> str:
        key = _MappingNames.sensor_key(e)
        if key is None or key not in self.sensor_address:
            raise Unsupported(f"the reading {key} at {e.loc}")
        return f"SD[{self.sensor_address[key]}]"

    def _IndexAccess(self, e: s.IndexAccess, local) -> str:
        if not (isinstance(e.base, s.Name) and len(e.base.name.parts) == 1 and e.base.name.last not in local
                and e.base.name.last in self.mapping.declared and isinstance(e.index, s.Literal)
                and e.index.value.__class__ is int and e.index.value >= 0):
            raise Unsupported(f"an index at {e.loc}")
        return f"V[{self.slot((e.base.name.last, e.index.value))}]"

    def _Unary(self, e: s.Unary, local) -> str:
        operand = self.expr(e.operand, local)
        if e.op == "not":
            return f"(!({operand}) ? 1.0 : 0.0)"
        if e.op == "-":
            return f"(-({operand}))"
        raise Unsupported(f"the operator {e.op} at {e.loc}")

    def _Binary(self, e: s.Binary, local) -> str:
        left, right = self.expr(e.left, local), self.expr(e.right, local)
        if e.op == "/\\":
            return f"((({left}) != 0.0 && ({right}) != 0.0) ? 1.0 : 0.0)"
        if e.op == "\\/":
            return f"((({left}) != 0.0 || ({right}) != 0.0) ? 1.0 : 0.0)"
        if e.op == "=>":
            return f"((({left}) == 0.0 || ({right}) != 0.0) ? 1.0 : 0.0)"
        if e.op in ("<", "<=", ">", ">=", "==", "!="):
            return f"((({left}) {e.op} ({right})) ? 1.0 : 0.0)"
        if e.op in ("+", "-", "*"):
            return f"(({left}) {e.op} ({right}))"
        raise Unsupported(f"the operator {e.op} at {e.loc}")

    def _IfExpr(self, e: s.IfExpr, local) -> str:
        condition, then, otherwise = (self.expr(x, local) for x in (e.condition, e.then, e.otherwise))
        return f"((({condition}) != 0.0) ? ({then}) : ({otherwise}))"

    def _Call(self, e: s.Call, local) -> str:
        name = e.function.name.last if isinstance(e.function, s.Name) else None
        spelt = C_FUNCTIONS.get(name)
        if spelt is None or self.mapping.functions.get(name) is not MATH[name] or len(e.args) != spelt[1]:
            raise Unsupported(f"the function {name} at {e.loc}")
        return f"{spelt[0]}({', '.join(self.expr(a, local) for a in e.args)})"


def _special(value: float) -> str:
    if value != value:
        return "(0.0 / 0.0)"
    return "(1.0 / 0.0)" if value > 0 else "(-1.0 / 0.0)"


def variable_values(mapping: Mapping, variables: list) -> list[float] | None:
    """The values `EventsInC.variables` name, as doubles (None when one is not a plain number now)."""
    out = []
    for key in variables:
        name, index = (key, None) if isinstance(key, str) else key
        value = mapping.variables.get(name)
        if index is not None:
            if value.__class__ is str or not hasattr(value, "__len__") or index >= len(value):
                return None
            value = value[index]
        if value.__class__ not in (bool, int, float) or (value.__class__ is int and abs(value) > 2 ** 53):
            return None
        out.append(float(value))
    return out


def quiet_step(unit, execution, make_part, feeds: list[tuple[str, int]], out: dict[str, int]):
    """The MappingUnit's step for the native loop (`make_part(...)`: cotwin.cosim.native.NativePart, given by
    the caller, a layer above), or why it has none (a str). `feeds`: its inputs and the slots they are set
    from; `out`: its observed outputs and their slots."""
    import ctypes

    from . import native
    from .endpoint import SimulatedEndpoint

    mapping: Mapping = unit.mapping
    endpoint = mapping.endpoint
    if type(endpoint) is not SimulatedEndpoint:
        return f"its platform ({type(endpoint).__name__}) is not cotwin's simulated one"
    sim = endpoint.sim
    if not sim.plain_stepping:
        why = ("its world is shared with other robots" if sim.shared is not None else
               "its ray sensors scan between physics steps" if sim.scanners else
               "its contacts with obstacles are checked between physics steps" if sim._obstacles else
               f"its integrator ({sim.model.opt.integrator}) does not advance time by one timestep a step")
        return f"{why} (the native step is MuJoCo's steps and nothing between them)"
    if mapping.monitor:
        return "it monitors readings other than the joints"
    if native.advance_function() is None:
        return "the endpoint's control loop cannot be built here"
    sensor_address = {path: int(adr) for path, (adr, _) in sim._sensors.items()}
    try:
        events = EventsInC(mapping, sensor_address, "m_")
    except Unsupported as why:
        return f"an input event's definition has a form the C spelling does not cover: {why}"
    names = list(mapping.events)
    ports = [p.name for p in unit.event_ports]
    if any(p not in out for p in ports) or any(m not in out for m in mapping.monitored):
        return "an output of the mapping is not observed"
    mirrors = []  # (variable, qpos or qvel, address or None)
    for var, joint in mapping._mirror_q:
        mirrors.append((var, 4, sim._joint_qpos.get(joint)))
    for var, joint in mapping._mirror_qd:
        mirrors.append((var, 5, sim._joint_dof.get(joint)))
    E = len(names)
    HELD, CAME = 11, 11 + E
    VBASE = 11 + 2 * E
    layout = events.variables
    calls = {op for op, _ in unit.calls}
    op_slots = [slot for name, slot in feeds if name in calls]
    lines = [f"if ({' || '.join(f'IN({i}) != 0.0' for i in op_slots) or '0'}) PAUSE();  /* an operation to run */",
             "double *time = &DD[0];",
             "int steps = (int)DD[3], period = (int)DD[4];",
             "cotwin_mj_step mjstep = (cotwin_mj_step)PP[0];",
             "if (steps > 0 && DD[5] != 0.0 && DD[6] == 0.0) {",
             "    int held = 0, done = 0;",
             "    int status = cotwin_advance(mjstep, PP[1], PP[2], time, DD[1], DD[2], steps, period, (const double *)PP[7],",
             "        (int)DD[7], (const int *)PP[8], (const double *)PP[9], (const double *)PP[10], (const double *)PP[11],",
             "        (const double *)PP[12], (double *)PP[3], (const double *)PP[4], (int)DD[8], &held, &done);",
             "    DD[9] += done;",
             "    if (held) DD[6] = 1.0;",
             "    if (status != 0) FAIL(status);",
             "} else if (steps > 0) {",
             "    for (int s = 0; s < steps; s++) { mjstep(PP[1], PP[2]); *time += DD[2]; }",
             "    DD[9] += steps;",
             "    const double *q = (const double *)PP[4]; double sum = 0.0;",
             "    for (int s = 0; s < (int)DD[8]; s++) sum += q[s] * q[s];",
             "    if (!(sum - sum == 0.0)) FAIL(2);",
             "}",
             f"double *V = DD + {VBASE}; (void)V;"]
    for var, array, address in mirrors:
        value = f"((const double *)PP[{array}])[{address}]" if address is not None else "0.0"
        if var in layout:
            lines.append(f"V[{layout.index(var)}] = {value};")
        lines.append(f"N[{out[var]}] = {value};")
    lines.append(f"int occ[{max(1, E)}]; m_events(V, (const double *)PP[6], occ);")
    lines.append("int came = 0;")
    lines.append(f"double outs[{max(1, E)}];")
    for i, name in enumerate(names):
        if name in mapping.answers:
            lines.append(f"if (occ[{i}] && DD[{HELD + i}] == 0.0) DD[{CAME} + came++] = {i}; outs[{i}] = 0.0;")
        else:
            lines.append(f"outs[{i}] = occ[{i}] ? 1.0 : 0.0;")
        lines.append(f"DD[{HELD + i}] = occ[{i}] ? 1.0 : 0.0;")
    lines.append("if (came) outs[(int)DD[" + str(CAME) + "]] = 1.0;")
    lines.append("DD[10] = came;")
    for name in ports:
        lines.append(f"N[{out[name]}] = outs[{names.index(name)}];")
    decls = native.SOURCE + "\n" + events.source
    jacobi = execution.algorithm.name == "jacobi"
    data = execution.algorithm.data
    steps_per = sim.steps_for(execution.step_size)
    from .endpoint import CONTROL_PERIOD

    period = max(1, int(round(CONTROL_PERIOD / sim.timestep)))
    pointers: list = [0] * 13
    doubles: list = [0.0] * (VBASE + len(layout))
    state = {}

    def quiet(n: int) -> int:
        n = min(n, max(1, MAX_PHYSICS // max(1, steps_per)))  # a segment of at most about a tenth of a second
        if mapping.pending or mapping.asked or (jacobi and any(data[i] is True for i in op_slots)):
            return 0
        segment = endpoint.segment
        if segment is not None and segment is not endpoint._held and endpoint._moves(segment) is None:
            return 0
        values = variable_values(mapping, layout)
        if values is None:
            return 0
        state["values"] = values
        return n

    def begin() -> None:
        fn, mj_step = native.advance_function()
        segment = endpoint.segment
        moving = segment is not None and segment is not endpoint._held
        d = sim.data
        address = lambda array: ctypes.cast(array, ctypes.c_void_p).value  # noqa: E731
        pointers[:7] = [mj_step, sim.model._address, d._address, sim.controls.ctypes.data, d.qpos.ctypes.data,
                        d.qvel.ctypes.data, d.sensordata.ctypes.data]
        joints = 0
        if moving:
            arrays, joints = endpoint._native_plan
            pointers[7:13] = [address(a) for a in arrays]
            state["arrays"] = arrays  # alive while the C loop reads them
        else:
            pointers[7:13] = [0] * 6
        doubles[:11] = [float(d.time), float(sim.timestep), float(sim.model.opt.timestep), float(steps_per),
                        float(period), 1.0 if moving else 0.0, 0.0, float(joints), float(d.qpos.size), 0.0, 0.0]
        for i, name in enumerate(names):
            doubles[HELD + i] = 1.0 if mapping.held.get(name, (False, None))[0] else 0.0
            doubles[CAME + i] = 0.0
        doubles[VBASE:] = state["values"]
        state["moving"] = segment if moving else None

    def end(first: int, k: int, rows, dd) -> None:
        done = int(dd[9])
        if done:
            sim.stepped(done)  # counted, and checked as `step` checks (an unstable state raises here)
        if float(dd[0]) != sim.data.time:
            raise CotwinError(f"the native loop kept time {float(dd[0])!r}, MuJoCo {sim.data.time!r}")
        if state.get("moving") is not None and dd[6] != 0.0:
            endpoint._held = state["moving"]
        if not k:
            return
        mapping.reports += k
        for i, name in enumerate(names):
            ev = mapping.events[name]
            mapping.held[name] = (True, ev.value) if dd[HELD + i] != 0.0 else (False, None)
        came = [names[int(dd[CAME + j])] for j in range(int(dd[10]))]
        if came:
            mapping.delivered[came[0]] = mapping.reports
            for name in came[1:]:
                mapping.pending[name] = mapping.events[name].value
        mapping._sync()
        last = rows[-1]
        for name in ports:
            unit.values[name] = bool(last[out[name]] != 0.0)
        for name in mapping.monitored:
            unit.values[name] = float(last[out[name]])
        origin, done = execution._origin
        unit.time = origin + (first + k - 1 - done) * execution.step_size + execution.step_size

    def failed(code: int, t: float) -> None:
        if code == 2:
            sim._check()
        raise CotwinError(f"mapping {mapping.model.name} at t = {t:g} s: a servo set-point is not a finite number"
                          if code == 1 else f"mapping {mapping.model.name} at t = {t:g} s: the native step failed ({code})")

    return make_part("\n".join(lines), decls=decls, pointers=pointers, doubles=doubles, quiet=quiet, begin=begin,
                      end=end, failed=failed, continuous=tuple(mapping.monitored))
