"""Honest outcomes: what became of every command a run applied (`cotwin run`, `twin`, `whatif`).

`CommandLedger`, an observer, follows each command from the step that applied it (the source's
`applied` list: cotwin.twin.assembly.commands) through the d-model and the mapping:
- *taken*: in the step the d-model reads it (the next under Jacobi, the same under Gauss-Seidel; with an
  FMI 3.0 d-model, the first step whose event phase ran its cycle: a clock slower than the step keeps it; one
  due at the run's start crosses in the event phase before the first step, the d-model's first cycle) its
  state changes or it calls an operation, by a way that reads the command's event (a change an earlier
  command's progress made, on transitions that never read it, is no taking: cotwin.dmodel.waits.CycleReads);
  else it was *not taken* (the d-model was busy: the state it read it in is named; or, before the tick of a clock
  slower than the step, the same event was applied again: the tick reads one occurrence, with the last one's
  values, so the earlier is *replaced*). A command taken is
  `accepted`; the operations and platform events that follow, until the next command taken, are its own;
- *infeasible*: among its events one the project's `[outcomes] infeasible` names, else (the key left out) one
  named `nonfeasible*`, `infeasible*`, `unreachable*` (feasible: `[outcomes] feasible`, else `feasible*`,
  `reachable*`), a naming convention of mappings such as the paper's, for events no key names;
- *stopped*: among its events, before it completed, one that stops a move (`[outcomes] stops`, else one a word
  of whose name is collision, fault, emergency or protective and none says the opposite: `stopping`): the
  d-model then returns to rest having not done it, which is no completion;
- *completed at t*: taken, not infeasible, not stopped, and the d-model back at rest (the leaf each machine
  rests in after its first cycle without inputs, e.g. Idle) at t, or passed through it in the cycle at t that
  took the next command (AwaitClosed -> Idle -> Requested: CycleReads.passes); *never completed* otherwise.

`Summary` words it, one line per command, with a warning when commands were applied and none
completed; `strict_failures` lists what makes `--strict` exit with STRICT_EXIT.
"""

from __future__ import annotations

import re
from collections import deque
from functools import lru_cache
from dataclasses import dataclass, field

from ...cosim.observers import Observer
from ...dmodel.waits import CycleReads
from ...memo import once_per
from .clocked import DModelCycles
from .system import DMODEL, MAPPING, TwinSystem

INFEASIBLE = re.compile(r"^(non|in|un)(feasible|reachable)", re.IGNORECASE)
FEASIBLE = re.compile(r"^(feasible|reachable)", re.IGNORECASE)
STOPS = {"collision", "fault", "emergency", "protective"}  # a word of the name of an event that stops a move
NOT_STOPS = {"no", "not", "non", "free", "clear", "cleared", "reset", "ok", "none"}  # ... unless it says the opposite


def answers_feasibility(program, roles: "EventRoles | None" = None) -> bool:
    """Whether a d-model takes feasibility answers (an input event named feasible*, infeasible*, ..., or one the
    project's [outcomes] names): only then is a command without one of unknown feasibility; for others
    feasibility is not a question."""
    roles = roles or EventRoles()
    return any(roles.feasible(ev.name) or roles.infeasible(ev.name) for ev in program.inputs)


@lru_cache(maxsize=None)  # asked of the events of every step: a mapping has a few names
def stopping(event: str) -> bool:
    """Whether an event's name says a move was stopped: one of its words (camelCase or snake_case) is collision,
    fault, emergency or protective (`collision`, `robotCollision`, `protectiveStop`, `fault_detected`), and none
    says the opposite (`noCollision`, `collisionFree`, `faultCleared`, `resetFault`; `setDefault` has no such word)."""
    words = {w.lower() for w in re.findall(r"[A-Z]?[a-z0-9]+|[A-Z]+(?![a-z])", event)}
    return bool(words & STOPS) and not words & NOT_STOPS


