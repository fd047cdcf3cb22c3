"""The p-model (links, bodies, joints, sensors, actuators, parts) and the platform mapping.

Local elements (`local joint J { def { ... } }`) carry their own definition (a `Device`); references
(`jref J = Revolute_y`) name one. New fields have defaults, so the paper's older forms build as before.
"""

from __future__ import annotations

from dataclasses import dataclass

from .declarations import VarDecl
from .syntax import Expr, Location, QName

Entry = tuple[str, Expr, Location]  # name = value, where


@dataclass(frozen=True)
class AnnotationEntry:
    key: str
    value: "Expr | AnnotationRecord"
    loc: Location


@dataclass(frozen=True)
class AnnotationRecord:
    """`Name { key = value ... }`; also the top-level `annotation Name { ... }`."""

    name: str
    entries: tuple[AnnotationEntry, ...]
    loc: Location

    def get(self, key: str) -> "Expr | AnnotationRecord | None":
        return next((e.value for e in self.entries if e.key == key), None)


@dataclass(frozen=True)
class AnnotationTemplate:
    """`annotation template Name { field : type  nested : template Other }` (declares an annotation)."""

    name: str
    fields: tuple[tuple[str, object, bool, Location], ...]  # name, type or template name, is nested, where
    loc: Location


@dataclass(frozen=True)
class Device:
    """A `sensor`, `actuator` or `joint` definition: top-level, or the `def` of a local one."""

    kind: str  # sensor | actuator | joint
    name: str
    ports: tuple[VarDecl, ...]  # kind: input | output | local | const | var | InOut
    equations: tuple[Expr, ...]
    annotations: tuple[AnnotationRecord, ...]
    loc: Location
    constraints: tuple[Expr, ...] = ()

    def port(self, name: str) -> VarDecl | None:
        return next((p for p in self.ports if p.name == name), None)

    def annotation(self, name: str) -> AnnotationRecord | None:
        return next((a for a in self.annotations if a.name == name), None)


@dataclass(frozen=True)
class Pose:
    """x, y, z (m) and roll, pitch, yaw (rad); a missing field is 0."""

    fields: tuple[tuple[str, Expr, Location], ...]
    loc: Location


@dataclass(frozen=True)
class Index:
    """`index i : [low, high]` or `[low, high)`: the element is replicated once per integer value."""

    var: str
    low: Expr
    high: Expr
    closed: bool  # ] includes high, ) excludes it
    loc: Location


@dataclass(frozen=True)
class Shape:
    kind: str  # box | cylinder | sphere | mesh | capsule
    params: tuple[Entry, ...]  # mesh: ("shape", file literal), ("scaling", factor)
    loc: Location


@dataclass(frozen=True)
class Surface:
    """Contact properties of a body: `bounce { }`, `friction { }` and `laser retro`."""

    restitution: Expr | None = None
    threshold: Expr | None = None
    friction: tuple[tuple[str, tuple[Entry, ...], Location], ...] = ()  # group (translational...), entries
    laser_retro: Expr | None = None


@dataclass(frozen=True)
class Inertial:
    mass: Expr | None
    unit: str | None
    inertia: tuple[Entry, ...]
    pose: Pose | None
    loc: Location


@dataclass(frozen=True)
class Body:
    """`local body B { def { shape inertial surfaces } pose }` or `bref B = Def { pose }`."""

    name: str
    shapes: tuple[Shape, ...]
    pose: Pose | None
    loc: Location
    inertial: Inertial | None = None
    surface: Surface | None = None
    ref: QName | None = None  # bref: the top-level body it instantiates
    index: Index | None = None
    relations: tuple[Expr, ...] = ()
    variables: tuple[VarDecl, ...] = ()
    equations: tuple[Expr, ...] = ()


@dataclass(frozen=True)
class DeviceRef:
    """A sensor or actuator of a link or joint: `sref S = Sensor { ... }`, `aref A = Actuator { relation ... }`,
    or `local sensor S { def { ... } }` (then `local` holds its definition and `device` is None)."""

    kind: str  # sref | aref
    name: str
    device: QName | None
    relations: tuple[Expr, ...]
    instantiations: tuple[Entry, ...]
    loc: Location
    local: Device | None = None
    pose: Pose | None = None
    index: Index | None = None
    annotations: tuple[AnnotationRecord, ...] = ()


@dataclass(frozen=True)
class JointRef:
    """`jref j = Revolute { annotation ... flexibly connected to child ... pose ... }` or a
    `local joint j { def { ... } ... }` (then `local` holds its definition and `joint` is None)."""

    name: str
    joint: QName | None
    annotations: tuple[AnnotationRecord, ...]
    instantiations: tuple[Entry, ...]
    actuators: tuple[DeviceRef, ...]
    child: str | None
    child_part: str | None
    child_loc: Location | None
    pose: Pose | None
    loc: Location
    local: Device | None = None
    sensors: tuple[DeviceRef, ...] = ()
    relations: tuple[Expr, ...] = ()
    index: Index | None = None
    #: declared in the joint's block itself, outside `def` (visible to its relations)
    variables: tuple[VarDecl, ...] = ()


