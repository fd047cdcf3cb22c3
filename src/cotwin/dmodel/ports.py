"""The FMU ports of a d-model module, as plain data: every scalar variable with its value reference,
FMI type, causality and where its value lives in the model. The packager (modelDescription.xml and
the FMI wrapper), the FMU runner, the mapping unit and the twin's wiring all read this one layout.

Ports (docs/interop.md): an input event is a Boolean input true in the step it occurs, plus one
input per value field; an operation call is a Boolean output plus its arguments (operations share an
argument port when name and type agree); output events likewise; `state` is the index of the active
leaf state; constants without a value are parameters; `cycle_period` sets cycles per step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError, Finding, Severity
from .program import Program, fmi_type

SLOT_ARRAY = {"Real": "r", "Integer": "i", "Boolean": "b"}


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    fmi_type: str  # Real | Integer | Boolean
    causality: str  # parameter | input | output
    variability: str  # fixed | discrete
    start: object | None
    slot: int  # index into the wrapper's array of that type
    description: str = ""


@dataclass(frozen=True)
class ValuePort:
    """One scalar of an event's value or an operation's argument: its variable and path into records."""

    var: Variable
    path: tuple[str, ...]


@dataclass(frozen=True)
class EventPorts:
    name: str
    flag: Variable
    values: tuple[ValuePort, ...]


@dataclass(frozen=True)
class CallPorts:
    name: str
    flag: Variable
    args: tuple[tuple[str, tuple[ValuePort, ...]], ...]  # (parameter name, its scalars)


@dataclass(frozen=True)
class ParameterPort:
    var: Variable
    machine: int
    name: str


@dataclass(frozen=True)
class StatePort:
    var: Variable
    machine: int
    leaves: tuple[str, ...]


@dataclass
class PortLayout:
    """Every port of the module's FMU, in value-reference order (see module doc)."""

    program: Program
    variables: list[Variable] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=lambda: {"Real": 0, "Integer": 0, "Boolean": 0})
    parameters: list[ParameterPort] = field(default_factory=list)
    inputs: list[EventPorts] = field(default_factory=list)
    operations: list[CallPorts] = field(default_factory=list)
    outputs: list[EventPorts] = field(default_factory=list)
    states: list[StatePort] = field(default_factory=list)

    def __post_init__(self) -> None:
        p = self.program
        self.period = self._add("cycle_period", "Real", "parameter", "fixed", 0.0,
                                "seconds per d-model cycle; 0 = one cycle per FMU step")
        unportable = list(dict.fromkeys((port.loc, f"{port.unportable}: it cannot cross the FMU boundary")
                                        for port in (*p.inputs, *p.outputs, *p.operations) if port.unportable))
        if unportable:  # each where its event or operation is declared
            raise CotwinError([Finding(loc, Severity.ERROR, message) if loc is not None else message
                               for loc, message in unportable])
        for par in p.parameters:
            owner = (f"constant {par.name} of state machine {p.machines[par.machine].machine.name}"
                     if par.machine >= 0 else "seed of the pseudo-random source (uninterpreted functions, "
                     "Mathematics::random)")
            var = self._add(par.port, fmi_type(par.ty), "parameter", "fixed", par.default, owner)
            self.parameters.append(ParameterPort(var, par.machine, par.name))
        for ev in p.inputs:
            flag = self._add(ev.name, "Boolean", "input", "discrete", False, f"input event {ev.name}")
            values = tuple(ValuePort(self._add(port, sc.fmi_type, "input", "discrete",
                                               False if sc.fmi_type == "Boolean" else 0), sc.path)
                           for port, sc in ev.value_ports)
            self.inputs.append(EventPorts(ev.name, flag, values))
        shared: dict[str, Variable] = {}
        for op in p.operations:
            flag = self._add(op.name, "Boolean", "output", "discrete", None, f"operation {op.name} called")
            args = []
            for (pname, _), group in zip(op.params, op.arg_ports):
                scalars = []
                for port, sc in group:
                    var = shared.get(port) or self._add(port, sc.fmi_type, "output", "discrete", None)
                    shared[port] = var
                    scalars.append(ValuePort(var, sc.path))
                args.append((pname, tuple(scalars)))
            self.operations.append(CallPorts(op.name, flag, tuple(args)))
        for ev in p.outputs:
            flag = self._add(ev.name, "Boolean", "output", "discrete", None, f"output event {ev.name}")
            values = tuple(ValuePort(self._add(port, sc.fmi_type, "output", "discrete", None), sc.path)
                           for port, sc in ev.value_ports)
            self.outputs.append(EventPorts(ev.name, flag, values))
        for m in p.machines:
            leaves = tuple(p.leaf_names(m))
            names = ", ".join(f"{k}={n}" for k, n in enumerate(leaves))
            var = self._add(p.state_port(m), "Integer", "output", "discrete", None,
                            f"active leaf state of {m.machine.name}: {names}; -1 = none")
            self.states.append(StatePort(var, m.index, leaves))

    def _add(self, name, fmi, causality, variability, start, description="") -> Variable:
        if any(v.name == name for v in self.variables):
            raise CotwinError(f"two FMU ports would be called '{name}'; rename an event, operation or parameter")
        var = Variable(name, len(self.variables), fmi, causality, variability, start, self.counts[fmi], description)
        self.counts[fmi] += 1
        self.variables.append(var)
        return var

    @property
    def state_ports(self) -> set[str]:
        return {s.var.name for s in self.states}

    def by_name(self) -> dict[str, Variable]:
        return {v.name: v for v in self.variables}

    @staticmethod
    def slot(var: Variable) -> str:
        """The wrapper's storage of a variable: `r[3]`, `i[0]`, `b[2]`."""
        return f"{SLOT_ARRAY[var.fmi_type]}[{var.slot}]"
