"""Test generation from a d-model: a small suite of cases that together cover every reachable state,
transition or pair of consecutive transitions (RoboStar's criteria, here timed and for co-simulation).

From the state graph (cotwin.dmodel.testgen_graph, the verifier's exploration) the generator walks
from the initial state to the nearest uncovered item, then on to the next nearest, until the case is
back at rest (where the initial state goes without inputs) having covered something, or has
`max_cycles` cycles; a new case starts afresh from the initial state. A greedy minimisation then
keeps the walks that add the most uncovered items (ties: the shorter), trims each kept walk after the
last cycle that adds something, and drops any walk the others make redundant; both counts are reported.

A case is a timed list of the d-model's input events with their values, one entry per cycle, and the
oracle: the operation calls and output events of every cycle (with their arguments), the leaf states
after it and the transitions it took, as the reference interpreter computes them. Inputs are of two
kinds: commands (from the operator or a plan) and the platform's answers (feasibility, completion,
sensor events). A case's `answers` say who gives the latter: "stub" (the case carries them: the
platform's events are replaced by the case's, an exact oracle cycle by cycle) or "platform" (only the
commands are sent, each once the d-model is back in the state the case sends it in; the platform
answers, and the case passes when the d-model conforms to the interpreter on what it received and
covers the items the case was made for).

Items no input sequence reaches are listed with the reason (the source state is never active, the
condition never holds there, the exploration stopped at its limit, ...).
"""

from __future__ import annotations

import hashlib
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Hashable, Iterable

from ..robosim.dmodel_elements import Initial
from .interpreter import Output
from .program import Program
from .testgen_graph import Cycle, StateGraph

CRITERIA = ("states", "transitions", "transition-pairs")
Item = Hashable


def machine_label(program: Program, m) -> str:
    return m.machine.name if len(program.machines) == 1 else m.name


# ---- coverage criteria: nodes to walk, the items each cycle covers, and every item there is ----


class Coverage:
    """A criterion over a state graph: `successors(node)` -> [(cycle, next node)], `items(node, cycle)`,
    `universe` (every item of the model, reachable or not) and a readable `name(item)`."""

    criterion = ""

    def __init__(self, graph: StateGraph):
        self.graph = graph
        self.program = graph.program
        self.start: Hashable = 0

    def successors(self, node) -> list[tuple[Cycle, Hashable]]:
        return [(c, c.target) for c in self.graph.cycles[node]]

    def items(self, node, cycle: Cycle) -> set:
        raise NotImplementedError

    @property
    def universe(self) -> list:
        raise NotImplementedError

    def name(self, item) -> str:
        raise NotImplementedError

    def why_unreached(self, item, reached: set) -> str:
        raise NotImplementedError

    # shared naming
    def edge(self, m: int, e: int):
        return self.program.machines[m].graph.edges[e]

    def transition_name(self, m: int, e: int) -> str:
        return f"{machine_label(self.program, self.program.machines[m])}.{self.edge(m, e).transition.name}"

    def state_name(self, m: int, node: int) -> str:
        machine = self.program.machines[m]
        return f"{machine_label(self.program, machine)}.{'.'.join(machine.graph.nodes[node].path)}"


def _entered_leaves(program: Program, cycle: Cycle) -> set:
    out = set()
    for m, e in cycle.taken:
        target = program.machines[m].graph.edges[e].target
        if target.is_leaf:
            out.add((m, target.index))
    return out


def _active_states(graph: StateGraph) -> set[tuple[int, int]]:
    """(machine, node) of every leaf state some cycle of the exploration enters."""
    out = set()
    for cycles in graph.cycles:
        for c in cycles:
            out |= _entered_leaves(graph.program, c)
    return out


class StateCoverage(Coverage):
    criterion = "states"

    def items(self, node, cycle: Cycle) -> set:
        return _entered_leaves(self.program, cycle)

    @property
    def universe(self) -> list:
        return [(m.index, leaf.index) for m in self.program.machines for leaf in m.graph.leaves]

    def name(self, item) -> str:
        return f"state {self.state_name(*item)}"

    def why_unreached(self, item, reached: set) -> str:
        m, node = item
        graph = self.program.machines[m].graph
        into = [e for e in graph.edges if e.target.index == node]
        if not into:
            return "no transition leads into it"
        return (f"no input sequence takes a transition into it ({', '.join(e.transition.name for e in into)}): "
                "each is never enabled where its source is active")


