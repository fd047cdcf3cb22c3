"""The platform-mapping co-simulation unit: the d-model's operation calls in, the platform's events out.

Its ports are the d-model FMU's with causalities swapped (one naming function: cotwin.dmodel.fmu),
minus the command events the scenario drives, plus the mapping's monitored variables (q0.., qd0..).
In a step: run the operations called in it, let the platform move for h, then report which events occur
in it (`Mapping.report`: an answer is true in the one step it comes, never held from a previous request)
and the values they carry (a value port keeps its last value while its event does not occur).
"""

from __future__ import annotations

from typing import Callable

from ...diagnostics import CotwinError
from ...cosim.units import Port, PythonUnit
from ...plaindata import fields, finite, of_type, port_value
from ...dmodel.ports import PortLayout
from ...dmodel.program import Program, assemble, get_path
from ...mapping.runtime import Mapping


def mapping_ports(program: Program, mapped_events: set[str], commands: set[str], monitored: list[str]) -> list[Port]:
    """The mapping unit's ports, from the models alone: the d-model FMU's outputs (but its `state`) as
    inputs; the platform events the mapping defines (but the scenario's commands) and the monitored
    variables as outputs."""
    layout = PortLayout(program)
    ports = [Port(v.name, v.fmi_type, "input") for v in layout.variables
             if v.causality == "output" and v.name not in layout.state_ports]
    for ev in program.inputs:
        if ev.name not in commands and ev.name in mapped_events:
            ports.append(Port(ev.name, "Boolean", "output"))
            ports.extend(Port(name, sc.fmi_type, "output") for name, sc in ev.value_ports)
    ports.extend(Port(name, "Real", "output") for name in monitored)
    return ports


