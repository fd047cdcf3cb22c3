"""The co-simulation master: fixed step, Jacobi (Maestro's algorithm) or dependency-ordered Gauss-Seidel.

Jacobi: every connected input takes its source's output of the previous step, then all units step at
the same t; so each hop of a chain costs one step (the paper's three-step delay from the broker to the
robot). Gauss-Seidel: units step in the topological order of the connection graph, each one reading the
outputs its sources produced in this very step, so a command crosses the whole chain in one step.
Connections out of a unit declared `delayed` are read from the previous step; they break cycles
(a cycle without one is reported). Initialisation propagates start values in dependency order.
Results go to a Maestro-format CSV written row by row, so a failure keeps what was computed.
"""

from __future__ import annotations

import csv
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path

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


@dataclass
class RunResult:
    rows: int
    end_time: float
    wall_seconds: float
    csv_path: Path | None
    columns: list[str] = field(default_factory=list)


def topological_order(units: list[str], connections: list[Connection], delayed: set[str]) -> list[str]:
    """Units ordered so that every undelayed connection goes forward; a cycle is an error naming it."""
    edges = {u: set() for u in units}
    for c in connections:
        if c.source not in delayed and c.source != c.target:
            edges[c.source].add(c.target)
    order, state = [], {u: 0 for u in units}

    def visit(u, path):
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


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


class Master:
    def __init__(self, units: list[Unit], connections: list[Connection], step: float, end: float,
                 start: float = 0.0, algorithm: str = "jacobi", delayed: set[str] | None = None,
                 log: dict[str, list[str]] | None = None, parameters: dict[str, dict] | None = None,
                 realtime: bool = False):
        if algorithm not in ("jacobi", "gauss-seidel"):
            raise CotwinError(f"unknown algorithm '{algorithm}' (jacobi or gauss-seidel)")
        if step <= 0 or end <= start:
            raise CotwinError(f"need a positive step and end > start (step {step}, start {start}, end {end})")
        self.units = {u.name: u for u in units}
        if len(self.units) != len(units):
            raise CotwinError("two units have the same name")
        self.connections = connections
        self.step_size, self.start, self.end = step, start, end
        self.algorithm = algorithm
        self.delayed = set(delayed or ())
        self.parameters = parameters or {}
        self.realtime = realtime
        for c in connections:
            for unit, port, kind in ((c.source, c.output, "output"), (c.target, c.input, "input")):
                if unit not in self.units:
                    raise CotwinError(f"connection {c}: no unit '{unit}'")
                p = self.units[unit].ports.get(port)
                if p is None or p.causality != kind:
                    raise CotwinError(f"connection {c}: unit {unit} has no {kind} '{port}'")
        self.log = {u: list(dict.fromkeys(names)) for u, names in (log or {}).items()}
        for unit, names in self.log.items():
            for n in names:
                if unit not in self.units or n not in self.units[unit].ports:
                    raise CotwinError(f"logVariables: unit {unit} has no variable '{n}'")
        self.order = topological_order(list(self.units), connections, self.delayed)
        self.incoming: dict[str, list[Connection]] = {u: [] for u in self.units}
        for c in connections:
            self.incoming[c.target].append(c)
        outputs: dict[str, list[str]] = {u: [] for u in self.units}
        for c in connections:
            outputs[c.source].append(c.output)
        for u, names in self.log.items():
            outputs[u].extend(names)
        self.watched = {u: list(dict.fromkeys(names)) for u, names in outputs.items()}
        self.columns = [(u, n) for u in self.units for n in self.watched[u]]
        self.values: dict[tuple[str, str], object] = {}
        self.previous: dict[tuple[str, str], object] = {}

    def _inputs_for(self, unit: str, current: bool) -> dict[str, object]:
        """Inputs from the sources' latest outputs; under Gauss-Seidel, a delayed source's are those of
        the previous step (under Jacobi all inputs are set before any unit steps, so latest = previous)."""
        out = {}
        for c in self.incoming[unit]:
            key = (c.source, c.output)
            source = self.previous if current and c.source in self.delayed and key in self.previous else self.values
            out[c.input] = source.get(key)
        return out

    def _read(self, unit: str) -> None:
        names = self.watched[unit]
        if names:
            for n, v in self.units[unit].get(names).items():
                self.values[(unit, n)] = v

    def run(self, csv_path: str | Path | None = None, column_name=None, progress=None) -> RunResult:
        """Co-simulate from start to end; rows are written (and flushed) as they are computed."""
        column_name = column_name or (lambda unit, var: f"{unit}.{var}")
        t = self.start
        rows = 0
        started = wallclock.perf_counter()
        handle = open(csv_path, "w", newline="") if csv_path else None
        writer = csv.writer(handle) if handle else None
        header = ["time"] + [column_name(u, n) for u, n in self.columns]
        try:
            if writer:
                writer.writerow(header)
            for name in self.order:
                unit = self.units[name]
                unit.instantiate(self.start)
                if self.parameters.get(name):
                    unit.set(self.parameters[name])
            for name in self.order:  # initialisation in dependency order
                inputs = self._inputs_for(name, current=True)
                if inputs:
                    self.units[name].set(inputs)
                self._read(name)
            for name in self.order:
                self.units[name].initialize()
                self._read(name)
            self._write(writer, handle, t)
            rows += 1
            n_steps = int(round((self.end - self.start) / self.step_size))
            for k in range(n_steps):
                t = self.start + k * self.step_size
                h = self.step_size
                if self.algorithm == "jacobi":  # inputs are all set before any unit steps: no copy needed
                    for name in self.order:
                        inputs = self._inputs_for(name, current=False)
                        if inputs:
                            self.units[name].set(inputs)
                    for name in self.order:
                        self.units[name].step(t, h)
                    for name in self.order:
                        self._read(name)
                else:
                    if self.delayed:  # delayed connections read the previous step's values
                        self.previous = dict(self.values)
                    for name in self.order:
                        inputs = self._inputs_for(name, current=True)
                        if inputs:
                            self.units[name].set(inputs)
                        self.units[name].step(t, h)
                        self._read(name)
                t = self.start + (k + 1) * self.step_size
                self._write(writer, handle, t)
                rows += 1
                if progress is not None:
                    progress(k + 1, n_steps)
                if self.realtime:
                    ahead = (t - self.start) - (wallclock.perf_counter() - started)
                    if ahead > 0:
                        wallclock.sleep(ahead)
        finally:
            for unit in self.units.values():
                unit.terminate()
            if handle:
                handle.close()
        return RunResult(rows, t, wallclock.perf_counter() - started, Path(csv_path) if csv_path else None, header)

    def _write(self, writer, handle, t: float) -> None:
        if writer is None:
            return
        writer.writerow([_fmt(round(t, 12))] + [_fmt(self.values.get(key, "")) for key in self.columns])
        handle.flush()
