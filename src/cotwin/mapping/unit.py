"""The platform-mapping co-simulation unit: the d-model's operation calls in, the platform's events out.

Its ports are the d-model FMU's with causalities swapped (one naming function: cotwin.dmodel.fmu),
minus the command events the scenario drives, plus the mapping's monitored variables (q0.., qd0..).
In a step: run the operations called in it, let the platform move for h, then report which events hold.
"""

from __future__ import annotations

from ..cosim.units import Port, PythonUnit
from ..dmodel.fmu import PortLayout
from ..dmodel.program import Program
from .runtime import Mapping


def mapping_ports(program: Program, mapping: Mapping, commands: set[str]) -> list[Port]:
    layout = PortLayout(program)
    ports = []
    for var in layout.variables:
        if var.causality == "output" and not var.name.startswith("state"):
            ports.append(Port(var.name, var.fmi_type, "input"))
    for ev in program.inputs:
        if ev.name not in commands and ev.name in mapping.events:
            ports.append(Port(ev.name, "Boolean", "output"))
    for name in mapping.monitored:
        ports.append(Port(name, "Real", "output"))
    return ports


class MappingUnit(PythonUnit):
    def __init__(self, name: str, program: Program, mapping: Mapping, commands: set[str]):
        super().__init__(name, mapping_ports(program, mapping, commands))
        self.program = program
        self.mapping = mapping
        self.calls = [(op.name, [(p, [port for port, _ in group]) for (p, _), group in zip(op.params, op.arg_ports)])
                      for op in program.operations if op.name in mapping.operations]
        self.event_ports = [p for p in self.ports.values() if p.causality == "output" and p.name in mapping.events]
        self.executed: list[tuple[float, str, dict]] = []  # (step start time, operation, arguments)

    def instantiate(self, start: float) -> None:
        super().instantiate(start)
        self.mapping.start_mapping()
        self._report()

    def step(self, t: float, h: float) -> None:
        for op, params in self.calls:
            if self.values.get(op):
                args = {p: self.values[ports[0]] for p, ports in params if len(ports) == 1}
                self.mapping.execute_operation(op, args)
                self.executed.append((t, op, args))
        self.mapping.step(h)
        self._report()

    def _report(self) -> None:
        for port in self.event_ports:
            self.values[port.name] = self.mapping.get_event(port.name)
        for name in self.mapping.monitored:
            self.values[name] = float(self.mapping.variables[name])

    def terminate(self) -> None:
        if self.mapping.started:
            self.mapping.stop_mapping()
