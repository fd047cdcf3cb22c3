"""Event Mode in the master: units with clocks run their clocked partitions at communication points.

A *clocked* unit (an FMI 3.0 FMU with Event Mode, cotwin.cosim.fmi3; a source whose commands are events)
has, besides the Unit interface, `event_setter(names)` and `event(t)`. At every communication point t
(after initialisation, and after every step, before the results at t are observed), the event phase
visits the clocked units in dependency order: each is offered
its inputs as they are at t (the outputs of units before it in this very phase included) and runs
`event(t)`, which runs its partition if one of its clocks ticks at t (else it keeps what it was
offered for its next tick and shows its events as not occurring); its outputs are read at once. So
a command raised at t crosses a clocked d-model and reaches a platform stepped from t in the same
communication step, under Jacobi as under Gauss-Seidel: the event phase is the superdense instant
at t that FMI 3.0 defines, not an ordering trick of the stepping.

The stepping algorithms (cotwin.cosim.algorithm) do not set a clocked unit's clocked inputs: FMI 3.0
allows those only in Event Mode while their clock is active, and each value at t is offered once.
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence, runtime_checkable


@runtime_checkable
class Clocked(Protocol):
    """What a unit adds to take part in the event phase (see module doc)."""

    def event_setter(self, names: list[str]) -> Callable[[Sequence], None]: ...

    def event(self, t: float) -> None: ...


class EventPhase:
    """The event phase of one algorithm's units (see module doc); None-like when no unit is clocked."""

    def __init__(self, algorithm) -> None:
        self.members = []
        for k, unit in enumerate(algorithm.units):
            if not isinstance(unit, Clocked):
                continue
            feeds = algorithm.feeds[k]
            write = (unit.event_setter([inp for inp, _ in feeds]),
                     [algorithm.slots[key] for _, key in feeds]) if feeds else None
            self.members.append((unit, write, k))
        self.algorithm = algorithm

    def __bool__(self) -> bool:
        return bool(self.members)

    def run(self, t: float) -> None:
        """The event phase at communication point t; a value no unit has produced yet is offered as None."""
        algorithm = self.algorithm
        data = algorithm.data
        unset = algorithm.UNSET
        for unit, write, k in self.members:
            if write is not None:
                setter, slots = write
                setter([None if data[i] is unset else data[i] for i in slots])
            unit.event(t)
            algorithm._read(k)
