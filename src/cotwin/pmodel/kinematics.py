"""The kinematic tree of a p-model, as data: the one intermediate form SDF, URDF, MJCF and the simulator
share (built by cotwin.pmodel.tree_build; cotwin.pmodel.tree is the public face of both).

Conventions (docs/pmodel-notation.md, section 4): a link's pose is in the model frame (the frame of
the including p-model for links of a part, composed with the part's pose); a joint's pose is relative
to its parent link; a joint axis is expressed in the joint frame; roll/pitch/yaw are fixed-axis
X-Y-Z angles (R = Rz(yaw) Ry(pitch) Rx(roll)), as in SDF and URDF. Everything is at joint values 0.

A sensor declared in a link measures the joint declared just before it in that link (the first
joint if it comes before any), which is how an arm's p-model lists FSJ1..PSJ1 after
shoulder_pan_joint and the finger sensors after each finger joint; a sensor declared in a joint
measures that joint. Joints that close a kinematic loop are kept apart (`loops`): SDF lists them,
MJCF turns them into equality constraints, URDF cannot say them.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import Location
from ..robosim.syntax import NOWHERE
from .kinds import RaySpec


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def matrix_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """Fixed-axis roll, pitch, yaw of a rotation matrix (inverse of rpy_matrix)."""
    pitch = float(np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0])))
    if abs(np.cos(pitch)) < 1e-12:  # gimbal lock: put everything into yaw
        return 0.0, pitch, float(np.arctan2(-R[0, 1], R[1, 1]))
    return float(np.arctan2(R[2, 1], R[2, 2])), pitch, float(np.arctan2(R[1, 0], R[0, 0]))


def transform(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)
    T = np.eye(4)
    T[:3, :3] = R
    return T



@dataclass
class Geom:
    name: str
    kind: str  # box | cylinder | sphere | capsule | mesh
    size: dict[str, float]  # mesh: the scaled bounding box's length, width, height
    pose: np.ndarray  # relative to the link frame (a mesh: its file's origin)
    body: str = ""  # the p-model body it comes from, as written ("" for a link's own shapes)
    surface: dict = field(default_factory=dict)  # restitution, threshold, laser_retro, friction groups
    mesh: str | None = None  # the mesh file (absolute path) when kind is mesh
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)  # a mesh's bounding-box centre in the geom frame
    placeholder: bool = False  # stands in for a mesh that cannot be read: shown, never collides
    written: str = ""  # a mesh's file as the p-model names it (also for placeholders and stand-ins)
    loc: Location = NOWHERE  # the p-model shape it comes from (a simulator's error names it)

    def volume(self) -> float:
        if self.kind in ("box", "mesh"):
            return self.size["length"] * self.size["width"] * self.size["height"]
        if self.kind == "cylinder":
            return np.pi * self.size["radius"] ** 2 * self.size["length"]
        if self.kind == "capsule":
            r = self.size["radius"]
            return np.pi * r * r * self.size["length"] + 4 / 3 * np.pi * r ** 3
        return 4 / 3 * np.pi * self.size["radius"] ** 3


@dataclass(frozen=True)
class ElementRef:
    """An annotation value naming a body, link or part of the model: written as that element's name."""

    kind: str
    target: object  # the TLink, the Geom, or the part instance

    def __str__(self) -> str:
        return self.target.name if hasattr(self.target, "name") else "/".join(self.target.path)


@dataclass(frozen=True)
class StandIn:
    """A shape standing in for a mesh file the p-model names but cotwin cannot read (e.g. one never
    published), given by the project: a primitive in the mesh's frame, optionally with its own sliding
    friction (0: a frictionless skid, as a caster ball)."""

    kind: str  # box | cylinder | sphere | capsule
    size: dict[str, float]  # box: length, width, height; cylinder, capsule: radius, length; sphere: radius
    pose: np.ndarray  # in the mesh's frame
    friction: float | None = None


@dataclass
class TLink:
    name: str
    pose: np.ndarray  # model frame, at zero joint values
    mass: float
    com: np.ndarray  # pose of the centre of mass relative to the link frame
    inertia: np.ndarray  # 3x3 about the COM, in the COM frame
    geoms: list[Geom]
    source: str  # the p-model link name as written (paths use it)
    part: str | None = None  # the part instance it comes through (its scope: `Gripper`, `1-p/q`)
    loc: Location = NOWHERE  # the p-model link (a simulator's error names it)
    index: int | None = None  # the value of its `index`, for a replicated link
    written_inertia: np.ndarray | None = None  # the model's inertia, where `inertia` (simulated) replaces it
    seq: int = 0  # its place in the model (parts first, in declaration order), for exports that keep it


