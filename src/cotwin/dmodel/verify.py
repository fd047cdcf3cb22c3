"""Exhaustive exploration of a module's state space with every input combination per cycle.

Checks the core properties RoboTool offers: timelock (deadlock) freedom, determinism, divergence
freedom, no output repeated in a cycle; and reachability of every state and transition. Breadth-first,
so each violation comes with a shortest input trace.

Event values: a value that no condition reads (it is only passed on to outputs) cannot change the
control flow, so one representative value explores all behaviours (data independence); values that
conditions read range over their domain (--domain, or a small default: 0 and 1, false and true,
every enumeration literal). A default domain is a sample: a transition that no sampled value enables
is reported with the inputs to give values for (`sampled`).

Random draws (Mathematics::random, uninterpreted functions): a run draws them from a seeded
pseudo-random sequence, whose state would make every cycle's state new and the search endless; the
verifier makes each draw a choice point instead and explores every choice (Mathematics::random takes
each of RANDOM_VALUES, or --random; an uninterpreted function's result each value of its type's
default domain, as an input's), so what it checks holds for any sequence of draws from those values.

A search stops at `max_states`, or as soon as a counter is proven to grow without bound (growth.py: the
search could never end): it is then incomplete, and reports what it did not reach as not reached,
never as a failure.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from ..diagnostics import CotwinError, Finding, Severity
from ..robosim.types import BOOL, NAT, REAL, EnumTy, RecordTy
from .growth import GrowthWatch
from .interpreter import ExecutionError, Frame, Interpreter
from .program import Program, Scalar, default_value, scalars
from .steering import condition_variables, input_event_tests


PROGRESS_CYCLES = 2_000  # cycles between two calls of verify's progress
RANDOM_VALUES = (0.0, 0.5)  # the values a real random draw takes in the search (Mathematics::random is in [0, 1))


@dataclass
class Violation:
    property: str  # timelock | determinism | divergence | repeated-output | ...
    message: str
    trace: list[dict]
    draws: list[tuple] = field(default_factory=list)  # per cycle of the trace, the random draws chosen

    def format(self) -> str:
        lines = [f"{self.property}: {self.message}", "  shortest input trace:"]
        for i, inputs in enumerate(self.trace, 1):
            drawn = self.draws[i - 1] if i - 1 < len(self.draws) else ()
            lines.append(f"    cycle {i}: {format_inputs(inputs)}"
                         + (f", random draws {', '.join(map(str, drawn))}" if drawn else ""))
        return "\n".join(lines)


def format_trace(trace: list[dict]) -> str:
    """An input sequence on one line, `[k] {inputs}` per cycle, a run of cycles with the same inputs as one
    `[i..j]`: a timeout told apart after 152 cycles reads `[1..151] {} [152] {start}`, not 152 entries."""
    shown, k = [], 0
    while k < len(trace):
        end = k
        while end + 1 < len(trace) and trace[end + 1] == trace[k]:
            end += 1
        cycles = f"{k + 1}" if end == k else f"{k + 1}..{end + 1}"
        shown.append(f"[{cycles}] {format_inputs(trace[k])}")
        k = end + 1
    return " ".join(shown)


def format_inputs(inputs: dict) -> str:
    if not inputs:
        return "{}"
    parts = []
    for name, value in inputs.items():
        if value is None:
            parts.append(name)
        elif isinstance(value, dict):
            parts.append(f"{name}({', '.join(str(v) for v in value.values())})")
        else:
            parts.append(f"{name}({value})")
    return "{" + ", ".join(parts) + "}"


@dataclass
class Report:
    states: int = 0
    cycles: int = 0
    seconds: float = 0.0
    violations: list[Violation] = field(default_factory=list)
    unreached_states: list[str] = field(default_factory=list)
    unreached_transitions: list[str] = field(default_factory=list)
    input_combinations: int = 0
    value_notes: list[str] = field(default_factory=list)
    complete: bool = True
    max_states: int = 0
    sampled: list[str] = field(default_factory=list)  # value ports explored with a default domain only
    random_values: tuple = ()  # what a real random draw took (empty: the model draws none)
    growth: str = ""  # an incomplete search: the variables that grew (growth_hint)
    unbounded: str = ""  # a search stopped early: the counter that grows without bound, where and how (growth.py)
    interrupted: bool = False  # stopped by an interrupt (Ctrl-C): what it found so far is kept, nothing verified

    @property
    def ok(self) -> bool:
        return not self.violations and not self.unreached_states and not self.unreached_transitions and self.complete


def widest_variables(program: Program, snapshots, top: int = 2) -> list[tuple[str, int]]:
    """The machines' variables with the most values among explored interpreter snapshots (at least ten, most
    first): a counter that grows without bound makes every state new, so a search that hit its limit names it."""
    values: dict[tuple[int, str], set] = {}
    for snap in snapshots:
        for m, (_, frames) in enumerate(snap[0]):
            for name, value in (Frame.frozen_variables(frames[0]) if frames else ()):
                values.setdefault((m, name), set()).add(value)
    machines = {m.index: m.machine.name for m in program.machines}
    ranked = sorted(((f"{machines.get(m, m)}.{name}", len(seen)) for (m, name), seen in values.items()),
                    key=lambda item: -item[1])
    return [(name, n) for name, n in ranked[:top] if n >= 10]


def uncapped_clocks(program: Program) -> list[str]:
    """The clocks (M.T) a condition compares with other than a constant (`since(T) > limit`, a variable): their counts
    are never capped (program.count_caps), so while one is not reset every cycle is a new state."""
    return [f"{m.machine.name}.{clock}" for m in program.machines for clock, cap in m.clock_caps.items() if cap is None]


def growth_hint(program: Program, snapshots) -> str:
    """What to say of a search that hit its state limit: the variables taking the most values, if any grows, and
    the clocks whose counts are never capped (a higher limit was no help for either)."""
    wide = widest_variables(program, snapshots)
    clocks = uncapped_clocks(program)
    hint = ""
    if wide:
        named = ", ".join(f"{name} took {n} values" for name, n in wide)
        hint = (f"; {named} in the states explored: a variable that grows without bound makes every state new, so "
                "bound it in the model (e.g. a modulus) or compare it with a constant")
    if clocks:
        hint += (f"; clock {', '.join(clocks)} is compared with other than a constant, so its count is never capped "
                 "and, while it is not reset, every cycle is a new state: the search may never end (compare it with "
                 "a constant to verify the rest)")
    return hint


def _bound_variables(program: Program, event: str) -> set[str]:
    return {node.bind for node in input_event_tests(program, event) if node.bind}


def _value_tested(program: Program, event: str) -> bool:
    """Whether a guard compares the event's value itself (`$sort.1`): that value steers control, no variable bound."""
    return any(node.value is not None for node in input_event_tests(program, event))


