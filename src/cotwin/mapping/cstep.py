"""A mapping's quiet step in C, for the native loop (cotwin.cosim.native, issue 23): `QuietStep`.

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

import ctypes
from dataclasses import dataclass

from ..diagnostics import CotwinError
from ..pmodel import memo
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
    const double *SD, int *occ)`; `variables` lists what V holds (name or (name, index)) and `kinds` the
    kind of value each held when spelt ('r' real, 'i' integer or enumeration, 'b' boolean: `variable_values`
    refuses a value of another kind later), `sensor_address` the sensor data indices.

    Every expression is spelt with its kind, so that the C computes what Python computes: reals and
    integers up to 2^53 are the same doubles, comparisons and logic the same; integer arithmetic (exact in
    Python, checked against overflow) and arithmetic on booleans (an error in Python) are not spelt."""

    def __init__(self, mapping: Mapping, sensor_address: dict[str, int], prefix: str):
        self.mapping = mapping
        self.sensor_address = sensor_address
        self.variables: list = []
        self.kinds: list[str] = []
        self.prefix = prefix
        functions = []
        for k, event in enumerate(mapping.events.values()):
            if event.definition is not None:
                raise Unsupported(f"input event {event.name} carries a value")
            functions.append(self._event(k, event))
        calls = "\n".join(f"    occ[{k}] = {prefix}event{k}(V, SD);" for k in range(len(functions)))
        self.source = (C_MATH + "\n".join(functions) +
                       f"\nstatic void {prefix}events(const double *V, const double *SD, int *occ) {{\n{calls}\n}}\n")

    def slot(self, key, value, loc) -> tuple[str, str]:
        """V[k] for a variable (or a vector's element) and its kind, from the value it holds now."""
        kind = _KINDS.get(value.__class__)
        if kind is None:
            raise Unsupported(f"{key if isinstance(key, str) else '%s[%d]' % key} holds {type(value).__name__} at {loc}")
        if key not in self.variables:
            self.variables.append(key)
            self.kinds.append(kind)
        return f"V[{self.variables.index(key)}]", kind

    def _event(self, k: int, event) -> str:
        lines = [f"static int {self.prefix}event{k}(const double *V, const double *SD) {{"]
        local: dict[str, str] = {}  # the event's own variables and their kinds
        for var in event.model.variables:
            if var.init is not None:
                code, kind = self.expr(var.init, local)
                lines.append(f"    double L_{var.name} = {code};")
                local[var.name] = kind
        if not event.conditions:
            lines.append("    return 0;")
        for condition in event.conditions:
            lines.append(f"    if (!({self.expr(condition, local)[0]})) return 0;")
        if event.conditions:
            lines.append("    return 1;")
        lines.append("}")
        return "\n".join(lines)

    def expr(self, e: s.Expr, local: dict[str, str]) -> tuple[str, str]:
        """The C of `e` and its kind ('r', 'i' or 'b'); Unsupported for a form not spelt."""
        method = getattr(self, f"_{type(e).__name__}", None)
        if method is None:
            raise Unsupported(f"{type(e).__name__} at {e.loc}")
        return method(e, local)

    def _Literal(self, e: s.Literal, local):
        value = e.value
        if value is True or value is False:
            return ("1.0" if value else "0.0"), "b"
        if value.__class__ in (int, float):
            if value.__class__ is int and abs(value) > 2 ** 53:
                raise Unsupported(f"an integer beyond a double's at {e.loc}")
            number = float(value)
            code = f"({number.hex()})" if number == number and abs(number) != float("inf") else _special(number)
            return code, _KINDS[value.__class__]
        raise Unsupported(f"a literal {value!r:.20} at {e.loc}")

    def _Name(self, e: s.Name, local):
        if len(e.name.parts) > 1:
            try:
                return f"({float(self.mapping.enum_value(e.name)).hex()})", "i"
            except CotwinError:
                raise Unsupported(f"the name {e.name} at {e.loc}") from None
        n = e.name.last
        if n in local:
            return f"L_{n}", local[n]
        if n not in self.mapping.declared:
            raise Unsupported(f"the name {n} at {e.loc}")
        return self.slot(n, self.mapping.variables.get(n), e.loc)

    def _FieldAccess(self, e: s.FieldAccess, local):
        key = _MappingNames.sensor_key(e)
        if key is None or key not in self.sensor_address:
            raise Unsupported(f"the reading {key} at {e.loc}")
        return f"SD[{self.sensor_address[key]}]", "r"

    def _IndexAccess(self, e: s.IndexAccess, local):
        if not (isinstance(e.base, s.Name) and len(e.base.name.parts) == 1 and e.base.name.last not in local
                and e.base.name.last in self.mapping.declared and isinstance(e.index, s.Literal)
                and e.index.value.__class__ is int and e.index.value >= 0):
            raise Unsupported(f"an index at {e.loc}")
        name, index = e.base.name.last, e.index.value
        try:
            value = self.mapping.variables.get(name)[index]
        except (TypeError, IndexError, KeyError):
            raise Unsupported(f"the index {name}[{index}] at {e.loc}") from None
        return self.slot((name, index), value, e.loc)

    def _Unary(self, e: s.Unary, local):
        operand, kind = self.expr(e.operand, local)
        if e.op == "not":
            return f"(!({operand}) ? 1.0 : 0.0)", "b"
        if e.op == "-" and kind != "b":
            return f"(-({operand}))", kind
        raise Unsupported(f"the operator {e.op} on {_NAMES[kind]} at {e.loc}")

    def _Binary(self, e: s.Binary, local):
        (left, a), (right, b) = self.expr(e.left, local), self.expr(e.right, local)
        if e.op == "/\\":
            return f"((({left}) != 0.0 && ({right}) != 0.0) ? 1.0 : 0.0)", "b"
        if e.op == "\\/":
            return f"((({left}) != 0.0 || ({right}) != 0.0) ? 1.0 : 0.0)", "b"
        if e.op == "=>":
            return f"((({left}) == 0.0 || ({right}) != 0.0) ? 1.0 : 0.0)", "b"
        if e.op in ("==", "!=") or (e.op in ("<", "<=", ">", ">=") and "b" not in (a, b)):
            return f"((({left}) {e.op} ({right})) ? 1.0 : 0.0)", "b"
        if e.op in ("+", "-", "*") and "b" not in (a, b) and (a, b) != ("i", "i"):
            return f"(({left}) {e.op} ({right}))", "r"  # a real among them: Python's float arithmetic too
        raise Unsupported(f"the operator {e.op} on {_NAMES[a]} and {_NAMES[b]} at {e.loc}")

    def _IfExpr(self, e: s.IfExpr, local):
        (condition, _), (then, a), (otherwise, b) = (self.expr(x, local) for x in (e.condition, e.then, e.otherwise))
        kind = a if a == b else "i" if "b" not in (a, b) else None  # an integer maybe: no integer arithmetic on it
        if kind is None:
            raise Unsupported(f"an if whose branches are a boolean and a number at {e.loc}")
        return f"((({condition}) != 0.0) ? ({then}) : ({otherwise}))", kind

    def _Call(self, e: s.Call, local):
        name = e.function.name.last if isinstance(e.function, s.Name) else None
        spelt = C_FUNCTIONS.get(name)
        if spelt is None or self.mapping.functions.get(name) is not MATH[name] or len(e.args) != spelt[1]:
            raise Unsupported(f"the function {name} at {e.loc}")
        args = [self.expr(a, local) for a in e.args]
        if any(kind == "b" for _, kind in args):
            raise Unsupported(f"the function {name} of a boolean at {e.loc}")
        return f"{spelt[0]}({', '.join(code for code, _ in args)})", "r"