@dataclass
class Sensor:
    """One output port of a p-model sensor, as the mapping reads it (`pmodel::link::sref.port`)."""

    name: str  # the sref name
    device: str  # the sensor device (e.g. VelocitySensor)
    link: str  # the p-model link it is declared in (as written)
    joint: str | None  # the joint it measures
    quantity: str  # position | velocity | effort | gyro | velocimeter | accelerometer | closest_range |
    # closest_bearing | range | none
    port: str  # the device's output port
    body: str = ""  # the tree link it is mounted on (for body quantities)
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))  # in that link's frame
    component: int = 0  # which component of a 3-vector MuJoCo sensor the port reads
    via: str = ""  # the joint (as written) of a sensor declared inside a joint: its path has it
    ray: RaySpec | None = None  # the beams of a ray sensor (a LiDAR, a sonar), for its ray quantities


def reading_path(pmodel: str, sensor: Sensor) -> str:
    """The one name of a sensor port's reading, on every platform (the simulator, a replayed log, a live robot)
    and in every mapping and [monitor] reading: `pmodel::link::sref.port`, or `pmodel::link::joint::sref.port`
    for a sensor declared inside a joint, so that a PT and a DT name the same reading alike."""
    via = f"{sensor.via}::" if sensor.via else ""
    return f"{pmodel}::{sensor.link}::{via}{sensor.name}.{sensor.port}"


@dataclass
class PlacedDevice:
    """A sensor or actuator placed on a link, for SDF <sensor> elements: one per sref/aref."""

    name: str
    kind: str  # sensor | actuator
    device: str  # its definition's name
    link: str  # the tree link it is mounted on
    pose: np.ndarray  # in that link's frame
    sdf_type: str | None  # the SDF element it is written as: a sensor type (ray, sonar, imu, logical_camera,
    # light, ...) named by its annotation, `light` for an actuator annotated Light; None: not written
    annotation: dict | None  # the annotation giving its SDF data, evaluated: {"name": ..., "entries": [(key, value)]}
    sdf_name: str = ""  # its name in SDF, RoboTool's: `S`, `S::0` for a replica of an indexed one
    loc: Location = NOWHERE


@dataclass
class Servo:
    name: str  # the aref name
    device: str
    joint: str
    kp: float | None
    kd: float | None
    mode: str = "position"  # position | velocity | effort: what the command sets
    port: str = "dangle"  # the actuator's command input port (the mapping writes `...::aref.port`)


@dataclass
class TJoint:
    name: str
    kind: str  # revolute | prismatic | fixed
    parent: str
    child: str
    pose: np.ndarray  # joint frame in the model frame at zero
    axis: np.ndarray  # unit vector in the joint frame
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    effort: float | None = None
    damping: float = 0.0
    servos: list[Servo] = field(default_factory=list)
    source_link: str = ""  # the p-model link that declares it (as written)
    source: str = ""  # the joint's name as written (without a part prefix)
    annotations: dict = field(default_factory=dict)  # SDF annotation entries (dynamics...), evaluated
    loc: Location = NOWHERE  # the p-model joint (or fixed connection) it comes from
    sdf_kind: str = ""  # its SDF type where that is not `kind`: continuous, gearbox
    flipped: bool = False  # a fixed connection the tree reaches from its child: written child -> parent

    @property
    def start(self) -> float:
        """Where the simulator starts the joint: 0, or the limit nearest it when 0 is outside [lower, upper]
        (a robot started beyond its limits is thrown against them: the Kinova's joint 2 lies in [0.82, 5.46])."""
        low = -math.inf if self.lower is None else self.lower
        high = math.inf if self.upper is None else self.upper
        return min(max(0.0, low), high) if low <= high else 0.0


