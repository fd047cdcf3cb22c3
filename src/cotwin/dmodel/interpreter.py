"""The reference interpreter of RoboSim's cycle semantics (docs/robosim-notation.md, section 6).

A machine's whole state is explicit and hashable: a stack of frames (the machine's own, then one per
operation call in progress), each with its active node, its continuation (the work left when the
last cycle stopped at an `exec`), its variables, clocks and state-entry counters. The verifier
explores these states; the generated C follows the same steps (settle a node, take an edge, resume
after an exec, call and return from an operation).

Work items of a continuation:
  ("exit_to", k)   exit states from the active node up to container k (-1 = the machine), running
                   exit actions (which may `exec`)
  ("ascend",)      after a state's exit action: its parent becomes the active node
  ("stmts", ss)    run statements ss (an `exec` among them ends the cycle; a call pushes a frame)
  ("enter", k)     make node k active and run its entry action
  ("settle", k)    choose a transition from node k (and its ancestors, outermost first)
  ("wait", k)      end the cycle; settle k in the next one (after a during action)
  ("final",)       the machine has terminated: nothing happens any more

Clocks and `since`: a clock counts the cycles since it was last reset (`#T`): 0 in the cycle of the
reset (or of the machine's start), 1 in the next, and so on; `sinceEntry(S)` likewise counts from
the last entry of S. A count only ever compared with constants stops one above the largest of them
(program.count_caps), where no comparison tells it apart from a larger one: the same behaviour,
finitely many states for the verifier. A run-time error (division by zero, overflow, an index out of range, ...) is an
ExecutionError located at the expression, naming the state the machine was in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from ..robosim import functions as fns
from ..robosim import syntax as s
from ..robosim.declarations import EnumDecl
from ..robosim.dmodel_elements import Final, Initial, Junction, State
from ..robosim.evaluator import Evaluator, replace_at
from ..robosim.evaluator import index as index_of
from ..robosim.types import BOOL, INT, NAT, REAL, EnumTy, Ty, TypeResolver
from ..robosim.values import EvalError, FrozenRecord, copy, freeze, show, thaw
from .program import (
    Body, MachineInstance, Program, beyond_int32, beyond_int32_message, coerce, default_value, node_description,
    state_index,
)

MAX_STEPS = 10_000  # instantaneous steps in one cycle before it counts as divergence

__all__ = ["ExecutionError", "FrozenRecord", "Interpreter", "MAX_STEPS", "Nondeterminism", "Output", "Random",
           "freeze", "lca_index", "thaw"]


class ExecutionError(CotwinError):
    """A run-time model error: timelock, divergence, an output repeated in one cycle, a division by
    zero... `site` says where, as data (machine, node, and what was repeated), so that it can be compared."""

    def __init__(self, kind: str, message: str, loc: Location | None = None, site: tuple = ()):
        self.kind = kind
        self.site = site
        super().__init__([Finding(loc or Location("<run>", 0, 0), Severity.ERROR, message)])


@dataclass(frozen=True)
class Nondeterminism:
    """Several transitions were enabled at once; the first in source order was taken."""

    machine: str
    node: str
    enabled: tuple[str, ...]
    cycle: int

    @property
    def site(self) -> tuple:
        return (self.machine, self.node, self.enabled)

    def __str__(self) -> str:
        return (f"nondeterminism in state machine {self.machine}, node {self.node}, cycle {self.cycle}: "
                f"{', '.join(self.enabled)} enabled; took {self.enabled[0]}")


@dataclass(frozen=True)
class Output:
    """An operation call `$op(args)` or an output event `$e!v` of one cycle."""

    kind: str  # operation | event
    name: str
    args: tuple

    def __str__(self) -> str:
        if self.kind == "event":
            return f"{self.name}" + (f"!{show(self.args[0])}" if self.args else "")
        return f"{self.name}({', '.join(show(a) for a in self.args)})"


def shared_port_message(first: str, second: str, port: str) -> str:
    return (f"operations '{first}' and '{second}' called in one cycle: both pass argument port '{port}', which holds "
            f"one value (rename a parameter to give each its own port)")


class Random:
    """splitmix64: the pseudo-random source of uninterpreted functions and Mathematics::random, the
    same sequence in the generated C for the same `seed`."""

    MASK = (1 << 64) - 1

    def __init__(self, seed: int = 0):
        self.state = seed & self.MASK

    def next(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & self.MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & self.MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & self.MASK
        return z ^ (z >> 31)

    def real(self) -> float:
        return (self.next() >> 11) * (1.0 / 9007199254740992.0)

    def value(self, ty: Ty):
        """A value of an uninterpreted function's result type."""
        if ty == REAL:
            return self.real()
        x = self.next()
        if ty == BOOL:
            return bool(x >> 63)
        if ty in (INT, NAT):
            return x >> 63
        if isinstance(ty, EnumTy):
            return x % len(ty.decl.literals)
        raise EvalError("unsupported", f"no random value of type {ty}")