@dataclass(frozen=True)
class EventRoles:
    """Which of the d-model's input events say a command is infeasible, feasible, or stopped: the project's
    `[outcomes]` lists where given (a d-model of one's own names its answers as it likes; an empty list: no event
    has that role), else the naming convention above, which never claims an event a list names for another role
    (`feasible = ["nonfeasibleX"]` makes nonfeasibleX feasible only)."""

    infeasible_events: frozenset[str] | None = None
    feasible_events: frozenset[str] | None = None
    stop_events: frozenset[str] | None = None

    @classmethod
    def of(cls, spec) -> "EventRoles":
        """The roles a project's `[outcomes]` gives (cotwin.twin.project: TwinProject.outcome_events)."""
        given = getattr(spec, "outcome_events", None) or {}
        named = {role: frozenset(given[role]) if role in given else None
                 for role in ("infeasible", "feasible", "stops")}
        return cls(named["infeasible"], named["feasible"], named["stops"])

    @lru_cache(maxsize=4096)  # asked at every step an event holds; the roles are values (equal, one entry)
    def infeasible(self, event: str) -> bool:
        return self._has(self.infeasible_events, event, lambda e: bool(INFEASIBLE.match(e)))

    @lru_cache(maxsize=4096)
    def feasible(self, event: str) -> bool:
        return self._has(self.feasible_events, event, lambda e: bool(FEASIBLE.match(e)))

    @lru_cache(maxsize=4096)
    def stops(self, event: str) -> bool:
        return self._has(self.stop_events, event, stopping)

    def _has(self, named: frozenset[str] | None, event: str, by_name) -> bool:
        """`event` in the role's list when given, else by its name unless a list names it (for another role)."""
        if named is not None:
            return event in named
        given = (self.infeasible_events, self.feasible_events, self.stop_events)
        return not any(event in g for g in given if g is not None) and by_name(event)


STRICT_EXIT = 3  # `--strict`: a command applied but not completed, or none at all completed (docs/interop.md)


def rest_states(program) -> dict[str, int]:
    """The leaf each machine rests in after its first cycle with no inputs (e.g. Idle), by state port."""
    from ...dmodel.interpreter import Interpreter

    interp = Interpreter(program)
    interp.step({})
    return {program.state_port(m): interp.state_index(k) for k, m in enumerate(program.machines)}


@dataclass
class CommandOutcome:
    time: float  # when it was due (simulation time; a what-if's plan time shifted to the fork's clock)
    event: str
    args: dict
    delivered: float | None = None  # the end of the step that applied it
    accepted: bool = False  # the d-model took it (its state changed or it called an operation)
    operations: list[str] = field(default_factory=list)
    events: list[str] = field(default_factory=list)  # platform events until the next command taken
    feasible: bool | None = None
    done: float | None = None  # back at rest after it
    origin: str = ""  # where it came from (a plan's line, a message's time)
    busy: str | None = None  # the d-model's state when it was not taken
    stopped: tuple[str, float] | None = None  # (event, time): a stopping event came before it completed
    replaced: float | None = None  # not taken: the same event applied at this time reached the d-model's cycle instead
    refused_by: str | None = None  # infeasible: the answer that said so

    @property
    def verdict(self) -> str:
        if self.delivered is None:
            return "not applied"
        if not self.accepted:
            return "not taken"
        if self.feasible is False:
            return "infeasible"
        if self.stopped is not None:
            return "stopped"
        return "completed" if self.done is not None else "never completed"

    def describe(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.args.items())
        verdict = self.verdict
        if verdict == "completed":
            how = f"completed at t = {self.done:g} s"
        elif verdict == "infeasible":
            how = f"infeasible ({self.refused_by})" if self.refused_by else "infeasible"
        elif verdict == "not taken" and self.replaced is not None:
            how = f"not taken (replaced by the one applied at t = {self.replaced:g} s before the d-model's cycle read it)"
        elif verdict == "not taken":
            how = f"not taken (the d-model was in state {self.busy})"
        elif verdict == "stopped":
            how = f"stopped by {self.stopped[0]} at t = {self.stopped[1]:g} s"
        else:
            how = {"never completed": "accepted, never completed", "not applied": "not applied before the end"}[verdict]
        when = f"applied at t = {self.delivered:g} s" if self.delivered is not None else f"due at t = {self.time:g} s"
        return f"{when} {self.event}({args}): {how}"