def default_domain(ty) -> list:
    """The values a scalar of type `ty` takes without --domain: every Boolean and enumeration literal (its index),
    a number only 0 and 1 (a sample); an input's, and an uninterpreted function's result (Draws.value)."""
    if ty == BOOL:
        return [False, True]
    if isinstance(ty, EnumTy):
        return list(range(len(ty.decl.literals)))
    if ty == REAL:
        return [0.0, 1.0]
    return [0, 1]


INTEGER_PORT = (-2 ** 31, 2 ** 31 - 1)  # what an FMI Integer port (an int, a nat, an enumeration) carries


def port_domain(port: str, sc: Scalar, values: list) -> list:
    """`values` given for value port `port` (--domain) as its type holds them: a Boolean 0 or 1 (false, true), an
    enumeration a literal's index, an int or a nat an integer its FMI Integer port carries (a nat not negative), a
    real any finite number. A value no run can send (a Boolean 2, a fourth literal of three, an int 0.5) would be
    explored as if it could: a CotwinError names the first."""
    ty = sc.ty
    if ty == REAL:
        wanted, low, high, make = "a finite number", -sys.float_info.max, sys.float_info.max, None
    elif ty == BOOL:
        wanted, low, high, make = "0 (false) or 1 (true)", 0, 1, bool
    elif isinstance(ty, EnumTy):
        wanted = "a literal's index: " + ", ".join(f"{k} ({lit.name})" for k, lit in enumerate(ty.decl.literals))
        low, high, make = 0, len(ty.decl.literals) - 1, int
    else:
        low, high, make = 0 if ty == NAT else INTEGER_PORT[0], INTEGER_PORT[1], int
        wanted = f"an integer from {low} to {high} (what its FMI Integer port carries)"
    out = []
    for v in values:
        number = isinstance(v, int) or (isinstance(v, float) and math.isfinite(v))  # an int past any float: no isfinite
        if not number or not low <= v <= high or (make is not None and not float(v).is_integer()):
            shown = repr(v) if len(repr(v)) <= 40 else repr(v)[:37] + "..."
            raise CotwinError(f"{port}: {shown} is not a value of its type {ty}: give {wanted}")
        out.append(v if make is None else make(v))
    return out


