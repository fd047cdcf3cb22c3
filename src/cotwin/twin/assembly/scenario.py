"""Scenarios of timed commands, and the controller unit that plays one.

Two formats: a TwinManager plan CSV (column `timestep` in ms of simulated time, then d-model input
ports; an event column true in a row sends that event) and a TOML list of commands:

    [[command]]
    time = 1.0                      # s
    event = "moveDiscreteCommand"
    args = { target_X = 0, target_Y = 23, target_Z = 1 }

Arguments are named by their d-model port (`MovementArgs_target_X`, as in plan CSVs, on the RMQ FMU's
wire and in the page's API: one naming everywhere); TOML scenarios and what-if plans also take the
field name older files use (`target_X`, or `value` for an event carrying one primitive value). A
command gives every argument of its event: it takes its arguments from itself, never from an earlier
one.

A command at time T is due in the step covering it (t <= T < t + h). Each raised event is an occurrence
(cotwin.twin.assembly.commands) queued in time order: the controller applies one per step, as an output of that
step true for exactly that step with its own arguments; commands due in the same step follow in the
next steps, none is lost. Both readers are strict: times must be finite and non-negative, integers
must fit the FMU's int32, and every problem is reported at its line and column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Collection, Iterator

from ...config import Key, Schema, TomlFile, did_you_mean, is_number, raise_problems
from ...cosim.units import INT32, Port, PythonUnit
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...dmodel.program import Program
from ...files import read_text
from ...plaindata import count
from .commands import CommandQueue, Occurrence

MAX_FIELD = 1 << 16  # characters: no cell of a plan is legitimately longer


@dataclass(frozen=True)
class Command:
    time: float  # s
    values: tuple[tuple[str, object], ...]  # port -> value
    where: str

    def raises(self, events: Collection[str]) -> list[str]:
        """The `events` this command raises, in its order: those it sets True (a plan's `true` or `1` cell is read
        as True; False, 0 or any other value raises nothing). The one rule the controller sends by (`occurrences`)
        and the plan's warnings (`no_event_rows`, `plan_order`) count by, so that they never disagree."""
        return [port for port, value in self.values if port in events and value is True]


def scenario_ports(program: Program) -> dict[str, str]:
    """The d-model input ports a scenario may drive, with their FMI types."""
    ports = {}
    for ev in program.inputs:
        ports[ev.name] = "Boolean"
        for port, sc in ev.value_ports:
            ports[port] = sc.fmi_type
    return ports


def row_time(row: list[str], line: int, problem) -> float | None:
    """A plan row's time (its first column, in ms), or None with the problem reported at the row."""
    try:
        time_ms = parse_value(row[0], "Real")
        if time_ms < 0:
            raise ValueError("is negative: a plan cannot send into the past")
    except ValueError as err:
        problem(line, 1, f"timestep '{row[0].strip()[:40]}' {err}")
        return None
    return time_ms


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


def _location(where: str) -> Location:
    """A command's `where` (file:line:column, or a name such as "plan item 2") as a Location."""
    parts = where.rsplit(":", 2)
    if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
        return Location(parts[0], int(parts[1]), int(parts[2]))
    return Location(where, 1, 1)


AFTER_END_SHOWN = 10  # warnings of commands after the end, one each; the rest summed up in one more


def _capped(rows: list, one: Callable[[object], Finding], more: Callable[[object, int], Finding]) -> list[Finding]:
    """A warning per row (`one`) for the first AFTER_END_SHOWN rows, then one (`more`: at the next row, with how
    many are left) for the rest."""
    out = [one(row) for row in rows[:AFTER_END_SHOWN]]
    if len(rows) > AFTER_END_SHOWN:
        out.append(more(rows[AFTER_END_SHOWN], len(rows) - AFTER_END_SHOWN))
    return out