@dataclass
class Summary:
    outcomes: list[CommandOutcome]
    blocked: list[str] = field(default_factory=list)  # cotwin.twin.assembly.waits: waits for answers that cannot come
    saturated: list[tuple[str, float]] = field(default_factory=list)  # joints at their effort limit at the end, each
    # with it (cotwin.pmodel.simulator.PlatformSimulator.saturated): why a move may never complete

    def counts(self) -> dict[str, int]:
        out = {"completed": 0, "stopped": 0, "infeasible": 0, "not taken": 0, "never completed": 0, "not applied": 0}
        for o in self.outcomes:
            out[o.verdict] += 1
        return out

    def lines(self) -> list[str]:
        if not self.outcomes:
            return ["commands: none applied"]
        counts = self.counts()
        head = f"commands: {len(self.outcomes)}, " + ", ".join(f"{n} {what}" for what, n in counts.items() if n)
        return [head, *(f"  {o.describe()}" for o in self.outcomes)]

    def warnings(self) -> list[str]:
        out = [f"blocked: {b}" for b in self.blocked]
        counts = self.counts()
        if self.outcomes and not counts["completed"]:
            applied = len(self.outcomes) - counts["not applied"]  # one due after the end was never applied
            out.append(f"no command completed ({applied} applied)" if applied == len(self.outcomes) else
                       f"no command completed ({applied} of {len(self.outcomes)} applied)")
        saturation = self.saturation()
        if saturation is not None:
            out.append(saturation)
        return out

    def saturation(self) -> str | None:
        """Why commands never completed, where joints pushed at their effort limit at the end (None otherwise):
        one of `warnings`, and a cell's per robot (cotwin.twin.assembly.cell.CellOutcomes)."""
        never = self.counts()["never completed"]
        if not never or not self.saturated:
            return None
        joints = ", ".join(f"{name} ({limit:g})" for name, limit in self.saturated)
        return (f"{never} command(s) never completed, and at the end these joints pushed at their effort limit: "
                f"{joints}: too weak to reach or hold the goal against its inertia, a load or a contact (the "
                "p-model's limit effort, the URDF's <limit effort>)")

    def strict_failures(self) -> list[str]:
        """What `--strict` refuses: every command that did not complete, and blocked waits."""
        return [o.describe() for o in self.outcomes if o.verdict != "completed"] + [f"blocked: {b}" for b in self.blocked]


def event_readers(program) -> dict[str, list[tuple[int, int]]]:
    """Per input event, the machines whose cycles read it: (machine index, its place among the state ports)."""
    position = {m.index: k for k, m in enumerate(program.machines)}
    return {name: sorted({(m, position[m]) for m, _ in routes if m in position})
            for name, routes in program.input_routes.items()}


