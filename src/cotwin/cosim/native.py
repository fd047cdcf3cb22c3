"""The native loop: stretches of communication steps made in C, every unit's step included (issue 23).

The fused loop (cotwin.cosim.fused) still makes each step in Python. Most steps of a twin change nothing
but the platform's continuous readings: no command is due, no operation is called, no event comes or
goes. The native loop makes those steps in one C function generated for the system: each unit gives its
step as C (`Unit.native_part`, a `NativePart`: the d-model FMU's doStep on its port arrays, the mapping's
physics, mirrors and input events, a command source that has nothing due), composed in the algorithm's
order (Jacobi: inputs from the previous step's outputs, every unit steps, every output read; Gauss-Seidel:
unit by unit, its delayed outputs copied at the step's start), the slots kept as doubles.

A stretch (a *segment*) ends after the first step in which a value other than a continuous one (a unit's
`continuous` outputs, e.g. the mapping's q0..qd5) changed that something must see on a whole step: a unit
whose C does not read it step by step (the mapping's operation calls: Python runs the operation), or an
observer that says so (`Observer.whole_changes`; one that does not say takes none inside a stretch's rows).
It also ends after a step in which a unit asked for it (`END_AFTER`: answers came together, a watched
contact) or after the step following one in which a unit asked for that (`END_NEXT`: an answer came, and the
d-model's reply to it is a step later), or when a unit says it cannot make the next step natively (a command
due, an answer waiting): the fused loop then makes the next step in Python. A unit may also pause a step
before doing anything of it (`PAUSE`, Gauss-Seidel: an operation called within it), which Python then
finishes. So every discrete change a Python object must see is a step it sees whole, and the steps made
natively are the others. Observers hear of a segment's steps at once: all but the last through
`Observer.repeated` (rows of the slots), the last through `step_complete`, as always; an observer that
defines no `repeated` keeps the run out of the native loop.

The C source is a function of the system's structure alone (addresses are passed at each call), built once
per machine and cached (cotwin.cbuild). A run gives the same values, byte for byte in its CSV, as the fused
and the step-by-step loops (tests/test_native.py). Where it does not apply (no C compiler, a unit without a
native step, an observer that must see every step, a stop condition asked after every step) the fused loop
runs alone and `why_not` says why.
"""

from __future__ import annotations

import ctypes
import hashlib
from functools import partial
from operator import is_, itemgetter
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from ..cbuild import compile_library, compiler
from ..interrupts import signals_held
from .algorithm import UNSET, GaussSeidel, Jacobi
from .observers import Observer, hears_repeats

QUIET_AFTER = 1  # Python steps after a segment ended on a change, before the next may start
MAX_SEGMENT = 2000  # steps of one segment at most: its rows' memory bounded, Ctrl-C heard between segments
KINDS = {"Real": "r", "Integer": "i", "Boolean": "b"}  # a port's FMI type -> its kind in the rows


