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
from ..assembly.system import DMODEL, MAPPING


class DeviationCheck(TwinObserver):
    """PT against DT after every step (the twin's DeviationMonitor); DIR/deviation.json when the run ends
    (with the [convergence] report, if any)."""

    def __init__(self, monitor, variables: list[str], out: Path):
        self.monitor, self.variables, self.out = monitor, list(variables), out
        self._readers: dict = {}
        self.report: dict = {}

    def twin_started(self, twin) -> None:
        self._readers = {name: side.execution.reader([(MAPPING.name, v) for v in self.variables])
                         for name, side in twin.sides.items()}

    def twin_step(self, twin, k: int, t: float) -> None:
        pt = {v: None if x is UNSET else x for v, x in zip(self.variables, self._readers["pt"]())}
        dt = {v: None if x is UNSET else x for v, x in zip(self.variables, self._readers["dt"]())}
        self.monitor.observe(t, pt, dt)

    def twin_ended(self, twin, status: str) -> None:
        report = self.monitor.report()
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
        """Readers bound once (after initialisation), then the samples the run starts from."""
        system = twin.system
        program = system.models.program
        self._readers = {}
        for name, side in twin.sides.items():
            execution = side.execution
            machines = [(m.name, program.leaf_names(m)) for m in program.machines]
            states = execution.reader([(DMODEL.name, program.state_port(m)) for m in program.machines])
            self._readers[name] = (execution, execution.reader(execution.system.observed()), states, machines)
        source = system.source
        if source is not None:
            events = [p for p in system.source_ports if p in system.command_events]
            values = [p for p in system.source_ports if p not in system.command_events]
            read = twin.sides["pt"].execution.reader([(source.name, p) for p in events + values])
            self._commands = (events, values, read)
        else:
            self._commands = None
        self.twin_step(twin, twin.steps, twin.time)

    def twin_step(self, twin, k: int, t: float) -> None:
        history = self.history
        for name, (execution, sample, states, machines) in self._readers.items():
            at = execution.time
            history.record_sample(name, k, at, sample())
            for (machine, leaves), state in zip(machines, states()):
                if isinstance(state, int) and not isinstance(state, bool):
                    history.record_state(name, k, at, machine, state, leaves[state] if 0 <= state < len(leaves) else "none")
        if self._commands is not None:
            events, values, read = self._commands
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
