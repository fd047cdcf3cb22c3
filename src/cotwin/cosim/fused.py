"""The fused loop: many communication steps of an execution in one call of a function generated for its
system, without the master's per-step bookkeeping (issue 23).

`Execution.step` and `Algorithm.do_step` are written for any system: each step they walk lists of bound
setters, units and getters, unpack slot lists with zip, and call every observer in a loop. For a given
system all of that is known once it is set up, so the fused loop spells one step of *this* system as
straight-line Python source (each unit's setter, step and getter by position, the slots as literal
indices, the observers by name), compiles it once with `compile()`, and runs it `n` times in one call.
It moves exactly the values the algorithm moves, in the same order (Jacobi: every input set from the
previous step's outputs, then every unit steps, then every output is read; Gauss-Seidel: unit by unit in
dependency order, delayed units' outputs from the start of the step), and keeps the execution's `steps`
and `time` as `Execution.step` keeps them (observers read them), so a run gives the same values, byte for
byte in its CSV, as the step-by-step master (tests/test_fused.py).

Applicable when the algorithm is cotwin's Jacobi or Gauss-Seidel and no unit has clocks (an FMI 3.0 event
phase runs between steps): `applicable` says why not otherwise. The source is deterministic; it is kept
in `FusedLoop.source` for inspection.
"""

from __future__ import annotations

from typing import Callable

from .. import memo
from .algorithm import GaussSeidel, Jacobi


def applicable(execution) -> str | None:
    """None when the fused loop can run this (initialised) execution, else why not."""
    algorithm = execution.algorithm
    if type(algorithm) not in (Jacobi, GaussSeidel):
        return f"its algorithm ({type(algorithm).__name__}) is not cotwin's Jacobi or Gauss-Seidel"
    if algorithm.events:
        return "a unit has clocks (an event phase runs between steps)"
    return None


class FusedLoop:
    """`run(n)`: n communication steps of an initialised execution (see the module doc)."""

    def __init__(self, execution):
        why = applicable(execution)
        if why is not None:
            raise ValueError(f"the fused loop cannot run this execution: {why}")
        self.execution = execution
        self.source, names = _source(execution)
        namespace: dict[str, object] = {"__builtins__": __builtins__, **names}
        exec(memo.code(self.source, "<cotwin fused loop>"), namespace)  # noqa: S102 - generated above
        self._run: Callable[[int, Callable | None], int] = namespace["run"]
        self._data, self._observers = execution.algorithm.data, list(execution.observers)

    def run(self, n: int, until: Callable[[object], bool] | None = None) -> int:
        """Up to n steps, the steps done returned: fewer if one fails (then the execution's steps and time are
        those of the last one done) or when `until(execution)`, asked after each step's observers, is true."""
        return self._run(n, until) if n > 0 else 0

    def current(self) -> bool:
        """Whether this loop still fits its execution (the algorithm's slots and the observers it was made for)."""
        execution = self.execution
        return self._data is execution.algorithm.data and self._observers == execution.observers


def _source(execution) -> tuple[str, dict[str, object]]:
    algorithm = execution.algorithm
    names: dict[str, object] = {"EX": execution, "DATA": algorithm.data}
    body: list[str] = []

    def bind(prefix: str, value) -> str:
        name = f"{prefix}{len(names)}"
        names[name] = value
        return name

    def write(k: int) -> None:
        entry = algorithm.writes[k]
        if entry is not None:
            setter, pick = entry
            body.append(f"{bind('_set', setter)}({bind('_pick', pick)}(DATA))")

    def step(k: int) -> None:
        body.append(f"{bind('_step', algorithm.units[k].step)}(t, H)")

    def read(k: int) -> None:
        entry = algorithm.reads[k]
        if entry is not None:
            getter, slots = entry
            targets = ", ".join(f"DATA[{i}]" for i in slots)
            body.append(f"{targets}{',' if len(slots) == 1 else ''} = {bind('_get', getter)}()")

    count = len(algorithm.units)
    if isinstance(algorithm, GaussSeidel):
        for source, shadow in algorithm.copies:
            body.append(f"DATA[{shadow}] = DATA[{source}]")
        for k in range(count):
            write(k)
            step(k)
            read(k)
    else:
        for k in range(count):
            write(k)
        for k in range(count):
            step(k)
        for k in range(count):
            read(k)
    observers = [bind("_seen", o.step_complete) for o in execution.observers]
    lines = ["def run(n, until):",
             "    ex = EX",
             "    for k in range(1, n + 1):",
             "        origin, done = ex._origin",
             "        steps = ex.steps",
             "        t = origin + (steps - done) * H",
             *(f"        {line}" for line in body),
             "        steps += 1",
             "        ex.steps = steps",
             "        ex.time = origin + (steps - done) * H",
             *(f"        {o}(ex)" for o in observers),
             "        if until is not None and until(ex):",
             "            return k",
             "    return n"]
    names["H"] = execution.step_size
    return "\n".join(lines) + "\n", names
