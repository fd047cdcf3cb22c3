"""FMI 3.0 co-simulation FMUs as units beside FMI 2.0 ones: Event Mode and clock activation.

An `FMU3Unit` is instantiated with Event Mode when the FMU has it (`hasEventMode`), and takes part in
the master's event phase (cotwin.cosim.clocks): at each communication point it is offered its inputs;
when one of its time-based input clocks ticks there it enters Event Mode, activates the clock
(fmi3SetClock), sets the clocked inputs, updates its discrete states (fmi3UpdateDiscreteStates) and
its outputs are read at once; then it steps (fmi3EnterStepMode, fmi3DoStep) like any unit.

Readings where FMI 3.0 leaves the importer free, for units that exchange values with FMI 2.0 ones:
- a clocked Boolean output is an event: true at its clock's tick, false between ticks; other clocked
  outputs keep their value from the last tick;
- a clocked Boolean input offered true between two ticks (a command arriving while the clock is
  slower than the step) is kept until the next tick and delivered there once; other clocked inputs
  take the latest value offered;
- ticks must fall on communication points (a clock's interval a whole number of steps): a tick
  between them is an error naming the clock and the times, never a tick silently skipped;
- triggered input clocks (which only the importer could time) are refused when the unit is made.

Every FMI call goes through `_call`: a status above fmi3Warning (or an exception from FMPy) is a
UnitError naming the unit, the time, the call and the FMU's last message. The unit's state
(`get_state`) is the FMU's serialised state (fmi3GetFMUState, fmi3SerializeFMUState) with the
unit's own: its mode, the next tick, the inputs kept for it and the outputs shown.
"""

from __future__ import annotations

import math
import shutil
from collections import deque
from ctypes import c_double, c_int, c_uint
from pathlib import Path
from typing import Callable, Sequence

from fmpy import extract
from fmpy.fmi3 import FMU3Slave, fmi3FMUState

from ..diagnostics import CotwinError
from .state import pack, unpack
from . import isolated
from .isolated import DEFAULT_TIMEOUT
from ..plaindata import StateError, count, fields, finite, of_type, port_value
from .units import Port, Unit, UnitError, checked_value, model_description

STATUS = ("fmi3OK", "fmi3Warning", "fmi3Discard", "fmi3Error", "fmi3Fatal")
PORT_TYPE = {"Float64": "Real", "Float32": "Real", "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer",
             "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer",
             "Boolean": "Boolean"}
_ACCESS = {"Float64": "Float64", "Float32": "Float32", "Int8": "Int8", "UInt8": "UInt8", "Int16": "Int16",
           "UInt16": "UInt16", "Int32": "Int32", "UInt32": "UInt32", "Int64": "Int64", "UInt64": "UInt64",
           "Boolean": "Boolean"}
PERIODIC = ("constant", "fixed", "tunable")


def fmi_version(path: str | Path) -> str:
    try:
        return model_description(path).fmiVersion
    except Exception as err:  # FMPy raises many kinds for a bad zip or XML
        raise CotwinError(f"cannot read {path}: {err}") from None


def fmu_unit(name: str, path: str | Path, isolate: bool | None = None, timeout: float = DEFAULT_TIMEOUT,
             restart: bool = False) -> Unit:
    """The unit of an FMU file, FMI 3.0 or FMI 2.0 by its model description; an FMI 2.0 FMU isolated as
    cotwin.cosim.isolated.fmu_unit says. FMI 3.0 FMUs run in this process: isolating them is refused."""
    path = Path(path)
    if not path.is_file():
        raise CotwinError(f"unit {name}: no FMU at {path}")
    if not fmi_version(path).startswith("3."):
        return isolated.fmu_unit(name, path, isolate, timeout, restart)
    if isolate or restart:
        raise CotwinError(f"unit {name}: {path.name} is an FMI 3.0 FMU, which cotwin runs in its own process only "
                          "(isolation and restart-from-state are for FMI 2.0 FMUs)")
    return FMU3Unit(name, path)


