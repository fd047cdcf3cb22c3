"""An execution: a System stepped by an Algorithm at a fixed communication step, watched by observers.

`Execution` can be run to an end time (`run`) or stepped one communication step at a time (`step`),
which is how the live twin keeps a physical and a digital twin on one clock. It always ends the units'
life as FMI asks, also after a failure, and tells observers how the run ended.

Its state (`get_state`: every unit's state, the values on the connections, the time) can be restored
into the same execution (a rollback) or into a fresh execution of the same system (a fork): stepped
with the same inputs, both continue bit for bit as the original did.
"""

from __future__ import annotations

import math

import time as wallclock
from dataclasses import dataclass, field
from typing import Callable, Iterable

from ..diagnostics import CotwinError, Interrupted
from .algorithm import ALGORITHMS, Algorithm
from .observers import Observer, Stop
from .state import StateError, count, fields, finite, of_type, pack, port_value, unpack
from .system import System


@dataclass(frozen=True)
class RunResult:
    """What an execution ran: its steps, its times, and how long it took."""

    algorithm: str
    step_size: float
    start: float
    end_time: float
    steps: int
    wall_seconds: float
    outputs: dict[str, object] = field(default_factory=dict)
    stepping: str = "step by step"  # or "fused" (cotwin.cosim.fused), or why the fused loop did not apply
    native_steps: int = 0  # of the steps, those made in the native loop (cotwin.cosim.native)
    native_why: str | None = None  # why the native loop did not apply, when the fused loop ran without it

    def describe_stepping(self) -> str:
        """How the steps were made, in a few words (for a run's summary line)."""
        if self.stepping != "fused":
            return self.stepping
        if self.native_steps:
            return f"fused, {self.native_steps} of {self.steps} steps in the native loop"
        return f"fused (the native loop did not apply: {self.native_why})" if self.native_why else "fused"

    @property
    def rows(self) -> int:
        return self.steps + 1

    @property
    def real_time_factor(self) -> float:
        return (self.end_time - self.start) / max(self.wall_seconds, 1e-12)


MAX_STEPS = 10**8  # steps of one run: beyond, hours of computing (a step or an end off by powers of ten)


def step_count(span: float, step: float, start: float = 0.0, what: str | None = None) -> int:
    """How many steps of `step` make `span` (from `start`); CotwinError, prefixed with `what`, for a span
    shorter than one step, more than MAX_STEPS (also inf and NaN), or not a whole number of steps (end
    1.05 s at 0.1 s): a run that would silently end elsewhere."""
    steps, end = span / step, start + span
    whole = round(steps) if steps <= MAX_STEPS else 0
    if not steps <= MAX_STEPS:
        problem = f"{end:g} s is {steps:.3g} steps of {step:g} s, more than {MAX_STEPS:.0e}"
    elif steps < 1 - 1e-9:
        problem = f"{end:g} s is shorter than one step of {step:g} s"
    elif abs(steps - whole) > 1e-6 * max(1.0, steps):
        low, high = start + math.floor(steps) * step, start + math.ceil(steps) * step
        problem = f"{end!r} s is not a whole number of steps of {step:g} s (it would be rounded): give {low:.10g} or {high:.10g}"
    else:
        return int(whole)
    raise CotwinError(f"{what}: {problem}" if what else problem)


def uninterrupted(calls: Iterable[Callable[[], object]]) -> None:
    """Each of `calls` in turn, even if an interrupt (a second Ctrl-C, SIGTERM) arrives during one or one fails
    (a result file that cannot be written): the ending of a run (units ended, result files renamed, its history
    closed, temporary files removed) is never left half-done; the first interrupt or error is raised once the
    last call is made."""
    late = None
    for call in calls:
        try:
            call()
        except BaseException as err:  # noqa: BLE001 -- raised after the others are made
            late = late or err
    if late is not None:
        raise late


def _terminated(unit) -> None:
    """End one unit; its failure must not stop the others from ending."""
    try:
        unit.terminate()
    except Exception:  # noqa: BLE001
        pass