@dataclass
class Frame:
    """The machine's own frame (body -1) or an operation call in progress (body = frame index)."""

    body: int = -1
    active: int = -1
    tasks: tuple = ()
    variables: dict = field(default_factory=dict)
    clocks: dict = field(default_factory=dict)
    entered: dict = field(default_factory=dict)  # state index -> cycles since its last entry

    def freeze(self):
        return (self.body, self.active, self.tasks, tuple((k, freeze(v)) for k, v in self.variables.items()),
                tuple(sorted(self.clocks.items())), tuple(sorted(self.entered.items())))

    @staticmethod
    def frozen_variables(data) -> tuple:
        """The (name, frozen value) pairs of a frame as `freeze` wrote it."""
        return data[3]

    @staticmethod
    def thaw(data) -> "Frame":
        body, active, tasks, variables, clocks, entered = data
        return Frame(body, active, tasks, {k: thaw(v) for k, v in variables}, dict(clocks), dict(entered))


@dataclass
class MachineState:
    frames: list[Frame] = field(default_factory=list)
    started: bool = False

    @property
    def active(self) -> int:
        """The machine's own active node (the caller's node while an operation runs)."""
        return self.frames[0].active if self.frames else -1

    @property
    def variables(self) -> dict:
        return self.frames[0].variables if self.frames else {}


