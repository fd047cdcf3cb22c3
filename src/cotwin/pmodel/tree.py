"""The kinematic tree of a p-model: the one intermediate form SDF, URDF, MJCF and the simulator share.

Conventions (docs/robosim-notation.md, section 3): a link's pose is in the model frame (the frame of
the including p-model for links of a part, composed with the part's pose); a joint's pose is relative
to its parent link; a joint axis is expressed in the joint frame; roll/pitch/yaw are fixed-axis
X-Y-Z angles (R = Rz(yaw) Ry(pitch) Rx(roll)), as in SDF and URDF. Everything is at joint values 0.

A sensor declared in a link measures the joint declared just before it in that link (the first
joint if it comes before any), which is how the UR5e model lists FSJ1..PSJ1 after
shoulder_pan_joint and the finger sensors after each finger joint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..diagnostics import CotwinError, Diagnostics
from ..robosim import syntax as s
from ..robosim.check_pmodel import pmodel_constants
from ..robosim.consteval import UNITS, ConstEnv, try_evaluate
from ..robosim.pmodel_elements import AnnotationRecord, Link, PModel, Pose, Shape
from .inertia import default_inertia

DEFAULT_MASS = 1.0  # kg, for a link without inertial information (a warning says so)


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
    kind: str  # box | cylinder | sphere | capsule
    size: dict[str, float]
    pose: np.ndarray  # relative to the link frame

    def volume(self) -> float:
        if self.kind == "box":
            return self.size["length"] * self.size["width"] * self.size["height"]
        if self.kind == "cylinder":
            return np.pi * self.size["radius"] ** 2 * self.size["length"]
        if self.kind == "capsule":
            r = self.size["radius"]
            return np.pi * r * r * self.size["length"] + 4 / 3 * np.pi * r ** 3
        return 4 / 3 * np.pi * self.size["radius"] ** 3


@dataclass
class TLink:
    name: str
    pose: np.ndarray  # model frame, at zero joint values
    mass: float
    com: np.ndarray  # pose of the centre of mass relative to the link frame
    inertia: np.ndarray  # 3x3 about the COM, in the COM frame
    geoms: list[Geom]
    source: str  # the p-model link name as written (paths use it)
    part: str | None = None


@dataclass
class Sensor:
    name: str  # the sref name
    device: str  # the sensor device (e.g. VelocitySensor)
    link: str  # the p-model link it is declared in (as written)
    joint: str | None  # the joint it measures
    quantity: str  # position | velocity | effort
    port: str  # the device's output port


@dataclass
class Servo:
    name: str  # the aref name
    device: str
    joint: str
    kp: float | None
    kd: float | None


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


@dataclass
class KinematicTree:
    name: str
    links: list[TLink]  # root first, parents before children
    joints: list[TJoint]  # in the order of `links` (joint i leads to a child link)
    sensors: list[Sensor]

    def link(self, name: str) -> TLink:
        return next(l for l in self.links if l.name == name)

    @property
    def root(self) -> TLink:
        return self.links[0]

    @property
    def actuated(self) -> list[TJoint]:
        return [j for j in self.joints if j.kind != "fixed"]

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
        world = {self.root.name: self.root.pose.copy()}
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

    def geom_poses(self, q: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        links = self.forward(q)
        return {g.name: links[l.name] @ g.pose for l in self.links for g in l.geoms}


# ---- building from a p-model --------------------------------------------------------------


SENSOR_QUANTITIES = (("position", "position"), ("angle", "position"), ("vel", "velocity"),
                     ("torque", "effort"), ("force", "effort"))


def sensor_quantity(device_name: str, port: str) -> str | None:
    """What a sensor measures, from its device and output port names (documented rule)."""
    text = f"{device_name} {port}".lower()
    for key, quantity in SENSOR_QUANTITIES:
        if key in text:
            return quantity
    return None


class _TreeBuilder:
    def __init__(self, project, diag: Diagnostics):
        self.project = project
        self.diag = diag
        self.links: dict[str, TLink] = {}
        self.joints: list[TJoint] = []
        self.sensors: list[Sensor] = []

    def num(self, expr, env: ConstEnv, what: str, default=0.0) -> float:
        if expr is None:
            return default
        value = try_evaluate(expr, env, self.diag, what)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            if value is not None:
                self.diag.error(expr.loc, f"{what} must be a number")
            return default
        return float(value)

    def pose(self, pose: Pose | None, env: ConstEnv, what: str) -> np.ndarray:
        if pose is None:
            return np.eye(4)
        v = {k: self.num(e, env, f"pose of {what}") for k, e, _ in pose.fields}
        return transform((v.get("x", 0.0), v.get("y", 0.0), v.get("z", 0.0)),
                         (v.get("roll", 0.0), v.get("pitch", 0.0), v.get("yaw", 0.0)))

    def shape(self, shape: Shape, env: ConstEnv, name: str, pose: np.ndarray) -> Geom | None:
        if shape.kind == "mesh":
            self.diag.warning(shape.loc, f"mesh in {name} is not exported (no mesh files): geometry skipped")
            return None
        size = {k: self.num(e, env, f"{shape.kind} of {name}") for k, e, _ in shape.params}
        return Geom(name, shape.kind, size, pose)

    def add_pmodel(self, pmodel: PModel, prefix: str, frame: np.ndarray, part: str | None) -> None:
        env = pmodel_constants(self.project, pmodel)
        for link in pmodel.links:
            self.add_link(link, env, prefix, frame, part)
        for part_ref in pmodel.parts:
            sub = self.project.lookup("pmodel", part_ref.pmodel)
            if sub is None:
                continue
            part_frame = frame @ self.pose(part_ref.pose, env, f"part {part_ref.name}")
            self.add_pmodel(sub, f"{prefix}{part_ref.name}_", part_frame, part_ref.name)
        for link in pmodel.links:
            self.add_joints(link, pmodel, env, prefix)

    def add_link(self, link: Link, env: ConstEnv, prefix: str, frame: np.ndarray, part: str | None) -> None:
        name = prefix + link.name
        pose = frame @ self.pose(link.pose, env, f"link {link.name}")
        geoms = []
        for k, shape in enumerate(link.shapes):
            g = self.shape(shape, env, f"{name}_shape{k}", np.eye(4))
            if g:
                geoms.append(g)
        for body in link.bodies:
            for k, shape in enumerate(body.shapes):
                suffix = "" if len(body.shapes) == 1 else f"_{k}"
                g = self.shape(shape, env, f"{prefix}{body.name}{suffix}", self.pose(body.pose, env, f"body {body.name}"))
                if g:
                    geoms.append(g)
        inertial = link.inertial
        if inertial is None or inertial.mass is None:
            mass = DEFAULT_MASS
        else:
            mass = self.num(inertial.mass, env, f"mass of {link.name}", DEFAULT_MASS) * UNITS.get(inertial.unit or "kg", 1.0)
        com = self.pose(inertial.pose if inertial else None, env, f"inertial of {link.name}")
        given = {k: self.num(e, env, f"inertia of {link.name}") for k, e, _ in (inertial.inertia if inertial else ())}
        if given:
            I = np.array([[given.get("ixx", 0.0), given.get("ixy", 0.0), given.get("ixz", 0.0)],
                          [given.get("ixy", 0.0), given.get("iyy", 0.0), given.get("iyz", 0.0)],
                          [given.get("ixz", 0.0), given.get("iyz", 0.0), given.get("izz", 0.0)]])
        else:
            I = default_inertia(mass, geoms, com)
        self.links[name] = TLink(name, pose, mass, com, I, geoms, link.name, part)

    def add_joints(self, link: Link, pmodel: PModel, env: ConstEnv, prefix: str) -> None:
        parent = prefix + link.name
        ordered = sorted([*link.joints, *link.sensors], key=lambda r: (r.loc.line, r.loc.column))
        current = None
        for ref in ordered:
            if hasattr(ref, "joint"):  # a JointRef
                current = ref
                self.add_joint(ref, parent, pmodel, env, prefix, link.name)
            else:
                self.add_sensor(ref, link, current or (link.joints[0] if link.joints else None), prefix, pmodel)
        for fixed in link.fixed_to:
            part = next((p for p in pmodel.parts if p.name == fixed.part), None)
            child = f"{prefix}{fixed.part}_{fixed.link}" if part else None
            if child not in self.links:
                continue
            self.joints.append(TJoint(f"{parent}_to_{child}", "fixed", parent, child, self.links[child].pose.copy(),
                                      np.array([0.0, 0.0, 1.0]), source_link=link.name))

    def add_joint(self, ref, parent: str, pmodel: PModel, env: ConstEnv, prefix: str, source_link: str) -> None:
        device = self.project.lookup("joint", ref.joint, self.project.file_of(pmodel))
        kind = (device.name if device else ref.joint.last).lower()
        kind = {"continuous": "revolute"}.get(kind, kind)
        if kind not in ("revolute", "prismatic", "fixed"):
            self.diag.error(ref.joint.loc, f"joint type '{ref.joint}' is not revolute, prismatic or fixed")
            return
        if ref.child is None:
            return
        child = prefix + (f"{ref.child_part}_" if ref.child_part else "") + ref.child
        if child not in self.links:
            return
        pose = self.links[parent].pose @ self.pose(ref.pose, env, f"joint {ref.name}")
        axis = np.array([0.0, 0.0, 1.0])
        joint = TJoint(prefix + ref.name, kind, parent, child, pose, axis, source_link=source_link, source=ref.name)
        for ann in ref.annotations:
            ax = ann.get("axis")
            if not isinstance(ax, AnnotationRecord):
                continue
            xyz = ax.get("xyz")
            if xyz is not None:
                value = try_evaluate(xyz, env, self.diag, f"axis of {ref.name}")
                if isinstance(value, tuple) and len(value) == 3:
                    vec = np.array([float(v) for v in value])
                    if np.linalg.norm(vec) > 0:
                        joint.axis = vec / np.linalg.norm(vec)
            dyn = ax.get("dynamics")
            if isinstance(dyn, AnnotationRecord):
                joint.damping = self.num(dyn.get("damping"), env, f"damping of {ref.name}")
            lim = ax.get("limit")
            if isinstance(lim, AnnotationRecord):
                for key in ("lower", "upper", "velocity", "effort"):
                    if lim.get(key) is not None:
                        setattr(joint, key, self.num(lim.get(key), env, f"limit {key} of {ref.name}"))
        for aref in ref.actuators:
            gains = {n: self.num(e, env, f"{aref.name}.{n}") for n, e, _ in aref.instantiations}
            joint.servos.append(Servo(aref.name, aref.device.last, joint.name, gains.get("Kp"), gains.get("Kd")))
        self.joints.append(joint)

    def add_sensor(self, ref, link: Link, joint, prefix: str, pmodel: PModel) -> None:
        device = self.project.lookup("sensor", ref.device, self.project.file_of(pmodel))
        if device is None:
            return
        outputs = [p for p in device.ports if p.kind == "output"]
        for port in outputs:
            quantity = sensor_quantity(device.name, port.name)
            if quantity is None:
                self.diag.warning(ref.loc, f"sensor {ref.name} ({device.name}.{port.name}): cannot tell what it "
                                  "measures (position, velocity, torque or force); it reads 0")
                quantity = "none"
            self.sensors.append(Sensor(ref.name, device.name, link.name, prefix + joint.name if joint else None,
                                       quantity, port.name))

    def order(self, name: str) -> KinematicTree:
        children = {j.child for j in self.joints}
        roots = [l for l in self.links if l not in children]
        if not roots:
            raise CotwinError(f"p-model {name} has no root link (a cycle of joints?)")
        ordered: list[str] = []
        joints: list[TJoint] = []
        stack = [roots[0]]
        while stack:
            current = stack.pop(0)
            ordered.append(current)
            for j in self.joints:
                if j.parent == current and j.child not in ordered:
                    joints.append(j)
                    stack.append(j.child)
        for other in roots[1:]:  # attach extra roots to the base with a fixed joint
            self.diag.warning(s.NOWHERE, f"link {other} is not connected to {roots[0]}: fixed to it")
            joints.append(TJoint(f"{roots[0]}_to_{other}", "fixed", roots[0], other, self.links[other].pose.copy(),
                                 np.array([0.0, 0.0, 1.0])))
            ordered.append(other)
        return KinematicTree(name, [self.links[n] for n in ordered], joints, self.sensors)


def build_tree(project, pmodel_name: str | None = None) -> KinematicTree:
    """The kinematic tree of a p-model (the only one not used as a part, or the one named)."""
    pmodels = project.elements(PModel)
    if pmodel_name is not None:
        pmodel = project.lookup("pmodel", pmodel_name)
        if pmodel is None:
            raise CotwinError(f"no p-model '{pmodel_name}' (p-models: {', '.join(p.name for p in pmodels)})")
    else:
        used = {p.pmodel.last for pm in pmodels for p in pm.parts}
        top = [p for p in pmodels if p.name not in used]
        if not pmodels:
            raise CotwinError("the model files hold no p-model (a .pm file with `pmodel NAME { ... }`)")
        if len(top) != 1:
            raise CotwinError("several p-models: choose one with --pmodel: " + ", ".join(p.name for p in top or pmodels))
        pmodel = top[0]
    diag = Diagnostics()
    builder = _TreeBuilder(project, diag)
    builder.add_pmodel(pmodel, "", np.eye(4), None)
    diag.raise_if_errors()
    return builder.order(pmodel.name)