def _build_value(ty, values: dict[tuple[str, ...], object], resolver):
    if isinstance(ty, RecordTy):
        out = {}
        for sc in scalars(ty, resolver):
            cursor = out
            for key in sc.path[:-1]:
                cursor = cursor.setdefault(key, {})
            cursor[sc.path[-1]] = values[sc.path]
        return out
    return values[()]


def _whole_domain(sc: Scalar) -> bool:
    """Does the default domain hold every value of the type (Booleans, enumerations)?"""
    return sc.ty == BOOL or isinstance(sc.ty, EnumTy)


def event_values(program: Program, domains: dict[str, list],
                 sampled: list[str] | None = None) -> tuple[dict[str, list], list[str]]:
    """The values each typed input event takes during exploration, and notes saying why; the value
    ports whose default domain is only a sample of their type are added to `sampled`."""
    relevant = condition_variables(program, failures=True)  # a value that can make a cycle fail is not one of many
    out: dict[str, list] = {}
    notes = []
    sampled = [] if sampled is None else sampled
    for ev in program.inputs:
        if ev.ty is None:
            continue
        ports = ev.value_ports
        explicit = {port: port_domain(port, sc, domains[port]) for port, sc in ports if port in domains}
        steers = bool(_bound_variables(program, ev.name) & relevant) or _value_tested(program, ev.name)
        if ev.unportable:  # a sequence, a set, a vector: no scalars to range over
            if steers:
                raise CotwinError([Finding(ev.loc or program.module.loc, Severity.ERROR,
                                           f"{ev.unportable}, and a condition reads its value: the search has no "
                                           "values of its type to try")])
            out[ev.name] = [default_value(ev.ty, program.resolver)]
            notes.append(f"{ev.name}: its value is read by no condition and can make no cycle fail (data independent): 1 representative "
                         f"value ({out[ev.name][0]}) explores every behaviour")
            continue
        if steers:
            sampled.extend(port for port, sc in ports if port not in explicit and not _whole_domain(sc))
        if not explicit and not steers:
            combos = [{sc.path: default_domain(sc.ty)[0] for _, sc in ports}]
            notes.append(f"{ev.name}: its value is read by no condition and can make no cycle fail (data independent): "
                         f"1 representative value explores every behaviour")
        else:
            axes = [explicit.get(port, default_domain(sc.ty)) for port, sc in ports]
            combos = [{sc.path: v for (_, sc), v in zip(ports, choice)} for choice in itertools.product(*axes)]
            notes.append(f"{ev.name}: {len(combos)} value(s) from its domain")
        out[ev.name] = [_build_value(ev.ty, c, program.resolver) for c in combos]
    return out, notes


MAX_COMBINATIONS = 1_000_000  # input combinations tried in each state: more is neither held nor ever expanded


def input_combinations(program: Program, values: dict[str, list]):
    """Every set of input events with every choice of their values (one cycle's inputs). More than MAX_COMBINATIONS
    is refused before any is made, saying how many each event brings (a domain of 100 000 values on a
    record command with ten input events made 204 million, and MemoryError after 20 s)."""
    names = [ev.name for ev in program.inputs]
    ways = {n: 1 + len(values.get(n, [None])) for n in names}  # absent, or present with each of its values
    total = math.prod(ways.values())
    if total > MAX_COMBINATIONS:
        counts = ", ".join(f"{n} {k - 1}" for n, k in sorted(ways.items(), key=lambda item: -item[1]) if k > 2)
        raise CotwinError([Finding(program.module.loc, Severity.ERROR,  # the module whose inputs they are
                                   f"{total:,} input combinations in each state, more than {MAX_COMBINATIONS:,} "
                                   f"({len(names)} input events; values: {counts}): give fewer values with --domain")])
    for mask in range(1 << len(names)):
        present = [n for i, n in enumerate(names) if mask >> i & 1]
        axes = [values.get(n, [None]) for n in present]
        for choice in itertools.product(*axes):
            yield dict(zip(present, choice))


