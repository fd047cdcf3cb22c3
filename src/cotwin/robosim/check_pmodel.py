"""Checks of p-model elements: devices, links, joints, parts; every constant dimension evaluates."""

from __future__ import annotations

from dataclasses import dataclass

from .checker import Checker
from . import syntax as s
from .consteval import UNITS, ConstEnv, const_env, try_evaluate
from .declarations import VarDecl
from .pmodel_elements import AnnotationRecord, Device, DeviceRef, JointRef, Link, PModel, Pose, Shape
from .typecheck import ExprChecker, Scope, Symbol
from .types import REAL

SHAPE_PARAMS = {
    "box": ("length", "width", "height"),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
    "sphere": ("radius",),
    "mesh": (),
}
INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


@dataclass(frozen=True)
class PlacedLink:
    """A link of a p-model after parts are flattened: where it comes from and its constants."""

    link: Link
    pmodel: PModel
    part: str | None  # the part it came through (None for the p-model's own links)


def file_constants(project) -> ConstEnv:
    """Top-level `const` declarations of all .pm files: the outermost constant scope."""
    decls = [e for f in project.files if f.notation == "pm" for e in f.elements if isinstance(e, VarDecl)]
    return const_env(decls)


def pmodel_constants(project, pmodel: PModel) -> ConstEnv:
    return const_env(pmodel.constants, file_constants(project))


def flatten_links(project, pmodel: PModel, _seen: frozenset = frozenset()) -> dict[str, PlacedLink]:
    """All links of a p-model by name, its own first, then those of its parts (recursively)."""
    out: dict[str, PlacedLink] = {link.name: PlacedLink(link, pmodel, None) for link in pmodel.links}
    for part in pmodel.parts:
        sub = project.lookup("pmodel", part.pmodel)
        if sub is None or sub.name in _seen or sub is pmodel:
            continue
        for name, placed in flatten_links(project, sub, _seen | {pmodel.name}).items():
            out.setdefault(name, PlacedLink(placed.link, placed.pmodel, placed.part or part.name))
    return out


