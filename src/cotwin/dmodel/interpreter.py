"""The reference interpreter of RoboSim's cycle semantics (docs/robosim-notation.md, section 5).

A machine's whole state is explicit and hashable: the active node, the continuation (the work left
when the last cycle stopped at an `exec`) and the variables. The verifier explores these states; the
generated C follows the same steps (settle a node, take an edge, resume after an exec).

Work items of a continuation:
  ("exit_to", k)   exit states from the active node up to container k (-1 = the machine)
  ("stmts", ss)    run statements ss (an `exec` among them ends the cycle)
  ("enter", k)     make node k active and run its entry action
  ("settle", k)    choose a transition from node k (and its ancestors, outermost first)
  ("wait", k)      end the cycle; settle k in the next one (after a during action)
  ("final",)       the machine has terminated: nothing happens any more
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError, Finding, Location, Severity
from ..robosim import syntax as s
from ..robosim.declarations import EnumDecl
from ..robosim.dmodel_elements import Final, Initial, Junction, State
from ..robosim.operators import MATH, SHORT_CIRCUIT, binary, short_circuit
from .program import MachineInstance, Program, default_value

MAX_STEPS = 10_000  # instantaneous steps in one cycle before it counts as divergence


class ExecutionError(CotwinError):
    """A run-time model error: timelock, divergence, an output repeated in one cycle. `site` says
    where, as data (machine, node, and what was repeated), so that it can be compared."""

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
            return f"{self.name}" + (f"!{_show(self.args[0])}" if self.args else "")
        return f"{self.name}({', '.join(_show(a) for a in self.args)})"


def _show(value) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}={_show(v)}" for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


class FrozenRecord(tuple):
    """A record in a snapshot: its (field, value) pairs, hashable, and told apart from other tuples."""


def freeze(value):
    """A hashable form of a value (records are dicts while running)."""
    if isinstance(value, dict):
        return FrozenRecord((k, freeze(v)) for k, v in value.items())
    return value


def thaw(value):
    if isinstance(value, FrozenRecord):
        return {k: thaw(v) for k, v in value}
    return value


@dataclass
class MachineState:
    active: int = -1
    cont: tuple = ()
    variables: dict = field(default_factory=dict)
    started: bool = False


class Evaluator:
    """Evaluates expressions of one machine: variables, constants, parameters, this cycle's inputs."""

    def __init__(self, program: Program, machine: MachineInstance, parameters: dict):
        self.program = program
        self.machine = machine
        self.values = {**machine.constants, **parameters}
        self.enums: dict[tuple[str, str], int] = {}

    def enum_index(self, name: s.QName) -> int:
        key = (name.parts[-2], name.last)
        if key not in self.enums:
            decl = self.program.project.lookup("type", s.QName(name.parts[:-1]), self.machine.source)
            if not isinstance(decl, EnumDecl):
                raise ExecutionError("name", f"unknown name '{name}'", name.loc)
            self.enums[key] = [lit.name for lit in decl.literals].index(name.last)
        return self.enums[key]

    def eval(self, e: s.Expr, variables: dict, inputs: dict):
        if isinstance(e, s.Literal):
            return e.value
        if isinstance(e, s.Name):
            if len(e.name.parts) > 1:
                return self.enum_index(e.name)
            n = e.name.last
            if n in variables:
                return variables[n]
            if n in self.values:
                return self.values[n]
            raise ExecutionError("name", f"unknown name '{n}'", e.loc)
        if isinstance(e, s.EventTest):
            return e.event.last in inputs
        if isinstance(e, s.Unary):
            v = self.eval(e.operand, variables, inputs)
            return (not v) if e.op == "not" else -v
        if isinstance(e, s.Binary):
            left = self.eval(e.left, variables, inputs)
            if e.op in SHORT_CIRCUIT:
                return short_circuit(e.op, left, lambda: self.eval(e.right, variables, inputs))
            try:
                return binary(e.op, left, self.eval(e.right, variables, inputs))
            except ZeroDivisionError as err:
                raise ExecutionError("division", str(err), e.loc) from None
            except KeyError:
                raise ExecutionError("unsupported", f"operator '{e.op}' is not executable", e.loc) from None
        if isinstance(e, s.FieldAccess):
            return self.eval(e.base, variables, inputs)[e.field]
        if isinstance(e, s.IfExpr):
            branch = e.then if self.eval(e.condition, variables, inputs) else e.otherwise
            return self.eval(branch, variables, inputs)
        if isinstance(e, s.Call) and isinstance(e.function, s.Name) and e.function.name.last in MATH:
            return MATH[e.function.name.last](*(self.eval(a, variables, inputs) for a in e.args))
        raise ExecutionError("unsupported", f"{type(e).__name__} expressions are not executable yet", e.loc)


