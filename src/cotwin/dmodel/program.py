"""A module flattened for execution: its machines, how events are routed, and its FMU ports.

The interpreter, the C generator, the FMU builder and the verifier all start from this one view, so
that port names, value encodings and event routes cannot drift apart.

Value encoding (shared with the generated C): boolean -> bool, int/nat -> int, real -> float,
enumeration -> index of the literal (int), record -> dict of field values (a struct in C).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError, Diagnostics
from ..robosim import syntax as s
from ..robosim.consteval import ConstEnv, ConstError, evaluate
from ..robosim.declarations import EventDecl, OperationSig, SourceFile
from ..robosim.dmodel_elements import Controller, Module, StateMachine
from ..robosim.interfaces import machine_io, platform_members
from ..robosim.machines import MachineGraph
from ..robosim.project import Project
from ..robosim.types import (
    BOOL, INT, NAT, REAL, EnumTy, RecordTy, Ty, TypeResolver,
)


@dataclass(frozen=True)
class Scalar:
    """One FMI scalar of a structured value: its name suffix, FMI type and path into the value."""

    suffix: str
    fmi_type: str  # Boolean | Integer | Real
    path: tuple[str, ...]  # field names into nested records
    ty: Ty


def fmi_type(ty: Ty) -> str:
    if ty == BOOL:
        return "Boolean"
    if ty in (INT, NAT) or isinstance(ty, EnumTy):
        return "Integer"
    if ty == REAL:
        return "Real"
    raise CotwinError(f"values of type {ty} cannot be FMU ports (only boolean, int, nat, real, enumerations and records of them)")


def scalars(ty: Ty, resolver: TypeResolver, prefix: str = "", path: tuple[str, ...] = ()) -> list[Scalar]:
    """Flatten a (record) type into scalars: record fields become `prefix_field` names."""
    if isinstance(ty, RecordTy):
        out: list[Scalar] = []
        for f in ty.decl.fields:
            name = f"{prefix}_{f.name}" if prefix else f.name
            out.extend(scalars(resolver.resolve(f.type), resolver, name, path + (f.name,)))
        return out
    return [Scalar(prefix, fmi_type(ty), path, ty)]


def set_path(value: dict, path: tuple[str, ...], leaf) -> None:
    """Store one scalar into a (nested) record dict at its field path."""
    for key in path[:-1]:
        value = value.setdefault(key, {})
    value[path[-1]] = leaf


def get_path(value, path: tuple[str, ...]):
    for key in path:
        value = value[key]
    return value


def assemble(group: list[tuple[str, "Scalar"]], read) -> object:
    """A value from its scalar ports: read(port) for each; a record dict, or the single scalar."""
    if len(group) == 1 and not group[0][1].path:
        return read(group[0][0])
    value: dict = {}
    for port, sc in group:
        set_path(value, sc.path, read(port))
    return value


def executable(ty: Ty, resolver: TypeResolver) -> bool:
    """Types the interpreter and the C code can hold: boolean, int, nat, real, enumerations, and
    records of these."""
    if isinstance(ty, RecordTy):
        return all(executable(resolver.resolve(f.type), resolver) for f in ty.decl.fields)
    return ty in (BOOL, INT, NAT, REAL) or isinstance(ty, EnumTy)


def default_value(ty: Ty, resolver: TypeResolver):
    if isinstance(ty, RecordTy):
        return {f.name: default_value(resolver.resolve(f.type), resolver) for f in ty.decl.fields}
    if ty == BOOL:
        return False
    if ty == REAL:
        return 0.0
    return 0


@dataclass
class EventPort:
    """An event crossing the module boundary (input from or output to the platform)."""

    name: str
    ty: Ty | None
    value_ports: list[tuple[str, Scalar]] = field(default_factory=list)  # (port name, scalar)


@dataclass
class OperationPort:
    name: str
    params: list[tuple[str, Ty]]
    arg_ports: list[list[tuple[str, Scalar]]] = field(default_factory=list)  # per parameter


@dataclass
class Parameter:
    """A constant of a machine without a value in the model: an FMU parameter (default 0)."""

    machine: int
    name: str
    port: str
    ty: Ty
    default: object


@dataclass
class MachineInstance:
    index: int
    name: str  # unique within the module, e.g. "sm" or "ctrl_sm"
    machine: StateMachine
    graph: MachineGraph
    source: SourceFile | None
    variables: list[tuple[str, Ty, s.Expr | None]]  # var declarations (and consts with a value)
    constants: dict[str, object]  # consts with a value, evaluated
    parameters: list[str]  # consts without a value
    inputs: dict[str, Ty | None]
    outputs: dict[str, Ty | None]
    operations: dict[str, OperationSig]


@dataclass
class Program:
    project: Project
    module: Module
    resolver: TypeResolver
    inputs: list[EventPort]
    outputs: list[EventPort]
    operations: list[OperationPort]
    machines: list[MachineInstance]
    parameters: list[Parameter]
    #: platform input event -> [(machine index, machine's event name)]
    input_routes: dict[str, list[tuple[int, str]]]
    #: (machine index, machine event) -> platform output event
    output_routes: dict[tuple[int, str], str]
    #: (machine index, machine event) -> [(machine index, event)], delivered one cycle later
    internal_routes: dict[tuple[int, str], list[tuple[int, str]]]

    def state_port(self, machine: MachineInstance) -> str:
        return "state" if len(self.machines) == 1 else f"state_{machine.name}"

    def leaf_names(self, machine: MachineInstance) -> list[str]:
        return [".".join(n.path) for n in machine.graph.leaves]


# ---- building -------------------------------------------------------------------------------


class _Builder:
    def __init__(self, project: Project, module: Module):
        self.project = project
        self.module = module
        self.source = project.file_of(module)
        self.diag = Diagnostics()
        self.resolver = TypeResolver(project, self.source, self.diag)

    def event_type(self, ev: EventDecl | None) -> Ty | None:
        if ev is None or ev.type is None:
            return None
        return self.resolver.resolve(ev.type)

    def build(self) -> Program:
        module = self.module
        if module.platform is None:
            raise CotwinError(f"module {module.name} has no robotic platform")
        members = platform_members(self.project, module.platform, self.source)
        machines: list[MachineInstance] = []
        controllers: list[tuple[str, Controller]] = []
        for ref in module.controller_refs:
            ctrl = self.project.lookup("controller", ref.target, self.source)
            controllers.append((ref.name, ctrl))
        controllers.extend((c.name, c) for c in module.controllers)
        # (controller node name, machine node name) -> machine index
        node_of: dict[tuple[str, str], int] = {}
        for ctrl_name, ctrl in controllers:
            refs = [(r.name, self.project.lookup("stm", r.target, self.project.file_of(ctrl) or self.source))
                    for r in ctrl.machine_refs]
            refs.extend((m.name, m) for m in ctrl.machines)
            for local, machine in refs:
                name = local if len(controllers) == 1 else f"{ctrl_name}_{local}"
                node_of[(ctrl_name, local)] = len(machines)
                machines.append(self.instance(len(machines), name, machine))
        inputs = {e.name: self.event_type(e) for e in members.events.values()}
        input_routes: dict[str, list[tuple[int, str]]] = {}
        output_routes: dict[tuple[int, str], str] = {}
        internal: dict[tuple[int, str], list[tuple[int, str]]] = {}
        platform = module.platform.name
        ctrl_by_name = dict(controllers)

        def into_controller(ctrl_name: str, event: str) -> list[tuple[int, str]]:
            ctrl = ctrl_by_name.get(ctrl_name)
            if ctrl is None:
                return []
            return [
                (node_of[(ctrl_name, c.target)], c.target_event)
                for c in ctrl.connections
                if c.source == ctrl.name and c.source_event == event and (ctrl_name, c.target) in node_of
            ]

        used_outputs: set[str] = set()
        for c in module.connections:
            if c.source == platform:
                input_routes.setdefault(c.source_event, []).extend(into_controller(c.target, c.target_event))
        for ctrl_name, ctrl in controllers:
            for c in ctrl.connections:
                if (ctrl_name, c.source) not in node_of:
                    continue
                src = (node_of[(ctrl_name, c.source)], c.source_event)
                if (ctrl_name, c.target) in node_of:  # machine to machine
                    internal.setdefault(src, []).append((node_of[(ctrl_name, c.target)], c.target_event))
                elif c.target == ctrl.name:  # leaves the controller
                    for mc in module.connections:
                        if mc.source == ctrl_name and mc.source_event == c.target_event:
                            if mc.target == platform:
                                output_routes[src] = mc.target_event
                                used_outputs.add(mc.target_event)
                            else:
                                internal.setdefault(src, []).extend(into_controller(mc.target, mc.target_event))
        input_ports = [self.event_port(name, inputs[name]) for name in inputs if name in input_routes]
        output_ports = [self.event_port(name, inputs[name]) for name in inputs if name in used_outputs]
        self.disambiguate([*input_ports, *output_ports])
        operations = [OperationPort(op.name, [(p.name, self.resolver.resolve(p.type)) for p in op.params])
                      for op in members.operations.values()]
        self.argument_ports(operations)
        parameters = []
        for m in machines:
            for const in m.parameters:
                ty = next(t for n, t, _ in self.const_decls(m.machine) if n == const)
                port = const if len(machines) == 1 else f"{m.name}_{const}"
                parameters.append(Parameter(m.index, const, port, ty, default_value(ty, self.resolver)))
        self.diag.raise_if_errors()
        return Program(self.project, module, self.resolver, input_ports, output_ports, operations, machines,
                       parameters, input_routes, output_routes, internal)

    def const_decls(self, machine: StateMachine):
        return [(v.name, self.resolver.resolve(v.type), v.init) for v in machine.variables if v.is_const]

    def instance(self, index: int, name: str, machine: StateMachine) -> MachineInstance:
        source = self.project.file_of(machine) or self.source
        io = machine_io(self.project, machine, source)
        resolver = TypeResolver(self.project, source, self.diag)
        env = ConstEnv({v.name: v.init for v in machine.variables if v.is_const and v.init is not None})
        constants = {}
        for v in machine.variables:
            if v.is_const and v.init is not None:
                try:
                    constants[v.name] = _coerce(evaluate(v.init, env), resolver.resolve(v.type))
                except ConstError as err:
                    raise CotwinError(f"{err.loc}: constant {v.name}: {err.message}") from None
        variables = [(v.name, resolver.resolve(v.type), v.init) for v in machine.variables if not v.is_const]
        for v in machine.variables:
            ty = resolver.resolve(v.type)
            if not executable(ty, resolver):
                self.diag.error(v.loc, f"{v.name}: values of type {ty} cannot be executed yet "
                                "(boolean, int, nat, real, enumerations and records of them can)")
        parameters = [v.name for v in machine.variables if v.is_const and v.init is None]
        return MachineInstance(
            index, name, machine, MachineGraph(machine), source, variables, constants, parameters,
            {n: self.event_type(e) for n, e in io.inputs.items()},
            {n: self.event_type(e) for n, e in io.outputs.items()},
            dict(io.operations),
        )

    def event_port(self, name: str, ty: Ty | None) -> EventPort:
        port = EventPort(name, ty)
        if ty is not None:
            base = ty.decl.name if isinstance(ty, RecordTy) else f"{name}_value"
            port.value_ports = [(sc.suffix, sc) for sc in scalars(ty, self.resolver, base)]
        return port

    def disambiguate(self, ports: list[EventPort]) -> None:
        """Value ports are named after the record type (`MovementArgs_target_X`, as in the paper);
        where two events carry the same record type, their ports are prefixed with the event name."""
        counts: dict[str, int] = {}
        for p in ports:
            for name, _ in p.value_ports:
                counts[name] = counts.get(name, 0) + 1
        for p in ports:
            if any(counts[n] > 1 for n, _ in p.value_ports):
                p.value_ports = [(f"{p.name}_{n}", sc) for n, sc in p.value_ports]

    def argument_ports(self, operations: list[OperationPort]) -> None:
        """Arguments are named after the parameter (`target_X`); operations may share a port when
        name and type agree (`pick` and `place` both pass `diameter`), otherwise `op_param`."""
        types: dict[str, set[str]] = {}
        for op in operations:
            for pname, ty in op.params:
                for sc in scalars(ty, self.resolver, pname):
                    types.setdefault(sc.suffix, set()).add(sc.fmi_type)
        for op in operations:
            op.arg_ports = []
            for pname, ty in op.params:
                group = []
                for sc in scalars(ty, self.resolver, pname):
                    name = sc.suffix if len(types[sc.suffix]) == 1 else f"{op.name}_{sc.suffix}"
                    group.append((name, sc))
                op.arg_ports.append(group)


def _coerce(value, ty: Ty):
    if ty == REAL and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def build_program(project: Project, module_name: str | None = None) -> Program:
    """The executable view of a module (the only one, or the one named)."""
    modules = project.elements(Module)
    if module_name is not None:
        module = project.lookup("module", module_name)
        if module is None:
            raise CotwinError(f"no module '{module_name}' (modules: {', '.join(m.name for m in modules) or 'none'})")
    elif len(modules) == 1:
        module = modules[0]
    elif not modules:
        raise CotwinError("the model has no module to execute")
    else:
        raise CotwinError(f"several modules ({', '.join(m.name for m in modules)}): choose one with --module")
    return _Builder(project, module).build()