class PModelChecker(Checker):

    def check(self) -> None:
        for element in self.source.elements:
            if isinstance(element, Device):
                self.device(element)
            elif isinstance(element, PModel):
                self.pmodel(element)
            elif isinstance(element, VarDecl) and element.init is not None:
                try_evaluate(element.init, file_constants(self.project), self.diag, f"constant {element.name}")

    # ---- devices ----
    def device(self, device: Device) -> None:
        seen: dict[str, s.Location] = {}
        scope = Scope({"t": Symbol("t", "param", REAL, device.loc)})
        for port in device.ports:
            if port.name in seen:
                self.diag.error(port.loc, f"duplicate port '{port.name}' in {device.kind} {device.name}")
            seen[port.name] = port.loc
            scope.symbols[port.name] = Symbol(port.name, "port", self.types.resolve(port.type), port.loc)
        checker = ExprChecker(self.types, self.diag, scope, self.functions)
        for eq in device.equations:
            checker.condition(eq, f"equation of {device.kind} {device.name}")

    # ---- p-models ----
    def pmodel(self, pmodel: PModel) -> None:
        env = pmodel_constants(self.project, pmodel)
        for const in pmodel.constants:
            if const.init is None:
                self.diag.error(const.loc, f"constant '{const.name}' of p-model {pmodel.name} has no value")
            else:
                try_evaluate(const.init, env, self.diag, f"constant {const.name}")
        names: dict[str, Link] = {}
        for link in pmodel.links:
            if link.name in names:
                self.diag.error(link.loc, f"duplicate link '{link.name}' (first at line {names[link.name].loc.line})")
            names[link.name] = link
        for part in pmodel.parts:
            sub = self.project.lookup("pmodel", part.pmodel, self.source)
            if sub is None:
                self.diag.error(part.pmodel.loc, f"unknown p-model '{part.pmodel}' for part {part.name}")
            elif sub is pmodel or self._includes(sub, pmodel.name):
                self.diag.error(part.loc, f"part {part.name} includes p-model {pmodel.name} in itself")
            if part.pose is not None:
                self.pose(part.pose, env, f"part {part.name}")
        all_links = flatten_links(self.project, pmodel)
        children: dict[str, str] = {}
        for link in pmodel.links:
            self.link(link, pmodel, env, all_links, children)
        roots = [link for link in pmodel.links if link.name not in children]
        if len(roots) > 1:
            self.diag.warning(roots[1].loc, f"p-model {pmodel.name} has several root links: "
                              + ", ".join(r.name for r in roots) + f"; '{roots[0].name}' is taken as the base")

    def _includes(self, pmodel: PModel, name: str, depth: int = 0) -> bool:
        if depth > 16:
            return True
        for part in pmodel.parts:
            sub = self.project.lookup("pmodel", part.pmodel, self.source)
            if sub is not None and (sub.name == name or self._includes(sub, name, depth + 1)):
                return True
        return False

    def link(self, link: Link, pmodel: PModel, env: ConstEnv, all_links: dict[str, PlacedLink],
             children: dict[str, str]) -> None:
        where = f"link {link.name}"
        if link.inertial is None:
            self.diag.warning(link.loc, f"{where} has no inertial information; a default mass is used")
        else:
            inertial = link.inertial
            if inertial.mass is None:
                self.diag.error(inertial.loc, f"inertial information of {where} has no mass")
            else:
                mass = try_evaluate(inertial.mass, env, self.diag, f"mass of {where}")
                if isinstance(mass, (int, float)) and not isinstance(mass, bool) and mass <= 0:
                    self.diag.error(inertial.mass.loc, f"mass of {where} must be positive, is {mass}")
            if inertial.unit is not None and inertial.unit not in UNITS:
                self.diag.error(inertial.loc, f"unknown unit '{inertial.unit}' (known: {', '.join(UNITS)})")
            for key, value, loc in inertial.inertia:
                if key not in INERTIA_KEYS:
                    self.diag.error(loc, f"unknown inertia entry '{key}' (known: {', '.join(INERTIA_KEYS)})")
                try_evaluate(value, env, self.diag, f"inertia of {where}")
            if inertial.pose is not None:
                self.pose(inertial.pose, env, f"inertial of {where}")
        if link.pose is not None:
            self.pose(link.pose, env, where)
        for shape in link.shapes:
            self.shape(shape, env, where)
        for body in link.bodies:
            for shape in body.shapes:
                self.shape(shape, env, f"body {body.name}")
            if body.pose is not None:
                self.pose(body.pose, env, f"body {body.name}")
        for ann in link.annotations:
            self.annotation(ann, env)
        for joint in link.joints:
            self.joint(joint, link, pmodel, env, all_links, children)
        for ref in (*link.sensors, *link.actuators):
            self.device_ref(ref, env)
        for fixed in link.fixed_to:
            part = next((p for p in pmodel.parts if p.name == fixed.part), None)
            if part is None:
                self.diag.error(fixed.loc, f"{where} is fixed to a link in unknown part '{fixed.part}'")
                continue
            sub = self.project.lookup("pmodel", part.pmodel, self.source)
            if sub is not None and fixed.link not in flatten_links(self.project, sub):
                self.diag.error(fixed.loc, f"part {fixed.part} (p-model {sub.name}) has no link '{fixed.link}'")
            children.setdefault(fixed.link, link.name)

    def joint(self, joint: JointRef, link: Link, pmodel: PModel, env: ConstEnv,
              all_links: dict[str, PlacedLink], children: dict[str, str]) -> None:
        device = self.project.lookup("joint", joint.joint, self.source)
        if device is None:
            self.diag.error(joint.joint.loc, f"unknown joint type '{joint.joint}' (import physmod::joints::* or declare it)")
        for ann in joint.annotations:
            self.annotation(ann, env)
            axis = ann.get("axis")
            xyz = axis.get("xyz") if isinstance(axis, AnnotationRecord) else None
            if xyz is not None:
                value = try_evaluate(xyz, env, None)
                if not (isinstance(value, tuple) and len(value) == 3 and any(v != 0 for v in value)):
                    self.diag.error(xyz.loc, f"axis of joint {joint.name} must be a non-zero 3-vector (|x, y, z|)")
        for _, value, _ in joint.instantiations:
            try_evaluate(value, env, self.diag, f"joint {joint.name}")
        if joint.pose is not None:
            self.pose(joint.pose, env, f"joint {joint.name}")
        if joint.child is None:
            self.diag.error(joint.loc, f"joint {joint.name} is not connected to a child link ('flexibly connected to ...')")
        else:
            if joint.child_part is not None:
                part = next((p for p in pmodel.parts if p.name == joint.child_part), None)
                sub = self.project.lookup("pmodel", part.pmodel, self.source) if part else None
                known = sub is not None and joint.child in flatten_links(self.project, sub)
            else:
                known = joint.child in all_links
            if not known:
                self.diag.error(joint.child_loc, f"joint {joint.name}: unknown child link '{joint.child}'")
            elif joint.child in children:
                self.diag.error(joint.child_loc, f"link '{joint.child}' already has a parent ({children[joint.child]})")
            elif joint.child == link.name:
                self.diag.error(joint.child_loc, f"joint {joint.name} connects link '{link.name}' to itself")
            else:
                children[joint.child] = link.name
        for ref in joint.actuators:
            self.device_ref(ref, env, joint=joint, joint_device=device)

    def device_ref(self, ref: DeviceRef, env: ConstEnv, joint: JointRef | None = None, joint_device=None) -> None:
        kind = "sensor" if ref.kind == "sref" else "actuator"
        device = self.project.lookup(kind, ref.device, self.source)
        if device is None:
            self.diag.error(ref.device.loc, f"unknown {kind} '{ref.device}'")
            return
        for name, value, loc in ref.instantiations:
            if device.port(name) is None:
                self.diag.error(loc, f"{kind} {device.name} has no constant '{name}'")
            try_evaluate(value, env, self.diag, f"{ref.name}.{name}")
        owners = {ref.name: device}
        if joint is not None and joint_device is not None:
            owners[joint.name] = joint_device
        for relation in ref.relations:
            for node in s.walk(relation):
                if isinstance(node, s.FieldAccess) and isinstance(node.base, s.Name) and len(node.base.name.parts) == 1:
                    owner = owners.get(node.base.name.last)
                    if owner is None:
                        self.diag.error(node.base.loc, f"relation of {ref.name}: unknown '{node.base.name}' "
                                        f"(expected {' or '.join(owners)})")
                    elif owner.port(node.field) is None:
                        self.diag.error(node.loc, f"{owner.kind} {owner.name} has no port '{node.field}'")

    def annotation(self, record: AnnotationRecord, env: ConstEnv) -> None:
        for entry in record.entries:
            if isinstance(entry.value, AnnotationRecord):
                self.annotation(entry.value, env)
            else:
                try_evaluate(entry.value, env, self.diag, f"annotation {record.name}.{entry.key}")

    def pose(self, pose: Pose, env: ConstEnv, where: str) -> None:
        for key, value, _ in pose.fields:
            v = try_evaluate(value, env, self.diag, f"pose of {where}")
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                self.diag.error(value.loc, f"pose {key} of {where} must be a number")

    def shape(self, shape: Shape, env: ConstEnv, where: str) -> None:
        required = SHAPE_PARAMS.get(shape.kind, ())
        given = {name for name, _, _ in shape.params}
        for missing in [r for r in required if r not in given]:
            self.diag.error(shape.loc, f"{shape.kind} in {where} needs '{missing}'")
        for name, value, loc in shape.params:
            if shape.kind != "mesh" and name not in required:
                self.diag.error(loc, f"{shape.kind} has no parameter '{name}' (it takes {', '.join(required)})")
            v = try_evaluate(value, env, self.diag, f"{shape.kind} in {where}")
            if shape.kind != "mesh" and isinstance(v, (int, float)) and not isinstance(v, bool) and v <= 0:
                self.diag.error(value.loc, f"{shape.kind} {name} in {where} must be positive, is {v}")