class TransitionCoverage(Coverage):
    criterion = "transitions"

    def items(self, node, cycle: Cycle) -> set:
        return set(cycle.taken)

    @property
    def universe(self) -> list:
        return [(m.index, e.index) for m in self.program.machines for e in m.graph.edges]

    def name(self, item) -> str:
        return f"transition {self.transition_name(*item)}"

    def why_unreached(self, item, reached: set) -> str:
        return _transition_reason(self, item, reached)


def _transition_reason(cov: Coverage, item, reached_transitions: set) -> str:
    m, e = item
    edge = cov.edge(m, e)
    source = edge.source
    entered = [cov.edge(mm, ee).target for mm, ee in reached_transitions if mm == m]
    reached = isinstance(source.node, Initial) or any(t is source or source in t.ancestors() for t in entered)
    where = ".".join(source.path)
    if not reached:
        kind = "state" if source.is_state else "junction"
        return f"its source {kind} {where} is never active"
    if edge.transition.condition is not None:
        return f"its condition never holds while {where} is active, for any input (values explored: see the notes)"
    return f"another transition is always taken from {where} before it"


class PairCoverage(Coverage):
    """Pairs of transitions one machine takes one after the other (in one cycle or across cycles). The
    walk's nodes are (graph node, last transition of each machine)."""

    criterion = "transition-pairs"

    def __init__(self, graph: StateGraph):
        super().__init__(graph)
        self.start = (0, tuple(-1 for _ in self.program.machines))

    def successors(self, node) -> list[tuple[Cycle, Hashable]]:
        g, last = node
        out = []
        for c in self.graph.cycles[g]:
            after = list(last)
            for m, e in c.taken:
                after[m] = e
            out.append((c, (c.target, tuple(after))))
        return out

    def items(self, node, cycle: Cycle) -> set:
        _, last = node
        last = list(last)
        pairs = set()
        for m, e in cycle.taken:
            if last[m] >= 0:
                pairs.add((m, last[m], e))
            last[m] = e
        return pairs

    @property
    def universe(self) -> list:
        """Syntactically adjacent pairs: the second leaves the first's target, a state around it or inside it."""
        out = []
        for m in self.program.machines:
            for first in m.graph.edges:
                target = first.target
                around = {target.index, *(a.index for a in target.ancestors())}
                for second in m.graph.edges:
                    src = second.source
                    if src.index in around or target.index in {a.index for a in src.ancestors()}:
                        out.append((m.index, first.index, second.index))
        return out

    def name(self, item) -> str:
        m, a, b = item
        return f"pair {self.transition_name(m, a)} -> {self.edge(m, b).transition.name}"

    def why_unreached(self, item, reached: set) -> str:
        m, a, b = item
        taken = {(mm, e) for cycles in self.graph.cycles for c in cycles for mm, e in c.taken}
        for e in (a, b):
            if (m, e) not in taken:
                return f"transition {self.edge(m, e).transition.name} is never taken"
        return "both are taken, but never one right after the other"


COVERAGE: dict[str, type[Coverage]] = {"states": StateCoverage, "transitions": TransitionCoverage,
                                       "transition-pairs": PairCoverage}


# ---- walks and their minimisation ----


@dataclass
class Walk:
    steps: list[tuple[Hashable, Cycle]] = field(default_factory=list)  # (node before, cycle)
    items: list[set] = field(default_factory=list)  # items each cycle covers

    @property
    def covered(self) -> set:
        return set().union(*self.items) if self.items else set()

    def trimmed(self, keep: set) -> "Walk":
        """This walk cut after its last cycle covering an item of `keep`."""
        last = max((k for k, its in enumerate(self.items) if its & keep), default=-1)
        return Walk(self.steps[:last + 1], self.items[:last + 1])


def _nearest(cov: Coverage, start, wanted: set, limit: int | None):
    """The shortest path [(node, cycle, next)] from `start` whose last cycle covers an item of `wanted`,
    within `limit` cycles (None: any length); None if there is none."""
    parent: dict = {start: None}
    queue = deque([(start, 0)])
    while queue:
        node, depth = queue.popleft()
        if limit is not None and depth >= limit:
            continue
        for cycle, nxt in cov.successors(node):
            if cov.items(node, cycle) & wanted:
                path = [(node, cycle, nxt)]
                back = parent[node]
                while back is not None:
                    path.append(back)
                    back = parent[back[0]]
                return list(reversed(path))
            if nxt not in parent:
                parent[nxt] = (node, cycle, nxt)
                queue.append((nxt, depth + 1))
    return None


def home(cov: Coverage) -> tuple | None:
    """The rest states: the active leaf states the initial state settles in without inputs (None if it does
    not). Data (a variable bound from the last command) may differ at rest: only the control state counts."""
    return next((cycle.states for cycle, _ in cov.successors(cov.start) if not cycle.inputs), None)


