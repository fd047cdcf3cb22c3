"""Drive a built d-model FMU with the interpreter's vocabulary (events in, outputs out), through the
co-simulation's FMU unit (so every FMI call is checked the same way).

Used by differential tests and benchmarks: same inputs as `Interpreter.step`, same `Output` list back.
"""

from __future__ import annotations

from pathlib import Path

from ..dmodel.interpreter import Output
from ..dmodel.ports import PortLayout
from ..dmodel.program import Program, get_path
from ..dmodel.runner import outputs_of
from .units import FMUUnit


class FMUDriver:
    def __init__(self, program: Program, fmu_path: str | Path, parameters: dict | None = None,
                 step_size: float = 1.0, instance_name: str = "dmodel"):
        self.program = program
        self.layout = PortLayout(program)
        self.vr = {v.name: v for v in self.layout.variables}
        self.unit = FMUUnit(instance_name, fmu_path)
        self.unit.instantiate(0.0)
        if parameters:
            self.unit.set(dict(parameters))
        self.unit.initialize()
        self.time = 0.0
        self.h = step_size
        self._events = [ev.name for ev in program.inputs]

    def _set(self, name: str, value) -> None:
        kind = self.vr[name].fmi_type
        self.unit.set({name: float(value) if kind == "Real" else int(value) if kind == "Integer" else bool(value)})

    def _get(self, name: str):
        return self.unit.get([name])[name]

    def step(self, inputs: dict | None = None) -> list[Output]:
        inputs = inputs or {}
        for ev in self.program.inputs:
            present = ev.name in inputs
            self._set(ev.name, present)
            if present and ev.ty is not None:
                for port, sc in ev.value_ports:
                    value = inputs[ev.name]
                    self._set(port, get_path(value, sc.path) if sc.path else value)
        self.unit.step(self.time, self.h)
        self.time += self.h
        return self.outputs()

    def outputs(self) -> list[Output]:
        """The operation calls and output events of the last step, in the program's port order."""
        return outputs_of(self.program, self._read)

    def _read(self, port: str):
        value = self._get(port)
        return float(value) if self.vr[port].fmi_type == "Real" else value

    def state(self, machine: int = 0) -> int:
        return self._get(self.program.state_port(self.program.machines[machine]))

    def close(self) -> None:
        self.unit.terminate()
