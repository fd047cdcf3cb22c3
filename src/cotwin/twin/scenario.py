"""Scenarios of timed commands, and the controller unit that plays one.

Two formats: a TwinManager plan CSV (column `timestep` in ms of simulated time, then d-model input
ports; an event column true in a row sends that event) and a TOML list of commands:

    [[command]]
    time = 1.0                      # s
    event = "moveDiscreteCommand"
    args = { target_X = 0, target_Y = 23, target_Z = 1 }

A command at time T is sent by the step covering it (t <= T < t + h): it is an output of that step, an
event for exactly one step; value ports keep their last value. Both readers are strict: times must be
finite and non-negative, two commands of one event at the same time are an error (one would be lost),
integers must fit the FMU's int32, and every problem is reported at its line and column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

from ..config import Key, Schema, TomlFile, is_number, raise_problems
from ..cosim.units import INT32, Port, PythonUnit
from ..diagnostics import CotwinError, Finding, Location, Severity
from ..dmodel.program import Program
from ..plaindata import count

MAX_FIELD = 1 << 16  # characters: no cell of a plan is legitimately longer


@dataclass(frozen=True)
class Command:
    time: float  # s
    values: tuple[tuple[str, object], ...]  # port -> value
    where: str


def scenario_ports(program: Program) -> dict[str, str]:
    """The d-model input ports a scenario may drive, with their FMI types."""
    ports = {}
    for ev in program.inputs:
        ports[ev.name] = "Boolean"
        for port, sc in ev.value_ports:
            ports[port] = sc.fmi_type
    return ports


def parse_value(text: str, fmi: str) -> object:
    """A plan cell as the port's FMI type, or ValueError saying why not."""
    text = text.strip()
    if fmi == "Boolean":
        if text.lower() not in ("true", "false", "1", "0"):
            raise ValueError("is not true/false")
        return text.lower() in ("true", "1")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"is not a valid {fmi.lower()}") from None
    if not math.isfinite(value):
        raise ValueError("is not a finite number")
    if fmi == "Integer":
        if value != int(value):
            raise ValueError("is not a valid integer")
        if not INT32[0] <= int(value) <= INT32[1]:
            raise ValueError("does not fit an FMI Integer (int32)")
        return int(value)
    return value


def _decode(path: Path, what: str) -> str:
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR,
                                   f"cannot read {what}: {err.strerror or err}")]) from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        column = err.start - (raw.rfind(b"\n", 0, err.start) + 1) + 1
        raise CotwinError([Finding(Location(str(path), line, column), Severity.ERROR,
                                   f"the {what} is not UTF-8 text (byte 0x{raw[err.start]:02x})")]) from None


def _same_time(commands: list[Command], events: set[str], problems: list[Finding], path: Path) -> None:
    problems.extend(same_step(commands, events))


def _location(where: str) -> Location:
    """A command's `where` (file:line:column, or a name such as "plan item 2") as a Location."""
    parts = where.rsplit(":", 2)
    if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
        return Location(parts[0], int(parts[1]), int(parts[2]))
    return Location(where, 1, 1)


def same_step(commands: list[Command], events: set[str], h: float = 0.0, start: float = 0.0) -> list[Finding]:
    """Commands raising one event in the same step of size `h` from `start` (with h = 0: at the same
    time): one step delivers an event once, so all but one would be lost."""
    eps = 1e-9
    seen: dict[tuple[float, str], Command] = {}
    found = []
    for c in commands:
        slot = c.time if h <= 0 else math.floor((c.time - start + eps) / h)
        for port, value in c.values:
            if port in events and value is True:
                first = seen.setdefault((slot, port), c)
                if first is not c:
                    when = f"at {c.time:g} s" if h <= 0 else f"at {c.time:g} s, in the step of {h:g} s that has one at {first.time:g} s"
                    found.append(Finding(_location(c.where), Severity.ERROR,
                                         f"a second {port} {when} (the first is at {first.where}): one step "
                                         "delivers an event once, so one of them would be lost"
                                         + ("" if h <= 0 else ": use a shorter step or space the commands")))
    return found


def after_end(commands: list[Command], end: float, h: float = 0.0) -> list[Finding]:
    """Warnings for the commands a run to `end` never sends (the last step covers up to end): a plan
    longer than its run, or a run cut short by --end, should say what it leaves out."""
    return [Finding(_location(c.where), Severity.WARNING, f"this command at {c.time:g} s is after the run's end "
                    f"({end:g} s): it is never sent") for c in commands if c.time >= end - 1e-9]


