"""Exhaustive exploration of a module's state space with every input combination per cycle.

Checks the core properties RoboTool offers: timelock (deadlock) freedom, determinism, divergence
freedom, no output repeated in a cycle; and reachability of every state and transition. Breadth-first,
so each violation comes with a shortest input trace.

Event values: a value that no condition reads (it is only passed on to outputs) cannot change the
control flow, so one representative value explores all behaviours (data independence); values that
conditions read range over their domain (--domain, or a small default: 0 and 1, false and true,
every enumeration literal).
"""

from __future__ import annotations

import itertools
import time
from collections import deque
from dataclasses import dataclass, field

from ..robosim import syntax as s
from ..robosim.dmodel_elements import State
from ..robosim.types import BOOL, REAL, EnumTy, RecordTy
from .interpreter import ExecutionError, Interpreter
from .program import Program, Scalar, scalars


@dataclass
class Violation:
    property: str  # timelock | determinism | divergence | repeated-output | ...
    message: str
    trace: list[dict]

    def format(self) -> str:
        lines = [f"{self.property}: {self.message}", "  shortest input trace:"]
        for i, inputs in enumerate(self.trace, 1):
            lines.append(f"    cycle {i}: {format_inputs(inputs)}")
        return "\n".join(lines)


def format_inputs(inputs: dict) -> str:
    if not inputs:
        return "{}"
    parts = []
    for name, value in inputs.items():
        if value is None:
            parts.append(name)
        elif isinstance(value, dict):
            parts.append(f"{name}({', '.join(str(v) for v in value.values())})")
        else:
            parts.append(f"{name}({value})")
    return "{" + ", ".join(parts) + "}"


@dataclass
class Report:
    states: int = 0
    cycles: int = 0
    seconds: float = 0.0
    violations: list[Violation] = field(default_factory=list)
    unreached_states: list[str] = field(default_factory=list)
    unreached_transitions: list[str] = field(default_factory=list)
    input_combinations: int = 0
    value_notes: list[str] = field(default_factory=list)
    complete: bool = True

    @property
    def ok(self) -> bool:
        return not self.violations and not self.unreached_states and not self.unreached_transitions and self.complete


def condition_variables(program: Program) -> set[str]:
    """Variables read by any transition guard or `if` condition (where values steer control)."""
    names: set[str] = set()

    def visit_expr(e):
        for node in s.walk(e):
            if isinstance(node, s.Name) and len(node.name.parts) == 1:
                names.add(node.name.last)

    def visit_stmt(st):
        if isinstance(st, s.Sequence):
            for item in st.statements:
                visit_stmt(item)
        elif isinstance(st, s.IfStmt):
            visit_expr(st.condition)
            visit_stmt(st.then)
            if st.otherwise is not None:
                visit_stmt(st.otherwise)

    for m in program.machines:
        for t in m.graph.transitions:
            if t.condition is not None:
                visit_expr(t.condition)
            if t.action is not None:
                visit_stmt(t.action)
        for n in m.graph.nodes:
            if isinstance(n.node, State):
                for st in (n.node.entry, n.node.during, n.node.exit):
                    if st is not None:
                        visit_stmt(st)
    return names


def _bound_variables(program: Program, event: str) -> set[str]:
    out = set()
    for machine, name in program.input_routes.get(event, ()):
        for t in program.machines[machine].graph.transitions:
            if t.condition is not None:
                for node in s.walk(t.condition):
                    if isinstance(node, s.EventTest) and node.event.last == name and node.bind:
                        out.add(node.bind)
    return out


def _default_domain(sc: Scalar) -> list:
    if sc.ty == BOOL:
        return [False, True]
    if isinstance(sc.ty, EnumTy):
        return list(range(len(sc.ty.decl.literals)))
    if sc.ty == REAL:
        return [0.0, 1.0]
    return [0, 1]


def _build_value(ty, values: dict[tuple[str, ...], object], resolver):
    if isinstance(ty, RecordTy):
        out = {}
        for sc in scalars(ty, resolver):
            cursor = out
            for key in sc.path[:-1]:
                cursor = cursor.setdefault(key, {})
            cursor[sc.path[-1]] = values[sc.path]
        return out
    return values[()]


