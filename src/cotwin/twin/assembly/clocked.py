"""A twin with an FMI 3.0 d-model: the scenario's commands as events at their own times.

With the d-model's cycle a clock (cotwin.dmodel.fmi3), the master's event phase (cotwin.cosim.clocks)
lets a command cross the d-model and reach the platform in the step it is issued in. The scenario
takes part: at communication point t it raises every command due by t (time <= t) that it has not
raised yet, and a step from t raises those due before its end, shown at t + h; each command is raised
once, at the first communication point at or after its time, one per point (those due together queued in
order, cotwin.twin.assembly.commands). A plan whose times lie on the grid of
steps is thus delivered at its times exactly.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from ...diagnostics import CotwinError
from .scenario import ScenarioUnit

EPS = 1e-9


class ClockedScenario(ScenarioUnit):
    """A scenario unit with an event phase (see module doc); its commands queued as the plan controller's,
    one applied per communication point (cotwin.twin.assembly.commands)."""

    def event_setter(self, names: list[str]) -> Callable[[Sequence], None]:
        return lambda values: None  # a source takes no inputs

    def event(self, t: float) -> None:
        self._offer_due(t, t + EPS)
        if not any(self.values[ev] is True for ev in self.events):  # none shown at t yet: the next one is
            self._apply(t)

    def step(self, t: float, h: float) -> None:
        for ev in self.events:
            self.values[ev] = False
        self._offer_due(t, t + h - EPS)
        self._apply(t + h)
        self.time = t + h

    def forked(self) -> None:
        """In a fork of a saved run (a what-if), the fork's time is an instant the saved d-model has already had
        its event phase at: the commands this source showed there reached only the d-model's fresh instance, which
        its saved state then replaced. They are taken back: nothing is shown at the fork's time, and the commands
        due from it on are offered from the first step (shown at the next communication point), as when the unit
        is restored with another plan (`restore`)."""
        self._offer_from_now()
        for ev in self.events:
            self.values[ev] = False


class DModelCycles:
    """Whether the d-model ran a cycle since the last look, for observers that judge what it read: a clocked one
    (FMI 3.0) runs one at each tick of its clock (`Unit.ticks`, counted by the unit), in the event phase before
    the step's results; one that is not clocked runs one every step."""

    def __init__(self, execution, dmodel: str | None = None) -> None:
        """`dmodel`: the d-model's unit (default the twin's, {dmodel}.dmodel; a cell's robot has its own)."""
        from .system import DMODEL

        unit = execution.system.units.get(dmodel or DMODEL.name)
        self.unit = unit if unit is not None and unit.ticks is not None else None
        self.seen = self.unit.ticks if self.unit is not None else 0  # ticks when last looked (at the start: before it)

    @property
    def clocked(self) -> bool:
        return self.unit is not None

    def ran(self) -> bool:
        """Whether a cycle ran since the last call (always, for a d-model that is not clocked)."""
        if self.unit is None:
            return True
        ticks = self.unit.ticks
        ran, self.seen = ticks != self.seen, ticks
        return ran


def clock_period(spec, step: float, period: float | None = None) -> float:
    """The FMI 3.0 d-model's clock interval: `period`, else the project's [cosim] parameters cycle_period,
    else the step; a whole number of steps (its ticks fall on communication points), else CotwinError."""
    period = period or spec.parameters.get("cycle_period") or step
    steps = period / step
    if not (period > 0 and math.isfinite(period)) or steps < 1 - 1e-9 or abs(steps - round(steps)) > 1e-6 * steps:
        raise CotwinError(f"cycle_period {period!r} s is not a whole number of steps of {step:g} s: the FMI 3.0 "
                          "d-model's clock must tick on communication points")
    return float(period)


def saved_clock(saved: dict) -> float | None:
    """The clock period (s) of the FMI 3.0 d-model in a saved execution (`saved_execution(state)`), None when its
    d-model is FMI 2.0's (or the state has none): what a fork of the DT as it ran builds (cotwin.twin.services.whatif).
    StateError for a state of an FMI 3.0 d-model saved by an earlier cotwin, which kept neither the clock's period
    nor its phase."""
    from ...cosim.fmi3 import clock_intervals
    from ...cosim.state import unpacked
    from ...plaindata import StateError
    from .system import DMODEL

    blob = saved["units"].get(DMODEL.name)
    if blob is None:
        return None
    try:
        kind, data = unpacked(blob, ("FMU", "FMU3"))
    except StateError:
        return None  # not a d-model's state: restoring it says why
    if kind != "FMU3":
        return None
    intervals = clock_intervals(data, f"unit {DMODEL.name}") if isinstance(data, dict) else None
    if not intervals or "start" not in data:
        raise StateError("a state of an FMI 3.0 d-model saved by an earlier cotwin, without its clock's period and "
                         "phase: run the twin again (cotwin run --fmi 3) to save one a what-if can fork")
    return intervals[0]


def clocked_system(system, fmu, endpoint, period: float, source=None):
    """The twin's co-simulation with `fmu` (the FMI 3.0 d-model) clocked every `period` seconds, and the
    scenario as a ClockedScenario (unless `source` is given)."""
    from ...cosim.fmi3 import FMU3Unit
    from .system import CONTROLLER, DMODEL

    if source is None and system.source is CONTROLLER:
        source = ClockedScenario(CONTROLLER.name, system.models.program, system.commands, system.source_ports)
    cosim = system.instantiate(fmu, endpoint, source=source, dmodel=FMU3Unit(DMODEL.name, fmu))
    cosim.parameters = {**cosim.parameters, DMODEL.name: {**cosim.parameters.get(DMODEL.name, {}),
                                                          "cycle_period": float(period)}}
    return cosim


def servo_delays(commands, executed, step: float) -> list[tuple[float, float, int]]:
    """The paper's command-to-servo delay of each command event: (its time, the start of the step in which
    the mapping set the servo targets of the operation it caused, the delay in steps counting the
    command's own step as the first: 3 under FMI 2.0 Jacobi). `commands` are scenario Commands,
    `executed` the mapping unit's (step start, operation, arguments); each command takes the first
    operation carried out at or after its time, and a command with none is left out."""
    out, used = [], set()
    for command in sorted(commands, key=lambda c: c.time):
        for k, (t, _, _) in enumerate(executed):
            if k not in used and t >= command.time - EPS:
                used.add(k)
                out.append((command.time, t, int(round((t - command.time) / step)) + 1))
                break
    return out
