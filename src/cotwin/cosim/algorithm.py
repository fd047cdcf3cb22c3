"""Master algorithms: how a System's units are stepped and how values cross its connections.

- Jacobi (Maestro's default): every input is set from the outputs read at the end of the previous
  step, then all units step at the same t; each hop of a chain costs one step (the paper's
  three-step delay from the broker to the robot).
- Gauss-Seidel: units step in the dependency order, each reading what its sources produced in this
  very step, so a command crosses the whole chain in one step. Outputs of a `delayed` unit are read
  as they were at the start of the step; they break cycles.

Initialisation propagates start values in dependency order, as Maestro does.

Units with clocks (FMI 3.0 FMUs in Event Mode) also run an event phase at every communication point,
after the units stepped to it (and after initialisation): cotwin.cosim.clocks.

The latest value of every observed port lives in one flat list of slots; each unit's inputs and
outputs are bound once (`Unit.setter`, `Unit.getter`) to slot positions, so a step moves values by
position without building dicts. `values` is a read-only view of the slots by (unit, port).
"""

from __future__ import annotations

from collections.abc import Mapping
from operator import itemgetter
from typing import Callable, Iterator

from ..diagnostics import CotwinError
from .clocks import EventPhase
from .system import System

UNSET = object()  # a slot no unit has written yet
_TYPE_ORDER = {"Real": 0, "Integer": 1, "Boolean": 2}  # the order in which FMUUnit groups ports


class Values(Mapping):
    """(unit, port) -> latest value of an observed port; ports not yet read are absent."""

    def __init__(self, slots: dict[tuple[str, str], int], data: list):
        self._slots = slots
        self._data = data

    def __getitem__(self, key: tuple[str, str]) -> object:
        value = self._data[self._slots[key]]
        if value is UNSET:
            raise KeyError(key)
        return value

    def __iter__(self) -> Iterator[tuple[str, str]]:
        return (key for key, i in self._slots.items() if self._data[i] is not UNSET)

    def __len__(self) -> int:
        return sum(1 for _ in self)


def _picker(slots: list[int]) -> Callable[[list], tuple]:
    """A function returning the values at these slots as a tuple (C speed through itemgetter)."""
    if len(slots) == 1:
        only = slots[0]
        return lambda data: (data[only],)
    return itemgetter(*slots)


