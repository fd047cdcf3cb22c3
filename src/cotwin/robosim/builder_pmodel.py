"""Building the typed p-model and mapping from the parse tree of a .pm file (see grammar/pmodel.lark).

`Builder` (builder.py) inherits these methods; they use its location helpers. A .pm file may hold
several `package` blocks: each becomes its own SourceFile (the first one is returned, the others
hang off its `siblings`).
"""

from __future__ import annotations

from lark import Token, Transformer, v_args

from . import syntax as s
from .build_items import _Group, _Tagged, _flatten, _ident, _of, _string, _tagged
from .consteval import UNITS
from .declarations import Import, SourceFile, VarDecl
from .pmodel_elements import (
    AnnotationEntry, AnnotationRecord, AnnotationTemplate, Body, BodyDecl, Device, DeviceRef, FixedTo, Fragment,
    Index, Inertial, JointRef, Link, LinkDecl, Mapping, MappingInputEvent, MappingOperation, PartFixed, PartJoint,
    PartRef, PModel, Pose, Shape, Solution, Surface,
)


def _kind(self, meta, token):
    return str(token)


@v_args(meta=True, inline=True)
class PModelBuilder(Transformer):
    port_kind = _kind
    device_kind = _kind
    device_end = _kind
    shape_kind = _kind
    pose_key = _kind
    interval_end = _kind

    # ---- files and packages ----
    def pm_package(self, meta, name):
        return _Tagged("package", name, self._loc(meta))

    def unit_decl(self, meta, name, *items):
        return _Group(())

    def derived_unit_item(self, meta, value):
        return None

    def pm_endpackage(self, meta):
        return _Tagged("endpackage", None, self._loc(meta))

    def pm_file(self, meta, *items):
        """One SourceFile per `package` block; items before the first package belong to the first."""
        blocks: list[list] = [[]]
        for item in _flatten(items):
            if isinstance(item, _Tagged) and item.tag == "package" and any(
                    isinstance(i, _Tagged) and i.tag == "package" or not isinstance(i, (Import, _Tagged))
                    for i in blocks[-1]):
                blocks.append([])
            blocks[-1].append(item)
        sources = [self._pm_source(block) for block in blocks]
        first = sources[0]
        first.siblings.extend(sources[1:])
        return first

    def _pm_source(self, items) -> SourceFile:
        package = next((i.value for i in _tagged(items, "package")), None)
        return SourceFile(self.path, self.notation, package, list(_of(items, Import)),
                          [i for i in items if not isinstance(i, (Import, _Tagged))])

    def port_list(self, meta, kind, *items):
        return _Group(VarDecl(n, t, i, kind, loc) for n, t, i, loc in items)

    # ---- devices and annotations ----
    def equation(self, meta, expr):
        return _Tagged("equation", expr, self._loc(meta))

    def constraint(self, meta, expr):
        return _Tagged("constraint", expr, self._loc(meta))

    def device(self, meta, kind, name, *items):
        items = _flatten(i for i in items if not isinstance(i, str))
        return self._device(kind, _ident(name), items, self._tok_loc(name))

    def _device(self, kind: str, name: str, items, loc) -> Device:
        return Device(kind, name, _of(items, VarDecl), tuple(t.value for t in _tagged(items, "equation")),
                      _of(items, AnnotationRecord), loc, tuple(t.value for t in _tagged(items, "constraint")))

    def annotation_entry(self, meta, key, value):
        return AnnotationEntry(_ident(key), value, self._tok_loc(key))

    def annotation(self, meta, name, *entries):
        return AnnotationRecord(_ident(name), tuple(entries), self._tok_loc(name))

    annotation_record = annotation

    def template_value(self, meta, name, type_):
        return (_ident(name), type_, False, self._tok_loc(name))

    def template_nested(self, meta, name, template):
        return (_ident(name), template, True, self._tok_loc(name))

    def annotation_template(self, meta, name, *fields):
        return AnnotationTemplate(_ident(name), tuple(fields), self._tok_loc(name))

    # ---- geometry, inertia, surfaces ----
    def named_value(self, meta, name, value):
        return (_ident(name), value, self._tok_loc(name))

    inertia_entry = named_value

    def pose_field(self, meta, key, value):
        return (key, value, self._loc(meta))

    def pose(self, meta, *fields):
        seen: dict[str, s.Location] = {}
        for key, _, loc in fields:
            if key in seen:
                self.diag.error(loc, f"pose field '{key}' given twice (first at line {seen[key].line})")
            seen[key] = loc
        return Pose(tuple(fields), self._loc(meta))

    def index(self, meta, var, low, high, end):
        return Index(_ident(var), low, high, end == "]", self._tok_loc(var))

    def shape(self, meta, kind, *params):
        return Shape(kind, tuple(params), self._loc(meta))

    def mesh_file(self, meta, token):
        return ("shape", s.Literal(_string(token), self._tok_loc(token)), self._tok_loc(token))

    def mesh_scaling(self, meta, value):
        return ("scaling", value, self._loc(meta))

    def mesh_block(self, meta, *items):
        return Shape("mesh", tuple(items), self._loc(meta))

    def restitution(self, meta, value):
        return ("restitution", value)

    def bounce_threshold(self, meta, value):
        return ("threshold", value)

    def bounce(self, meta, *items):
        values = dict(items)
        return Surface(restitution=values.get("restitution"), threshold=values.get("threshold"))

    def friction_entry(self, meta, key, value):
        return (_ident(key), value, self._tok_loc(key))

    def friction_group(self, meta, name, *entries):
        return (_ident(name), tuple(entries), self._tok_loc(name))

    def friction(self, meta, *groups):
        return Surface(friction=tuple(groups))

    def laser_retro(self, meta, value):
        return Surface(laser_retro=value)

    def mass(self, meta, value, unit=None):
        return _Tagged("mass", (value, str(unit) if unit is not None else None), self._loc(meta))

    def inertia_matrix(self, meta, *values):
        return _Tagged("inertia", tuple(values), self._loc(meta))

    def inertial(self, meta, *items):
        where = "inertial information"
        mass = self._single(_tagged(items, "mass"), "mass", where)
        poses = _of(items, Pose)
        return Inertial(mass[0] if mass else None, mass[1] if mass else None,
                        self._single(_tagged(items, "inertia"), "inertia matrix", where) or (),
                        poses[0] if poses else None, self._loc(meta))

    def def_block(self, meta, *items):
        return _Tagged("def", tuple(_flatten(items)), self._loc(meta))

    # ---- helpers for blocks ----
    def _defs(self, items) -> list:
        return [x for d in _tagged(items, "def") for x in d.value]

    def _one(self, items, cls, what: str, where: str):
        found = _of(items, cls)
        for extra in found[1:]:
            self.diag.error(extra.loc, f"more than one {what} in {where}")
        return found[0] if found else None

    def _one_pose(self, items, where: str) -> Pose | None:
        return self._one(items, Pose, "pose", where)

    def _surface(self, items) -> Surface | None:
        parts = _of(items, Surface)
        if not parts:
            return None
        merged: dict = {}
        for part in parts:
            for key in ("restitution", "threshold", "laser_retro"):
                if getattr(part, key) is not None:
                    merged[key] = getattr(part, key)
            if part.friction:
                merged["friction"] = merged.get("friction", ()) + part.friction
        return Surface(**merged)

    def _inertial(self, items, where: str) -> Inertial | None:
        return self._one(items, Inertial, "inertial information", where)

    def _values(self, items, tag: str) -> tuple:
        return tuple(t.value for t in _tagged(items, tag))

    # ---- bodies ----
    def local_body(self, meta, name, *items):
        return self._body(_ident(name), None, items, self._tok_loc(name))

    def body_ref(self, meta, name, target, *items):
        return self._body(_ident(name), target, items, self._tok_loc(name))

    def _body(self, name: str, ref, items, loc) -> Body:
        where = f"body {name}"
        definition = self._defs(items)
        return Body(name, _of(definition, Shape), self._one_pose(items, where), loc,
                    self._inertial(definition, where), self._surface(definition), ref,
                    self._one(items, Index, "index", where), self._values(items, "relation"),
                    _of(definition, VarDecl), self._values(definition, "equation"))

    def body_decl(self, meta, name, *items):
        items = _flatten(items)
        where = f"body {name}"
        return BodyDecl(_ident(name), _of(items, Shape), self._inertial(items, where), self._surface(items),
                        _of(items, VarDecl), self._tok_loc(name))

    def link_decl(self, meta, name, *items):
        items = _flatten(items)
        return LinkDecl(_ident(name), self._inertial(items, f"link {name}"), _of(items, Shape), _of(items, VarDecl),
                        self._values(items, "equation"), _of(items, AnnotationRecord), self._tok_loc(name))

    # ---- links ----
    def fixed_to(self, meta, link, *rest):
        part = _ident(rest[-1]) if len(rest) == 2 else None
        return FixedTo(_ident(link), part, self._tok_loc(link))

    def instantiation(self, meta, name, value):
        return _Tagged("instantiation", (_ident(name), value, self._tok_loc(name)), self._loc(meta))

    def relation(self, meta, expr):
        return _Tagged("relation", expr, self._loc(meta))

    bare_relation = relation

    def relation_flexi(self, meta, expr):
        return _Tagged("relation", expr, self._loc(meta))

    def flexibly_connected(self, meta, child, *rest):
        part = _ident(rest[-1]) if len(rest) == 2 else None
        return _Tagged("child", (_ident(child), part, self._tok_loc(child)), self._loc(meta))

    def _pm_device_ref(self, kind: str, name, target, items, local: Device | None = None) -> DeviceRef:
        where = f"{'sensor' if kind == 'sref' else 'actuator'} {name}"
        return DeviceRef(kind, _ident(name), target, self._values(items, "relation"),
                         self._values(items, "instantiation"), self._tok_loc(name), local,
                         self._one_pose(items, where), self._one(items, Index, "index", where),
                         _of(items, AnnotationRecord))

    def aref(self, meta, name, target, *items):
        return self._pm_device_ref("aref", name, target, items)

    def _local_device(self, kind: str, ref_kind: str, name, items) -> DeviceRef:
        definition = self._defs(items)
        device = self._device(kind, _ident(name), definition, self._tok_loc(name))
        return self._pm_device_ref(ref_kind, name, None, items, device)

    def local_sensor(self, meta, name, *items):
        return self._local_device("sensor", "sref", name, items)

    def local_actuator(self, meta, name, *items):
        return self._local_device("actuator", "aref", name, items)

    def _joint(self, name, joint, items, local: Device | None) -> JointRef:
        where = f"joint {name}"
        items = _flatten(items)
        child = self._single(_tagged(items, "child"), "flexibly connected to", where)
        refs = _of(items, DeviceRef)
        return JointRef(
            _ident(name), joint, _of(items, AnnotationRecord) + (local.annotations if local else ()),
            self._values(items, "instantiation"), tuple(r for r in refs if r.kind == "aref"),
            child[0] if child else None, child[1] if child else None, child[2] if child else None,
            self._one_pose(items, where), self._tok_loc(name), local, tuple(r for r in refs if r.kind == "sref"),
            self._values(items, "relation"), self._one(items, Index, "index", where), _of(items, VarDecl),
        )

    def jref(self, meta, name, joint, *items):
        return self._joint(name, joint, items, None)

    def local_joint(self, meta, name, *items):
        local = self._device("joint", _ident(name), self._defs(items), self._tok_loc(name))
        return self._joint(name, None, items, local)

    def _link(self, name, ref, items) -> Link:
        where = f"link {name}"
        definition = self._defs(items)
        refs = _of(items, DeviceRef)
        return Link(
            _ident(name), self._inertial(definition, where), _of(definition, Shape),
            _of(definition, AnnotationRecord), _of(definition, VarDecl), self._values(definition, "equation"),
            self._one_pose(items, where), _of(items, Body), _of(items, JointRef),
            tuple(r for r in refs if r.kind == "sref"), tuple(r for r in refs if r.kind == "aref"),
            _of(items, FixedTo), self._tok_loc(name), ref, self._one(items, Index, "index", where),
            self._values(items, "relation"), self._values(definition, "constraint"),
        )

    def local_link(self, meta, name, *items):
        return self._link(name, None, items)

    def link_ref(self, meta, name, target, *items):
        return self._link(name, target, items)

    # ---- parts, solutions, p-models, fragments ----
    def part_fixed(self, meta, link, target, *rest):
        return PartFixed(_ident(link), _ident(target), _ident(rest[-1]) if len(rest) == 2 else None,
                         self._tok_loc(link))

    def part_joint(self, meta, joint, child, *rest):
        return PartJoint(_ident(joint), _ident(child), _ident(rest[-1]) if len(rest) == 2 else None,
                         self._tok_loc(joint))

    def part(self, meta, name, pmodel, *items):
        return PartRef(_ident(name), pmodel, self._one_pose(items, f"part {name}"),
                       self._values(items, "instantiation"), self._tok_loc(name),
                       _of(items, PartFixed), _of(items, PartJoint), self._one(items, Index, "index", f"part {name}"))

    def _solution_item(tag):
        def build(self, meta, value):
            if isinstance(value, Token):
                value = _ident(value)
            return _Tagged("solution", (tag, value), self._loc(meta))
        return build

    solution_expr = _solution_item("solutionExpr")
    solution_order = _solution_item("order")
    solution_group = _solution_item("group")
    solution_method = _solution_item("method")
    solution_input = _solution_item("Input")

    def solution(self, meta, *items):
        entries = []
        for item in _flatten(items):
            if isinstance(item, _Tagged) and item.tag == "solution":
                entries.append((*item.value, item.loc))
            elif isinstance(item, _Tagged):
                entries.append((item.tag, item.value, item.loc))
            elif isinstance(item, VarDecl):
                entries.append((item.kind, item, item.loc))
        return Solution(tuple(entries), self._loc(meta))

    def pmodel(self, meta, name, *items):
        items = _flatten(items)
        variables = _of(items, VarDecl)
        return PModel(_ident(name), tuple(v for v in variables if v.kind == "const"), _of(items, Link),
                      _of(items, PartRef), self._tok_loc(name), tuple(v for v in variables if v.kind != "const"),
                      self._values(items, "equation"), self._values(items, "constraint"), _of(items, Solution),
                      _of(items, AnnotationRecord), _of(items, JointRef))

    def fragment(self, meta, name, *items):
        items = _flatten(items)
        refs = _of(items, DeviceRef)
        return Fragment(_ident(name), _of(items, Link), _of(items, JointRef), tuple(r for r in refs if r.kind == "sref"),
                        tuple(r for r in refs if r.kind == "aref"), _of(items, VarDecl), self._values(items, "equation"),
                        self._tok_loc(name))

    # ---- p-model-only expression and type forms ----
    def unit_lit(self, meta, number, unit):
        factor = UNITS[str(unit)]
        text = str(number)
        value = float(text) * factor if factor != 1.0 or not text.isdigit() else int(text)
        return s.Literal(value, self._tok_loc(number))

    def unit_expr(self, meta, expr, unit):
        factor = UNITS[str(unit)]
        return expr if factor == 1.0 else s.Binary("*", expr, s.Literal(factor, self._tok_loc(unit)), self._loc(meta))

    def unsized_vector_type(self, meta, element):
        return s.VectorType(element, None, self._loc(meta))

    # ---- mapping ----
    def map_action(self, meta, target, value):
        return _Tagged("action", (target, value, self._loc(meta)), self._loc(meta))

    def predicate(self, meta, expr):
        return _Tagged("predicate", expr, self._loc(meta))

    def map_operation(self, meta, name, *items):
        items = _flatten(items)
        return MappingOperation(_ident(name), _of(items, VarDecl), self._values(items, "equation"),
                                self._values(items, "action"), self._tok_loc(name))

    def map_input_event(self, meta, name, *items):
        bind = _ident(items[0]) if items and isinstance(items[0], Token) else None
        items = _flatten(i for i in items if not isinstance(i, Token))
        return MappingInputEvent(_ident(name), bind, self._values(items, "equation"),
                                 self._values(items, "predicate"), _of(items, VarDecl), self._tok_loc(name))

    def mapping(self, meta, name, dmodel, pmodel, *items):
        items = _flatten(items)
        return Mapping(_ident(name), dmodel, pmodel, _of(items, VarDecl), _of(items, MappingOperation),
                       _of(items, MappingInputEvent), self._tok_loc(name))

