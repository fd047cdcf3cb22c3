"""Building the kinematic tree from a checked p-model: parts flattened, indexed elements replicated,
inertia gathered from links and bodies, meshes measured, joints, sensors and actuators classified.

Names: a link keeps its name; a part's links and joints get the part's name as prefix (`Gripper_...`,
as RoboTool's SKO generator writes `p1_L1`); an indexed element gets its index value as suffix
(`Tip_1`); a geometry is named after its body (`Wheel`), or `link_body` where that name is taken.
Anything a simulator needs and the model leaves open gets a documented default and a warning.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import replace

import numpy as np

from ..diagnostics import CotwinError, Diagnostics
from ..robosim import syntax as s
from ..robosim.check_pmodel import (
    device_env, device_of, index_values, joint_device, mesh_path, pmodel_constants, with_index,
)
from ..robosim.consteval import UNITS, ConstEnv, try_evaluate
from ..robosim.pmodel_elements import AnnotationRecord, BodyDecl, DeviceRef, Inertial, JointRef, Link, LinkDecl, PModel, Pose, Shape
from .inertia import FALLBACK_RADIUS, beyond_reach, default_inertia, reach, valid_inertia
from .kinds import body_quantity, joint_motion, ray_quantity, ray_spec, sdf_sensor_type, sensor_quantity, servo_command
from .meshes import READABLE, bounding_box
from .tree import Geom, KinematicTree, PlacedDevice, Sensor, Servo, StandIn, TJoint, TLink, transform

DEFAULT_MASS = 1.0  # kg, for a link without (usable) inertial information (the checker warns)
MIN_SIZE = 1e-4  # m: flat shapes (RoboTool accepts a box of height 0) get this thickness
WHEEL_TOLERANCE = 1e-3  # m: a wheel's axis this far from its geometry's centre is moved through it


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _scalar(port) -> bool:
    """A port of a number type (a ray sensor's scan record or sequence is not one)."""
    return isinstance(port.type, s.NamedType) and port.type.name.last in ("real", "int", "nat")


class TreeBuilder:
    def __init__(self, project, diag: Diagnostics, stand_ins: dict[str, list[StandIn]] | None = None):
        self.project = project
        self.diag = diag
        self.stand_ins = dict(stand_ins or {})
        self.stood_in: set[str] = set()  # stand-ins used
        self.links: dict[str, TLink] = {}
        self.joints: list[TJoint] = []
        self.sensors: list[Sensor] = []
        self.devices: list[PlacedDevice] = []
        self.geom_names: set[str] = set()
        self.part_links: list = []  # (prefix, part ref) whose `link L fixed to M` clauses wait for all links
        self.joint_children: dict[str, str] = {}  # joint tree name -> child tree name, from part clauses

    # ---- values ----
    def num(self, expr, env: ConstEnv, what: str, default=0.0) -> float:
        if expr is None:
            return default
        value = try_evaluate(expr, env, self.diag, what)
        if not _number(value):
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

    def record(self, record: AnnotationRecord, env: ConstEnv) -> dict:
        """An annotation evaluated: {"name": ..., "entries": [(key, value or nested record)]}."""
        entries = []
        for entry in record.entries:
            value = entry.value
            entries.append((entry.key, self.record(value, env) if isinstance(value, AnnotationRecord)
                            else try_evaluate(value, env, None)))
        return {"name": record.name, "entries": entries}

    def _unique(self, name: str, fallback: str) -> str:
        for candidate in (name, fallback):
            if candidate not in self.geom_names:
                self.geom_names.add(candidate)
                return candidate
        k = 2
        while f"{fallback}_{k}" in self.geom_names:
            k += 1
        self.geom_names.add(f"{fallback}_{k}")
        return f"{fallback}_{k}"

    # ---- p-models and parts ----
    def add_pmodel(self, pmodel: PModel, prefix: str, frame: np.ndarray, part: str | None,
                   instantiations=()) -> None:
        env = pmodel_constants(self.project, pmodel, instantiations)
        source = self.project.file_of(pmodel)
        placed = [(link, v, with_index(env, link.index, v)) for link in pmodel.links
                  for v in index_values(link.index, env)]
        for link, v, lenv in placed:
            self.add_link(link, lenv, self._link_name(prefix, link, v), prefix, frame, part, source)
        for part_ref in pmodel.parts:
            sub = self.project.lookup("pmodel", part_ref.pmodel, source)
            if sub is None:
                continue
            part_frame = frame @ self.pose(part_ref.pose, env, f"part {part_ref.name}")
            values = tuple((n, s.Literal(try_evaluate(e, env, None), loc) if _number(try_evaluate(e, env, None)) else e, loc)
                           for n, e, loc in part_ref.instantiations)
            inner = f"{prefix}{part_ref.name}_"
            for pj in part_ref.joints:
                owner = f"{prefix}{pj.child_part}_" if pj.child_part else prefix
                self.joint_children[inner + pj.joint] = owner + pj.child
            self.add_pmodel(sub, inner, part_frame, part_ref.name, values)
            self.part_links.append((prefix, part_ref))
        for link, v, lenv in placed:
            self.add_joints(link, pmodel, lenv, prefix, self._link_name(prefix, link, v), source)

    @staticmethod
    def _link_name(prefix: str, link: Link, value) -> str:
        return prefix + link.name + (f"_{value}" if link.index is not None else "")

    def connect_parts(self) -> None:
        """`link L fixed to M [in P]` clauses of parts, once every link exists."""
        for prefix, part_ref in self.part_links:
            for fixed in part_ref.fixed:
                parent = (f"{prefix}{fixed.target_part}_" if fixed.target_part else prefix) + fixed.target
                child = f"{prefix}{part_ref.name}_{fixed.link}"
                self._fixed(parent, child, part_ref.name)

    def _fixed(self, parent: str, child: str, source_link: str) -> None:
        if parent not in self.links or child not in self.links:
            return
        self.joints.append(TJoint(f"{parent}_to_{child}", "fixed", parent, child, self.links[child].pose.copy(),
                                  np.array([0.0, 0.0, 1.0]), source_link=source_link))

    # ---- links, bodies, geometry, inertia ----
    def add_link(self, link: Link, env: ConstEnv, name: str, prefix: str, frame: np.ndarray, part: str | None,
                 source) -> None:
        decl = self.project.lookup("link", link.ref, source) if link.ref is not None else None
        pose = frame @ self.pose(link.pose, env, f"link {link.name}")
        geoms: list[Geom] = []
        shapes = (*link.shapes, *(decl.shapes if isinstance(decl, LinkDecl) else ()))
        for k, shape in enumerate(shapes):
            geoms.extend(self.geom(shape, env, f"{name}_shape{k}", f"{name}_shape{k}", np.eye(4), "", source))
        masses = []  # (mass, com pose in the link frame, inertia or None) of bodies with inertial information
        for body in link.bodies:
            bdecl = self.project.lookup("body", body.ref, source) if body.ref is not None else None
            bdecl = bdecl if isinstance(bdecl, BodyDecl) else None
            for v in index_values(body.index, env):
                benv = with_index(env, body.index, v)
                label = body.name + (f"_{v}" if body.index is not None else "")
                body_pose = self.pose(body.pose, benv, f"body {body.name}")
                body_shapes = body.shapes or (bdecl.shapes if bdecl else ())
                surface = self.surface(body.surface or (bdecl.surface if bdecl else None), benv)
                body_geoms = []
                for k, shape in enumerate(body_shapes):
                    suffix = "" if len(body_shapes) == 1 else f"_{k}"
                    body_geoms.extend(self.geom(shape, benv, f"{prefix}{label}{suffix}", f"{name}_{label}{suffix}",
                                                body_pose, body.name, source, surface))
                geoms.extend(body_geoms)
                inertial = body.inertial or (bdecl.inertial if bdecl else None)
                if inertial is not None:
                    m, com, inertia = self.inertial(inertial, benv, f"body {body.name}", body_geoms, body_pose)
                    if m is not None:
                        masses.append((m, body_pose @ com, inertia))
        inertial = link.inertial or (decl.inertial if isinstance(decl, LinkDecl) else None)
        if inertial is not None:
            mass, com, I = self.inertial(inertial, env, f"link {link.name}", geoms, np.eye(4))
            if mass is None:
                mass, com = DEFAULT_MASS, self.pose(inertial.pose, env, f"inertial of {link.name}")
                I = default_inertia(mass, geoms, com)
        elif masses:
            mass, com, I = self.combine(masses, geoms)
        else:
            mass, com = DEFAULT_MASS, np.eye(4)
            I = default_inertia(mass, geoms, com)
        self.links[name] = TLink(name, pose, mass, com, I, geoms, link.name, part)

    def inertial(self, inertial: Inertial, env: ConstEnv, what: str, geoms: list[Geom], frame: np.ndarray):
        """(mass, COM pose in its holder's frame, inertia about the COM); mass None if not usable."""
        if inertial.mass is None:
            return None, np.eye(4), None
        mass = self.num(inertial.mass, env, f"mass of {what}", 0.0) * UNITS.get(inertial.unit or "kg", 1.0)
        com = self.pose(inertial.pose, env, f"inertial of {what}")
        if mass <= 0:
            return None, com, None
        given = {k: self.num(e, env, f"inertia of {what}") for k, e, _ in inertial.inertia}
        local = [self._shift(g, np.linalg.inv(frame)) for g in geoms]
        if given:
            I = np.array([[given.get("ixx", 0.0), given.get("ixy", 0.0), given.get("ixz", 0.0)],
                          [given.get("ixy", 0.0), given.get("iyy", 0.0), given.get("iyz", 0.0)],
                          [given.get("ixz", 0.0), given.get("iyz", 0.0), given.get("izz", 0.0)]])
            far = reach(local, com)
            if not valid_inertia(I):
                self.diag.warning(inertial.loc, f"inertia of {what} is not physical (not positive definite or "
                                  "against the triangle inequality): the geometry's inertia is used")
                I = default_inertia(mass, local, com)
            elif far is not None and beyond_reach(I, mass, far):
                moment = float(np.linalg.eigvalsh(I).max())
                self.diag.warning(inertial.loc, f"inertia of {what} is beyond what its geometry allows (a moment of "
                                  f"{moment:.4g} kg m^2, where {mass:.4g} kg within {far:.4g} m of its centre of mass "
                                  f"give at most {mass * far * far:.4g}): the geometry's inertia is used")
                I = default_inertia(mass, local, com)
        else:
            I = default_inertia(mass, local, com)
        return mass, com, I

    @staticmethod
    def _shift(g: Geom, T: np.ndarray) -> Geom:
        return replace(g, pose=T @ g.pose)

    @staticmethod
    def combine(masses, geoms) -> tuple[float, np.ndarray, np.ndarray]:
        """Bodies' masses gathered into their link: total mass, common COM, inertia about it (parallel axes)."""
        total = sum(m for m, _, _ in masses)
        c = sum(m * T[:3, 3] for m, T, _ in masses) / total
        I = np.zeros((3, 3))
        for m, T, Ib in masses:
            R = T[:3, :3]
            Ib = Ib if Ib is not None else default_inertia(m, [], np.eye(4))
            d = T[:3, 3] - c
            I += R @ Ib @ R.T + m * (d @ d * np.eye(3) - np.outer(d, d))
        com = np.eye(4)
        com[:3, 3] = c
        return total, com, (I + I.T) / 2

    def surface(self, surface, env: ConstEnv) -> dict:
        if surface is None:
            return {}
        out = {}
        for key in ("restitution", "threshold", "laser_retro"):
            if getattr(surface, key) is not None:
                out[key] = self.num(getattr(surface, key), env, key)
        for group, entries, _ in surface.friction:
            out.setdefault("friction", {})[group] = {k: try_evaluate(v, env, None) for k, v, _ in entries}
        return out

    def geom(self, shape: Shape, env: ConstEnv, name: str, fallback: str, pose: np.ndarray, body: str, source,
             surface: dict | None = None) -> list[Geom]:
        surface = surface or {}
        if shape.kind == "mesh":
            return self.mesh(shape, env, name, fallback, pose, body, source, surface)
        size = {k: max(self.num(e, env, f"{shape.kind} of {name}"), MIN_SIZE) for k, e, _ in shape.params}
        return [Geom(self._unique(name, fallback), shape.kind, size, pose, body, surface)]

    def mesh(self, shape: Shape, env, name, fallback, pose, body, source, surface) -> Geom:
        params = {k: e for k, e, _ in shape.params}
        file = try_evaluate(params["shape"], env, None) if "shape" in params else None
        scaling = try_evaluate(params["scaling"], env, None) if "scaling" in params else 1.0
        scale = tuple(float(v) for v in scaling) if isinstance(scaling, tuple) else (float(scaling),) * 3 \
            if _number(scaling) else (1.0, 1.0, 1.0)
        path = mesh_path(source.path if source else ".", file) if isinstance(file, str) else None
        if path is not None and path.is_file() and path.suffix.lower() in READABLE:
            try:
                low, high = bounding_box(path)
            except ValueError as err:
                self.diag.warning(shape.loc, f"{err}: a placeholder stands in for it")
            else:
                low, high = low * scale, high * scale
                extent = np.maximum(np.abs(high - low), MIN_SIZE)
                size = {"length": float(extent[0]), "width": float(extent[1]), "height": float(extent[2])}
                return [Geom(self._unique(name, fallback), "mesh", size, pose, body, surface, str(path.resolve()),
                             scale, tuple(float(v) for v in (low + high) / 2), written=file)]
        elif path is not None and path.is_file():
            self.diag.warning(shape.loc, f"mesh '{file}' is not a format cotwin measures ({', '.join(READABLE)}): "
                              "a placeholder stands in for it")
        if isinstance(file, str) and file in self.stand_ins:
            self.stood_in.add(file)
            out = []
            for k, stand in enumerate(self.stand_ins[file]):
                own = dict(surface)
                if stand.friction is not None:
                    own["friction"] = {**own.get("friction", {}), "translational": {"coefficient1": stand.friction}}
                out.append(Geom(self._unique(name if k == 0 else f"{name}_{k}", f"{fallback}_{k}"), stand.kind,
                                dict(stand.size), pose @ stand.pose, body, own, written=file))
            return out
        return [Geom(self._unique(name, fallback), "sphere", {"radius": FALLBACK_RADIUS}, pose, body, surface,
                     placeholder=True, written=file if isinstance(file, str) else "")]

    # ---- joints, sensors, actuators ----
    def add_joints(self, link: Link, pmodel: PModel, env: ConstEnv, prefix: str, parent: str, source) -> None:
        ordered = sorted([*link.joints, *link.sensors], key=lambda r: (r.loc.line, r.loc.column))
        current = None
        for ref in ordered:
            if isinstance(ref, JointRef):
                current = ref
                self.add_joint(ref, parent, env, prefix, link.name, source)
            else:
                measured = current or (link.joints[0] if link.joints else None)
                self.add_sensor(ref, link, prefix + measured.name if measured else None, parent, env, source)
        for aref in link.actuators:
            self.place(aref, "actuator", parent, env, source)
        for fixed in link.fixed_to:
            child = prefix + (f"{fixed.part}_" if fixed.part else "") + fixed.link
            self._fixed(parent, child, link.name)

    def add_joint(self, ref: JointRef, parent: str, env: ConstEnv, prefix: str, source_link: str, source) -> None:
        name = prefix + ref.name
        device = joint_device(self.project, ref, source)
        denv = device_env(device, ref.instantiations, env) if device is not None else env
        type_name = device.name if device is not None else (ref.joint.last if ref.joint else ref.name)
        kind, axis, note = joint_motion(device, type_name, ref.annotations, denv)
        if kind is None:
            self.diag.warning(ref.loc, f"joint {ref.name} ({type_name}): cannot tell a revolute, prismatic or fixed "
                              "joint from its definition; exported as fixed")
            kind = "fixed"
        elif note:
            self.diag.warning(ref.loc, f"joint {ref.name}: {note}")
        child = self.joint_children.get(name)
        if child is None and ref.child is not None:
            child = prefix + (f"{ref.child_part}_" if ref.child_part else "") + ref.child
        if child is None or child not in self.links or parent not in self.links:
            return
        pose = self.links[parent].pose @ self.pose(ref.pose, env, f"joint {ref.name}")
        joint = TJoint(name, kind, parent, child, pose, axis, source_link=source_link, source=ref.name)
        for ann in ref.annotations:
            ax = ann.get("axis")
            if not isinstance(ax, AnnotationRecord):
                continue
            joint.annotations = self.record(ann, denv)
            dyn = ax.get("dynamics")
            if isinstance(dyn, AnnotationRecord):
                joint.damping = self.num(dyn.get("damping"), denv, f"damping of {ref.name}")
            lim = ax.get("limit")
            if isinstance(lim, AnnotationRecord):
                for key in ("lower", "upper", "velocity", "effort"):
                    if lim.get(key) is not None:
                        setattr(joint, key, self.num(lim.get(key), denv, f"limit {key} of {ref.name}"))
        for aref in ref.actuators:
            actuator = device_of(self.project, aref, source)
            gains = {n: self.num(e, env, f"{aref.name}.{n}") for n, e, _ in aref.instantiations}
            port, mode = servo_command(actuator)
            joint.servos.append(Servo(aref.name, actuator.name if actuator else aref.name, name, gains.get("Kp"),
                                      gains.get("Kd"), mode, port or "dangle"))
        self._centre_wheel(joint, ref)
        self.joints.append(joint)
        for sref in ref.sensors:
            self.add_sensor(sref, None, name, parent, env, source, source_link, ref.name)

    def _centre_wheel(self, joint: TJoint, ref: JointRef) -> None:
        """A revolute joint driven by a speed (a wheel) whose axis misses the centre of its child's geometry
        would spin that geometry eccentrically, which no wheel does: its axis is moved, parallel, through
        that centre, with a warning (the published TurtleBot3 puts its wheel joints 13 mm below the wheels)."""
        if joint.kind != "revolute" or not joint.servos or joint.servos[0].mode != "velocity":
            return
        child = self.links[joint.child]
        if not child.geoms or any(g.placeholder for g in child.geoms):
            return
        centres = []
        for g in child.geoms:
            centre = g.pose[:3, 3] + g.pose[:3, :3] @ np.asarray(g.center) if g.kind == "mesh" else g.pose[:3, 3]
            centres.append(child.pose[:3, :3] @ centre + child.pose[:3, 3])
        centre = np.mean(centres, axis=0)
        axis = joint.pose[:3, :3] @ joint.axis
        offset = centre - joint.pose[:3, 3]
        off_axis = offset - axis * (offset @ axis)
        miss = float(np.linalg.norm(off_axis))
        if miss > WHEEL_TOLERANCE:
            self.diag.warning(ref.loc, f"joint {ref.name} turns {joint.child} by speed (a wheel) about an axis "
                              f"{miss * 1000:.3g} mm from the centre of its geometry: read as the parallel axis "
                              "through that centre")
            joint.pose = joint.pose.copy()
            joint.pose[:3, 3] = joint.pose[:3, 3] + off_axis

    def place(self, ref: DeviceRef, kind: str, parent: str, env: ConstEnv, source) -> list[tuple[str, ConstEnv, np.ndarray]]:
        """Record a sensor or actuator for SDF (one per index value); returns (name, env, pose) of each."""
        device = device_of(self.project, ref, source)
        annotations = (*ref.annotations, *(device.annotations if device else ()))
        sdf_type = sdf_sensor_type(device.name if device else ref.name, annotations) if kind == "sensor" else None
        placed = []
        for v in index_values(ref.index, env):
            renv = with_index(env, ref.index, v)
            if device is not None:
                renv = device_env(device, ref.instantiations, renv)
            name = ref.name + (f"_{v}" if ref.index is not None else "")
            pose = self.pose(ref.pose, renv, f"{kind} {ref.name}")
            chosen = next((a for a in annotations if sdf_type is None or sdf_sensor_type("", (a,)) == sdf_type), None)
            self.devices.append(PlacedDevice(name, kind, device.name if device else ref.name, parent, pose, sdf_type,
                                             self.record(chosen, renv) if chosen is not None else None))
            placed.append((name, renv, pose))
        return placed

    def add_sensor(self, ref: DeviceRef, link: Link | None, joint: str | None, parent: str, env: ConstEnv, source,
                   link_name: str | None = None, via: str = "") -> None:
        device = device_of(self.project, ref, source)
        placed = self.place(ref, "sensor", parent, env, source)
        if device is None:
            return
        sdf_type = self.devices[-1].sdf_type if placed else None
        written = link.name if link is not None else (link_name or "")
        for k, (name, _, pose) in enumerate(placed):
            unknown = []
            device_record = self.devices[len(self.devices) - len(placed) + k].annotation
            ray = ray_spec(sdf_type, device_record) if sdf_type in ("ray", "sonar") else None
            for port in (p for p in device.ports if p.kind == "output"):
                body = body_quantity(sdf_type, port.name)
                if body is not None:
                    self.sensors.append(Sensor(name, device.name, written, joint, body[0], port.name, parent, pose,
                                               body[1], via))
                    continue
                beam = ray_quantity(port.name) if ray is not None and _scalar(port) else None
                if beam is not None:
                    self.sensors.append(Sensor(name, device.name, written, None, beam, port.name, parent, pose, 0,
                                               via, ray))
                    continue
                # a sensor of the body (ray, camera...) measures no joint, whatever its ports are called
                joint_sensor = joint is not None and sdf_type is None
                quantity = (sensor_quantity(device.name, port.name) if joint_sensor else None) or "none"
                if quantity == "none":
                    unknown.append(port.name)
                self.sensors.append(Sensor(name, device.name, written, joint if joint_sensor else None, quantity,
                                           port.name, parent, pose, 0, via))
            if unknown:
                self.diag.warning(ref.loc, f"sensor {name} ({device.name}): cotwin's simulator cannot tell what "
                                  f"{', '.join(unknown)} measure{'s' if len(unknown) == 1 else ''}; they read 0")

    # ---- the tree ----
    def order(self, name: str) -> KinematicTree:
        """Links root first, each joint leading to a new link; joints reaching a link again close loops."""
        if not self.links:
            raise CotwinError(f"p-model {name} has no links")
        outgoing = defaultdict(list)
        for j in self.joints:
            outgoing[j.parent].append(j)
        children = {j.child for j in self.joints}
        candidates = [l for l in self.links if l not in children] or list(self.links)
        root = candidates[0]
        ordered, tree_joints, loops = [root], [], []
        reached = {root}
        queue = [root]
        while True:
            while queue:
                current = queue.pop(0)
                for j in outgoing[current]:
                    if j.child in reached:
                        loops.append(j)
                    else:
                        reached.add(j.child)
                        tree_joints.append(j)
                        ordered.append(j.child)
                        queue.append(j.child)
            rest = [l for l in candidates if l not in reached] or [l for l in self.links if l not in reached]
            if not rest:
                break
            other = rest[0]  # an extra root (or a loop no root reaches): fixed to the base
            self.diag.warning(s.NOWHERE, f"link {other} is not connected to {root}: fixed to it")
            tree_joints.append(TJoint(f"{root}_to_{other}", "fixed", root, other, self.links[other].pose.copy(),
                                      np.array([0.0, 0.0, 1.0])))
            ordered.append(other)
            reached.add(other)
            queue.append(other)
        for j in loops:
            self.diag.warning(s.NOWHERE, f"joint {j.name} closes a kinematic loop ({j.parent} -> {j.child})")
        return KinematicTree(name, [self.links[n] for n in ordered], tree_joints, self.sensors, loops, self.devices)