class Draws:
    """The verifier's random source: every draw is a choice point (see the module doc). `prefix` holds
    the choices of the draws so far (an index into each draw's values; draws beyond it take the first
    value) and `sizes` records how many values each draw had, so that the search can try the others.
    Its `state` never changes, so a snapshot no longer grows with the draws."""

    state = 0

    def __init__(self, reals: tuple[float, ...]):
        self.reals = tuple(reals)
        self.prefix: tuple[int, ...] = ()
        self.sizes: list[int] = []
        self.drawn: list = []

    def _choose(self, values):
        k = len(self.sizes)
        self.sizes.append(len(values))
        value = values[self.prefix[k]] if k < len(self.prefix) else values[0]
        self.drawn.append(value)
        return value

    def real(self) -> float:
        return self._choose(self.reals)

    def value(self, ty):
        """An uninterpreted function's result: each value of its type's default domain."""
        return self._choose(default_domain(ty))

    def start(self, prefix: tuple[int, ...]) -> None:
        self.prefix, self.sizes, self.drawn = prefix, [], []

    def alternatives(self) -> list[tuple[int, ...]]:
        """The prefixes of the choices not yet tried below the current one (each full choice once)."""
        out = []
        for j in range(len(self.prefix), len(self.sizes)):
            for k in range(1, self.sizes[j]):
                out.append(self.prefix + (0,) * (j - len(self.prefix)) + (k,))
        return out


def verify(program: Program, domains: dict[str, list] | None = None, max_states: int = 100_000,
           parameters: dict | None = None, random_values: tuple[float, ...] = RANDOM_VALUES,
           progress: Callable[[int, int, int], None] | None = None) -> Report:
    """Explore breadth first (see the module doc); `progress(states, cycles, frontier)` is called about
    every PROGRESS_CYCLES cycles."""
    started = time.perf_counter()
    report = Report(max_states=max_states)
    values, report.value_notes = event_values(program, domains or {}, report.sampled)
    given, machines = parameters or {}, {m.index: m.machine.name for m in program.machines}
    for par in program.parameters:  # constants without a value: what holds below holds for the value taken
        if par.machine >= 0:
            report.value_notes.append(
                f"constant {machines[par.machine]}.{par.name} has no value in the model: the "
                f"search takes {given.get(par.port, par.default)!r}, {'as given' if par.port in given else 'its default'} "
                f"(FMU parameter {par.port}); what holds below holds for that value")
    combos = list(input_combinations(program, values))
    report.input_combinations = len(combos)
    interp = Interpreter(program, parameters)
    draws = Draws(random_values)
    interp.random = draws
    interp.taken = set()  # every (machine, edge) taken anywhere in the exploration
    root = interp.snapshot()
    parent: dict = {root: None}
    depth = {root: 0}
    queue = deque([root])
    found: dict[tuple[str, str], Violation] = {}
    drew = False
    watch = GrowthWatch(program, interp)

    def trace_to(snap, last):
        path = [last]
        while parent[snap] is not None:
            snap, step = parent[snap]
            path.append(step)
        path.reverse()
        return Violation("", "", [inputs for inputs, _ in path], [d for _, d in path])

    def violation(kind: str, message: str, snap, inputs) -> Violation:
        v = trace_to(snap, (inputs, tuple(draws.drawn)))
        v.property, v.message = kind, message
        if not drew:
            v.draws = []
        return v

    try:
        while queue:
            snap = queue.popleft()
            for inputs in combos:
                choices = [()]
                while choices:
                    prefix = choices.pop()
                    interp.restore(snap)
                    interp.cycle = depth[snap]
                    interp.warnings = []
                    draws.start(prefix)
                    report.cycles += 1
                    if progress is not None and report.cycles % PROGRESS_CYCLES == 0:
                        progress(len(parent), report.cycles, len(queue))
                    try:
                        interp.step(inputs)
                        failed = None
                    except ExecutionError as err:
                        failed = err
                    choices.extend(draws.alternatives())
                    drew = drew or bool(draws.sizes)
                    # a choice made before the cycle failed is nondeterminism all the same (it was lost with the cycle)
                    for w in interp.warnings:
                        key = ("determinism", w.site)
                        if key not in found:  # breadth first: the first one found has a shortest trace
                            found[key] = violation("determinism", str(w), snap, inputs)
                    if failed is not None:
                        key = (failed.kind, failed.site or failed.findings[0].message)
                        if key not in found:
                            found[key] = violation(failed.kind, failed.findings[0].message, snap, inputs)
                        continue
                    nxt = interp.snapshot()
                    if nxt not in parent:
                        if len(parent) >= max_states:
                            report.complete = False
                            continue
                        parent[nxt] = (snap, (inputs, tuple(draws.drawn)))
                        depth[nxt] = depth[snap] + 1
                        queue.append(nxt)
                        grows = watch.add(nxt, parent, depth)
                        if grows is not None:  # the search cannot end: stop now, not at max_states
                            report.complete = False
                            report.unbounded = grows.message(format_trace)
                            queue.clear()
                            choices.clear()
                            break
                if report.unbounded:
                    break
    except KeyboardInterrupt:  # Ctrl-C mid-search: the violations found so far are reported, not lost
        report.complete = False
        report.interrupted = True
    report.states = len(parent)
    if not report.complete and not report.unbounded and not report.interrupted:
        report.growth = growth_hint(program, parent)
    report.random_values = draws.reals if drew else ()
    report.violations = sorted(found.values(), key=lambda v: (len(v.trace), v.property))
    for m in program.machines:
        # a state is reached when a taken transition enters it, even if the cycle moves on from it
        entered = {e.target.index for e in m.graph.edges if (m.index, e.index) in interp.taken}
        for leaf in m.graph.leaves:
            if leaf.index not in entered:
                report.unreached_states.append(f"{m.machine.name}: state {'.'.join(leaf.path)}")
        for e in m.graph.edges:
            if (m.index, e.index) not in interp.taken:
                report.unreached_transitions.append(f"{m.machine.name}: transition {e.transition.name}")
    report.seconds = time.perf_counter() - started
    return report


