"""What a platform, controller or state machine can see through its `uses`/`provides`/`requires`."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..diagnostics import Diagnostics
from .declarations import EventDecl, OperationSig, SourceFile, VarDecl
from .dmodel_elements import Interface, InterfaceUse, Module, RoboticPlatform, StateMachine


@dataclass
class Members:
    """Operations, events and variables gathered from interfaces, in declaration order."""

    operations: dict[str, OperationSig] = field(default_factory=dict)
    events: dict[str, EventDecl] = field(default_factory=dict)
    variables: dict[str, VarDecl] = field(default_factory=dict)
    clocks: set[str] = field(default_factory=set)

    def add_interface(self, interface: Interface, operations: bool = True, events: bool = True) -> None:
        if operations:
            for op in interface.operations:
                self.operations.setdefault(op.name, op)
        if events:
            for ev in interface.events:
                self.events.setdefault(ev.name, ev)
        for var in interface.variables:
            self.variables.setdefault(var.name, var)
        self.clocks.update(c.name for c in interface.clocks)


def interface_of(project, use: InterfaceUse, source: SourceFile | None, diag: Diagnostics | None) -> Interface | None:
    found = project.lookup("interface", use.name, source)
    if found is None and diag is not None and not project.ambiguous("interface", use.name):
        hint = project.elsewhere("interface", use.name)
        extra = f" (there is {', '.join(hint)}: import its package or qualify the name)" if hint else ""
        diag.error(use.name.loc, f"unknown interface '{use.name}'{extra}")
    return found


def module_platform(project, module: Module, source: SourceFile | None,
                    diag: Diagnostics | None = None) -> RoboticPlatform | None:
    """The module's robotic platform: defined in it, or referenced with `rref`."""
    if module.platform is not None:
        return module.platform
    ref = module.platform_ref
    if ref is None:
        return None
    found = project.lookup("platform", ref.target, source)
    if found is None and diag is not None:
        diag.error(ref.target.loc, f"unknown robotic platform '{ref.target}'")
    return found


def platform_node_name(module: Module) -> str | None:
    """The name connections use for the module's platform (its own, or the rref's)."""
    if module.platform is not None:
        return module.platform.name
    return module.platform_ref.name if module.platform_ref is not None else None


def platform_members(project, platform: RoboticPlatform, source: SourceFile | None,
                     diag: Diagnostics | None = None) -> Members:
    """The platform's operations (provided) and events (used), plus those it declares itself."""
    members = Members()
    for use in platform.interfaces:
        interface = interface_of(project, use, source, diag)
        if interface is not None:
            members.add_interface(interface)
    for op in platform.operations:
        members.operations.setdefault(op.name, op)
    for ev in platform.events:
        members.events.setdefault(ev.name, ev)
    for var in platform.variables:
        members.variables.setdefault(var.name, var)
    return members


@dataclass
class MachineIO:
    """A state machine's view: input events it may test, output events and operations it may emit,
    the variables and clocks its interfaces give it, and the interfaces it uses (not requires)."""

    inputs: dict[str, EventDecl]
    outputs: dict[str, EventDecl]
    operations: dict[str, OperationSig]
    variables: dict[str, VarDecl]
    clocks: set[str]
    used: list[Interface] = field(default_factory=list)
    required: list[Interface] = field(default_factory=list)


def machine_io(project, machine: StateMachine, source: SourceFile | None, diag: Diagnostics | None = None) -> MachineIO:
    inputs, outputs = Members(), Members()
    both = Members()
    used: list[Interface] = []
    required: list[Interface] = []

    def note(use: InterfaceUse, interface: Interface) -> None:
        (required if use.kind == "requires" else used).append(interface)

    for use in machine.interfaces:
        interface = interface_of(project, use, source, diag)
        if interface is not None:
            both.add_interface(interface)
            note(use, interface)
    for item in machine.input_context:
        if isinstance(item, EventDecl):
            inputs.events.setdefault(item.name, item)
        elif (interface := interface_of(project, item, source, diag)) is not None:
            inputs.add_interface(interface, operations=False)
            note(item, interface)
    for item in machine.output_context:
        if isinstance(item, EventDecl):
            outputs.events.setdefault(item.name, item)
        elif (interface := interface_of(project, item, source, diag)) is not None:
            outputs.add_interface(interface)
            note(item, interface)
    for ev in machine.events:
        both.events.setdefault(ev.name, ev)
    operations = {**both.operations, **outputs.operations}
    variables = {**both.variables, **inputs.variables, **outputs.variables}
    return MachineIO(
        inputs={**both.events, **inputs.events},
        outputs={**both.events, **outputs.events},
        operations=operations,
        variables=variables,
        clocks=both.clocks | inputs.clocks | outputs.clocks | {c.name for c in machine.clocks},
        used=used,
        required=required,
    )
