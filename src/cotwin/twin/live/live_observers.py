"""The live twin's own services as its observers (cotwin.twin.assembly.observing): deviation checking, the history
store, alarms on the broker, what-if requests and real-time pacing. cotwin.twin.live.runtime registers them
before the caller's observers, in this order: DeviationCheck (its alarms reach every observer's
`twin_alarm`), HistoryRecording, AlarmPublisher, WhatIfPolling, the project's [convergence], the caller's,
then Pacing (the wait comes after everyone has looked at the step).
"""

from __future__ import annotations

import json
from pathlib import Path

from ...cosim.algorithm import UNSET
from ...cosim.observers import Pacer
from ...files import write_text
from ..assembly.observing import TwinObserver
from ..assembly.system import MAPPING


class DeviationCheck(TwinObserver):
    """PT against DT after every step (a DeviationMonitor over ports of `unit`, by default the twin's mapping);
    with `out`, DIR/deviation.json when the run ends (with the PT's kind and the [convergence] report, if
    any). A cell has one per robot, over the robot's scoped ports of the cell's mapping, and writes them
    together."""

    def __init__(self, monitor, variables: list[str], out: Path | None = None, unit: str = MAPPING.name):
        self.monitor, self.variables, self.out, self.unit = monitor, list(variables), out, unit
        self._readers: dict = {}
        self.report: dict = {}

    def twin_started(self, twin) -> None:
        self._readers = {name: side.execution.reader([(self.unit, v) for v in self.variables])
                         for name, side in twin.sides.items()}

    def twin_step(self, twin, k: int, t: float) -> None:
        pt = {v: None if x is UNSET else x for v, x in zip(self.variables, self._readers["pt"]())}
        dt = {v: None if x is UNSET else x for v, x in zip(self.variables, self._readers["dt"]())}
        self.monitor.observe(t, pt, dt)

    def twin_ended(self, twin, status: str) -> None:
        report = self.monitor.report()
        if self.out is not None:
            report["pt"] = twin.system.spec.pt.endpoint if twin.system.spec.pt else "custom"
            if twin.convergence is not None:
                report["convergence"] = twin.convergence.report()
            write_text(self.out / "deviation.json", json.dumps(report, indent=1) + "\n")
        self.report = report


class HistoryRecording(TwinObserver):
    """Both sides' samples and state changes, the commands taken and the alarms, into the history store
    (a cotwin.twin.services.history.HistoryRecorder); the run's status when it ends."""

    def __init__(self, history):
        self.history = history

    def twin_started(self, twin) -> None:
        """Readers bound once (after initialisation), then the samples the run starts from. What is recorded
        comes from the twin's system: its state machines and its command sources (one of each per robot in a
        cell, named by the robot)."""
        system = twin.system
        machines = system.state_machines()
        names = [(m.machine, m.leaves) for m in machines]
        self._readers = {}
        for name, side in twin.sides.items():
            execution = side.execution
            states = execution.reader([(m.unit, m.port) for m in machines])
            self._readers[name] = (execution, execution.reader(execution.system.observed()), states, names)
        pt = twin.sides["pt"].execution
        self._commands = [([name for _, name in c.events], [name for _, name in c.values],
                           pt.reader([(c.unit, p) for p, _ in (*c.events, *c.values)]))
                          for c in system.command_ports()]
        self.twin_step(twin, twin.steps, twin.time)

    def twin_step(self, twin, k: int, t: float) -> None:
        history = self.history
        for name, (execution, sample, states, machines) in self._readers.items():
            at = execution.time
            history.record_sample(name, k, at, sample())
            for (machine, leaves), state in zip(machines, states()):
                if isinstance(state, int) and not isinstance(state, bool):
                    history.record_state(name, k, at, machine, state, leaves[state] if 0 <= state < len(leaves) else "none")
        for events, values, read in self._commands:
            current = read()
            fired = [e for e, v in zip(events, current) if v is True]
            for event in fired:  # a command and the values it carries
                history.record_command(k, t, event, True)
                for port, value in zip(values, current[len(events):]):
                    history.record_command(k, t, port, value)

    def twin_alarm(self, twin, event: dict) -> None:
        self.history.record_alarm(event)

    def twin_ended(self, twin, status: str) -> None:
        self.history.close(status, twin.message)


class AlarmPublisher(TwinObserver):
    """Every alarm published on the broker's event exchange (a cotwin.twin.assembly.rabbitmq.EventPublisher)."""

    def __init__(self, publisher, routing_key: str):
        self.publisher, self.routing_key = publisher, routing_key

    def twin_alarm(self, twin, event: dict) -> None:
        self.publisher.publish(self.routing_key, event)


class WhatIfPolling(TwinObserver):
    """Between two steps, the DT's state forked for every waiting what-if request (cotwin.twin.services.whatif)."""

    def __init__(self, service):
        self.service = service

    def twin_step(self, twin, k: int, t: float) -> None:
        self.service.poll(twin.sides["dt"].execution)


class Pacing(TwinObserver):
    """The co-simulation's real-time pacer (cotwin.cosim.observers.Pacer) on the live twin's clock: its epoch
    when both sides started (or the live publisher's), a wait after every step."""

    def __init__(self, factor: float = 1.0):
        self.pacer = Pacer(factor)

    def twin_started(self, twin) -> None:
        self.pacer.begin(twin.sides["pt"].execution.system.units.values(), twin.time)

    def twin_step(self, twin, k: int, t: float) -> None:
        self.pacer.wait(t)
