"""`cotwin test`: a generated suite (cotwin.dmodel.testgen) run on a twin's co-simulation or its PT.

Each case runs in a fresh co-simulation of the project: the d-model FMU (FMI 2.0, or 3.0 with its cycle
a clock), the platform mapping and the platform (the project's simulated robot, or the PT through the
twin's [pt] endpoint: hardware in the loop). Its source of inputs depends on the case's answers:
- "stub": a plan of every input the case sends, commands and the platform's answers alike, drives
  the d-model; the platform's own events are recorded but not connected (the platform still moves as
  the d-model commands it);
- "platform": a driver sends the commands only, each once the d-model is in the state the case sends
  it in (and has reacted to the previous one); the platform's events reach the d-model as in the twin.

The verdict compares, cycle by cycle, what the d-model FMU did with the oracle:
1. conformance: the reference interpreter (cotwin.dmodel.interpreter) replays the inputs the FMU
   actually received; its operation calls, output events and active states must be the FMU's;
2. the case: for a stub case, what the FMU received and did must be the case's inputs and oracle, shifted
   by the master's delay (one cycle under Jacobi: the plan reaches the d-model one step after it is
   sent); for a platform case, the run must cover the items the case was made for.
The first difference is reported (cycle, what, expected, actual), with the items covered and what the
platform did (the operations it carried out, its events, collisions). The comparison reads only the
d-model FMU's ports, so it holds whatever the co-simulation's event semantics around it.
"""

from __future__ import annotations

import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution
from ...cosim.observers import Observer
from ...cosim.system import Connection, System
from ...cosim.units import Port, PythonUnit
from ...diagnostics import CotwinError
from ...dmodel.interpreter import ExecutionError, Interpreter
from ...dmodel.ports import PortLayout
from ...dmodel.runner import inputs_of, outputs_of
from ...dmodel.testgen import model_digest, replay_items
from ...dmodel.testgen_files import SuiteCase, SuiteFile, output_record, plain
from ...dmodel.testgen_graph import _Sequence
from ..assembly.outcomes import EventRoles
from ..assembly.scenario import Command, ScenarioUnit, scenario_ports
from ..assembly.system import CONTROLLER, DMODEL, MAPPING, TwinSystem


@dataclass
class Divergence:
    cycle: int
    what: str  # outputs | states | inputs | coverage | run
    expected: str
    actual: str

    def __str__(self) -> str:
        where = f"cycle {self.cycle}: " if self.cycle else ""
        return f"{where}{self.what}: expected {self.expected}, got {self.actual}"


@dataclass
class CaseResult:
    name: str
    answers: str
    divergence: Divergence | None
    cycles: int  # d-model cycles observed
    simulated: float  # s
    wall: float  # s
    covered: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)  # items of the case not covered
    platform: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.divergence is None


@dataclass
class Observed:
    """One d-model cycle as the FMU did it: the inputs it received, its outputs and states."""

    inputs: dict
    outputs: list
    states: list[str]


# ---- what the d-model FMU did, cycle by cycle ----


class DModelTrace(Observer):
    """Reads the d-model unit's ports after initialisation and every step: one Observed per cycle (an FMI 2.0
    step is one cycle; an FMI 3.0 unit's cycles are its clock's ticks, with the inputs it delivered)."""

    def __init__(self, program, unit):
        self.program = program
        self.unit = unit
        self.cycles: list[Observed] = []
        self.leaves = [program.leaf_names(m) for m in program.machines]
        self.clocked = unit.ticks is not None  # an FMI 3.0 d-model: one cycle per clock tick
        self._ticks = 0

    def _states(self, values) -> list[str]:
        out = []
        for m, names in zip(self.program.machines, self.leaves):
            k = values(self.program.state_port(m))
            out.append(names[k] if 0 <= k < len(names) else "")
        return out

    def _read(self) -> None:
        unit = self.unit
        layout = self.layout

        def value(port):
            v = cache[port]
            return float(v) if layout[port] == "Real" else v

        if self.clocked:
            if unit.ticks == self._ticks:
                return
            self._ticks = unit.ticks
            cache = {**unit.get(self.outputs), **{p: v for p, v in unit.delivered.items()}}
            cache.update({p: False for p in self.events if p not in unit.delivered})
            for p in self.values_ports:
                cache.setdefault(p, 0)
        else:
            cache = unit.get(self.ports)
        self.cycles.append(Observed(inputs_of(self.program, value), outputs_of(self.program, value),
                                    self._states(lambda p: cache[p])))

    def simulation_initialized(self, execution) -> None:
        layout = PortLayout(self.program)
        self.layout = {v.name: v.fmi_type for v in layout.variables}
        self.outputs = [v.name for v in layout.variables if v.causality == "output"]
        self.events = [ev.flag.name for ev in layout.inputs]
        self.values_ports = [v.var.name for ev in layout.inputs for v in ev.values]
        self.ports = [*self.outputs, *self.events, *self.values_ports]
        if self.clocked:
            self._read()

    def step_complete(self, execution) -> None:
        self._read()


