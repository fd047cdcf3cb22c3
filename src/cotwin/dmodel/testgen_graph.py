"""The state graph of a d-model module, for test generation: the verifier's exploration kept as a graph.

The exploration is the verifier's (cotwin.dmodel.verify): breadth first from the initial state, every
combination of input events per cycle, event values from the same domains (data independence where
no condition reads a value). Where the verifier keeps only a parent per state (a shortest trace),
this keeps every cycle as an edge: its inputs, its outputs, the transitions taken in it (in order)
and the active leaf state of each machine after it. Input combinations with the same effect (same
next state, outputs and transitions) collapse into one edge whose stimulus is the simplest of them
(fewest events, then the first in exploration order), so that generated cases send no more than
they need.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

from .growth import GrowthWatch
from .interpreter import ExecutionError, Interpreter, Output, freeze
from .program import Program
from .verify import event_values, format_trace, input_combinations


class _Sequence(list):
    """The interpreter records each transition taken with `taken.add`; kept here in order."""

    add = list.append


@dataclass(frozen=True)
class Cycle:
    """One cycle from graph node `source` to `target`."""

    source: int
    target: int
    inputs: tuple[tuple[str, object], ...]  # (event, value or None), in the program's input order
    outputs: tuple[Output, ...]
    taken: tuple[tuple[int, int], ...]  # (machine, edge index) of the transitions taken, in order
    states: tuple[int, ...]  # per machine: index of the active leaf state after the cycle (-1: none)

    @property
    def input_dict(self) -> dict:
        return dict(self.inputs)


@dataclass
class Failure:
    """A cycle the model cannot complete (a timelock, a division by zero...): what it would have covered
    is unreachable through it."""

    source: int
    inputs: tuple[tuple[str, object], ...]
    kind: str
    message: str


@dataclass
class StateGraph:
    program: Program
    snapshots: list = field(default_factory=list)  # node id -> interpreter snapshot (node 0: the initial state)
    cycles: list[list[Cycle]] = field(default_factory=list)  # node id -> its outgoing cycles
    failures: list[Failure] = field(default_factory=list)
    complete: bool = True
    input_combinations: int = 0
    value_notes: list[str] = field(default_factory=list)
    domains: dict[str, list] = field(default_factory=dict)  # the value domains given (--domain)
    stopped: str = ""  # why the exploration ended before the last state (every transition taken)
    unbounded: str = ""  # the exploration stopped early: a counter grows without bound, where and how (growth.py)
    seconds: float = 0.0

    @property
    def edges(self) -> int:
        return sum(len(c) for c in self.cycles)


def _frozen(inputs: dict) -> tuple:
    return tuple(inputs.items())


def explore(program: Program, domains: dict[str, list] | None = None, max_states: int = 100_000,
            parameters: dict | None = None, until_all_taken: bool = False, progress=None) -> StateGraph:
    """Every state reachable from the initial one under every input combination (see module doc). With
    `until_all_taken` the exploration adds no state once every transition of the model has been taken (every
    state has then been entered, and the graph holds a path to each); the states found are still expanded,
    so that walks can go on from each: a model with endless data (a counter, a random source) then needs
    only the states up to there. A counter proven to grow without bound (growth.py, the verifier's watch) stops
    the adding of states at once, as the state limit would, with `unbounded` saying which and where.
    `progress(states done, states found)` is called every 100 states."""
    started = time.perf_counter()
    graph = StateGraph(program, domains=dict(domains or {}))
    values, graph.value_notes = event_values(program, domains or {})
    combos = sorted(input_combinations(program, values), key=len)  # stable: fewest events first
    graph.input_combinations = len(combos)
    interp = Interpreter(program, parameters)
    root = interp.snapshot()
    ids = {root: 0}
    depth = [0]
    graph.snapshots.append(root)
    graph.cycles.append([])
    queue = deque([0])
    watch = GrowthWatch(program, interp)
    parent: dict = {root: None}  # snapshot -> (parent snapshot, (inputs, draws)), for the watch
    depths: dict = {root: 0}
    edges = {(m.index, e.index) for m in program.machines for e in m.graph.edges}
    taken_all: set = set()
    closing = False  # every transition taken: the states found are expanded, no new one is added
    while queue:
        if until_all_taken and not closing and taken_all >= edges:
            closing = True
            graph.stopped = f"every transition taken after {len(graph.snapshots)} states"
        node = queue.popleft()
        if progress is not None and node % 100 == 0:
            progress(node, len(graph.snapshots))
        snap = graph.snapshots[node]
        seen: dict[tuple, Cycle] = {}
        for inputs in combos:
            interp.restore(snap)
            interp.cycle = depth[node]
            interp.warnings = []
            interp.taken = _Sequence()
            try:
                outputs = tuple(interp.step(dict(inputs)))
            except ExecutionError as err:
                graph.failures.append(Failure(node, _frozen(inputs), err.kind, err.findings[0].message))
                continue
            nxt = interp.snapshot()
            target = ids.get(nxt)
            fresh = False  # a new state for the growth watch (after this cycle's transitions and states are read)
            if target is None:
                if closing:
                    continue
                if len(ids) >= max_states or graph.unbounded:
                    graph.complete = False
                    continue
                target = ids[nxt] = len(graph.snapshots)
                graph.snapshots.append(nxt)
                graph.cycles.append([])
                depth.append(depth[node] + 1)
                queue.append(target)
                fresh = watch.enabled
            taken = tuple(interp.taken)
            taken_all.update(taken)
            states = tuple(interp.state_index(m.index) for m in program.machines)
            if fresh:  # the watch replays a round on the interpreter: only now
                parent[nxt], depths[nxt] = (snap, (dict(inputs), ())), depth[target]
                grows = watch.add(nxt, parent, depths)
                if grows is not None:  # the state space is infinite: add no more states
                    graph.complete = False
                    graph.unbounded = grows.message(format_trace)
                    graph.stopped = graph.stopped or f"after {len(graph.snapshots)} states: {graph.unbounded}"
            key = (target, tuple((o.kind, o.name, freeze(o.args)) for o in outputs), taken)
            if key not in seen:
                seen[key] = Cycle(node, target, _frozen(inputs), outputs, taken, states)
        graph.cycles[node] = list(seen.values())
    interp.taken = None
    graph.seconds = time.perf_counter() - started
    return graph
