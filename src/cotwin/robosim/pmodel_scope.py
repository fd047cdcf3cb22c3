"""The one resolver of p-model names and constants, shared by the checker (robosim.check_pmodel) and the
kinematic tree builder (pmodel.tree_build): the constant environments of files, p-models, devices,
links and bodies with a part's or a reference's instantiations applied, index replication, the
definitions that references name, and the links a joint or a fixed connection may name.

Constants and variables declared without a value are *parameters*: they take the value RoboTool's SDF
generator gives them, 1, 2, 3, ... in the order it first meets them (a `ParameterNumbering` shared by
one build; docs/pmodel-notation.md, section 3). An instantiation (`instantiation K = e` on a part or a
reference) is evaluated where it is written and gives its constant that value.

Link names are scoped as RoboTool scopes them: `flexibly connected to L` and `fixed to L` name a link
of the p-model that declares them, `... to L in P` a link of its part P; a name that only parts have
is read when exactly one part has it (with a warning: RoboTool needs `in P`), and is ambiguous
otherwise. Nothing is flattened into one table, so two parts' links of one name never overwrite
each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import syntax as s
from .consteval import ConstEnv, ParameterNumbering, try_evaluate
from .declarations import VarDecl
from .pmodel_elements import BodyDecl, Device, DeviceRef, Index, JointRef, Link, LinkDecl, PartRef, PModel

Entry = tuple[str, s.Expr, s.Location]


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def mesh_path(model_path: str, file: str) -> Path:
    """Where a mesh named in a model is: relative names are relative to the model file's folder."""
    path = Path(file)
    return path if path.is_absolute() else Path(model_path).parent / path


@dataclass(frozen=True)
class LinkTarget:
    """A link a joint or a fixed connection names: the link, and the part it is reached through (None
    for the p-model's own)."""

    link: Link
    part: PartRef | None