def build_walks(cov: Coverage, targets: set, max_cycles: int, split: str = "rest") -> tuple[list[Walk], set]:
    """Walks from the initial state, each going to the nearest uncovered item while it has room (a case's
    first item may lie further than `max_cycles`: it is reached all the same); with `split` "rest" a walk
    also ends when it is back at rest (`home`) having covered something new, so that each case is one
    excursion from rest and back. Returns the walks and the items left uncovered."""
    uncovered = set(targets)
    walks: list[Walk] = []
    rest = home(cov) if split == "rest" else None
    while uncovered:
        walk, node, fresh, back = Walk(), cov.start, False, False
        while not back:
            room = None if not walk.steps else max_cycles - len(walk.steps)
            if room is not None and room <= 0:
                break
            path = _nearest(cov, node, uncovered, room)
            if path is None:
                break
            for k, (before, cycle, after) in enumerate(path):
                its = cov.items(before, cycle)
                walk.steps.append((before, cycle))
                walk.items.append(its)
                fresh |= bool(its & uncovered) and len(walk.steps) > 1
                uncovered -= its
                node = after
                if rest is not None and cycle.states == rest and fresh:
                    back = True
                    break
        if not walk.steps:
            break
        walks.append(walk)
    return walks, uncovered


def minimise(walks: list[Walk], targets: set) -> list[Walk]:
    """Greedy set cover of `targets` by the walks (most new items first, then the shorter), each kept
    walk trimmed after its last new item, then any walk the others cover dropped (see module doc)."""
    chosen: list[Walk] = []
    left = set(targets)
    pool = list(walks)
    while left and pool:
        best = max(pool, key=lambda w: (len(w.covered & left), -len(w.steps), -walks.index(w)))
        gain = best.covered & left
        if not gain:
            break
        pool.remove(best)
        chosen.append(best.trimmed(gain))
        left -= gain
    for walk in list(chosen):
        others = set().union(*(w.covered for w in chosen if w is not walk)) if len(chosen) > 1 else set()
        if (walk.covered & targets) <= others:
            chosen.remove(walk)
    return chosen


# ---- the suite ----


@dataclass
class CaseStep:
    """One cycle of a case: what the d-model receives and what the oracle says it does."""

    cycle: int
    inputs: dict  # event -> value (None for an event without one)
    outputs: list[Output]
    states: list[str]  # per machine, the active leaf after the cycle
    transitions: list[str]  # taken in the cycle, in order ("Machine.name")


@dataclass
class Case:
    name: str
    steps: list[CaseStep]
    covers: list[str]  # items this case was kept for
    items: list[str]  # every item it covers
    answers: str = "stub"  # stub | platform (see module doc)
    note: str = ""  # why its answers are what they are, when chosen by trying them (cotwin testgen --answers auto)

    @property
    def cycles(self) -> int:
        return len(self.steps)


@dataclass
class Suite:
    program: Program
    criterion: str
    cases: list[Case]
    total: list[str]  # every item of the model
    reached: list[str]  # those some input sequence reaches
    unreachable: list[tuple[str, str]]  # (item, why)
    uncovered: list[tuple[str, str]]  # reachable but left out by the generator, and why
    walks: int  # built before minimisation
    commands: list[str]  # input events that are commands; the others are the platform's answers
    graph: StateGraph
    max_cycles: int

    @property
    def covered(self) -> list[str]:
        seen = {i for c in self.cases for i in c.items}
        return [i for i in self.reached if i in seen]

    @property
    def cycles(self) -> int:
        return sum(c.cycles for c in self.cases)