class CommandLedger(Observer):
    """Follows every command a run applies (see module doc); `outcomes` grows as the run goes."""

    def __init__(self, system: TwinSystem, units: dict[str, str] | None = None, scope=None):
        """`units`: the co-simulation's name of each of the twin's units where it differs (a robot of a cell: its
        own d-model and source units, the cell's one mapping unit); `scope`: the mapping unit's name of one of the
        twin's mapping ports (a cell's: `ROBOT.port`)."""
        program = system.models.program
        self.program = program
        self.system = system
        units = units or {}
        self._dmodel = units.get(DMODEL.name, DMODEL.name)
        self._mapping = units.get(MAPPING.name, MAPPING.name)
        self._source = units.get(system.source.name, system.source.name) if system.source is not None else None
        self._scope = scope or (lambda port: port)
        self.roles = EventRoles.of(system.spec)
        self.rest = once_per(program, "rest states", lambda: rest_states(program))  # the same for every what-if
        self.cycles = once_per(program, "cycle reads", lambda: CycleReads(program))
        self._readers = once_per(program, "event readers", lambda: event_readers(program))
        self.outcomes: list[CommandOutcome] = []
        self._states = [(program.state_port(m), m) for m in program.machines]
        self._calls = [op.name for op in program.operations]
        self._events = list(system.platform_events)

    def simulation_initialized(self, execution) -> None:
        source = execution.system.units.get(self._source) if self._source is not None else None
        self._queue = source.command_queue if source is not None else None  # cotwin.twin.assembly.commands.CommandQueue
        self._seen = self._count()
        # a clocked d-model (FMI 3.0) reads a command at its clock's first tick from the point it was applied:
        # in that point's event phase, or at a later one when the clock is slower than the step
        self._cycles = DModelCycles(execution, self._dmodel)
        # a run's first event phase (at its start, before any step) may have applied commands and ticked: the
        # d-model's first cycle, from its initial junction, read them (judged below, not passed over as old)
        first = self._seen if self._cycles.clocked and execution.steps == 0 and self._cycles.seen else 0
        self._seen -= first
        self._lag = 1 if execution.algorithm.name == "jacobi" else 0  # steps until the d-model reads a command
        period = self.system.spec.parameters.get("cycle_period")
        # a cycle_period shorter than the step runs several d-model cycles a step (cotwin.dmodel.fmu): a state
        # change then spans cycles, on paths past `exec` (CycleReads `several`)
        self._several = isinstance(period, (int, float)) and 0 < period < execution.step_size * (1 - 1e-9)
        slots = execution.algorithm.slots
        self._calls = [c for c in self._calls if (self._dmodel, c) in slots]  # read in this order
        calls = [(self._dmodel, c) for c in self._calls]
        events = [(self._mapping, self._scope(e)) for e in self._events]
        states = [(self._dmodel, port) for port, _ in self._states]
        self._calls_read, self._events_read, self._state_read = map(execution.reader, (calls, events, states))
        # what it reads in a native stretch's rows: states and calls (a change is a step it is told), events (one
        # coming is)
        self._changing = [slots[port] for port in states + calls if port in slots]
        self._coming = [(e, slots[port]) for e, port in zip(self._events, events) if port in slots]
        self._before = self._state_read()
        # the platform events of the last steps seen: those in none of them were absent when the d-model's cycle
        # before the one judged read its exec guards (a step not seen repeats the one before it)
        self._recent: deque[frozenset[str]] = deque(maxlen=3)
        self._waiting: list[tuple[int, CommandOutcome, tuple]] = []  # (steps to read, outcome, state when applied)
        self._current: CommandOutcome | None = None
        self._taken_at: float | None = None  # when the current command was taken (None: the d-model's first cycle)
        if first:
            calls = [c for c, v in zip(self._calls, self._calls_read()) if v is True]
            for outcome in self._fresh():
                self._judge(outcome, None, self._before, calls)

    def _count(self) -> int:
        return self._queue.applied_count if self._queue is not None else 0

    def step_complete(self, execution) -> None:
        t = execution.time
        states = self._state_read()
        ticked = self._cycles.ran() if self._cycles.clocked else None  # None: a cycle every step, read after _lag
        calls = [c for c, v in zip(self._calls, self._calls_read()) if v is True]
        events = [e for e, v in zip(self._events, self._events_read()) if v is True]
        self._recent.append(frozenset(events))
        for outcome in self._fresh(t + 0.5 * execution.step_size):
            self._waiting.append((self._lag, outcome, self._before))
        still, read = [], []
        for steps, outcome, before in self._waiting:
            if (steps > 0) if ticked is None else not ticked:
                still.append((steps - 1, outcome, before))
            else:
                read.append(outcome)
        for outcome in self._read_by_cycle(read) if read else ():
            self._judge(outcome, self._before, states, calls, t)
        self._waiting = still
        current = self._current
        if current is not None:
            current.operations.extend(c for c in calls if c not in current.operations)
            for e in events:
                if e not in current.events:
                    current.events.append(e)
                if current.feasible is None and self.roles.infeasible(e):
                    current.feasible, current.refused_by = False, e
                elif current.feasible is None and self.roles.feasible(e):
                    current.feasible = True
                if current.done is None and current.stopped is None and self.roles.stops(e):
                    current.stopped = (e, t)
            if current.done is None and self.resting(states):
                current.done = t
        self._before = states

    @staticmethod
    def _read_by_cycle(outcomes: list[CommandOutcome]) -> list[CommandOutcome]:
        """Of the commands one d-model cycle reads (several, applied in the steps before the tick of a clock
        slower than the step), those it can have read: an event applied again before the tick is one occurrence
        with the last one's values, so the earlier are replaced, not taken."""
        last = {o.event: o for o in outcomes}
        for o in outcomes:
            if last[o.event] is not o:
                o.replaced = last[o.event].delivered
        return [o for o in outcomes if o.replaced is None]

    def _fresh(self, before: float | None = None) -> list[CommandOutcome]:
        """The outcomes of the commands applied since the last look (those applied `before` that time, when given:
        a native stretch's command is looked at in its step), recorded."""
        if self._count() <= self._seen:
            return []
        fresh = list(self._queue.applied)[-(self._count() - self._seen):]
        if before is not None:
            fresh = [a for a in fresh if a.time < before]
        self._seen += len(fresh)
        outcomes = [CommandOutcome(a.command.due, a.command.event, dict(a.command.values), a.time,
                                   origin=a.command.origin) for a in fresh]
        self.outcomes.extend(outcomes)
        return outcomes

    def _judge(self, outcome: CommandOutcome, before: tuple | None, states: tuple, calls: list[str],
               t: float | None = None) -> None:
        """Taken or not, by the cycle that took the d-model from `before` (None: its first) to `states` at `t`."""
        if (before is None or states != before or calls) and self._may_read(outcome.event, before, states,
                                                                              self._absent()):
            outcome.accepted = True
            current = self._current
            if current is not None and current.done is None and current.stopped is None \
                    and self._taken_at != t and self._rested_between(before, states):
                current.done = t  # back at rest and off again with this command, within one cycle
            self._current, self._taken_at = outcome, t
        else:
            outcome.busy = self._names(before)

    def whole_changes(self, execution) -> tuple:
        return ()  # the steps in which what it reads changed are told to it from the rows (`repeated`)

    def repeated(self, execution, rows) -> None:
        """Steps made at once. Each in which a state or a call changed or an event came is told to it as a step,
        and each while a command applied waits to be read; each of the others would find what the step before it
        found (a command taken, done or stopped is decided at such a step), so only the events it held are
        remembered (of the last three steps, before a step told: `_absent`)."""
        told = []
        for k in rows.changed():
            row, previous = rows.rows[k].tolist(), (rows.rows[k - 1] if k else rows.before).tolist()
            if any(row[i] != previous[i] for i in self._changing) or \
                    any(row[i] and not previous[i] for _, i in self._coming):
                told.append(k)
        if self._count() > self._seen:  # commands applied among the steps (cotwin.twin.assembly.native_commands)
            times, half = rows.times, 0.5 * execution.step_size
            for a in list(self._queue.applied)[-(self._count() - self._seen):]:
                k = next((k for k, t in enumerate(times) if a.time < t + half), None)
                if k is not None:
                    told.append(k)
            told = sorted(set(told))
        if not told and not self._waiting:  # it would find what it found: only the events held are remembered
            self._recent.extend(self._held(row) for row in rows.rows[-3:])
            return
        def chosen():  # read as the rows are told: a command taken waits to be read from the next one on
            k = 0  # the first row not looked at
            for mark in [*told, len(rows)]:  # and the stretch's last step, told after
                while self._waiting and k < mark:
                    yield k
                    k += 1
                for j in range(max(k, mark - 2), mark):  # the events of the two steps before (it keeps three)
                    self._recent.append(self._held(rows.rows[j]))
                if k <= mark < len(rows):
                    yield mark
                k = max(k, mark + 1)

        for _ in rows.replay(execution, chosen()):  # it reads only the values on the connections
            self.step_complete(execution)

    def _held(self, row) -> frozenset[str]:
        """The events held in a row of a stretch."""
        row = row.tolist()
        return frozenset(e for e, i in self._coming if row[i])

    def _absent(self) -> frozenset[str]:
        """The platform events that occurred in none of the last steps: the cycle before the one judged read its
        guards without them. Nothing is known so at a run's start, of a clocked d-model (its cycle before may lie
        further back) or of several cycles a step."""
        if self._cycles.clocked or self._several or len(self._recent) < (self._recent.maxlen or 0):
            return frozenset()
        return frozenset(self._events).difference(*self._recent)

    def _may_read(self, event: str, before, after, absent: frozenset[str] = frozenset()) -> bool:
        """Whether a machine reading `event` may have read it in the cycle that took it from `before` (None: its
        first cycle) to `after` (cotwin.dmodel.waits.CycleReads): a command the d-model reads while its state changes for another reason
        (an earlier move going on) is not taken when no path of that change reads it."""
        for m, k in self._readers.get(event, ()):
            was = before[k] if before is not None and k < len(before) else None
            now = after[k] if k < len(after) else None
            known = isinstance(now, int) and (before is None or isinstance(was, int))  # else: cannot tell
            read = self.cycles.between(m, was, now, self._several, absent) if known else None
            if read is None or event in read:
                return True
        return False

    def _rested_between(self, before: tuple | None, after: tuple) -> bool:
        """Whether the d-model was at rest within the cycle from `before` to `after` though neither shows it:
        every machine rests at one end or enters its rest leaf on every way between them."""
        if before is None or len(before) != len(self._states) or len(after) != len(self._states):
            return False
        return all(was == self.rest[port] or now == self.rest[port] or
                   isinstance(was, int) and isinstance(now, int) and
                   self.cycles.passes(m.index, was, now, self.rest[port], self._several)
                   for (port, m), was, now in zip(self._states, before, after))

    def resting(self, states) -> bool:
        return all(index == self.rest[port] for (port, _), index in zip(self._states, states))

    def _names(self, states) -> str:
        if states is None:  # before the d-model's first cycle
            return "its initial junction"
        names = []
        for (_, m), index in zip(self._states, states):
            leaves = self.program.leaf_names(m)
            names.append(leaves[index] if isinstance(index, int) and 0 <= index < len(leaves) else "none")
        return ", ".join(names)

    def summary(self, blocked=(), waiting=(), saturated=()) -> Summary:
        """The outcomes so far, the commands `waiting` (not applied by the end) after them; `saturated`: the joints
        at their effort limit at the end (Summary.saturated)."""
        return Summary([*self.outcomes, *waiting], [str(b) for b in blocked], list(saturated))


def saturated_joints(endpoint) -> list[tuple[str, float]]:
    """The joints of a platform's simulator pushing at their effort limit now, each with it
    (cotwin.pmodel.simulator.PlatformSimulator.saturated; Summary.saturated): none on a platform without one
    in this process (a real robot, a replayed log: cotwin.mapping.platform.Endpoint.sim is None)."""
    return endpoint.sim.saturated() if endpoint.sim is not None else []


def not_applied(source) -> list[CommandOutcome]:
    """The commands a run's source (unit) accepted but did not apply before the end: still in its queue."""
    queue = source.command_queue if source is not None else None
    if queue is None:
        return []
    return [CommandOutcome(c.due, c.event, dict(c.values), origin=c.origin) for c in queue.waiting]