# ---- the driver of a case whose answers are left to the platform ----


@dataclass
class _Send:
    cycle: int  # the case's cycle
    values: tuple  # (port, value)
    before: list[str]  # the states the case sends it in
    reacts: bool  # does the case's d-model change state in that cycle


class CaseDriver(PythonUnit):
    """Sends a case's commands, each once the d-model is in the state the case sends it in, at least as many
    cycles after the previous one as in the case, and after the d-model reacted to the previous one (see
    module doc). Gives up after `patience` seconds of waiting, saying for what."""

    def __init__(self, name: str, program, sends: list[_Send], ports: list[str], patience: float):
        types = scenario_ports(program)
        self.program = program
        self.state_ports = [program.state_port(m) for m in program.machines]
        self.leaves = [program.leaf_names(m) for m in program.machines]
        super().__init__(name, [Port(p, types[p], "output") for p in ports]
                         + [Port(p, "Integer", "input") for p in self.state_ports])
        self.events = {ev.name for ev in program.inputs} & set(ports)
        self.sends = sends
        self.patience = patience
        self.next = 0
        self.steps_since = 10 ** 9
        self.sent_in: list[str] | None = None
        self.waiting = 0.0
        self.stuck: str | None = None

    def _observed(self) -> list[str]:
        return [names[k] if 0 <= (k := self.values[p]) < len(names) else "" for p, names in zip(self.state_ports, self.leaves)]

    @property
    def done(self) -> bool:
        return self.next >= len(self.sends)

    def step(self, t: float, h: float) -> None:
        for ev in self.events:
            self.values[ev] = False
        self.time = t + h
        self.steps_since += 1
        if self.done or self.stuck:
            return
        send = self.sends[self.next]
        now = self._observed()
        if self.sent_in is not None and self.sends[self.next - 1].reacts and now == self.sent_in:
            ready = False  # the d-model has not yet reacted to the previous command
        else:
            self.sent_in = None if self.sent_in is not None and now != self.sent_in else self.sent_in
            gap = send.cycle - (self.sends[self.next - 1].cycle if self.next else 0)
            ready = (send.before is None or now == send.before) and self.steps_since >= gap
        if not ready:
            self.waiting += h
            if self.waiting > self.patience:
                self.stuck = (f"waited {self.patience:g} s to send {', '.join(p for p, _ in send.values if p in self.events)} "
                              f"(case cycle {send.cycle}) in state {', '.join(send.before or ['its first'])}; "
                              f"the d-model stayed in {', '.join(now)}")
            return
        for port, value in send.values:
            self.values[port] = value
        self.next += 1
        self.steps_since = 0
        self.waiting = 0.0
        self.sent_in = now


def _sends(case: SuiteCase, commands: set[str], program) -> list[_Send]:
    out, before = [], None
    for k, cycle in enumerate(case.cycles):
        sent = {n: v for n, v in cycle["inputs"].items() if n in commands}
        if sent:
            values = []
            for ev in program.inputs:
                if ev.name in sent:
                    values.append((ev.name, True))
                    for port, sc in ev.value_ports:
                        v = sent[ev.name]
                        for key in sc.path:
                            v = v[key]
                        values.append((port, v))
            out.append(_Send(cycle["cycle"], tuple(values), before, cycle["states"] != before))
        before = cycle["states"]
    return out


def _commands(case: SuiteCase, program, period: float, include) -> list[Command]:
    """The case's inputs (those `include(event)` keeps) as scenario Commands, cycle c at (c - 1) x period."""
    out = []
    for cycle in case.cycles:
        values = []
        for ev in program.inputs:
            if ev.name in cycle["inputs"] and include(ev.name):
                values.append((ev.name, True))
                for port, sc in ev.value_ports:
                    v = cycle["inputs"][ev.name]
                    for key in sc.path:
                        v = v[key]
                    values.append((port, v))
        if values:
            out.append(Command((cycle["cycle"] - 1) * period, tuple(values), f"{case.name} cycle {cycle['cycle']}"))
    return out


