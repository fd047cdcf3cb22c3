"""Mutation analysis of a generated suite: mutants of a d-model made automatically, run against the suite.

Mutants are made on the model's text, from its parse tree, one change each (Offutt's operators, as
RoboStar's mutation work uses them on RoboChart):
- guard-negated: a transition's condition C becomes `not (C)`;
- conjunct-dropped: one operand of a condition's top-level `/\\` or `\\/` is dropped;
- connective-swapped: a condition's top-level `/\\` becomes `\\/`, or the reverse;
- not-dropped: a condition's top-level `not` is dropped;
- event-swapped: the first `$e` of a condition tests another input event;
- target-swapped: a transition goes to another node of its container;
- exec-dropped: an `exec` transition no longer ends the cycle;
- action-dropped: an entry, during or exit action, or a transition's action, becomes `skip`;
- constant-changed: a numeric constant's value is changed.
A mutant that no longer checks or builds is stillborn and left out.

A mutant is killed when a case of the suite, replayed with the inputs its oracle records, makes it do
something else than the oracle says (another operation call or argument, output event or state), or
makes it fail (a timelock, ...). A survivor is explained by exploring the original and the mutant
side by side (every input combination per cycle, the verifier's value domains): either no input
sequence tells them apart (an equivalent mutant: no test can kill it), or the shortest one that does
is given (the criterion did not ask for it: a stronger criterion, e.g. transition pairs, would).
"""

from __future__ import annotations

import tempfile
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from ..diagnostics import CotwinError
from ..robosim.parser import lark_parser, notation_of
from .interpreter import ExecutionError, Interpreter
from .program import Program, build_program
from .testgen_files import SuiteFile, output_record
from .verify import event_values, format_trace, input_combinations


@dataclass
class Mutant:
    number: int
    operator: str
    where: str  # path:line:column
    change: str  # what was changed, in words
    path: Path  # the mutated file
    text: str  # its text

    @property
    def name(self) -> str:
        return f"M{self.number:02d}"


@dataclass
class Outcome:
    mutant: Mutant
    status: str  # killed | survived | stillborn
    by: str = ""  # killed: the case, cycle and difference; stillborn: why
    equivalent: bool | None = None  # survivors: proved equivalent (True) or told apart (False)
    explanation: str = ""


def _line_col(text: str, pos: int) -> tuple[int, int]:
    line = text.count("\n", 0, pos) + 1
    return line, pos - (text.rfind("\n", 0, pos) + 1) + 1


def _span(node) -> tuple[int, int]:
    if hasattr(node, "meta"):
        return node.meta.start_pos, node.meta.end_pos
    return node.start_pos, node.end_pos


def _tokens(tree) -> list:
    return [t for t in tree.scan_values(lambda v: hasattr(v, "type"))]


