"""Building the kinematic tree from a checked p-model: parts and indexed elements instantiated, inertia
gathered from links and bodies, meshes measured, joints, sensors and actuators classified.

The model is walked in the order RoboTool's SDF generator walks it (a p-model's parts, each in full,
then its own links; joints and fixed connections once every link exists), so that parameters without a
value get the values RoboTool gives them (cotwin.robosim.pmodel_scope). Names and constants are
resolved by cotwin.robosim.pmodel_scope, as the checker resolves them.

Names (docs/pmodel-notation.md, section 7) are unique per scope, as dm_control's mjcf namescopes keep
them: a link keeps its name (`link_2fg7_base`, also in a part), a replica of an indexed link is
`1-Tip`, `2-Tip`, ... (its index value); only where two elements would have one name are they
qualified by their scope (`p/L2`, `1-p/L2` for a replica of an indexed part, `Bottom/0-PJ` for a joint
of one of several links), with a warning at each for links and joints. Anything a simulator needs and
the model leaves open gets a documented default and a warning.
"""

from __future__ import annotations

import math

from collections import defaultdict
from dataclasses import dataclass, field, replace

import numpy as np

from ..diagnostics import CotwinError, Diagnostics, Location
from ..robosim import syntax as s
from ..robosim.check_pmodel import MOVING_FRAME_MASS, grams
from ..robosim.consteval import UNITS, ConstEnv, ParameterNumbering, try_evaluate
from ..robosim.pmodel_elements import (
    AnnotationRecord, DeviceRef, Inertial, JointRef, Link, PartRef, PModel, Pose, Shape,
)
from ..robosim.pmodel_scope import PModelScope, element_reference, mesh_path
from .inertia import FALLBACK_RADIUS, beyond_reach, default_inertia, reach, valid_inertia
from .kinematics import ElementRef, Geom, KinematicTree, PlacedDevice, Sensor, Servo, StandIn, TJoint, TLink, transform
from .kinds import JOINT_KINDS, RaySpec, annotated_sdf_type, body_quantity, joint_motion, ray_quantity, ray_spec, \
    sdf_sensor_type, sensor_quantity, servo_command
from .meshes import READABLE, bounding_box

DEFAULT_MASS = 1.0  # kg: RoboTool's for a link without inertial information
DEFAULT_INERTIA = np.eye(3)  # kg m^2: RoboTool's (ixx = iyy = izz = 1) for a link without inertial information
MIN_SIZE = 1e-4  # m: flat shapes (RoboTool accepts a box of height 0) get this thickness
RESERVED = frozenset({"world"})  # link names a simulator keeps for itself (MuJoCo's world body)
WHEEL_TOLERANCE = 1e-3  # m: a wheel's axis this far from its geometry's centre is moved through it


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _scalar(port) -> bool:
    """A port of a number type (a ray sensor's scan record or sequence is not one)."""
    return isinstance(port.type, s.NamedType) and port.type.name.last in ("real", "int", "nat")


def _label(name: str, value) -> str:
    """A replica's name: `1-Tip` for value 1 of `index i` on Tip (RoboTool's form), the name otherwise."""
    return name if value is None else f"{value}-{name}"


def _bound(limit: float | None, absent: float) -> float:
    """A joint limit as written, or the unbounded side it stands for when absent."""
    return absent if limit is None else limit


@dataclass(eq=False)
class _Instance:
    """A p-model as instantiated: the top one, or one part (one replica of an indexed part)."""

    pmodel: PModel
    env: ConstEnv
    frame: np.ndarray
    path: tuple[str, ...]  # part labels from the top (`Gripper`, `1-p`)
    ref: PartRef | None = None  # the part clause instantiating it
    parent: "_Instance | None" = None
    links: dict[str, list["_LinkInstance"]] = field(default_factory=dict)  # written name -> replicas
    parts: dict[str, list["_Instance"]] = field(default_factory=dict)  # part name -> replicas


@dataclass(eq=False)
class _LinkInstance:
    link: Link
    scope: _Instance
    env: ConstEnv
    label: str
    tlink: TLink


@dataclass(eq=False)
class _Named:
    """An element to name: its candidate names, least qualified first."""

    element: object
    candidates: list[str]
    kind: str  # link | joint | geometry
    loc: Location


