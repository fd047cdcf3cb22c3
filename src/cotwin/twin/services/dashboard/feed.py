"""The dashboard's view of a running twin: an observer that copies a few values per step into a bounded
ring and notes discrete events (commands, operation calls, alarms) in a second, larger ring (a
publisher commanding at every step of a long run, or a flood of alarms, cannot grow it without bound:
a page opened late gets the newest `event_capacity` events, and a reader that falls behind is told how
many it skipped).

The twin's thread only writes (a handful of dict look-ups and one list store per step, no lock, no
I/O, no encoding), and copies values at most `max_rate` times a second of wall time: a paced twin at
100 Hz is seen step by step, an unpaced one racing at thousands of steps a second is sampled (a page
draws no more than that), while events are never missed. The server's thread reads from its own
cursors and does everything else. A reader that falls behind more than the ring holds skips ahead and
counts what it missed, so a slow or closed browser can never slow the run.

One feed serves both kinds of run: as a cosim Observer of one twin (`cotwin run`, side `twin`) and as
an observer of a LiveTwin (`twin_started`/`twin_step`, sides `pt` and `dt`).
"""

from __future__ import annotations

import time as wallclock

from ....cosim.observers import Observer
from ...assembly.observing import TwinObserver
from ...assembly.system import DMODEL, MAPPING, TwinSystem


class Ring:
    """A bounded sequence with one writer and any number of readers, safe without a lock under the
    GIL: the writer stores then counts; a reader copies from its cursor and then drops whatever the
    writer may have overwritten meanwhile."""

    def __init__(self, capacity: int):
        if capacity < 1:
            raise ValueError("a ring needs a positive capacity")
        self.capacity = capacity
        self.items: list = [None] * capacity
        self.count = 0  # items ever appended

    def append(self, item) -> None:
        self.items[self.count % self.capacity] = item
        self.count += 1

    def since(self, cursor: int) -> tuple[list, int, int]:
        """Items appended at or after `cursor`: (items, new cursor, items skipped because overwritten)."""
        end = self.count
        start = max(cursor, end - self.capacity)
        cap = self.capacity
        out = [self.items[i % cap] for i in range(start, end)]
        lapped = self.count - cap  # anything below this may have been overwritten during the copy
        if lapped > start:
            cut = min(lapped - start, len(out))
            out = out[cut:]
            start += cut
        return out, end, start - cursor

    def last(self):
        return self.items[(self.count - 1) % self.capacity] if self.count else None

    def __iter__(self):
        """The items held, oldest first."""
        return iter(self.since(0)[0])

    def __len__(self) -> int:
        return min(self.count, self.capacity)