# ---- one case ----


class CaseRun:
    """The co-simulation of one case (see module doc)."""

    def __init__(self, system: TwinSystem, suite: SuiteFile, case: SuiteCase, fmu: Path, endpoint, algorithm: str,
                 step: float, fmi: int = 2):
        program = system.models.program
        self.system, self.suite, self.case, self.program = system, suite, case, program
        self.step_size, self.algorithm, self.fmi = step, algorithm, fmi
        commands = set(suite.commands)
        all_ports = list(scenario_ports(program))
        dmodel_inputs = set(all_ports)
        if case.answers == "stub":
            if fmi == 3:
                from ..assembly.clocked import ClockedScenario as Source
            else:
                Source = ScenarioUnit
            self.driver = None
            source = Source(CONTROLLER.name, program, _commands(case, program, step, lambda e: True), all_ports,
                            together=True)  # a cycle's inputs arrive in one step, as the oracle has them
            fed = dmodel_inputs
        else:
            ports = [p for ev in program.inputs if ev.name in commands for p in [ev.name, *(n for n, _ in ev.value_ports)]]
            self.driver = source = CaseDriver(CONTROLLER.name, program, _sends(case, commands, program), ports,
                                              patience=float(suite.data.get("settle", 10.0)))
            fed = set(ports)
        if fmi == 3:
            from ...cosim.fmi3 import FMU3Unit

            dmodel = FMU3Unit(DMODEL.name, fmu)
        else:
            from ...cosim.units import FMUUnit

            dmodel = FMUUnit(DMODEL.name, fmu)
        mapping = system.mapping_unit(endpoint)
        connections = [Connection(CONTROLLER.name, p, DMODEL.name, p) for p in source.outputs() if p in fed]
        connections += [c for c in system.connections if c.source == DMODEL.name and c.target == MAPPING.name]
        connections += [c for c in system.connections if c.source == MAPPING.name and c.target == DMODEL.name
                        and c.input not in fed]
        if self.driver is not None:
            connections += [Connection(DMODEL.name, p, CONTROLLER.name, p) for p in self.driver.state_ports]
        events = [p.name for p in mapping.event_ports]
        log = {MAPPING.name: list(dict.fromkeys([*system.log[MAPPING.name], *events])),
               DMODEL.name: [program.state_port(m) for m in program.machines]}
        parameters = dict(system.parameters)
        if fmi == 3:
            parameters[DMODEL.name] = {**parameters.get(DMODEL.name, {}), "cycle_period": float(step)}
        delayed = {MAPPING.name} if self.driver is None else {MAPPING.name, CONTROLLER.name}  # the driver reads the state
        self.cosim = System.of([source, dmodel, mapping], connections, delayed=delayed, log=log,
                               parameters=parameters)
        self.dmodel, self.mapping, self.events = dmodel, mapping, events
        self.trace = DModelTrace(program, dmodel)
        self.platform_events: dict[str, int] = {}
        self._held: dict[str, bool] = {}

    def _count_events(self, execution) -> None:
        for name in self.events:
            on = bool(execution.values.get((MAPPING.name, name), False))
            if on and not self._held.get(name):
                self.platform_events[name] = self.platform_events.get(name, 0) + 1
            self._held[name] = on

    def run(self) -> CaseResult:
        case = self.case
        started = wallclock.perf_counter()
        execution = Execution(self.cosim, make_algorithm(self.algorithm), self.step_size, 0.0, [self.trace])
        wanted = len(case.cycles) + 2  # the case, the master's delay and one more
        patience = float(self.suite.data.get("settle", 10.0))
        limit = wanted + int(round((patience * (1 + len(case.cycles))) / self.step_size)) if self.driver else wanted
        error = None
        try:
            execution.initialize()
            while len(self.trace.cycles) < limit:
                execution.step()
                self._count_events(execution)
                if self.driver is None and len(self.trace.cycles) >= wanted:
                    break
                if self.driver is not None and (self.driver.stuck or (self.driver.done and self._settled())):
                    break
        except CotwinError as err:
            error = err
        finally:
            execution.close()
        result = self.judge(error)
        result.simulated = execution.time
        result.wall = wallclock.perf_counter() - started
        return result

    def _settled(self) -> bool:
        """A platform case is over when its last command was sent and the d-model reached the case's last
        states (or stayed a while)."""
        last = self.case.cycles[-1]["states"] if self.case.cycles else None
        if not self.trace.cycles:
            return False
        return self.trace.cycles[-1].states == last and self.driver.steps_since >= 2

    # ---- the verdict ----
    def judge(self, error: CotwinError | None) -> CaseResult:
        case, program = self.case, self.program
        result = CaseResult(case.name, case.answers, None, len(self.trace.cycles), 0.0, 0.0)
        result.platform = self.platform_report()
        interp = Interpreter(program, self.system.parameters.get(DMODEL.name))
        taken: list[list] = []
        expected_cycles: list[tuple[list, list[str]]] = []
        for k, seen in enumerate(self.trace.cycles, start=1):
            interp.taken = _Sequence()
            try:
                outputs = interp.step(seen.inputs)
            except ExecutionError as err:
                result.divergence = Divergence(k, "run", "the reference interpreter to complete the cycle",
                                               err.findings[0].message)
                break
            taken.append(list(interp.taken))
            states = [self._leaf(m, interp) for m in program.machines]
            expected_cycles.append((_records(outputs), states))
            if result.divergence is None:
                if _records(outputs) != _records(seen.outputs):
                    result.divergence = Divergence(k, "outputs (conformance to the interpreter)",
                                                   _show(outputs), _show(seen.outputs))
                elif states != seen.states:
                    result.divergence = Divergence(k, "states (conformance to the interpreter)", ", ".join(states),
                                                   ", ".join(seen.states))
        result.covered = replay_items(program, self.suite.criterion, taken)
        result.missing = [i for i in case.items if i not in set(result.covered)]
        if result.divergence is None and case.answers == "stub":
            result.divergence = self._against_oracle()
        if result.divergence is None and case.answers == "platform" and self.driver.stuck:
            result.divergence = Divergence(len(self.trace.cycles), "platform", "the d-model to reach the state the "
                                           "case sends its next command in", self.driver.stuck)
        if result.divergence is None and result.missing:
            result.divergence = self._left_path() or Divergence(
                0, "coverage", f"the case's items ({len(case.items)})",
                f"not reached: {', '.join(result.missing)}{self._first_cycle_late()}")
        if error is not None:
            result.divergence = Divergence(len(self.trace.cycles), "run", "the co-simulation to complete",
                                           "; ".join(f.message for f in error.findings))
        return result

    def _first_cycle_late(self) -> str:
        """Why items of the d-model's first cycle cannot be reached under FMI 2.0 Jacobi: a source's values reach
        the d-model a step late, so its first cycle reads no input, whatever a case gives it there."""
        if self.fmi == 3 or self.algorithm != "jacobi" or not self.case.cycles or not self.case.cycles[0].get("inputs"):
            return ""
        return ("; the case gives the d-model inputs in its first cycle, which no source can under Jacobi (they reach "
                "it a step late): run the suite with --algorithm gauss-seidel or --fmi 3")

    def _left_path(self) -> Divergence | None:
        """Where a run left the case's path: the first state (repeats collapsed) that differs."""
        def collapse(seq):
            out = []
            for k, states, inputs in seq:
                if not out or out[-1][1] != states:
                    out.append((k, states, inputs))
            return out

        commands = set(self.suite.commands)

        def from_first_input(seq):  # both paths from the cycle that received the case's first command
            start = next((k for k, (_, _, inputs) in enumerate(seq) if set(inputs) & commands), len(seq))
            return seq[start:]

        designed = collapse(from_first_input([(c["cycle"], c["states"], c["inputs"]) for c in self.case.cycles]))
        seen = collapse(from_first_input([(k, s.states, plain(s.inputs)) for k, s in enumerate(self.trace.cycles, 1)]))
        for (dk, ds, di), (sk, ss, si) in zip(designed, seen):
            if ds != ss:
                return Divergence(sk, "states (the case's path)", f"{', '.join(ds)} (the case's cycle {dk}, after "
                                  f"{_inputs(di)})", f"{', '.join(ss)} after {_inputs(si)}")
        if len(seen) < len(designed):
            dk, ds, _ = designed[len(seen)]
            return Divergence(len(self.trace.cycles), "states (the case's path)",
                              f"{', '.join(ds)} (the case's cycle {dk})", "the run ended before")
        return None

    def _leaf(self, m, interp) -> str:
        k = interp.state_index(m.index)
        names = self.program.leaf_names(m)
        return names[k] if 0 <= k < len(names) else ""

    def _against_oracle(self) -> Divergence | None:
        """A stub case: the FMU's cycles are the case's, shifted by the master's delay."""
        designed = self.case.cycles
        seen = self.trace.cycles
        first = next((c["cycle"] for c in designed if c["inputs"]), None)
        got = next((k for k, s in enumerate(seen, start=1) if s.inputs), None)
        shift = 0 if first is None or got is None else got - first
        if shift < 0:
            shift = 0
        for c in designed:
            k = c["cycle"] + shift
            if k > len(seen):
                return Divergence(c["cycle"], "run", f"cycle {k} of the d-model", f"only {len(seen)} cycles ran")
            s = seen[k - 1]
            if plain(s.inputs) != c["inputs"]:
                return Divergence(c["cycle"], "inputs (the case's plan as the d-model received it)",
                                  _inputs(c["inputs"]), _inputs(plain(s.inputs)))
            if sorted(c["outputs"], key=_key) != _records(s.outputs):
                return Divergence(c["cycle"], "outputs", _show_records(c["outputs"]), _show(s.outputs))
            if c["states"] != s.states:
                return Divergence(c["cycle"], "states", ", ".join(c["states"]), ", ".join(s.states))
        return None

    def platform_report(self) -> dict:
        executed = {}
        for _, op, _ in self.mapping.executed:
            executed[op] = executed.get(op, 0) + 1
        # the project's one rule for an event that stops a move (its [outcomes] stops, else outcomes.stopping's
        # naming convention): a substring 'collision' counted noCollision and collisionFree, and missed protectiveStop
        roles = EventRoles.of(self.system.spec)
        collisions = sum(n for e, n in self.platform_events.items() if roles.stops(e))
        return {"operations": executed, "events": dict(self.platform_events), "collisions": collisions}