def after_end(commands: list[Command], end: float, h: float = 0.0) -> list[Finding]:
    """Warnings for the commands a run to `end` never sends (the last step covers up to end): a plan
    longer than its run, or a run cut short by --end, should say what it leaves out. One per plan row (a
    cell's row holds several robots' commands), the first AFTER_END_SHOWN of them, then how many more."""
    rows = list(dict.fromkeys((c.where, c.time) for c in commands if c.time >= end - 1e-9))
    return _capped(rows, lambda row: Finding(_location(row[0]), Severity.WARNING, f"this command at {row[1]:g} s is "
                                             f"after the run's end ({end:g} s): it is never sent"),
                   lambda row, left: Finding(_location(row[0]), Severity.WARNING, f"and {left} more command(s) from "
                                             f"here on after the run's end ({end:g} s): never sent"))


def plan_order(commands: list[Command], events: set[str] | frozenset[str] = frozenset()) -> list[Finding]:
    """Warnings for a plan whose rows are not in time order (commands are sent in time order, not the file's),
    for rows that share a time and for a row raising several of the command `events` (a source applies one
    command per step: the others wait for the next steps; `Command.raises`, the controller's rule). One per plan row
    (a cell's row holds several robots' commands), the first AFTER_END_SHOWN, then how many more (`_capped`)."""
    rows = sorted(dict.fromkeys((_location(c.where), c.time) for c in commands),
                  key=lambda row: (row[0].path, row[0].line))
    out, latest, seen = [], None, {}
    for where, time in rows:
        if latest is not None and time < latest[1]:
            out.append(Finding(where, Severity.WARNING, f"this row at {time:g} s comes after one at {latest[1]:g} s "
                               f"(line {latest[0].line}): commands are sent in time order, not in the plan's"))
        elif time in seen:
            out.append(Finding(where, Severity.WARNING, f"this row has the time of line {seen[time].line} ({time:g} s): "
                               "one command is applied per step, this one in a later step"))
        if latest is None or time >= latest[1]:
            latest = (where, time)
        seen.setdefault(time, where)
    for c in commands:
        raised = c.raises(events)
        if len(raised) > 1:
            out.append(Finding(_location(c.where), Severity.WARNING, f"this row raises {', '.join(raised)}: one "
                               f"command is applied per step, {raised[0]} first and each other in a later step"))
    out.sort(key=lambda f: (f.location.path, f.location.line))
    return _capped(out, lambda f: f, lambda f, left: Finding(f.location, Severity.WARNING, f"... and {left} more "
                                                             "warning(s) of rows out of time order, sharing a time or "
                                                             "raising several events"))


def no_event_rows(commands: list[Command], program: Program) -> list[Finding]:
    """Warnings for plan rows that raise no event (`Command.raises`, the controller's rule): every event column false
    (or 0), or no event column at all (an event's argument columns alone). Such a row is accepted as 'no event this
    row' (a row switched off) but commands nothing, so it is neither sent nor counted: said at its line, not passed
    over in silence. The first AFTER_END_SHOWN, the rest summed up in one more."""
    events = {ev.name for ev in program.inputs}
    silent = [c for c in commands if not c.raises(events)]

    def one(c: Command) -> Finding:
        columns = [port for port, _ in c.values if port in events]
        why = (f"its event column(s) {', '.join(columns)} false" if columns else
               f"no event column, only {', '.join(port for port, _ in c.values) or 'its time'}: an event's arguments "
               "are read with the event")
        return Finding(_location(c.where), Severity.WARNING, f"this row at {c.time:g} s raises no event ({why}): it "
                       "commands nothing and is not counted")

    return _capped(silent, one, lambda c, left: Finding(_location(c.where), Severity.WARNING,
                                                        f"... and {left} more row(s) raising no event"))


def nothing_planned(plan: Path | None, commands: list[Command]) -> list[Finding]:
    """A warning for a plan (or command list) that holds no command: the run goes ahead without commands from
    outside, which a user who wrote a plan did not mean ("nothing happened" is said, not taken for success)."""
    if plan is None or commands:
        return []
    return [Finding(Location(str(plan), 1, 1), Severity.WARNING, "the plan holds no command: the d-model runs "
                    "without commands from outside")]


CLIP = min(MAX_FIELD * 4, csv.field_size_limit() - 1)  # a line cut here: a longer cell is reported, not met by csv


