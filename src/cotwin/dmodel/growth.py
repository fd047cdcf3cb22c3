"""Early proof that a search cannot end: a counter that grows without bound, found after a few rounds of one cycle.

A machine variable is a *counter* when every assignment to it, in every machine and operation, adds a non-zero
constant to it (`x = x + 1`, `x = x - 2`) or sets it to a constant (`x = 0`), at least one adds; no binding `$e?x`
sets it; no condition reads it, directly or through what it flows into (steering.py); and its value is read nowhere
but in its own steps and as plain arithmetic (`+ - *`) sent out (`$report!x`, `$op(x + 1)`), where it cannot fail
before an FMI Integer port overflows, after 2^31 cycles at the least. A counter's value never changes what the
machines do.

If the search adds a state S' equal to one of its ancestors S in everything but counters (control, every other
variable, clocks, events in flight), the inputs and random draws that led from S to S' lead from S' round the same
cycle again (no condition reads a counter), to S''. The round's effect on a counter is either a constant sum of steps
(no reset on the way) or a constant (a reset): replaying it from S' tells which. If S'' is S' grown by exactly what S'
grew from S, the round resets nothing, and S, S', S'', ... are all different: the state space is infinite and the
search cannot end. A bounded model never has such a round (its counters would grow for ever along it), so the watch
never stops a search that could end: `x = (x + 1) % 5` is no counter (no constant step), nor is one a guard reads
(`x < 10` steers). The verifier stops at the REPETITIONS-th round (each one a proof; the rounds show the growth), and
says which variable grows, where it steps, the cycle's control states and its inputs. A model that reads `cycle` or
`sinceEntry` (whose values the states do not all hold) is not watched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..diagnostics import Location
from ..robosim import syntax as s
from ..robosim.types import INT, NAT, REAL
from .interpreter import ExecutionError, Interpreter
from .program import OperationInstance, Program
from .steering import bodies, body_statements, condition_variables, read

REPETITIONS = 3  # rounds of one cycle, each adding to a counter, before the search stops
MAX_PERIOD = 1_000  # the longest cycle looked for (in cycles between two states alike but for counters)
CANDIDATES = 4  # the most recent states alike but for counters that are tried as an ancestor
NEAR = 16  # the nearest ancestors tried too


@dataclass
class Increment:
    machine: str
    text: str  # `count = count + 1`
    loc: Location


@dataclass
class Growth:
    """A counter proven to grow without bound: where it grows, along which cycle, with the values it took."""

    variables: list[str]  # Machine.variable
    increments: list[Increment]
    values: dict[str, list]  # Machine.variable -> its value at each round
    period: int  # cycles per round
    control: list[str]  # Machine: state, at the start of a round
    round_inputs: list[dict]  # the inputs of one round
    trace: list[dict]  # from the start to the last round

    def message(self, format_trace) -> str:
        grown = ", ".join(f"{name} took {', '.join(_show(v) for v in values)}" for name, values in self.values.items())
        where = "; ".join(f"{inc.text} at {inc.loc}" for inc in self.increments)
        return (f"{' and '.join(self.variables)} grow{'s' if len(self.variables) == 1 else ''} without bound: no "
                f"condition reads {'it' if len(self.variables) == 1 else 'them'} and only constant steps change "
                f"{'it' if len(self.variables) == 1 else 'them'} ({where}), so every round of the cycle through "
                f"{', '.join(self.control)} ({self.period} cycle{'s' if self.period != 1 else ''}, inputs "
                f"{format_trace(self.round_inputs)}) adds the same and makes a new state ({grown}; input trace "
                f"{format_trace(self.trace)}): the search cannot end. Bound it in the model (e.g. a modulus, or a "
                "guard that stops it) to verify the rest")


def _show(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _constant(e: s.Expr, constants: dict):
    """The value of a numeric constant expression (a literal, its negation, a named constant), else None."""
    negate = 1
    if isinstance(e, s.Unary) and e.op == "-":
        negate, e = -1, e.operand
    if isinstance(e, s.Literal):
        value = e.value
    elif isinstance(e, s.Name) and len(e.name.parts) == 1 and e.name.last in constants:
        value = constants[e.name.last]
    else:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        return None
    return negate * value


def _counting(st: s.Assign, constants: dict) -> tuple[str, bool] | None:
    """(x, True) for an increment `x = x + c`, `x = c + x` or `x = x - c` with c a non-zero constant; (x, False)
    for a reset `x = c`; None for any other assignment."""
    if not isinstance(st.target, s.Name) or len(st.target.name.parts) != 1:
        return None
    name, value = st.target.name.last, st.value
    if _constant(value, constants) is not None:
        return name, False
    if not isinstance(value, s.Binary):
        return None

    def is_x(e):
        return isinstance(e, s.Name) and e.name.parts == (name,)
    if value.op == "+":
        other = value.right if is_x(value.left) else value.left if is_x(value.right) else None
    elif value.op == "-" and is_x(value.left):
        other = value.right
    else:
        other = None
    step = _constant(other, constants) if other is not None else None
    return (name, True) if step else None


_PLAIN = (s.Name, s.Literal)


def _plain_arithmetic(e: s.Expr) -> bool:
    """Names, literals, `+ - *` and negation: what cannot fail for any value but by overflowing."""
    return all(isinstance(n, _PLAIN) or (isinstance(n, s.Binary) and n.op in "+-*")
               or (isinstance(n, s.Unary) and n.op == "-") for n in s.walk(e))


def _reads_time(program: Program) -> bool:
    """Does the model read `cycle` or `sinceEntry`, whose values the explored states do not all hold?"""
    for m in program.machines:
        for body in bodies(m):
            exprs = [t.condition for t in body.graph.transitions if t.condition is not None]
            exprs += [e for st in body_statements(body) for e in s.statement_expressions(st) if e is not None]
            exprs += [init for _, _, init in body.variables if init is not None]
            if any(isinstance(n, (s.CycleExpr, s.SinceEntryExpr)) for e in exprs for n in s.walk(e)):
                return True
    return False


def counters(program: Program) -> dict[str, list[Increment]]:
    """The counters of the module (see the module doc), each with its increments."""
    if _reads_time(program):
        return {}
    steering = condition_variables(program)
    steps: dict[str, list[tuple[bool, Increment]]] = {}  # (an increment, not a reset?)
    spoiled: set[str] = set()
    for m in program.machines:
        for body in bodies(m):
            if isinstance(body, OperationInstance):
                spoiled |= set(body.types)  # an operation's own names: not the machine's counter
            constants = {**m.constants, **body.constants}
            for _, _, init in body.variables:
                if init is not None:
                    spoiled |= read(init)
            for t in body.graph.transitions:
                for node in s.walk(t.condition) if t.condition is not None else ():
                    if isinstance(node, s.EventTest) and node.bind:
                        spoiled.add(node.bind)
            for st in body_statements(body):
                if isinstance(st, s.Assign):
                    counted = _counting(st, constants)
                    if counted is not None:
                        name, increment = counted
                        text = f"{name} = {_source(st.value)}"
                        steps.setdefault(name, []).append((increment, Increment(m.machine.name, text, st.loc)))
                        continue
                    root = s.root_name(st.target)
                    if root is not None:
                        spoiled.add(root.name.last)
                    spoiled |= read(st.target) | read(st.value)
                elif isinstance(st, (s.Send, s.PlatformCall)) or \
                        (isinstance(st, s.CallStmt) and st.operation.last not in body.calls):
                    spoiled |= {name for e in s.statement_expressions(st) if e is not None and not _plain_arithmetic(e)
                                for name in read(e)}
                else:
                    spoiled |= {name for e in s.statement_expressions(st) if e is not None for name in read(e)}
    found = {}
    for name, incs in steps.items():
        if name in spoiled or name in steering or not any(increment for increment, _ in incs):
            continue
        holders = [m for m in program.machines if any(n == name for n, _, _ in m.variables)]
        if holders and all(m.types.get(name) in (INT, NAT, REAL) for m in holders):
            found[name] = [inc for increment, inc in incs if increment]
    return found


def _source(e: s.Expr) -> str:
    if isinstance(e, s.Binary):
        return f"{_source(e.left)} {e.op} {_source(e.right)}"
    if isinstance(e, s.Unary):
        return f"-{_source(e.operand)}"
    if isinstance(e, s.Name):
        return str(e.name.last)
    if isinstance(e, s.Literal):
        return str(e.value)
    return "..."


def _where(machine, frames: tuple) -> str:
    """Where a machine is in a state (its frames as Frame.freeze wrote them): its active node, or the node it is
    entering when the last cycle ended inside a transition."""
    if not frames:
        return "not started"
    _, active, tasks = frames[0][:3]
    if active >= 0:
        return ".".join(machine.graph.nodes[active].path)
    node = next((task[1] for task in tasks if task[0] in ("enter", "settle", "wait")), None)
    return f"entering {'.'.join(machine.graph.nodes[node].path)}" if node is not None else "not started"


def _frame_with(data: tuple, variables: tuple) -> tuple:
    """A frame as Frame.freeze wrote it, with other variables."""
    return (*data[:3], variables, *data[4:])


class _Replayed:
    """The random source of a replay: the values the search drew on the way, in order."""

    state = 0

    def __init__(self, drawn: tuple):
        self.drawn = list(drawn)

    def real(self):
        return self.drawn.pop(0)

    def value(self, ty):
        return self.drawn.pop(0)


def _counts(snap, machine: int) -> dict:
    """The machine's own variables in a state, by name."""
    frames = snap[0][machine][1]
    return dict(frames[0][3]) if frames and frames[0][0] == -1 else {}