class Algorithm:
    name = "algorithm"
    UNSET = UNSET

    def __init__(self) -> None:
        self.system: System | None = None
        self.slots: dict[tuple[str, str], int] = {}
        self.data: list = []
        self.values: Mapping = Values(self.slots, self.data)

    def setup(self, system: System, start: float) -> None:
        """Instantiate every unit (dependency order), set its parameters and bind its ports to slots."""
        self.system = system
        self.start = start
        self.order = system.order
        self.units = [system.units[n] for n in self.order]
        self.slots = {key: i for i, key in enumerate(system.observed())}
        self.data = [UNSET] * len(self.slots)
        self.values = Values(self.slots, self.data)
        incoming: dict[str, list[tuple[str, tuple[str, str]]]] = {n: [] for n in self.order}
        for c in system.connections:
            incoming[c.target].append((c.input, (c.source, c.output)))
        self.feeds = [incoming[n] for n in self.order]
        watched: dict[str, list[str]] = {n: [] for n in self.order}
        for unit, var in system.observed():
            watched[unit].append(var)
        # ports bound grouped by type: an FMU moves each group in one call, as one slice
        self.feeds = [sorted(feeds, key=lambda f, u=u: _TYPE_ORDER.get(u.ports[f[0]].type, 3))
                      for u, feeds in zip((system.units[n] for n in self.order), self.feeds)]
        self.watched = [sorted(watched[n], key=lambda v, u=system.units[n]: _TYPE_ORDER.get(u.ports[v].type, 3))
                        for n in self.order]
        for unit in self.units:
            unit.instantiate(start)
            if system.parameters.get(unit.name):
                unit.set(system.parameters[unit.name])
        self._bind()
        self.events = EventPhase(self)  # units with clocks (FMI 3.0): Event Mode at each communication point

    def _source_slot(self, key: tuple[str, str]) -> int:
        return self.slots[key]

    def _bind(self) -> None:
        """Per unit: a setter of its inputs fed from their source slots, a getter of its watched
        outputs and the slots they go to (None where a unit has none)."""
        self.writes: list[tuple[Callable, Callable] | None] = []
        self.reads: list[tuple[Callable, list[int]] | None] = []
        for k, unit in enumerate(self.units):
            feeds = self.feeds[k]
            self.writes.append((unit.setter([inp for inp, _ in feeds]),
                                _picker([self._source_slot(key) for _, key in feeds])) if feeds else None)
            names = self.watched[k]
            self.reads.append((unit.getter(names), [self.slots[(unit.name, n)] for n in names]) if names else None)

    def reader(self, keys: list[tuple[str, str]]) -> Callable[[], tuple]:
        """A function returning the latest values of these observed ports, in this order (UNSET
        where none was read yet)."""
        unknown = [k for k in keys if k not in self.slots]
        if unknown:
            raise CotwinError(f"not observed: {', '.join(f'{u}.{v}' for u, v in unknown)}")
        if not keys:
            return lambda: ()
        pick, data = _picker([self.slots[k] for k in keys]), self.data
        return lambda: pick(data)

    def _read(self, k: int) -> None:
        read = self.reads[k]
        if read is not None:
            getter, slots = read
            data = self.data
            for i, value in zip(slots, getter()):
                data[i] = value

    def _inputs(self, k: int) -> dict[str, object]:
        """The inputs of unit k whose sources have a value (initialisation)."""
        data, slots = self.data, self.slots
        return {inp: data[slots[key]] for inp, key in self.feeds[k] if data[slots[key]] is not UNSET}

    def initialize(self) -> None:
        for k, unit in enumerate(self.units):
            inputs = self._inputs(k)
            if inputs:
                unit.set(inputs)
            self._read(k)
        for k, unit in enumerate(self.units):
            unit.initialize()
            self._read(k)
        if self.events:
            self.events.run(self.start)

    def do_step(self, t: float, h: float) -> None:
        raise NotImplementedError

    # ---- state: the slots are part of a co-simulation's state (Jacobi feeds them to the next step) ----
    def snapshot(self) -> dict[tuple[str, str], object]:
        return {key: self.data[i] for key, i in self.slots.items() if self.data[i] is not UNSET}

    def restore(self, values: dict[tuple[str, str], object]) -> None:
        unknown = [k for k in values if k not in self.slots]
        if unknown:
            raise CotwinError(f"the saved state has values of ports this system does not observe: "
                              f"{', '.join(f'{u}.{v}' for u, v in unknown)}")
        for i in range(len(self.slots)):
            self.data[i] = UNSET
        for key, value in values.items():
            self.data[self.slots[key]] = value


class Jacobi(Algorithm):
    name = "jacobi"

    def do_step(self, t: float, h: float) -> None:
        data = self.data  # all inputs are set before any unit steps: no copy needed
        for write in self.writes:
            if write is not None:
                setter, pick = write
                setter(pick(data))
        for unit in self.units:
            unit.step(t, h)
        for read in self.reads:
            if read is not None:
                getter, slots = read
                for i, value in zip(slots, getter()):
                    data[i] = value
        if self.events:
            self.events.run(t + h)


class GaussSeidel(Algorithm):
    name = "gauss-seidel"

    def setup(self, system: System, start: float) -> None:
        self._delayed = system.delayed
        self._shadow: dict[tuple[str, str], int] = {}
        super().setup(system, start)
        # outputs of delayed units as they were at the start of the step, in extra slots after the others
        self.copies = [(self.slots[key], shadow) for key, shadow in self._shadow.items()]
        self.data.extend([UNSET] * len(self._shadow))

    def _source_slot(self, key: tuple[str, str]) -> int:
        if key[0] in self._delayed:
            return self._shadow.setdefault(key, len(self.slots) + len(self._shadow))
        return self.slots[key]

    def do_step(self, t: float, h: float) -> None:
        data = self.data
        for source, shadow in self.copies:
            data[shadow] = data[source]
        for unit, write, read in zip(self.units, self.writes, self.reads):
            if write is not None:
                setter, pick = write
                setter(pick(data))
            unit.step(t, h)
            if read is not None:
                getter, slots = read
                for i, value in zip(slots, getter()):
                    data[i] = value
        if self.events:
            self.events.run(t + h)


ALGORITHMS = {"jacobi": Jacobi, "gauss-seidel": GaussSeidel}


def algorithm(name: str) -> Algorithm:
    if name not in ALGORITHMS:
        raise CotwinError(f"unknown algorithm '{name}' (known: {', '.join(ALGORITHMS)})")
    return ALGORITHMS[name]()