@dataclass(frozen=True)
class FixedTo:
    """`fixed to link [in Part]`: a rigid attachment of this link to another (the other is the child)."""

    link: str
    part: str | None
    loc: Location


@dataclass(frozen=True)
class Link:
    name: str
    inertial: Inertial | None
    shapes: tuple[Shape, ...]
    annotations: tuple[AnnotationRecord, ...]
    variables: tuple[VarDecl, ...]
    equations: tuple[Expr, ...]
    pose: Pose | None
    bodies: tuple[Body, ...]
    joints: tuple[JointRef, ...]
    sensors: tuple[DeviceRef, ...]
    actuators: tuple[DeviceRef, ...]
    fixed_to: tuple[FixedTo, ...]
    loc: Location
    ref: QName | None = None  # lref: the top-level link it instantiates
    index: Index | None = None
    relations: tuple[Expr, ...] = ()
    constraints: tuple[Expr, ...] = ()


@dataclass(frozen=True)
class LinkDecl:
    """A top-level `link Name { inertial ... const ... }`, instantiated by `lref`."""

    name: str
    inertial: Inertial | None
    shapes: tuple[Shape, ...]
    variables: tuple[VarDecl, ...]
    equations: tuple[Expr, ...]
    annotations: tuple[AnnotationRecord, ...]
    loc: Location


@dataclass(frozen=True)
class BodyDecl:
    """A top-level `body Name { shape inertial surfaces }`, instantiated by `bref`."""

    name: str
    shapes: tuple[Shape, ...]
    inertial: Inertial | None
    surface: Surface | None
    variables: tuple[VarDecl, ...]
    loc: Location


@dataclass(frozen=True)
class PartFixed:
    """In a part: `link L fixed to M [in P]`: link L of the part is fixed to link M (of part P)."""

    link: str
    target: str
    target_part: str | None
    loc: Location


@dataclass(frozen=True)
class PartJoint:
    """In a part: `joint J flexibly connected to L [in P]`: the part's joint J gets child L (of part P)."""

    joint: str
    child: str
    child_part: str | None
    loc: Location


@dataclass(frozen=True)
class PartRef:
    """`part name = PModel { ... }`: another p-model included in this one."""

    name: str
    pmodel: QName
    pose: Pose | None
    instantiations: tuple[Entry, ...]
    loc: Location
    fixed: tuple[PartFixed, ...] = ()
    joints: tuple[PartJoint, ...] = ()
    index: Index | None = None  # `index i : [a, b]`: one instance of the p-model per value


@dataclass(frozen=True)
class Solution:
    """A solver-generated `solution { solutionExpr ... order ... method ... Input ... }` block."""

    items: tuple[tuple[str, object, Location], ...]
    loc: Location


@dataclass(frozen=True)
class PModel:
    name: str
    constants: tuple[VarDecl, ...]
    links: tuple[Link, ...]
    parts: tuple[PartRef, ...]
    loc: Location
    variables: tuple[VarDecl, ...] = ()  # input, output, local, InOut declarations of the p-model
    equations: tuple[Expr, ...] = ()
    constraints: tuple[Expr, ...] = ()
    solutions: tuple[Solution, ...] = ()
    annotations: tuple[AnnotationRecord, ...] = ()
    joints: tuple[JointRef, ...] = ()  # joints declared in the p-model itself: their parent is the base link


@dataclass(frozen=True)
class Fragment:
    """`fragment Name { links, joints, sensors, actuators }`: a reusable collection of p-model elements."""

    name: str
    links: tuple[Link, ...]
    joints: tuple[JointRef, ...]
    sensors: tuple[DeviceRef, ...]
    actuators: tuple[DeviceRef, ...]
    variables: tuple[VarDecl, ...]
    equations: tuple[Expr, ...]
    loc: Location


@dataclass(frozen=True)
class MappingOperation:
    name: str
    variables: tuple[VarDecl, ...]
    equations: tuple[Expr, ...]
    actions: tuple[tuple[Expr, Expr, Location], ...]  # (target, value, where)
    loc: Location


@dataclass(frozen=True)
class MappingInputEvent:
    name: str
    bind: str | None
    equations: tuple[Expr, ...]
    predicates: tuple[Expr, ...]
    variables: tuple[VarDecl, ...]
    loc: Location


@dataclass(frozen=True)
class Mapping:
    """`map M dmodel Module to pmodel P { ... }`."""

    name: str
    dmodel: QName
    pmodel: QName
    variables: tuple[VarDecl, ...]
    operations: tuple[MappingOperation, ...]
    input_events: tuple[MappingInputEvent, ...]
    loc: Location