def plan_rows(path: Path, text: str) -> tuple[list[str], list[list[str]]]:
    """A plan's lines and CSV rows (each line cut at CLIP, so that csv never meets a field beyond its limit;
    `data_rows` reports such a row), its header checked to start with `timestep`; bad CSV is a located error."""
    lines = text.splitlines()
    reader = csv.reader(line if len(line) <= CLIP else line[:CLIP] for line in lines)
    try:
        rows = list(reader)
    except csv.Error as err:
        raise CotwinError([Finding(Location(str(path), max(reader.line_num, 1), 1), Severity.ERROR,
                                   f"bad CSV: {err}")]) from None
    if rows and len(rows[0]) == 1:  # one cell: another separator than the comma (a spreadsheet's ';', a tab)?
        other = next((sep for sep in (";", "\t", "|") if sep in rows[0][0]), None)
        if other is not None and rows[0][0].split(other)[0].strip() == "timestep":
            raise CotwinError([Finding(Location(str(path), 1, len(rows[0][0].split(other)[0]) + 1), Severity.ERROR,
                                       f"the plan's columns are separated by {other!r}: a plan is comma-separated "
                                       f"(CSV), e.g. 'timestep,{rows[0][0].split(other)[1].strip()[:40]}'")])
    if not rows or not rows[0] or rows[0][0].strip() != "timestep":
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR,
                                   "a plan starts with a header whose first column is 'timestep' (ms)")])
    return lines, rows


def data_rows(lines: list[str], rows: list[list[str]], width: int, problem) -> Iterator[tuple[int, list[str]]]:
    """A plan's rows after its header that can be read, with their line numbers: blank rows skipped; a row
    with a cell longer than MAX_FIELD (or its line cut at CLIP) or of another width than the header's reported
    through `problem(line, column, message)` and skipped."""
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(lines[line - 1]) > CLIP or any(len(cell) > MAX_FIELD for cell in row):
            problem(line, 1, f"a cell longer than {MAX_FIELD} characters")
        elif len(row) != width:
            problem(line, 1, f"{len(row)} values for {width} columns")
        else:
            yield line, row


def read_plan(path: str | Path, program: Program) -> list[Command]:
    path = Path(path)
    ports = scenario_ports(program)
    text = read_text(path, "plan")  # capped; errors located
    problems: list[Finding] = []

    def problem(line: int, column: int, message: str) -> None:
        problems.append(Finding(Location(str(path), line, column), Severity.ERROR, message))

    lines, rows = plan_rows(path, text)
    header = [h.strip() for h in rows[0]]
    starts = _column_starts(lines[0])
    column = lambda k: _column_at(starts, k)  # noqa: E731
    for k, h in enumerate(header[1:], start=1):
        if h not in ports:
            problem(1, column(k), f"unknown d-model input '{h}'{did_you_mean(h, ports)} (known: {', '.join(ports)})")
        elif h in header[1:k]:
            problem(1, column(k), f"column '{h}' appears twice")
    for ev in program.inputs:
        missing = [port for port, _ in ev.value_ports if port not in header]
        if ev.name in header and missing:
            problem(1, column(header.index(ev.name)), f"column '{ev.name}' without its argument column(s) "
                    f"{', '.join(missing)}: a command takes its arguments from its own row")
    commands = []
    for line, row in data_rows(lines, rows, len(header), problem):
        starts = _column_starts(lines[line - 1])
        values = []
        time_ms = row_time(row, line, problem)
        ok = time_ms is not None
        for k, (h, cell) in enumerate(zip(header[1:], row[1:]), start=1):
            if h not in ports:
                continue
            try:
                values.append((h, parse_value(cell, ports[h])))
            except ValueError as err:
                problem(line, _column_at(starts, k), f"column '{h}': '{cell.strip()[:40]}' {err}")
                ok = False
        if ok:
            commands.append(Command(time_ms / 1000.0, tuple(values), f"{path}:{line}:1"))
    raise_problems(problems)
    return sorted(commands, key=lambda c: c.time)