class GrowthWatch:
    """Watches the states a breadth-first search adds for a counter growing round a cycle (see the module doc)."""

    def __init__(self, program: Program, interp: Interpreter):
        self.program = program
        self.interp = interp
        self.counters = counters(program)
        self.enabled = bool(self.counters)
        self.seen: dict[int, list] = {}  # hash of a state's key -> the states with that key, oldest first
        self.digests: dict = {}  # state -> the hash of its key
        self.rounds: dict = {}  # state -> (the ancestor alike but for counters, rounds so far)

    def key(self, snap) -> tuple:
        """The state with every counter's value blanked."""
        machines, *rest = snap
        out = []
        for started, frames in machines:
            if frames and frames[0][0] == -1:
                variables = tuple((k, None if k in self.counters else v) for k, v in frames[0][3])
                frames = (_frame_with(frames[0], variables), *frames[1:])
            out.append((started, frames))
        return (tuple(out), *rest)

    def add(self, snap, parent: dict, depth: dict) -> Growth | None:
        """Note a state just added (its parent and depth known); a Growth once a counter has grown REPETITIONS
        rounds of one cycle."""
        if not self.enabled:
            return None
        key = self.key(snap)
        digest = self.digests[snap] = hash(key)
        same = self.seen.setdefault(digest, [])
        for earlier in self.candidates(snap, digest, same, parent):
            period = depth[snap] - depth[earlier]
            if not 0 < period <= MAX_PERIOD or self.key(earlier) != key:
                continue
            steps, cursor = [], snap
            while depth[cursor] > depth[earlier]:
                cursor, step = parent[cursor]
                steps.append(step)
            if cursor != earlier:
                continue
            steps.reverse()
            again = self.replay(snap, depth[snap], steps)
            if again is None or not self.grows_alike(earlier, snap, again):
                continue  # a reset on the way, or the round went elsewhere: no proof
            rounds = self.rounds.get(earlier, (None, 0))[1] + 1
            self.rounds[snap] = (earlier, rounds)
            if rounds >= REPETITIONS:
                return self.growth(snap, parent, depth)
            break
        same.append(snap)
        return None

    def candidates(self, snap, digest: int, same: list, parent: dict):
        """The states that may be an ancestor alike but for counters: the nearest ancestors' (a short cycle), then
        the latest states alike (a longer one; siblings alike are tried at no cost)."""
        tried, cursor = set(), snap
        for _ in range(NEAR):
            step = parent[cursor]
            if step is None:
                break
            cursor = step[0]
            if self.digests.get(cursor) == digest:
                tried.add(cursor)
                yield cursor
        for earlier in reversed(same[-CANDIDATES:]):
            if earlier not in tried:
                yield earlier

    def replay(self, snap, cycle: int, steps: list):
        """The state after the round's inputs and draws from `snap`, or None if the round cannot be repeated."""
        interp, saved = self.interp, self.interp.random
        try:
            interp.restore(snap)
            interp.cycle = cycle
            for inputs, drawn in steps:
                interp.random = _Replayed(drawn)
                interp.warnings = []
                interp.step(inputs)
                if interp.random.drawn:
                    return None
            return interp.snapshot()
        except (ExecutionError, IndexError):
            return None
        finally:
            interp.random = saved

    def grows_alike(self, first, second, third) -> bool:
        """Are three states alike but for counters, each grown from the one before by the same amount? Then the
        round adds a constant (it resets nothing, or the second and third would be equal) and repeats for ever."""
        if self.key(third) != self.key(second):
            return False
        for m in range(len(self.program.machines)):
            a, b, c = _counts(first, m), _counts(second, m), _counts(third, m)
            for name in self.counters:
                if name in b and not math.isclose(c[name] - b[name], b[name] - a[name], rel_tol=1e-9, abs_tol=0):
                    return False
        return True

    def growth(self, snap, parent: dict, depth: dict) -> Growth:
        chain = [snap]
        while chain[-1] in self.rounds:
            chain.append(self.rounds[chain[-1]][0])
        chain.reverse()
        machines = self.program.machines
        values: dict[str, list] = {}
        for m in machines:
            series = [_counts(data, m.index) for data in chain]
            for name in self.counters:
                if name in series[0] and any(row.get(name) != series[0][name] for row in series):
                    values[f"{m.machine.name}.{name}"] = [row.get(name) for row in series]
        grown = {tuple(name.split(".", 1)) for name in values}
        control = [f"{m.machine.name}: {_where(m, chain[-1][0][m.index][1])}" for m in machines]
        trace = []
        cursor = snap
        while parent[cursor] is not None:
            cursor, (inputs, _) = parent[cursor]
            trace.append(inputs)
        trace.reverse()
        period = depth[chain[-1]] - depth[chain[-2]]
        return Growth(list(values), [inc for name in sorted({n for _, n in grown})
                                     for inc in self.counters[name] if (inc.machine, name) in grown],
                      values, period, control, trace[-period:], trace)
