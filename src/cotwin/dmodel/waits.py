"""What a d-model's leaf states wait for: the platform's input events that can move a machine out of one.

A leaf state *waits* when every way out of it (a path of transitions from it, or from a state enclosing
it, through junctions, to another state) is guarded by input events of the platform; `waits` gives, per
waiting leaf, those events by their platform names. A way out whose guards read no platform event (a
clock, a variable, no guard at all, an event from another machine) is one the machine may take by
itself: such a state does not wait. What the state does while it waits (entry and during actions) is
not looked at here; the run-time watch (cotwin.twin.assembly.waits) also asks that the machine calls nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..robosim import syntax as s
from ..robosim.dmodel_elements import Junction, State
from .program import Program


@dataclass(frozen=True)
class Wait:
    machine: str  # the machine instance's name
    state: str  # the leaf's path, e.g. "Moving" or "Avoid.Listening"
    events: frozenset[str]  # platform input events read on the ways out


def _events(expr, platform: dict[str, str]) -> tuple[set[str], bool]:
    """The platform events a guard reads, and whether it reads one that is not the platform's."""
    found, other = set(), False
    for node in s.walk(expr) if expr is not None else ():
        if isinstance(node, s.EventTest):
            name = platform.get(node.event.last)
            if name is None:
                other = True
            else:
                found.add(name)
    return found, other


def waits(program: Program) -> dict[tuple[int, int], Wait]:
    """(machine index, leaf index) -> Wait, for the leaves that wait (see module doc)."""
    out: dict[tuple[int, int], Wait] = {}
    for m in program.machines:
        platform = {event: name for name, routes in program.input_routes.items()
                    for machine, event in routes if machine == m.index}
        for k, leaf in enumerate(m.graph.leaves):
            events, free = set(), False
            stack = [(edge, frozenset(), frozenset()) for node in (leaf, *leaf.ancestors()) for edge in node.outgoing]
            while stack and not free:
                edge, read, seen = stack.pop()
                found, other = _events(edge.transition.condition, platform)
                read = read | found
                if other:
                    free = True
                elif isinstance(edge.target.node, Junction):
                    if edge.target.index not in seen:
                        stack.extend((e, read, seen | {edge.target.index}) for e in edge.target.outgoing)
                elif edge.target is not leaf:  # a way out
                    if not read:
                        free = True
                    events |= read
            if not free and events:
                out[(m.index, k)] = Wait(m.name, ".".join(leaf.path), frozenset(events))
    return out


