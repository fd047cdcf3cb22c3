"""Checks of platform mappings against the d-model's robotic platform and the p-model's sensors.

Readings chosen where the notation is silent (see docs/pmodel-notation.md, section 5, and
docs/robosim-notation.md, section 8):
several `equation`s of an input event are a conjunction; `action x = e` assigns mapping variable x
when the operation is called.
"""

from __future__ import annotations

from ..diagnostics import Diagnostics
from .checker import Checker
from . import syntax as s
from .pmodel_scope import PModelScope
from .consteval import const_env, try_evaluate
from .declarations import SourceFile
from .dmodel_elements import Module
from .interfaces import Members, platform_members
from .pmodel_elements import Mapping, PModel
from .typecheck import ExprChecker, Scope, Symbol
from .types import BOOL, UNKNOWN, DeviceTy, Ty

MAPPING_FIRST_INDEX = 0  # a platform mapping's vectors count from 0 (q[0] is the first joint's: cotwin.mapping.runtime)


def mapping_targets(project, mapping: Mapping, source: SourceFile | None, diag: Diagnostics | None = None):
    """The module and p-model a mapping connects, and the module's platform members."""
    module = project.lookup("module", mapping.dmodel, source)
    pmodel = project.lookup("pmodel", mapping.pmodel, source)
    if diag is not None:
        if module is None:
            diag.error(mapping.dmodel.loc, f"unknown d-model module '{mapping.dmodel}'")
        if pmodel is None:
            diag.error(mapping.pmodel.loc, f"unknown p-model '{mapping.pmodel}'")
    members = None
    if isinstance(module, Module) and module.platform is not None:
        module_source = project.file_of(module)
        members = platform_members(project, module.platform, module_source)
    return module, pmodel, members


def device_path(project, pmodel: PModel, name: s.QName):
    """Resolve `pmodel::link::sref` (or `pmodel::link::joint::aref`) to (link, device-ref, device),
    or return an error message."""
    parts = name.parts
    if parts[0] != pmodel.name:
        return f"'{name}' does not start with the mapped p-model '{pmodel.name}'"
    if len(parts) not in (3, 4):
        return f"'{name}' is not a path pmodel::link::sensor"
    scope = PModelScope(project)
    target, problem, _ = scope.link_target(pmodel, parts[1], None)
    if target is None:
        return f"p-model '{pmodel.name}' has no link '{parts[1]}'" if problem.startswith("unknown") else problem
    link = target.link
    if len(parts) == 3:
        ref = next((r for r in (*link.sensors, *link.actuators) if r.name == parts[2]), None)
        if ref is None:
            return f"link '{link.name}' of p-model '{pmodel.name}' has no sensor or actuator '{parts[2]}'"
    else:
        joint = next((j for j in link.joints if j.name == parts[2]), None)
        if joint is None:
            return f"link '{link.name}' has no joint '{parts[2]}'"
        ref = next((a for a in (*joint.actuators, *joint.sensors) if a.name == parts[3]), None)
        if ref is None:
            return f"joint '{joint.name}' has no actuator or sensor '{parts[3]}'"
    kind = "sensor" if ref.kind == "sref" else "actuator"
    device = scope.device_of(ref)
    if device is None:
        return f"unknown {kind} '{ref.device}'"
    return link, ref, device