def event_values(program: Program, domains: dict[str, list]) -> tuple[dict[str, list], list[str]]:
    """The values each typed input event takes during exploration, and notes saying why."""
    relevant = condition_variables(program)
    out: dict[str, list] = {}
    notes = []
    for ev in program.inputs:
        if ev.ty is None:
            continue
        ports = ev.value_ports
        explicit = {port: domains[port] for port, _ in ports if port in domains}
        bound = _bound_variables(program, ev.name)
        if not explicit and not (bound & relevant):
            combos = [{sc.path: _default_domain(sc)[0] for _, sc in ports}]
            notes.append(f"{ev.name}: its value is not read by any condition (data independent): "
                         f"1 representative value explores every behaviour")
        else:
            axes = [explicit.get(port, _default_domain(sc)) for port, sc in ports]
            combos = [{sc.path: v for (_, sc), v in zip(ports, choice)} for choice in itertools.product(*axes)]
            notes.append(f"{ev.name}: {len(combos)} value(s) from its domain")
        out[ev.name] = [_build_value(ev.ty, c, program.resolver) for c in combos]
    return out, notes


def input_combinations(program: Program, values: dict[str, list]):
    names = [ev.name for ev in program.inputs]
    for mask in range(1 << len(names)):
        present = [n for i, n in enumerate(names) if mask >> i & 1]
        axes = [values.get(n, [None]) for n in present]
        for choice in itertools.product(*axes):
            yield dict(zip(present, choice))


def verify(program: Program, domains: dict[str, list] | None = None, max_states: int = 100_000,
           parameters: dict | None = None) -> Report:
    started = time.perf_counter()
    report = Report()
    values, report.value_notes = event_values(program, domains or {})
    combos = list(input_combinations(program, values))
    report.input_combinations = len(combos)
    interp = Interpreter(program, parameters)
    interp.taken = set()  # every (machine, edge) taken anywhere in the exploration
    root = interp.snapshot()
    parent: dict = {root: None}
    depth = {root: 0}
    queue = deque([root])
    found: dict[tuple[str, str], Violation] = {}

    def trace_to(snap, last):
        path = [last]
        while parent[snap] is not None:
            snap, inputs = parent[snap]
            path.append(inputs)
        return list(reversed(path))

    while queue:
        snap = queue.popleft()
        for inputs in combos:
            interp.restore(snap)
            interp.cycle = depth[snap]
            interp.warnings = []
            report.cycles += 1
            try:
                interp.step(inputs)
            except ExecutionError as err:
                key = (err.kind, err.site or err.findings[0].message)
                if key not in found:  # breadth first: the first one found has a shortest trace
                    found[key] = Violation(err.kind, err.findings[0].message, trace_to(snap, inputs))
                continue
            for w in interp.warnings:
                key = ("determinism", w.site)
                if key not in found:
                    found[key] = Violation("determinism", str(w), trace_to(snap, inputs))
            nxt = interp.snapshot()
            if nxt not in parent:
                if len(parent) >= max_states:
                    report.complete = False
                    continue
                parent[nxt] = (snap, inputs)
                depth[nxt] = depth[snap] + 1
                queue.append(nxt)
    report.states = len(parent)
    report.violations = sorted(found.values(), key=lambda v: (len(v.trace), v.property))
    for m in program.machines:
        # a state is reached when a taken transition enters it, even if the cycle moves on from it
        entered = {e.target.index for e in m.graph.edges if (m.index, e.index) in interp.taken}
        for leaf in m.graph.leaves:
            if leaf.index not in entered:
                report.unreached_states.append(f"{m.machine.name}: state {'.'.join(leaf.path)}")
        for e in m.graph.edges:
            if (m.index, e.index) not in interp.taken:
                report.unreached_transitions.append(f"{m.machine.name}: transition {e.transition.name}")
    report.seconds = time.perf_counter() - started
    return report


def format_report(program: Program, report: Report) -> str:
    lines = [f"module {program.module.name}: {report.states} states, {report.cycles} cycles explored "
             f"({report.input_combinations} input combinations per state) in {report.seconds:.2f} s"]
    lines.extend(f"  note: {n}" for n in report.value_notes)
    if not report.complete:
        lines.append("  INCOMPLETE: the state limit was reached; raise --max-states")
    props = [("timelock", "deadlock/timelock freedom"), ("determinism", "determinism"),
             ("divergence", "divergence freedom"), ("repeated-output", "at most one of each output per cycle")]
    for key, title in props:
        bad = [v for v in report.violations if v.property == key]
        lines.append(f"{'FAIL' if bad else 'ok  '} {title}" + (f": {len(bad)} violation(s)" if bad else ""))
    others = [v for v in report.violations if v.property not in dict(props)]
    for v in others:
        lines.append(f"FAIL {v.property}")
    lines.append(("FAIL" if report.unreached_states else "ok  ") + " every state reachable"
                 + (": unreachable " + ", ".join(report.unreached_states) if report.unreached_states else ""))
    lines.append(("FAIL" if report.unreached_transitions else "ok  ") + " every transition can be taken"
                 + (": never taken " + ", ".join(report.unreached_transitions) if report.unreached_transitions else ""))
    for v in report.violations:
        lines.append("")
        lines.append(v.format())
    return "\n".join(lines)