def ended_early(err: BaseException, time: float, kept: str) -> CotwinError:
    """The error of a run that failed (`err` a CotwinError) or was interrupted (KeyboardInterrupt) at `time`,
    saying where the rows it computed are (`kept`, e.g. CSVWriter.kept()); the latter is an Interrupted."""
    if isinstance(err, KeyboardInterrupt):
        return Interrupted(f"interrupted at t = {time:g} s; {kept}")
    return CotwinError([*err.findings, *CotwinError(kept).findings], ordered=True)  # the cause first, then what was kept


def saved_execution(state: bytes) -> dict:
    """The data of an execution's saved state with its structure and times checked (before anything is
    built from it): the time a finite number that is `steps` steps of `step_size` from the origin, steps
    a whole number, the units' states bytes by name, the values by (unit, port); StateError otherwise."""
    data = fields(unpack(state, "Execution"), "execution", ("algorithm", "time", "steps", "step_size", "origin",
                                                             "values", "units"), ("models",))
    of_type(data["algorithm"], str, "algorithm")
    if data["algorithm"] not in ALGORITHMS:
        raise StateError(f"the saved state's algorithm {data['algorithm']!r:.60} is unknown (known: "
                         f"{', '.join(ALGORITHMS)})")
    time = finite(data["time"], "time")
    steps = count(data["steps"], "number of steps", MAX_STEPS)
    step = finite(data["step_size"], "step size")
    if not step > 0:
        raise StateError(f"the saved state's step size is {step!r}, not a positive number of seconds")
    origin = data["origin"]
    if origin.__class__ not in (tuple, list) or len(origin) != 2:
        raise StateError(f"the saved state's origin is {origin!r:.60}, not a (time, steps) pair")
    origin = (finite(origin[0], "origin's time"), count(origin[1], "origin's steps", steps))
    expected = origin[0] + (steps - origin[1]) * step
    if abs(expected - time) > 1e-6 * max(1.0, abs(time), step):
        raise StateError(f"the saved state's time {time!r} s is not {steps - origin[1]} steps of {step!r} s from "
                         f"{origin[0]!r} s (that is {expected!r} s)")
    values = of_type(data["values"], dict, "values")
    for key in values:
        if key.__class__ is not tuple or len(key) != 2 or not all(k.__class__ is str for k in key):
            raise StateError(f"the saved state's values are keyed by (unit, port), not by {key!r:.60}")
    units = of_type(data["units"], dict, "units")
    for name, blob in units.items():
        of_type(name, str, "unit name")
        of_type(blob, bytes, f"state of unit {name}")
    models = of_type(data.get("models", {}), dict, "models")
    for name, digest in models.items():
        of_type(name, str, "model name")
        of_type(digest, str, f"digest of model {name}")
    return {**data, "time": time, "steps": steps, "step_size": step, "origin": origin, "models": models}


def check_models(saved: dict[str, str], here: dict[str, str]) -> None:
    """StateError naming what differs when a state was saved from other models than these."""
    differences = model_differences(saved, here)
    if differences:
        raise StateError(f"the state was saved from other models than these: {'; '.join(differences)}")


def model_differences(saved: dict[str, str], here: dict[str, str]) -> list[str]:
    """What differs between the models (name -> digest) a state was saved from and these; nothing when
    either does not name its models."""
    if not saved or not here:
        return []
    out = [f"{name} changed (sha256 {saved[name][:12]} when saved, {here[name][:12]} here)"
           for name in sorted(set(saved) & set(here)) if saved[name] != here[name]]
    out += [f"{name} is not among these models" for name in sorted(set(saved) - set(here))]
    out += [f"{name} was not among the saved models" for name in sorted(set(here) - set(saved))]
    return out


@dataclass(frozen=True, eq=False)
class Checkpoint:
    """An execution's state kept in memory (Execution.checkpoint): only that execution goes back to it."""
    execution: "Execution"
    time: float
    steps: int
    origin: tuple
    values: dict
    units: dict