@dataclass
class KinematicTree:
    name: str
    links: list[TLink]  # root first, parents before children
    joints: list[TJoint]  # in the order of `links` (joint i leads to a child link)
    sensors: list[Sensor]
    loops: list[TJoint] = field(default_factory=list)  # joints closing kinematic loops (not in `joints`)
    devices: list[PlacedDevice] = field(default_factory=list)  # placed sensors and actuators (SDF)
    findings: list = field(default_factory=list)  # warnings of the readings chosen while building it
    stood_in: set[str] = field(default_factory=set)  # mesh files (as written) replaced by stand-ins

    def link(self, name: str) -> TLink:
        return next(l for l in self.links if l.name == name)

    @property
    def root(self) -> TLink:
        """The base: the first root link (the p-model's own before a part's)."""
        return self.links[0]

    @property
    def roots(self) -> list[TLink]:
        """Links no joint leads to: the base, then free bodies (as RoboTool's SDF has them)."""
        children = {j.child for j in self.joints}
        return [l for l in self.links if l.name not in children]

    def located(self, name: str) -> Location | None:
        """Where the link, joint or geometry of that (exported) name comes from in the p-model."""
        for element in (*self.links, *self.joints, *self.loops, *(g for l in self.links for g in l.geoms)):
            if element.name == name:
                return element.loc
        return None

    @property
    def actuated(self) -> list[TJoint]:
        return [j for j in self.joints if j.kind != "fixed"]

    def moved_alone(self) -> list[tuple[TLink, str]]:
        """The massless links a moving joint (or a free body's free joint) carries with nothing of mass fixed to them,
        each with what moves it: MuJoCo refuses such a body, so its model alone gives it a mass (cotwin.pmodel.mjcf);
        the tree keeps them massless, as the source says (a URDF link without <inertial>)."""
        fixed_below: dict[str, list[str]] = {}
        for j in self.joints:
            if j.kind == "fixed":
                fixed_below.setdefault(j.parent, []).append(j.child)
        links = {l.name: l for l in self.links}

        def rigid_mass(name: str) -> float:
            return links[name].mass + sum(rigid_mass(child) for child in fixed_below.get(name, ()))

        moved = [(j.child, f"joint {j.name}") for j in self.actuated]
        moved += [(l.name, "its free joint") for l in self.roots[1:]]
        return [(links[name], mover) for name, mover in moved if rigid_mass(name) <= 0]

    def _chain(self):
        """Per joint, the constant transforms around its motion: parent0^-1 J0 and J0^-1 child0."""
        if getattr(self, "_chain_cache", None) is None:
            poses = {l.name: l.pose for l in self.links}
            self._chain_cache = [(j.name, j.kind, j.axis, j.parent, j.child, inverse(poses[j.parent]) @ j.pose,
                                  inverse(j.pose) @ poses[j.child]) for j in self.joints]
        return self._chain_cache

    def forward(self, q: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        """World pose of every link frame for joint values q (missing joints at 0)."""
        q = q or {}
        world = {root.name: root.pose.copy() for root in self.roots}
        for name, kind, axis, parent, child, before, after in self._chain():
            value = q.get(name, 0.0)
            if kind == "revolute":
                motion = axis_angle(axis, value)
            elif kind == "prismatic":
                motion = np.eye(4)
                motion[:3, 3] = axis * value
            else:
                world[child] = world[parent] @ before @ after
                continue
            world[child] = world[parent] @ before @ motion @ after
        return world

    @property
    def start_posture(self) -> dict[str, float]:
        """The joint values the simulator starts from (TJoint.start): what a world places the robot by."""
        return {j.name: j.start for j in self.actuated}

    def geom_poses(self, q: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        links = self.forward(q)
        return {g.name: links[l.name] @ g.pose for l in self.links for g in l.geoms}


# ---- actuators: what a mapping commands ----

def servo_mode(joint: TJoint) -> str:
    """What a joint's command sets: its first servo's mode (position, velocity or effort); position without one."""
    return joint.servos[0].mode if joint.servos else "position"


def servo_name(joint: TJoint) -> str:
    """The name of the servo driving a joint (its first aref; `J_servo` for a joint declaring none)."""
    return joint.servos[0].name if joint.servos else f"{joint.name}_servo"


def command_path(pmodel: str, joint: TJoint, servo: Servo) -> str:
    """The one name of an actuator's command, on every platform (the simulator, a replayed log, a live robot)
    and in every mapping: `pmodel::link::joint::aref.port`, the port being the actuator's own command input
    (`dangle` of a ServoMotor, `speed` of a SpeedControlMotor, `ControlIn` of a ControlledMotor...), so that a
    PT and a DT take a speed- or effort-driven actuator's command by the same name."""
    return f"{pmodel}::{joint.source_link}::{joint.source}::{servo.name}.{servo.port}"


def actuator_names(tree: KinematicTree) -> dict[str, TJoint]:
    """Every name an actuator answers to -> the joint it moves: the joint's name, its servo's (servo_name), each
    aref's name and command_path. Every platform endpoint takes these names (or refuses one it cannot drive by
    name), so a mapping commands the PT as it commands the DT."""
    out: dict[str, TJoint] = {}
    for joint in tree.actuated:
        out[joint.name] = joint
        out[servo_name(joint)] = joint
        for servo in joint.servos:
            out.setdefault(servo.name, joint)
            out[command_path(tree.name, joint, servo)] = joint
    return out