class TreeBuilder:
    def __init__(self, project, diag: Diagnostics, stand_ins: dict[str, list[StandIn]] | None = None,
                 rays: dict[str, RaySpec] | None = None):
        self.project = project
        self.rays = rays  # a robot profile's ray sensor defaults ("lidar", "sonar"), where it gives them
        self.diag = diag
        self.stand_ins = dict(stand_ins or {})
        self.stood_in: set[str] = set()  # stand-ins used
        self.numbering = ParameterNumbering()
        self.scope = PModelScope(project, self.numbering)
        self.instances: list[_LinkInstance] = []
        self.joints: list[TJoint] = []
        self.sensors: list[Sensor] = []
        self.devices: list[PlacedDevice] = []
        self._named: list[_Named] = []
        self._links_named: list[tuple[object, str, TLink]] = []  # (element, attribute, link): set once links are named

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

    def record(self, record: AnnotationRecord, env: ConstEnv, where: "_LinkInstance | None" = None) -> dict:
        """An annotation evaluated: {"name": ..., "entries": [(key, value or nested record)]}; a value naming a
        body, link or part of the model becomes a reference to it (written as its exported name)."""
        entries = []
        for entry in record.entries:
            value = entry.value
            if isinstance(value, AnnotationRecord):
                entries.append((entry.key, self.record(value, env, where)))
                continue
            ref = self._element(value, where) if where is not None else None
            entries.append((entry.key, ref if ref is not None else try_evaluate(value, env, None)))
        return {"name": record.name, "entries": entries}

    def _element(self, expr, where: _LinkInstance) -> ElementRef | None:
        found = element_reference(expr, where.scope.pmodel, where.link, self.scope)
        if found is None:
            return None
        kind, element, holder = found
        if kind == "part":
            replicas = where.scope.parts.get(element.name, [])
            return ElementRef("part", replicas[0]) if replicas else None
        if kind == "link":
            scope = where.scope if holder is None else (where.scope.parts.get(holder.name) or [None])[0]
            replicas = scope.links.get(element.name, []) if scope is not None else []
            return ElementRef("link", replicas[0].tlink) if replicas else None
        owner = where if holder is where.link else next(iter(where.scope.links.get(holder.name, [])), None)
        geom = next((g for g in owner.tlink.geoms if g.body == element.name), None) if owner else None
        return ElementRef("body", geom) if geom is not None else None

    # ---- p-models and parts (RoboTool's order: a p-model's parts first, then its links) ----
    def instantiate(self, pmodel: PModel, env: ConstEnv, frame: np.ndarray, path: tuple[str, ...],
                    ref: PartRef | None = None, parent: _Instance | None = None) -> _Instance:
        inst = _Instance(pmodel, env, frame, path, ref, parent)
        for part in pmodel.parts:
            sub = self.scope.part_pmodel(part)
            if sub is None:
                continue
            for value in self.scope.index_values(part.index, env):
                penv = self.scope.with_index(env, part.index, value)
                part_frame = frame @ self.pose(part.pose, penv, f"part {part.name}")
                sub_env = self.scope.pmodel_env(sub, part.instantiations, evaluated_in=penv)
                label = _label(part.name, value)
                inst.parts.setdefault(part.name, []).append(
                    self.instantiate(sub, sub_env, part_frame, path + (label,), part, inst))
        source = self.project.file_of(pmodel)
        for link in pmodel.links:
            for value in self.scope.index_values(link.index, env):
                lenv = self.scope.decls_env(link.variables, self.scope.with_index(env, link.index, value))
                label = _label(link.name, value)
                tlink = self.add_link(link, lenv, label, path, frame, source, value)
                tlink.seq = len(self.instances)
                instance = _LinkInstance(link, inst, lenv, label, tlink)
                inst.links.setdefault(link.name, []).append(instance)
                self.instances.append(instance)
                self._named.append(_Named(tlink, [label, "/".join(path + (label,))], "link", link.loc))
                self.place_all(instance)
        return inst

    # ---- links, bodies, geometry, inertia ----
    def add_link(self, link: Link, env: ConstEnv, label: str, path: tuple[str, ...], frame: np.ndarray, source,
                 value) -> TLink:
        decl = self.scope.link_decl(link)
        pose = frame @ self.pose(link.pose, env, f"link {link.name}")
        qualified = "/".join(path + (label,))
        geoms: list[Geom] = []
        shapes = (*link.shapes, *(decl.shapes if decl is not None else ()))
        for k, shape in enumerate(shapes):
            geoms.extend(self.geom(shape, env, [f"{label}_shape{k}", f"{qualified}_shape{k}"], np.eye(4), "", source))
        masses = []  # (mass, com pose in the link frame, inertia or None) of bodies with inertial information
        declared = False  # a body gives inertial information (of mass 0 where `masses` stays empty)
        for body in link.bodies:
            bdecl = self.scope.body_decl(body.ref)
            for v in self.scope.index_values(body.index, env):
                benv = self.scope.decls_env(body.variables, self.scope.with_index(env, body.index, v))
                blabel = _label(body.name, v)
                body_pose = self.pose(body.pose, benv, f"body {body.name}")
                body_shapes = body.shapes or (bdecl.shapes if bdecl else ())
                surface = self.surface(body.surface or (bdecl.surface if bdecl else None), benv)
                body_geoms = []
                for k, shape in enumerate(body_shapes):
                    suffix = "" if len(body_shapes) == 1 else f"_{k}"
                    body_geoms.extend(self.geom(shape, benv, [f"{blabel}{suffix}", f"{qualified}/{blabel}{suffix}"],
                                                body_pose, body.name, source, surface))
                geoms.extend(body_geoms)
                inertial = body.inertial or (bdecl.inertial if bdecl else None)
                if inertial is not None:
                    declared = True
                    m, com, inertia, given = self.inertial(inertial, benv, f"body {body.name}", body_geoms, body_pose)
                    if m is not None:
                        masses.append((m, body_pose @ com, inertia, given))
        inertial = link.inertial or (decl.inertial if decl is not None else None)
        written = None  # the inertia as the model gives it, where the tree has a physical one instead
        if inertial is not None:
            mass, com, I, written = self.inertial(inertial, env, f"link {link.name}", geoms, np.eye(4))
            if mass is None:  # mass 0: a massless frame (a URDF link without <inertial>); see warn_moved_alone
                mass, com, I = 0.0, np.eye(4), np.zeros((3, 3))
        elif masses:
            mass, com, I = self.combine([(m, T, inertia) for m, T, inertia, _ in masses])
            if any(given is not None for *_, given in masses):
                written = self.combine([(m, T, inertia if given is None else given) for m, T, inertia, given in masses])[2]
        elif declared:  # its bodies' inertial information all says mass 0: massless, as a link saying it itself
            mass, com, I = 0.0, np.eye(4), np.zeros((3, 3))
        else:  # RoboTool's SDF generator gives a link without inertial information 1 kg and a unit inertia
            mass, com, I = DEFAULT_MASS, np.eye(4), DEFAULT_INERTIA.copy()
        part = "/".join(path) if path else None
        return TLink(label, pose, mass, com, I, geoms, link.name, part, link.loc, value, written)

    def inertial(self, inertial: Inertial, env: ConstEnv, what: str, geoms: list[Geom], frame: np.ndarray):
        """(mass, COM pose in its holder's frame, inertia about the COM, the model's inertia where that one
        replaces it); mass None if not usable."""
        if inertial.mass is None:
            return None, np.eye(4), None, None
        mass = self.num(inertial.mass, env, f"mass of {what}", 0.0) * UNITS.get(inertial.unit or "kg", 1.0)
        com = self.pose(inertial.pose, env, f"inertial of {what}")
        if mass <= 0:
            return None, com, None, None
        given = {k: self.num(e, env, f"inertia of {what}") for k, e, _ in inertial.inertia}
        written = None
        local = [self._shift(g, np.linalg.inv(frame)) for g in geoms]
        if given:
            I = np.array([[given.get("ixx", 0.0), given.get("ixy", 0.0), given.get("ixz", 0.0)],
                          [given.get("ixy", 0.0), given.get("iyy", 0.0), given.get("iyz", 0.0)],
                          [given.get("ixz", 0.0), given.get("iyz", 0.0), given.get("izz", 0.0)]])
            far = reach(local, com)
            if not valid_inertia(I):
                self.diag.warning(inertial.loc, f"inertia of {what} is not physical (not positive definite or "
                                  "against the triangle inequality): the geometry's inertia is simulated (SDF "
                                  "writes the model's, as RoboTool does)")
                I, written = default_inertia(mass, local, com), I
            elif far is not None and beyond_reach(I, mass, far):
                moment = float(np.linalg.eigvalsh(I).max())
                self.diag.warning(inertial.loc, f"inertia of {what} is beyond what its geometry allows (a moment of "
                                  f"{moment:.4g} kg m^2, where {mass:.4g} kg within {far:.4g} m of its centre of mass "
                                  f"give at most {mass * far * far:.4g}): the geometry's inertia is simulated (SDF "
                                  "writes the model's, as RoboTool does)")
                I, written = default_inertia(mass, local, com), I
        else:
            I = default_inertia(mass, local, com)
        return mass, com, I, written

    @staticmethod
    def _shift(g: Geom, T: np.ndarray) -> Geom:
        return replace(g, pose=T @ g.pose)

    @staticmethod
    def combine(masses) -> tuple[float, np.ndarray, np.ndarray]:
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

    def _geom(self, candidates: list[str], shape: Shape, *args, **kwargs) -> Geom:
        g = Geom(candidates[0], *args, loc=shape.loc, **kwargs)
        self._named.append(_Named(g, list(candidates), "geometry", shape.loc))
        return g

    def geom(self, shape: Shape, env: ConstEnv, names: list[str], pose: np.ndarray, body: str, source,
             surface: dict | None = None) -> list[Geom]:
        surface = surface or {}
        if shape.kind == "mesh":
            return self.mesh(shape, env, names, pose, body, source, surface)
        size = {k: max(self.num(e, env, f"{shape.kind} of {names[0]}"), MIN_SIZE) for k, e, _ in shape.params}
        return [self._geom(names, shape, shape.kind, size, pose, body, surface)]

    def mesh(self, shape: Shape, env, names, pose, body, source, surface) -> list[Geom]:
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
                return [self._geom(names, shape, "mesh", size, pose, body, surface, str(path.resolve()), scale,
                                   tuple(float(v) for v in (low + high) / 2), written=file)]
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
                out.append(self._geom([n if k == 0 else f"{n}_{k}" for n in names], shape, stand.kind, dict(stand.size),
                                      pose @ stand.pose, body, own, written=file))
            return out
        return [self._geom(names, shape, "sphere", {"radius": FALLBACK_RADIUS}, pose, body, surface,
                           placeholder=True, written=file if isinstance(file, str) else "")]

    # ---- joints and fixed connections (once every link exists) ----
    def targets(self, scope: _Instance, name: str, part_name: str | None, loc: Location) -> list[_LinkInstance]:
        """Every replica of the link a joint or fixed connection of `scope` names (all replicas of an indexed
        link, or of the link in every replica of an indexed part)."""
        target, _, _ = self.scope.link_target(scope.pmodel, name, part_name)  # the checker reported problems
        if target is None:
            return []
        holders = [scope] if target.part is None else scope.parts.get(target.part.name, [])
        return [replica for holder in holders for replica in holder.links.get(target.link.name, [])]

    def connect(self, scope: _Instance) -> None:
        for replicas in scope.parts.values():
            for inst in replicas:
                self.connect(inst)
        overrides = {pj.joint: pj for pj in scope.ref.joints} if scope.ref is not None else {}
        for replicas in scope.links.values():
            for instance in replicas:
                self.add_joints(instance, overrides)
        base = next((i for replicas in scope.links.values() for i in replicas), None)
        for joint in scope.pmodel.joints:  # declared in the p-model: the base link is the parent
            if base is not None:
                self.add_joint(joint, base, base.env, None)
        if scope.ref is not None and scope.parent is not None:
            for fixed in scope.ref.fixed:  # `link L fixed to M [in P]` of a part clause
                for target in self.targets(scope.parent, fixed.target, fixed.target_part, fixed.loc):
                    for link in scope.links.get(fixed.link, []):  # RoboTool: the part's link is the parent
                        self._fixed(link, target, fixed.loc)

    def add_joints(self, instance: _LinkInstance, overrides: dict) -> None:
        link = instance.link
        ordered = sorted([*link.joints, *link.sensors], key=lambda r: (r.loc.line, r.loc.column))
        current = None
        for ref in ordered:
            if isinstance(ref, JointRef):
                current = ref
                self.add_joint(ref, instance, instance.env, overrides.get(ref.name))
            else:
                measured = current or (link.joints[0] if link.joints else None)
                self.add_sensor(ref, instance, measured)
        for fixed in link.fixed_to:
            for child in self.targets(instance.scope, fixed.link, fixed.part, fixed.loc):
                self._fixed(instance, child, fixed.loc)

    def _fixed(self, parent: _LinkInstance, child: _LinkInstance, loc: Location) -> None:
        joint = TJoint("", "fixed", parent.tlink.name, child.tlink.name, child.tlink.pose.copy(),
                       np.array([0.0, 0.0, 1.0]), source_link=parent.link.name, loc=loc)
        self._link_name(joint, "parent", parent.tlink), self._link_name(joint, "child", child.tlink)
        self.joints.append(joint)
        label = f"{parent.label}_to_{child.label}"
        self._named.append(_Named(joint, [label, "/".join(parent.scope.path + (label,)),
                                          "/".join(parent.scope.path + (parent.label, label))], "joint", loc))

    def add_joint(self, ref: JointRef, parent: _LinkInstance, env: ConstEnv, override) -> None:
        device = self.scope.joint_device(ref)
        type_name = device.name if device is not None else (ref.joint.last if ref.joint else ref.name)
        if override is not None:  # `joint J flexibly connected to L [in P]` of the part clause
            children = self.targets(parent.scope.parent, override.child, override.child_part, override.loc)
        elif ref.child is not None:
            children = self.targets(parent.scope, ref.child, ref.child_part, ref.child_loc)
        else:
            children = []
        for value in self.scope.index_values(ref.index, env):
            jenv = self.scope.with_index(env, ref.index, value)
            denv = self.scope.device_env(device, ref.instantiations, jenv) if device is not None else jenv
            motion = joint_motion(device, type_name, ref.annotations, denv)
            if motion.kind is None:
                self.diag.error(ref.loc, f"joint {ref.name} ({type_name}): {motion.note}")
                return
            if motion.note:
                self.diag.warning(ref.loc, f"joint {ref.name}: {motion.note}")
            label = _label(ref.name, value)
            for child in children:
                self._joint(ref, label, parent, child, jenv, denv, motion)

    def _joint(self, ref: JointRef, label: str, parent: _LinkInstance, child: _LinkInstance, env: ConstEnv,
               denv: ConstEnv, motion) -> None:
        pose = parent.tlink.pose @ self.pose(ref.pose, env, f"joint {ref.name}")
        joint = TJoint(label, motion.kind, parent.tlink.name, child.tlink.name, pose, motion.axis,
                       source_link=parent.link.name, source=ref.name, loc=ref.loc, sdf_kind=motion.sdf_kind)
        self._link_name(joint, "parent", parent.tlink), self._link_name(joint, "child", child.tlink)
        main = next((a for a in ref.annotations if a.name.lower() in JOINT_KINDS), None) or next(
            (a for a in ref.annotations if isinstance(a.get("axis"), AnnotationRecord)), None)
        if main is not None:
            joint.annotations = self.record(main, denv, parent)
            ax = main.get("axis")
            dyn = ax.get("dynamics") if isinstance(ax, AnnotationRecord) else None
            if isinstance(dyn, AnnotationRecord):
                joint.damping = self.num(dyn.get("damping"), denv, f"damping of {ref.name}")
            lim = ax.get("limit") if isinstance(ax, AnnotationRecord) else None
            if isinstance(lim, AnnotationRecord):
                for key in ("lower", "upper", "velocity", "effort"):
                    if lim.get(key) is not None:
                        setattr(joint, key, self.num(lim.get(key), denv, f"limit {key} of {ref.name}"))
                if joint.start != 0.0:
                    self.diag.warning(ref.loc, f"joint {ref.name}: its zero position is outside its limits "
                                      f"[{_bound(joint.lower, -math.inf):g}, {_bound(joint.upper, math.inf):g}]: the simulator "
                                      f"starts it at {joint.start:g}")
        for aref in ref.actuators:
            actuator = self.scope.device_of(aref)
            gains = {n: self.num(e, env, f"{aref.name}.{n}") for n, e, _ in aref.instantiations}
            port, mode = servo_command(actuator)
            joint.servos.append(Servo(aref.name, actuator.name if actuator else aref.name, label, gains.get("Kp"),
                                      gains.get("Kd"), mode, port or "dangle"))
            self.place(aref, "actuator", parent, env)
        self._centre_wheel(joint, ref, child.tlink)
        self.joints.append(joint)
        scope, target = parent.scope.path, "/".join(child.scope.path + (child.label,))
        self._named.append(_Named(joint, [label, "/".join(scope + (label,)), "/".join(scope + (label,)) + "@" + target,
                                          "/".join(scope + (parent.label, label)) + "@" + target], "joint", ref.loc))
        for sref in ref.sensors:
            self.add_sensor(sref, parent, ref, via=ref.name, joint=joint)

    def _centre_wheel(self, joint: TJoint, ref: JointRef, child: TLink) -> None:
        """A revolute joint driven by a speed (a wheel) whose axis misses the centre of its child's geometry
        would spin that geometry eccentrically, which no wheel does: its axis is moved, parallel, through
        that centre, with a warning (a published mobile robot's p-model puts its wheel joints 13 mm below the wheels)."""
        if joint.kind != "revolute" or not joint.servos or joint.servos[0].mode != "velocity":
            return
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
            self.diag.warning(ref.loc, f"joint {ref.name} turns {child.source} by speed (a wheel) about an axis "
                              f"{miss * 1000:.3g} mm from the centre of its geometry: read as the parallel axis "
                              "through that centre")
            joint.pose = joint.pose.copy()
            joint.pose[:3, 3] = joint.pose[:3, 3] + off_axis

    # ---- sensors and actuators ----
    def place_all(self, instance: _LinkInstance) -> None:
        """A link's own actuators (sensors are placed with the joints they measure, in declaration order)."""
        for aref in instance.link.actuators:
            self.place(aref, "actuator", instance, instance.env)

    def place(self, ref: DeviceRef, kind: str, holder: _LinkInstance, env: ConstEnv) -> list[tuple[str, ConstEnv, np.ndarray]]:
        """Record a sensor or actuator (one per index value) with the SDF element RoboTool writes for it: a
        <sensor> of the type its annotation names, a <light> for an actuator annotated Light, or none."""
        device = self.scope.device_of(ref)
        annotations = (*ref.annotations, *(device.annotations if device else ()))
        sdf_type, chosen = annotated_sdf_type(annotations)
        if kind == "actuator" and sdf_type != "light":
            sdf_type, chosen = None, None
        sim_type = sdf_sensor_type(device.name if device else ref.name, annotations) if kind == "sensor" else None
        placed = []
        for v in self.scope.index_values(ref.index, env):
            renv = self.scope.with_index(env, ref.index, v)
            if device is not None:
                renv = self.scope.device_env(device, ref.instantiations, renv)
            name = ref.name + (f"_{v}" if ref.index is not None else "")
            pose = self.pose(ref.pose, renv, f"{kind} {ref.name}")
            record = self.record(chosen, renv, holder) if chosen is not None else None
            if record is None and sim_type is not None and kind == "sensor":  # the simulator's reading of it
                other = next((a for a in annotations if sdf_sensor_type("", (a,)) == sim_type), None)
                record = self.record(other, renv, holder) if other is not None else None
            placed_device = PlacedDevice(name, kind, device.name if device else ref.name, holder.tlink.name, pose,
                                         sdf_type, record, ref.name + (f"::{v}" if ref.index is not None else ""), ref.loc)
            self._link_name(placed_device, "link", holder.tlink)
            self.devices.append(placed_device)
            placed.append((name, renv, pose, sim_type, record))
        return placed

    def add_sensor(self, ref: DeviceRef, holder: _LinkInstance, measured: JointRef | None, via: str = "",
                   joint: TJoint | None = None) -> None:
        device = self.scope.device_of(ref)
        placed = self.place(ref, "sensor", holder, holder.env)
        if device is None:
            return
        # the joint measured, named once every joint is (rename_references)
        joint_name = joint if joint is not None else (measured.name, holder.tlink) if measured is not None else None
        for name, _, pose, sim_type, record in placed:
            unknown = []
            ray = ray_spec(sim_type, record, self.rays) if sim_type in ("ray", "sonar") else None
            for port in (p for p in device.ports if p.kind == "output"):
                body = body_quantity(sim_type, port.name)
                if body is not None:
                    self._sensor(Sensor(name, device.name, holder.link.name, None, body[0], port.name,
                                        holder.tlink.name, pose, body[1], via), holder)
                    continue
                beam = ray_quantity(port.name) if ray is not None and _scalar(port) else None
                if beam is not None:
                    self._sensor(Sensor(name, device.name, holder.link.name, None, beam, port.name,
                                        holder.tlink.name, pose, 0, via, ray), holder)
                    continue
                # a sensor of the body (ray, camera...) measures no joint, whatever its ports are called
                joint_sensor = joint_name is not None and sim_type is None
                quantity = (sensor_quantity(device.name, port.name) if joint_sensor else None) or "none"
                if quantity == "none":
                    unknown.append(port.name)
                self._sensor(Sensor(name, device.name, holder.link.name, joint_name if joint_sensor else None,
                                    quantity, port.name, holder.tlink.name, pose, 0, via), holder)
            if unknown:
                self.diag.warning(ref.loc, f"sensor {name} ({device.name}): cotwin's simulator cannot tell what "
                                  f"{', '.join(unknown)} measure{'s' if len(unknown) == 1 else ''}; they read 0")

    def _sensor(self, sensor: Sensor, holder: _LinkInstance) -> None:
        self._link_name(sensor, "body", holder.tlink)
        self.sensors.append(sensor)

    # ---- names unique per scope ----
    def name_elements(self) -> None:
        """Every link, joint and geometry gets its least qualified candidate name that no other element of
        its kind has (links and joints: the qualification is reported at the element)."""
        for kind in ("link", "joint", "geometry"):
            items = [n for n in self._named if n.kind == kind]
            level = {id(n): 0 for n in items}
            while True:
                groups = defaultdict(list)
                for n in items:
                    groups[n.candidates[min(level[id(n)], len(n.candidates) - 1)]].append(n)
                clashing = [g for g in groups.values() if len(g) > 1
                            and any(level[id(n)] < len(n.candidates) - 1 for n in g)]
                if not clashing:
                    break
                for group in clashing:
                    for n in group:
                        level[id(n)] += 1
            taken: dict[str, int] = {}
            for n in items:
                name = n.candidates[min(level[id(n)], len(n.candidates) - 1)]
                if kind == "link" and name in RESERVED:  # MuJoCo's world body has it
                    self.diag.warning(n.loc, f"link {name} has the name of MuJoCo's world body: it is named "
                                      f"{name}_link in the exports")
                    name = f"{name}_link"
                if name in taken:  # the same element declared twice (the checker reported it)
                    taken[name] += 1
                    name = f"{name}#{taken[name]}"
                taken.setdefault(name, 1)
                if level[id(n)] > 0 and kind != "geometry":
                    self.diag.warning(n.loc, f"{kind} {n.candidates[0]} has the name of another {kind} of the model: "
                                      f"it is named {name} in the exports")
                n.element.name = name

    def _link_name(self, element, attribute: str, tlink: TLink) -> str:
        """`tlink`'s name, for `element.attribute`: set again once names are chosen (name_elements)."""
        self._links_named.append((element, attribute, tlink))
        return tlink.name

    def rename_references(self) -> None:
        """Joints, sensors and devices name links, servos and sensors name joints, by the names just chosen
        (a sensor of a link measures the first joint of that name declared in that link)."""
        for element, attribute, tlink in self._links_named:
            setattr(element, attribute, tlink.name)
        for joint in self.joints:
            for servo in joint.servos:
                servo.joint = joint.name
        for sensor in self.sensors:
            if isinstance(sensor.joint, tuple):
                written, tlink = sensor.joint
                sensor.joint = next((j for j in self.joints if j.source == written and j.parent == tlink.name), None)
            if isinstance(sensor.joint, TJoint):
                sensor.joint = sensor.joint.name

    # ---- the tree ----
    def order(self, name: str, loc: Location) -> KinematicTree:
        """Links from the base, each joint leading to a new link; joints reaching a link again close loops;
        links nothing leads to are free bodies (RoboTool's SDF has them so), after the base's tree. The
        base is the p-model's first own link no joint leads to; a fixed connection joins two links rigidly
        whichever way it is written, and is followed backwards where that reaches more of the model."""
        if not self.instances:
            raise CotwinError([f"p-model {name} has no links"])
        tlinks = list({id(i.tlink): i.tlink for i in self.instances}.values())
        names = {l.name: l for l in tlinks}
        edges = defaultdict(list)  # link -> (joint, other end, traversed backwards)
        for j in self.joints:
            edges[j.parent].append((j, j.child, False))
            if j.kind == "fixed":
                edges[j.child].append((j, j.parent, True))
        moved = {j.child for j in self.joints if j.kind != "fixed"}  # links a moving joint leads to
        fixed_children = {j.child for j in self.joints if j.kind == "fixed"}
        candidates = [l.name for l in tlinks if l.name not in moved]
        own = [n for n in candidates if names[n].part is None]

        def reach(start: str) -> int:
            seen, queue = {start}, [start]
            while queue:
                for _, other, _ in edges[queue.pop()]:
                    if other not in seen:
                        seen.add(other)
                        queue.append(other)
            return len(seen)

        pool = own or candidates or [tlinks[0].name]
        base = max(pool, key=lambda n: (reach(n), -pool.index(n)))  # the most reaching, the first declared
        ordered, tree_joints, loops, reached, used = [], [], [], set(), set()
        starts = [base] + [l.name for l in tlinks if l.name not in moved and l.name not in fixed_children]
        for root in starts + [l.name for l in tlinks]:
            if root in reached:
                continue
            if root not in starts:  # a loop no root reaches: its first link stands free
                self.diag.warning(names[root].loc, f"link {root} is reached only through a kinematic loop: it is a "
                                  "free body")
            reached.add(root)
            ordered.append(root)
            queue = [root]
            while queue:
                current = queue.pop(0)
                for j, other, backwards in edges[current]:
                    if id(j) in used:
                        continue
                    used.add(id(j))
                    if other in reached:
                        loops.append(j)
                        continue
                    if backwards:  # a fixed connection followed from its child: written as RoboTool writes it
                        j.parent, j.child, j.flipped = j.child, j.parent, True
                        j.pose = names[j.child].pose.copy()
                    reached.add(other)
                    tree_joints.append(j)
                    ordered.append(other)
                    queue.append(other)
        for j in loops:
            self.diag.warning(j.loc, f"joint {j.name} closes a kinematic loop ({j.parent} -> {j.child})")
        free = [n for n in ordered if n != ordered[0] and n not in {j.child for j in tree_joints}]
        tree = KinematicTree(name, [names[n] for n in ordered], tree_joints, self.sensors, loops, self.devices)
        self.warn_moved_alone(tree)
        if free:
            self.diag.warning(loc, f"p-model {name}: no joint or fixed connection leads to {', '.join(free)}: free "
                              f"bodies beside the base {ordered[0]}, as in RoboTool's SDF")
        return tree

    def warn_moved_alone(self, tree: KinematicTree) -> None:
        """A massless link (mass 0) is a frame: fixed to its parent, it adds nothing, as in URDF. Where a moving joint
        (or a free body's) carries one with nothing of mass fixed to it, MuJoCo's model gives it MOVING_FRAME_MASS
        (cotwin.pmodel.mjcf; the tree keeps it massless): a warning names it, never a silent gram."""
        for link, mover in tree.moved_alone():
            self.diag.warning(link.loc, f"link {link.name} has no mass and {mover} moves it with nothing of mass fixed "
                              f"to it: MuJoCo needs a mass there, so the simulator gives it {grams(MOVING_FRAME_MASS)} "
                              "with the inertia of its geometry (a link a fixed joint carries stays massless); give it "
                              "inertial information with its real mass")

    def build(self, pmodel: PModel) -> KinematicTree:
        top = self.instantiate(pmodel, self.scope.pmodel_env(pmodel), np.eye(4), ())
        self.connect(top)
        self.name_elements()
        self.rename_references()
        self.report_parameters()
        self.diag.raise_if_errors()
        return self.order(pmodel.name, pmodel.loc)

    def report_parameters(self) -> None:
        for decl, value in self.numbering.given.values():
            self.diag.warning(decl.loc, f"'{decl.name}' has no value: it is {value}, as RoboTool's SDF generator "
                              "numbers parameters (1, 2, 3, ... in the order it meets them)")


def build_tree(project, pmodel_name: str | None = None, stand_ins: dict[str, list[StandIn]] | None = None,
               rays: dict[str, RaySpec] | None = None) -> KinematicTree:
    """The kinematic tree of a p-model (the only one not used as a part, or the one named); `stand_ins`
    gives shapes for mesh files (as the p-model names them) that cannot be read; `rays` the beams of ray
    sensors whose annotations leave them out ("lidar", "sonar": a robot profile's, cotwin.mapping.profile)."""
    pmodels = project.elements(PModel)
    if pmodel_name is not None:
        pmodel = project.lookup("pmodel", pmodel_name)
        if pmodel is None:  # a p-model of a package, by its simple name
            named = [p for p in pmodels if p.name == pmodel_name]
            if len(named) > 1:
                raise CotwinError(f"several p-models named '{pmodel_name}': give its package "
                                  f"({', '.join('::'.join(project.qualified_name(p)) for p in named)})")
            pmodel = named[0] if named else None
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
    builder = TreeBuilder(project, diag, stand_ins, rays)
    tree = builder.build(pmodel)
    tree.findings = list(diag.findings)
    tree.stood_in = set(builder.stood_in)
    return tree