def _key(record: dict):
    return (record["kind"], record["name"])


def _records(outputs) -> list[dict]:
    return sorted((output_record(o) for o in outputs), key=_key)


def _show(outputs) -> str:
    return ", ".join(str(o) for o in outputs) or "no call"


def _show_records(records: list[dict]) -> str:
    return ", ".join(f"{r['name']}({', '.join(map(str, r['args']))})" for r in records) or "no call"


def _inputs(inputs: dict) -> str:
    return ", ".join(n if v is None else f"{n}({v})" for n, v in inputs.items()) or "no input"


# ---- the suite ----


@dataclass
class SuiteResult:
    suite: SuiteFile
    cases: list[CaseResult]
    target: str  # the co-simulation | the PT at ...
    criterion: str
    covered: list[str]
    reachable: int
    wall: float
    warnings: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.cases)


def check_suite(system: TwinSystem, suite: SuiteFile) -> list[str]:
    """A suite of another module is an error; one generated from another version of the module's texts is run
    (a regression test: its oracle is that version's) with a warning, returned."""
    program = system.models.program
    if suite.data.get("module") != program.module.name:
        raise CotwinError(f"{suite.folder}/suite.json: the suite was generated from module {suite.data.get('module')}, "
                          f"the project's d-model is module {program.module.name}")
    if suite.data.get("model_digest") != model_digest(program):
        return [f"{suite.folder}/suite.json: the suite was generated from another version of module "
                f"{program.module.name}: its oracle is that version's behaviour (regenerate it with cotwin testgen if "
                "the change was meant)"]
    return []


