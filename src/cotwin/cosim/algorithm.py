"""Co-simulation algorithms: how a step moves values between units (libcosim's `algorithm`).

An algorithm is set up with a checked System, initialises it, then takes steps; it holds the latest
value of every observed variable in `values`, keyed (unit, variable), for observers to read.

- Jacobi (Maestro's algorithm): every connected input takes its source's output of the previous
  step, then all units step at the same t; each hop of a chain costs one step (the paper's
  three-step delay from the broker to the robot).
- Gauss-Seidel: units step in the dependency order, each reading what its sources produced in this
  very step, so a command crosses the whole chain in one step. Outputs of a `delayed` unit are read
  as they were at the start of the step; they break cycles.

Initialisation propagates start values in dependency order, as Maestro does.
"""

from __future__ import annotations

from .system import System


class Algorithm:
    name = "algorithm"

    def __init__(self) -> None:
        self.system: System | None = None
        self.values: dict[tuple[str, str], object] = {}

    def setup(self, system: System, start: float) -> None:
        """Instantiate every unit (dependency order) and set its parameters."""
        self.system = system
        self.order = system.order
        self.units = [system.units[n] for n in self.order]
        incoming: dict[str, list[tuple[str, tuple[str, str]]]] = {n: [] for n in self.order}
        for c in system.connections:
            incoming[c.target].append((c.input, (c.source, c.output)))
        self.feeds = [incoming[n] for n in self.order]
        watched: dict[str, list[str]] = {n: [] for n in self.order}
        for unit, var in system.observed():
            watched[unit].append(var)
        self.watched = [watched[n] for n in self.order]
        for unit in self.units:
            unit.instantiate(start)
            if system.parameters.get(unit.name):
                unit.set(system.parameters[unit.name])

    def _read(self, k: int) -> None:
        names = self.watched[k]
        if names:
            name = self.units[k].name
            for var, value in self.units[k].get(names).items():
                self.values[(name, var)] = value

    def _inputs(self, k: int, source: dict) -> dict[str, object]:
        return {inp: source.get(key) for inp, key in self.feeds[k] if key in source}

    def initialize(self) -> None:
        for k, unit in enumerate(self.units):
            inputs = self._inputs(k, self.values)
            if inputs:
                unit.set(inputs)
            self._read(k)
        for k, unit in enumerate(self.units):
            unit.initialize()
            self._read(k)

    def do_step(self, t: float, h: float) -> None:
        raise NotImplementedError


class Jacobi(Algorithm):
    name = "jacobi"

    def do_step(self, t: float, h: float) -> None:
        values = self.values  # all inputs are set before any unit steps: no copy needed
        for k, unit in enumerate(self.units):
            if self.feeds[k]:
                unit.set(self._inputs(k, values))
        for unit in self.units:
            unit.step(t, h)
        for k in range(len(self.units)):
            self._read(k)


class GaussSeidel(Algorithm):
    name = "gauss-seidel"

    def setup(self, system: System, start: float) -> None:
        super().setup(system, start)
        self.delayed_keys = {key for feeds in self.feeds for _, key in feeds if key[0] in system.delayed}

    def do_step(self, t: float, h: float) -> None:
        values = self.values
        previous = {key: values[key] for key in self.delayed_keys if key in values}
        for k, unit in enumerate(self.units):
            if self.feeds[k]:
                unit.set({inp: previous[key] if key in previous else values.get(key) for inp, key in self.feeds[k]})
            unit.step(t, h)
            self._read(k)


ALGORITHMS = {"jacobi": Jacobi, "gauss-seidel": GaussSeidel}


def algorithm(name: str) -> Algorithm:
    from ..diagnostics import CotwinError

    if name not in ALGORITHMS:
        raise CotwinError(f"unknown algorithm '{name}' (known: {', '.join(ALGORITHMS)})")
    return ALGORITHMS[name]()