class Execution:
    def __init__(self, system: System, algorithm: Algorithm, step_size: float, start: float = 0.0,
                 observers: list[Observer] | tuple[Observer, ...] = (), fused: bool = False):
        """`fused`: `run` steps in the fused loop (cotwin.cosim.fused: the same values, without the per-step
        bookkeeping) when it applies; `stepping` then says which loop ran."""
        if not step_size > 0:
            raise CotwinError(f"the step size must be positive, got {step_size!r}")
        self.system = system
        self.algorithm = algorithm
        self.step_size = float(step_size)
        self.start = float(start)
        self.observers = list(observers)
        self.steps = 0
        self.total_steps = 0
        self.time = self.start
        self.initialized = False
        self.closed = False
        self._wall = 0.0
        self._origin = (self.start, 0)  # (time, steps) from which step times are counted
        self._first = (self.start, 0)  # (time, steps) where this execution began (later for a fork)
        self.fused = fused
        self._loop = None  # the fused loop `advance` made (rebuilt when the slots or observers change)
        self._native = None  # the native loop (cotwin.cosim.native) beside it, where it applies
        self.native_steps = 0  # steps made in the native loop
        self.native_why: str | None = "not tried"  # why the native loop did not apply (None: it did)
        self.stepping = "step by step"  # or "fused" (see run), or why the fused loop did not apply

    @property
    def values(self):
        """(unit, port) -> the latest value of every observed port (a read-only mapping)."""
        return self.algorithm.values

    def reader(self, keys: list[tuple[str, str]]):
        """A function returning the latest values of these observed ports as a tuple, in this order."""
        return self.algorithm.reader(keys)

    def add_observer(self, observer: Observer) -> None:
        self.observers.append(observer)
        if self.initialized:
            observer.simulation_initialized(self)

    def initialize(self) -> None:
        self._setup()
        try:
            for o in self.observers:
                o.simulation_initialized(self)
        except BaseException as err:  # an observer that cannot start (a result file in use ...) ends the run
            self.close(err)
            raise

    def _setup(self) -> None:
        self._wall = wallclock.perf_counter()
        try:
            self.algorithm.setup(self.system, self.start)
            self.algorithm.initialize()
        except BaseException as err:
            self.close(err)
            raise
        self.initialized = True

    def _time_at(self, steps: int) -> float:
        time, done = self._origin
        return time + (steps - done) * self.step_size

    def step(self) -> float:
        """One communication step from the current time; returns the new time."""
        t = self._time_at(self.steps)
        try:
            self.algorithm.do_step(t, self.step_size)
        except BaseException as err:
            self.close(err)
            raise
        self.steps += 1
        self.time = self._time_at(self.steps)
        for o in self.observers:
            o.step_complete(self)
        return self.time

    def run(self, end: float) -> RunResult:
        """Initialise (if not yet), step until `end`, close; the result says what ran."""
        if not end > self.time:
            raise CotwinError(f"the end time ({end!r} s) must come after the current time ({self.time!r} s)")
        time, done = self._origin
        self.total_steps = done + step_count(end - time, self.step_size, time, "the end time")
        if not self.initialized:
            self.initialize()
        try:
            if self.fused:
                self._run_fused()
            while self.steps < self.total_steps:
                self.step()
        except BaseException as err:
            self.close(err)
            raise
        self.close()
        return self.result()

    def advance(self, n: int, until: Stop | Callable[["Execution"], bool] | None = None) -> int:
        """Up to n communication steps from the current time (initialised first if not yet), in the fused loop
        when `fused` and it applies (its quiet stretches in the native loop), else one `step` at a time; stops
        early after the first step at which `until` is reached: a `Stop` among the observers (the native loop
        may run: its `quiet_for` bounds the stretches), or a function of the execution asked after every step
        (the native loop does not run). Returns the steps done; a failure closes the execution, as `step` does."""
        if not self.initialized:
            self.initialize()
        if isinstance(until, Stop):
            if until not in self.observers:
                raise ValueError("a Stop ends a run only as one of its observers")
            stop, until = until, until.reached
        else:
            stop = None
        if self.fused:
            from .fused import FusedLoop, applicable

            why = applicable(self)
            if why is None:
                loop = self._loop
                if loop is None or not loop.current():
                    loop = self._loop = FusedLoop(self)
                self.stepping = "fused"
                try:
                    if until is not None and stop is None:
                        return loop.run(n, until)
                    return self._fused_steps(loop, n, until)
                except BaseException as err:
                    self.close(err)
                    raise
            self.stepping = f"step by step: the fused loop does not apply ({why})"
        for k in range(1, n + 1):
            self.step()
            if until is not None and until(self):
                return k
        return n

    def _run_fused(self) -> None:
        """The steps left in the fused loop (cotwin.cosim.fused), when it applies; `stepping` says."""
        from .fused import FusedLoop, applicable

        why = applicable(self)
        if why is not None:
            self.stepping = f"step by step: the fused loop does not apply ({why})"
            return
        self.stepping = "fused"
        loop = FusedLoop(self)
        try:
            self._fused_steps(loop, self.total_steps - self.steps)
        except BaseException as err:
            self.close(err)
            raise

    def _fused_steps(self, loop, n: int, until: Callable[["Execution"], bool] | None = None) -> int:
        """Up to n steps: stretches of quiet steps in the native loop (cotwin.cosim.native) where it applies,
        the others in the fused loop; `native_steps` counts the former, `native_why` says why none (or None).
        `until` (a Stop's `reached`) is asked after each step the Python objects see whole: the last of a
        stretch, each made in Python."""
        from .native import QUIET_AFTER, NativeLoop

        native = self._native
        if native is None or not native.current():
            try:
                native = self._native = NativeLoop(self)
                self.native_why = None
            except ValueError as why:
                self._native, self.native_why = None, str(why)
                return loop.run(n, until)
        done = 0
        try:
            while done < n:
                k = native.run(n - done)
                if k:
                    self.native_steps += k
                    done += k
                    if until is not None and until(self):
                        break
                    continue
                k = loop.run(min(QUIET_AFTER, n - done), until)
                if k == 0:
                    break
                done += k
                if until is not None and until(self):
                    break
        finally:
            if not self.native_steps:
                self.native_why = f"no step was quiet enough: {native.idle()}"
        return done

    def result(self) -> RunResult:
        outputs = {type(o).__name__: o.path for o in self.observers if getattr(o, "path", None) is not None}
        start, done = self._first
        return RunResult(self.algorithm.name, self.step_size, start, self.time, self.steps - done,
                         wallclock.perf_counter() - self._wall, outputs, self.stepping, self.native_steps,
                         self.native_why if self.native_why != "not tried" else None)

    # ---- state ----
    def get_state(self) -> bytes:
        """The co-simulation's whole state at the current time: every unit's, the values on the
        connections, the time and steps done, and the models the system was made from when it names
        them (cotwin.cosim.state bytes)."""
        if not self.initialized or self.closed:
            raise CotwinError("only a running execution (initialised, not closed) has a state to save")
        return pack("Execution", {
            "algorithm": self.algorithm.name, "time": self.time, "steps": self.steps,
            "step_size": self.step_size, "origin": self._origin,
            "values": self.algorithm.snapshot(), "models": dict(self.system.models),
            "units": {name: unit.get_state() for name, unit in self.system.units.items()}})

    def set_state(self, state: bytes, units: Iterable[str] | None = None) -> None:
        """Continue from `state`: of this execution (a rollback; observers see time jump back) or of
        another execution of the same system (a fork: this one is initialised first, and its observers
        start at the restored time). The step size may differ from the saved execution's.

        With `units`, only those units and the values of their ports are restored, and the others start
        afresh (a fork whose command source is another: a what-if plan in place of the live stream);
        build such an execution with `start` at the saved time so they are instantiated there.

        Everything in the state is checked against this system before anything is restored: its models,
        units, observed ports and their types, and its times; each unit checks its own part."""
        data = saved_execution(state)
        if self.closed:
            raise CotwinError("a closed execution cannot restore a state")
        saved = data["units"]
        chosen = set(self.system.units) if units is None else set(units)
        missing = sorted(chosen - set(saved))
        check_models(data["models"], self.system.models)
        if units is None and set(saved) != set(self.system.units):
            raise StateError(f"the saved state is of units {', '.join(sorted(saved))}, this system has "
                             f"{', '.join(sorted(self.system.units))}")
        if missing or not chosen <= set(self.system.units):
            raise StateError(f"cannot restore {', '.join(sorted(chosen))}: the saved state has units "
                             f"{', '.join(sorted(saved))}, this system {', '.join(sorted(self.system.units))}")
        if data["algorithm"] != self.algorithm.name:
            raise StateError(f"the saved state was taken under {data['algorithm']:.40}, this execution runs "
                             f"{self.algorithm.name}: the values on the connections would mean something else")
        values = data["values"]
        observed = set(self.system.observed())
        if units is not None:  # a fork takes the values of the restored units' ports it observes
            values = {k: v for k, v in values.items() if k[0] in chosen and k in observed}
        for (unit, port), value in values.items():
            if (unit, port) not in observed:
                raise StateError(f"the saved state has a value of {unit:.60}.{port:.60}, which this system does not observe")
            port_value(value, self.system.units[unit].ports[port].type, f"value of {unit}.{port}")
        fresh = not self.initialized
        if fresh:
            self._setup()
        try:
            for name in chosen:
                self.system.units[name].set_state(saved[name])
            if units is not None:  # the others told they started afresh; the restored units' values this system
                self._forked(chosen)  # observes, the rest as they are
                values.update({k: v for k, v in self.algorithm.snapshot().items() if k[0] not in chosen})
            self.algorithm.restore(values)
        except BaseException as err:
            self.close(err)
            raise
        self.steps = self.total_steps = data["steps"]
        self.time = data["time"]
        # the same step size counts times as the saved execution did (bit-identical times), another from here
        self._origin = tuple(data["origin"]) if data["step_size"] == self.step_size else (self.time, self.steps)
        if fresh:
            self._first = (self.time, self.steps)
            for o in self.observers:
                o.simulation_initialized(self)

    def _forked(self, restored: set[str]) -> None:
        """A fork's units that started afresh, told so (`Unit.forked`) and their outputs read again: the event
        phase of their initialisation was shown to the restored units' fresh instances, not to them."""
        algorithm = self.algorithm
        for k, unit in enumerate(algorithm.units):
            if unit.name not in restored:
                unit.forked()
                algorithm._read(k)

    def checkpoint(self) -> "Checkpoint":
        """The co-simulation as it is now, kept in memory for `rollback` on this same execution (as libcosim's
        save_state beside export_state): each unit's checkpoint, the values on the connections, the time and
        steps. The execution's own state is not packed, parsed or checked again (each unit's `rollback` does
        what it must: a Python unit checks its snapshot, an FMU deserialises its bytes): a sweep's fork goes back
        to its start plan after plan (cotwin.twin.services.whatif.Forks)."""
        if not self.initialized or self.closed:
            raise CotwinError("only a running execution (initialised, not closed) has a state to keep")
        return Checkpoint(self, self.time, self.steps, self._origin, self.algorithm.snapshot(),
                          {name: unit.checkpoint() for name, unit in self.system.units.items()})

    def rollback(self, checkpoint: "Checkpoint") -> None:
        """Continue from a `checkpoint` of this execution (observers see time jump, as after `set_state`)."""
        if checkpoint.execution is not self:
            raise CotwinError("a checkpoint goes back only to the execution that kept it (another one: save its "
                              "state with get_state and restore it with set_state)")
        if self.closed:
            raise CotwinError("a closed execution cannot go back to a checkpoint")
        try:
            for name, unit in self.system.units.items():
                unit.rollback(checkpoint.units[name])
            self.algorithm.restore(checkpoint.values)
        except BaseException as err:
            self.close(err)
            raise
        self.steps = self.total_steps = checkpoint.steps
        self.time, self._origin = checkpoint.time, checkpoint.origin

    def close(self, error: BaseException | None = None) -> None:
        """Terminate every unit (each unit knows which FMI calls its state still allows) and tell the
        observers; idempotent."""
        if self.closed:
            return
        self.closed = True
        uninterrupted([*(lambda unit=unit: _terminated(unit) for unit in self.system.units.values()),
                       *(lambda o=o: o.simulation_ended(self, error) for o in self.observers)])