def run_suite(system: TwinSystem, suite: SuiteFile, out: str | Path, endpoint=None, target: str = "the co-simulation",
              algorithm: str | None = None, fmi: int = 2, cc: str = "cc", only: list[str] | None = None,
              progress=None) -> SuiteResult:
    """Every case of `suite` (or those named in `only`) on the project's co-simulation, against `endpoint`
    (a function making the platform endpoint for a case; default: the project's simulated platform)."""
    from ..assembly.build import dmodel_fmu, folder_lock
    from ..assembly.run import simulated_endpoint

    warnings = check_suite(system, suite)
    step = float(suite.data.get("period", system.spec.step))
    period = system.spec.parameters.get("cycle_period")
    if fmi == 2 and period and abs(step / period - 1) > 1e-9:
        raise CotwinError(f"{system.spec.path}: [cosim] parameters cycle_period {period:g} s runs several d-model cycles "
                          f"per step of {step:g} s; cotwin test compares cycle by cycle (one per step)")
    out = Path(out)
    cases = [c for c in suite.cases if only is None or c.name in only]
    unknown = sorted(set(only or ()) - {c.name for c in suite.cases})
    if unknown:
        raise CotwinError(f"{suite.folder}: no case(s) {', '.join(unknown)} (cases: {', '.join(c.name for c in suite.cases)})")
    started = wallclock.perf_counter()
    results = []
    with folder_lock(out):
        fmu = dmodel_fmu(system, out, cc, fmi=fmi)
        for k, case in enumerate(cases):
            made = endpoint() if endpoint is not None else simulated_endpoint(system)
            try:
                run = CaseRun(system, suite, case, fmu, made, algorithm or system.spec.algorithm, step, fmi)
                results.append(run.run())
            finally:
                made.close()
            if progress is not None:
                progress(k + 1, len(cases), results[-1])
    covered = list(dict.fromkeys(i for r in results for i in r.covered))
    return SuiteResult(suite, results, target, suite.criterion, covered, int(suite.data["items"]["reachable"]),
                       wallclock.perf_counter() - started, warnings)