_KINDS = {bool: "b", int: "i", float: "r"}
_NAMES = {"b": "a boolean", "i": "an integer (exact in Python, not in a double)", "r": "a real"}


def _special(value: float) -> str:
    if value != value:
        return "(0.0 / 0.0)"
    return "(1.0 / 0.0)" if value > 0 else "(-1.0 / 0.0)"


@dataclass(frozen=True)
class SpeltEvents:
    """What EventsInC made of a mapping's events: its C `source`, the `variables` V holds and their `kinds`."""
    source: str
    variables: tuple
    kinds: tuple[str, ...]


def events_in_c(mapping: Mapping, sensor_address: dict[str, int], prefix: str) -> SpeltEvents:
    """EventsInC's result, made once per mapping model, sensor layout and kinds of the variables' values (a run,
    a what-if and a sweep's plans of one twin spell the same C), or Unsupported."""
    from ..memo import once_per

    kinds = tuple((name, value.__class__.__name__, tuple(v.__class__.__name__ for v in value)
                   if value.__class__ in (list, tuple) else None) for name, value in sorted(mapping.variables.items()))
    key = (kinds, tuple(sorted(sensor_address.items())), prefix)
    spelt = once_per(mapping.model, "events in C", dict)
    if key not in spelt:
        try:
            made = EventsInC(mapping, sensor_address, prefix)
            spelt[key] = SpeltEvents(made.source, tuple(made.variables), tuple(made.kinds))
        except Unsupported as why:
            spelt[key] = why
    if isinstance(spelt[key], Unsupported):
        raise Unsupported(str(spelt[key]))
    return spelt[key]


