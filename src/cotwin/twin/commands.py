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

    def restore(self, snapshot: dict) -> None:
        self.waiting = deque(Occurrence(*c) for c in snapshot["waiting"])
        self.applied = deque((Applied(Occurrence(*c), t) for c, t in snapshot["applied"]), maxlen=self.MAX_APPLIED)
        self.accepted, self.refused = snapshot["accepted"], snapshot["refused"]
        self.applied_count = snapshot.get("applied_count", len(self.applied))


def _plain(c: Occurrence) -> tuple:
    return (c.event, tuple(c.values), c.origin, c.due, c.ident)
