"""Checks of p-model elements: devices, links, bodies, joints, sensors, actuators, parts and fragments.

As strict as RoboTool's validators, not stricter (docs/pmodel-notation.md): references must resolve
(joint, sensor, actuator, link and body definitions, parts, child links, instantiated constants),
every geometric quantity must evaluate to a number, and a link must not carry inertial information
both itself and in its bodies (RoboTool's rule L2). p-model equations are relations for a solver that
cotwin does not run: their names are checked, an unknown one is a warning (RoboTool's own
solver output refers to solver variables it never declares).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .checker import Checker
from . import syntax as s
from .consteval import UNITS, ConstEnv, const_env, try_evaluate
from .declarations import VarDecl
from .operators import MATH
from .pmodel_elements import (
    AnnotationRecord, Body, BodyDecl, Device, DeviceRef, Fragment, Index, JointRef, Link, LinkDecl, PModel, Pose,
    Shape,
)

SHAPE_PARAMS = {
    "box": ("length", "width", "height"),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
    "sphere": ("radius",),
    "mesh": (),
}
INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
PARAMETER_DEFAULT = 0.0  # the value of a constant declared without one (RoboTool's default for a number)
TIME = "t"  # the time variable of equations and initial conditions
#: the operators RoboTool's equations use without declaring them (calculus and matrix algebra of its solver)
SOLVER_OPERATORS = frozenset({"derivative", "integral", "adj", "submatrix", "transpose", "inverse", "identity",
                              "zeroes", "norm", "dot", "cross"}) | frozenset(MATH)


@dataclass(frozen=True)
class PlacedLink:
    """A link of a p-model after parts are flattened: where it comes from and its constants."""

    link: Link
    pmodel: PModel
    part: str | None  # the part it came through (None for the p-model's own links)


def parameters_env(decls, outer: ConstEnv | None = None) -> ConstEnv:
    """Constants with a value, plus those without (parameters) at PARAMETER_DEFAULT."""
    env = const_env(decls, outer)
    for d in decls:
        if d.init is None and getattr(d, "kind", "const") == "const":
            env.definitions.setdefault(d.name, s.Literal(PARAMETER_DEFAULT, d.loc))
    return env


def file_constants(project) -> ConstEnv:
    """Top-level `const` declarations of all .pm files: the outermost constant scope."""
    decls = [e for f in project.files if f.notation == "pm" for e in f.elements if isinstance(e, VarDecl)]
    return parameters_env([d for d in decls if d.kind == "const"])


def pmodel_constants(project, pmodel: PModel, instantiations=()) -> ConstEnv:
    """The constants of a p-model (a part's instantiations override them), inside the file scope."""
    env = parameters_env(pmodel.constants, file_constants(project))
    outer = env.outer
    for name, value, _ in instantiations:  # evaluated where the part is declared, stored as values
        result = try_evaluate(value, outer, None) if outer is not None else None
        env.definitions[name] = s.Literal(result, value.loc) if result is not None else value
    return env


def index_values(index: Index | None, env: ConstEnv) -> list[int]:
    """The integers an `index i : [a, b]` (or `[a, b)`) ranges over; [None] when there is no index."""
    if index is None:
        return [None]
    low, high = try_evaluate(index.low, env, None), try_evaluate(index.high, env, None)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (low, high)):
        return []
    return list(range(int(low), int(high) + (1 if index.closed else 0)))


def with_index(env: ConstEnv, index: Index | None, value) -> ConstEnv:
    if index is None:
        return env
    return ConstEnv({index.var: s.Literal(value if value is not None else 0, index.loc)}, env)


def flatten_links(project, pmodel: PModel, _seen: frozenset = frozenset()) -> dict[str, PlacedLink]:
    """All links of a p-model by name, its own first, then those of its parts (recursively)."""
    out: dict[str, PlacedLink] = {link.name: PlacedLink(link, pmodel, None) for link in pmodel.links}
    for part in pmodel.parts:
        sub = project.lookup("pmodel", part.pmodel, project.file_of(pmodel))
        if sub is None or sub.name in _seen or sub is pmodel:
            continue
        for name, placed in flatten_links(project, sub, _seen | {pmodel.name}).items():
            out.setdefault(name, PlacedLink(placed.link, placed.pmodel, placed.part or part.name))
    return out


