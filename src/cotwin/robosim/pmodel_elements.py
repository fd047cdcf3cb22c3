"""The p-model (links, bodies, joints, sensors, actuators, parts) and the platform mapping."""

from __future__ import annotations

from dataclasses import dataclass

from .declarations import VarDecl
from .syntax import Expr, Location, QName


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
class Device:
    """A top-level `sensor`, `actuator` or `joint` definition with its ports and equations."""

    kind: str  # sensor | actuator | joint
    name: str
    ports: tuple[VarDecl, ...]  # kind: input | output | local | const
    equations: tuple[Expr, ...]
    annotations: tuple[AnnotationRecord, ...]
    loc: Location

    def port(self, name: str) -> VarDecl | None:
        return next((p for p in self.ports if p.name == name), None)


@dataclass(frozen=True)
class Pose:
    """x, y, z (m) and roll, pitch, yaw (rad); a missing field is 0."""

    fields: tuple[tuple[str, Expr, Location], ...]
    loc: Location


@dataclass(frozen=True)
class Shape:
    kind: str  # box | cylinder | sphere | mesh | capsule
    params: tuple[tuple[str, Expr, Location], ...]
    loc: Location


@dataclass(frozen=True)
class Inertial:
    mass: Expr | None
    unit: str | None
    inertia: tuple[tuple[str, Expr, Location], ...]
    pose: Pose | None
    loc: Location


@dataclass(frozen=True)
class Body:
    name: str
    shapes: tuple[Shape, ...]
    pose: Pose | None
    loc: Location


@dataclass(frozen=True)
class DeviceRef:
    """`sref S = Sensor { ... }` or `aref A = Actuator { relation ... }`."""

    kind: str  # sref | aref
    name: str
    device: QName
    relations: tuple[Expr, ...]
    instantiations: tuple[tuple[str, Expr, Location], ...]
    loc: Location


@dataclass(frozen=True)
class JointRef:
    """`jref j = Revolute { annotation ... flexibly connected to child ... pose ... }`."""

    name: str
    joint: QName
    annotations: tuple[AnnotationRecord, ...]
    instantiations: tuple[tuple[str, Expr, Location], ...]
    actuators: tuple[DeviceRef, ...]
    child: str | None
    child_part: str | None
    child_loc: Location | None
    pose: Pose | None
    loc: Location


@dataclass(frozen=True)
class FixedTo:
    """`fixed to link in Part`: a rigid attachment of this link to a link of a part."""

    link: str
    part: str
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


@dataclass(frozen=True)
class PartRef:
    """`part name = PModel { ... }`: another p-model included in this one."""

    name: str
    pmodel: QName
    pose: Pose | None
    instantiations: tuple[tuple[str, Expr, Location], ...]
    loc: Location


@dataclass(frozen=True)
class PModel:
    name: str
    constants: tuple[VarDecl, ...]
    links: tuple[Link, ...]
    parts: tuple[PartRef, ...]
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