def _column_at(starts: list[int], k: int) -> int:
    """Where cell k starts (_column_starts), or 1 where the line shows fewer cells than csv read (a quoted cell
    holding a comma or a line break)."""
    return starts[k] if k < len(starts) else 1


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
                                    f"[[command]] {i + 1}: unknown event {name!r}{did_you_mean(name, events)} "
                                    f"(known: {', '.join(events)})"))
            continue
        args = item["args"] or {}
        values, wrong = command_values(events[name], args)
        for key, message in wrong:
            where = file.location(at + ("args", key)) if key in args else file.location(at)
            problems.append(Finding(where, Severity.ERROR, f"[[command]] {i + 1}: {message}"))
        if item["time"] is not None and not wrong:
            line, column = file.location(at).line, file.location(at).column
            commands.append(Command(float(item["time"]), tuple(values), f"{path}:{line}:{column}"))
    if not commands and not problems:
        problems.append(Finding(file.location(), Severity.ERROR, "the scenario has no [[command]]"))
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
    from ...robosim.types import NAT, EnumTy

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


def argument_keys(ev) -> dict[str, tuple[str, object]]:
    """The names a command may give an argument of the d-model input event `ev` by -> (port, Scalar): its
    port name (canonical: `MovementArgs_target_X`) and the field name older files use (`target_X`, or
    `value` for an event carrying one primitive value)."""
    keys = {port: (port, sc) for port, sc in ev.value_ports}
    for port, sc in ev.value_ports:
        keys.setdefault(sc.path[-1] if sc.path else "value", (port, sc))
    return keys


def command_values(ev, args: dict) -> tuple[list[tuple[str, object]], list[tuple[str | None, str]]]:
    """A command of event `ev` with `args` (either naming, see `argument_keys`) as port values: the event
    true, then each argument typed by `scalar_value`; and the problems, each with the key it is about
    (None for the command as a whole): an unknown or doubly given argument, a wrong value, a missing one."""
    keys = argument_keys(ev)
    given: dict[str, object] = {}
    problems: list[tuple[str | None, str]] = []
    for key, value in args.items():
        if key not in keys:
            problems.append((key, f"event {ev.name} has no argument {str(key)[:80]!r} (it has "
                                  f"{', '.join(port for port, _ in ev.value_ports) or 'none'})"))
            continue
        port, sc = keys[key]
        if port in given:
            problems.append((key, f"argument {port} of {ev.name} is given twice"))
            continue
        try:
            given[port] = scalar_value(value, sc)
        except ValueError as err:
            problems.append((key, f"argument {key}: {value!r:.80} {err}"))
            given[port] = None
    missing = [port for port, _ in ev.value_ports if port not in given]
    if missing:
        problems.append((None, f"event {ev.name} carries {', '.join(missing)}: a command gives every argument "
                               "(it never takes one from an earlier command)"))
    return [(ev.name, True), *((port, given[port]) for port, _ in ev.value_ports if port in given)], problems


def read_scenario(path: str | Path, program: Program) -> list[Command]:
    return read_toml(path, program) if str(path).endswith(".toml") else read_plan(path, program)


def occurrences(command: Command, events: set[str], arguments: dict[str, list[str]]) -> list[tuple[str, dict]]:
    """The events a command raises (its command events set true), in its order, each with the values of its own
    arguments (`arguments`: event -> its argument ports): what ScenarioUnit offers, one occurrence a step."""
    values = dict(command.values)
    return [(port, {p: values[p] for p in arguments.get(port, ()) if p in values}) for port in command.raises(events)]


def steps_before_due(due: float, origin: float, first: int, h: float, n: int) -> int:
    """How many of the next n steps (the first `first` steps after `origin`, of h s) offer no command due at
    `due`: a step starting at t offers those due before t + h (ScenarioUnit.step)."""
    k = max(0, min(n, int((due - origin) / h) - first - 1))  # an estimate, then made exact
    while k > 0 and not due >= origin + (first + k - 1) * h + h - 1e-9:
        k -= 1
    while k < n and due >= origin + (first + k) * h + h - 1e-9:
        k += 1
    return k


