"""The blocked-wait watch: says when the d-model waits for an answer that cannot come.

An observer of a twin's execution. A machine *waits* in a leaf state whose every way out is guarded by
platform events (cotwin.dmodel.waits). When it has stayed there for `patience` steps calling no
operation, the watch asks the mapping about each event it waits for: a command may still be sent (no
warning); an observation may still be sampled; an *answer* (cotwin.mapping.runtime) cannot come when a
condition of it on what operations assign is false, or it holds still and was delivered already, since
the machine calls no operation while it waits. When every answer it waits for cannot come and nothing
else it waits for is a command or an answer that may come, the wait is blocked: a warning names the
machine, the state, since when, the events and why each cannot come (once per wait).

This is a run-time judgement, sound for what the d-model and the mapping do by themselves: it does not
predict the platform (an observation such as `collision` is named as what could still end the wait).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from ...cosim.observers import Observer
from ...dmodel.waits import waits
from ...memo import once_per
from .clocked import DModelCycles
from .system import DMODEL, MAPPING, TwinSystem

log = logging.getLogger("cotwin.twin")


@dataclass
class Blocked:
    machine: str
    state: str
    since: float  # when the machine entered the state (s)
    noticed: float  # when the watch said so (s)
    events: list[str]
    reasons: dict[str, str]  # answer -> why it cannot come
    others: list[str]  # observations that could still end the wait

    def __str__(self) -> str:
        why = "; ".join(f"{e} cannot come ({r})" for e, r in self.reasons.items())
        rest = f"; only {' or '.join(self.others)}, an observation of the platform, could end the wait" \
            if self.others else ": it waits forever"
        return (f"the d-model's machine {self.machine} waits in state {self.state} since t = {self.since:g} s for "
                f"{' or '.join(self.events)}: {why}{rest}")


class WaitWatch(Observer):
    """See module doc; `found` lists the blocked waits seen, `prefix` marks the warning (e.g. "DT: ")."""

    def __init__(self, system: TwinSystem, patience: int = 3, prefix: str = ""):
        program = system.models.program
        self.program = program
        self.waits = once_per(program, "waits", lambda: waits(program))  # the same for every what-if of it
        self.commands = set(system.command_events)
        self.patience = patience
        self.prefix = prefix
        self.found: list[Blocked] = []
        self._ports = [(DMODEL.name, program.state_port(m)) for m in program.machines]
        self._calls = [(DMODEL.name, op.name) for op in program.operations]

    def simulation_initialized(self, execution) -> None:
        unit = execution.system.units.get(MAPPING.name)
        self.mapping = unit.mapping if unit is not None else None  # an in-process mapping unit: it can be asked
        slots = execution.algorithm.slots
        self._states = execution.reader(self._ports)
        self._called = execution.reader([c for c in self._calls if c in slots])
        self._call_slots = [slots[c] for c in self._calls if c in slots]
        self._judged_leaves = [[leaf for (k, leaf) in self.waits if k == m and self._judged(m, leaf)]
                               for m in range(len(self._ports))]
        self._since = [(None, execution.time, 0)] * len(self._ports)  # (leaf, entered at, steps idle)
        self._cycles = DModelCycles(execution)  # a clocked d-model changes and reads at its ticks: idle counted in them

    def step_complete(self, execution) -> None:
        if self.mapping is None:
            return
        if not self._cycles.ran():
            return  # a clocked d-model with no cycle since the last step: nothing changed, nothing was read
        calling = any(v is True for v in self._called())
        for m, leaf in enumerate(self._states()):
            previous, entered, idle = self._since[m]
            if leaf != previous:
                self._since[m] = (leaf, execution.time, 0)
                continue
            idle = 0 if calling else idle + 1
            self._since[m] = (leaf, entered, idle)
            if idle == self.patience:
                self._judge(m, leaf, entered, execution.time)

    def quiet_for(self, execution) -> int | None:
        """A machine whose state is not known yet (a run's first steps) is judged `patience` steps from now: that
        step must be made as the observer sees it (it asks the mapping, whose state is the step's)."""
        if self.mapping is None:
            return None
        waiting = [self.patience - idle for leaf, _, idle in self._since if leaf is None and idle < self.patience]
        return min(waiting) if waiting else None

    def checkpoints(self, execution) -> list:
        """A machine not yet judged in its state is judged `patience` idle steps after it entered it, if it is
        still there: that step must be made as the observer sees it. A state with nothing to judge (no wait, one
        a command ends, or one the judgement lets pass whenever it falls among the stretch's steps: `_passes`)
        has no such step."""
        if self.mapping is None:
            return []
        return [(self._ports[m], leaf, self.patience - idle) for m, (leaf, _, idle) in enumerate(self._since)
                if leaf is not None and idle < self.patience and self._judged(m, leaf) and not self._passes(m, leaf)]

    def _passes(self, m: int, leaf, possible: dict[str, bool] | None = None) -> bool:
        """Whether the judgement of machine m waiting in `leaf` finds it not blocked at any step of a stretch
        starting now: an answer it waits for may come and stays so until it comes (Mapping.stays_possible),
        and the stretch ends the step after it comes (the judgement there and then finds that it may come: it
        was delivered a step before). No operation runs within a stretch (one called stops it before the next
        step: NativePart.ready). The judgement then changes nothing, so its step need not be seen whole.
        `possible`: the answers asked so far, kept across the waits of one question."""
        possible = {} if possible is None else possible
        for event in self.waits[(m, leaf)].events:
            if event not in possible:
                possible[event] = self.mapping.stays_possible(event)
            if possible[event]:
                return True
        return False

    def _judged(self, m: int, leaf) -> bool:
        """Whether machine m waiting in `leaf` would be judged (see _judge: a wait no command ends)."""
        wait = self.waits.get((m, leaf)) if isinstance(leaf, int) else None
        return wait is not None and not wait.events & self.commands

    def whole_changes(self, execution) -> list:
        """Its machines' states: a change of them is a step it sees whole (the mapping it asks is then as that step
        left it), where `whole_values` says; the operation calls it counts from the rows."""
        return list(self._ports)

    def whole_values(self, execution) -> dict:
        """A machine entering a wait it would judge is a step it sees whole, unless the judgement lets the wait
        pass at any step of a stretch starting now (`_passes`): then the judgement can only pass wherever it
        falls among the stretch's steps, and the wait is counted from them (`repeated`)."""
        if self.mapping is None:
            return {}
        possible: dict[str, bool] = {}  # each answer asked once
        return {port: [leaf for leaf in self._judged_leaves[m] if not self._passes(m, leaf, possible)]
                for m, port in enumerate(self._ports)}

    def repeated(self, execution, rows) -> None:
        """Steps made at once: each machine's state, since when, and its idle steps counted from them. No
        judgement that could find a wait blocked falls among them: a wait entered among them is one the
        judgement lets pass (whole_values), and one entered before them ends the stretch at its judgement
        (checkpoints)."""
        if self.mapping is None:
            return
        slots = execution.algorithm.slots
        ports = [slots[port] for port in self._ports]
        times = rows.times
        changes = rows.changes(ports + self._call_slots)
        if changes:  # a state entered or a call made among them: counted from each change to the next
            calls, calling = self._call_slots, False
            last = -1  # the row whose values hold until the next change
            for k in [*sorted({0, *changes}), len(rows)]:
                held = k - last - 1  # rows repeating row `last`
                self._since = [(leaf, entered, 0 if calling else idle + held) for leaf, entered, idle in self._since]
                if k == len(rows):
                    break
                values = rows.row(k, ports + calls)
                calling = any(v is True for v in values[len(ports):])
                self._since = [(leaf, times[k], 0) if leaf != previous else (leaf, entered, 0 if calling else idle + 1)
                               for leaf, (previous, entered, idle) in zip(values, self._since)]
                last = k
            return
        first = rows.row(0, ports)  # the stretch's states (a run's first rows: seen here)
        self._since = [(leaf, entered, idle + len(rows)) if leaf == previous else (leaf, times[0], len(rows) - 1)
                       for leaf, (previous, entered, idle) in zip(first, self._since)]

    def progress(self) -> tuple:
        """What it has seen so far (each machine's state since when, idle how long; the waits found), to go on
        from in a run restored to this step (a start shared by a sweep's plans: cotwin.twin.services.whatif)."""
        return list(self._since), list(self.found)

    def resume(self, progress: tuple) -> None:
        since, found = progress
        self._since, self.found = list(since), list(found)

    def _judge(self, m: int, leaf, entered: float, now: float) -> None:
        if not self._judged(m, leaf):
            return
        wait = self.waits[(m, leaf)]
        reasons, others = {}, []
        for event in sorted(wait.events):
            if event not in self.mapping.events:
                reasons[event] = "nothing produces it (neither a command nor an event of the mapping)"
            elif event not in self.mapping.answers:
                never = self.mapping.never(event)
                if never:
                    reasons[event] = never
                else:
                    others.append(event)
            else:
                why = self.mapping.cannot_come(event, 0 if self._cycles.clocked else 2)
                if why is None:
                    return  # an answer that may still come
                reasons[event] = why
        if not reasons or not any(e in self.mapping.answers for e in reasons) and others:
            return
        blocked = Blocked(wait.machine, wait.state, entered, now, sorted(wait.events), reasons, others)
        self.found.append(blocked)
        log.warning("%st = %g s: %s", self.prefix, now, blocked)