def variable_values(mapping: Mapping, variables: list, kinds: list[str]) -> list[float] | None:
    """The values `EventsInC.variables` name, as doubles; None when one is no longer of the kind it was
    spelt for, or an integer beyond 2^53 (then the step stays in Python, which says what is wrong)."""
    out = []
    for key, kind in zip(variables, kinds):
        name, index = (key, None) if isinstance(key, str) else key
        value = mapping.variables.get(name)
        if index is not None:
            try:
                value = value[index] if value.__class__ is not str else None
            except (TypeError, IndexError, KeyError):
                return None
        if _KINDS.get(value.__class__) != kind or (kind == "i" and abs(value) > 2 ** 53):
            return None
        out.append(float(value))
    return out


# The step's doubles (DD): these scalars, then per input event whether it held at the last step and the
# answers that came in it and whether each was asked anew (by an operation run before the segment's first step),
# then the variables the events read (EventsInC.variables). MADE counts the segment's steps; DELIVERED is the
# first answer delivered in it (-1: none) and DELIVERED_AT the step (MADE) it came in; ACTED: Python ran the
# operations called before the first step (Mapping.act), which the step then does not pause for.
TIME, TIMESTEP, PHYSICS_TIMESTEP, STEPS, PERIOD, MOVING, MOVE_HELD, JOINTS, NQ, DONE, CAME, DEPTH, MADE, DELIVERED, \
    DELIVERED_AT, ACTED = range(16)
SCALARS = 16
# Its pointers (PP): MuJoCo's mj_step, model and data, the data's arrays, the held steps' memo (cotwin.pmodel.memo,
# or none), the move's arrays (cotwin.mapping.native)
MJ_STEP, MODEL, DATA, CTRL, QPOS, QVEL, SENSORDATA, WATCH, MEMO, FLAGS, MOVE = range(11)  # WATCH: the watched geoms
# (a mask); FLAGS: the model's opt.disableflags, for sensors computed in a stretch's last step (cotwin.pmodel.sensing)
POINTERS = MOVE + 6  # the move: shape, joints' control indices, starts, deltas, lows, highs