def format_result(result: SuiteResult) -> str:
    lines = [f"warning: {w}" for w in result.warnings]
    for c in result.cases:
        verdict = "pass" if c.passed else "FAIL"
        ops = ", ".join(f"{op} x{n}" for op, n in c.platform.get("operations", {}).items()) or "none"
        events = ", ".join(f"{e} x{n}" for e, n in c.platform.get("events", {}).items()) or "none"
        lines.append(f"{verdict} {c.name} ({c.answers} answers): {c.cycles} cycles, {c.simulated:g} s simulated in "
                     f"{c.wall:.2f} s; covered {len(c.covered)} item(s)")
        lines.append(f"     platform: operations carried out {ops}; events {events}; collisions {c.platform.get('collisions', 0)}")
        if c.divergence is not None:
            lines.append(f"     first divergence: {c.divergence}")
    reachable = result.reachable
    share = 100.0 * len(result.covered) / reachable if reachable else 100.0
    passed = sum(c.passed for c in result.cases)
    lines.append(f"{passed} of {len(result.cases)} case(s) passed on {result.target}; {result.criterion} covered: "
                 f"{len(result.covered)} of {reachable} reachable ({share:.0f}%); "
                 f"{sum(c.simulated for c in result.cases):g} s simulated in {result.wall:.1f} s")
    return "\n".join(lines)


def junit_xml(result: SuiteResult) -> str:
    """The results as JUnit XML (one testsuite, a testcase per case, a failure with the first divergence)."""
    module = result.suite.data.get("module", "dmodel")
    failures = sum(not c.passed for c in result.cases)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<testsuites name="cotwin test" tests="{len(result.cases)}" failures="{failures}" errors="0" '
             f'time="{result.wall:.3f}">',
             f'  <testsuite name={quoteattr(f"{module} on {result.target}")} tests="{len(result.cases)}" '
             f'failures="{failures}" errors="0" skipped="0" time="{result.wall:.3f}">',
             "    <properties>",
             f'      <property name="criterion" value={quoteattr(result.criterion)}/>',
             f'      <property name="covered" value="{len(result.covered)}"/>',
             f'      <property name="reachable" value="{result.reachable}"/>',
             "    </properties>"]
    for c in result.cases:
        lines.append(f'    <testcase classname={quoteattr(module)} name={quoteattr(c.name)} time="{c.wall:.3f}">')
        if c.divergence is not None:
            lines.append(f'      <failure message={quoteattr(str(c.divergence))} type={quoteattr(c.divergence.what)}>'
                         f'{escape(str(c.divergence))}</failure>')
        lines.append(f"      <system-out>{escape(_case_text(c))}</system-out>")
        lines.append("    </testcase>")
    lines += ["  </testsuite>", "</testsuites>"]
    return "\n".join(lines) + "\n"


def _case_text(c: CaseResult) -> str:
    return (f"answers: {c.answers}; cycles: {c.cycles}; simulated: {c.simulated:g} s\n"
            f"covered: {', '.join(c.covered) or 'nothing'}\n"
            f"platform: {c.platform}")