class MachineEvaluator(Evaluator):
    """Expressions of one machine: names are the top frame's locals, then the machine's variables,
    constants and parameters; `$e` is this cycle's input event e."""

    def __init__(self, interp: "Interpreter", m: MachineInstance, parameters: dict):
        super().__init__()
        self.interp = interp
        self.program = interp.program
        self.m = m
        self.parameters = parameters
        self.readings = interp.program.readings
        self.frames: list[Frame] = []
        self.inputs: dict = {}
        self.enums: dict[tuple, int] = {}
        self.function_bodies: dict[int, object] = {}

    # context
    def at(self, frames: list[Frame], inputs: dict) -> "MachineEvaluator":
        self.frames = frames
        self.inputs = inputs
        self.bound = {}
        return self

    @property
    def body(self) -> Body:
        return self.m.body_of(self.frames[-1].body) if self.frames else self.m

    def lookup(self, name: str, loc):
        top = self.frames[-1] if self.frames else None
        if top is not None and top.body >= 0:
            body = self.m.frames[top.body]
            if name in top.variables:
                return top.variables[name]
            if name in body.constants:
                return body.constants[name]
            holder = body.bindings.get(name, -1)
            if holder >= 0:
                frame = next(f for f in reversed(self.frames) if f.body == holder)
                if name in frame.variables:
                    return frame.variables[name]
                return self.m.frames[holder].constants[name]
        if self.frames and name in self.frames[0].variables:
            return self.frames[0].variables[name]
        if name in self.m.constants:
            return self.m.constants[name]
        if name in self.parameters:
            return self.parameters[name]
        raise EvalError("name", f"'{name}' has no value", loc)

    def name(self, e: s.Name):
        if len(e.name.parts) > 1:
            return self.enum_index(e.name)
        return self.lookup(e.name.last, e.loc)

    def enum_index(self, name: s.QName) -> int:
        key = name.parts
        if key not in self.enums:
            decl = self.program.project.lookup("type", s.QName(name.parts[:-1]), self.body.source)
            if not isinstance(decl, EnumDecl) or decl.literal(name.last) is None:
                raise EvalError("name", f"unknown name '{name}'", name.loc)
            self.enums[key] = [lit.name for lit in decl.literals].index(name.last)
        return self.enums[key]

    def dollar(self, e: s.EventTest):
        name = e.event.last
        if name in self.m.inputs:
            if name not in self.inputs:
                return False
            value = self.inputs[name]
            if e.value is not None and value != self.visit(e.value):
                return False
            if e.bind is not None and e.predicate is not None:
                saved = dict(self.bound)
                self.bound[e.bind] = value
                try:
                    return bool(self.visit(e.predicate))
                finally:
                    self.bound = saved
            return True
        return self.dollar_value(e, self.lookup(name, e.loc))

    def first_index(self, e: s.IndexAccess) -> int:
        return self.readings.first_index.get(id(e), 1)

    def function(self, e: s.Call):
        fn = fns.target(self.program.project, e, self.body.source)
        if fn is None:
            return None
        impl = fns.builtin(self.program.project, fn)
        if impl == "random":
            return self.interp.random.real
        if impl is not None:
            return impl
        cached = self.function_bodies.get(id(fn))
        if cached is None:
            cached = self.function_bodies[id(fn)] = self._compile_function(fn)
        return cached

    def _compile_function(self, fn):
        owner = self.program.project.file_of(fn) or self.body.source
        resolver = TypeResolver(self.program.project, owner, Diagnostics())
        result = resolver.resolve(fn.result)
        definition = fns.definition(fn)
        if definition is None:
            return lambda *args: self.interp.random.value(result)
        params = [(p.name, resolver.resolve(p.type)) for p in fn.params]

        def run(*args):
            saved = self.bound
            self.bound = {name: coerce(a, ty, resolver) for (name, ty), a in zip(params, args)}
            try:
                return coerce(self.visit(definition), result, resolver)
            finally:
                self.bound = saved
        return run

    def since(self, e: s.SinceExpr):
        for frame in reversed(self.frames):
            if e.clock in frame.clocks:
                return frame.clocks[e.clock]
        raise EvalError("name", f"unknown clock '{e.clock}'", e.loc)

    def since_entry(self, e: s.SinceEntryExpr):
        frame = self.frames[-1]
        index = state_index(self.m.body_of(frame.body).graph, e.state)
        if index in frame.entered:
            return frame.entered[index]
        cap = self.m.body_of(frame.body).entry_caps.get(index)
        count = self.interp.cycle - 1  # never entered: counted from the start
        return count if cap is None else min(count, cap)

    def cycle(self, e: s.CycleExpr):
        return self.interp.cycle