class CycleReads:
    """Which platform input events a machine may have read in a cycle that took it from one leaf to another
    (`between`): the events the guards read on the cycle's possible paths from the leaf (its ways out, or those
    of a state enclosing it) through junctions and the states entered (up to their `exec`) to the other leaf
    (or a state enclosing it), with the guards of the `exec` transitions out of that leaf (or a state enclosing
    it: one of them chosen there ends the cycle, its target entered in the next) and the events the machine's
    actions and software operations read anywhere (an `if $e` in an entry action). An over-approximation: an
    event outside it was not taken in that cycle (a command the d-model read while an earlier one moved it on:
    cotwin.twin.assembly.outcomes). `several`: the step ran several cycles (a d-model cycle_period shorter than
    the step): the paths then go on past `exec`. None where it cannot tell (a RoboChart trigger on the way, too
    many paths, or no path it knows of from the one leaf to the other)."""

    LIMIT = 20000  # paths explored per question, beyond which it cannot tell

    def __init__(self, program: Program):
        self.program = program
        self._cache: dict[tuple[int, int, int], frozenset[str] | None] = {}
        self._passes: dict[tuple, bool] = {}
        self._machines = {m.index: m for m in program.machines}
        self._platform = {m.index: {event: name for name, routes in program.input_routes.items()
                                    for machine, event in routes if machine == m.index} for m in program.machines}
        self._actions = {m.index: _action_reads(m, self._platform[m.index]) for m in program.machines}

    def between(self, machine: int, before: int | None, after: int, several: bool = False,
                absent: frozenset[str] = frozenset()) -> frozenset[str] | None:
        """What a cycle taking the machine from leaf `before` (None: its first cycle, from its initial junction) to
        leaf `after` may have read, or None where that cannot be told. `absent`: platform events that did not
        occur when the cycle before read its guards: an `exec` transition out of `before` whose guard needs one
        of them (Going -> Idle on `$unreachable`) was not chosen then, so no path starts with it."""
        key = (machine, before, after, several, absent)
        if key not in self._cache:
            self._cache[key] = self._explore(machine, before, after, several, absent=absent)
        return self._cache[key]

    def passes(self, machine: int, before: int, after: int, through: int, several: bool = False) -> bool:
        """Whether every cycle taking the machine from leaf `before` to leaf `after` enters leaf `through` on the
        way (Idle entered and left in one cycle: the d-model came back to rest and took the next command at once);
        False where that cannot be told."""
        key = (machine, before, after, several, through)
        if key not in self._passes:
            known = through not in (before, after) and self.between(machine, before, after, several) is not None
            self._passes[key] = known and self._explore(machine, before, after, several, avoid=through) is None
        return self._passes[key]

    def _explore(self, machine: int, before: int | None, after: int, several: bool = False,
                 avoid: int | None = None, absent: frozenset[str] = frozenset()) -> frozenset[str] | None:
        """`between`'s paths; `avoid`: a leaf no path may enter (None back when no path avoids it)."""
        m = self._machines.get(machine)
        leaves = m.graph.leaves if m is not None else []
        start = m.graph.initial_of(None) if before is None and m is not None else \
            leaves[before] if before is not None and 0 <= before < len(leaves) else None
        if start is None or not 0 <= after < len(leaves):
            return None
        platform, goal = self._platform[machine], leaves[after]
        arrivals = {id(goal), *(id(a) for a in goal.ancestors())}
        found: set[str] = set()
        arrived = False
        # an exec transition out of the leaf was chosen by the cycle before (which read its guard), its target
        # entered in this one
        stack = [(edge, frozenset(), edge.transition.is_exec) for node in (start, *start.ancestors())
                 for edge in node.outgoing
                 if not (edge.transition.is_exec and _required(edge.transition.condition, platform) & absent)]
        seen: set[tuple[int, frozenset, bool]] = set()
        while stack:
            edge, read, chosen = stack.pop()
            if (id(edge), read, chosen) in seen:
                continue
            seen.add((id(edge), read, chosen))
            if len(seen) > self.LIMIT or edge.transition.trigger is not None:
                return None
            if not chosen:
                read = read | _events(edge.transition.condition, platform)[0]
            target = edge.target
            if avoid is not None and target is leaves[avoid]:
                continue
            if id(target) in arrivals:
                found |= read
                arrived = True
            inside, todo = [], [target]
            while todo:  # the target and every node within it (a composite state's initial junction ...)
                node = todo.pop()
                inside.append(node)
                todo.extend(node.children)
            stack.extend((e, read, False) for node in (*inside, *target.ancestors()) for e in node.outgoing
                         if several or not e.transition.is_exec)
        if not arrived:
            return None
        for node in (goal, *goal.ancestors()):  # the exec transition chosen where the cycle ends
            for e in node.outgoing:
                if e.transition.is_exec:
                    if e.transition.trigger is not None:
                        return None
                    found |= _events(e.transition.condition, platform)[0]
        return frozenset(found | self._actions[machine])


def _required(expr, platform: dict[str, str]) -> set[str]:
    """Platform events a guard cannot hold without (`$a /\\ not $b`: a; `$a \\/ $b`: none; `$a \\/ ($a /\\ x)`: a)."""
    if isinstance(expr, s.EventTest):
        name = platform.get(expr.event.last)
        return {name} if name is not None else set()
    if isinstance(expr, s.Binary) and expr.op == "/\\":
        return _required(expr.left, platform) | _required(expr.right, platform)
    if isinstance(expr, s.Binary) and expr.op == "\\/":
        return _required(expr.left, platform) & _required(expr.right, platform)
    return set()


def _action_reads(m, platform: dict[str, str]) -> set[str]:
    """The platform events a machine's actions (entry, during, exit, a transition's) read, and everything its
    software operations read (their guards too: CycleReads follows the machine's own graph only)."""
    found: set[str] = set()

    def read(expr):
        events, other = _events(expr, platform)
        found.update(events if not other else platform.values())  # an event it cannot name: any of them

    for body in (m, *m.frames):
        for node in body.graph.nodes:
            state = node.node
            for stmt in (state.entry, state.during, state.exit) if isinstance(state, State) else ():
                for sub in s.statements(stmt):
                    for expr in s.statement_expressions(sub):
                        read(expr)
            for e in node.outgoing:
                for sub in s.statements(e.transition.action):
                    for expr in s.statement_expressions(sub):
                        read(expr)
                if body is not m:
                    read(e.transition.condition)
    return found