class DashboardFeed(Observer, TwinObserver):
    """Samples `(time, wall, [values side 1, states side 1, values side 2, ...])` per step, and events
    (dicts with `kind` = command | op | alarm | correction) as they happen (see module doc)."""

    def __init__(self, system: TwinSystem, capacity: int = 1 << 14, max_rate: float = 500.0,
                 event_capacity: int = 1 << 12):
        self.system = system
        self._watch(system)
        self.samples = Ring(capacity)
        self.min_interval = 1.0 / max_rate  # s of wall time between two copied samples
        self._last_copy = float("-inf")
        self._last_time: float | None = None  # the newest step's time, copied or not
        self.events = Ring(event_capacity)  # of dicts
        self.sides: list[str] = []
        self.state = "waiting"  # waiting | running | done | stopped | failed
        self.message: str | None = None
        self.step_size: float | None = None
        self.end: float | None = None
        self.started_wall: float | None = None
        self.started_time = 0.0
        self._executions: list = []
        self._mappings: list = []
        self._seen_ops: list[int] = []
        self._monitor = None
        self._seen_alarms = 0
        self._corrections: list = []  # a LiveTwin's [convergence] corrections (cotwin.twin.assembly.convergence)
        self._seen_corrections = 0

    def _watch(self, system: TwinSystem) -> None:
        """What a sample copies (the monitored variables, the d-model's states) and which commands are events."""
        program = system.models.program
        self.variables = list(system.models.monitored)
        self._keys = [(MAPPING.name, v) for v in self.variables]
        self._state_keys = [(DMODEL.name, program.state_port(m)) for m in program.machines]
        source = system.source
        self._commands = []  # (event key, name, [(port, key)])
        if source is not None:
            for ev in program.inputs:
                if ev.name in system.command_events:
                    self._commands.append(((source.name, ev.name), ev.name,
                                           [(port, (source.name, port)) for port, _ in ev.value_ports]))

    # ---- attaching ----
    def _attach(self, executions: dict, monitor=None, step: float | None = None, end: float | None = None) -> None:
        self.sides = list(executions)
        self._executions = list(executions.values())
        self._mappings = [e.system.units.get(MAPPING.name) for e in self._executions]
        self._seen_ops = [len(m.executed) if m is not None else 0 for m in self._mappings]
        self._monitor = monitor
        self._seen_alarms = len(monitor.events) if monitor is not None else 0
        first = self._executions[0]
        self.step_size = step if step is not None else first.step_size
        self.end = end if end is not None else (first.start + first.total_steps * first.step_size
                                                if first.total_steps else None)
        self.started_wall = wallclock.time()
        self.started_time = first.time
        self.state = "running"
        self._capture(first.time)

    # a LiveTwin's observer
    def twin_started(self, twin) -> None:
        self._attach({name: side.execution for name, side in twin.sides.items()}, twin.monitor, twin.step_size, twin.end)
        if twin.convergence is not None:
            self._corrections = twin.convergence.events
            self._seen_corrections = len(self._corrections)

    def twin_step(self, twin, k: int, t: float) -> None:
        self._capture(t)

    # one run's cosim Observer
    def simulation_initialized(self, execution) -> None:
        self._attach({"twin": execution})

    def step_complete(self, execution) -> None:
        self._capture(execution.time)

    def simulation_ended(self, execution, error: BaseException | None) -> None:
        self.finish("done" if error is None else "failed", None if error is None else str(error) or type(error).__name__)

    def finish(self, state: str, message: str | None = None) -> None:
        """The run ended (the LiveTwin's caller says how; one run's execution says it itself)."""
        if self.state in ("waiting", "running"):
            if self._last_time is not None:  # the last step, if it was not copied
                self._copy(self._last_time)
            self.state, self.message = state, message

    # ---- the twin's thread ----
    def _capture(self, t: float) -> None:
        now = wallclock.perf_counter()
        if now - self._last_copy >= self.min_interval:
            self._last_copy = now
            self._copy(t)
        else:
            self._last_time = t
        self._events(t)

    def _copy(self, t: float) -> None:
        self._last_time = None
        row = []
        keys, state_keys = self._keys, self._state_keys
        for execution in self._executions:
            values = execution.values
            row.append([values.get(k) for k in keys])
            row.append([values.get(k) for k in state_keys])
        self.samples.append((t, wallclock.time(), row))

    def _events(self, t: float) -> None:
        for i, mapping in enumerate(self._mappings):
            executed = mapping.executed if mapping is not None else ()
            if len(executed) > self._seen_ops[i]:
                for start, name, args in executed[self._seen_ops[i]:]:
                    self.events.append({"kind": "op", "side": self.sides[i], "time": start, "name": name,
                                        "args": args})
                self._seen_ops[i] = len(executed)
        if self._commands and self._executions:
            values = self._executions[0].values
            for key, name, ports in self._commands:
                if values.get(key) is True:
                    self.events.append({"kind": "command", "time": t, "name": name,
                                        "values": {port: values.get(k) for port, k in ports}})
        monitor = self._monitor
        if monitor is not None and len(monitor.events) > self._seen_alarms:
            for event in monitor.events[self._seen_alarms:]:
                self.events.append({"kind": "alarm", **event})
            self._seen_alarms = len(monitor.events)
        if len(self._corrections) > self._seen_corrections:  # the DT resynced or given an estimate: a marker
            for event in self._corrections[self._seen_corrections:]:
                self.events.append({**event, "kind": "correction", "correction": event["kind"]})
            self._seen_corrections = len(self._corrections)

    # ---- the server's side ----
    def status(self) -> dict:
        last = self.samples.last()
        out = {"state": self.state, "message": self.message, "sides": self.sides, "step": self.step_size,
               "end": self.end, "samples": self.samples.count, "time": last[0] if last else None}
        if last is not None and self.started_wall is not None:
            elapsed = last[1] - self.started_wall
            out["rtf"] = (last[0] - self.started_time) / elapsed if elapsed > 0 else None
        return out


class CellFeed(DashboardFeed):
    """The feed of a cell of several robots (cotwin.twin.assembly.cell): every robot's monitored variables (`ROBOT.q0`),
    every robot's d-model states, in the order the page's description (describe_cell) lists them; commands
    are named `ROBOT.event`."""

    def _watch(self, cell) -> None:
        from ...assembly.cell import CELL_MAPPING, dmodel_of

        program = cell.program
        self.variables, self._keys, self._state_keys, self._commands = [], [], [], []
        for robot in cell.robots:
            system = robot.system
            names = [robot.scoped(v) for v in system.models.monitored]
            self.variables += names
            self._keys += [(CELL_MAPPING.name, v) for v in names]
            self._state_keys += [(dmodel_of(robot.name).name, program.state_port(m)) for m in program.machines]
            source = robot.source
            for ev in program.inputs if source is not None else ():
                if ev.name in system.command_events:
                    self._commands.append(((source.name, ev.name), robot.scoped(ev.name),
                                           [(port, (source.name, port)) for port, _ in ev.value_ports]))