@dataclass
class NativePart:
    """A unit's step in C, for the native loop.

    `step` is C statements run once per step: they read the step's start time `t` and size `H` and the
    unit's inputs `IN(slot)` (Jacobi: the step before's outputs; Gauss-Seidel: this step's), write the
    unit's outputs into the next slots `N[slot]` (the ports named in `writes`; the others keep their
    values), and use `PP[i]` (pointers) and `DD[i]` (doubles) given in `pointers` and `doubles`. `FAIL(code)`:
    the step failed (not counted; `failed(code, t)` raises the error the step in Python raises). `PAUSE()`:
    before anything of the step is done, leave it to Python from this unit on (Gauss-Seidel). `END_AFTER()`:
    end the segment after this step; `END_NEXT()`: after the next one. `decls` holds file-scope C (static functions, prefixed) the step calls.
    `quiet(n)`: how many of the next n steps the unit can make natively now (0: none). `begin()`: refresh
    `pointers`/`doubles` before a segment. `end(first, made, rows, doubles)`: bring the Python object up to
    date after it made `made` steps natively from step index `first` (rows: the slots after each complete
    step; doubles: its `DD` as the steps left them). `continuous`: outputs whose change does not end a
    segment. `takes`: inputs whose changes the C reads step by step (a change of another input it is fed ends
    the segment after its step, so that Python sees it). `ready`: a C condition (over `IN` and `DD`, Jacobi)
    asked at each step's start, before any unit's step: false, the segment ends before the step. `prepare()`:
    Python's share of the segment's first step, done before it runs (the mapping runs the operations called);
    False: the step is then made in Python (which must not do that share again). `sets_inputs`: the C writes the unit's inputs itself
    (its Python setter is not called after).
    `refusal()`: why `quiet` last said 0, in a few words. `include_dirs`: where the headers `decls` includes are.
    """

    step: str
    decls: str = ""
    pointers: list = field(default_factory=list)
    doubles: list = field(default_factory=list)
    quiet: Callable[[int], int] = lambda n: n
    begin: Callable[[], None] = lambda: None
    end: Callable[[int, int, np.ndarray, np.ndarray], None] = lambda first, made, rows, doubles: None
    failed: Callable[[int, float], None] = lambda code, t: None
    continuous: tuple[str, ...] = ()
    writes: frozenset[str] = frozenset()
    takes: frozenset[str] = frozenset()
    ready: str = ""
    prepare: Callable[[], bool] = lambda: True
    sets_inputs: bool = False
    refusal: Callable[[], str] = lambda: "it was not quiet"  # why `quiet` last said 0
    include_dirs: tuple[str, ...] = ()


def feeds(execution, unit) -> list[tuple[str, int]]:
    """The unit's connected inputs and the slot each is set from (Gauss-Seidel: a delayed unit's copy)."""
    algorithm = execution.algorithm
    k = algorithm.units.index(unit)
    return [(name, algorithm._source_slot(key)) for name, key in algorithm.feeds[k]]


def outputs(execution, unit) -> dict[str, int]:
    """The unit's observed ports (its outputs the master reads) and their slots."""
    algorithm = execution.algorithm
    k = algorithm.units.index(unit)
    return {name: algorithm.slots[(unit.name, name)] for name in algorithm.watched[k]}


def why_not(execution) -> str | None:
    """None when the native loop may run this (initialised) execution, else why not (the units may still
    say why they cannot: NativeLoop)."""
    if type(execution.algorithm) not in (Jacobi, GaussSeidel):
        return f"its algorithm ({type(execution.algorithm).__name__}) is not cotwin's Jacobi or Gauss-Seidel"
    if execution.algorithm.events:
        return "a unit has clocks"
    if compiler() is None:
        return "no C compiler (cc) on this machine"
    for observer in execution.observers:
        if not hears_repeats(observer):
            return f"observer {type(observer).__name__} must see every step as it is made (it defines no `repeated`)"
    return None