class Interpreter:
    """Runs a program cycle by cycle: `step(inputs)` -> outputs of that cycle."""

    def __init__(self, program: Program, parameters: dict | None = None):
        self.program = program
        params = parameters or {}
        self.evaluators = []
        for m in program.machines:
            mine = {p.name: params.get(p.port, p.default) for p in program.parameters if p.machine == m.index}
            self.evaluators.append(MachineEvaluator(self, m, mine))
        seed = next((p for p in program.parameters if p.machine < 0), None)
        self.seed = int(params.get(seed.port, 0)) if seed is not None else 0
        self.warnings: list[Nondeterminism] = []
        self.taken: set[tuple[int, int]] | None = None  # (machine, edge) taken, when the verifier asks
        self.reset()

    def reset(self) -> None:
        self.cycle = 0
        self.random = Random(self.seed)
        self.states = [MachineState() for _ in self.program.machines]
        self.pending: dict[int, dict] = {}  # machine index -> events delivered in the next cycle

    # ---- snapshots (for the verifier and what-if forks) ----
    def snapshot(self):
        return (
            tuple((st.started, tuple(f.freeze() for f in st.frames)) for st in self.states),
            tuple(sorted((i, tuple(sorted((k, freeze(v)) for k, v in evs.items()))) for i, evs in self.pending.items())),
            self.random.state,
        )

    def restore(self, snap) -> None:
        machines, pending, random_state = snap
        self.states = [MachineState([Frame.thaw(f) for f in frames], started) for started, frames in machines]
        self.pending = {i: {k: thaw(v) for k, v in evs} for i, evs in pending}
        self.random.state = random_state

    # ---- one cycle ----
    def step(self, inputs: dict | None = None) -> list[Output]:
        """Run one cycle with the platform's input events {name: value or None}; return the outputs."""
        self.cycle += 1
        inputs = inputs or {}
        unknown = [n for n in inputs if n not in self.program.input_routes]
        if unknown:
            raise ExecutionError("input", f"unknown input event(s): {', '.join(sorted(unknown))}")
        per_machine: dict[int, dict] = {i: dict(evs) for i, evs in self.pending.items()}
        for name, value in inputs.items():
            for machine, event in self.program.input_routes[name]:
                per_machine.setdefault(machine, {})[event] = value
        self.pending = {}
        outputs: list[Output] = []
        for m in self.program.machines:
            self._run(m, per_machine.get(m.index, {}), outputs)
        return outputs

    def active_leaf(self, machine: int = 0) -> str | None:
        st = self.states[machine]
        if st.active < 0:
            return None
        return ".".join(self.program.machines[machine].graph.nodes[st.active].path)

    def state_index(self, machine: int = 0) -> int:
        """Index of the active leaf state among the machine's leaves (-1 if none), the FMU's `state`."""
        m = self.program.machines[machine]
        st = self.states[machine]
        leaves = m.graph.leaves
        node = m.graph.nodes[st.active] if st.active >= 0 else None
        return next((i for i, leaf in enumerate(leaves) if leaf is node), -1)

    def variables(self, machine: int = 0) -> dict:
        """The machine's variables now (for tests and what-if inspection)."""
        return self.states[machine].variables

    def _run(self, m: MachineInstance, inputs: dict, outputs: list[Output]) -> None:
        st = self.states[m.index]
        if not st.started:
            st.started = True
            frame = Frame(-1, -1, (), {}, {c: 0 for c in m.clocks}, {})
            st.frames = [frame]
            cycle = _Cycle(self, m, st, inputs, outputs)
            for name, ty, init in m.variables:
                value = cycle.evaluate(init) if init is not None else default_value(ty, m.resolver)
                frame.variables[name] = coerce(value, ty, m.resolver)
            initial = m.graph.initial_of(None)
            if initial is None:
                raise ExecutionError("structure", f"state machine {m.machine.name} has no initial junction", m.machine.loc)
            frame.tasks = (("enter", initial.index), ("settle", initial.index))
        else:
            caps = m.clock_caps  # counts stop where no comparison can tell them apart (program.count_caps)
            for frame in st.frames:
                for c, count in frame.clocks.items():
                    cap = caps.get(c)
                    frame.clocks[c] = count + 1 if cap is None or count < cap else cap
                entry_caps = m.body_of(frame.body).entry_caps
                for k, count in frame.entered.items():
                    cap = entry_caps.get(k)
                    frame.entered[k] = count + 1 if cap is None or count < cap else cap
        _Cycle(self, m, st, inputs, outputs).run()


