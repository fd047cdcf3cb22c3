"""A scenario's commands applied inside the native loop (cotwin.cosim.native, issue 23): `NativeCommands`.

The controller's step (ScenarioUnit.step) resets its events, then shows the command due in the step: its event
true for that step, with its own arguments. Inside a stretch of the native loop the same is C: every event reset
at each step, and the next command's values written at the step it is due in, when the C can apply it as the
Python step would: it raises at most one event (a second would wait in the queue, which Python keeps), no other
command is due in its step, it is not due before its step starts (Python skips such a command), and each of its
values is a plain number of its port's type, written to an observed port that already holds one (a Real port
still at the integer 0 it starts with keeps that spelling: Python sets it). Otherwise the stretch stops before
the step, which Python makes. After the stretch the unit is brought up to date: the command offered and taken
at its step's end, the values it set, the events as the last step left them.
"""

from __future__ import annotations

from ...cosim.native import NativePart, outputs
from .scenario import occurrences, steps_before_due

_CLASS = {"Real": float, "Integer": int, "Boolean": bool}


class NativeCommands:
    """The controller's step in C for the native loop, for a ScenarioUnit `unit` of `execution` (see module doc)."""

    def __init__(self, unit, execution):
        self.unit, self.execution = unit, execution
        self.slots = outputs(execution, unit)  # the observed ports: those the C can write
        self.ports = list(self.slots)
        self.doubles = [-1.0] + [0.0] * (2 * len(self.ports))  # the step a command is due in, then per port: written, value
        self.due: tuple[int, object, list] | None = None  # (step since origin, command, values) of the stretch to run
        self.refusal = "a command is due or waits"
        writes = " ".join(f"if (DD[{1 + 2 * k}] != 0.0) N[{self.slots[p]}] = DD[{2 + 2 * k}];"
                          for k, p in enumerate(self.ports))
        self.lines = [*(f"N[{self.slots[e]}] = 0.0;" for e in sorted(unit.events) if e in self.slots),
                      f"if ((double)(base + j) == DD[0]) {{ {writes} }}  /* the command due in this step */"]

    def part(self) -> NativePart:
        return NativePart("\n".join(self.lines), doubles=self.doubles, quiet=self.quiet, begin=self.begin,
                          end=self.end, writes=frozenset(self.ports), refusal=lambda: self.refusal)

    def quiet(self, n: int) -> int:
        """How many of the next n steps the controller can make natively: up to the step of the command after
        the next when the C can apply the next, else up to the next one's step."""
        unit, execution = self.unit, self.execution
        self.due = None
        if len(unit.queue) or (unit.together and any(unit.values[ev] is True for ev in unit.events)):
            return 0
        commands, k = unit.commands, unit._next
        if k >= len(commands):
            return n
        origin, done = execution._origin
        first, h = execution.steps - done, execution.step_size
        ahead = steps_before_due(commands[k].time, origin, first, h, n)
        if ahead >= n:
            return n
        values = None if unit.together else self._values(commands[k], origin + (first + ahead) * h)
        if values is None:
            return ahead
        if k + 1 < len(commands):
            after = steps_before_due(commands[k + 1].time, origin, first, h, n)
            if after <= ahead:  # due in the same step: the second waits in the queue
                return ahead
            n = min(n, after)
        self.due = (first + ahead, commands[k], values)
        return n

    def _values(self, command, start: float) -> list[tuple[str, object]] | None:
        """The values the step starting at `start` shows for `command` (its other ports, then its event and the
        event's arguments), or None when the C cannot show them as Python does (see module doc)."""
        unit = self.unit
        if command.time < start - 1e-9:
            return None
        raised = occurrences(command, unit.events, unit.arguments)
        if len(raised) > 1:
            return None
        values = [(port, value) for port, value in command.values
                  if port not in unit.events and port not in unit.argument_ports]
        for event, args in raised:
            values += [(event, True), *args.items()]
        for port, value in values:
            cls = _CLASS.get(unit.ports[port].type) if port in self.slots else None
            if cls is None or value.__class__ is not cls or unit.values[port].__class__ is not cls or \
                    (cls is int and abs(value) > 2 ** 53):
                return None
        return values

    def begin(self) -> None:
        doubles = self.doubles
        doubles[:] = [-1.0] + [0.0] * (2 * len(self.ports))
        if self.due is not None:
            step, _, values = self.due
            doubles[0] = float(step)
            for port, value in values:
                k = self.ports.index(port)
                doubles[1 + 2 * k], doubles[2 + 2 * k] = 1.0, float(value)

    def end(self, first: int, made: int, rows, doubles) -> None:
        """The unit as `step` leaves it after `made` steps from step `first`: the step a command was due in made by
        `step` itself (the command offered and taken at its end, its values shown), its events reset by the
        steps after, its time that of the last."""
        unit, execution = self.unit, self.execution
        due, self.due = self.due, None
        if not made:
            return
        origin, done = execution._origin
        h = execution.step_size
        last = first - done + made - 1  # the last step made, counted from the origin
        shown = due is not None and due[0] <= last
        if shown:
            unit.step(origin + due[0] * h, h)
        if not shown or due[0] < last:
            for event in unit.events:
                unit.values[event] = False
        unit.time = origin + last * h + h