class NativeLoop:
    """Segments of steps in C for an initialised execution (see the module doc); `run` makes one."""

    def __init__(self, execution):
        why = why_not(execution)
        if why is not None:
            raise ValueError(why)
        algorithm = execution.algorithm
        self.execution = execution
        self.seidel = isinstance(algorithm, GaussSeidel)
        self.parts: list[NativePart] = []
        for unit in algorithm.units:
            part = unit.native_part(execution)
            if isinstance(part, str):
                raise ValueError(f"unit {unit.name}: {part}")
            self.parts.append(part)
        self.width = len(algorithm.data)  # slots per row: the observed ports, then Gauss-Seidel's copies
        kinds = {i: KINDS.get(execution.system.units[key[0]].ports[key[1]].type, "?") for key, i in algorithm.slots.items()}
        self.copies = list(algorithm.copies) if self.seidel else []  # (source, shadow): Gauss-Seidel's delayed outputs
        for source, shadow in self.copies:
            kinds[shadow] = kinds[source]
        self.kinds = [kinds.get(i, "?") for i in range(self.width)]
        if "?" in self.kinds:
            raise ValueError("a port of a type other than Real, Integer or Boolean is observed")
        written = {algorithm.slots[(unit.name, name)] for unit, part in zip(algorithm.units, self.parts)
                   for name in part.writes if (unit.name, name) in algorithm.slots}
        written |= {shadow for source, shadow in self.copies if source in written}
        self.written = sorted(written)  # the slots C writes; the others hold still in a segment
        continuous = {algorithm.slots[(unit.name, name)] for unit, part in zip(algorithm.units, self.parts)
                      for name in part.continuous if (unit.name, name) in algorithm.slots}
        shadows = {shadow for _, shadow in self.copies}
        self.discrete = [i for i in self.written if i not in continuous and i not in shadows]
        shadow_of = {shadow: source for source, shadow in self.copies}
        fed = {shadow_of.get(slot, slot) for unit, part in zip(algorithm.units, self.parts)
               for name, slot in feeds(execution, unit) if name not in part.takes}
        self._fed = frozenset(i for i in self.discrete if i in fed)  # changes a unit's C does not read: Python must
        self._masks: dict[frozenset | None, object] = {}  # the slots whose change ends a segment, as the C reads them
        self._data, self._observers = algorithm.data, list(execution.observers)
        self._still = [i for i in range(self.width) if i not in written]  # the slots no C writes
        self._pick_still = _picker(self._still)  # their values, picked in C
        # the slots C writes, with the class their port's values have: one holding another (a scenario's Real port
        # still at the integer 0 it starts with) is held as it is for a stretch, whose C must leave it be
        self._classes = [(i, _CLASS[self.kinds[i]]) for i in self.written]
        self._kinds: dict[tuple, list[str]] = {}  # the rows' kinds by the classes of the values held still
        self._bools = [i for i in self.written if self.kinds[i] == "b"]  # slots C writes as Booleans
        self._ints = [i for i in self.written if self.kinds[i] == "i"]  # ... as Integers
        self._asking, self._telling = self._listeners(self._observers)
        self._pointers: tuple[list, object] = ([], None)  # the last segment's pointers and their C array
        self._flags = (ctypes.c_int * 2)()  # failed, paused
        self._flag_addresses = (ctypes.addressof(self._flags), ctypes.addressof(self._flags) + ctypes.sizeof(ctypes.c_int))
        self.refusals: dict[str, int] = {}  # why steps were left to Python, and how often
        self.source = self._source()
        self._fn = _compiled(self.source, tuple(sorted({d for part in self.parts for d in part.include_dirs})))

    @staticmethod
    def _listeners(observers: list) -> tuple[list, list]:
        """The observers that bound the steps of a segment (they define `quiet_for` or `checkpoints`) and those
        told of its repeats (they define `repeated`): the others have nothing to say or do there."""
        return ([o for o in observers if type(o).quiet_for is not Observer.quiet_for
                 or type(o).checkpoints is not Observer.checkpoints],
                [o for o in observers if type(o).repeated is not Observer.repeated])

    def _ends(self, telling: list) -> tuple:
        """Which changes end this segment, as the C arrays it reads (E per slot: 0 none, 1 any, 2 a change to a
        value M's bits name, or to one beyond them): those of the slots a unit's C does not read, and those an
        observer told of the repeats must see on a whole step (every discrete one for an observer that does not
        say; the arrival of some values only, for a port it gives `whole_values` of)."""
        execution, slots = self.execution, self.execution.algorithm.slots
        whole: set[int] | None = set()
        values: dict[int, int] = {}  # slot -> the bits of the values whose arrival ends the segment
        for o in telling:
            ports = o.whole_changes(execution)
            if ports is None:
                whole = None
                break
            some = o.whole_values(execution)
            for port in ports:
                if port not in slots:
                    continue
                if port in some:
                    values[slots[port]] = values.get(slots[port], 0) | sum(1 << v for v in some[port] if 0 <= v < 64)
                else:
                    whole.add(slots[port])
        key = None if whole is None else (frozenset(whole), frozenset(values.items()))
        arrays = self._masks.get(key)
        if arrays is None:
            discrete = set(self.discrete)
            ends = discrete if whole is None else self._fed | (whole & discrete)
            codes = [1 if i in ends else 2 if i in values and i in discrete else 0 for i in range(self.width)]
            arrays = self._masks[key] = ((ctypes.c_ubyte * max(1, self.width))(*codes),
                                         (ctypes.c_ulonglong * max(1, self.width))(*(values.get(i, 0) for i in range(self.width))))
        return arrays

    def _checks(self, asking: list) -> tuple[int, int]:
        """The observers' checkpoints (Observer.checkpoints) as the C reads them: their array's address and count."""
        slots, found = self.execution.algorithm.slots, []
        for o in asking:
            for port, value, steps in o.checkpoints(self.execution):
                if port in slots and value.__class__ in _PLAIN:
                    found += [float(steps), float(slots[port]), float(value)]
        self._checked = np.array(found or [0.0], dtype=np.float64)  # kept alive while the C reads it
        return self._checked.ctypes.data, len(found) // 3

    def _source(self) -> str:
        algorithm = self.execution.algorithm
        decls, body, ready = [], [], []
        pbase = dbase = 0
        width = self.width
        for k, (unit, part) in enumerate(zip(algorithm.units, self.parts)):
            decls.append(part.decls)
            if part.ready and not self.seidel:
                ready.append(f"    {{ double *DD = D + {dbase}; (void)DD; if (!({part.ready})) return j; }}  /* {unit.name} */")
            body.append(f"    /* unit {unit.name} */")
            body.append(f"    {{ void **PP = P + {pbase}; double *DD = D + {dbase}; (void)PP; (void)DD;")
            body.append(f"#define FAIL(code) do {{ *failed = {k} * 1000 + (code); return j; }} while (0)")
            if self.seidel:  # the step is finished in Python from this unit on
                body.append(f"#define PAUSE() do {{ *paused = {k + 1}; memcpy(rows + (size_t)j * {width}, N, "
                            f"sizeof(double) * {width}); return j; }} while (0)")
            else:  # Jacobi: `quiet` rules a pause out (a unit's inputs are those of the step before)
                body.append("#define PAUSE() FAIL(999)")
            body.extend("    " + line for line in part.step.strip("\n").split("\n"))
            body.append("#undef FAIL")
            body.append("#undef PAUSE")
            body.append("    }")
            pbase += len(part.pointers)
            dbase += len(part.doubles)
        self._sizes = (pbase, dbase)
        changed = " || ".join(f"(E[{i}] && N[{i}] != S[{i}] && (E[{i}] == 1 || !(N[{i}] >= 0.0 && N[{i}] < 64.0) || "
                              f"N[{i}] != (double)(int)N[{i}] || ((M[{i}] >> (int)N[{i}]) & 1ULL)))"
                              for i in self.discrete) or "0"
        moved = " || ".join(f"N[{i}] != S[{i}]" for i in self.discrete) or "0"
        lines = [_PRELUDE,
                 "#define IN(slot) " + ("N[slot]" if self.seidel else "S[slot]") +
                 ("  /* Gauss-Seidel: this step's outputs of the units before */" if self.seidel else
                  "  /* Jacobi: the outputs of the step before */"),
                 "#define END_AFTER() (end_here = 1)",
                 "#define END_NEXT() (end_next = 1)",
                 *decls,
                 "/* Up to n steps from step `base` (since `origin`); returns the steps made. `failed`: unit * 1000 + code",
                 "   of a step that failed; `paused`: 1 + the unit that paused the step after them (rows[return] holds",
                 "   its slots so far). rows: the slots after each step. E: whether a slot's change ends the segment",
                 "   (1: any change; 2: one to a value whose bit M has, or beyond 63); moved: whether a discrete slot",
                 "   changed in each step; checks: the step (counted from 1) after which the segment ends if a slot",
                 "   holds a value then, (step, slot, value) for each of `nchecks`. */",
                 "int cotwin_segment(void **P, double *D, double *S, double *rows, int n, double origin, long long base,",
                 "                   double H, int *failed, int *paused, const unsigned char *E,",
                 "                   const unsigned long long *M, unsigned char *moved, const double *checks, int nchecks) {",
                 f"  double N[{max(1, width)}];",
                 "  int ending = 0;  /* a unit asked, in the step before, to end after this one */",
                 "  *failed = 0;",
                 "  *paused = 0;",
                 "  for (int j = 0; j < n; j++) {",
                 "    double t = origin + (double)(base + j) * H;",
                 "    int end_here = ending, end_next = 0;",
                 *ready,
                 f"    memcpy(N, S, sizeof(double) * {width});",
                 *(f"    N[{shadow}] = N[{source}];" for source, shadow in self.copies),
                 *body,
                 f"    int changed = {changed};",
                 f"    moved[j] = {moved};",
                 f"    memcpy(S, N, sizeof(double) * {width});",
                 f"    memcpy(rows + (size_t)j * {width}, S, sizeof(double) * {width});",
                 "    for (int c = 0; c < nchecks; c++)",
                 "      if (checks[3 * c] == (double)(j + 1) && S[(int)checks[3 * c + 1]] == checks[3 * c + 2]) end_here = 1;",
                 "    if (changed || end_here) return j + 1;",
                 "    ending = end_next;",
                 "  }",
                 "  return n;",
                 "}"]
        return "\n".join(lines) + "\n"

    def current(self) -> bool:
        """Whether this loop still fits its execution: the algorithm's slots it was made for, and observers that
        hear repeats (another set of them, e.g. the next what-if's on a sweep's fork, is taken on here)."""
        execution = self.execution
        if self._data is not execution.algorithm.data:
            return False
        observers = execution.observers
        if self._observers != observers:
            if not all(hears_repeats(o) for o in observers):
                return False
            self._observers = list(observers)
            self._asking, self._telling = self._listeners(self._observers)
        return True

    def quiet(self, n: int) -> int:
        """How many of the next n steps every unit can make natively now (and every observer lets pass)."""
        execution = self.execution
        data = execution.algorithm.data
        if any(map(_IS_UNSET, data)):
            return 0
        values = (*self._pick_still(data), *(data[i] for i in self._kept(data)))  # those a stretch holds as they are
        classes = set(map(type, values))
        if not _PLAIN.issuperset(classes) or int in classes and any(abs(v) > 2 ** 53 for v in values if v.__class__ is int):
            why = "a value on a connection is not a number a double carries exactly"
            self.refusals[why] = self.refusals.get(why, 0) + 1
            return 0
        observers = execution.observers
        for observer in self._asking if observers == self._observers else observers:
            bound = observer.quiet_for(execution)
            if bound is not None:
                n = min(n, bound)
        for unit, part in zip(execution.algorithm.units, self.parts):
            n = min(n, part.quiet(n))
            if n <= 0:
                why = f"unit {unit.name}: {part.refusal()}"
                self.refusals[why] = self.refusals.get(why, 0) + 1
                return 0
        return n

    def _kept(self, data: list) -> list[int]:
        """The slots C writes that a stretch starting now holds as they are, besides those no C writes: they hold a
        value of another class than their port's (the unit's `quiet` sees that its C leaves them be)."""
        return [i for i, cls in self._classes if data[i].__class__ is not cls]

    def idle(self) -> str:
        """Why steps were left to Python, the most frequent reason first (for a run that made none here)."""
        ranked = sorted(self.refusals.items(), key=lambda item: -item[1])
        return "; ".join(f"{why} ({n} steps)" for why, n in ranked[:3]) or "no step was quiet"

    def run(self, n: int) -> int:
        """Up to n steps natively (fewer: see the module doc); the steps made, observers told. 0 when the
        system is not quiet now (the caller makes a step in Python). A step a unit paused is finished in
        Python, from that unit on, and counted. A step that failed raises its error once the steps before it
        are committed and told. Ctrl-C waits until they are (a stretch is a tenth of a second at most)."""
        n = self.quiet(min(n, MAX_SEGMENT))
        if n <= 0:
            return 0
        for part in self.parts:
            if not part.prepare():
                return 0
        with signals_held():
            return self._run(n)

    def _run(self, n: int) -> int:
        execution, algorithm = self.execution, self.execution.algorithm
        data = algorithm.data
        # the rows' kinds this segment: C writes its slots as their ports' types; the others hold still, as
        # the Python objects they are (an Integer 0 in a Real port stays 0), and are put back as they were
        kept = self._kept(data)
        held = {i: data[i] for i in self._still + kept}
        kinds = self._kinds_of(held)
        for part in self.parts:
            part.begin()
        P = self._pointer_array()
        doubles = [d for part in self.parts for d in part.doubles]
        assert len(doubles) == self._sizes[1], "a native part changed its number of doubles"
        D = np.array(doubles or [0.0], dtype=np.float64)
        S = np.array(data, dtype=np.float64)  # plain numbers all (`quiet`): each as float() makes it
        before = S.copy()
        rows = np.empty((n, self.width), dtype=np.float64)
        moved = np.zeros(n + 1, dtype=np.uint8)
        flags = self._flags
        origin, done = execution._origin
        first = execution.steps
        observers = execution.observers
        ends = self._ends(self._telling if observers == self._observers else self._listeners(observers)[1])
        checks = self._checks(self._asking if observers == self._observers else self._listeners(observers)[0])
        k = self._fn(P, D.ctypes.data, S.ctypes.data, rows.ctypes.data, n, float(origin), first - done,
                     execution.step_size, *self._flag_addresses, *ends, moved.ctypes.data, *checks)
        failed, paused = flags[0], flags[1]
        failing, code = divmod(failed, 1000) if failed else (-1, 0)
        stopped = paused - 1 if paused else failing  # the unit that ended step k early, or -1
        half = rows[k].copy() if paused else None
        rows = rows[:k]
        for i in kept:
            if (rows[:, i] != float(held[i])).any():
                raise RuntimeError(f"a unit's C wrote slot {i} in a stretch that held its value {held[i]!r} as it was")
        if k:
            self._commit(rows, before if k == 1 else rows[k - 2], held)
        errors = []
        base = 0
        for u, part in enumerate(self.parts):
            made = k + 1 if 0 <= u < stopped else k  # the units before the one that stopped made step k too
            try:
                part.end(first, made, rows, D[base:base + len(part.doubles)])
            except Exception as err:  # every part is brought up to date; the first error is raised after
                errors.append(err)
            base += len(part.doubles)
        if failed or errors:
            if k:
                self._tell(rows[:-1], kinds, before, moved)
            if errors:
                raise errors[0]
            self.parts[failing].failed(code, origin + (first + k - done) * execution.step_size)
            raise RuntimeError(f"unit {algorithm.units[failing].name} failed in the native loop (code {code})")
        if paused:
            self._finish(half, stopped, held)
            self._tell(rows, kinds, before, moved)
            return k + 1
        if k:
            self._tell(rows[:-1], kinds, before, moved)
        return k

    def _finish(self, half: np.ndarray, pause: int, held: dict[int, object]) -> None:
        """The step a unit paused, made in Python from that unit on (as Gauss-Seidel makes it), counted."""
        execution, algorithm = self.execution, self.execution.algorithm
        data = algorithm.data
        data[:] = self._typed(half, held)
        origin, done = execution._origin
        t = origin + (execution.steps - done) * execution.step_size
        for k in range(pause, len(algorithm.units)):
            write, read = algorithm.writes[k], algorithm.reads[k]
            if write is not None:
                setter, pick = write
                setter(pick(data))
            algorithm.units[k].step(t, execution.step_size)
            if read is not None:
                getter, slots = read
                for i, value in zip(slots, getter()):
                    data[i] = value
        execution.steps += 1
        execution.time = origin + (execution.steps - done) * execution.step_size

    def _commit(self, rows: np.ndarray, previous: np.ndarray, held: dict[int, object]) -> None:
        """The execution's slots, steps and time after the segment; the Python units' inputs as they were set
        for its last step (Jacobi: from the slots before it; Gauss-Seidel: from its own)."""
        execution, algorithm = self.execution, self.execution.algorithm
        data = algorithm.data
        data[:] = self._typed(rows[-1], held)
        execution.steps += len(rows)
        origin, done = execution._origin
        execution.time = origin + (execution.steps - done) * execution.step_size
        typed = data if self.seidel else self._typed(previous, held)
        for write, part in zip(algorithm.writes, self.parts):
            if write is not None and not part.sets_inputs:
                setter, pick = write
                setter(pick(typed))

    def _tell(self, repeats: np.ndarray, kinds: list[str], before: np.ndarray, moved: np.ndarray) -> None:
        """Observers hear of the repeated steps (the rows before the current step; `before`: the slots before the
        first; `moved`: the steps in which a discrete value changed), then of the current one."""
        execution = self.execution
        observers = execution.observers
        if len(repeats):
            batch = StepRows(execution, repeats, kinds, before, moved[:len(repeats)])
            for o in self._telling if observers == self._observers else self._listeners(observers)[1]:
                o.repeated(execution, batch)  # the others have nothing to do after a step
        for o in observers:
            o.step_complete(execution)

    def _typed(self, row: np.ndarray, held: dict[int, object]) -> list:
        """A row as the values the ports hold (as _typed makes it: C's slots of their ports' types, the slots
        held still put back as they were)."""
        out = row.tolist()
        for i in self._bools:
            out[i] = out[i] != 0.0
        for i in self._ints:
            out[i] = int(out[i])
        for i, value in held.items():
            out[i] = value
        return out

    def _kinds_of(self, held: dict[int, object]) -> list[str]:
        """The rows' kinds: the ports' where C writes, the held values' own elsewhere (made once per their classes)."""
        key = tuple(value.__class__ for value in held.values())
        kinds = self._kinds.get(key)
        if kinds is None:
            kinds = self._kinds[key] = [self.kinds[i] if i not in held else _KIND[held[i].__class__]
                                        for i in range(self.width)]
        return list(kinds)

    def _pointer_array(self):
        """The parts' pointers as the C array the segment reads (the last one again while they are the same)."""
        pointers = [p for part in self.parts for p in part.pointers]
        assert len(pointers) == self._sizes[0], "a native part changed its number of pointers"
        last, array = self._pointers
        if pointers != last:
            array = (ctypes.c_void_p * max(1, len(pointers)))(*pointers)
            self._pointers = (pointers, array)
        return array