def format_report(program: Program, report: Report) -> str:
    lines = [f"module {program.module.name}: {report.states} states, {report.cycles} cycles explored "
             f"({report.input_combinations} input combinations per state) in {report.seconds:.2f} s"]
    lines.extend(f"  note: {n}" for n in report.value_notes)
    if report.random_values:
        lines.append(f"  note: every random draw is a choice: random() takes each of "
                     f"{', '.join(f'{v:g}' for v in report.random_values)} (--random), an uninterpreted function "
                     "each value of its type's default domain")
    sampled = (f"{', '.join(report.sampled)} took only sample values (0 and 1): give the values that matter "
               f"with --domain {report.sampled[0]}=V1,V2,...") if report.sampled else ""
    if sampled and report.complete:  # else the INCOMPLETE line says it; "ok" alone claimed every value
        lines.append(f"  NOT VERIFIED for every value: {sampled}; what holds below holds for those values only")
    if report.interrupted:
        lines.append(f"  INTERRUPTED: the search was stopped by an interrupt after {report.states} states: what it "
                     "found so far holds, nothing else is verified" + (f" ({sampled})" if sampled else ""))
    elif report.unbounded:
        lines.append(f"  INCOMPLETE: the search stopped after {report.states} states: {report.unbounded}"
                     + (f" ({sampled})" if sampled else ""))
    elif not report.complete:
        lines.append(f"  INCOMPLETE: the search stopped at its limit of {report.max_states} states: what it "
                     "found holds, what it did not reach is not judged (raise --max-states"
                     + (f"; {sampled}" if sampled else "") + report.growth + ")")
    scope = "in the states explored" if report.unbounded or report.interrupted else "within the limit"
    props = [("timelock", "deadlock/timelock freedom"), ("determinism", "determinism"),
             ("divergence", "divergence freedom"), ("repeated-output", "at most one of each output per cycle")]
    for key, title in props:
        bad = [v for v in report.violations if v.property == key]
        if bad:
            lines.append(f"FAIL {title}: {len(bad)} violation(s)")
        else:
            lines.append(f"ok   {title}" if report.complete else f"?    {title}: no violation {scope}")
    others = [v for v in report.violations if v.property not in dict(props)]
    for v in others:
        lines.append(f"FAIL {v.property}")
    for what, title, missing in (("state", "every state reachable", report.unreached_states),
                                 ("transition", "every transition can be taken", report.unreached_transitions)):
        verb = "reached" if what == "state" else "taken"
        if not missing:
            lines.append(f"ok   {title}")
        elif report.complete:
            lines.append(f"FAIL {title}: never {verb} " + ", ".join(missing) + (f" ({sampled})" if sampled else ""))
        else:
            lines.append(f"?    {title}: not {verb} {scope}: " + ", ".join(missing))
    for v in report.violations:
        lines.append("")
        lines.append(v.format())
    return "\n".join(lines)
