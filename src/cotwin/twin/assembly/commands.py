"""Commands as event occurrences: every accepted command is applied, once, in order.

A command source (a plan's controller, the RabbitMQ bridge, and through it the page's panel) turns each
command into an `Occurrence`: one d-model input event with the values of its own arguments. It
offers them to a `CommandQueue`, which applies one per step (a d-model's waiting state takes one event
per cycle; two raised in one step would be one occurrence, or one taken and the other ignored), the
others in the following steps in the order they came. A bounded queue refuses a command when it is
full (`QueueFull`, said to the sender); a command it accepted is applied, and `applied` says in which
step: the time at that step's end, the row of outputs.csv that shows it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from ...plaindata import StateError, count, fields, finite, of_type, port_value


@dataclass(frozen=True)
class Occurrence:
    """One occurrence of a command event with the values of its arguments (value ports)."""

    event: str
    values: tuple[tuple[str, object], ...]
    origin: str  # where it came from: a plan's line, a message's time
    due: float  # the simulation time it was sent for (s)
    ident: str | None = None  # the sender's id, given back when it is applied or refused

    def describe(self) -> str:
        args = ", ".join(f"{port}={value}" for port, value in self.values)
        return f"{self.event}({args})"


@dataclass(frozen=True)
class Applied:
    command: Occurrence
    time: float  # the end of the step that applied it (s)


class QueueFull(Exception):
    """The queue holds `limit` commands: this one is refused (the sender is told so)."""


class CommandQueue:
    """Commands waiting for their step, applied one per step in the order offered (see module doc)."""

    MAX_APPLIED = 10_000  # applied commands remembered (a live twin may run for days)

    def __init__(self, limit: int | None = None):
        self.limit = limit
        self.waiting: deque[Occurrence] = deque()
        self.applied: deque[Applied] = deque(maxlen=self.MAX_APPLIED)
        self.accepted = 0
        self.refused = 0
        self.applied_count = 0  # every command applied (`applied` keeps the newest)

    def __len__(self) -> int:
        return len(self.waiting)

    def offer(self, command: Occurrence) -> int:
        """Accept `command` to be applied after those waiting; its place in the queue (0: next step), or
        QueueFull when `limit` wait already."""
        if self.limit is not None and len(self.waiting) >= self.limit:
            self.refused += 1
            raise QueueFull(f"{self.limit} commands wait to be applied, one per step")
        self.waiting.append(command)
        self.accepted += 1
        return len(self.waiting) - 1

    def take(self, step_end: float) -> Occurrence | None:
        """The command the step ending at `step_end` applies, if any."""
        if not self.waiting:
            return None
        command = self.waiting.popleft()
        self.applied.append(Applied(command, step_end))
        self.applied_count += 1
        return command

    # ---- state (plain data: a fork continues with the commands that were waiting) ----
    def snapshot(self) -> dict:
        return {"waiting": [_plain(c) for c in self.waiting], "applied": [(_plain(a.command), a.time) for a in self.applied],
                "accepted": self.accepted, "refused": self.refused, "applied_count": self.applied_count}

    def restore(self, snapshot: dict, ports: dict | None = None, what: str = "command queue") -> None:
        """Continue with a saved queue, checked first: its counts, and every command an event of `ports`
        (name -> cotwin.cosim.units.Port, where known) with values of its value ports' types."""
        fields(snapshot, what, ("waiting", "applied", "accepted", "refused"), ("applied_count",))
        waiting = [self._occurrence(c, ports, f"{what}'s waiting command")
                   for c in of_type(snapshot["waiting"], (list, tuple), f"{what}'s waiting commands")]
        applied = []
        for entry in of_type(snapshot["applied"], (list, tuple), f"{what}'s applied commands")[-self.MAX_APPLIED:]:
            if not isinstance(entry, (list, tuple)) or len(entry) != 2:
                raise StateError(f"the saved state's {what} has an applied command {entry!r:.60}, not a (command, time)")
            applied.append(Applied(self._occurrence(entry[0], ports, f"{what}'s applied command"),
                                   finite(entry[1], f"{what}'s applied command's time")))
        self.waiting = deque(waiting)
        self.applied = deque(applied, maxlen=self.MAX_APPLIED)
        self.accepted = count(snapshot["accepted"], f"{what}'s accepted count")
        self.refused = count(snapshot["refused"], f"{what}'s refused count")
        self.applied_count = count(snapshot.get("applied_count", len(applied)), f"{what}'s applied count")

    @staticmethod
    def _occurrence(data, ports: dict | None, what: str) -> Occurrence:
        if not isinstance(data, (list, tuple)) or len(data) != 5:
            raise StateError(f"the saved state's {what} is {data!r:.60}, not (event, values, origin, due, id)")
        event, values, origin, due, ident = data
        if not isinstance(event, str) or (ports is not None and event not in ports):
            raise StateError(f"the saved state's {what} is an event {event!r:.60} this unit does not send")
        pairs = []
        for pair in of_type(values, (list, tuple), f"{what}'s values"):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2 or not isinstance(pair[0], str) or \
                    (ports is not None and pair[0] not in ports):
                raise StateError(f"the saved state's {what} sets {pair!r:.60}, not a value port of this unit")
            value = pair[1] if ports is None else port_value(pair[1], ports[pair[0]].type, f"{what}'s {pair[0]}")
            pairs.append((pair[0], value))
        if ident is not None:
            of_type(ident, str, f"{what}'s id")
        return Occurrence(event, tuple(pairs), of_type(origin, str, f"{what}'s origin"), finite(due, f"{what}'s time"),
                          ident)


def _plain(c: Occurrence) -> tuple:
    return (c.event, tuple(c.values), c.origin, c.due, c.ident)