class MappingUnit(PythonUnit):
    """`mapping` is a Mapping, or a function making one when the unit is instantiated (then `events` and
    `monitored` give the ports), so that describing the unit (e.g. packaging it as an FMU) never
    connects to its platform."""

    def __init__(self, name: str, program: Program, mapping: Mapping | Callable[[], Mapping], commands: set[str],
                 events: set[str] | None = None, monitored: list[str] | None = None):
        made = isinstance(mapping, Mapping)
        events = set(mapping.events) if made else set(events or ())
        monitored = list(mapping.monitored) if made else list(monitored or [])
        super().__init__(name, mapping_ports(program, events, commands, monitored))
        self.program = program
        self.mapping: Mapping | None = mapping if made else None
        self._make = None if made else mapping
        self.monitored = monitored
        self.event_ports = [p for p in self.ports.values() if p.causality == "output" and p.name in events]
        self.value_ports = {ev.name: [(name, sc) for name, sc in ev.value_ports] for ev in program.inputs
                            if ev.name in self.ports and ev.name in events and ev.value_ports}
        self.calls: list = []
        self.executed: list[tuple[float, str, dict]] = []  # (step start time, operation, arguments)
        self._ran: float | None = None  # the start of the step the native loop ran the operations of and left to Python

    def instantiate(self, start: float) -> None:
        super().instantiate(start)
        if self.mapping is None:
            self.mapping = self._make()
        self.calls = [(op.name, list(zip((p for p, _ in op.params), op.arg_ports)))
                      for op in self.program.operations if op.name in self.mapping.operations]
        self.mapping.start_mapping()
        self._report()

    def step(self, t: float, h: float) -> None:
        self.act(t)
        self.mapping.step(h)
        self.reached(t + h)

    def act(self, t: float) -> None:
        """The step's first half: run the operations the d-model called (a cell of several robots acts
        for each, steps their shared world once, then has each report: cotwin.twin.assembly.cell); once for
        the step starting at t (the native loop may have run them before the step it then left to Python)."""
        ran, self._ran = self._ran, None
        if ran == t:
            return
        for op, params in self.calls:
            if self.values.get(op):
                args = {p: assemble(group, self.values.__getitem__) for p, group in params}
                self.mapping.execute_operation(op, args)
                self.executed.append((t, op, args))

    def reached(self, time: float) -> None:
        """The step's second half, once the platform has moved: the events and monitored values at `time`."""
        self.time = time
        self._report()

    def _report(self) -> None:
        occurring = self.mapping.report()
        for port in self.event_ports:
            occurs, value = occurring[port.name]
            self.values[port.name] = occurs
            if occurs and port.name in self.value_ports:
                for name, sc in self.value_ports[port.name]:
                    v = get_path(value, sc.path) if sc.path else value
                    self.values[name] = float(v) if sc.fmi_type == "Real" else v
        for name in self.mapping.monitored:
            self.values[name] = float(self.mapping.variables[name])

    def native_part(self, execution):
        """Its quiet step for the native loop (cotwin.mapping.cstep.QuietStep: the platform moves, the mirrors and
        events in C), or why it has none; after a stretch, its ports and time as `step` leaves them."""
        from ...cosim.native import NativePart, feeds, outputs
        from ...mapping.cstep import QuietStep

        out = outputs(execution, self)
        if any(p.name not in out for p in self.event_ports) or any(m not in out for m in self.monitored):
            return "an output of the mapping is not observed"
        calls = {op for op, _ in self.calls}
        fed = feeds(execution, self)
        quiet = QuietStep(self.mapping, execution.step_size, [slot for name, slot in fed if name in calls],
                          {p.name: out[p.name] for p in self.event_ports}, {m: out[m] for m in self.monitored})
        if quiet.why is not None:
            return quiet.why
        data, jacobi = execution.algorithm.data, execution.algorithm.name == "jacobi"
        events = [(p.name, out[p.name]) for p in self.event_ports]
        monitored = [(name, out[name]) for name in self.monitored]
        write = execution.algorithm.writes[execution.algorithm.units.index(self)]

        def prepare() -> bool:
            """The operations called, run as the step's first half (act) before the segment's first step."""
            if not quiet.calling:
                return True
            if write is not None:  # its inputs as the step reads them (the native loop set those of the step before)
                setter, pick = write
                setter(pick(data))
            origin, done = execution._origin
            t = origin + (execution.steps - done) * execution.step_size
            self.act(t)
            if quiet.acted():
                return True
            self._ran = t  # the step is made in Python, which must not run them again
            return False

        def end(first: int, made: int, rows, doubles) -> None:
            quiet.end(made, doubles)
            if made and len(rows):
                last, values = rows[-1].tolist(), self.values  # Python floats, as float() of each made them
                for port, slot in events:
                    values[port] = last[slot] != 0.0
                for name, slot in monitored:
                    values[name] = last[slot]
            if made:
                origin, done = execution._origin
                self.time = origin + (first + made - 1 - done) * execution.step_size + execution.step_size

        return NativePart("\n".join(quiet.lines), decls=quiet.decls, pointers=quiet.pointers, doubles=quiet.doubles,
                          quiet=lambda n: quiet.quiet(n, data, jacobi), begin=quiet.begin, end=end, prepare=prepare,
                          ready=quiet.ready, takes=frozenset(name for name, _ in fed),
                          failed=quiet.failed, continuous=tuple(self.monitored),
                          writes=frozenset(p.name for p in self.event_ports) | frozenset(self.monitored),
                          refusal=lambda: quiet.refusal, include_dirs=quiet.headers[0] if quiet.headers else ())

    def terminate(self) -> None:
        if self.mapping is not None and self.mapping.started:
            self.mapping.stop_mapping()

    # ---- state: the port values, the mapping runtime's (variables, platform) and the operations run ----
    STATE_KEYS = (*PythonUnit.STATE_KEYS, "mapping", "executed")

    def snapshot(self) -> dict:
        return {**super().snapshot(), "mapping": self.mapping.snapshot(), "executed": list(self.executed)}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked first (cotwin.plaindata): the operations run (known operations at
        finite times), the events' values (each value port's scalar where the unit reads it), then the
        mapping's own state and the port values."""
        if self.mapping is None:
            raise CotwinError(f"unit {self.name}: instantiate it before restoring a state into it")
        what = f"unit {self.name}"
        fields(snapshot, what, self.STATE_KEYS)
        executed = of_type(snapshot["executed"], list, f"{what}'s operations run")
        operations = {op.name for op in self.program.operations}
        for entry in executed:
            if entry.__class__ is not tuple or len(entry) != 3 or entry[1] not in operations or \
                    entry[2].__class__ is not dict:
                raise CotwinError(f"the saved state's {what} ran {entry!r:.80}, not (time, operation, arguments)")
            finite(entry[0], f"{what}'s operation time")
        events = fields(snapshot["mapping"], f"{what}'s mapping", Mapping.STATE_KEYS,
                        Mapping.OPTIONAL_STATE_KEYS).get("events", {})
        for name, scalars in self.value_ports.items():
            value = events.get(name) if events.__class__ is dict else None
            for port, sc in scalars if value is not None else ():
                try:
                    scalar = get_path(value, sc.path) if sc.path else value
                except (KeyError, IndexError, TypeError):
                    raise CotwinError(f"the saved state's {what}: event {name}'s value {value!r:.80} has no "
                                      f"{'.'.join(map(str, sc.path))}") from None
                port_value(scalar, sc.fmi_type, f"{what}'s event {name} ({port})")
        super().restore(snapshot)
        self.mapping.restore(snapshot["mapping"])
        self.executed = list(executed)