_PLAIN = frozenset((bool, int, float))
_IS_UNSET = partial(is_, UNSET)  # whether a slot is still unwritten, asked in C over a row


def _picker(slots: list[int]) -> Callable[[list], tuple]:
    """A function giving a row's values at `slots`, as a tuple (operator.itemgetter's, whatever their number)."""
    if len(slots) > 1:
        return itemgetter(*slots)
    if slots:
        only = slots[0]
        return lambda row: (row[only],)
    return lambda row: ()
_KIND = {bool: "b", int: "i", float: "r"}
_CLASS = {"b": bool, "i": int, "r": float}


class StepRows:
    """Steps an observer hears of at once: the slots after each (`rows`, doubles), each row's `steps` (its
    start index) and `times` (its end), counted as the execution counts them (`counted`: origin, the first
    row's steps since it, the step size); `before`: the slots before the first; `moved`: whether a discrete
    value changed in each (None: not known); `replay` makes each the execution's current step in turn (values
    typed as the ports hold them), and puts the current one back after."""

    def __init__(self, execution, rows: np.ndarray, kinds: list[str], before: np.ndarray | None = None,
                 moved: np.ndarray | None = None):
        self.rows, self.kinds = rows, kinds
        self.before, self.moved = before, moved
        origin, done = execution._origin
        self.first = execution.steps - 1 - len(rows)  # the rows are the steps before the current one
        self.counted = (origin, self.first + 1 - done, execution.step_size)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def steps(self) -> range:
        return range(self.first, self.first + len(self.rows))

    @property
    def times(self) -> list[float]:
        origin, n, h = self.counted
        return [origin + (n + k) * h for k in range(len(self.rows))]

    def values(self, slots: list[int]) -> list[tuple]:
        """The rows' values at these slots, typed, one tuple per row."""
        kinds = [self.kinds[i] for i in slots]
        columns = [_column(self.rows[:, i], kind) for i, kind in zip(slots, kinds)]
        return list(zip(*columns)) if columns else [() for _ in self.rows]

    def changed(self) -> list[int]:
        """The rows in which a discrete value changed (all of them when it is not known)."""
        if self.moved is None or self.before is None:
            return list(range(len(self.rows)))
        return np.flatnonzero(self.moved).tolist()

    def changes(self, slots: list[int]) -> list[int]:
        """The rows in which a discrete value at these slots differs from the row before (the first: from
        `before`; every row when that is not known)."""
        if not slots:
            return []
        out = []
        for k in self.changed():
            row, previous = self.rows[k].tolist(), (self.rows[k - 1] if k else self.before).tolist()
            if any(row[i] != previous[i] for i in slots):
                out.append(k)
        return out

    def row(self, k: int, slots: list[int]) -> tuple:
        """Row k's values at these slots, typed (one row read, not the stretch's columns)."""
        row, kinds = self.rows[k].tolist(), self.kinds
        return tuple((row[i] != 0.0) if kinds[i] == "b" else int(row[i]) if kinds[i] == "i" else row[i] for i in slots)

    def replay(self, execution, only: Iterable[int] | None = None):
        """Each row (or those `only` names, in order; it is read as the rows are told, so a generator may choose
        the next row by what the last one did) made the execution's current step in turn."""
        data = execution.algorithm.data
        kept = (list(data), execution.steps, execution.time)
        times = self.times
        try:
            for k in range(len(self.rows)) if only is None else only:
                data[:] = _typed(self.rows[k], self.kinds)
                execution.steps, execution.time = self.first + k + 1, times[k]
                yield
        finally:
            data[:], execution.steps, execution.time = kept


