"""Scenarios of timed commands, and the controller unit that plays one.

Two formats: a TwinManager plan CSV (column `timestep` in ms of simulated time, then d-model input
ports; an event column true in a row sends that event) and a TOML list of commands:

    [[command]]
    time = 1.0                      # s
    event = "moveDiscreteCommand"
    args = { target_X = 0, target_Y = 23, target_Z = 1 }

A command at time T is sent by the step covering it (t <= T < t + h): it is an output of that step, an
event for exactly one step; value ports keep their last value.
"""

from __future__ import annotations

import csv
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..cosim.units import Port, PythonUnit
from ..diagnostics import CotwinError, Finding, Location, Severity
from ..dmodel.program import Program


@dataclass(frozen=True)
class Command:
    time: float  # s
    values: tuple[tuple[str, object], ...]  # port -> value
    where: str


def _error(path, line, message):
    return CotwinError([Finding(Location(str(path), line, 1), Severity.ERROR, message)])


def scenario_ports(program: Program) -> dict[str, str]:
    """The d-model input ports a scenario may drive, with their FMI types."""
    ports = {}
    for ev in program.inputs:
        ports[ev.name] = "Boolean"
        for port, sc in ev.value_ports:
            ports[port] = sc.fmi_type
    return ports


def _value(text: str, fmi: str, path, line, column: str):
    text = text.strip()
    try:
        if fmi == "Boolean":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if fmi == "Integer":
            value = float(text)
            if value != int(value):
                raise ValueError
            return int(value)
        return float(text)
    except ValueError:
        raise _error(path, line, f"column '{column}': '{text}' is not a valid {fmi.lower()}") from None


def read_plan(path: str | Path, program: Program) -> list[Command]:
    path = Path(path)
    ports = scenario_ports(program)
    try:
        rows = list(csv.reader(path.read_text().splitlines()))
    except OSError as err:
        raise _error(path, 1, f"cannot read plan: {err}") from None
    if not rows or not rows[0] or rows[0][0].strip() != "timestep":
        raise _error(path, 1, "a plan starts with a header whose first column is 'timestep' (ms)")
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header[1:] if h not in ports]
    if unknown:
        raise _error(path, 1, f"unknown d-model input(s) {', '.join(unknown)} (known: {', '.join(ports)})")
    commands = []
    for line, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise _error(path, line, f"{len(row)} values for {len(header)} columns")
        time_ms = _value(row[0], "Real", path, line, "timestep")
        values = tuple((h, _value(v, ports[h], path, line, h)) for h, v in zip(header[1:], row[1:]))
        commands.append(Command(time_ms / 1000.0, values, f"{path}:{line}"))
    return sorted(commands, key=lambda c: c.time)


def read_toml(path: str | Path, program: Program) -> list[Command]:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise _error(path, 1, f"cannot read scenario: {err}") from None
    events = {ev.name: ev for ev in program.inputs}
    commands = []
    for i, item in enumerate(data.get("command", []), start=1):
        where = f"{path}: command {i}"
        name = item.get("event")
        if name not in events:
            raise _error(path, 1, f"command {i}: unknown event {name!r} (known: {', '.join(events)})")
        if not isinstance(item.get("time"), (int, float)) or item["time"] < 0:
            raise _error(path, 1, f"command {i}: 'time' must be a non-negative number of seconds")
        args = item.get("args", {})
        ev = events[name]
        fields = {sc.path[-1] if sc.path else "value": (port, sc) for port, sc in ev.value_ports}
        values = [(name, True)]
        for key, value in args.items():
            if key not in fields:
                raise _error(path, 1, f"command {i}: event {name} has no argument '{key}' (has {', '.join(fields) or 'none'})")
            port, sc = fields[key]
            if sc.fmi_type == "Integer" and (not isinstance(value, int) or isinstance(value, bool)):
                raise _error(path, 1, f"command {i}: argument {key} must be an integer, got {value!r}")
            if sc.fmi_type == "Real" and not isinstance(value, (int, float)):
                raise _error(path, 1, f"command {i}: argument {key} must be a number, got {value!r}")
            values.append((port, value))
        commands.append(Command(float(item["time"]), tuple(values), where))
    if not commands:
        raise _error(path, 1, "the scenario has no [[command]]")
    return sorted(commands, key=lambda c: c.time)


def read_scenario(path: str | Path, program: Program) -> list[Command]:
    return read_toml(path, program) if str(path).endswith(".toml") else read_plan(path, program)


class ScenarioUnit(PythonUnit):
    """The controller: plays a scenario's commands into the d-model's inputs."""

    def __init__(self, name: str, program: Program, commands: list[Command]):
        types = scenario_ports(program)
        used = list(dict.fromkeys(port for c in commands for port, _ in c.values))
        super().__init__(name, [Port(p, types[p], "output") for p in used])
        self.events = {ev.name for ev in program.inputs} & set(used)
        self.commands = commands

    @property
    def command_events(self) -> set[str]:
        return set(self.events)

    def step(self, t: float, h: float) -> None:
        for ev in self.events:
            self.values[ev] = False
        eps = 1e-9
        for c in self.commands:
            if t - eps <= c.time < t + h - eps:
                for port, value in c.values:
                    if port in self.events:
                        self.values[port] = self.values[port] or bool(value)
                    else:
                        self.values[port] = value