class Interpreter:
    """Runs a program cycle by cycle: `step(inputs)` -> outputs of that cycle."""

    def __init__(self, program: Program, parameters: dict | None = None):
        self.program = program
        params = parameters or {}
        self.evaluators = []
        for m in program.machines:
            mine = {p.name: params.get(p.port, p.default) for p in program.parameters if p.machine == m.index}
            self.evaluators.append(Evaluator(program, m, mine))
        self.warnings: list[Nondeterminism] = []
        self.taken: set[tuple[int, int]] | None = None  # (machine, edge) taken, when the verifier asks
        self.reset()

    def reset(self) -> None:
        self.cycle = 0
        self.states = [self._initial(m) for m in self.program.machines]
        self.pending: dict[int, dict] = {}  # machine index -> events delivered in the next cycle

    def _initial(self, m: MachineInstance) -> MachineState:
        ev = self.evaluators[m.index]
        variables = {}
        for name, ty, init in m.variables:
            variables[name] = ev.eval(init, variables, {}) if init is not None else default_value(ty, self.program.resolver)
        return MachineState(variables=variables)

    # ---- snapshots (for the verifier and what-if forks) ----
    def snapshot(self):
        return (
            tuple((st.active, st.cont, st.started, tuple((k, freeze(v)) for k, v in st.variables.items()))
                  for st in self.states),
            tuple(sorted((i, tuple(sorted((k, freeze(v)) for k, v in evs.items()))) for i, evs in self.pending.items())),
        )

    def restore(self, snap) -> None:
        machines, pending = snap
        self.states = [MachineState(a, c, {k: thaw(v) for k, v in vs}, started) for a, c, started, vs in machines]
        self.pending = {i: {k: thaw(v) for k, v in evs} for i, evs in pending}

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

    def _run(self, m: MachineInstance, inputs: dict, outputs: list[Output]) -> None:
        st = self.states[m.index]
        graph = m.graph
        if not st.started:
            st.started = True
            initial = graph.initial_of(None)
            if initial is None:
                raise ExecutionError("structure", f"state machine {m.machine.name} has no initial junction", m.machine.loc)
            tasks = [("enter", initial.index), ("settle", initial.index)]
        else:
            tasks = list(st.cont)
        ctx = _Cycle(self, m, st, inputs, outputs)
        st.cont = ctx.run(tasks)