def read_plan(path: str | Path, program: Program) -> list[Command]:
    path = Path(path)
    ports = scenario_ports(program)
    text = _decode(path, "plan")
    problems: list[Finding] = []

    def problem(line: int, column: int, message: str) -> None:
        problems.append(Finding(Location(str(path), line, column), Severity.ERROR, message))

    lines = text.splitlines()
    clip = min(MAX_FIELD * 4, csv.field_size_limit() - 1)  # a longer cell is reported below, not by csv
    reader = csv.reader(line if len(line) <= clip else line[:clip] for line in lines)
    try:
        rows = list(reader)
    except csv.Error as err:
        raise CotwinError([Finding(Location(str(path), max(reader.line_num, 1), 1), Severity.ERROR,
                                   f"bad CSV: {err}")]) from None
    if not rows or not rows[0] or rows[0][0].strip() != "timestep":
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR,
                                   "a plan starts with a header whose first column is 'timestep' (ms)")])
    header = [h.strip() for h in rows[0]]
    columns = _column_starts(lines[0])
    for k, h in enumerate(header[1:], start=1):
        if h not in ports:
            problem(1, columns[k], f"unknown d-model input '{h}' (known: {', '.join(ports)})")
        elif h in header[1:k]:
            problem(1, columns[k], f"column '{h}' appears twice")
    commands = []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        starts = _column_starts(lines[line - 1])
        if len(lines[line - 1]) > clip or any(len(cell) > MAX_FIELD for cell in row):
            problem(line, 1, f"a cell longer than {MAX_FIELD} characters")
            continue
        if len(row) != len(header):
            problem(line, 1, f"{len(row)} values for {len(header)} columns")
            continue
        values, ok = [], True
        try:
            time_ms = parse_value(row[0], "Real")
            if time_ms < 0:
                raise ValueError("is negative: a plan cannot send into the past")
        except ValueError as err:
            problem(line, 1, f"timestep '{row[0].strip()[:40]}' {err}")
            ok = False
        for k, (h, cell) in enumerate(zip(header[1:], row[1:]), start=1):
            if h not in ports:
                continue
            try:
                values.append((h, parse_value(cell, ports[h])))
            except ValueError as err:
                problem(line, starts[k] if k < len(starts) else 1, f"column '{h}': '{cell.strip()[:40]}' {err}")
                ok = False
        if ok:
            commands.append(Command(time_ms / 1000.0, tuple(values), f"{path}:{line}:1"))
    _same_time(commands, {ev.name for ev in program.inputs}, problems, path)
    raise_problems(problems)
    return sorted(commands, key=lambda c: c.time)


def _column_starts(line: str) -> list[int]:
    """1-based columns where each comma-separated cell of a line starts (quotes not expected in plans)."""
    starts, column = [1], 1
    for ch in line:
        column += 1
        if ch == ",":
            starts.append(column)
    return starts


COMMAND = Schema({"time": Key("nonnegative", required=True), "event": Key("str", required=True),
                  "args": Key("table", {})})
SCENARIO = Schema({"command": Key("list", required=True)})


def read_toml(path: str | Path, program: Program) -> list[Command]:
    path = Path(path)
    file = TomlFile(path, "scenario")
    problems: list[Finding] = []
    data = SCENARIO.read(file.data, file, (), problems)
    events = {ev.name: ev for ev in program.inputs}
    commands = []
    for i, item in enumerate(data.get("command") or [], start=0):
        at = ("command", i)
        if not isinstance(item, dict):
            problems.append(Finding(file.location(at), Severity.ERROR, f"[[command]] {i + 1} must be a table"))
            continue
        item = COMMAND.read(item, file, at, problems)
        name = item["event"]
        if name is None:
            continue
        if name not in events:
            problems.append(Finding(file.location(at + ("event",)), Severity.ERROR,
                                    f"[[command]] {i + 1}: unknown event {name!r} (known: {', '.join(events)})"))
            continue
        ev = events[name]
        fields = {sc.path[-1] if sc.path else "value": (port, sc) for port, sc in ev.value_ports}
        values = [(name, True)]
        for key, value in (item["args"] or {}).items():
            where = file.location(at + ("args", key))
            if key not in fields:
                problems.append(Finding(where, Severity.ERROR, f"[[command]] {i + 1}: event {name} has no argument "
                                                               f"'{key}' (has {', '.join(fields) or 'none'})"))
                continue
            port, sc = fields[key]
            try:
                values.append((port, scalar_value(value, sc)))
            except ValueError as err:
                problems.append(Finding(where, Severity.ERROR,
                                        f"[[command]] {i + 1}: argument {key} must be {_article(sc.fmi_type)}: "
                                        f"{value!r} {err}"))
        if item["time"] is not None:
            line, column = file.location(at).line, file.location(at).column
            commands.append(Command(float(item["time"]), tuple(values), f"{path}:{line}:{column}"))
    if not commands and not problems:
        problems.append(Finding(file.location(), Severity.ERROR, "the scenario has no [[command]]"))
    _same_time(commands, set(events), problems, path)
    raise_problems(problems)
    return sorted(commands, key=lambda c: c.time)