class _Cycle:
    """The instantaneous steps of one machine in one cycle."""

    def __init__(self, interp: Interpreter, m: MachineInstance, st: MachineState, inputs: dict, outputs: list):
        self.interp = interp
        self.m = m
        self.st = st
        self.inputs = inputs
        self.outputs = outputs
        self.ev = interp.evaluators[m.index]
        self.steps = 0

    # ---- context ----
    @property
    def frame(self) -> Frame:
        return self.st.frames[-1]

    @property
    def body(self) -> Body:
        return self.m.body_of(self.frame.body)

    @property
    def graph(self):
        return self.body.graph

    def node_name(self) -> str:
        return self.graph.nodes[self.frame.active].name if self.frame.active >= 0 else "(start)"

    def where(self) -> str:
        frame = f", operation {self.body.name}" if self.frame.body >= 0 else ""
        return f"state machine {self.m.machine.name}{frame}, node {self.node_name()}, cycle {self.interp.cycle}"

    def node_description(self) -> str:
        if self.frame.active < 0:  # starting, or between states (a transition's action)
            return f"state machine {self.m.machine.name}"
        return node_description(self.graph.nodes[self.frame.active], self.body.name if self.frame.body >= 0 else "")

    def site(self, *extra) -> tuple:
        return (self.m.machine.name, self.node_name(), *extra)

    def evaluate(self, e: s.Expr):
        try:
            return self.ev.at(self.st.frames, self.inputs).visit(e)
        except EvalError as err:
            raise ExecutionError(err.kind, f"{err.message} in {self.node_description()} (cycle {self.interp.cycle})",
                                 err.loc or e.loc, self.site(err.kind)) from None

    # ---- the task loop ----
    def run(self) -> None:
        tasks = list(self.frame.tasks)
        while True:
            self.steps += 1
            if self.steps > MAX_STEPS:
                raise ExecutionError("divergence", f"divergence: no exec reached after {MAX_STEPS} steps in "
                                     f"state machine {self.m.machine.name} (cycle {self.interp.cycle})",
                                     self.m.machine.loc, self.site())
            if not tasks:
                raise ExecutionError("timelock", f"timelock: the cycle ends without reaching exec in {self.where()}",
                                     site=self.site())
            task = tasks.pop(0)
            kind = task[0]
            if kind == "final":
                self.frame.tasks = (task,)
                return
            if kind == "wait":
                self.frame.tasks = (("settle", task[1]), *tasks)
                return
            if kind == "exit_to":
                tasks[0:0] = self.exit_step(task[1])
            elif kind == "ascend":
                node = self.graph.nodes[self.frame.active]
                self.frame.active = node.parent.index if node.parent is not None else -1
            elif kind == "enter":
                node = self.graph.nodes[task[1]]
                self.frame.active = task[1]
                if isinstance(node.node, State):
                    if task[1] in self.body.entry_timers:
                        self.frame.entered[task[1]] = 0
                    if node.node.entry is not None:
                        tasks.insert(0, ("stmts", (node.node.entry,)))
            elif kind == "stmts":
                outcome = self.statements(list(task[1]))
                if outcome is None:
                    continue
                what, rest, call = outcome
                if what == "exec":
                    self.frame.tasks = (*((("stmts", tuple(rest)),) if rest else ()), *tasks)
                    return
                # a call: the caller continues after it once the operation returns
                self.frame.tasks = (*((("stmts", tuple(rest)),) if rest else ()), *tasks)
                tasks = self.push(call)
            elif kind == "settle":
                result = self.settle(task[1])
                if result[0] == "final":
                    self.frame.tasks = (("final",),)
                    return
                if result[0] == "return":
                    self.st.frames.pop()
                    tasks = list(self.frame.tasks)
                    continue
                if result[0] == "end":
                    self.frame.tasks = tuple(result[1])
                    return
                tasks[0:0] = result[1]

    def exit_step(self, container: int) -> list:
        if self.frame.active == container or self.frame.active < 0:
            return []
        node = self.graph.nodes[self.frame.active]
        steps: list = []
        if isinstance(node.node, State) and node.node.exit is not None:
            steps.append(("stmts", (node.node.exit,)))
        steps.extend((("ascend",), ("exit_to", container)))
        return steps

    def push(self, call: s.CallStmt) -> list:
        op = self.body.calls[call.operation.last]
        args = [self.evaluate(a) for a in call.args]
        frame = Frame(op.index, -1, (), {}, {c: 0 for c in op.clocks}, {})
        for (name, ty), value in zip(op.params, args):
            frame.variables[name] = coerce(copy(value), ty, op.resolver)
        self.st.frames.append(frame)
        for name, ty, init in op.variables:
            value = self.evaluate(init) if init is not None else default_value(ty, op.resolver)
            frame.variables[name] = coerce(value, ty, op.resolver)
        initial = op.graph.initial_of(None)
        if initial is None:
            raise ExecutionError("structure", f"operation {op.name} has no initial junction", op.machine.loc)
        return [("enter", initial.index), ("settle", initial.index)]

    # ---- statements ----
    def statements(self, todo: list):
        """Run statements; at an `exec` return ("exec", rest, None), at a call of a software operation
        ("call", rest, call); None when all ran."""
        while todo:
            stmt = todo.pop(0)
            if isinstance(stmt, s.Sequence):
                todo[0:0] = list(stmt.statements)
            elif isinstance(stmt, s.Exec):
                return ("exec", todo, None)
            elif isinstance(stmt, s.Skip):
                pass
            elif isinstance(stmt, s.IfStmt):
                branch = stmt.then if self.evaluate(stmt.condition) else stmt.otherwise
                if branch is not None:
                    todo.insert(0, branch)
            elif isinstance(stmt, s.Assign):
                self.assign(stmt.target, self.evaluate(stmt.value))
            elif isinstance(stmt, s.PlatformCall):
                self.platform_call(stmt.operation.last, stmt.args, stmt.loc)
            elif isinstance(stmt, s.CallStmt):
                if stmt.operation.last in self.body.calls:
                    return ("call", todo, stmt)
                self.platform_call(stmt.operation.last, stmt.args, stmt.loc)
            elif isinstance(stmt, s.Send):
                value = copy(self.evaluate(stmt.value)) if stmt.value is not None else None
                ty = self.m.outputs.get(stmt.event.last)
                if value is not None and ty is not None:
                    value = coerce(value, ty, self.m.resolver)
                self.send(stmt.event.last, value, stmt.loc)
            elif isinstance(stmt, s.ClockReset):
                self.reset_clock(stmt.clock, stmt.loc)
            else:
                raise ExecutionError("unsupported", f"{type(stmt).__name__} statements are not executable", stmt.loc)
        return None

    def platform_call(self, name: str, arg_exprs, loc) -> None:
        sig = self.m.operations.get(name)
        args = [copy(self.evaluate(a)) for a in arg_exprs]
        if sig is not None:
            args = [coerce(a, self.m.resolver.resolve(p.type), self.m.resolver) for a, p in zip(args, sig.params)]
        self.emit(Output("operation", name, tuple(args)), loc)

    def reset_clock(self, clock: str, loc) -> None:
        for frame in reversed(self.st.frames):
            if clock in frame.clocks:
                frame.clocks[clock] = 0
                return
        raise ExecutionError("name", f"unknown clock '{clock}'", loc)

    def _type_of_target(self, target: s.Expr) -> Ty | None:
        root = s.root_name(target)
        name = root.name.last
        if self.frame.body >= 0 and name in self.body.types:
            return self.body.types[name]
        return self.m.types.get(name)

    def _storage(self, name: str) -> dict:
        if self.frame.body >= 0:
            if name in self.frame.variables:
                return self.frame.variables
            holder = self.body.bindings.get(name, -1)
            if holder >= 0:
                return next(f for f in reversed(self.st.frames) if f.body == holder).variables
        return self.st.frames[0].variables

    def assign(self, target: s.Expr, value) -> None:
        ty = self.interp.program.type_of(target) or self._type_of_target(target)
        if ty is not None:
            value = coerce(value, ty, self.m.resolver)
        value = copy(value)
        if isinstance(target, s.Name):
            self._storage(target.name.last)[target.name.last] = value
            return
        root = s.root_name(target)
        store = self._storage(root.name.last)
        store[root.name.last] = self._updated(store[root.name.last], target, value)

    def _updated(self, current, target: s.Expr, value):
        """`current` (the root variable's value) with the part `target` selects replaced by value."""
        path = []
        node = target
        while isinstance(node, (s.FieldAccess, s.IndexAccess)):
            path.append(node)
            node = node.base
        return self._replace(current, list(reversed(path)), value)

    def _replace(self, current, path, value):
        if not path:
            return value
        step = path[0]
        if isinstance(step, s.FieldAccess):
            inner = current[step.field]
            current = dict(current)
            current[step.field] = self._replace(inner, path[1:], value)
            return current
        position = self.evaluate(step.index)
        first = self.ev.first_index(step)
        try:
            inner = index_of(current, position, step.loc, first)
            return replace_at(current, position, self._replace(inner, path[1:], value), step.loc, first)
        except EvalError as err:
            raise ExecutionError(err.kind, f"{err.message} in {self.node_description()} (cycle {self.interp.cycle})",
                                 err.loc, self.site(err.kind)) from None

    def emit(self, out: Output, loc) -> None:
        if any(o.kind == out.kind and o.name == out.name for o in self.outputs):
            raise ExecutionError("repeated-output", f"{out.kind} '{out.name}' emitted twice in one cycle in "
                                 f"{self.node_description()} (cycle {self.interp.cycle})", loc, self.site(out.name))
        program = self.interp.program
        where = f" in {self.node_description()} (cycle {self.interp.cycle})"
        port = program.operation_port(out.name) if out.kind == "operation" else None
        for o in self.outputs if port is not None else ():
            if o.kind == "operation" and o.name in port.shares:
                raise ExecutionError("shared-port", shared_port_message(o.name, out.name, port.shares[o.name]) + where,
                                     loc, self.site(out.name))
        # what the FMU's ports cannot hold is an error here as in the C, not a value only the interpreter shows
        if port is not None:
            groups = list(zip(port.arg_ports, out.args))
        else:
            event = program.output_port(out.name) if out.kind == "event" else None
            groups = [(event.value_ports, out.args[0])] if event is not None and out.args else []
        for group, value in groups:
            wide = beyond_int32(group, value)
            if wide is not None:
                raise ExecutionError("overflow", beyond_int32_message(*wide) + where, loc, self.site(out.name))
        self.outputs.append(out)

    def send(self, event: str, value, loc) -> None:
        key = (self.m.index, event)
        program = self.interp.program
        if key in program.output_routes:
            self.emit(Output("event", program.output_routes[key], () if value is None else (value,)), loc)
        for machine, target in program.internal_routes.get(key, ()):
            box = self.interp.pending.setdefault(machine, {})
            if target in box:
                raise ExecutionError("repeated-output", f"event '{event}' emitted twice in one cycle in "
                                     f"{self.node_description()} (cycle {self.interp.cycle})", loc, self.site(event))
            box[target] = value

    # ---- choosing transitions ----
    def settle(self, index: int):
        node = self.graph.nodes[index]
        if isinstance(node.node, Final):
            self.frame.active = index
            return ("return",) if self.frame.body >= 0 else ("final",)
        if isinstance(node.node, State) and any(c.is_state or isinstance(c.node, Initial) for c in node.children):
            initial = self.graph.initial_of(node)
            if initial is not None and not self._inside(self.frame.active, index):
                return ("go", [("enter", initial.index), ("settle", initial.index)])
        for group in choice_groups(node):
            enabled = self.enabled(group.outgoing)
            if not enabled:
                continue
            if len(enabled) > 1:
                self.interp.warnings.append(Nondeterminism(self.m.machine.name, node.name,
                                                           tuple(e.transition.name for e in enabled), self.interp.cycle))
            edge = enabled[0]
            if self.interp.taken is not None and self.frame.body < 0:
                self.interp.taken.add((self.m.index, edge.index))
            self.bind(edge)
            completion = completion_tasks(self.graph, edge)
            if edge.transition.is_exec:
                return ("end", tuple(completion))
            return ("go", completion)
        if isinstance(node.node, State) and node.node.during is not None:
            return ("go", [("stmts", (node.node.during,)), ("wait", index)])
        what = "junction" if isinstance(node.node, (Junction, Initial)) else "state"
        raise ExecutionError("timelock", f"timelock: no transition enabled from {what} {node.name} in state machine "
                             f"{self.m.machine.name} (cycle {self.interp.cycle})",
                             node.node.loc, self.site())

    def _inside(self, active: int, container: int) -> bool:
        if active < 0 or active == container:
            return False
        node = self.graph.nodes[active]
        return any(a.index == container for a in node.ancestors())

    def enabled(self, edges) -> list:
        """The enabled edges, each condition evaluated once, in source order; `else` holds when no
        other edge's condition does (an edge without a condition counts as holding)."""
        holds = {}
        for e in edges:
            if e.transition.condition is not None:
                holds[id(e)] = bool(self.evaluate(e.transition.condition))
        out = []
        for e in edges:
            t = e.transition
            if t.condition is not None:
                ok = holds[id(e)]
            elif not t.is_else:
                ok = True
            else:
                ok = not any(holds.get(id(o), True) for o in edges if o is not e and not o.transition.is_else)
            if ok:
                out.append(e)
        return out

    def bind(self, edge) -> None:
        """`$e?x` in the taken transition's guard: x := e's value (when e arrived)."""
        if edge.transition.condition is None:
            return
        for node in s.walk(edge.transition.condition):
            if isinstance(node, s.EventTest) and node.bind is not None and node.event.last in self.inputs:
                name = node.bind
                ty = self.body.types.get(name) if self.frame.body >= 0 else None
                ty = ty or self.m.types.get(name)
                value = copy(self.inputs[node.event.last])
                self._storage(name)[name] = coerce(value, ty, self.m.resolver) if ty is not None else value


