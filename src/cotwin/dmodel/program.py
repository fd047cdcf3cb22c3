"""A module flattened for execution: its machines, the operations they call, how events are routed,
and its FMU ports.

The interpreter, the C generator, the FMU builder and the verifier all start from this one view, so
that port names, value encodings, name resolution and event routes cannot drift apart. Building it
also checks that everything the module does can run; what cannot (a RoboChart-only statement, a
quantifier over an infinite type, a string variable, ...) is reported as one located "not supported"
error per construct, all together, before any code is generated.

Value encoding (shared with the generated C): boolean -> bool, int/nat -> int, real -> float,
enumeration -> index of the literal (int), record -> dict of field values (a struct in C); vectors,
matrices, tuples, sets and sequences as in cotwin.robosim.values.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import CotwinError, Diagnostics, Finding, Location, Severity
from ..memo import once_per
from ..robosim import functions as fns
from ..robosim import syntax as s
from ..robosim.consteval import ConstEnv, ConstError, evaluate
from ..robosim.declarations import EnumDecl, EventDecl, FunctionDecl, OperationSig, SourceFile, VarDecl
from ..robosim.dmodel_elements import Controller, Module, OperationDef, ProbabilisticJunction, State, StateMachine
from ..robosim.interfaces import machine_io, module_platform, platform_members, platform_node_name
from ..robosim.machines import MachineGraph, NodeInfo
from ..robosim.project import Project
from ..robosim.types import (
    BOOL, INT, NAT, REAL, CollectionTy, EnumTy, MatrixTy, RecordTy, TupleTy, Ty, TypeResolver, VectorTy,
)
from ..robosim.values import MatrixValue, SeqValue, SetValue, TupleValue, VectorValue
from ..robosim.visitor import describe


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


INT32 = (-(2 ** 31), 2 ** 31 - 1)  # an FMI 2 Integer port


def beyond_int32(group: list[tuple[str, Scalar]], value) -> tuple[str, int] | None:
    """The first integer scalar of `value` (sent through the ports `group`) that an FMI Integer cannot
    hold, as (port, value); the model computes in int64."""
    for port, sc in group:
        if sc.ty in (INT, NAT):
            x = get_path(value, sc.path) if sc.path else value
            if not INT32[0] <= x <= INT32[1]:
                return port, x
    return None


def beyond_int32_message(port: str, value: int) -> str:
    return f"port {port} = {value} does not fit an FMI Integer (int32)"


def unsupported_type(ty: Ty, resolver: TypeResolver) -> str | None:
    """Why values of a type cannot be held by the interpreter and the C code, or None if they can:
    boolean, int, nat, real, enumerations without parameters, records, vectors and matrices of known
    size, tuples, and sets and sequences of these."""
    if ty in (BOOL, INT, NAT, REAL):
        return None
    if isinstance(ty, EnumTy):
        return None if not any(lit.params for lit in ty.decl.literals) else "enumerations with parameters"
    if isinstance(ty, RecordTy):
        for f in ty.decl.fields:
            why = unsupported_type(resolver.resolve(f.type), resolver)
            if why:
                return why
        return None
    if isinstance(ty, VectorTy):
        if ty.size is None or ty.size < 1:
            return "vectors whose size is not a positive constant"
        return unsupported_type(ty.element, resolver)
    if isinstance(ty, MatrixTy):
        if not ty.rows or not ty.columns or ty.rows < 1 or ty.columns < 1:
            return "matrices whose size is not constant"
        return unsupported_type(ty.element, resolver)
    if isinstance(ty, TupleTy):
        for item in ty.items:
            why = unsupported_type(item, resolver)
            if why:
                return why
        return None
    if isinstance(ty, CollectionTy):
        return unsupported_type(ty.element, resolver)
    return f"values of type {ty}"


def executable(ty: Ty, resolver: TypeResolver) -> bool:
    return unsupported_type(ty, resolver) is None


def default_value(ty: Ty, resolver: TypeResolver):
    if isinstance(ty, RecordTy):
        return {f.name: default_value(resolver.resolve(f.type), resolver) for f in ty.decl.fields}
    if ty == BOOL:
        return False
    if ty == REAL:
        return 0.0
    if isinstance(ty, VectorTy):
        return VectorValue(default_value(ty.element, resolver) for _ in range(ty.size or 0))
    if isinstance(ty, MatrixTy):
        return MatrixValue(VectorValue(default_value(ty.element, resolver) for _ in range(ty.columns or 0))
                           for _ in range(ty.rows or 0))
    if isinstance(ty, TupleTy):
        return TupleValue(default_value(i, resolver) for i in ty.items)
    if isinstance(ty, CollectionTy):
        return SetValue() if ty.kind == "Set" else SeqValue()
    return 0


def coerce(value, ty: Ty, resolver: TypeResolver):
    """A value as stored in a place of type `ty`: integers become reals where reals are expected."""
    if ty == REAL and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(ty, VectorTy) and isinstance(value, tuple):
        return VectorValue(coerce(v, ty.element, resolver) for v in value)
    if isinstance(ty, MatrixTy) and isinstance(value, tuple):
        return MatrixValue(VectorValue(coerce(v, ty.element, resolver) for v in row) for row in value)
    if isinstance(ty, TupleTy) and isinstance(value, tuple):
        return TupleValue(coerce(v, t, resolver) for v, t in zip(value, ty.items))
    if isinstance(ty, RecordTy) and isinstance(value, dict):
        return {f.name: coerce(value[f.name], resolver.resolve(f.type), resolver) if f.name in value else None
                for f in ty.decl.fields}
    if isinstance(ty, CollectionTy) and isinstance(value, (SetValue, SeqValue)):
        items = (coerce(v, ty.element, resolver) for v in value)
        return SetValue(items) if isinstance(value, SetValue) else SeqValue(items)
    return value


def node_description(node: NodeInfo, frame: str = "") -> str:
    """How run-time errors name where a machine was: `state Requested`, `junction J (operation op)`."""
    kind = {"State": "state", "Initial": "initial junction", "Junction": "junction", "Final": "final state",
            "ProbabilisticJunction": "junction"}[type(node.node).__name__]
    return f"{kind} {'.'.join(node.path)}" + (f" (operation {frame})" if frame else "")


@dataclass
class EventPort:
    """An event crossing the module boundary (input from or output to the platform)."""

    name: str
    ty: Ty | None
    value_ports: list[tuple[str, Scalar]] = field(default_factory=list)  # (port name, scalar)
    unportable: str | None = None  # why its value cannot be FMU ports (a set, a vector...)
    bound: set[str] = field(default_factory=set)  # the variables the machines bind its value to ($e?x)
    loc: Location | None = None  # where the event is declared (what is said of it is said there)


@dataclass
class OperationPort:
    name: str
    params: list[tuple[str, Ty]]
    arg_ports: list[list[tuple[str, Scalar]]] = field(default_factory=list)  # per parameter
    unportable: str | None = None  # why an argument cannot be FMU ports
    loc: Location | None = None  # where the operation is declared
    shares: dict[str, str] = field(default_factory=dict)  # other operation -> an argument port both write


@dataclass
class Parameter:
    """A constant without a value in the model (machine >= 0), or the module's random `seed`
    (machine -1): an FMU parameter."""

    machine: int
    name: str
    port: str
    ty: Ty
    default: object


@dataclass
class Body:
    """What a machine or an operation definition runs: its graph and the names local to it."""

    machine: StateMachine
    graph: MachineGraph
    source: SourceFile | None
    resolver: TypeResolver
    variables: list[tuple[str, Ty, s.Expr | None]]  # storage with its initial value (None: default)
    constants: dict[str, object]  # consts with a value, evaluated
    types: dict[str, Ty]  # every name local to it -> its type (variables, constants, parameters)
    clocks: list[str]
    calls: dict[str, "OperationInstance"] = field(default_factory=dict)  # software operations it calls
    entry_timers: set[int] = field(default_factory=set)  # states whose entry `sinceEntry` reads
    #: state index -> the count beyond which its `sinceEntry` reads all alike (None: unbounded)
    entry_caps: dict[int, int | None] = field(default_factory=dict)
    #: names it requires but does not declare -> the frame that holds them (-1: the machine's own)
    bindings: dict[str, int] = field(default_factory=dict)


@dataclass
class OperationInstance(Body):
    """An operation definition as called by one machine instance (one frame; RoboChart forbids recursion)."""

    index: int = 0
    name: str = ""
    params: list[tuple[str, Ty]] = field(default_factory=list)
    callers: list[Body] = field(default_factory=list)
    required: list[str] = field(default_factory=list)  # variables its interfaces require

    def declares(self, name: str) -> bool:
        return any(n == name for n, _, _ in self.variables) or any(n == name for n, _ in self.params) \
            or name in self.constants


@dataclass
class MachineInstance(Body):
    index: int = 0
    name: str = ""  # unique within the module, e.g. "sm" or "ctrl_sm"
    parameters: list[str] = field(default_factory=list)  # consts without a value
    inputs: dict[str, Ty | None] = field(default_factory=dict)
    outputs: dict[str, Ty | None] = field(default_factory=dict)
    operations: dict[str, OperationSig] = field(default_factory=dict)  # platform operations ($op)
    frames: list[OperationInstance] = field(default_factory=list)  # every operation it may call
    #: clock -> the count beyond which every `since` of it reads alike (None: unbounded), see `count_caps`
    clock_caps: dict[str, int | None] = field(default_factory=dict)

    def body_of(self, frame: int) -> Body:
        return self if frame < 0 else self.frames[frame]


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
    #: does anything draw from the pseudo-random source (uninterpreted functions, Mathematics::random)?
    uses_random: bool = False

    @property
    def readings(self):
        return self.project.readings

    def operation_port(self, name: str) -> OperationPort | None:
        return next((op for op in self.operations if op.name == name), None)

    def output_port(self, name: str) -> EventPort | None:
        return next((ev for ev in self.outputs if ev.name == name), None)

    def state_port(self, machine: MachineInstance) -> str:
        return "state" if len(self.machines) == 1 else f"state_{machine.name}"

    def leaf_names(self, machine: MachineInstance) -> list[str]:
        """The machine's leaf states by index (the value of its state port), named by their paths (found once per
        machine: observers name a state at every change)."""
        return list(once_per(machine.graph, "leaf names", lambda: tuple(".".join(n.path) for n in machine.graph.leaves)))

    def type_of(self, expr: s.Expr) -> Ty | None:
        return self.project.readings.type_of(expr)


# ---- building -------------------------------------------------------------------------------


class _Builder:
    def __init__(self, project: Project, module: Module):
        self.project = project
        self.module = module
        self.source = project.file_of(module)
        self.diag = Diagnostics()
        self.resolver = TypeResolver(project, self.source, self.diag)
        self.uses_random = False

    def event_type(self, ev: EventDecl | None, resolver: TypeResolver | None = None) -> Ty | None:
        if ev is None or ev.type is None:
            return None
        return (resolver or self.resolver).resolve(ev.type)

    def build(self) -> Program:
        module = self.module
        platform = module_platform(self.project, module, self.source)
        if platform is None:
            raise CotwinError(f"module {module.name} has no robotic platform")
        platform_source = self.project.file_of(platform) or self.source
        members = platform_members(self.project, platform, platform_source)
        platform_resolver = TypeResolver(self.project, platform_source, self.diag)
        machines: list[MachineInstance] = []
        controllers: list[tuple[str, Controller]] = []
        for ref in module.controller_refs:
            ctrl = self.project.lookup("controller", ref.target, self.source)
            controllers.append((ref.name, ctrl))
        controllers.extend((c.name, c) for c in module.controllers)
        # (controller node name, machine node name) -> machine index
        node_of: dict[tuple[str, str], int] = {}
        for ctrl_name, ctrl in controllers:
            ctrl_source = self.project.file_of(ctrl) or self.source
            refs = [(r.name, self.project.lookup("stm", r.target, ctrl_source)) for r in ctrl.machine_refs]
            refs.extend((m.name, m) for m in ctrl.machines)
            for local, machine in refs:
                name = local if len(controllers) == 1 else f"{ctrl_name}_{local}"
                node_of[(ctrl_name, local)] = len(machines)
                machines.append(self.instance(len(machines), name, machine, ctrl, ctrl_source))
        inputs = {e.name: self.event_type(e, platform_resolver) for e in members.events.values()}
        input_routes: dict[str, list[tuple[int, str]]] = {}
        output_routes: dict[tuple[int, str], str] = {}
        internal: dict[tuple[int, str], list[tuple[int, str]]] = {}
        platform_name = platform_node_name(module)
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
            if c.source == platform_name:
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
                            if mc.target == platform_name:
                                output_routes[src] = mc.target_event
                                used_outputs.add(mc.target_event)
                            else:
                                internal.setdefault(src, []).extend(into_controller(mc.target, mc.target_event))
        input_ports = [self.event_port(name, inputs[name], _bound_names(machines, input_routes[name]),
                                       members.events[name].loc) for name in inputs if name in input_routes]
        output_ports = [self.event_port(name, inputs[name], loc=members.events[name].loc)
                        for name in inputs if name in used_outputs]
        self.disambiguate([*input_ports, *output_ports])
        operations = [OperationPort(op.name, [(p.name, platform_resolver.resolve(p.type)) for p in op.params], loc=op.loc)
                      for op in members.operations.values()]
        self.argument_ports(operations)
        self.name_after_bindings(input_ports, {p.name for p in (*input_ports, *output_ports, *operations)}
                                 | {name for op in operations for group in op.arg_ports for name, _ in group}
                                 | {"state" if len(machines) == 1 else f"state_{m.name}" for m in machines})
        taken = {"cycle_period", *(p.name for p in (*input_ports, *output_ports, *operations))}
        taken |= {name for p in (*input_ports, *output_ports) for name, _ in p.value_ports}
        taken |= {name for op in operations for group in op.arg_ports for name, _ in group}
        taken |= {"state" if len(machines) == 1 else f"state_{m.name}" for m in machines}
        parameters = []
        for m in machines:
            for const in m.parameters:
                ty = m.types[const]
                port = const if len(machines) == 1 else f"{m.name}_{const}"
                if port in taken:  # a constant named like an operation's argument or an event
                    port = f"{m.name}_{const}"
                while port in taken:
                    port += "_parameter"
                taken.add(port)
                parameters.append(Parameter(m.index, const, port, ty, default_value(ty, self.resolver)))
        if self.uses_random:
            port = "seed"
            while port in taken:
                port = "random_" + port
            parameters.append(Parameter(-1, "seed", port, INT, 0))
        self.diag.raise_if_errors()
        return Program(self.project, module, self.resolver, input_ports, output_ports, operations, machines,
                       parameters, input_routes, output_routes, internal, self.uses_random)

    # ---- machines and the operations they call ----
    def _constants(self, body_vars: list[VarDecl], resolver: TypeResolver, outer: dict | None = None) -> dict:
        assigned = self.project.readings.assigned_constants
        definitions = {v.name: v.init for v in body_vars if v.is_const and v.init is not None and id(v) not in assigned}
        env = ConstEnv(definitions, enums=lambda q: self._enum(q, resolver))
        if outer:
            env.outer = ConstEnv({k: s.Literal(v, s.NOWHERE) for k, v in outer.items() if not isinstance(v, dict)})
        values = {}
        for v in body_vars:
            if v.name in definitions:
                try:
                    values[v.name] = coerce(evaluate(v.init, env), resolver.resolve(v.type), resolver)
                except ConstError as err:
                    self.diag.error(err.loc, f"constant {v.name}: {err.message}")
        return values

    def _enum(self, name: s.QName, resolver: TypeResolver):
        decl = self.project.lookup("type", s.QName(name.parts[:-1]), resolver.source)
        if isinstance(decl, EnumDecl) and decl.literal(name.last) is not None:
            return [lit.name for lit in decl.literals].index(name.last)
        return None

    def _storage(self, decls: list[VarDecl], resolver: TypeResolver, types: dict, where: str):
        """Variables (and assigned constants) with their initial values, checking their types run."""
        assigned = self.project.readings.assigned_constants
        out = []
        for v in decls:
            ty, init = resolver.declared(v)
            types[v.name] = ty
            why = unsupported_type(ty, resolver)
            if why:
                self.diag.error(v.loc, f"{v.name}: {why} cannot be executed yet (in {where})")
            if not v.is_const or id(v) in assigned:
                out.append((v.name, ty, init))
        return out

    def instance(self, index: int, name: str, machine: StateMachine, ctrl: Controller,
                 ctrl_source: SourceFile | None) -> MachineInstance:
        source = self.project.file_of(machine) or ctrl_source
        io = machine_io(self.project, machine, source)
        resolver = TypeResolver(self.project, source, self.diag)
        types: dict[str, Ty] = {}
        own = {v.name for v in machine.variables}
        interface_vars = [v for v in io.variables.values() if v.name not in own]
        decls = [*interface_vars, *machine.variables]
        variables = self._storage(decls, resolver, types, f"state machine {machine.name}")
        constants = self._constants(decls, resolver)
        assigned = self.project.readings.assigned_constants
        parameters = [v.name for v in decls if v.is_const and v.init is None and id(v) not in assigned]
        inst = MachineInstance(
            machine, MachineGraph(machine), source, resolver, variables, constants, types,
            sorted(io.clocks), index=index, name=name, parameters=parameters,
            inputs={n: self.event_type(e, resolver) for n, e in io.inputs.items()},
            outputs={n: self.event_type(e, resolver) for n, e in io.outputs.items()},
            operations=dict(io.operations),
        )
        definitions = self._operation_definitions(ctrl, ctrl_source)
        self._link(inst, inst, definitions, [])
        for frame in inst.frames:
            self._bind(inst, frame)
        self._runnable(inst, inst, f"state machine {machine.name}")
        for frame in inst.frames:
            self._runnable(inst, frame, f"operation {frame.name}")
        return inst

    def _operation_definitions(self, ctrl: Controller, source) -> dict[str, OperationDef]:
        defs = {op.name: op for op in ctrl.operations}
        for ref in ctrl.operation_refs:
            op = self.project.lookup("operation", ref.target, source)
            if op is not None:
                defs.setdefault(op.name, op)
        return defs

    def _link(self, machine: MachineInstance, body: Body, definitions: dict[str, OperationDef], stack: list[str]) -> None:
        """Find the operations a body calls, giving each one frame in the machine instance."""
        for st in _body_statements(body.machine):
            if not isinstance(st, s.CallStmt):
                continue
            name = st.operation.last
            if name in body.calls:
                continue
            op = definitions.get(name)
            if op is None:
                if name in machine.operations:
                    continue  # a platform operation called without `$`: the same output
                self.diag.error(st.operation.loc, f"operation '{name}' cannot be executed: the controller "
                                                  "neither defines it (operation, opref) nor requires it from the platform")
                continue
            if name in stack:
                self.diag.error(st.loc, f"operation '{name}' calls itself (RoboTool forbids recursive operations)")
                continue
            frame = next((f for f in machine.frames if f.name == name), None)
            if frame is None:
                frame = self._operation(machine, op, len(machine.frames))
                machine.frames.append(frame)
                self._link(machine, frame, definitions, [*stack, name])
            body.calls[name] = frame
            if body not in frame.callers:
                frame.callers.append(body)

    def _bind(self, machine: MachineInstance, frame: "OperationInstance") -> None:
        """Where each variable an operation requires lives: in its caller (a calling operation that
        declares it, or the machine), the same for every call, as RoboChart requires the caller to
        provide it."""
        for name in frame.required:
            places = {self._place(machine, caller, name, []) for caller in frame.callers}
            places.discard(None)
            if len(places) == 1:
                frame.bindings[name] = places.pop()
            elif not places:
                self.diag.error(frame.machine.loc, f"operation {frame.name} requires '{name}', which neither state "
                                                   f"machine {machine.machine.name} nor any caller declares")
            else:
                self.diag.error(frame.machine.loc, f"operation {frame.name} requires '{name}', which its callers hold "
                                                   "in different places: this cannot be executed")

    def _place(self, machine: MachineInstance, body: Body, name: str, seen: list) -> int | None:
        if isinstance(body, OperationInstance):
            if body.declares(name):
                return body.index
            if body in seen:
                return None
            places = {self._place(machine, c, name, [*seen, body]) for c in body.callers}
            places.discard(None)
            return places.pop() if len(places) == 1 else None
        return -1 if name in machine.types else None

    def _operation(self, machine: MachineInstance, op: OperationDef, index: int) -> OperationInstance:
        source = self.project.file_of(op) or machine.source
        resolver = TypeResolver(self.project, source, self.diag)
        types: dict[str, Ty] = {}
        params = [(p.name, resolver.resolve(p.type)) for p in op.params]
        for pname, ty in params:
            types[pname] = ty
            why = unsupported_type(ty, resolver)
            if why:
                self.diag.error(op.loc, f"parameter {pname} of operation {op.name}: {why} cannot be executed yet")
        variables = self._storage(list(op.variables), resolver, types, f"operation {op.name}")
        constants = self._constants(list(op.variables), resolver)
        io = machine_io(self.project, op, source)
        clocks = sorted(c.name for c in op.clocks)
        required = [name for name in io.variables if name not in types]
        return OperationInstance(op, MachineGraph(op), source, resolver, variables, constants, types, clocks,
                                 index=index, name=op.name, params=params, required=required)

    # ---- what can run ----
    def _runnable(self, machine: MachineInstance, body: Body, where: str) -> None:
        for node in body.graph.nodes:
            if isinstance(node.node, ProbabilisticJunction):
                self.diag.error(node.node.loc, f"probabilistic junction {node.name} cannot be executed (in {where})")
        for t in body.graph.transitions:
            if t.trigger is not None:
                self.diag.error(t.loc, f"transition {t.name}: RoboChart triggers cannot be executed (in {where})")
            if t.probability is not None:
                self.diag.error(t.probability.loc, f"transition {t.name}: probabilities cannot be executed (in {where})")
            if t.condition is not None:
                self._expression(t.condition, body, where, machine)
        for st in _body_statements(body.machine):
            if isinstance(st, (s.Wait, s.Receive, s.Timed)):
                kind = {s.Wait: "wait", s.Receive: "an input communication", s.Timed: "a deadline"}[type(st)]
                self.diag.error(st.loc, f"{kind} is RoboChart's, not RoboSim's: it cannot be executed (in {where})")
            for e in s.statement_expressions(st):
                self._expression(e, body, where, machine)
        for name, ty, init in body.variables:
            if init is not None:
                self._expression(init, body, where, machine)

    def _expression(self, expr: s.Expr, body: Body, where: str, machine: MachineInstance | None = None) -> None:
        readings = self.project.readings
        if machine is not None:
            count_caps(expr, body, machine)
        for node in s.walk(expr):
            why = None
            if isinstance(node, s.Quantified) and node.kind == "lambda":
                why = "a lambda expression"
            elif isinstance(node, s.TypeTest) and node.kind == "is":
                why = "a type test ('is')"
            elif isinstance(node, s.TypeTest):
                source, target = readings.type_of(node.expr), readings.type_of(node)
                if target in (INT, NAT) and source == REAL:
                    why = "a cast of a real to an integer ('as')"
            elif isinstance(node, s.Unary) and node.op == "inverse":
                why = "the inverse of a matrix"
            elif isinstance(node, (s.Quantified, s.SetComprehension)):
                binders = node.binders
                bound = _bounded_names(node.such_that if isinstance(node, s.Quantified) else node.predicate)
                for name, ref in binders:
                    ty = body.resolver.resolve(ref)
                    if name not in bound and not (ty == BOOL or isinstance(ty, EnumTy)):
                        why = (f"{describe(node)} over all values of {ty} ('{name}' is not bounded by "
                               f"'{name} in S')")
            elif isinstance(node, s.RangeExpr):
                why = None  # only read by `in`
            elif isinstance(node, s.Call):
                why = self._call(node, body)
            elif isinstance(node, s.SinceEntryExpr):
                index = _state_index(body.graph, node.state)
                if index is None:
                    why = f"sinceEntry of '{node.state}', not a state of this machine"
                else:
                    body.entry_timers.add(index)
            if why:
                self.diag.error(node.loc, f"{why} cannot be executed (in {where})")
            ty = readings.type_of(node)
            if ty is not None and isinstance(node, (s.SetExpr, s.SeqExpr, s.SetComprehension, s.SetRangeExpr)):
                bad = unsupported_type(ty, body.resolver)
                if bad:
                    self.diag.error(node.loc, f"{bad} cannot be executed (in {where})")

    def _call(self, call: s.Call, body: Body) -> str | None:
        if isinstance(call.function, s.Name) and len(call.function.name.parts) > 1:
            decl = self.project.lookup("type", s.QName(call.function.name.parts[:-1]), body.source)
            if isinstance(decl, EnumDecl):
                return "an enumeration literal with parameters"
        fn = fns.target(self.project, call, body.source)
        if fn is None:
            return "a call of an unknown function"
        impl = fns.builtin(self.project, fn)
        if impl == "random":
            self.uses_random = True
            return None
        if impl is not None:
            return None
        if fns.definition(fn) is not None:
            return self._recursive(fn, body, [])
        result = body.resolver.resolve(fn.result) if not fns.is_builtin(self.project, fn) else None
        if result is not None and (result in (BOOL, INT, NAT, REAL) or isinstance(result, EnumTy)):
            self.uses_random = True  # uninterpreted: values from the random source
            return None
        return f"function '{fn.name}' (no definition, result of type {result})"

    def _recursive(self, fn: FunctionDecl, body: Body, stack: list) -> str | None:
        if fn in stack:
            return f"function '{fn.name}' (defined in terms of itself)"
        for node in s.walk(fns.definition(fn)):
            if isinstance(node, s.Call):
                inner = fns.target(self.project, node, self.project.file_of(fn))
                if inner is not None and fns.definition(inner) is not None:
                    why = self._recursive(inner, body, [*stack, fn])
                    if why:
                        return why
        return None

    # ---- ports ----
    def event_port(self, name: str, ty: Ty | None, bound: set[str] | None = None,
                   loc: Location | None = None) -> EventPort:
        port = EventPort(name, ty, loc=loc)
        port.bound = bound or set()
        if ty is not None:
            base = ty.decl.name if isinstance(ty, RecordTy) else f"{name}_value"
            try:
                port.value_ports = [(sc.suffix, sc) for sc in scalars(ty, self.resolver, base)]
            except CotwinError as err:
                port.unportable = f"event {name}: {err.findings[0].message}"
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

    @staticmethod
    def name_after_bindings(ports: list[EventPort], taken: set[str]) -> None:
        """The value port of an event of a primitive type is named after the variable the d-model binds
        it to (`$closestDistance?closest_distance` gives `closest_distance`, as the paper's Listing 6),
        when every binding uses one name that no other port has; otherwise it stays `<event>_value`."""
        names = [n for p in ports for n, _ in p.value_ports] + sorted(taken)
        for p in ports:
            if len(p.value_ports) != 1 or p.value_ports[0][1].path or len(p.bound) != 1:
                continue
            (bound,) = p.bound
            if bound in names or bound == "cycle_period":
                continue
            sc = p.value_ports[0][1]
            p.value_ports = [(bound, sc)]
            names.append(bound)

    def argument_ports(self, operations: list[OperationPort]) -> None:
        """Arguments are named after the parameter (`target_X`); operations may share a port when
        name and type agree (`pick` and `place` both pass `diameter`), otherwise `op_param`."""
        types: dict[str, set[str]] = {}
        for op in operations:
            for pname, ty in op.params:
                try:
                    for sc in scalars(ty, self.resolver, pname):
                        types.setdefault(sc.suffix, set()).add(sc.fmi_type)
                except CotwinError as err:
                    op.unportable = f"operation {op.name}: {err.findings[0].message}"
        for op in operations:
            op.arg_ports = []
            for pname, ty in op.params:
                group = []
                try:
                    for sc in scalars(ty, self.resolver, pname):
                        name = sc.suffix if len(types[sc.suffix]) == 1 else f"{op.name}_{sc.suffix}"
                        group.append((name, sc))
                except CotwinError:
                    pass
                op.arg_ports.append(group)
        # operations sharing a port cannot both be called in one cycle: the port holds one value (the
        # interpreter and the C refuse it at run time, as they refuse an output emitted twice)
        writers: dict[str, list[str]] = {}
        for op in operations:
            for group in op.arg_ports:
                for name, _ in group:
                    writers.setdefault(name, []).append(op.name)
        for op in operations:
            op.shares = {other: name for name, ops in sorted(writers.items()) if op.name in ops for other in ops if other != op.name}


def time_readings(program: "Program") -> list[Location]:
    """Where the d-model reads time (`since`, `sinceEntry`), in source order: counted in cycles, so what it reads
    in seconds follows the cycle's length (a communication step, unless [cosim] parameters cycle_period says)."""
    found = set()
    for inst in program.machines:
        for body in (inst, *inst.frames):
            roots = [t.condition for t in body.graph.transitions if t.condition is not None]
            roots += [e for st in _body_statements(body.machine) for e in s.statement_expressions(st)]
            found.update(node.loc for root in roots for node in s.walk(root)
                         if isinstance(node, (s.SinceExpr, s.SinceEntryExpr)))
    return sorted(found, key=lambda loc: (loc.path, loc.line, loc.column))


def _body_statements(machine: StateMachine):
    graph_nodes = []
    stack = list(machine.nodes)
    while stack:
        node = stack.pop(0)
        graph_nodes.append(node)
        if isinstance(node, State):
            stack.extend(node.nodes)
    roots = []
    for node in graph_nodes:
        if isinstance(node, State):
            roots.extend(x for x in (node.entry, node.during, node.exit) if x is not None)
            roots.extend(t.action for t in node.transitions if t.action is not None)
    roots.extend(t.action for t in machine.transitions if t.action is not None)
    for root in roots:
        yield from s.statements(root)


def _bounded_names(predicate) -> set[str]:
    out = set()
    stack = [predicate] if predicate is not None else []
    while stack:
        e = stack.pop()
        if isinstance(e, s.Binary) and e.op == "/\\":
            stack.extend((e.left, e.right))
        elif isinstance(e, s.Binary) and e.op == "in" and isinstance(e.left, s.Name):
            out.add(e.left.name.last)
    return out


def _bound_names(machines: list[MachineInstance], routes: list[tuple[int, str]]) -> set[str]:
    """The variables the machines bind a platform event's value to (`$e?x` in their guards)."""
    names: set[str] = set()
    for index, event in routes:
        machine = machines[index]
        for body in (machine, *machine.frames):
            for t in body.graph.transitions:
                for node in s.walk(t.condition) if t.condition is not None else ():
                    if isinstance(node, s.EventTest) and node.bind and node.event.last == event:
                        names.add(node.bind)
    return names


def _state_index(graph: MachineGraph, state: s.QName) -> int | None:
    """The node a `sinceEntry(S)` names: by its path (A::B or A.B) or, if unique, its name."""
    path = tuple(state.parts)
    hits = [n for n in graph.nodes if isinstance(n.node, State) and (n.path == path or n.path[-len(path):] == path)]
    return hits[0].index if len(hits) == 1 else None


def state_index(graph: MachineGraph, state: s.QName) -> int:
    index = _state_index(graph, state)
    if index is None:  # pragma: no cover - build_program reports it
        raise CotwinError(f"{state.loc}: no state '{state}'")
    return index


def build_program(project: Project, module_name: str | None = None) -> Program:
    """The executable view of a module (the only one, or the one named)."""
    modules = project.elements(Module)
    named = {id(m): "::".join(project.qualified_name(m)) for m in modules}
    module = project.lookup("module", module_name) if module_name is not None else None
    if module is None and module_name is not None:  # `Mod` for P::Mod: the modules whose name ends so
        parts = tuple(module_name.split("::"))
        candidates = [m for m in modules if tuple(named[id(m)].split("::"))[-len(parts):] == parts]
        if not candidates:
            raise CotwinError(f"no module '{module_name}' (modules: {', '.join(named.values()) or 'none'})")
    else:
        candidates = [module] if module is not None else modules
    if not candidates:
        raise CotwinError("the model has no module to execute")
    if len(candidates) > 1:  # each named where it is declared, as --module takes it (`Mod` of two packages chose one)
        which = f"modules named '{module_name}'" if module_name is not None else "modules"
        raise CotwinError([Finding(m.loc, Severity.ERROR, f"{len(candidates)} {which}: this is {named[id(m)]}: choose "
                                                          f"one with --module {named[id(m)]}") for m in candidates])
    return _Builder(project, candidates[0]).build()


__all__ = [
    "Body", "EventPort", "MachineInstance", "OperationInstance", "OperationPort", "Parameter", "Program", "Scalar",
    "assemble", "build_program", "coerce", "default_value", "executable", "fmi_type", "get_path", "node_description",
    "scalars", "set_path", "state_index", "unsupported_type", "OperationDef", "StateMachine",
]


_COMPARISONS = frozenset({"<", "<=", ">", ">=", "==", "!="})


def count_caps(expr: s.Expr, body: Body, machine: MachineInstance) -> None:
    """Where `since(C)` and `sinceEntry(S)` are only compared with constants, every count above the
    largest constant k reads alike, so the interpreter may stop counting at floor(k) + 1: the states
    the verifier explores stay finite. Any other use (arithmetic, output, a parameter) leaves the
    count unbounded (None)."""
    compared: dict[int, int] = {}
    for node in s.walk(expr):
        if isinstance(node, s.Binary) and node.op in _COMPARISONS:
            for counter, other in ((node.left, node.right), (node.right, node.left)):
                if isinstance(counter, (s.SinceExpr, s.SinceEntryExpr)):
                    bound = _constant_bound(other, body)
                    if bound is not None:
                        compared[id(counter)] = max(compared.get(id(counter), 0), bound)
    for node in s.walk(expr):
        if isinstance(node, s.SinceExpr):
            caps, key = machine.clock_caps, node.clock
        elif isinstance(node, s.SinceEntryExpr):
            key = _state_index(body.graph, node.state)
            if key is None:
                continue
            caps = body.entry_caps
        else:
            continue
        cap = compared.get(id(node))
        if key in caps and (caps[key] is None or cap is None):
            caps[key] = None
        else:
            caps[key] = max(caps.get(key, 0), cap) if cap is not None else None


def _constant_bound(expr: s.Expr, body: Body) -> int | None:
    """floor(k) + 1 (at least 0) for a numeric constant k, else None."""
    env = ConstEnv({k: s.Literal(v, s.NOWHERE) for k, v in body.constants.items()
                    if isinstance(v, (int, float)) and not isinstance(v, bool)})
    try:
        value = evaluate(expr, env)
    except ConstError:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        return None
    if abs(value) > 2 ** 62:
        return None
    return max(0, int(value // 1) + 1)