class QuietStep:
    """A mapping's quiet step for the native loop (see the module doc), for a unit whose operation calls come
    in at `op_slots`, whose events go out at `event_slots` (event -> slot) and monitored variables at
    `monitored_slots`; `why` says why there is none (then the rest is not set)."""

    def __init__(self, mapping: Mapping, step_size: float, op_slots: list[int], event_slots: dict[str, int],
                 monitored_slots: dict[str, int]):
        from . import native
        from .endpoint import CONTROL_PERIOD, SimulatedEndpoint

        self.mapping = mapping
        self.why: str | None = None
        endpoint = self.endpoint = mapping.endpoint
        if type(endpoint) is not SimulatedEndpoint:
            self.why = f"its platform ({type(endpoint).__name__}) is not cotwin's simulated one"
            return
        sim = self.sim = endpoint.sim
        if not sim.plain_stepping:
            why = ("its world is shared with other robots" if sim.shared is not None else
                   "its ray sensors scan between physics steps" if sim.scanners else
                   "its contacts with obstacles are checked between physics steps" if sim.obstacles else
                   f"its integrator ({sim.model.opt.integrator}) does not advance time by one timestep a step")
            self.why = f"{why} (the native step is MuJoCo's steps and nothing between them)"
            return
        if mapping.monitor:
            self.why = "it monitors readings other than the joints"
            return
        if native.advance_function() is None:
            self.why = "the endpoint's control loop cannot be built here (no C compiler?)"
            return
        try:
            self.events = events_in_c(mapping, sim.sensor_addresses(), "m_")
        except Unsupported as why:
            self.why = f"an input event's definition has a form the C spelling does not cover: {why}"
            return
        self.names = list(mapping.events)
        self.op_slots = list(op_slots)
        self.steps = sim.steps_for(step_size)
        self.period = max(1, int(round(CONTROL_PERIOD / sim.timestep)))
        E = len(self.names)
        self.held_at, self.came_at, self.again_at = SCALARS, SCALARS + E, SCALARS + 2 * E
        self.variables_at = SCALARS + 3 * E
        self.pointers: list = [0] * POINTERS
        self.doubles: list = [0.0] * (self.variables_at + len(self.events.variables))
        self.headers = mujoco_headers()
        self.decls = native.SOURCE + "\n" + memo.SOURCE + "\n" + self.events.source + (self.headers[1] if self.headers else "")
        self.lines = self._lines(event_slots, monitored_slots)
        self._values: list[float] = []
        self._move = None
        self._addressed: tuple | None = None  # (model, data, controls, watch, memo) `pointers` has addresses of
        self._arrays = None  # the move's arrays `pointers` has the addresses of (None: no move)
        self._zeros = [0.0] * E
        self._acted = False  # Python ran the operations called before the next segment
        self.calling = False  # (Jacobi) an operation is called, which Python runs before the next segment
        self.refusal = ""  # why `quiet` last said 0

    def _lines(self, event_slots: dict[str, int], monitored_slots: dict[str, int]) -> list[str]:
        """One quiet step in C (inside the native loop's step: IN, N, PP, DD, FAIL, PAUSE, END_AFTER)."""
        sim, layout, mapping = self.sim, self.events.variables, self.mapping
        ops = " || ".join(f"IN({i}) != 0.0" for i in self.op_slots) or "0"
        lines = [f"if (({ops}) && DD[{ACTED}] == 0.0) PAUSE();  /* an operation to run: Python runs it */",
                 f"DD[{ACTED}] = 0.0;",
                 f"DD[{MADE}] += 1.0;",
                 f"double *time = &DD[{TIME}];",
                 f"int steps = (int)DD[{STEPS}], period = (int)DD[{PERIOD}];",
                 f"cotwin_mj_step mjstep = (cotwin_mj_step)PP[{MJ_STEP}];",
                 f"if (steps > 0 && DD[{MOVING}] != 0.0 && DD[{MOVE_HELD}] == 0.0) {{  /* a move: its set-points */",
                 "    int held = 0, done = 0;",
                 f"    int status = cotwin_advance(mjstep, PP[{MODEL}], PP[{DATA}], time, DD[{TIMESTEP}], "
                 f"DD[{PHYSICS_TIMESTEP}], steps, period,",
                 f"        (const double *)PP[{MOVE}], (int)DD[{JOINTS}], (const int *)PP[{MOVE + 1}], "
                 f"(const double *)PP[{MOVE + 2}],",
                 f"        (const double *)PP[{MOVE + 3}], (const double *)PP[{MOVE + 4}], (const double *)PP[{MOVE + 5}],",
                 f"        (double *)PP[{CTRL}], (const double *)PP[{QPOS}], (int)DD[{NQ}], &held, &done, (int *)PP[{FLAGS}]);",
                 f"    DD[{DONE}] += done;",
                 f"    if (held) DD[{MOVE_HELD}] = 1.0;",
                 "    if (status != 0) FAIL(status);  /* 1: a set-point not finite; 2: the state not finite */",
                 "} else if (steps > 0) {  /* the servos hold: the physics steps in one go, then the check */",
                 f"    cotwin_held(mjstep, PP[{MODEL}], PP[{DATA}], steps, (cotwin_memo *)PP[{MEMO}], (int *)PP[{FLAGS}]);",
                 f"    for (int s = 0; s < steps; s++) *time += DD[{PHYSICS_TIMESTEP}];",
                 f"    DD[{DONE}] += steps;",
                 f"    const double *q = (const double *)PP[{QPOS}]; double sum = 0.0;",
                 f"    for (int s = 0; s < (int)DD[{NQ}]; s++) sum += q[s] * q[s];",
                 "    if (!(sum - sum == 0.0)) FAIL(2);",
                 "}",
                 *([f"if (PP[{WATCH}] && m_contact(PP[{DATA}], (const unsigned char *)PP[{WATCH}], DD[{DEPTH}])) "
                    "END_AFTER();  /* a watched contact: the step is seen whole */"] if self.headers else []),
                 f"double *V = DD + {self.variables_at}; (void)V;"]
        for var, (joint, kind) in mapping.mirrors.items():
            address = sim.joint_address(joint, kind)
            value = f"((const double *)PP[{QPOS if kind == 'position' else QVEL}])[{address}]" \
                if address is not None else "0.0"
            if var in layout:
                lines.append(f"V[{layout.index(var)}] = {value};")
            lines.append(f"N[{monitored_slots[var]}] = {value};")
        E = len(self.names)
        lines += [f"int occ[{max(1, E)}]; m_events(V, (const double *)PP[{SENSORDATA}], occ);",
                  f"int came = 0; double outs[{max(1, E)}];"]
        for i, name in enumerate(self.names):  # Mapping.report: the answers asked anew first, then those that came
            if name in mapping.answers:
                lines.append(f"if (occ[{i}] && DD[{self.again_at + i}] != 0.0) DD[{self.came_at} + came++] = {i};")
        for i, name in enumerate(self.names):
            if name in mapping.answers:
                lines.append(f"if (occ[{i}] && DD[{self.again_at + i}] == 0.0 && DD[{self.held_at + i}] == 0.0) "
                             f"DD[{self.came_at} + came++] = {i}; outs[{i}] = 0.0; DD[{self.again_at + i}] = 0.0;")
            else:
                lines.append(f"outs[{i}] = occ[{i}] ? 1.0 : 0.0;")
            lines.append(f"DD[{self.held_at + i}] = occ[{i}] ? 1.0 : 0.0;")
        lines += [f"if (came) {{ outs[(int)DD[{self.came_at}]] = 1.0;  /* the first answer delivered */",
                  f"    if (DD[{DELIVERED}] < 0.0) {{ DD[{DELIVERED}] = DD[{self.came_at}]; DD[{DELIVERED_AT}] = DD[{MADE}]; }}",
                  "    if (came > 1) END_AFTER(); else END_NEXT(); }  /* others wait for Python; else the reply is seen",
                  "                                                      whole, with the mapping as it left it */",
                  f"DD[{CAME}] = came;"]
        lines += [f"N[{slot}] = outs[{self.names.index(name)}];" for name, slot in event_slots.items()]
        return lines

    def quiet(self, n: int, data: list, jacobi: bool) -> int:
        """How many of the next n steps the mapping can make natively now: none while an answer waits or an
        operation was asked (its report not made yet), when the move in flight cannot run in C or a variable the
        events read is not a plain number; at most about 20 000 physics steps. `calling`: (Jacobi) an operation is
        called, which Python runs before the first step (Mapping.act, then `acted`)."""
        mapping = self.mapping
        self.calling = jacobi and any(data[i] is True for i in self.op_slots)
        if mapping.asked:
            self.refusal = "an operation runs or an answer waits"
            return 0
        if self.sim.contact_watch is not None and not self.headers:
            self.refusal = "its contacts are watched after each step and MuJoCo's C headers are not installed"
            return 0
        if not self._goes_on():
            return 0
        return min(n, max(1, MAX_PHYSICS // max(1, self.steps)))

    def acted(self) -> bool:
        """After Python ran the operations called (before the segment's first step): whether the segment can go on
        in C; its first step then reports the answers the operations asked anew."""
        self._acted = self._goes_on()
        return self._acted

    def _goes_on(self) -> bool:
        """Whether the C can make the mapping's next steps as it is now: no answer waits, the move in flight runs in
        C, the variables the events read are plain numbers (kept for `begin`); else `refusal` says why not."""
        mapping = self.mapping
        if mapping.pending:
            self.refusal = "an operation runs or an answer waits"
            return False
        if self.endpoint.native_move() is False:
            self.refusal = "the move in flight cannot run in C"
            return False
        values = variable_values(mapping, self.events.variables, self.events.kinds)
        if values is None:
            self.refusal = "a variable its events read is no longer a number of its kind a double carries exactly"
            return False
        self._values = values
        return True

    @property
    def ready(self) -> str:
        """The C condition a step starts on (Jacobi, NativePart.ready): no operation called, unless Python ran it
        before the segment's first step (ACTED); "" where nothing is called."""
        ops = " || ".join(f"IN({i}) != 0.0" for i in self.op_slots)
        return f"!(({ops}) && DD[{ACTED}] == 0.0)" if ops else ""

    def begin(self) -> None:
        """The pointers and doubles of the segment about to run (after `quiet`, and `acted` where operations ran)."""
        sim, mapping = self.sim, self.mapping
        move = self.endpoint.native_move()
        d = sim.data
        watch = sim.contact_watch
        joints, arrays = (move[2], move[1]) if move else (0, None)
        addressed = self._addressed  # the objects whose addresses `pointers` holds: looked up again when one changed
        if addressed is None or addressed[0] is not sim.model or addressed[1] is not d or \
                addressed[2] is not sim.controls or addressed[3] is not watch or addressed[4] is not sim.memo:
            from . import native

            _, mj_step = native.advance_function()
            self.pointers[:MOVE] = [mj_step, sim.model._address, d._address, sim.controls.ctypes.data,
                                    d.qpos.ctypes.data, d.qvel.ctypes.data, d.sensordata.ctypes.data,
                                    watch[0].ctypes.data if watch is not None else 0,
                                    sim.memo.address if sim.memo is not None else 0, 0]
            self._addressed = (sim.model, d, sim.controls, watch, sim.memo)
        if arrays is not self._arrays:  # a move of its own arrays (each plan's): their addresses
            self.pointers[MOVE:] = [ctypes.addressof(a) for a in arrays] if move else [0] * (POINTERS - MOVE)
            self._arrays = arrays
        self.pointers[FLAGS] = sim.sensor_flags() or 0  # asked per stretch: sensors the user turned off stay off
        if sim.memo is not None:
            sim.memo.check(sim.model)  # its stretches were of this model's numbers (cotwin.pmodel.memo)
        self._watch = watch  # kept: its mask stays alive while the C loop reads it
        self._move = move or None  # kept: its arrays stay alive while the C loop reads them
        doubles, names, E = self.doubles, self.names, len(self.names)
        doubles[:SCALARS] = [float(d.time), float(sim.timestep), float(sim.model.opt.timestep), float(self.steps),
                             float(self.period), 1.0 if move else 0.0, 0.0, float(joints), float(d.qpos.size),
                             0.0, 0.0, -watch[1] if watch is not None else 0.0, 0.0, -1.0, 0.0,
                             1.0 if self._acted else 0.0]
        held = mapping.held
        doubles[self.held_at:self.came_at] = [1.0 if name in held and held[name][0] else 0.0 for name in names]
        doubles[self.came_at:self.again_at] = self._zeros
        requested = mapping.asked  # the variables an operation just assigned: answers reading them are asked anew
        events = mapping.events
        doubles[self.again_at:self.again_at + E] = [0.0 if events[name].reads.isdisjoint(requested) else 1.0
                                                   for name in names] if requested else self._zeros
        self._acted = False
        doubles[self.variables_at:] = self._values

    def end(self, made: int, dd) -> None:
        """The mapping and its platform after `made` steps made natively (dd: the doubles they left)."""
        sim = self.sim
        dd = dd.tolist()  # Python floats: read many times, each numpy read makes a scalar
        self.endpoint.stepped_natively(int(dd[DONE]), self._move[0] if self._move and dd[MOVE_HELD] != 0.0 else None)
        if dd[TIME] != sim.data.time:
            raise CotwinError(f"the native loop kept time {dd[TIME]!r}, MuJoCo {sim.data.time!r}")
        if made:
            held_at, came_at = self.held_at, self.came_at
            held = {name: dd[held_at + i] != 0.0 for i, name in enumerate(self.names)}
            came = [self.names[int(dd[came_at + j])] for j in range(int(dd[CAME]))]
            first, at = int(dd[DELIVERED]), int(dd[DELIVERED_AT])
            earlier = (self.names[first], at) if first >= 0 and at < made else None  # not the last step's
            self.mapping.reported_elsewhere(made, held, came, earlier)

    def failed(self, code: int, t: float) -> None:
        """Raise the error the step made in Python raises: the physics unstable (2), a set-point not finite (1)."""
        if code == 2:
            self.sim.check()
        if code == 1:
            self.endpoint.set_point(self.period)  # writes the set-point the C loop found not finite: says which
        raise CotwinError(f"mapping {self.mapping.model.name} at t = {t:g} s: the native step failed ({code})")


CONTACT_CHECK = r"""
/* Whether a contact of a watched geom with another one (or a flex) is at least `depth` deep (dist <= limit). */
static int m_contact(const void *data, const unsigned char *watched, double limit) {
    const mjData *d = (const mjData *)data;
    for (int c = 0; c < d->ncon; c++) {
        int a = d->contact[c].geom[0], b = d->contact[c].geom[1];
        int mine = a >= 0 && watched[a], theirs = b >= 0 && watched[b];
        if (mine != theirs && d->contact[c].dist <= limit) return 1;
    }
    return 0;
}
"""


def mujoco_headers() -> tuple[tuple[str, ...], str] | None:
    """(include dirs, C declarations) reading MuJoCo's mjData through the headers of the installed version (named
    in the source: another version builds anew), or None where they are not installed."""
    import mujoco

    from ..pmodel.mujoco_c import include_dir

    folder = include_dir("mjdata.h")
    if folder is None:
        return None
    return (folder,), f"/* MuJoCo {mujoco.__version__} */\n#include <mujoco/mjdata.h>\n{CONTACT_CHECK}"
