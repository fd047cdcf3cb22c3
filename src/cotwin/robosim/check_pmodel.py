"""Checks of p-model elements: devices, links, bodies, joints, sensors, actuators, parts and fragments.

As strict as RoboTool's validators, not stricter (docs/pmodel-notation.md): references must resolve
(joint, sensor, actuator, link and body definitions, parts, child links, instantiated constants),
every geometric quantity must evaluate to a number, and a link must not carry inertial information
both itself and in its bodies (RoboTool's rule L2). p-model equations are relations for a solver that
cotwin does not run: their names are checked, an unknown one is a warning (RoboTool's own
solver output refers to solver variables it never declares).
"""

from __future__ import annotations

import math

from .checker import Checker
from . import syntax as s
from .consteval import UNITS, ConstEnv, ParameterNumbering, try_evaluate
from .declarations import VarDecl
from .operators import MATH
from .pmodel_elements import (
    AnnotationRecord, Body, BodyDecl, Device, DeviceRef, Fragment, Index, JointRef, Link, LinkDecl, PModel, Pose,
    Shape,
)
from .pmodel_scope import PModelScope, element_reference, mesh_path

SHAPE_PARAMS = {
    "box": ("length", "width", "height"),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
    "sphere": ("radius",),
    "mesh": (),
}
INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
#: kg: what MuJoCo's model (cotwin.pmodel.mjcf) gives a massless link a moving joint carries with nothing of mass fixed
#: to it (MuJoCo refuses a moving body without mass); the kinematic tree and the URDF/SDF exports keep it massless
MOVING_FRAME_MASS = 1e-3
TIME = "t"  # the time variable of equations and initial conditions
#: the operators RoboTool's equations use without declaring them (calculus and matrix algebra of its solver)
SOLVER_OPERATORS = frozenset({"derivative", "integral", "adj", "submatrix", "transpose", "inverse", "identity",
                              "zeroes", "norm", "dot", "cross"}) | frozenset(MATH)


def grams(kg: float) -> str:
    """A small mass as a warning says it: 0.001 -> "1 g" (MOVING_FRAME_MASS, whatever its value)."""
    return f"{kg * 1000:g} g"


def _is_number(value) -> bool:
    """A finite number: `mass 1e400 kg` (read as infinity) or 0.0/0.0 is none, and reached the MJCF as inf/nan."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _numbers_in(value) -> list[float]:
    """The numbers of an evaluated constant: itself, or a vector's entries."""
    if isinstance(value, tuple):
        return [v for item in value for v in _numbers_in(item)]
    return [value] if isinstance(value, (int, float)) and not isinstance(value, bool) else []