def _column(values: np.ndarray, kind: str) -> list:
    if kind == "b":
        return [v != 0.0 for v in values.tolist()]
    if kind == "i":
        return [int(v) for v in values.tolist()]
    return values.tolist()


def _typed(row: np.ndarray, kinds: list[str], held: dict[int, object] | None = None) -> list:
    """A row of doubles as the values the ports hold (bool, int, float); `held`: slots put back as they were."""
    out = [(v != 0.0) if k == "b" else int(v) if k == "i" else v for v, k in zip(row.tolist(), kinds)]
    for i, value in (held or {}).items():
        out[i] = value
    return out


_PRELUDE = r"""
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdbool.h>
#include <string.h>
typedef void (*cotwin_mj_step)(const void *, void *);
typedef int (*cotwin_do_step)(void *, double, double, int);
"""

_CACHE: dict[str, object] = {}


def _compiled(source: str, include_dirs: tuple[str, ...] = ()):
    """The segment function of this source, compiled once per machine (cached by its hash)."""
    digest = hashlib.sha256("\0".join([source, *include_dirs]).encode()).hexdigest()[:20]
    if digest in _CACHE:
        return _CACHE[digest]
    lib = compile_library(source, "segment", keep_gil=False, include_dirs=include_dirs)  # other threads run meanwhile
    fn = lib.cotwin_segment
    address = ctypes.c_void_p  # the arrays' addresses as integers (no pointer object made per call)
    fn.argtypes = [ctypes.POINTER(ctypes.c_void_p), address, address, address, ctypes.c_int, ctypes.c_double,
                   ctypes.c_longlong, ctypes.c_double, address, address, ctypes.POINTER(ctypes.c_ubyte),
                   ctypes.POINTER(ctypes.c_ulonglong), address, address, ctypes.c_int]
    fn.restype = ctypes.c_int
    _CACHE[digest] = fn
    return fn