class _Cycle:
    """The instantaneous steps of one machine in one cycle."""

    def __init__(self, interp: Interpreter, m: MachineInstance, st: MachineState, inputs: dict, outputs: list):
        self.interp = interp
        self.m = m
        self.st = st
        self.inputs = inputs
        self.outputs = outputs
        self.ev = interp.evaluators[m.index]
        self.graph = m.graph
        self.steps = 0

    def node_name(self) -> str:
        return self.graph.nodes[self.st.active].name if self.st.active >= 0 else "(start)"

    def where(self) -> str:
        return f"state machine {self.m.machine.name}, node {self.node_name()}, cycle {self.interp.cycle}"

    def site(self, *extra) -> tuple:
        return (self.m.machine.name, self.node_name(), *extra)

    def run(self, tasks: list) -> tuple:
        while tasks:
            self.steps += 1
            if self.steps > MAX_STEPS:
                raise ExecutionError("divergence", f"divergence: no exec reached after {MAX_STEPS} steps in {self.where()}",
                                     site=self.site())
            task = tasks.pop(0)
            kind = task[0]
            if kind == "final":
                return (task,)
            if kind == "wait":
                return (("settle", task[1]), *tasks)
            if kind == "exit_to":
                self.exit_to(task[1])
            elif kind == "enter":
                node = self.graph.nodes[task[1]]
                self.st.active = task[1]
                if isinstance(node.node, State) and node.node.entry is not None:
                    tasks.insert(0, ("stmts", (node.node.entry,)))
            elif kind == "stmts":
                rest = self.statements(list(task[1]))
                if rest is not None:
                    return (("stmts", tuple(rest)), *tasks) if rest else tuple(tasks)
            elif kind == "settle":
                result = self.settle(task[1])
                if result[0] == "end":
                    return result[1]
                tasks[0:0] = result[1]
        raise ExecutionError("timelock", f"timelock: the cycle ends without reaching exec in {self.where()}",
                             site=self.site())

    def exit_to(self, container: int) -> None:
        nodes = self.graph.nodes
        while self.st.active != container and self.st.active >= 0:
            node = nodes[self.st.active]
            if isinstance(node.node, State) and node.node.exit is not None:
                if self.statements([node.node.exit]) is not None:
                    raise ExecutionError("structure", f"exec in the exit action of {node.name}", node.node.loc)
            self.st.active = node.parent.index if node.parent is not None else -1

    def statements(self, todo: list) -> list | None:
        """Run statements; at an `exec` return what is left (possibly []), else None."""
        variables = self.st.variables
        while todo:
            stmt = todo.pop(0)
            if isinstance(stmt, s.Sequence):
                todo[0:0] = list(stmt.statements)
            elif isinstance(stmt, s.Exec):
                return todo
            elif isinstance(stmt, s.Skip):
                pass
            elif isinstance(stmt, s.IfStmt):
                branch = stmt.then if self.ev.eval(stmt.condition, variables, self.inputs) else stmt.otherwise
                if branch is not None:
                    todo.insert(0, branch)
            elif isinstance(stmt, s.Assign):
                self.assign(stmt.target, self.ev.eval(stmt.value, variables, self.inputs))
            elif isinstance(stmt, s.PlatformCall):
                args = tuple(_copy(self.ev.eval(a, variables, self.inputs)) for a in stmt.args)
                self.emit(Output("operation", stmt.operation.last, args), stmt.loc)
            elif isinstance(stmt, s.Send):
                value = _copy(self.ev.eval(stmt.value, variables, self.inputs)) if stmt.value is not None else None
                self.send(stmt.event.last, value, stmt.loc)
            else:
                raise ExecutionError("unsupported", f"{type(stmt).__name__} statements are not executable yet", stmt.loc)
        return None

    def assign(self, target: s.Expr, value) -> None:
        if isinstance(target, s.Name):
            self.st.variables[target.name.last] = _copy(value)
            return
        if isinstance(target, s.FieldAccess):
            container = self._lvalue(target.base)
            container[target.field] = _copy(value)
            return
        raise ExecutionError("unsupported", "only variables and record fields can be assigned", target.loc)

    def _lvalue(self, e: s.Expr) -> dict:
        if isinstance(e, s.Name):
            return self.st.variables[e.name.last]
        if isinstance(e, s.FieldAccess):
            return self._lvalue(e.base)[e.field]
        raise ExecutionError("unsupported", "only variables and record fields can be assigned", e.loc)

    def emit(self, out: Output, loc) -> None:
        if any(o.kind == out.kind and o.name == out.name for o in self.outputs):
            raise ExecutionError("repeated-output", f"{out.kind} '{out.name}' emitted twice in one cycle ({self.where()})",
                                 loc, self.site(out.name))
        self.outputs.append(out)

    def send(self, event: str, value, loc) -> None:
        key = (self.m.index, event)
        program = self.interp.program
        if key in program.output_routes:
            self.emit(Output("event", program.output_routes[key], () if value is None else (value,)), loc)
        for machine, target in program.internal_routes.get(key, ()):
            box = self.interp.pending.setdefault(machine, {})
            if target in box:
                raise ExecutionError("repeated-output", f"event '{event}' sent twice in one cycle ({self.where()})",
                                     loc, self.site(event))
            box[target] = value

    def settle(self, index: int):
        node = self.graph.nodes[index]
        if isinstance(node.node, Final):
            self.st.active = index
            return ("end", (("final",),))
        if isinstance(node.node, State) and any(c.is_state or isinstance(c.node, Initial) for c in node.children):
            initial = self.graph.initial_of(node)
            if initial is not None and not self._inside(self.st.active, index):
                return ("go", [("enter", initial.index), ("settle", initial.index)])
        groups = [a for a in reversed(node.ancestors())] + [node]
        for group in groups:
            enabled = [e for e in group.outgoing if self.guard(e)]
            if not enabled:
                continue
            if len(enabled) > 1:
                self.interp.warnings.append(Nondeterminism(self.m.machine.name, node.name,
                                                           tuple(e.transition.name for e in enabled), self.interp.cycle))
            edge = enabled[0]
            if self.interp.taken is not None:
                self.interp.taken.add((self.m.index, edge.index))
            self.bind(edge)
            completion = completion_tasks(self.graph, edge)
            if edge.transition.is_exec:
                return ("end", tuple(completion))
            return ("go", completion)
        if isinstance(node.node, State) and node.node.during is not None:
            return ("go", [("stmts", (node.node.during,)), ("wait", index)])
        what = "junction" if isinstance(node.node, (Junction, Initial)) else "state"
        raise ExecutionError("timelock", f"timelock: no transition enabled from {what} {node.name} in {self.where()}",
                             node.node.loc, self.site())

    def _inside(self, active: int, container: int) -> bool:
        if active < 0 or active == container:
            return False
        node = self.graph.nodes[active]
        return any(a.index == container for a in node.ancestors())

    def guard(self, edge) -> bool:
        t = edge.transition
        if t.condition is None:
            return not t.is_else or not any(
                e is not edge and (e.transition.condition is None or self.ev.eval(e.transition.condition, self.st.variables, self.inputs))
                for e in edge.source.outgoing if not e.transition.is_else)
        return bool(self.ev.eval(t.condition, self.st.variables, self.inputs))

    def bind(self, edge) -> None:
        if edge.transition.condition is None:
            return
        for node in s.walk(edge.transition.condition):
            if isinstance(node, s.EventTest) and node.bind is not None and node.event.last in self.inputs:
                self.st.variables[node.bind] = _copy(self.inputs[node.event.last])


def _copy(value):
    return {k: _copy(v) for k, v in value.items()} if isinstance(value, dict) else value


def lca_index(edge) -> int:
    """The container whose states are not exited by this edge (-1 = the machine)."""
    src = [edge.source.parent, *edge.source.parent.ancestors()] if edge.source.parent else []
    tgt = {id(n) for n in ([edge.target.parent, *edge.target.parent.ancestors()] if edge.target.parent else [])}
    for node in src:
        if id(node) in tgt:
            return node.index
    return -1


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