class PModelScope:
    """Names and constants of a project's p-models, as one build (one parameter numbering) sees them."""

    def __init__(self, project, numbering: ParameterNumbering | None = None):
        self.project = project
        self.numbering = numbering if numbering is not None else ParameterNumbering()
        self._file_env: ConstEnv | None = None

    # ---- constants ----
    def env(self, decls, outer: ConstEnv | None, instantiations: tuple[Entry, ...] = (),
            evaluated_in: ConstEnv | None = None) -> ConstEnv:
        """An environment of declarations inside `outer`: those with a value define it, those without
        are parameters; `instantiations` (evaluated in `evaluated_in`, default `outer`) give values."""
        definitions: dict[str, s.Expr] = {}
        parameters: dict[str, object] = {}
        for d in decls:
            if d.init is not None:
                definitions.setdefault(d.name, d.init)
            else:
                parameters.setdefault(d.name, d)
        where = evaluated_in if evaluated_in is not None else outer
        for name, value, _ in instantiations:
            result = try_evaluate(value, where, None) if where is not None else None
            definitions[name] = s.Literal(result, value.loc) if result is not None else value
            parameters.pop(name, None)
        numbering = self.numbering if outer is None else None
        return ConstEnv(definitions, outer, parameters=parameters, numbering=numbering)

    def file_env(self) -> ConstEnv:
        """Top-level `const` declarations of all .pm files: the outermost constant scope."""
        if self._file_env is None:
            decls = [e for f in self.project.files if f.notation == "pm" for e in f.elements
                     if isinstance(e, VarDecl) and e.kind == "const"]
            self._file_env = self.env(decls, None)
        return self._file_env

    def pmodel_env(self, pmodel: PModel, instantiations: tuple[Entry, ...] = (),
                   evaluated_in: ConstEnv | None = None) -> ConstEnv:
        """A p-model's constants and variables (a part's instantiations applied), inside the file scope."""
        return self.env((*pmodel.constants, *pmodel.variables), self.file_env(), instantiations, evaluated_in)

    def device_env(self, device: Device, instantiations: tuple[Entry, ...], outer: ConstEnv) -> ConstEnv:
        """A device's ports and constants with a reference's instantiations applied."""
        return self.env(device.ports, outer, instantiations)

    def decls_env(self, decls, outer: ConstEnv) -> ConstEnv:
        """The declarations of a link's or body's `def` block."""
        return self.env(decls, outer) if decls else outer

    @staticmethod
    def index_values(index: Index | None, env: ConstEnv) -> list:
        """The integers an `index i : [a, b]` (or `[a, b)`) ranges over; [None] when there is no index."""
        if index is None:
            return [None]
        low, high = try_evaluate(index.low, env, None), try_evaluate(index.high, env, None)
        if not (_is_number(low) and _is_number(high)):
            return []
        return list(range(int(low), int(high) + (1 if index.closed else 0)))

    @staticmethod
    def with_index(env: ConstEnv, index: Index | None, value) -> ConstEnv:
        if index is None:
            return env
        return ConstEnv({index.var: s.Literal(value if value is not None else 0, index.loc)}, env)

    # ---- definitions references name ----
    def device_of(self, ref: DeviceRef) -> Device | None:
        """The definition of a sensor or actuator reference (its own for a local one)."""
        if ref.local is not None:
            return ref.local
        if ref.device is None:
            return None
        return self.project.lookup("sensor" if ref.kind == "sref" else "actuator", ref.device)

    def joint_device(self, joint: JointRef) -> Device | None:
        if joint.local is not None:
            return joint.local
        return self.project.lookup("joint", joint.joint) if joint.joint is not None else None

    def link_decl(self, link: Link) -> LinkDecl | None:
        found = self.project.lookup("link", link.ref) if link.ref is not None else None
        return found if isinstance(found, LinkDecl) else None

    def body_decl(self, ref: s.QName | None) -> BodyDecl | None:
        found = self.project.lookup("body", ref) if ref is not None else None
        return found if isinstance(found, BodyDecl) else None

    def part_pmodel(self, part: PartRef) -> PModel | None:
        found = self.project.lookup("pmodel", part.pmodel)
        return found if isinstance(found, PModel) else None

    # ---- links named by joints and connections ----
    @staticmethod
    def own_link(pmodel: PModel, name: str) -> Link | None:
        return next((link for link in pmodel.links if link.name == name), None)

    @staticmethod
    def part(pmodel: PModel, name: str) -> PartRef | None:
        return next((p for p in pmodel.parts if p.name == name), None)

    def link_target(self, pmodel: PModel, name: str, part_name: str | None) -> tuple[LinkTarget | None, str, bool]:
        """The link `name` (of part `part_name`) as named from `pmodel`: (target, problem, lenient): the
        problem says why there is none; lenient is set when a part's link is named without `in P`."""
        if part_name is not None:
            part = self.part(pmodel, part_name)
            if part is None:
                return None, f"unknown part '{part_name}'", False
            sub = self.part_pmodel(part)
            if sub is None:
                return None, f"part {part_name}'s p-model is unknown", False
            link = self.own_link(sub, name)
            if link is None:
                return None, f"part {part_name} (p-model {sub.name}) has no link '{name}'", False
            return LinkTarget(link, part), "", False
        link = self.own_link(pmodel, name)
        if link is not None:
            return LinkTarget(link, None), "", False
        holders = [(p, self.own_link(sub, name)) for p in pmodel.parts
                   if (sub := self.part_pmodel(p)) is not None and self.own_link(sub, name) is not None]
        if len(holders) == 1:
            return LinkTarget(holders[0][1], holders[0][0]), "", True
        if len(holders) > 1:
            return None, (f"link '{name}' is ambiguous: parts {', '.join(p.name for p, _ in holders)} all have one "
                          f"(name one: '{name} in {holders[0][0].name}')"), False
        return None, f"unknown link '{name}'", False

    def includes(self, pmodel: PModel, other: PModel, depth: int = 0) -> bool:
        """Whether `pmodel` includes `other` through its parts (a p-model including itself is an error)."""
        if depth > 32:
            return True
        for part in pmodel.parts:
            sub = self.part_pmodel(part)
            if sub is not None and (sub is other or self.includes(sub, other, depth + 1)):
                return True
        return False


def element_reference(expr, pmodel: PModel, link: Link | None, scope: "PModelScope"):
    """The body, link or part of the model an annotation value names (`gearbox_reference_body = B`,
    `collision = Rod::my_body`, `collision = my_body`), or None: (kind, element, holder link or part)."""
    if not isinstance(expr, s.Name):
        return None
    parts = expr.name.parts
    if len(parts) == 1:
        name = parts[0]
        if link is not None and (body := next((b for b in link.bodies if b.name == name), None)) is not None:
            return "body", body, link
        if (own := scope.own_link(pmodel, name)) is not None:
            return "link", own, None
        for other in pmodel.links:
            if (body := next((b for b in other.bodies if b.name == name), None)) is not None:
                return "body", body, other
        if (part := scope.part(pmodel, name)) is not None:
            return "part", part, None
        return None
    if len(parts) == 2:
        holder = scope.own_link(pmodel, parts[0])
        if holder is not None and (body := next((b for b in holder.bodies if b.name == parts[1]), None)) is not None:
            return "body", body, holder
        part = scope.part(pmodel, parts[0])
        sub = scope.part_pmodel(part) if part is not None else None
        if sub is not None and (target := scope.own_link(sub, parts[1])) is not None:
            return "link", target, part
    return None
