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
from ..robosim.dmodel_elements import Junction
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
