"""An execution: a System stepped by an Algorithm at a fixed communication step, watched by observers.

`Execution` can be run to an end time (`run`) or stepped one communication step at a time (`step`),
which is how the live twin keeps a physical and a digital twin on one clock. It always ends the units'
life as FMI asks, also after a failure, and tells observers how the run ended.
"""

from __future__ import annotations

import time as wallclock
from dataclasses import dataclass, field

from ..diagnostics import CotwinError
from .algorithm import Algorithm
from .observers import Observer
from .system import System


@dataclass(frozen=True)
class RunResult:
    """What an execution ran: its steps, its times, and how long it took."""

    algorithm: str
    step_size: float
    start: float
    end_time: float
    steps: int
    wall_seconds: float
    outputs: dict[str, object] = field(default_factory=dict)

    @property
    def rows(self) -> int:
        return self.steps + 1

    @property
    def real_time_factor(self) -> float:
        return (self.end_time - self.start) / max(self.wall_seconds, 1e-12)


class Execution:
    def __init__(self, system: System, algorithm: Algorithm, step_size: float, start: float = 0.0,
                 observers: list[Observer] | tuple[Observer, ...] = ()):
        if not step_size > 0:
            raise CotwinError(f"the step size must be positive, got {step_size!r}")
        self.system = system
        self.algorithm = algorithm
        self.step_size = float(step_size)
        self.start = float(start)
        self.observers = list(observers)
        self.steps = 0
        self.total_steps = 0
        self.time = self.start
        self.initialized = False
        self.closed = False
        self._wall = 0.0

    @property
    def values(self) -> dict[tuple[str, str], object]:
        return self.algorithm.values

    def add_observer(self, observer: Observer) -> None:
        self.observers.append(observer)
        if self.initialized:
            observer.simulation_initialized(self)

    def initialize(self) -> None:
        self._wall = wallclock.perf_counter()
        try:
            self.algorithm.setup(self.system, self.start)
            self.algorithm.initialize()
        except BaseException as err:
            self.close(err)
            raise
        self.initialized = True
        for o in self.observers:
            o.simulation_initialized(self)

    def step(self) -> float:
        """One communication step from the current time; returns the new time."""
        t = self.start + self.steps * self.step_size
        try:
            self.algorithm.do_step(t, self.step_size)
        except BaseException as err:
            self.close(err)
            raise
        self.steps += 1
        self.time = self.start + self.steps * self.step_size
        for o in self.observers:
            o.step_complete(self)
        return self.time

    def run(self, end: float) -> RunResult:
        """Initialise (if not yet), step until `end`, close; the result says what ran."""
        if not end > self.start:
            raise CotwinError(f"the end time ({end!r} s) must come after the start ({self.start!r} s)")
        self.total_steps = int(round((end - self.start) / self.step_size))
        if not self.initialized:
            self.initialize()
        try:
            while self.steps < self.total_steps:
                self.step()
        except BaseException as err:
            self.close(err)
            raise
        self.close()
        return self.result()

    def result(self) -> RunResult:
        outputs = {type(o).__name__: o.path for o in self.observers if getattr(o, "path", None) is not None}
        return RunResult(self.algorithm.name, self.step_size, self.start, self.time, self.steps,
                         wallclock.perf_counter() - self._wall, outputs)

    def close(self, error: BaseException | None = None) -> None:
        """Terminate every unit (each unit knows which FMI calls its state still allows) and tell the
        observers; idempotent."""
        if self.closed:
            return
        self.closed = True
        for unit in self.system.units.values():
            try:
                unit.terminate()
            except Exception:  # noqa: BLE001 - ending one unit must not stop the others from ending
                pass
        for o in self.observers:
            o.simulation_ended(self, error)
