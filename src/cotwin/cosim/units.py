"""Co-simulation units behind one interface: FMI 2.0 FMUs loaded with FMPy, and in-process Python units.

A unit has typed input and output ports, `initialize`, `set`, `step(t, h)`, `get` and `terminate`.
Every FMI call of an FMU that fails is raised as UnitError naming the unit, the time and the call.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from ..diagnostics import CotwinError


INT32 = (-(2 ** 31), 2 ** 31 - 1)


class UnitError(CotwinError):
    def __init__(self, unit: str, time: float, call: str, detail: str):
        super().__init__(f"unit {unit}: {call} failed at t = {time:g} s: {detail}")
        self.unit, self.time, self.call = unit, time, call


def checked_value(unit: str, port: "Port", value) -> object:
    """`value` as the port's FMI type, or CotwinError naming the port: integers must fit int32 (never
    wrapped), reals must be finite numbers, Booleans must be Booleans (or 0/1)."""
    kind = port.type
    if kind == "Boolean":
        if isinstance(value, bool):
            return value
        if isinstance(value, int) and value in (0, 1):
            return bool(value)
    elif kind == "Integer":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, int) and not isinstance(value, bool) and INT32[0] <= value <= INT32[1]:
            return value
        if isinstance(value, int) and not isinstance(value, bool):
            raise CotwinError(f"unit {unit}: {port.name} = {value} does not fit an FMI Integer (int32)")
    elif kind == "Real":
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
    raise CotwinError(f"unit {unit}: {port.name} takes a{'n' if kind[0] in 'IA' else ''} {kind}, "
                      f"not {value!r}" + (" (not finite)" if isinstance(value, float) else ""))


@dataclass(frozen=True)
class Port:
    name: str
    type: str  # Real | Integer | Boolean
    causality: str  # input | output | parameter


class Unit:
    """The interface the master drives."""

    name: str
    ports: dict[str, Port]

    def inputs(self) -> list[str]:
        return [p.name for p in self.ports.values() if p.causality == "input"]

    def outputs(self) -> list[str]:
        return [p.name for p in self.ports.values() if p.causality == "output"]

    def instantiate(self, start: float) -> None: ...
    def set(self, values: dict[str, object]) -> None: ...
    def initialize(self) -> None: ...
    def step(self, t: float, h: float) -> None: ...
    def get(self, names: list[str]) -> dict[str, object]: ...
    def terminate(self) -> None: ...


class FMUUnit(Unit):
    def __init__(self, name: str, path: str | Path):
        self.name = name
        self.path = Path(path)
        if not self.path.is_file():
            raise CotwinError(f"unit {name}: no FMU at {self.path}")
        try:
            self.md = read_model_description(str(self.path))
        except Exception as err:  # FMPy raises many kinds for a bad zip or XML
            raise CotwinError(f"unit {name}: cannot read {self.path}: {err}") from None
        if self.md.coSimulation is None:
            raise CotwinError(f"unit {name}: {self.path} is not a co-simulation FMU")
        self.ports = {}
        self.vr = {}
        for v in self.md.modelVariables:
            if v.type in ("Real", "Integer", "Boolean") and v.causality in ("input", "output", "parameter"):
                self.ports[v.name] = Port(v.name, v.type, v.causality)
                self.vr[v.name] = v.valueReference
        self.fmu = None
        self.folder = None
        self.time = 0.0
        self.status = "new"  # new | instantiated | error | fatal
        self._plans: dict[tuple[str, ...], list] = {}

    def _call(self, call: str, fn, *args):
        """Every FMI call goes through here: a failure becomes a UnitError naming the unit, the time and
        the call, and the unit remembers an fmi2Error or fmi2Fatal so that `terminate` only makes the
        calls FMI still allows."""
        try:
            return fn(*args)
        except Exception as err:  # FMPy raises FMICallException, ctypes and OS errors their own kinds
            status = getattr(err, "status", None)
            self.status = "fatal" if status == 4 else "error"
            raise UnitError(self.name, self.time, call, str(err)) from None

    def instantiate(self, start: float) -> None:
        self.time = start
        try:
            self.folder = extract(str(self.path))
        except Exception as err:  # a bad zip
            raise UnitError(self.name, start, "extract", str(err)) from None
        self.fmu = self._call("load", lambda: FMU2Slave(
            guid=self.md.guid, unzipDirectory=self.folder, modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=self.name))
        try:
            self._call("fmi2Instantiate", self.fmu.instantiate)
        except UnitError:
            self.fmu = None  # no instance: nothing to free
            raise
        self.status = "instantiated"
        self._call("fmi2SetupExperiment", lambda: self.fmu.setupExperiment(startTime=start))
        self._call("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)

    def _plan(self, names: tuple[str, ...]) -> list[tuple[str, list[str], list[int]]]:
        """Ports grouped by FMI type with their value references, computed once per list of names
        (the master asks for the same ports every step)."""
        plan = self._plans.get(names)
        if plan is None:
            unknown = [n for n in names if n not in self.ports]
            if unknown:
                raise CotwinError(f"unit {self.name} has no port(s) {', '.join(unknown)}")
            plan = []
            for kind in ("Real", "Integer", "Boolean"):
                chosen = [n for n in names if self.ports[n].type == kind]
                if chosen:
                    plan.append((kind, chosen, [self.vr[n] for n in chosen]))
            self._plans[names] = plan
        return plan

    def set(self, values: dict[str, object]) -> None:
        for kind, names, refs in self._plan(tuple(values)):
            checked = [checked_value(self.name, self.ports[n], values[n]) for n in names]
            if kind == "Real":
                self._call("fmi2SetReal", self.fmu.setReal, refs, checked)
            elif kind == "Integer":
                self._call("fmi2SetInteger", self.fmu.setInteger, refs, checked)
            else:
                self._call("fmi2SetBoolean", self.fmu.setBoolean, refs, checked)

    def initialize(self) -> None:
        self._call("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)

    def step(self, t: float, h: float) -> None:
        self.time = t
        self._call("fmi2DoStep", lambda: self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h))

    def get(self, names: list[str]) -> dict[str, object]:
        out = {}
        for kind, chosen, refs in self._plan(tuple(names)):
            if kind == "Real":
                out.update(zip(chosen, self._call("fmi2GetReal", self.fmu.getReal, refs)))
            elif kind == "Integer":
                out.update(zip(chosen, self._call("fmi2GetInteger", self.fmu.getInteger, refs)))
            else:
                out.update((n, bool(v)) for n, v in zip(chosen, self._call("fmi2GetBoolean", self.fmu.getBoolean, refs)))
        return out

    def terminate(self) -> None:
        """End the instance as FMI 2.0 allows from its state: fmi2Terminate then fmi2FreeInstance when
        healthy, only fmi2FreeInstance after an fmi2Error, and no call at all after fmi2Fatal (the FMU's
        memory is then leaked rather than touched)."""
        if self.fmu is not None:
            if self.status == "instantiated":
                try:
                    self.fmu.terminate()
                except Exception:  # noqa: BLE001 - still free the instance
                    pass
            if self.status != "fatal":
                try:
                    self.fmu.freeInstance()
                except Exception:  # noqa: BLE001
                    pass
            self.fmu = None
        if self.folder:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None


class PythonUnit(Unit):
    """An in-process unit: subclasses keep their port values in `self.values`."""

    def __init__(self, name: str, ports: list[Port]):
        self.name = name
        self.ports = {p.name: p for p in ports}
        self.values: dict[str, object] = {p.name: (False if p.type == "Boolean" else 0) for p in ports}

    def instantiate(self, start: float) -> None:
        self.time = start

    def set(self, values: dict[str, object]) -> None:
        for name, value in values.items():
            if name not in self.ports:
                raise CotwinError(f"unit {self.name} has no port '{name}'")
            self.values[name] = value

    def initialize(self) -> None:
        pass

    def get(self, names: list[str]) -> dict[str, object]:
        return {n: self.values[n] for n in names}

    def terminate(self) -> None:
        pass
