"""Which values steer control: the variables and event values that a transition guard or an `if` condition reads,
directly or through what flows into them.

The verifier explores one representative value of an input event whose value steers nothing (data independence),
and calls a counter that steers nothing a counter whose growth cannot change what the machines do (growth.py). Both
need every way a value reaches a condition: an assignment (`leg = BIN0 + item % 3`), an operation's argument
(`place(item)`), and an event one machine sends with a value (`$fwd!item`) that another machine of the module binds
(`$fwd?k`, a guard reading k) or compares (`$fwd.1`): the interpreter delivers it one cycle later
(docs/robosim-notation.md, section 6), value included. Variables are named without their machine: a name steering in
one machine counts as steering in all (more values explored, never fewer).
"""

from __future__ import annotations

from typing import Iterator

from ..robosim import syntax as s
from ..robosim.dmodel_elements import State
from .program import Body, MachineInstance, Program


def read(e: s.Expr) -> set[str]:
    """The simple names an expression reads (`$v` on a variable reads v too)."""
    names = set()
    for node in s.walk(e):
        if isinstance(node, s.Name) and len(node.name.parts) == 1:
            names.add(node.name.last)
        elif isinstance(node, s.EventTest) and len(node.event.parts) == 1:
            names.add(node.event.last)
    return names


def failing_operands(e: s.Expr) -> set[str]:
    """The simple names an expression reads where a value can make the cycle fail (a violation the verifier reports):
    a divisor (`10 / (x - 5)`), an index, a function's argument (`log(x)`, `floor(y)` of nan)."""
    names = set()
    for node in s.walk(e):
        if isinstance(node, s.Binary) and node.op in ("/", "%"):
            names |= read(node.right)
        elif isinstance(node, s.IndexAccess):
            names |= read(node.index)
        elif isinstance(node, s.Call):
            for arg in node.args:
                names |= read(arg)
    return names


def bodies(machine: MachineInstance) -> tuple[Body, ...]:
    """A machine and the operations it calls: what runs in its frames."""
    return (machine, *machine.frames)


def body_statements(body: Body) -> Iterator[s.Stmt]:
    """Every statement a body runs: transition actions and its states' entry, during and exit actions, nested ones
    opened."""
    for t in body.graph.transitions:
        yield from s.statements(t.action)
    for n in body.graph.nodes:
        if isinstance(n.node, State):
            for st in (n.node.entry, n.node.during, n.node.exit):
                yield from s.statements(st)


def event_tests_in(machine: MachineInstance, event: str) -> list[s.EventTest]:
    """The tests `$e`, `$e?x`, `$e.v` of the machine's input event `event` in its guards and its operations'."""
    return [node for body in bodies(machine) for t in body.graph.transitions if t.condition is not None
            for node in s.walk(t.condition) if isinstance(node, s.EventTest) and node.event.last == event]


def input_event_tests(program: Program, event: str) -> list[s.EventTest]:
    """The tests of platform input event `event` in the machines it reaches."""
    return [node for machine, name in program.input_routes.get(event, ())
            for node in event_tests_in(program.machines[machine], name)]


def condition_variables(program: Program, failures: bool = False) -> set[str]:
    """Variables whose value steers control: read by a transition guard or an `if` condition, of a machine or of
    an operation it calls, or assigned to one that is (`leg = BIN0 + item % 3` where a guard reads `leg`: item's
    value then steers too, though no condition names it), also as an operation's argument (`place(item)` where
    place's guards read its parameter) or as the value of an event another machine binds (`$fwd!item` where the
    receiver's guard reads the k of its `$fwd?k`) or compares (`$fwd.1`). With `failures`, also those read where
    a value can make a cycle fail (`failing_operands`: `k = 10 / (x - 5)` fails for x = 5 only), which decide
    whether a run fails as a guard decides where it goes."""
    names: set[str] = set()
    flows: list[tuple[str, set[str]]] = []  # (variable assigned, the variables its value reads)
    for m in program.machines:
        for body in bodies(m):
            for t in body.graph.transitions:
                if t.condition is not None:
                    names.update(read(t.condition))
                    if failures:
                        names.update(failing_operands(t.condition))
            for st in body_statements(body):
                if failures:
                    for e in s.statement_expressions(st):
                        names.update(failing_operands(e))
                if isinstance(st, s.IfStmt):
                    names.update(read(st.condition))
                elif isinstance(st, s.Assign) and s.root_name(st.target) is not None:
                    flows.append((s.root_name(st.target).name.last, read(st.value)))
                elif isinstance(st, s.CallStmt) and (callee := body.calls.get(st.operation.last)) is not None:
                    flows.extend((param, read(arg)) for (param, _), arg in zip(callee.params, st.args))
                elif isinstance(st, s.Send) and st.value is not None:
                    for receiver, event in program.internal_routes.get((m.index, st.event.last), ()):
                        for test in event_tests_in(program.machines[receiver], event):
                            if test.bind:
                                flows.append((test.bind, read(st.value)))
                            if test.value is not None:
                                names.update(read(st.value))
    grown = True
    while grown:  # what flows into a steering variable steers too
        before = len(names)
        for target, sources in flows:
            if target in names:
                names |= sources
        grown = len(names) > before
    return names