class ScenarioUnit(PythonUnit):
    """The controller: plays a scenario's commands into the d-model's inputs, one event per step (see
    module doc); `queue.applied` says when each was applied."""

    def __init__(self, name: str, program: Program, commands: list[Command], ports: list[str] | None = None,
                 together: bool = False):
        """Outputs: the ports the commands use, or `ports` (which must include them). `together`: every event due
        in a step is shown in that step (a generated test case's cycle of several inputs, whose oracle has them
        in one cycle), not one per step as a plan or a broker applies them."""
        types = scenario_ports(program)
        used = list(dict.fromkeys(port for c in commands for port, _ in c.values))
        if ports is not None:
            extra = [p for p in used if p not in ports]
            if extra:
                raise CotwinError(f"the scenario drives {', '.join(extra)}, which the unit {name} does not output")
            used = list(ports)
        super().__init__(name, [Port(p, types[p], "output") for p in used])
        self.events = {ev.name for ev in program.inputs} & set(used)
        self.arguments = {ev.name: [port for port, _ in ev.value_ports] for ev in program.inputs if ev.name in self.events}
        # an event's arguments are set with it only: a plan row's cells for an event it does not raise (a CSV's
        # 0s) would overwrite those of one applied before, which a clock slower than the step reads at its tick
        self.argument_ports = {port for ports in self.arguments.values() for port in ports}
        self.commands = sorted(commands, key=lambda c: c.time)
        self.queue = CommandQueue()
        self.together = together
        self._next = 0

    @property
    def command_events(self) -> set[str]:
        return set(self.events)

    @property
    def command_queue(self) -> CommandQueue:
        return self.queue

    def instantiate(self, start: float) -> None:
        super().instantiate(start)
        self._next = 0
        eps = 1e-9
        while self._next < len(self.commands) and self.commands[self._next].time < start - eps:
            self._next += 1

    def step(self, t: float, h: float) -> None:
        self.time = t + h
        for ev in self.events:
            self.values[ev] = False
        self._offer_due(t, t + h - 1e-9)
        self._apply(t + h)

    def _offer_due(self, start: float, before: float) -> None:
        """Offer the queue every command due before `before` not offered yet, each event with the values of
        its own arguments (those due before `start` are skipped: a start in the middle of the plan)."""
        eps = 1e-9
        commands = self.commands
        while self._next < len(commands) and commands[self._next].time < before:
            c = commands[self._next]
            self._next += 1
            if c.time < start - eps:
                continue
            raised = occurrences(c, self.events, self.arguments)
            for event, args in raised:
                self.queue.offer(Occurrence(event, tuple(args.items()), c.where, c.time))
            for port, value in c.values:  # values of no event: set as they come
                if port not in self.events and port not in self.argument_ports:
                    self.values[port] = value

    def _apply(self, at: float) -> None:
        """Show the next waiting command (its event true, its arguments set), or with `together` every one
        waiting, applied at time `at`."""
        for _ in range(len(self.queue) if self.together else 1):
            occurrence = self.queue.take(at)
            if occurrence is None:
                return
            self.values[occurrence.event] = True
            self.values.update(occurrence.values)

    def native_part(self, execution):
        """Its step for the native loop (cotwin.twin.assembly.native_commands): events reset, and the next command
        shown in the step it is due in where the C can show it as `step` does."""
        from .native_commands import NativeCommands

        return NativeCommands(self, execution).part()

    # ---- state: the port values, the time reached, the next command to play and those waiting ----
    STATE_KEYS = (*PythonUnit.STATE_KEYS, "next", "plan", "queue")

    def snapshot(self) -> dict:
        return {**super().snapshot(), "next": self._next, "plan": self._plan(), "queue": self.queue.snapshot()}

    def restore(self, snapshot: dict) -> None:
        """Continue where the saved unit was; a unit with another plan (a what-if) continues with the
        first of its commands not yet due at the saved time, none waiting."""
        super().restore(snapshot)
        if snapshot["plan"] == self._plan():
            self._next = count(snapshot["next"], f"unit {self.name}'s next command", len(self.commands))
            self.queue.restore(snapshot["queue"], self.ports, f"unit {self.name}'s command queue")
        else:
            self._offer_from_now()

    def _offer_from_now(self) -> None:
        """The commands due from its time on offered from its next step, none waiting (another plan than the saved
        one, or a fork's time whose event phase went to units since replaced: ClockedScenario.forked)."""
        self._next = next((k for k, c in enumerate(self.commands) if c.time >= self.time - 1e-9), len(self.commands))
        self.queue = CommandQueue()

    def _plan(self) -> list[tuple[float, tuple]]:
        return [(c.time, c.values) for c in self.commands]