def lca_index(edge) -> int:
    """The container whose states are not exited by this edge (-1 = the machine)."""
    src = [edge.source.parent, *edge.source.parent.ancestors()] if edge.source.parent else []
    tgt = {id(n) for n in ([edge.target.parent, *edge.target.parent.ancestors()] if edge.target.parent else [])}
    for node in src:
        if id(node) in tgt:
            return node.index
    return -1


def choice_groups(node) -> list:
    """Whose transitions a node chooses from, outermost first: a state its ancestors' and its own; a junction
    (an initial one too) only its own, since the machine never rests there: the transitions of a composite
    state being entered must not cut its entry short at its initial junction (docs/robosim-notation.md, 6.4)."""
    if isinstance(node.node, State):
        return [*reversed(node.ancestors()), node]
    return [node]


def completion_tasks(graph, edge) -> list:
    """Exit to the common container, run the action, enter down to the target, settle there."""
    lca = lca_index(edge)
    tasks: list = [("exit_to", lca)]
    if edge.transition.action is not None:
        tasks.append(("stmts", (edge.transition.action,)))
    path = []
    node = edge.target
    while node is not None and node.index != lca:
        path.append(node)
        node = node.parent
    tasks.extend(("enter", n.index) for n in reversed(path))
    tasks.append(("settle", edge.target.index))
    return tasks