class MappingChecker(Checker):

    def check(self) -> None:
        for element in self.source.elements:
            if isinstance(element, Mapping):
                self.mapping(element)

    def mapping(self, mapping: Mapping) -> None:
        module, pmodel, members = mapping_targets(self.project, mapping, self.source, self.diag)
        if isinstance(module, Module) and module.platform is None:
            self.diag.error(mapping.dmodel.loc, f"module '{module.name}' has no robotic platform to map")
        members = members or Members()
        scope = Scope()
        env = const_env([v for v in mapping.variables if v.is_const])
        for var in mapping.variables:
            ty, init = self.types.declared(var)
            if init is not None:
                self._checker(scope, pmodel).expect(init, ty, f"initial value of '{var.name}'")
                if var.is_const:
                    try_evaluate(init, env, self.diag, f"constant {var.name}")
            if var.name in scope.symbols:
                self.diag.error(var.loc, f"duplicate mapping variable '{var.name}'")
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var", ty, var.loc)
        seen: dict[str, s.Location] = {}
        for op in mapping.operations:
            self._unique(seen, op.name, op.loc, "operation")
            sig = members.operations.get(op.name)
            if module is not None and sig is None:
                self.diag.error(op.loc, f"operation '{op.name}' is not an operation of robotic platform "
                                f"'{module.platform.name if module.platform else '?'}'")
            op_scope = scope.child()
            for p in sig.params if sig else ():
                op_scope.symbols.setdefault(p.name, Symbol(p.name, "param", self.types.resolve(p.type), p.loc))
            self._locals(op.variables, op_scope, pmodel)
            checker = self._checker(op_scope, pmodel)
            for eq in op.equations:
                checker.condition(eq, f"equation of operation {op.name}")
            for target, value, _ in op.actions:
                checker.assignment(target, value)
        for ev in mapping.input_events:
            self._unique(seen, ev.name, ev.loc, "input event")
            decl = members.events.get(ev.name)
            if module is not None and decl is None:
                self.diag.error(ev.loc, f"input event '{ev.name}' is not an event of robotic platform "
                                f"'{module.platform.name if module.platform else '?'}'")
            ev_scope = scope.child()
            if ev.bind is not None:
                ty = self.types.resolve(decl.type) if decl is not None and decl.type is not None else None
                if decl is not None and ty is None:
                    self.diag.error(ev.loc, f"event '{ev.name}' carries no value to bind to '{ev.bind}'")
                ev_scope.symbols[ev.bind] = Symbol(ev.bind, "var", ty or BOOL, ev.loc)
            self._locals(ev.variables, ev_scope, pmodel)
            checker = self._checker(ev_scope, pmodel)
            for eq in (*ev.equations, *ev.predicates):
                checker.condition(eq, f"equation of input event {ev.name}")
            if not ev.equations and not ev.predicates:
                self.diag.warning(ev.loc, f"input event '{ev.name}' has no equation: it never occurs")
        for name, op in members.operations.items():
            if name not in seen and module is not None:
                self.diag.warning(mapping.loc, f"platform operation '{name}' is not mapped by {mapping.name}")
        sent = platform_outputs(module) if isinstance(module, Module) else set()
        for name in members.events:
            if name not in seen and name not in sent and module is not None:
                self.diag.warning(mapping.loc, f"platform event '{name}' is not mapped by {mapping.name}")

    def _unique(self, seen: dict, name: str, loc, what: str) -> None:
        if name in seen:
            self.diag.error(loc, f"duplicate {what} '{name}' in mapping (first at line {seen[name].line})")
        seen[name] = loc

    def _locals(self, variables, scope: Scope, pmodel) -> None:
        for var in variables:
            ty, init = self.types.declared(var)
            if init is not None:
                self._checker(scope, pmodel).expect(init, ty, f"initial value of '{var.name}'")
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var", ty, var.loc)

    def _checker(self, scope: Scope, pmodel: PModel | None) -> ExprChecker:
        def qualified(name: s.QName) -> Ty | None:
            if pmodel is None or name.parts[0] != pmodel.name:
                return None
            found = device_path(self.project, pmodel, name)
            if isinstance(found, str):
                self.diag.error(name.loc, found)
                return UNKNOWN
            return DeviceTy(found[2])

        return ExprChecker(self.types, self.diag, scope, self.functions, None, qualified,
                           first_index=MAPPING_FIRST_INDEX)


def platform_outputs(module: Module) -> set[str]:
    """The platform's events the d-model sends to it (a connection from a controller to the platform): a mapping
    maps input events only, so these are no event it leaves unmapped (a sorter's `sorted` report)."""
    platform = module.platform.name if module.platform is not None else None
    return {c.target_event for c in module.connections if c.target == platform and not c.bidirectional}
