"""Checks of d-model elements: names resolve, transitions connect existing nodes, types agree."""

from __future__ import annotations

from .checker import Checker
from . import syntax as s
from .declarations import EnumDecl, RecordDecl
from .dmodel_elements import (
    Connection, Controller, Final, Initial, Interface, Junction, Module, RoboticPlatform, State,
    StateMachine,
)
from .interfaces import interface_of, machine_io, platform_members
from .machines import MachineGraph
from .typecheck import ExprChecker, Scope, Symbol
from .types import assignable


class DModelChecker(Checker):

    def check(self) -> None:
        for element in self.source.elements:
            method = getattr(self, "_check_" + type(element).__name__, None)
            if method is not None:
                method(element)

    # ---- declarations ----
    def _unique(self, items, what: str, where: str) -> None:
        seen = {}
        for item in items:
            if item.name in seen:
                self.diag.error(item.loc, f"duplicate {what} '{item.name}' in {where} (first at line {seen[item.name].line})")
            else:
                seen[item.name] = item.loc

    def _check_Interface(self, interface: Interface) -> None:
        where = f"interface {interface.name}"
        self._unique([*interface.operations, *interface.events, *interface.variables], "member", where)
        for op in interface.operations:
            self._params(op.params, f"operation {op.name}")
        for ev in interface.events:
            if ev.type is not None:
                self.types.resolve(ev.type)
        self.variables(interface.variables, Scope())

    def _params(self, params, where: str) -> None:
        self._unique(params, "parameter", where)
        for p in params:
            self.types.resolve(p.type)

    def _check_RecordDecl(self, record: RecordDecl) -> None:
        self._params(record.fields, f"record {record.name}")

    def _check_EnumDecl(self, enum: EnumDecl) -> None:
        self._unique(enum.literals, "literal", f"enumeration {enum.name}")
        for lit in enum.literals:
            for t in lit.params:
                self.types.resolve(t)

    def _check_FunctionDecl(self, fn) -> None:
        self._params(fn.params, f"function {fn.name}")
        result = self.types.resolve(fn.result)
        scope = Scope({p.name: Symbol(p.name, "param", self.types.resolve(p.type), p.loc) for p in fn.params})
        scope.symbols["result"] = Symbol("result", "param", result, fn.loc)
        checker = self.expressions(scope)
        for cond in (*fn.preconditions, *fn.postconditions):
            checker.condition(cond, "pre/postcondition")

    def variables(self, decls, scope: Scope) -> Scope:
        """Add declarations to scope, checking types and initial values."""
        for var in decls:
            ty, init = self.types.declared(var)
            if init is not None:
                self.expressions(scope).expect(init, ty, f"initial value of '{var.name}'")
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var", ty, var.loc)
        return scope

    def expressions(self, scope: Scope, events=None, clocks=frozenset()) -> ExprChecker:
        return ExprChecker(self.types, self.diag, scope, self.functions, events, clocks=clocks)

    def _cycle_def(self, expr: s.Expr | None, where: str) -> None:
        if expr is None:
            return
        self.expressions(Scope()).condition(expr, f"cycleDef of {where}")

    # ---- platform, module, controller ----
    def _check_RoboticPlatform(self, platform: RoboticPlatform) -> None:
        members = platform_members(self.project, platform, self.source, self.diag)
        self._unique([*platform.operations, *platform.events, *platform.variables], "member", f"platform {platform.name}")
        for use in platform.interfaces:
            if use.kind == "requires":
                self.diag.warning(use.loc, f"a robotic platform provides or uses interfaces; 'requires {use.name}' is unusual")
        return members

    def _check_Module(self, module: Module) -> None:
        where = f"module {module.name}"
        self._cycle_def(module.cycle_def, where)
        if module.platform is None:
            self.diag.error(module.loc, f"{where} has no robotic platform")
            platform_events: dict = {}
        else:
            members = self._check_RoboticPlatform(module.platform)
            platform_events = dict(members.events)
        endpoints: dict[str, dict] = {}
        if module.platform is not None:
            endpoints[module.platform.name] = platform_events
        for ref in module.controller_refs:
            ctrl = self.project.lookup("controller", ref.target, self.source)
            if ctrl is None:
                self.diag.error(ref.target.loc, f"unknown controller '{ref.target}'")
                endpoints[ref.name] = None
            else:
                endpoints[ref.name] = self._controller_events(ctrl)
        for ctrl in module.controllers:
            self._check_Controller(ctrl)
            endpoints[ctrl.name] = self._controller_events(ctrl)
        if not module.controllers and not module.controller_refs:
            self.diag.warning(module.loc, f"{where} has no controller")
        self._connections(module.connections, endpoints, where)

    def _controller_events(self, ctrl: Controller) -> dict:
        events = {e.name: e for e in ctrl.events}
        for use in ctrl.interfaces:
            interface = self.project.lookup("interface", use.name, self.source)
            if interface is not None:
                for ev in interface.events:
                    events.setdefault(ev.name, ev)
        return events

    def _machine_events(self, machine: StateMachine) -> dict:
        io = machine_io(self.project, machine, self.source)
        return {**io.inputs, **io.outputs}

    def _connections(self, connections: tuple[Connection, ...], endpoints: dict[str, dict | None], where: str) -> None:
        for c in connections:
            for node, event in ((c.source, c.source_event), (c.target, c.target_event)):
                if node not in endpoints:
                    self.diag.error(c.loc, f"connection in {where}: unknown endpoint '{node}'")
                    continue
                events = endpoints[node]
                if events is not None and event not in events:
                    self.diag.error(c.loc, f"connection in {where}: '{node}' has no event '{event}'")
            src = (endpoints.get(c.source) or {}).get(c.source_event)
            dst = (endpoints.get(c.target) or {}).get(c.target_event)
            if src is not None and dst is not None:
                a = self.types.resolve(src.type) if src.type is not None else None
                b = self.types.resolve(dst.type) if dst.type is not None else None
                if (a is None) != (b is None) or (a is not None and not assignable(b, a)):
                    self.diag.error(c.loc, f"connection in {where}: event types differ ({a or 'none'} to {b or 'none'})")

    def _check_Controller(self, ctrl: Controller) -> None:
        where = f"controller {ctrl.name}"
        self._cycle_def(ctrl.cycle_def, where)
        for use in ctrl.interfaces:
            interface_of(self.project, use, self.source, self.diag)
        self._unique([*ctrl.machine_refs, *ctrl.machines, *ctrl.operations], "machine", where)
        endpoints: dict[str, dict | None] = {ctrl.name: self._controller_events(ctrl)}
        for ref in ctrl.machine_refs:
            machine = self.project.lookup("stm", ref.target, self.source)
            if machine is None:
                self.diag.error(ref.target.loc, f"unknown state machine '{ref.target}'")
                endpoints[ref.name] = None
            else:
                endpoints[ref.name] = self._machine_events(machine)
        for machine in ctrl.machines:
            self._check_StateMachine(machine)
            endpoints[machine.name] = self._machine_events(machine)
        for op in ctrl.operations:
            self._check_StateMachine(op)
        self._connections(ctrl.connections, endpoints, where)

    # ---- state machines ----
    def _check_OperationDef(self, machine) -> None:
        self._check_StateMachine(machine)

    def _check_StateMachine(self, machine: StateMachine) -> None:
        where = f"state machine {machine.name}"
        self._cycle_def(machine.cycle_def, where)
        io = machine_io(self.project, machine, self.source, self.diag)
        scope = Scope()
        for var in io.variables.values():
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var", self.types.declared(var)[0], var.loc)
        for p in machine.params:
            scope.symbols[p.name] = Symbol(p.name, "param", self.types.resolve(p.type), p.loc)
        self._unique(machine.variables, "variable", where)
        self.variables(machine.variables, scope)
        events = {name: (self.types.resolve(ev.type) if ev.type is not None else None) for name, ev in io.inputs.items()}
        outputs = {name: (self.types.resolve(ev.type) if ev.type is not None else None) for name, ev in io.outputs.items()}
        checker = self.expressions(scope, events, io.clocks)
        graph = MachineGraph(machine, self.diag)
        self._structure(graph, where)
        operations = dict(io.operations)
        local_ops = {}
        for node in graph.nodes:
            if isinstance(node.node, State):
                for stmt in (node.node.entry, node.node.during, node.node.exit):
                    checker.statement(stmt, operations, outputs, local_ops)
        for t in graph.transitions:
            if t.condition is not None:
                checker.condition(t.condition, f"condition of transition {t.name}")
            checker.statement(t.action, operations, outputs, local_ops)
            for clock in t.clock_resets:
                if clock not in io.clocks:
                    self.diag.error(t.loc, f"unknown clock '{clock}'")

    def _structure(self, graph: MachineGraph, where: str) -> None:
        containers = [None] + [n for n in graph.nodes if n.is_state and n.children]
        for container in containers:
            children = graph.children_of(container)
            initials = [n for n in children if isinstance(n.node, Initial)]
            states = [n for n in children if isinstance(n.node, (State, Final))]
            place = where if container is None else f"state {container.name}"
            if states and not initials:
                loc = graph.machine.loc if container is None else container.node.loc
                self.diag.error(loc, f"{place} has states but no initial junction")
            for extra in initials[1:]:
                self.diag.error(extra.node.loc, f"{place} has more than one initial junction")
        for node in graph.nodes:
            if isinstance(node.node, Initial):
                if len(node.outgoing) != 1:
                    self.diag.error(node.node.loc, f"initial junction '{node.name}' needs exactly one outgoing transition, has {len(node.outgoing)}")
                for edge in node.outgoing:
                    if edge.transition.is_exec or edge.transition.condition is not None:
                        self.diag.error(edge.transition.loc, f"transition {edge.transition.name} from an initial junction has a condition or exec")
            elif isinstance(node.node, Junction) and not node.outgoing:
                self.diag.error(node.node.loc, f"junction '{node.name}' has no outgoing transition")
            elif isinstance(node.node, Final) and node.outgoing:
                self.diag.error(node.outgoing[0].transition.loc, f"transition {node.outgoing[0].transition.name} leaves final state '{node.name}'")
        for edge in graph.edges:
            if isinstance(edge.target.node, Initial):
                self.diag.error(edge.transition.target_loc, f"transition {edge.transition.name} enters initial junction '{edge.target.name}'")
            if edge.transition.is_else and edge.source.outgoing.count(edge) and sum(
                    e.transition.is_else for e in edge.source.outgoing) > 1:
                self.diag.error(edge.transition.loc, f"more than one 'else' transition from '{edge.source.name}'")