class _Clock:
    def __init__(self, variable):
        self.name = variable.name
        self.vr = variable.valueReference
        self.kind = variable.intervalVariability
        self.interval = float(variable.intervalDecimal) if variable.intervalDecimal is not None else None
        self.shift = float(variable.shiftDecimal or 0.0)
        self.next = 0  # the number of the next tick


class FMU3Unit(Unit):
    """An FMI 3.0 Co-Simulation FMU through FMPy (see module doc)."""

    def __init__(self, name: str, path: str | Path):
        self.name = name
        self.path = Path(path)
        if not self.path.is_file():
            raise CotwinError(f"unit {name}: no FMU at {self.path}")
        try:
            self.md = model_description(self.path)
        except Exception as err:
            raise CotwinError(f"unit {name}: cannot read {self.path}: {err}") from None
        if not self.md.fmiVersion.startswith("3.") or self.md.coSimulation is None:
            raise CotwinError(f"unit {name}: {self.path} is not an FMI 3.0 co-simulation FMU")
        self.event_mode = bool(self.md.coSimulation.hasEventMode)
        self.ports: dict[str, Port] = {}
        self.variables = {}
        self.clocks: list[_Clock] = []
        for v in self.md.modelVariables:
            if v.type == "Clock":
                if v.causality == "input":
                    if v.intervalVariability not in PERIODIC:
                        raise CotwinError(f"unit {name}: input clock {v.name} is {v.intervalVariability}: cotwin's "
                                          f"master activates time-based periodic clocks only ({', '.join(PERIODIC)})")
                    self.clocks.append(_Clock(v))
                continue
            if v.type in PORT_TYPE and v.causality in ("input", "output", "parameter"):
                self.ports[v.name] = Port(v.name, PORT_TYPE[v.type], v.causality)
                self.variables[v.name] = v
        if self.clocks and not self.event_mode:
            raise CotwinError(f"unit {name}: {self.path} has clocks but no Event Mode (hasEventMode), which FMI 3.0 "
                              "requires of a Co-Simulation FMU with clocks")
        self.clocked = {n for n, v in self.variables.items() if getattr(v, "clocks", None)}
        self.fmu = None
        self.folder = None
        self.time = 0.0
        self.start = 0.0
        self.mode = "new"  # new | initialization | event | step | error | fatal
        self.messages: deque[tuple[str, str, str]] = deque(maxlen=50)
        self.offered: dict[str, object] = {}  # clocked inputs kept for the next tick
        self.shown: dict[str, object] = {n: (False if p.type == "Boolean" else 0) for n, p in self.ports.items()
                                         if p.causality == "output"}
        self.ticks = 0  # ticks run (all clocks together), for reports
        self.delivered: dict[str, object] = {}  # the clocked inputs set at the last tick
        self._pending = False  # the FMU asked for event handling (eventHandlingNeeded)

    # ---- the one path into the FMU ----
    def _call(self, call: str, fn, *args):
        try:
            return fn(*args)
        except Exception as err:  # FMPy's FMICallException carries the status
            status = getattr(err, "status", None)
            self.mode = "fatal" if status == 4 else "error"
            logged = self.messages[-1][2] if self.messages else ""
            detail = f"returned {STATUS[status]}" if isinstance(status, int) and 0 <= status < len(STATUS) else str(err)
            raise UnitError(self.name, self.time, call, f"{detail}: {logged}" if logged else detail) from None

    def _log(self, env, status, category, message) -> None:
        decode = (lambda b: b.decode("utf-8", "replace") if b else "")
        self.messages.append((STATUS[status] if 0 <= status < len(STATUS) else str(status), decode(category),
                              decode(message)))

    # ---- values by FMI 3.0 type ----
    def _set(self, values: dict[str, object]) -> None:
        by_type: dict[str, tuple[list, list]] = {}
        for name, value in values.items():
            v = self.variables[name]
            refs, vals = by_type.setdefault(v.type, ([], []))
            refs.append(v.valueReference)
            vals.append(checked_value(self.name, self.ports[name], value))
        for kind, (refs, vals) in by_type.items():
            self._call(f"fmi3Set{_ACCESS[kind]}", getattr(self.fmu, f"set{_ACCESS[kind]}"), refs, vals)

    def _get(self, names: list[str]) -> dict[str, object]:
        by_type: dict[str, list[str]] = {}
        for name in names:
            by_type.setdefault(self.variables[name].type, []).append(name)
        out = {}
        for kind, chosen in by_type.items():
            refs = [self.variables[n].valueReference for n in chosen]
            values = self._call(f"fmi3Get{_ACCESS[kind]}", getattr(self.fmu, f"get{_ACCESS[kind]}"), refs)
            for n, value in zip(chosen, values):
                out[n] = bool(value) if kind == "Boolean" else float(value) if PORT_TYPE[kind] == "Real" else int(value)
        return out

    # ---- life cycle ----
    def instantiate(self, start: float) -> None:
        self.time = self.start = start
        try:
            self.folder = extract(str(self.path))
        except Exception as err:
            raise UnitError(self.name, start, "extract", str(err)) from None
        self.fmu = self._call("load", lambda: FMU3Slave(guid=self.md.guid, unzipDirectory=self.folder,
                                                        modelIdentifier=self.md.coSimulation.modelIdentifier,
                                                        instanceName=self.name))
        self._call("fmi3InstantiateCoSimulation", lambda: self.fmu.instantiate(eventModeUsed=self.event_mode,
                                                                               logMessage=self._log))
        self.mode = "initialization"
        self._call("fmi3EnterInitializationMode", lambda: self.fmu.enterInitializationMode(startTime=start))

    def set(self, values: dict[str, object]) -> None:
        unknown = [n for n in values if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        if self.mode == "initialization":
            self._set(values)
            return
        plain = {n: v for n, v in values.items() if n not in self.clocked}
        if plain:
            self._set(plain)

    def initialize(self) -> None:
        for clock in self.clocks:
            if clock.kind != "constant" or clock.interval is None:
                intervals, qualifiers = (c_double * 1)(), (c_int * 1)()
                self._call("fmi3GetIntervalDecimal", self.fmu.getIntervalDecimal, (c_uint * 1)(clock.vr), intervals,
                           qualifiers)
                shifts = (c_double * 1)()
                self._call("fmi3GetShiftDecimal", self.fmu.getShiftDecimal, (c_uint * 1)(clock.vr), shifts)
                clock.interval, clock.shift = float(intervals[0]), float(shifts[0])
            if not (clock.interval and clock.interval > 0 and math.isfinite(clock.interval)):
                raise UnitError(self.name, self.time, "fmi3GetIntervalDecimal",
                                f"clock {clock.name} has interval {clock.interval!r}: not a positive number of seconds")
        self._call("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)
        self.mode = "event" if self.event_mode else "step"
        self._show(self._get(list(self.shown)))

    def _tick_time(self, clock: _Clock) -> float:
        return self.start + clock.shift + clock.next * clock.interval

    def _show(self, values: dict[str, object]) -> None:
        self.shown.update(values)

    # ---- the event phase (cotwin.cosim.clocks) ----
    def event_setter(self, names: list[str]) -> Callable[[Sequence], None]:
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        clocked = [(n, self.ports[n].type == "Boolean") for n in names if n in self.clocked]
        offered = self.offered

        def offer(values: Sequence) -> None:
            for (name, flag), value in zip(clocked, (v for n, v in zip(names, values) if n in self.clocked)):
                if value is None:
                    continue
                offered[name] = (bool(offered.get(name)) or bool(value)) if flag else value
        return offer

    def event(self, t: float) -> None:
        """Event Mode at t if a clock ticks there or the FMU asked for it; else its events are not occurring."""
        self.time = t
        eps = 1e-9 * max(1.0, abs(t))
        due = []
        for clock in self.clocks:
            at = self._tick_time(clock)
            if at < t - eps:
                raise UnitError(self.name, t, "fmi3SetClock", f"clock {clock.name} ticks at t = {at:.9g} s, between "
                                f"communication points: its interval {clock.interval:g} s must be a whole number "
                                "of steps")
            if abs(at - t) <= eps:
                due.append(clock)
        events = [n for n in self.shown if n in self.clocked and self.ports[n].type == "Boolean"]
        if not due and not self._pending:
            for n in events:
                self.shown[n] = False
            return
        if self.mode == "step":
            self._call("fmi3EnterEventMode", self.fmu.enterEventMode)
            self.mode = "event"
        if due:
            self._call("fmi3SetClock", self.fmu.setClock, [c.vr for c in due], [True] * len(due))
            if self.offered:
                self._set(self.offered)
        while True:
            need_update, terminate, *_ = self._call("fmi3UpdateDiscreteStates", self.fmu.updateDiscreteStates)
            if terminate:
                raise UnitError(self.name, t, "fmi3UpdateDiscreteStates", "the FMU asked to terminate the simulation")
            if not need_update:
                break
        for n in events:
            self.shown[n] = False
        self._show(self._get(list(self.shown)))
        for clock in due:
            clock.next += 1
        if due:
            self.ticks += 1
            self.delivered = dict(self.offered)
            for name in list(self.offered):
                if self.ports[name].type == "Boolean":
                    self.offered[name] = False
        self._pending = False

    # ---- stepping ----
    def step(self, t: float, h: float) -> None:
        self.time = t
        if self.mode == "event":
            self._call("fmi3EnterStepMode", self.fmu.enterStepMode)
            self.mode = "step"
        event, terminate, early, last = self._call("fmi3DoStep", self.fmu.doStep, t, h)
        if terminate:
            raise UnitError(self.name, t, "fmi3DoStep", "the FMU asked to terminate the simulation")
        if early and abs(last - (t + h)) > 1e-9 * max(1.0, abs(t + h)):
            raise UnitError(self.name, t, "fmi3DoStep", f"returned early at t = {last:.9g} s, which cotwin's "
                            "fixed-step master does not handle")
        self._pending = bool(event) and not any(abs(self._tick_time(c) - (t + h)) <= 1e-9 * max(1.0, t + h)
                                                for c in self.clocks)
        unclocked = [n for n in self.shown if n not in self.clocked]
        if unclocked:
            self._show(self._get(unclocked))
        self.time = t + h

    def get(self, names: list[str]) -> dict[str, object]:
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        values = {n: self.shown[n] for n in names if n in self.shown}
        rest = [n for n in names if n not in self.shown]
        if rest:
            values.update(self._get(rest))
        return values

    def getter(self, names: list[str]) -> Callable[[], Sequence]:
        names = list(names)
        unknown = [n for n in names if n not in self.ports]
        if unknown:
            raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
        if all(n in self.shown for n in names):
            shown = self.shown
            return lambda: [shown[n] for n in names]
        return super().getter(names)

    def terminate(self) -> None:
        if self.fmu is not None:
            if self.mode in ("initialization", "event", "step"):
                try:
                    self._call("fmi3Terminate", self.fmu.terminate)
                except UnitError:
                    pass
            if self.mode != "fatal":
                try:
                    self.fmu.freeInstance()
                except Exception:  # noqa: BLE001 - ending the instance must not hide the run's own error
                    pass
            self.fmu = None
        if self.folder:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None

    # ---- state ----
    @property
    def can_save_state(self) -> bool:
        cs = self.md.coSimulation
        return bool(cs.canGetAndSetFMUstate and cs.canSerializeFMUstate)

    def get_state(self) -> bytes:
        if not self.can_save_state:
            raise UnitError(self.name, self.time, "fmi3GetFMUState", "the FMU cannot save and serialise its state")
        handle = self._call("fmi3GetFMUState", self.fmu.getFMUState)
        try:
            raw = self._call("fmi3SerializeFMUState", self.fmu.serializeFMUState, handle)
        finally:
            self._call("fmi3FreeFMUState", self.fmu.freeFMUState, handle)
        return pack("FMU3", {"guid": self.md.guid, "time": self.time, "fmu": raw, "mode": self.mode,
                             "ticks": [c.next for c in self.clocks], "offered": dict(self.offered),
                             "shown": dict(self.shown), "pending": self._pending, "start": self.start,
                             "intervals": [c.interval for c in self.clocks]})

    def set_state(self, state: bytes) -> None:
        what = f"unit {self.name}"
        data = fields(unpack(state, "FMU3"), what, ("guid", "time", "fmu", "mode", "ticks", "offered", "shown", "pending"),
                      ("start", "intervals"))  # both absent from states of an earlier cotwin
        if data["guid"] != self.md.guid:
            raise UnitError(self.name, self.time, "fmi3SetFMUState",
                            f"the state is of another FMU (GUID {str(data['guid'])[:60]}, this one is {self.md.guid})")
        finite(data["time"], f"{what}'s time")
        if data["mode"] not in ("initialization", "event", "step"):
            raise StateError(f"the saved state's {what} is in mode {data['mode']!r:.40}, not one a state is taken in")
        ticks = of_type(data["ticks"], list, f"{what}'s clock ticks")
        if len(ticks) != len(self.clocks):
            raise StateError(f"the saved state's {what} has {len(ticks)} clocks, this FMU {len(self.clocks)}")
        for clock, k in zip(self.clocks, ticks):
            count(k, f"{what}'s tick of clock {clock.name}")
        start = finite(data.get("start", self.start), f"{what}'s start")
        intervals = clock_intervals(data, what)
        if intervals is not None:
            if len(intervals) != len(self.clocks):
                raise StateError(f"the saved state's {what} has {len(intervals)} clock intervals, this FMU {len(self.clocks)} "
                                 "clocks")
            for clock, interval in zip(self.clocks, intervals):
                if clock.interval is not None and abs(interval - clock.interval) > 1e-9 * max(1.0, interval):
                    raise StateError(f"the saved state's {what} ticks clock {clock.name} every {interval:g} s, this "
                                     f"one every {clock.interval:g} s: give it the saved period (cycle_period)")
        for key in ("offered", "shown"):
            for name, value in of_type(data[key], dict, f"{what}'s {key} values").items():
                if name not in self.ports:
                    raise StateError(f"the saved state's {what} has a value of {name!r:.60}, which it has no port of")
                port_value(value, self.ports[name].type, f"{what}'s {name}")
        of_type(data["pending"], bool, f"{what}'s pending event")
        of_type(data["fmu"], (bytes, bytearray), f"{what}'s FMU state")
        handle = self._call("fmi3DeserializeFMUState", self.fmu.deserializeFMUState, data["fmu"], fmi3FMUState())
        try:
            self._call("fmi3SetFMUState", self.fmu.setFMUState, handle)
        finally:
            self._call("fmi3FreeFMUState", self.fmu.freeFMUState, handle)
        self.time, self.mode, self._pending = data["time"], data["mode"], data["pending"]
        self.start = start  # the ticks' origin: a fork instantiated at the saved time ticks in the saved phase
        for clock, k in zip(self.clocks, data["ticks"]):
            clock.next = k
        self.offered.clear()
        self.offered.update(data["offered"])
        self.shown.clear()
        self.shown.update(data["shown"])


def clock_intervals(data: dict, what: str = "FMU3 unit") -> list[float] | None:
    """The clocks' intervals (s) in an FMU3Unit's state data (`unpack(state, "FMU3")`), None in a state of an
    earlier cotwin, which did not save them; StateError unless each is a positive number of seconds."""
    if "intervals" not in data:
        return None
    intervals = of_type(data["intervals"], list, f"{what}'s clock intervals")
    out = [finite(v, f"{what}'s clock interval") for v in intervals]
    if not all(v > 0 for v in out):
        raise StateError(f"the saved state's {what} has clock intervals {out!r:.60}, not positive numbers of seconds")
    return out


__all__ = ["FMU3Unit", "clock_intervals", "fmi_version", "fmu_unit"]
