"""The d-model: interfaces, robotic platforms, state machines, controllers and modules."""

from __future__ import annotations

from dataclasses import dataclass

from .declarations import ClockDecl, EventDecl, OperationSig, Param, VarDecl
from .syntax import Expr, Location, QName, Stmt


@dataclass(frozen=True)
class InterfaceUse:
    """`uses I`, `provides I` or `requires I`."""

    kind: str  # uses | provides | requires
    name: QName
    loc: Location


@dataclass(frozen=True)
class Interface:
    name: str
    operations: tuple[OperationSig, ...]
    events: tuple[EventDecl, ...]
    variables: tuple[VarDecl, ...]
    clocks: tuple[ClockDecl, ...]
    loc: Location


@dataclass(frozen=True)
class RoboticPlatform:
    name: str
    interfaces: tuple[InterfaceUse, ...]
    variables: tuple[VarDecl, ...]
    operations: tuple[OperationSig, ...]
    events: tuple[EventDecl, ...]
    loc: Location
    clocks: tuple[ClockDecl, ...] = ()


@dataclass(frozen=True)
class PlatformRef:
    """`rref name = Platform` in a module: a robotic platform defined elsewhere."""

    name: str
    target: QName
    loc: Location


@dataclass(frozen=True)
class Connection:
    """`connection A on e to B on f (_async)`: e of A flows to f of B."""

    source: str
    source_event: str
    target: str
    target_event: str
    is_async: bool
    loc: Location
    bidirectional: bool = False  # `[mult]`


@dataclass(frozen=True)
class Transition:
    name: str
    source: str
    target: str
    is_exec: bool
    clock_resets: tuple[str, ...]
    condition: Expr | None
    is_else: bool
    action: Stmt | None
    loc: Location
    source_loc: Location
    target_loc: Location
    trigger: "Communication | None" = None  # RoboChart (.rct) only
    probability: Expr | None = None
    deadline: Expr | None = None


@dataclass(frozen=True)
class Communication:
    """A RoboChart trigger `e`, `e?x`, `e!v`, `e.v`, optionally guarded `e[|p|]` (in .rct files)."""

    event: str
    kind: str  # simple | input | output | sync
    value: Expr | QName | None
    guard: Expr | None
    loc: Location


@dataclass(frozen=True)
class State:
    name: str
    nodes: tuple["Node", ...]
    transitions: tuple[Transition, ...]
    entry: Stmt | None
    during: Stmt | None
    exit: Stmt | None
    loc: Location


@dataclass(frozen=True)
class Initial:
    name: str
    loc: Location


@dataclass(frozen=True)
class Junction:
    name: str
    loc: Location


@dataclass(frozen=True)
class Final:
    name: str
    loc: Location


@dataclass(frozen=True)
class ProbabilisticJunction:
    name: str
    loc: Location


Node = State | Initial | Junction | Final | ProbabilisticJunction


@dataclass(frozen=True)
class StateMachine:
    """An `stm` (or the body of an `operation` definition, which has parameters)."""

    name: str
    cycle_def: Expr | None
    interfaces: tuple[InterfaceUse, ...]
    input_context: tuple[InterfaceUse | EventDecl, ...]
    output_context: tuple[InterfaceUse | EventDecl, ...]
    variables: tuple[VarDecl, ...]
    clocks: tuple[ClockDecl, ...]
    nodes: tuple[Node, ...]
    transitions: tuple[Transition, ...]
    loc: Location
    params: tuple[Param, ...] = ()
    events: tuple[EventDecl, ...] = ()  # RoboChart declares events in the machine itself


@dataclass(frozen=True)
class OperationDef(StateMachine):
    """An `operation name(params) { ... }` definition: a state machine called from a controller."""

    terminates: bool = False
    preconditions: tuple[Expr, ...] = ()
    postconditions: tuple[Expr, ...] = ()


@dataclass(frozen=True)
class OperationRef:
    """`opref name = Operation` in a controller: an operation definition made available to its machines."""

    name: str
    target: QName
    loc: Location


@dataclass(frozen=True)
class MachineRef:
    """`sref name = Stm` in a controller, or `cref name = Controller` in a module."""

    name: str
    target: QName
    loc: Location


@dataclass(frozen=True)
class Controller:
    name: str
    cycle_def: Expr | None
    interfaces: tuple[InterfaceUse, ...]
    variables: tuple[VarDecl, ...]
    events: tuple[EventDecl, ...]
    operations: tuple[StateMachine, ...]
    machines: tuple[StateMachine, ...]
    machine_refs: tuple[MachineRef, ...]
    connections: tuple[Connection, ...]
    loc: Location
    operation_refs: tuple[OperationRef, ...] = ()
    clocks: tuple[ClockDecl, ...] = ()


@dataclass(frozen=True)
class Module:
    name: str
    cycle_def: Expr | None
    platform: RoboticPlatform | None
    controllers: tuple[Controller, ...]
    controller_refs: tuple[MachineRef, ...]
    connections: tuple[Connection, ...]
    loc: Location
    platform_ref: PlatformRef | None = None  # `rref`: the platform is defined elsewhere
    machines: tuple[StateMachine, ...] = ()  # RoboTool rejects machines directly in a module
    machine_refs: tuple[MachineRef, ...] = ()
    variables: tuple[VarDecl, ...] = ()  # `const` declarations of the module (RoboSim's ConstCycle)


@dataclass(frozen=True)
class ForeignComponent:
    """RoboChart's `generalcontroller`, `generaloperation` and its ANN extension's `anncontroller`, `annoperation`:
    RoboTool reads them; cotwin reads their names only and cannot run them (a reference to one is an error)."""

    name: str
    kind: str  # "general controller" | "ANN controller" | "general operation" | "ANN operation"
    loc: Location
