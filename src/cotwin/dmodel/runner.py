"""Drive a built d-model FMU with the interpreter's vocabulary (events in, outputs out), through the
co-simulation's FMU unit (so every FMI call is checked the same way).

Used by differential tests and benchmarks: same inputs as `Interpreter.step`, same `Output` list back.
"""

from __future__ import annotations

from pathlib import Path

from ..cosim.units import FMUUnit
from .interpreter import Output
from .ports import PortLayout
from .program import Program, assemble, get_path


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


def outputs_of(program: Program, read) -> list[Output]:
    """The operation calls and output events an FMU's output ports show (`read(port)` -> value), in the
    program's port order."""
    out = []
    for op in program.operations:
        if read(op.name):
            out.append(Output("operation", op.name, tuple(assemble(group, read) for group in op.arg_ports)))
    for ev in program.outputs:
        if read(ev.name):
            out.append(Output("event", ev.name, (assemble(ev.value_ports, read),) if ev.value_ports else ()))
    return out


def inputs_of(program: Program, read) -> dict:
    """The input events an FMU's input ports hold (`read(port)` -> value): {event: value or None}."""
    return {ev.name: (assemble(ev.value_ports, read) if ev.value_ports else None)
            for ev in program.inputs if read(ev.name)}
