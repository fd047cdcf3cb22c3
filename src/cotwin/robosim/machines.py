"""The graph of a state machine: its nodes with their nesting, and transitions resolved to nodes.

A transition declared in a container (the machine or a state) names its source and target by simple
name: first among the container's own nodes, then among its descendants (the name must be unique
there), then among the enclosing containers' nodes. Checker, interpreter, C generator and verifier
all use this one resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import Diagnostics
from .dmodel_elements import Final, Initial, Junction, Node, State, StateMachine, Transition


@dataclass(eq=False)
class NodeInfo:
    node: Node
    path: tuple[str, ...]  # names from the machine's top level down to this node
    parent: "NodeInfo | None"
    index: int = -1
    children: list["NodeInfo"] = field(default_factory=list)
    outgoing: list["Edge"] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.node.name

    @property
    def qualified(self) -> str:
        return "_".join(self.path)

    @property
    def is_state(self) -> bool:
        return isinstance(self.node, State)

    @property
    def is_leaf(self) -> bool:
        return isinstance(self.node, (State, Final)) and not any(c.is_state for c in self.children)

    def ancestors(self) -> list["NodeInfo"]:
        """From the parent outwards."""
        out, node = [], self.parent
        while node is not None:
            out.append(node)
            node = node.parent
        return out


@dataclass(eq=False)
class Edge:
    transition: Transition
    source: NodeInfo
    target: NodeInfo
    index: int


class MachineGraph:
    def __init__(self, machine: StateMachine, diag: Diagnostics | None = None):
        self.machine = machine
        self.diag = diag
        self.nodes: list[NodeInfo] = []
        self.top: list[NodeInfo] = []
        self.edges: list[Edge] = []
        self._containers: list[tuple[NodeInfo | None, tuple[Node, ...], tuple[Transition, ...]]] = []
        self.top = self._add_nodes(machine.nodes, None, ())
        self._containers.insert(0, (None, machine.nodes, machine.transitions))
        for container, _, transitions in self._containers:
            for t in transitions:
                self._add_edge(container, t)

    def _add_nodes(self, nodes, parent: NodeInfo | None, path: tuple[str, ...]) -> list[NodeInfo]:
        infos = []
        seen: dict[str, Node] = {}
        for node in nodes:
            if node.name in seen and self.diag is not None:
                self.diag.error(node.loc, f"duplicate node '{node.name}' (first declared at {seen[node.name].loc})")
            seen.setdefault(node.name, node)
            info = NodeInfo(node, path + (node.name,), parent, len(self.nodes))
            self.nodes.append(info)
            infos.append(info)
            if isinstance(node, State):
                info.children = self._add_nodes(node.nodes, info, info.path)
                self._containers.append((info, node.nodes, node.transitions))
        return infos

    def children_of(self, container: NodeInfo | None) -> list[NodeInfo]:
        return self.top if container is None else container.children

    def _descendants(self, container: NodeInfo | None) -> list[NodeInfo]:
        out, stack = [], list(self.children_of(container))
        while stack:
            node = stack.pop(0)
            out.append(node)
            stack.extend(node.children)
        return out

    def resolve(self, container: NodeInfo | None, name: str) -> tuple[NodeInfo | None, str | None]:
        """The node `name` as seen from a transition declared in `container`; or an error text."""
        direct = [n for n in self.children_of(container) if n.name == name]
        if direct:
            return direct[0], None
        deeper = [n for n in self._descendants(container) if n.name == name]
        if len(deeper) == 1:
            return deeper[0], None
        if len(deeper) > 1:
            return None, f"'{name}' is ambiguous: " + ", ".join(".".join(n.path) for n in deeper)
        scope = container.parent if container is not None else None
        while container is not None:
            hits = [n for n in self.children_of(scope) if n.name == name]
            if hits:
                return hits[0], None
            if scope is None:
                break
            container, scope = scope, scope.parent
        return None, None

    def _add_edge(self, container: NodeInfo | None, t: Transition) -> None:
        source, why_s = self.resolve(container, t.source)
        target, why_t = self.resolve(container, t.target)
        where = f"transition {t.name}"
        if source is None and self.diag is not None:
            self.diag.error(t.source_loc, why_s or f"{where}: unknown source state '{t.source}'")
        if target is None and self.diag is not None:
            self.diag.error(t.target_loc, why_t or f"{where}: unknown target state '{t.target}'")
        if source is None or target is None:
            return
        edge = Edge(t, source, target, len(self.edges))
        self.edges.append(edge)
        source.outgoing.append(edge)

    @property
    def transitions(self) -> list[Transition]:
        """Every declared transition, resolved or not, in container order."""
        return [t for _, _, transitions in self._containers for t in transitions]

    def initial_of(self, container: NodeInfo | None) -> NodeInfo | None:
        return next((n for n in self.children_of(container) if isinstance(n.node, Initial)), None)

    @property
    def states(self) -> list[NodeInfo]:
        return [n for n in self.nodes if isinstance(n.node, (State, Final))]

    @property
    def leaves(self) -> list[NodeInfo]:
        return [n for n in self.nodes if n.is_leaf]

    @property
    def junctions(self) -> list[NodeInfo]:
        return [n for n in self.nodes if isinstance(n.node, Junction)]