def device_of(project, ref: DeviceRef, source) -> Device | None:
    """The definition of a sensor or actuator reference (its own for a local one)."""
    if ref.local is not None:
        return ref.local
    if ref.device is None:
        return None
    return project.lookup("sensor" if ref.kind == "sref" else "actuator", ref.device, source)


def joint_device(project, joint: JointRef, source) -> Device | None:
    if joint.local is not None:
        return joint.local
    return project.lookup("joint", joint.joint, source) if joint.joint is not None else None


def device_env(device: Device, instantiations, outer: ConstEnv) -> ConstEnv:
    """A device's constants (parameters at their default) with a reference's instantiations applied."""
    env = parameters_env([p for p in device.ports if p.kind == "const"], outer)
    for name, value, _ in instantiations:
        result = try_evaluate(value, outer, None)
        env.definitions[name] = s.Literal(result, value.loc) if result is not None else value
        env._values.pop(name, None)
    return env


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class PModelChecker(Checker):

    def check(self) -> None:
        self._warned_parameters: set[str] = set()
        files = file_constants(self.project)
        for element in self.source.elements:
            if isinstance(element, Device):
                self.device(element, files)
            elif isinstance(element, PModel):
                self.pmodel(element)
            elif isinstance(element, LinkDecl):
                self.link_decl(element, files)
            elif isinstance(element, BodyDecl):
                self.body_decl(element, files)
            elif isinstance(element, Fragment):
                self.fragment(element, files)
            elif isinstance(element, VarDecl) and element.init is not None:
                try_evaluate(element.init, files, self.diag, f"constant {element.name}")

    # ---- names in equations ----
    def _names(self, exprs, known: set[str], where: str) -> None:
        """Report names of `exprs` that nothing declares (warnings: equations are the solver's)."""
        for expr in exprs:
            for node in s.walk(expr):
                if isinstance(node, s.Name) and len(node.name.parts) == 1:
                    name = node.name.last
                    if name not in known and name not in self.functions and name not in SOLVER_OPERATORS:
                        self.diag.warning(node.loc, f"'{name}' in {where} is declared nowhere "
                                          "(cotwin does not solve p-model equations)")
                        known.add(name)  # once per name and place

    def _scope_names(self, *groups) -> set[str]:
        names = {TIME}
        for group in groups:
            for item in group:
                names.add(item if isinstance(item, str) else item.name)
        return names

    def _file_names(self) -> set[str]:
        return set(file_constants(self.project).definitions)

    # ---- devices ----
    def device(self, device: Device, env: ConstEnv, outer_names: set[str] | None = None) -> None:
        seen: dict[str, s.Location] = {}
        for port in device.ports:
            if port.name in seen:
                self.diag.error(port.loc, f"duplicate port '{port.name}' in {device.kind} {device.name}")
            seen[port.name] = port.loc
            self.types.resolve(port.type)
        denv = parameters_env([p for p in device.ports if p.kind == "const"], env)
        for port in device.ports:
            if port.kind == "const" and port.init is not None and not isinstance(port.init, (s.MatrixExpr,)):
                try_evaluate(port.init, denv, None)
        known = self._scope_names(device.ports) | (outer_names or set()) | self._file_names()
        where = f"{device.kind} {device.name}"
        self._names(device.equations, known, f"an equation of {where}")
        self._names(device.constraints, known, f"a constraint of {where}")
        for ann in device.annotations:
            self.annotation(ann, denv)

    def link_decl(self, decl: LinkDecl, env: ConstEnv) -> None:
        lenv = parameters_env([v for v in decl.variables if v.kind == "const"], env)
        if decl.inertial is not None:
            self.inertial(decl.inertial, lenv, f"link {decl.name}")
        for shape in decl.shapes:
            self.shape(shape, lenv, f"link {decl.name}")
        self._names(decl.equations, self._scope_names(decl.variables) | self._file_names(),
                    f"an equation of link {decl.name}")

    def body_decl(self, decl: BodyDecl, env: ConstEnv) -> None:
        benv = parameters_env([v for v in decl.variables if v.kind == "const"], env)
        if decl.inertial is not None:
            self.inertial(decl.inertial, benv, f"body {decl.name}")
        for shape in decl.shapes:
            self.shape(shape, benv, f"body {decl.name}")
        self.surface(decl, benv, f"body {decl.name}")

    def fragment(self, fragment: Fragment, env: ConstEnv) -> None:
        holder = PModel(fragment.name, (), fragment.links, (), fragment.loc, fragment.variables, fragment.equations)
        known = self._scope_names(fragment.variables) | self._file_names()
        self._names(fragment.equations, known, f"an equation of fragment {fragment.name}")
        children: dict[str, str] = {}
        all_links = {link.name: PlacedLink(link, holder, None) for link in fragment.links}
        for link in fragment.links:
            self.link(link, holder, env, all_links, children, known)
        for joint in fragment.joints:
            self.joint(joint, None, holder, env, all_links, children, known)
        for ref in (*fragment.sensors, *fragment.actuators):
            self.device_ref(ref, env, known)

    # ---- p-models ----
    def pmodel(self, pmodel: PModel) -> None:
        env = pmodel_constants(self.project, pmodel)
        for const in pmodel.constants:
            if const.init is None:
                self.diag.warning(const.loc, f"constant '{const.name}' of p-model {pmodel.name} has no value: "
                                  f"{PARAMETER_DEFAULT:g} is used unless a part instantiates it")
            else:
                try_evaluate(const.init, env, self.diag, f"constant {const.name}")
        for var in pmodel.variables:
            self.types.resolve(var.type)
        known = (self._scope_names(pmodel.constants, pmodel.variables, pmodel.links, pmodel.parts)
                 | self._file_names() | self._solution_names(pmodel))
        self._names(pmodel.equations, known, f"an equation of p-model {pmodel.name}")
        self._names(pmodel.constraints, known, f"a constraint of p-model {pmodel.name}")
        names: dict[str, Link] = {}
        for link in pmodel.links:
            if link.name in names:
                self.diag.error(link.loc, f"duplicate link '{link.name}' (first at line {names[link.name].loc.line})")
            names[link.name] = link
        for part in pmodel.parts:
            self.part(part, pmodel, env)
        all_links = flatten_links(self.project, pmodel)
        children: dict[str, str] = {}
        for link in pmodel.links:
            self.link(link, pmodel, env, all_links, children, known)
        for part in pmodel.parts:
            for fixed in part.fixed:
                children.setdefault(fixed.target, part.name)
        roots = [link for link in pmodel.links if link.name not in children]
        if len(roots) > 1:
            self.diag.warning(roots[1].loc, f"p-model {pmodel.name} has several root links: "
                              + ", ".join(r.name for r in roots) + f"; '{roots[0].name}' is taken as the base")

    def _solution_names(self, pmodel: PModel) -> set[str]:
        names = set()
        for solution in pmodel.solutions:
            for tag, value, _ in solution.items:
                if isinstance(value, tuple) and value and isinstance(value[0], str):  # var_item
                    names.add(value[0])
                elif isinstance(value, VarDecl):
                    names.add(value.name)
        return names

    def part(self, part, pmodel: PModel, env: ConstEnv) -> None:
        sub = self.project.lookup("pmodel", part.pmodel, self.source)
        if sub is None:
            self.diag.error(part.pmodel.loc, f"unknown p-model '{part.pmodel}' for part {part.name}")
        elif sub is pmodel or self._includes(sub, pmodel.name):
            self.diag.error(part.loc, f"part {part.name} includes p-model {pmodel.name} in itself")
            sub = None
        if part.pose is not None:
            self.pose(part.pose, env, f"part {part.name}")
        for name, value, loc in part.instantiations:
            if sub is not None and not any(c.name == name for c in sub.constants):
                self.diag.error(loc, f"p-model {sub.name} has no constant '{name}' (part {part.name})")
            try_evaluate(value, env, self.diag, f"part {part.name}.{name}")
        if sub is None:
            return
        own = flatten_links(self.project, sub)
        here = flatten_links(self.project, pmodel)
        for fixed in part.fixed:
            if fixed.link not in own:
                self.diag.error(fixed.loc, f"part {part.name} (p-model {sub.name}) has no link '{fixed.link}'")
            self._link_in(fixed.target, fixed.target_part, pmodel, here, fixed.loc, f"part {part.name}")
        for pj in part.joints:
            if not any(j.name == pj.joint for placed in own.values() for j in placed.link.joints):
                self.diag.error(pj.loc, f"part {part.name} (p-model {sub.name}) has no joint '{pj.joint}'")
            self._link_in(pj.child, pj.child_part, pmodel, here, pj.loc, f"part {part.name}")

    def _link_in(self, link: str, part_name: str | None, pmodel: PModel, here, loc, where: str) -> bool:
        if part_name is None:
            if link not in here:
                self.diag.error(loc, f"{where}: unknown link '{link}'")
                return False
            return True
        part = next((p for p in pmodel.parts if p.name == part_name), None)
        if part is None:
            self.diag.error(loc, f"{where}: unknown part '{part_name}'")
            return False
        sub = self.project.lookup("pmodel", part.pmodel, self.source)
        if sub is not None and link not in flatten_links(self.project, sub):
            self.diag.error(loc, f"part {part_name} (p-model {sub.name}) has no link '{link}'")
            return False
        return True

    def _includes(self, pmodel: PModel, name: str, depth: int = 0) -> bool:
        if depth > 16:
            return True
        for part in pmodel.parts:
            sub = self.project.lookup("pmodel", part.pmodel, self.source)
            if sub is not None and (sub.name == name or self._includes(sub, name, depth + 1)):
                return True
        return False

    # ---- links ----
    def index(self, index: Index | None, env: ConstEnv, where: str) -> ConstEnv:
        if index is None:
            return env
        for bound in (index.low, index.high):
            value = try_evaluate(bound, env, self.diag, f"index of {where}")
            if value is not None and not (_is_number(value) and float(value).is_integer()):
                self.diag.error(bound.loc, f"index bounds of {where} must be integers, is {value!r}")
        if not index_values(index, env):
            self.diag.warning(index.loc, f"index '{index.var}' of {where} ranges over no value")
        return with_index(env, index, index_values(index, env)[0] if index_values(index, env) else 0)

    def link(self, link: Link, pmodel: PModel, env: ConstEnv, all_links: dict[str, PlacedLink],
             children: dict[str, str], known: set[str]) -> None:
        where = f"link {link.name}"
        env = self.index(link.index, env, where)
        decl = None
        if link.ref is not None:
            decl = self.project.lookup("link", link.ref, self.source)
            if decl is None:
                self.diag.error(link.ref.loc, f"unknown link definition '{link.ref}' for lref {link.name}")
        lenv = parameters_env([v for v in link.variables if v.kind == "const"], env)
        body_inertia = [b for b in link.bodies if self._body_inertial(b) is not None]
        if link.inertial is not None:
            self.inertial(link.inertial, lenv, where)
            if body_inertia:
                self.diag.error(link.inertial.loc, f"{where} has inertial information and so does its body "
                                f"{body_inertia[0].name}: give it once (RoboTool's rule L2)")
        elif decl is None or decl.inertial is None:
            if not body_inertia:
                self.diag.warning(link.loc, f"{where} has no inertial information; a default mass is used")
        if link.pose is not None:
            self.pose(link.pose, lenv, where)
        for shape in link.shapes:
            self.shape(shape, lenv, where)
        names = (known | self._scope_names(link.variables, link.bodies, link.joints, link.sensors, link.actuators)
                 | ({link.index.var} if link.index else set()) | {link.name})
        self._names(link.equations, names, f"an equation of {where}")
        self._names(link.constraints, names, f"a constraint of {where}")
        self._names(link.relations, names, f"a relation of {where}")
        for body in link.bodies:
            self.body(body, lenv, names)
        for ann in link.annotations:
            self.annotation(ann, lenv)
        for joint in link.joints:
            self.joint(joint, link, pmodel, lenv, all_links, children, names)
        for ref in (*link.sensors, *link.actuators):
            self.device_ref(ref, lenv, names)
        for fixed in link.fixed_to:
            if fixed.part is None:
                if fixed.link not in all_links:
                    self.diag.error(fixed.loc, f"{where} is fixed to unknown link '{fixed.link}'")
                    continue
            else:
                part = next((p for p in pmodel.parts if p.name == fixed.part), None)
                if part is None:
                    self.diag.error(fixed.loc, f"{where} is fixed to a link in unknown part '{fixed.part}'")
                    continue
                sub = self.project.lookup("pmodel", part.pmodel, self.source)
                if sub is not None and fixed.link not in flatten_links(self.project, sub):
                    self.diag.error(fixed.loc, f"part {fixed.part} (p-model {sub.name}) has no link '{fixed.link}'")
            if fixed.link == link.name and fixed.part is None:
                self.diag.error(fixed.loc, f"{where} is fixed to itself")
            children.setdefault(fixed.link, link.name)

    def _body_inertial(self, body: Body):
        if body.inertial is not None:
            return body.inertial
        if body.ref is not None:
            decl = self.project.lookup("body", body.ref, self.source)
            return decl.inertial if isinstance(decl, BodyDecl) else None
        return None

    def body(self, body: Body, env: ConstEnv, known: set[str]) -> None:
        where = f"body {body.name}"
        env = self.index(body.index, env, where)
        if body.ref is not None and self.project.lookup("body", body.ref, self.source) is None:
            self.diag.error(body.ref.loc, f"unknown body definition '{body.ref}' for bref {body.name}")
        benv = parameters_env([v for v in body.variables if v.kind == "const"], env)
        for shape in body.shapes:
            self.shape(shape, benv, where)
        if body.inertial is not None:
            self.inertial(body.inertial, benv, where)
        if body.pose is not None:
            self.pose(body.pose, benv, where)
        self.surface(body, benv, where)
        names = known | self._scope_names(body.variables) | ({body.index.var} if body.index else set())
        self._names(body.relations, names, f"a relation of {where}")
        self._names(body.equations, names, f"an equation of {where}")

    def surface(self, holder, env: ConstEnv, where: str) -> None:
        surface = holder.surface
        if surface is None:
            return
        for value in (surface.restitution, surface.threshold, surface.laser_retro):
            if value is not None:
                self._number(value, env, f"surface of {where}")
        for _, entries, _ in surface.friction:
            for _, value, _ in entries:
                try_evaluate(value, env, self.diag, f"friction of {where}")

    def inertial(self, inertial, env: ConstEnv, where: str) -> None:
        if inertial.mass is None:
            self.diag.error(inertial.loc, f"inertial information of {where} has no mass")
        else:
            mass = self._number(inertial.mass, env, f"mass of {where}")
            if mass is not None and mass < 0:
                self.diag.error(inertial.mass.loc, f"mass of {where} must be positive, is {mass}")
            elif mass == 0:
                self.diag.warning(inertial.mass.loc, f"mass of {where} is 0: simulators use a default mass")
        if inertial.unit is not None and inertial.unit not in UNITS:
            self.diag.error(inertial.loc, f"unknown unit '{inertial.unit}' (known: {', '.join(UNITS)})")
        for key, value, loc in inertial.inertia:
            if key not in INERTIA_KEYS:
                self.diag.error(loc, f"unknown inertia entry '{key}' (known: {', '.join(INERTIA_KEYS)})")
            self._number(value, env, f"inertia of {where}")
        if inertial.pose is not None:
            self.pose(inertial.pose, env, f"inertial of {where}")

    def _number(self, expr: s.Expr, env: ConstEnv, what: str):
        value = try_evaluate(expr, env, self.diag, what)
        if value is None:
            return None
        if not _is_number(value):
            self.diag.error(expr.loc, f"{what} must be a number, is {value!r}")
            return None
        return value

    # ---- joints, sensors, actuators ----
    def joint(self, joint: JointRef, link: Link | None, pmodel: PModel, env: ConstEnv,
              all_links: dict[str, PlacedLink], children: dict[str, str], known: set[str]) -> None:
        where = f"joint {joint.name}"
        env = self.index(joint.index, env, where)
        device = joint_device(self.project, joint, self.source)
        if joint.local is not None:
            self.device(joint.local, env, known)
        elif device is None:
            self.diag.error(joint.joint.loc, f"unknown joint type '{joint.joint}' "
                            "(import physmod::joints::* or physmod::SKO::joints::*, or declare it)")
        self._instantiations(joint.instantiations, device, env, where)
        if device is not None:  # the joint's own constants, as instantiated, are visible in its annotations
            env = device_env(device, joint.instantiations, env)
        for ann in joint.annotations:
            self.annotation(ann, env)
            axis = ann.get("axis")
            xyz = axis.get("xyz") if isinstance(axis, AnnotationRecord) else None
            if xyz is not None:
                value = try_evaluate(xyz, env, None)
                if not (isinstance(value, tuple) and len(value) == 3 and any(v != 0 for v in value)):
                    self.diag.error(xyz.loc, f"axis of joint {joint.name} must be a non-zero 3-vector (|x, y, z|)")
        if joint.pose is not None:
            self.pose(joint.pose, env, where)
        names = known | {joint.name} | ({p.name for p in device.ports} if device else set())
        self._names(joint.relations, names, f"a relation of {where}")
        if joint.child is None:
            self.diag.warning(joint.loc, f"joint {joint.name} is not connected to a child link "
                              "('flexibly connected to ...'): it is left out of the kinematic tree")
        else:
            if joint.child_part is not None:
                part = next((p for p in pmodel.parts if p.name == joint.child_part), None)
                sub = self.project.lookup("pmodel", part.pmodel, self.source) if part else None
                known_child = sub is not None and joint.child in flatten_links(self.project, sub)
            else:
                known_child = joint.child in all_links
            if not known_child:
                self.diag.error(joint.child_loc, f"joint {joint.name}: unknown child link '{joint.child}'")
            elif link is not None and joint.child == link.name and joint.child_part is None:
                self.diag.error(joint.child_loc, f"joint {joint.name} connects link '{link.name}' to itself")
            else:
                children.setdefault(joint.child, link.name if link is not None else joint.name)
        for ref in (*joint.actuators, *joint.sensors):
            self.device_ref(ref, env, names, joint=joint, joint_dev=device)

    def _instantiations(self, instantiations, device: Device | None, env: ConstEnv, where: str) -> None:
        for name, value, loc in instantiations:
            if device is not None and device.port(name) is None:
                self.diag.error(loc, f"{device.kind} {device.name} has no constant '{name}' ({where})")
            try_evaluate(value, env, self.diag, f"{where}.{name}")

    def device_ref(self, ref: DeviceRef, env: ConstEnv, known: set[str], joint: JointRef | None = None,
                   joint_dev: Device | None = None) -> None:
        kind = "sensor" if ref.kind == "sref" else "actuator"
        where = f"{kind} {ref.name}"
        env = self.index(ref.index, env, where)
        if ref.pose is not None:
            self.pose(ref.pose, env, where)
        for ann in ref.annotations:
            self.annotation(ann, env)
        device = device_of(self.project, ref, self.source)
        if ref.local is not None:
            self.device(ref.local, env, known)
        elif device is None:
            self.diag.error(ref.device.loc, f"unknown {kind} '{ref.device}'")
        self._instantiations(ref.instantiations, device, env, where)
        owners = {ref.name: device}
        if joint is not None:
            owners[joint.name] = joint_dev
        names = known | set(owners) | ({p.name for p in device.ports} if device else set())
        names |= {ref.index.var} if ref.index else set()
        for relation in ref.relations:
            for node in s.walk(relation):
                if isinstance(node, s.FieldAccess) and isinstance(node.base, s.Name) and len(node.base.name.parts) == 1:
                    base = node.base.name.last
                    if base in owners and owners[base] is not None and owners[base].port(node.field) is None:
                        owner = owners[base]
                        self.diag.error(node.loc, f"{owner.kind} {owner.name} has no port '{node.field}'")
        self._names(ref.relations, names, f"a relation of {where}")

    # ---- values ----
    def annotation(self, record: AnnotationRecord, env: ConstEnv) -> None:
        for entry in record.entries:
            if isinstance(entry.value, AnnotationRecord):
                self.annotation(entry.value, env)
            else:
                try_evaluate(entry.value, env, self.diag, f"annotation {record.name}.{entry.key}")

    def pose(self, pose: Pose, env: ConstEnv, where: str) -> None:
        for key, value, _ in pose.fields:
            self._number(value, env, f"pose {key} of {where}")

    def shape(self, shape: Shape, env: ConstEnv, where: str) -> None:
        if shape.kind == "mesh":
            self.mesh(shape, env, where)
            return
        required = SHAPE_PARAMS.get(shape.kind, ())
        given = {name for name, _, _ in shape.params}
        for missing in [r for r in required if r not in given]:
            self.diag.error(shape.loc, f"{shape.kind} in {where} needs '{missing}'")
        for name, value, loc in shape.params:
            if name not in required:
                self.diag.error(loc, f"{shape.kind} has no parameter '{name}' (it takes {', '.join(required)})")
            v = self._number(value, env, f"{shape.kind} in {where}")
            if v is not None and v < 0:
                self.diag.error(value.loc, f"{shape.kind} {name} in {where} must be positive, is {v}")
            elif v == 0:
                self.diag.warning(value.loc, f"{shape.kind} {name} in {where} is 0: a flat shape")

    def mesh(self, shape: Shape, env: ConstEnv, where: str) -> None:
        params = {name: (value, loc) for name, value, loc in shape.params}
        for name, (value, loc) in params.items():
            if name not in ("shape", "scaling"):
                self.diag.error(loc, f"mesh has no parameter '{name}' (it takes shape and scaling)")
        if "scaling" in params:
            value = try_evaluate(params["scaling"][0], env, self.diag, f"mesh scaling in {where}")
            ok = _is_number(value) or (isinstance(value, tuple) and len(value) == 3 and all(map(_is_number, value)))
            if value is not None and not ok:
                self.diag.error(params["scaling"][1], f"mesh scaling in {where} must be a number or a 3-vector")
        if "shape" not in params:
            self.diag.error(shape.loc, f"mesh in {where} names no file ('shape \"file.stl\"')")
            return
        file = try_evaluate(params["shape"][0], env, None)
        if not isinstance(file, str):
            self.diag.error(params["shape"][1], f"mesh file in {where} must be a string")
        elif not mesh_path(self.source.path, file).is_file():
            self.diag.warning(params["shape"][1], f"mesh file '{file}' of {where} not found: a placeholder "
                              "shape stands in for it in exports")


def mesh_path(model_path: str, file: str) -> Path:
    """Where a mesh named in a model is: relative names are relative to the model file's folder."""
    path = Path(file)
    return path if path.is_absolute() else Path(model_path).parent / path
