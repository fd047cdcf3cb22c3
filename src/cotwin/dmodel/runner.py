"""A d-model FMU's ports read with the interpreter's vocabulary: the operation calls and output events its
outputs show, the input events its inputs hold. The FMU itself is driven one level up, through the
co-simulation's FMU unit (cotwin.cosim.driver.FMUDriver), so that this package stays below cotwin.cosim.
"""

from __future__ import annotations

from .interpreter import Output
from .program import Program, assemble


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