def typed_value(value, fmi: str) -> object:
    """A TOML or JSON value as the port's FMI type, or ValueError saying why not (never coerced
    silently: 1.5 is not an integer, 1 is not a Boolean, 2**32 does not fit int32)."""
    if fmi == "Boolean":
        if isinstance(value, bool):
            return value
        raise ValueError("is not true or false")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError("is not a number")
    if not is_number(value):  # also an integer too large for any float
        raise ValueError("is not a finite number")
    if fmi == "Integer":
        if isinstance(value, float):
            raise ValueError("is not an integer")
        if not INT32[0] <= value <= INT32[1]:
            raise ValueError("does not fit an FMI Integer (int32)")
        return value
    return float(value)


def scalar_value(value, sc, typed=None) -> object:
    """A TOML or JSON value for the d-model input scalar `sc` (a dmodel Scalar): `typed` (typed_value, or a
    reader's own FMI typing) within its RoboSim type: an enumeration takes one of its literals (by name, or
    by index), a nat is not negative; ValueError saying why not."""
    from ..robosim.types import NAT, EnumTy

    typed = typed or typed_value
    if isinstance(sc.ty, EnumTy):
        names = [lit.name for lit in sc.ty.decl.literals]
        if isinstance(value, str) and value in names:
            return names.index(value)
        index = typed(value, "Integer") if not isinstance(value, str) else None
        if index is None or not 0 <= index < len(names):
            raise ValueError(f"is not a literal of {sc.ty.decl.name} ({', '.join(names)}, or their index "
                             f"0..{len(names) - 1})")
        return index
    out = typed(value, sc.fmi_type)
    if sc.ty == NAT and out < 0:
        raise ValueError("is negative (the input is a nat)")
    return out


def _article(fmi: str) -> str:
    return {"Integer": "an integer", "Real": "a number", "Boolean": "true or false"}[fmi]


def read_scenario(path: str | Path, program: Program) -> list[Command]:
    return read_toml(path, program) if str(path).endswith(".toml") else read_plan(path, program)


class ScenarioUnit(PythonUnit):
    """The controller: plays a scenario's commands into the d-model's inputs."""

    def __init__(self, name: str, program: Program, commands: list[Command], ports: list[str] | None = None):
        """Outputs: the ports the commands use, or `ports` (which must include them)."""
        types = scenario_ports(program)
        used = list(dict.fromkeys(port for c in commands for port, _ in c.values))
        if ports is not None:
            extra = [p for p in used if p not in ports]
            if extra:
                raise CotwinError(f"the scenario drives {', '.join(extra)}, which the unit {name} does not output")
            used = list(ports)
        super().__init__(name, [Port(p, types[p], "output") for p in used])
        self.events = {ev.name for ev in program.inputs} & set(used)
        self.commands = sorted(commands, key=lambda c: c.time)
        self._next = 0
        self._checked_step = None

    @property
    def command_events(self) -> set[str]:
        return set(self.events)

    def instantiate(self, start: float) -> None:
        super().instantiate(start)
        self._next = 0
        eps = 1e-9
        while self._next < len(self.commands) and self.commands[self._next].time < start - eps:
            self._next += 1

    def step(self, t: float, h: float) -> None:
        if h != self._checked_step:  # once per step size: no two commands of one event may share a step
            problems = same_step(self.commands[self._next:], self.events, h, t)
            if problems:
                raise CotwinError(problems)
            self._checked_step = h
        self.time = t + h
        for ev in self.events:
            self.values[ev] = False
        eps = 1e-9
        commands = self.commands
        while self._next < len(commands) and commands[self._next].time < t + h - eps:
            c = commands[self._next]
            self._next += 1
            if c.time < t - eps:  # before this step: a start in the middle of the plan skips it
                continue
            for port, value in c.values:
                if port in self.events:
                    self.values[port] = self.values[port] or bool(value)
                else:
                    self.values[port] = value

    # ---- state: the port values, the time reached and the next command to play ----
    STATE_KEYS = (*PythonUnit.STATE_KEYS, "next", "plan")

    def snapshot(self) -> dict:
        return {**super().snapshot(), "next": self._next, "plan": self._plan()}

    def restore(self, snapshot: dict) -> None:
        """Continue where the saved unit was; a unit with another plan (a what-if) continues with the
        first of its commands not yet due at the saved time."""
        super().restore(snapshot)
        if snapshot["plan"] == self._plan():
            self._next = count(snapshot["next"], f"unit {self.name}'s next command", len(self.commands))
        else:
            self._next = next((k for k, c in enumerate(self.commands) if c.time >= self.time - 1e-9), len(self.commands))

    def _plan(self) -> list[tuple[float, tuple]]:
        return [(c.time, c.values) for c in self.commands]