class PModelChecker(Checker):

    def check(self) -> None:
        self.scope = PModelScope(self.project, ParameterNumbering())
        self._pmodel: PModel | None = None  # the p-model (or fragment) being checked: link names resolve in it
        self._link: Link | None = None  # the link being checked: body names resolve in it first
        files = self.scope.file_env()
        for element in self.source.elements:
            self._pmodel, self._link = None, None
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
            elif isinstance(element, VarDecl) and element.kind == "const":
                if element.init is None:
                    self._parameter(element, "of the file")
                else:
                    try_evaluate(element.init, files, self.diag, f"constant {element.name}")

    def _parameter(self, decl: VarDecl, where: str) -> None:
        self.diag.warning(decl.loc, f"constant '{decl.name}' {where} has no value: unless an instantiation gives it "
                          "one, it takes the value RoboTool's SDF generator gives such parameters, 1, 2, 3, ... in "
                          "the order it meets them (export-pmodel says which)")

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

    def _unique(self, where: str, **groups) -> None:
        """Report every element of one scope that repeats an earlier one's name, at the second declaration,
        naming the first: a p-model's constants, variables, links, parts and joints, a link's variables,
        bodies, joints, sensors and actuators, a joint's sensors and actuators share one namespace (RoboTool's
        qualified names, P::link::S, and dm_control's per-scope names); the exports and the mapping's
        paths name an element by it, so a second one would silently shadow, duplicate or rename the first."""
        seen: dict[str, tuple[str, s.Location]] = {}
        for what, items in groups.items():
            for item in items:
                if item.name in seen:
                    first_what, first = seen[item.name]
                    as_what = "" if first_what == what else f" as a {first_what}"
                    self.diag.error(item.loc, f"duplicate {what} '{item.name}' in {where} (first declared{as_what} "
                                    f"at line {first.line}, column {first.column})")
                else:
                    seen[item.name] = (what, item.loc)

    def _file_names(self) -> set[str]:
        env = self.scope.file_env()
        return set(env.definitions) | set(env.parameters)

    # ---- devices ----
    def device(self, device: Device, env: ConstEnv, outer_names: set[str] | None = None) -> None:
        self._unique(f"{device.kind} {device.name}", port=device.ports)
        for port in device.ports:
            self.types.resolve(port.type)
        denv = self.scope.device_env(device, (), env)
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
        lenv = self.scope.decls_env(decl.variables, env)
        if decl.inertial is not None:
            self.inertial(decl.inertial, lenv, f"link {decl.name}")
        for shape in decl.shapes:
            self.shape(shape, lenv, f"link {decl.name}")
        self._names(decl.equations, self._scope_names(decl.variables) | self._file_names(),
                    f"an equation of link {decl.name}")

    def body_decl(self, decl: BodyDecl, env: ConstEnv) -> None:
        benv = self.scope.decls_env(decl.variables, env)
        if decl.inertial is not None:
            self.inertial(decl.inertial, benv, f"body {decl.name}")
        for shape in decl.shapes:
            self.shape(shape, benv, f"body {decl.name}")
        self.surface(decl, benv, f"body {decl.name}")

    def fragment(self, fragment: Fragment, env: ConstEnv) -> None:
        holder = PModel(fragment.name, (), fragment.links, (), fragment.loc, fragment.variables, fragment.equations)
        known = self._scope_names(fragment.variables) | self._file_names()
        self._names(fragment.equations, known, f"an equation of fragment {fragment.name}")
        self._unique(f"fragment {fragment.name}", variable=fragment.variables, link=fragment.links,
                     joint=fragment.joints, sensor=fragment.sensors, actuator=fragment.actuators)
        self._pmodel = holder
        children: dict[str, str] = {}
        for link in fragment.links:
            self.link(link, holder, env, children, known)
        for joint in fragment.joints:
            self.joint(joint, None, holder, env, children, known)
        for ref in (*fragment.sensors, *fragment.actuators):
            self.device_ref(ref, env, known)

    # ---- p-models ----
    def pmodel(self, pmodel: PModel) -> None:
        self._pmodel = pmodel
        env = self.scope.pmodel_env(pmodel)
        for const in pmodel.constants:
            if const.init is None:
                self._parameter(const, f"of p-model {pmodel.name}")
            else:
                try_evaluate(const.init, env, self.diag, f"constant {const.name}")
        for var in pmodel.variables:
            self.types.resolve(var.type)
        known = (self._scope_names(pmodel.constants, pmodel.variables, pmodel.links, pmodel.parts)
                 | self._file_names() | self._solution_names(pmodel))
        self._names(pmodel.equations, known, f"an equation of p-model {pmodel.name}")
        self._names(pmodel.constraints, known, f"a constraint of p-model {pmodel.name}")
        self._unique(f"p-model {pmodel.name}", constant=pmodel.constants, variable=pmodel.variables,
                     link=pmodel.links, part=pmodel.parts, joint=pmodel.joints)
        for part in pmodel.parts:
            self.part(part, pmodel, env)
        children: dict[str, str] = {}
        for link in pmodel.links:
            self.link(link, pmodel, env, children, known)
        for joint in pmodel.joints:  # declared in the p-model: the base link is their parent
            self.diag.warning(joint.loc, f"joint {joint.name} is declared in p-model {pmodel.name}, not in a link: "
                              "its parent is the base link")
            self.joint(joint, None, pmodel, env, children, known)
        # several root links are several free bodies, as in RoboTool's SDF (docs/pmodel-notation.md, 4)

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
        sub = self.scope.part_pmodel(part)
        if sub is None:
            self.diag.error(part.pmodel.loc, f"unknown p-model '{part.pmodel}' for part {part.name}")
        elif sub is pmodel or self.scope.includes(sub, pmodel):
            self.diag.error(part.loc, f"part {part.name} includes p-model {pmodel.name} in itself")
            sub = None
        env = self.index(part.index, env, f"part {part.name}")
        if part.pose is not None:
            self.pose(part.pose, env, f"part {part.name}")
        for name, value, loc in part.instantiations:
            if sub is not None and not any(c.name == name for c in (*sub.constants, *sub.variables)):
                self.diag.error(loc, f"p-model {sub.name} has no constant '{name}' (part {part.name})")
            try_evaluate(value, env, self.diag, f"part {part.name}.{name}")
        if sub is None:
            return
        for fixed in part.fixed:
            if self.scope.own_link(sub, fixed.link) is None:
                self.diag.error(fixed.loc, f"part {part.name} (p-model {sub.name}) has no link '{fixed.link}'")
            self._target(pmodel, fixed.target, fixed.target_part, fixed.loc, f"part {part.name}")
        for pj in part.joints:
            if not any(j.name == pj.joint for link in sub.links for j in link.joints):
                self.diag.error(pj.loc, f"part {part.name} (p-model {sub.name}) has no joint '{pj.joint}'")
            self._target(pmodel, pj.child, pj.child_part, pj.loc, f"part {part.name}")

    def _target(self, pmodel: PModel, name: str, part_name: str | None, loc, where: str):
        """The link a joint or a fixed connection names (docs/pmodel-notation.md, 4), reported if none."""
        target, problem, lenient = self.scope.link_target(pmodel, name, part_name)
        if target is None:
            self.diag.error(loc, f"{where}: {problem}")
        elif lenient:
            self.diag.warning(loc, f"{where}: '{name}' is a link of part {target.part.name}, not of p-model "
                              f"{pmodel.name}: RoboTool needs '{name} in {target.part.name}'; cotwin reads it so")
        return target

    # ---- links ----
    def index(self, index: Index | None, env: ConstEnv, where: str) -> ConstEnv:
        if index is None:
            return env
        for bound in (index.low, index.high):
            value = try_evaluate(bound, env, self.diag, f"index of {where}")
            if value is not None and not (_is_number(value) and float(value).is_integer()):
                self.diag.error(bound.loc, f"index bounds of {where} must be integers, is {value!r}")
        values = self.scope.index_values(index, env)
        if not values:
            self.diag.warning(index.loc, f"index '{index.var}' of {where} ranges over no value")
        return self.scope.with_index(env, index, values[0] if values else 0)

    def link(self, link: Link, pmodel: PModel, env: ConstEnv, children: dict[str, str], known: set[str]) -> None:
        where = f"link {link.name}"
        self._link = link
        self._unique(where, variable=link.variables, body=link.bodies, joint=link.joints, sensor=link.sensors,
                     actuator=link.actuators)
        env = self.index(link.index, env, where)
        decl = None
        if link.ref is not None:
            decl = self.scope.link_decl(link)
            if decl is None:
                self.diag.error(link.ref.loc, f"unknown link definition '{link.ref}' for lref {link.name}")
        lenv = self.scope.decls_env(link.variables, env)
        body_inertia = [b for b in link.bodies if self._body_inertial(b) is not None]
        if link.inertial is not None:
            self.inertial(link.inertial, lenv, where)
            if body_inertia:
                self.diag.error(link.inertial.loc, f"{where} has inertial information and so does its body "
                                f"{body_inertia[0].name}: give it once (RoboTool's rule L2)")
        elif decl is None or decl.inertial is None:
            if not body_inertia:
                self.diag.warning(link.loc, f"{where} has no inertial information: RoboTool's default is used "
                                  "(1 kg, inertia 1 kg m^2 about each axis)")
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
            self.joint(joint, link, pmodel, lenv, children, names)
        for ref in (*link.sensors, *link.actuators):
            self.device_ref(ref, lenv, names)
        for fixed in link.fixed_to:
            if fixed.link == link.name and fixed.part is None:
                self.diag.error(fixed.loc, f"{where} is fixed to itself")
            elif self._target(pmodel, fixed.link, fixed.part, fixed.loc, f"{where} is fixed to a link") is not None:
                children.setdefault(fixed.link, link.name)

    def _body_inertial(self, body: Body):
        if body.inertial is not None:
            return body.inertial
        decl = self.scope.body_decl(body.ref)
        return decl.inertial if decl is not None else None

    def body(self, body: Body, env: ConstEnv, known: set[str]) -> None:
        where = f"body {body.name}"
        env = self.index(body.index, env, where)
        if body.ref is not None and self.scope.body_decl(body.ref) is None:
            self.diag.error(body.ref.loc, f"unknown body definition '{body.ref}' for bref {body.name}")
        benv = self.scope.decls_env(body.variables, env)
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
                self.diag.warning(inertial.mass.loc, f"mass of {where} is 0: a massless frame, no mass in the "
                                  f"simulator (a link a moving joint carries alone gets {grams(MOVING_FRAME_MASS)}, "
                                  "docs/pmodel-notation.md)")
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
            self.diag.error(expr.loc, f"{what} must be a finite number, is {value!r}")
            return None
        return value

    # ---- joints, sensors, actuators ----
    def joint(self, joint: JointRef, link: Link | None, pmodel: PModel, env: ConstEnv,
              children: dict[str, str], known: set[str]) -> None:
        where = f"joint {joint.name}"
        self._unique(where, variable=joint.variables, actuator=joint.actuators, sensor=joint.sensors)
        env = self.scope.decls_env(joint.variables, self.index(joint.index, env, where))
        device = self.scope.joint_device(joint)
        if joint.local is not None:
            self.device(joint.local, env, known)
        elif device is None:
            self.diag.error(joint.joint.loc, f"unknown joint type '{joint.joint}' "
                            "(import physmod::joints::* or physmod::SKO::joints::*, or declare it)")
        self._instantiations(joint.instantiations, device, env, where)
        if device is not None:  # the joint's own constants, as instantiated, are visible in its annotations
            env = self.scope.device_env(device, joint.instantiations, env)
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
        names = (known | {joint.name} | ({p.name for p in device.ports} if device else set())
                 | self._scope_names(joint.variables))
        self._names(joint.relations, names, f"a relation of {where}")
        if joint.child is None:
            self.diag.warning(joint.loc, f"joint {joint.name} is not connected to a child link "
                              "('flexibly connected to ...'): it is left out of the kinematic tree")
        else:
            target, problem, lenient = self.scope.link_target(pmodel, joint.child, joint.child_part)
            if target is None:
                message = f"unknown child link '{joint.child}'" if problem.startswith("unknown link") else problem
                self.diag.error(joint.child_loc, f"joint {joint.name}: {message}")
            elif link is not None and joint.child == link.name and joint.child_part is None:
                self.diag.error(joint.child_loc, f"joint {joint.name} connects link '{link.name}' to itself")
            else:
                if lenient:
                    self.diag.warning(joint.child_loc, f"joint {joint.name}: '{joint.child}' is a link of part "
                                      f"{target.part.name}, not of p-model {pmodel.name}: RoboTool needs "
                                      f"'{joint.child} in {target.part.name}'; cotwin reads it so")
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
        device = self.scope.device_of(ref)
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
        """Annotation values are constants, or name a body, link or part of the model (a gearbox's reference
        body, a contact sensor's collision): RoboTool's SDF generator writes that element's name."""
        for entry in record.entries:
            if isinstance(entry.value, AnnotationRecord):
                self.annotation(entry.value, env)
            elif self._pmodel is None or element_reference(entry.value, self._pmodel, self._link, self.scope) is None:
                value = try_evaluate(entry.value, env, self.diag, f"annotation {record.name}.{entry.key}")
                if any(not math.isfinite(v) for v in _numbers_in(value)):  # a limit of 1e400: range="-inf inf"
                    self.diag.error(entry.value.loc, f"annotation {record.name}.{entry.key} must be finite, is {value!r}")

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