def make_mutants(path: str | Path, events: list[str]) -> list[Mutant]:
    """Every mutant of one d-model file (see module doc), in source order; `events` are the module's input
    events (for event-swapped)."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    tree = lark_parser(notation_of(path) or "rst").parse(text)
    edits: list[tuple[str, int, int, str, str]] = []  # (operator, start, end, replacement, change)

    def add(operator, node_or_span, replacement, change):
        start, end = node_or_span if isinstance(node_or_span, tuple) else _span(node_or_span)
        edits.append((operator, start, end, replacement, change))

    for machine in tree.find_data("stm"):
        containers = [machine, *machine.find_data("state")]
        for container in containers:
            nodes = [c for c in container.children if hasattr(c, "data") and c.data in ("state", "junction", "final")]
            names = [str(n.children[0]) for n in nodes]
            for tr in (c for c in container.children if hasattr(c, "data") and c.data == "transition"):
                name = str(tr.children[0])
                target = tr.children[2]
                others = [n for n in names if n != str(target)]
                if others:
                    add("target-swapped", target, others[0], f"transition {name} goes to {others[0]}, not {target}")
                for part in tr.children[3:]:
                    if not hasattr(part, "data"):
                        continue
                    if part.data == "exec_flag":
                        add("exec-dropped", part, "", f"transition {name} no longer ends the cycle (exec dropped)")
                    elif part.data == "condition":
                        _condition_mutants(add, text, name, part.children[0], events)
                    elif part.data == "action":
                        add("action-dropped", part, "", f"transition {name} loses its action")
        for kind in ("entry_action", "during_action", "exit_action"):
            for act in machine.find_data(kind):
                stmt = act.children[0]
                add("action-dropped", stmt, "skip", f"{kind.split('_')[0]} action {text[slice(*_span(stmt))][:50]} "
                    "becomes skip")
    for const in tree.find_data("var_list"):
        source = text[slice(*_span(const))]
        if not source.lstrip().startswith("const"):
            continue
        for lit in list(const.find_data("real_lit")) + list(const.find_data("int_lit")):
            token = lit.children[0]
            value = float(token) if lit.data == "real_lit" else int(token)
            changed = repr(round(value * 1.5, 6)) if lit.data == "real_lit" and value else \
                ("1.0" if lit.data == "real_lit" else str(value + 1))
            add("constant-changed", token, changed, f"constant value {token} becomes {changed}")
    out, seen = [], {text}
    for operator, start, end, replacement, change in sorted(edits, key=lambda e: (e[1], e[0])):
        mutated = text[:start] + replacement + text[end:]
        if mutated in seen:
            continue
        seen.add(mutated)
        line, col = _line_col(text, start)
        out.append(Mutant(len(out) + 1, operator, f"{path}:{line}:{col}", change, path, mutated))
    return out


def _condition_mutants(add, text: str, transition: str, expr, events: list[str]) -> None:
    source = text[slice(*_span(expr))]
    add("guard-negated", expr, f"not ({source})", f"transition {transition}: condition negated")
    kind = getattr(expr, "data", None)
    if kind == "not_expr":
        inner = expr.children[0]
        add("not-dropped", expr, text[slice(*_span(inner))], f"transition {transition}: the condition's not dropped")
    if kind == "binary":
        left, op, right = expr.children
        if op.type in ("AND", "OR"):
            swap = "\\/" if op.type == "AND" else "/\\"
            add("connective-swapped", op, swap, f"transition {transition}: {op} becomes {swap}")
            add("conjunct-dropped", expr, text[slice(*_span(left))], f"transition {transition}: operand "
                f"{text[slice(*_span(right))][:40]} dropped")
            add("conjunct-dropped", expr, text[slice(*_span(right))], f"transition {transition}: operand "
                f"{text[slice(*_span(left))][:40]} dropped")
    for dollar in expr.find_data("dollar_expr"):
        name = dollar.children[0]
        token = _tokens(name)[-1] if hasattr(name, "data") else name
        others = [e for e in events if e != str(token)]
        if others:
            add("event-swapped", token, others[0], f"transition {transition}: ${token} becomes ${others[0]}")
        break


# ---- running the suite on a mutant ----


def mutant_program(mutant: Mutant, model_files: list[Path], module: str | None) -> Program:
    """The mutant built with the other model files unchanged; CotwinError when it does not check or build."""
    from ..robosim.check import load_checked

    with tempfile.TemporaryDirectory(prefix="cotwin-mutant-") as tmp:
        copy = Path(tmp) / mutant.path.name
        copy.write_text(mutant.text, encoding="utf-8")
        others = [p for p in model_files if p.resolve() != mutant.path.resolve()]
        return build_program(load_checked([copy, *others]), module)


def _leaves(program: Program, interp: Interpreter) -> list[str]:
    out = []
    for m in program.machines:
        names = program.leaf_names(m)
        k = interp.state_index(m.index)
        out.append(names[k] if 0 <= k < len(names) else "")
    return out


def run_case(program: Program, cycles: list[dict], parameters: dict | None = None) -> str | None:
    """The first difference between a program replaying a case's recorded inputs and the case's oracle
    ("cycle N: what: expected ..., got ..."), or None."""
    interp = Interpreter(program, parameters)
    for c in cycles:
        try:
            outputs = interp.step(dict(c["inputs"]))
        except ExecutionError as err:
            return f"cycle {c['cycle']}: the mutant fails: {err.findings[0].message}"
        got = sorted((output_record(o) for o in outputs), key=lambda r: (r["kind"], r["name"]))
        want = sorted(c["outputs"], key=lambda r: (r["kind"], r["name"]))
        if got != want:
            show = (lambda rs: ", ".join(f"{r['name']}({', '.join(map(str, r['args']))})" for r in rs) or "no call")
            return f"cycle {c['cycle']}: outputs: expected {show(want)}, got {show(got)}"
        states = _leaves(program, interp)
        if states != c["states"]:
            return f"cycle {c['cycle']}: states: expected {', '.join(c['states'])}, got {', '.join(states)}"
    return None


def run_case_fmu(program: Program, cycles: list[dict], fmu: Path, fmu_driver) -> str | None:
    """As run_case, through the mutant's FMU (built by the caller) with a stub platform; `fmu_driver(program,
    fmu)` drives it (cotwin.cosim.driver.FMUDriver: the co-simulation layer, above this one)."""
    driver = fmu_driver(program, fmu)
    try:
        for c in cycles:
            outputs = driver.step(dict(c["inputs"]))
            got = sorted((output_record(o) for o in outputs), key=lambda r: (r["kind"], r["name"]))
            want = sorted(c["outputs"], key=lambda r: (r["kind"], r["name"]))
            if got != want:
                return f"cycle {c['cycle']}: outputs differ (FMU)"
            states = [program.leaf_names(m)[driver.state(m.index)] if driver.state(m.index) >= 0 else ""
                      for m in program.machines]
            if states != c["states"]:
                return f"cycle {c['cycle']}: states: expected {', '.join(c['states'])}, got {', '.join(states)} (FMU)"
    except CotwinError as err:
        return f"the mutant's FMU fails: {err.findings[0].message}"
    finally:
        driver.close()
    return None


def _recording(interp: Interpreter) -> set:
    """The platform input events `interp` tests (`$e`) from now on, gathered in the set returned (cleared by the
    caller): a cycle's outcome depends on the inputs only through these."""
    reads: set = set()
    platform = {}
    for name, routes in interp.program.input_routes.items():
        for machine, event in routes:
            platform.setdefault((machine, event), []).append(name)
    for ev in interp.evaluators:
        def dollar(e, ev=ev, test=ev.dollar):
            reads.update(platform.get((ev.m.index, e.event.last), ()))
            return test(e)
        ev.dollar = dollar
    return reads


def tell_apart(original: Program, mutant: Program, domains: dict | None = None, max_pairs: int = 100_000,
               memo: dict | None = None):
    """The shortest input trace after which the mutant does something else than the original (outputs or
    states), as (trace, what); (None, pairs explored) when none exists (equivalent); (None, None) when the
    exploration stopped at max_pairs before deciding. `memo` keeps the original's cycles between calls.

    An input combination agreeing, on every event both programs tested in an earlier combination's cycle,
    with that combination gives the same cycle (the programs are deterministic): it is skipped, which
    leaves a handful of combinations per state where 2^events would be tried."""
    values, _ = event_values(original, domains or {})
    combos = sorted(input_combinations(original, values), key=len)
    a, b = Interpreter(original), Interpreter(mutant)
    reads_a, reads_b = _recording(a), _recording(b)
    memo = {} if memo is None else memo
    root = (a.snapshot(), b.snapshot())
    parent = {root: None}
    queue = deque([(root, 0)])
    while queue:
        (sa, sb), depth = queue.popleft()
        tried: list[tuple[tuple, tuple]] = []  # (events tested, their presence and values)
        for k, inputs in enumerate(combos):
            if any(tuple((n, n in inputs, inputs.get(n)) for n in names) == seen for names, seen in tried):
                continue
            reads_a.clear()
            reads_b.clear()
            key = (sa, depth, k)
            if key not in memo:
                a.restore(sa)
                a.cycle = depth
                try:
                    out = a.step(dict(inputs))
                    memo[key] = (out, a.snapshot(), [s.active for s in a.states], _leaves(original, a), set(reads_a))
                except ExecutionError:
                    memo[key] = None  # the original fails there too: not a behaviour a test can ask for
            if memo[key] is None:
                continue
            oa, next_a, active_a, leaves_a, tested = memo[key]
            b.restore(sb)
            b.cycle = depth
            what = None
            try:
                ob = b.step(dict(inputs))
            except ExecutionError as err:
                what = f"the mutant fails: {err.findings[0].message}"
                ob = None
            if what is None:
                if oa != ob and sorted(map(str, oa)) != sorted(map(str, ob)):
                    what = "other outputs"
                elif active_a != [s.active for s in b.states] and leaves_a != _leaves(mutant, b):
                    what = f"state {', '.join(_leaves(mutant, b))} instead of {', '.join(leaves_a)}"
            if what is not None:
                trace = [inputs]
                node = (sa, sb)
                while parent[node] is not None:
                    node, step = parent[node]
                    trace.append(step)
                return list(reversed(trace)), what
            names = tuple(sorted(tested | reads_b))
            tried.append((names, tuple((n, n in inputs, inputs.get(n)) for n in names)))
            nxt = (next_a, b.snapshot())
            if nxt not in parent:
                if len(parent) >= max_pairs:
                    return None, None
                parent[nxt] = ((sa, sb), inputs)
                queue.append((nxt, depth + 1))
    return None, len(parent)


@dataclass
class MutationReport:
    outcomes: list[Outcome] = field(default_factory=list)

    def of(self, status: str) -> list[Outcome]:
        return [o for o in self.outcomes if o.status == status]

    @property
    def valid(self) -> int:
        return len(self.outcomes) - len(self.of("stillborn"))

    @property
    def equivalent(self) -> int:
        return sum(1 for o in self.of("survived") if o.equivalent)

    @property
    def kill_rate(self) -> float:
        return len(self.of("killed")) / self.valid if self.valid else 1.0

    @property
    def kill_rate_non_equivalent(self) -> float:
        killable = self.valid - self.equivalent
        return len(self.of("killed")) / killable if killable else 1.0


def analyse(original: Program, suite: SuiteFile, mutants: list[Mutant], model_files: list[Path],
            module: str | None = None, domains: dict | None = None, fmu_builder=None,
            fmu_driver=None) -> MutationReport:
    """Run the suite on every mutant and explain the survivors (see module doc). `fmu_builder(program,
    path)`, when given, runs each case through the mutant's FMU, driven by `fmu_driver(program, fmu)`,
    instead of the interpreter."""
    if fmu_builder is not None and fmu_driver is None:
        raise ValueError("analyse: an fmu_builder needs an fmu_driver (cotwin.cosim.driver.FMUDriver)")
    report = MutationReport()
    memo: dict = {}  # the original's cycles, shared by every survivor's side-by-side exploration
    for mutant in mutants:
        try:
            program = mutant_program(mutant, model_files, module)
        except CotwinError as err:
            report.outcomes.append(Outcome(mutant, "stillborn", err.findings[0].message))
            continue
        outcome = Outcome(mutant, "survived")
        fmu_dir = tempfile.TemporaryDirectory(prefix="cotwin-mutant-fmu-") if fmu_builder else None
        try:
            fmu = fmu_builder(program, Path(fmu_dir.name) / "mutant.fmu") if fmu_builder else None
            for case in suite.cases:
                why = run_case_fmu(program, case.cycles, fmu, fmu_driver) if fmu else run_case(program, case.cycles)
                if why is not None:
                    outcome = Outcome(mutant, "killed", f"{case.name} {why}")
                    break
        except CotwinError as err:
            outcome = Outcome(mutant, "stillborn", err.findings[0].message)
        finally:
            if fmu_dir is not None:
                fmu_dir.cleanup()
        if outcome.status == "survived":
            trace, what = tell_apart(original, program, domains, memo=memo)
            if trace is None and what is None:
                outcome.explanation = "undecided: the side-by-side exploration reached its limit"
            elif trace is None:
                outcome.equivalent = True
                outcome.explanation = (f"equivalent: no input sequence tells it apart from the original ({what} state "
                                       "pairs explored, every input combination per cycle): no test can kill it")
            else:
                outcome.equivalent = False
                shown = format_trace(trace)
                outcome.explanation = (f"told apart after {len(trace)} cycle(s) ({what}): {shown}; no case of the "
                                       f"{suite.criterion} suite holds that sequence")
        report.outcomes.append(outcome)
    return report


def format_report(report: MutationReport, criterion: str) -> str:
    lines = []
    for o in report.outcomes:
        m = o.mutant
        if o.status == "killed":
            lines.append(f"killed    {m.name} {m.operator:19s} {m.where}: {m.change}; by {o.by}")
        elif o.status == "stillborn":
            lines.append(f"stillborn {m.name} {m.operator:19s} {m.where}: {m.change}; {o.by}")
        else:
            lines.append(f"SURVIVED  {m.name} {m.operator:19s} {m.where}: {m.change}; {o.explanation}")
    killed = len(report.of("killed"))
    lines.append(f"{len(report.outcomes)} mutants ({report.valid} valid, {len(report.of('stillborn'))} stillborn): "
                 f"{killed} killed by the {criterion} suite: kill rate {100 * report.kill_rate:.0f}% "
                 f"({100 * report.kill_rate_non_equivalent:.0f}% of the {report.valid - report.equivalent} "
                 f"non-equivalent); {len(report.of('survived'))} survived, {report.equivalent} of them equivalent")
    return "\n".join(lines)
