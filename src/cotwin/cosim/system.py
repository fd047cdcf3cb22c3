"""The system structure of a co-simulation: units, the connections between their ports, the units whose
outputs are read one step late (`delayed`), logged variables and parameters, and the model files it was
made from (`models`, so that a saved state names which one changed). Description only: the
algorithms (cotwin.cosim.algorithm) execute it and the observers (cotwin.cosim.observers) watch it.

`System.check()` returns every problem at once: unknown units or ports, an output feeding an output,
two sources into one input (fan-in), type-incompatible connections, and cycles no delayed unit breaks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError
from .units import Unit


@dataclass(frozen=True)
class Connection:
    source: str  # unit name
    output: str
    target: str
    input: str

    def __str__(self) -> str:
        return f"{self.source}.{self.output} -> {self.target}.{self.input}"


def topological_order(units: list[str], connections: list[Connection], delayed: set[str]) -> list[str]:
    """Units ordered so that every undelayed connection goes forward; a cycle is an error naming it."""
    edges: dict[str, set[str]] = {u: set() for u in units}
    for c in connections:
        if c.source not in delayed and c.source != c.target:
            edges[c.source].add(c.target)
    order: list[str] = []
    state = {u: 0 for u in units}

    def visit(u: str, path: list[str]) -> None:
        if state[u] == 2:
            return
        if state[u] == 1:
            cycle = path[path.index(u):] + [u]
            raise CotwinError("the connections form a cycle " + " -> ".join(cycle)
                              + "; declare one of its units' outputs delayed to break it")
        state[u] = 1
        for v in sorted(edges[u]):
            visit(v, path + [u])
        state[u] = 2
        order.append(u)

    for u in units:
        visit(u, [])
    return list(reversed(order))


@dataclass
class System:
    """Units and connections, checked once; `order` is the dependency order (delayed sources cut)."""

    units: dict[str, Unit]
    connections: list[Connection]
    delayed: set[str] = field(default_factory=set)
    log: dict[str, list[str]] = field(default_factory=dict)
    parameters: dict[str, dict[str, object]] = field(default_factory=dict)
    models: dict[str, str] = field(default_factory=dict)  # the model files it was made from: name -> sha256

    @classmethod
    def of(cls, units: list[Unit], connections: list[Connection], delayed=(), log=None, parameters=None,
           models=None) -> "System":
        by_name: dict[str, Unit] = {}
        for u in units:
            if u.name in by_name:
                raise CotwinError(f"two units are called '{u.name}'")
            by_name[u.name] = u
        system = cls(by_name, list(connections), set(delayed),
                     {u: list(dict.fromkeys(names)) for u, names in (log or {}).items()}, dict(parameters or {}),
                     dict(models or {}))
        problems = system.check()
        if problems:
            raise CotwinError(problems)
        return system

    def check(self) -> list[str]:
        problems: list[str] = []
        for name in self.delayed:
            if name not in self.units:
                problems.append(f"delayed unit '{name}' is not a unit of the system")
        sources: dict[tuple[str, str], Connection] = {}
        for c in self.connections:
            kinds = []
            for unit, port, kind in ((c.source, c.output, "output"), (c.target, c.input, "input")):
                if unit not in self.units:
                    problems.append(f"connection {c}: no unit '{unit}'")
                    kinds.append(None)
                    continue
                p = self.units[unit].ports.get(port)
                if p is None or p.causality != kind:
                    problems.append(f"connection {c}: unit {unit} has no {kind} '{port}'")
                    kinds.append(None)
                    continue
                kinds.append(p.type)
            if None not in kinds and kinds[0] != kinds[1]:
                problems.append(f"connection {c}: {_article(kinds[0])} output cannot feed {_article(kinds[1])} input")
            key = (c.target, c.input)
            if key in sources and sources[key] != c:
                problems.append(f"input {c.target}.{c.input} has two sources: {sources[key].source}.{sources[key].output} "
                                f"and {c.source}.{c.output}")
            sources.setdefault(key, c)
        for unit, names in self.log.items():
            if unit not in self.units:
                problems.append(f"logged variables of unknown unit '{unit}'")
                continue
            for n in names:
                if n not in self.units[unit].ports:
                    problems.append(f"logVariables: unit {unit} has no variable '{n}'")
        for unit, values in self.parameters.items():
            if unit not in self.units:
                problems.append(f"parameters of unknown unit '{unit}'")
                continue
            for n in values:
                p = self.units[unit].ports.get(n)
                if p is None or p.causality != "parameter":
                    problems.append(f"parameters: unit {unit} has no parameter '{n}'")
        if not problems:
            try:
                topological_order(list(self.units), self.connections, self.delayed)
            except CotwinError as err:
                problems.extend(f.message for f in err.findings)
        return problems

    @property
    def order(self) -> list[str]:
        return topological_order(list(self.units), self.connections, self.delayed)

    def observed(self) -> list[tuple[str, str]]:
        """The variables a result shows (Maestro's columns): connected outputs, then logged variables,
        unit by unit in the system's order, each once."""
        out: dict[str, list[str]] = {u: [] for u in self.units}
        for c in self.connections:
            out[c.source].append(c.output)
        for u, names in self.log.items():
            out[u].extend(names)
        return [(u, n) for u in self.units for n in dict.fromkeys(out[u])]


def _article(kind: str) -> str:
    """'a Real', 'an Integer'."""
    return f"{'an' if kind[:1] in 'AEIOU' else 'a'} {kind}"