def generate(graph: StateGraph, criterion: str = "transitions", max_cycles: int = 30,
             commands: Iterable[str] | None = None, answers: str = "stub", split: str = "rest") -> Suite:
    """The suite covering every reachable item of `criterion` (see module doc). `commands` names the input
    events that are commands (default: all of them, so that no input is the platform's); `split` "rest"
    ends a case when it is back at rest, "length" only at `max_cycles`."""
    program = graph.program
    if criterion not in COVERAGE:
        raise ValueError(f"unknown coverage criterion {criterion!r} (known: {', '.join(CRITERIA)})")
    cov = COVERAGE[criterion](graph)
    universe = cov.universe
    reached = _reachable(cov)
    targets = {i for i in universe if i in reached}
    walks, left = build_walks(cov, targets, max_cycles, split)
    kept = minimise(walks, targets)
    cases = []
    for k, walk in enumerate(kept, start=1):
        seen_before = set().union(*(w.covered for w in kept[:k - 1])) if k > 1 else set()
        cases.append(Case(f"case_{k:02d}", _steps(program, walk), [cov.name(i) for i in _ordered(walk, targets - seen_before)],
                          [cov.name(i) for i in _ordered(walk, targets)], answers))
    reached_transitions = {(m, e) for cycles in graph.cycles for c in cycles for m, e in c.taken}
    if graph.complete:
        unreachable = [(cov.name(i), cov.why_unreached(i, reached_transitions)) for i in universe if i not in reached]
    elif graph.unbounded:  # a counter grows for ever: the exploration stopped early, located
        limit = f"not reached: the exploration stopped after {len(graph.snapshots)} states: {graph.unbounded}"
        unreachable = [(cov.name(i), limit) for i in universe if i not in reached]
    else:  # nothing is known of what lies beyond the limit
        from .verify import growth_hint

        limit = (f"not reached within the state limit ({len(graph.snapshots)} states): raise --max-states, or give "
                 "--domain values of the inputs its conditions compare against" + growth_hint(program, graph.snapshots))
        unreachable = [(cov.name(i), limit) for i in universe if i not in reached]
    covered = set().union(*(w.covered for w in kept)) if kept else set()
    uncovered = [(cov.name(i), "no walk from the initial state reaches it") for i in universe
                  if i in targets and i not in covered]
    names = [ev.name for ev in program.inputs]
    return Suite(program, criterion, cases, [cov.name(i) for i in universe], [cov.name(i) for i in universe if i in reached],
                 unreachable, uncovered, len(walks), [n for n in names if commands is None or n in set(commands)],
                 graph, max_cycles)


def _reachable(cov: Coverage) -> set:
    """Every item some walk from the start covers (a search of the criterion's whole node space)."""
    out, seen, queue = set(), {cov.start}, deque([cov.start])
    while queue:
        node = queue.popleft()
        for cycle, nxt in cov.successors(node):
            out |= cov.items(node, cycle)
            if nxt not in seen:
                seen.add(nxt)
                queue.append(nxt)
    return out


def _ordered(walk: Walk, wanted: set) -> list:
    """Items of `wanted` in the order the walk first covers them."""
    out, seen = [], set()
    for its in walk.items:
        for i in sorted(its & wanted, key=repr):
            if i not in seen:
                seen.add(i)
                out.append(i)
    return out


def _steps(program: Program, walk: Walk) -> list[CaseStep]:
    out = []
    for k, (_, cycle) in enumerate(walk.steps, start=1):
        states = []
        for m, index in zip(program.machines, cycle.states):
            states.append(".".join(m.graph.leaves[index].path) if index >= 0 else "")
        transitions = [f"{machine_label(program, program.machines[m])}.{program.machines[m].graph.edges[e].transition.name}"
                       for m, e in cycle.taken]
        out.append(CaseStep(k, cycle.input_dict, list(cycle.outputs), states, transitions))
    return out


def replay_items(program: Program, criterion: str, taken: list[list[tuple[int, int]]]) -> list[str]:
    """The items of `criterion` a run covers, in the order it first covers them, from the transitions
    (machine, edge) it took in each cycle (an interpreter's record, e.g. a replay of a co-simulation)."""
    from .testgen_graph import StateGraph

    cov = COVERAGE[criterion](StateGraph(program))
    node = cov.start
    seen: dict = {}
    for cycle_taken in taken:
        cycle = Cycle(0, 0, (), (), tuple(cycle_taken), ())
        for item in sorted(cov.items(node, cycle), key=repr):
            seen.setdefault(item, None)
        if criterion == "transition-pairs":
            last = list(node[1])
            for m, e in cycle_taken:
                last[m] = e
            node = (0, tuple(last))
    return [cov.name(i) for i in seen]


def model_digest(program: Program) -> str:
    """A digest of the d-model texts (.rst, .rct) the program was built from: a suite refuses to judge another
    d-model (p-models and mappings may change: they are the platform's)."""
    h = hashlib.sha256()
    for f in sorted(program.project.files, key=lambda f: str(f.path)):
        if str(f.path).startswith("<") or Path(f.path).suffix not in (".rst", ".rct"):
            continue
        try:
            h.update(Path(f.path).read_bytes())
        except OSError:
            continue
    h.update(program.module.name.encode())
    return h.hexdigest()[:16]


__all__ = ["CRITERIA", "Case", "CaseStep", "Coverage", "Suite", "build_walks", "generate", "minimise", "model_digest"]
