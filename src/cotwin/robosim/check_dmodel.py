"""Checks of d-model elements: names resolve, transitions connect existing nodes, types agree, and
RoboTool's well-formedness rules hold (RoboSimValidator and the RoboChartValidator it extends).

As strict as RoboTool where a rule makes a model meaningless or unrunnable (unresolved names, type
errors, a machine without an initial junction); RoboTool's rules about the shape of interfaces are
warnings (cotwin can still read such a model). RoboTool accepts non-boolean cycleDef expressions and
conditions on transitions out of an initial junction, and so does cotwin. In .rct files (RoboChart,
which RoboTool loads beside the .rst files) cotwin reads the declarations only.
"""

from __future__ import annotations

from . import syntax as s
from .checker import Checker
from .consteval import ConstError, const_env, evaluate
from .declarations import EnumDecl, EventDecl, FunctionDecl, RecordDecl
from .dmodel_elements import (
    Connection, Controller, Final, Initial, Interface, Junction, Module, OperationDef, RoboticPlatform, State,
    StateMachine,
)
from .interfaces import interface_of, machine_io, module_platform, platform_members, platform_node_name
from .machines import MachineGraph
from .typecheck import ExprChecker, Scope, Symbol
from .types import NAT, REAL, VectorTy, assignable

_DECLARATIONS = ("Interface", "RecordDecl", "EnumDecl", "FunctionDecl", "RoboticPlatform")
_TIMED = (s.SinceExpr, s.SinceEntryExpr)
_ARITHMETIC_ERRORS = ("division by zero", "integer overflow")
_COMPARISONS = ("<", "<=", ">", ">=", "==")


class DModelChecker(Checker):

    def check(self) -> None:
        behaviour = self.source.notation != "rct"
        for element in self.source.elements:
            kind = type(element).__name__
            if not behaviour and kind not in _DECLARATIONS:
                continue
            method = getattr(self, "_check_" + kind, None)
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
        if interface.events and interface.operations:
            self.diag.warning(interface.loc, f"{where} has both events and operations; RoboTool requires "
                                             "one or the other (besides variables)")
        self.variables(interface.variables, Scope())

    def _params(self, params, where: str) -> None:
        self._unique(params, "parameter", where)
        for p in params:
            self.types.resolve(p.type)

    def _check_RecordDecl(self, record: RecordDecl) -> None:
        self._params(record.fields, f"record {record.name}")
        if not record.fields:
            self.diag.error(record.loc, f"datatype {record.name} has no field (a datatype needs at least one)")

    def _check_EnumDecl(self, enum: EnumDecl) -> None:
        self._unique(enum.literals, "literal", f"enumeration {enum.name}")
        for lit in enum.literals:
            for t in lit.params:
                self.types.resolve(t)

    def _check_FunctionDecl(self, fn: FunctionDecl) -> None:
        self._params(fn.params, f"function {fn.name}")
        result = self.types.resolve(fn.result)
        scope = Scope({p.name: Symbol(p.name, "param", self.types.resolve(p.type), p.loc) for p in fn.params})
        scope.symbols["result"] = Symbol("result", "param", result, fn.loc)
        checker = self.expressions(scope)
        checker.strays_read = True  # only checked, never evaluated (a definition `result == e` holds no stray)
        for cond in (*fn.preconditions, *fn.postconditions):
            checker.condition(cond, "pre/postcondition")

    def variables(self, decls, scope: Scope) -> Scope:
        """Add declarations to scope, checking types and initial values; evaluate the constants now,
        so that a division by zero or an overflow in one is reported here, where it is written."""
        for var in decls:
            ty, init = self.types.declared(var)
            if init is not None:
                self.expressions(scope).expect(init, ty, f"initial value of '{var.name}'")
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var", ty, var.loc, var)
        env = const_env([d for d in decls if d.is_const])
        env.enums = self._enum_value
        for var in decls:
            if var.is_const and var.init is not None:
                try:
                    evaluate(var.init, env)
                except ConstError as err:
                    if err.message.endswith(_ARITHMETIC_ERRORS):
                        self.diag.error(err.loc, f"{err.message} (in constant {var.name})")
        return scope

    def _enum_value(self, name: s.QName):
        decl = self.project.lookup("type", s.QName(name.parts[:-1]), self.source)
        if isinstance(decl, EnumDecl) and decl.literal(name.last) is not None:
            return [lit.name for lit in decl.literals].index(name.last)
        return None

    def expressions(self, scope: Scope, events=None, clocks=frozenset(), states=None) -> ExprChecker:
        return ExprChecker(self.types, self.diag, scope, self.functions, events, clocks=clocks, states=states)

    def _foreign(self, name: s.QName) -> str | None:
        """Why a reference to a RoboChart general or ANN component cannot be followed, None if it names none."""
        found = self.project.lookup("foreign", name, self.source)
        if found is None:
            return None
        return (f"'{name}' is a RoboChart {found.kind} (declared at {found.loc}): RoboTool reads it, and cotwin cannot "
                f"run it (it has no state machine to simulate)")

    def _cycle_def(self, expr: s.Expr | None, where: str) -> None:
        """RoboTool accepts any expression (`cycleDef cycle == 1`, `cycleDef 1`); it must be typeable."""
        if expr is not None:
            self.expressions(Scope()).check(expr)

    # ---- platform, module, controller ----
    def _check_RoboticPlatform(self, platform: RoboticPlatform) -> None:
        self._unique([*platform.operations, *platform.events, *platform.variables], "member", f"platform {platform.name}")
        for use in platform.interfaces:
            interface = interface_of(self.project, use, self.source, self.diag)
            if use.kind == "requires":
                self.diag.warning(use.loc, f"a robotic platform provides or uses interfaces; 'requires {use.name}' is unusual")
            elif interface is not None and use.kind == "provides" and interface.events:
                self.diag.warning(use.loc, f"{platform.name} provides interface {interface.name}, which has events; "
                                           "RoboTool expects events in used interfaces")
        for clock in platform.clocks:
            self.diag.error(clock.loc, f"robotic platform {platform.name} cannot declare clocks")

    def _check_Module(self, module: Module) -> None:
        where = f"module {module.name}"
        self._cycle_def(module.cycle_def, where)
        self._unique(module.variables, "constant", where)
        self.variables(module.variables, Scope())
        platform = module_platform(self.project, module, self.source, self.diag)
        endpoints: dict[str, dict | None] = {}
        provided: dict | None = None
        if module.platform is not None:
            self._check_RoboticPlatform(module.platform)
        if platform is None:
            if module.platform_ref is None:
                self.diag.error(module.loc, f"{where} has no robotic platform")
        else:
            members = platform_members(self.project, platform, self.project.file_of(platform) or self.source, self.diag)
            endpoints[platform_node_name(module)] = dict(members.events)
            provided = members.operations
        for machine in (*module.machines, *module.machine_refs):
            self.diag.error(machine.loc, f"{where} must not have a state machine outside a controller")
        controllers: list[tuple[str, Controller | None, object]] = []
        for ref in module.controller_refs:
            ctrl = self.project.lookup("controller", ref.target, self.source)
            if ctrl is None:
                self.diag.error(ref.target.loc, self._foreign(ref.target) or f"unknown controller '{ref.target}'")
                endpoints[ref.name] = None
            else:
                endpoints[ref.name] = self._controller_events(ctrl)
            controllers.append((ref.name, ctrl, ref.loc))
        for ctrl in module.controllers:
            self._check_Controller(ctrl)
            endpoints[ctrl.name] = self._controller_events(ctrl)
            controllers.append((ctrl.name, ctrl, ctrl.loc))
        if not controllers:
            self.diag.warning(module.loc, f"{where} has no controller")
        if provided is not None:
            for name, ctrl, loc in controllers:
                if ctrl is None:
                    continue
                missing = [op for op in self._controller_required_ops(ctrl) if op not in provided]
                if missing:
                    self.diag.error(loc, f"{where} does not provide operation(s) {', '.join(missing)} that "
                                         f"controller {ctrl.name} requires")
        for name, ctrl, loc in controllers:  # an event a controller passes to its machines that nothing brings it
            if ctrl is None:
                continue
            fed = {c.target_event for c in module.connections if c.target == name}
            unfed = list(dict.fromkeys(c.source_event for c in ctrl.connections
                                       if c.source == ctrl.name and c.source_event not in fed))
            if unfed:
                events, it = ("event", "it") if len(unfed) == 1 else ("events", "them")
                self.diag.warning(loc, f"{where} connects nothing to {events} {', '.join(unfed)} of {name}: controller "
                                       f"{ctrl.name} passes {it} to its machines, which never see {it} (add e.g. "
                                       f"'connection {platform_node_name(module)} on {unfed[0]} to {name} on {unfed[0]} "
                                       "(_async)')")
        self._connections(module.connections, endpoints, where, platform_node_name(module))

    def _controller_required_ops(self, ctrl: Controller) -> list[str]:
        source = self.project.file_of(ctrl) or self.source
        names = []
        for use in ctrl.interfaces:
            if use.kind == "requires":
                interface = self.project.lookup("interface", use.name, source)
                if interface is not None:
                    names.extend(op.name for op in interface.operations)
        return names

    def _controller_events(self, ctrl: Controller) -> dict:
        source = self.project.file_of(ctrl) or self.source
        events = {e.name: e for e in ctrl.events}
        for use in ctrl.interfaces:
            interface = self.project.lookup("interface", use.name, source)
            if interface is not None:
                for ev in interface.events:
                    events.setdefault(ev.name, ev)
        return events

    def _machine_events(self, machine: StateMachine, source=None) -> dict:
        io = machine_io(self.project, machine, source or self.source)
        return {**io.inputs, **io.outputs}

    def _connections(self, connections: tuple[Connection, ...], endpoints: dict[str, dict | None], where: str,
                     platform: str | None = None) -> None:
        ends: dict[tuple[str, str], Connection] = {}
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
            if platform is not None and platform in (c.source, c.target) and not c.is_async:
                self.diag.error(c.loc, f"connection in {where}: a connection with the robotic platform must be "
                                       "asynchronous: add (_async)")
            for end in ((c.source, c.source_event, "from"), (c.target, c.target_event, "to")):
                key = end[:2]
                if key in ends and not c.bidirectional:
                    self.diag.error(c.loc, f"connection in {where}: {end[1]} on {end[0]} already has a connection "
                                           f"(line {ends[key].loc.line})")
                ends.setdefault(key, c)

    def _check_Controller(self, ctrl: Controller) -> None:
        where = f"controller {ctrl.name}"
        self._cycle_def(ctrl.cycle_def, where)
        for use in ctrl.interfaces:
            interface_of(self.project, use, self.source, self.diag)
            if use.kind == "provides":
                self.diag.error(use.loc, f"{ctrl.name} is a controller and cannot provide interface {use.name}")
        for clock in ctrl.clocks:
            self.diag.error(clock.loc, f"{where} cannot declare clocks")
        self._unique([*ctrl.machine_refs, *ctrl.machines, *ctrl.operations, *ctrl.operation_refs], "machine", where)
        for ref in ctrl.operation_refs:
            if self.project.lookup("operation", ref.target, self.source) is None:
                self.diag.error(ref.target.loc, self._foreign(ref.target) or f"unknown operation '{ref.target}'")
        if not ctrl.machine_refs and not ctrl.machines:
            self.diag.error(ctrl.loc, f"{ctrl.name} must have at least one state machine")
        endpoints: dict[str, dict | None] = {ctrl.name: self._controller_events(ctrl)}
        provided_ops = set(self._controller_required_ops(ctrl)) | {op.name for op in ctrl.operations} | {
            r.name for r in ctrl.operation_refs} | {r.target.last for r in ctrl.operation_refs}
        members: list[tuple[str, StateMachine, object, object]] = []
        for ref in ctrl.machine_refs:
            machine = self.project.lookup("stm", ref.target, self.source)
            if machine is None:
                self.diag.error(ref.target.loc, f"unknown state machine '{ref.target}'")
                endpoints[ref.name] = None
                continue
            source = self.project.file_of(machine) or self.source
            endpoints[ref.name] = self._machine_events(machine, source)
            members.append((ref.name, machine, source, ref.loc))
        for machine in ctrl.machines:
            self._check_StateMachine(machine)
            endpoints[machine.name] = self._machine_events(machine)
            members.append((machine.name, machine, self.source, machine.loc))
        for op in ctrl.operations:
            self._check_StateMachine(op)
        for name, machine, source, loc in members:
            # RoboTool does not require a controller to declare the interfaces its machines use (RoboSim's
            # missingDeclaredInterface check is disabled): only the operations they require (RoboChart's C4)
            io = machine_io(self.project, machine, source)
            unprovided = [op for op in io.operations if op not in provided_ops]
            if unprovided:
                self.diag.error(loc, f"{ctrl.name} does not provide operation(s) {', '.join(unprovided)} that "
                                     f"{machine.name} requires (require them, or define them with operation/opref)")
            # an input event of the machine's input context that no connection of the controller brings: it
            # never occurs there, and its commands are 'not taken' with no word why
            fed = {c.target_event for c in ctrl.connections if c.target == name} | {
                c.source_event for c in ctrl.connections if c.source == name and c.bidirectional}
            unfed = [ev for ev in self._context_inputs(machine, source) if ev not in fed]
            if unfed:
                events, they = ("input event", "it never occurs") if len(unfed) == 1 else ("input events", "they never occur")
                self.diag.warning(loc, f"{where} connects nothing to {events} {', '.join(unfed)} of {name}: {they} in "
                                       f"{machine.name} (add e.g. 'connection {ctrl.name} on {unfed[0]} to {name} on "
                                       f"{unfed[0]} (_async)')")
        self._connections(ctrl.connections, endpoints, where)

    def _context_inputs(self, machine: StateMachine, source) -> list[str]:
        """The events of a machine's input context (its own and its interfaces'): events it only takes."""
        names: dict[str, None] = {}  # in the order written
        for item in machine.input_context:
            if isinstance(item, EventDecl):
                names[item.name] = None
            elif (interface := interface_of(self.project, item, source, None)) is not None:
                names.update((ev.name, None) for ev in interface.events)
        return list(names)

    # ---- state machines ----
    def _check_OperationDef(self, machine) -> None:
        self._check_StateMachine(machine)

    def _check_StateMachine(self, machine: StateMachine) -> None:
        kind = "operation" if isinstance(machine, OperationDef) else "state machine"
        where = f"{kind} {machine.name}"
        self._cycle_def(machine.cycle_def, where)
        io = machine_io(self.project, machine, self.source, self.diag)
        scope = Scope()
        for var in io.variables.values():
            scope.symbols[var.name] = Symbol(var.name, "const" if var.is_const else "var",
                                             self.types.declared(var)[0], var.loc, var)
        for p in machine.params:
            scope.symbols[p.name] = Symbol(p.name, "param", self.types.resolve(p.type), p.loc)
        self._unique(machine.variables, "variable", where)
        self.variables(machine.variables, scope)
        events = {name: (self.types.resolve(ev.type) if ev.type is not None else None) for name, ev in io.inputs.items()}
        outputs = {name: (self.types.resolve(ev.type) if ev.type is not None else None) for name, ev in io.outputs.items()}
        graph = MachineGraph(machine, self.diag)
        states = {n.name for n in graph.nodes if isinstance(n.node, State)} | {
            ".".join(n.path) for n in graph.nodes if isinstance(n.node, State)}
        checker = self.expressions(scope, events, io.clocks, states)
        self._structure(graph, where, isinstance(machine, OperationDef))
        operations = dict(io.operations)
        for node in graph.nodes:
            if isinstance(node.node, State):
                for stmt in (node.node.entry, node.node.during, node.node.exit):
                    checker.statement(stmt, operations, outputs)
                    self._action_expressions(stmt, checker)
        for t in graph.transitions:
            if t.condition is not None:
                checker.condition(t.condition, f"condition of transition {t.name}")
                self._timed(t.condition, checker)
                self._zero_based(t.condition, checker)
            checker.statement(t.action, operations, outputs)
            self._action_expressions(t.action, checker)
            for clock in t.clock_resets:
                if clock not in io.clocks:
                    self.diag.error(t.loc, f"unknown clock '{clock}'")
            if t.probability is not None:
                checker.check(t.probability)
        if isinstance(machine, OperationDef):
            conditions = checker.with_scope(checker.scope)
            conditions.strays_read = True  # only checked, never evaluated
            for cond in (*machine.preconditions, *machine.postconditions):
                conditions.condition(cond, f"pre/postcondition of operation {machine.name}")

    def _action_expressions(self, stmt, checker: ExprChecker) -> None:
        """Timed expressions are not allowed in actions (RoboChart TE1); 0-based vector readings."""
        for st in s.statements(stmt):
            for e in s.statement_expressions(st):
                for node in s.walk(e):
                    if isinstance(node, _TIMED):
                        self.diag.error(node.loc, "timed expression (since, sinceEntry) not allowed in an action")
                self._zero_based(e, checker, statement=st)

    def _timed(self, condition: s.Expr, checker: ExprChecker) -> None:
        """since(C) and sinceEntry(S) may only be compared with a number (RoboChart TE4)."""
        parents: dict[int, s.Expr] = {}
        for node in s.walk(condition):
            for child in s.sub_expressions(node):
                parents[id(child)] = node
        for node in s.walk(condition):
            if not isinstance(node, _TIMED):
                continue
            parent = parents.get(id(node))
            if not (isinstance(parent, s.Binary) and parent.op in _COMPARISONS):
                self.diag.error(node.loc, "unsupported use of a timed expression: compare it with a number")
                continue
            other = parent.right if parent.left is node else parent.left
            ty = checker.readings.type_of(other)
            if ty is not None and not (assignable(NAT, ty) or assignable(REAL, ty)):
                self.diag.error(node.loc, f"a timed expression is compared with a number, not {ty}")

    def _zero_based(self, expr: s.Expr, checker: ExprChecker, statement=None) -> None:
        """A constant index 0 into a vector: RoboChart vectors index from 1, so it is out of range.
        Read as a statement written for 0-based vectors: every constant index into that vector in
        the same statement (or condition) counts from 0."""
        root = statement if statement is not None else expr
        exprs = s.statement_expressions(statement) if statement is not None else (expr,)
        accesses = [node for e in exprs for node in s.walk(e) if isinstance(node, s.IndexAccess)
                    and isinstance(node.index, s.Literal) and node.index.value is not True
                    and isinstance(node.index.value, int)
                    and isinstance(checker.readings.type_of(node.base), VectorTy)]
        zero = [a for a in accesses if a.index.value == 0]
        if not zero:
            return
        del root
        for z in zero:
            base = _describe(z.base)
            same = [a for a in accesses if _describe(a.base) == base]
            if any(id(a) in checker.readings.first_index for a in same):
                continue
            size = checker.readings.type_of(z.base).size
            self.diag.warning(z.index.loc, f"'{base}[0]': vectors index from 1 (1..{size if size else 'n'}), so index 0 "
                                           f"is out of range; read as written for 0-based vectors: every constant "
                                           f"index into {base} here counts from 0 "
                                           f"({', '.join(f'{base}[{a.index.value}]' for a in same)})")
            for a in same:
                checker.readings.first_index[id(a)] = 0

    def _structure(self, graph: MachineGraph, where: str, operation: bool = False) -> None:
        containers = [None] + [n for n in graph.nodes if n.is_state and n.children]
        for container in containers:
            children = graph.children_of(container)
            initials = [n for n in children if isinstance(n.node, Initial)]
            states = [n for n in children if isinstance(n.node, (State, Final))]
            place = where if container is None else f"state {container.name}"
            if states and not initials:
                loc = graph.machine.loc if container is None else container.node.loc
                if container is None and not operation:
                    self.diag.error(loc, f"{place} has states but no initial junction")
                else:
                    self.diag.warning(loc, f"{place} has states but no initial junction")
            elif children and not states:
                loc = graph.machine.loc if container is None else container.node.loc
                self.diag.error(loc, f"{place} has no state or final state")
            for extra in initials[1:]:
                self.diag.error(extra.node.loc, f"{place} has more than one initial junction")
        incoming = {id(e.target) for e in graph.edges}
        for node in graph.nodes:
            if isinstance(node.node, Initial):
                if len(node.outgoing) != 1:
                    self.diag.error(node.node.loc, f"initial junction '{node.name}' needs exactly one outgoing transition, has {len(node.outgoing)}")
            elif isinstance(node.node, Junction):
                if not node.outgoing:
                    self.diag.error(node.node.loc, f"junction '{node.name}' has no outgoing transition")
                if id(node) not in incoming:
                    self.diag.error(node.node.loc, f"junction '{node.name}' has no incoming transition")
            elif isinstance(node.node, Final) and node.outgoing:
                self.diag.error(node.outgoing[0].transition.loc, f"transition {node.outgoing[0].transition.name} leaves final state '{node.name}'")
        for edge in graph.edges:
            if isinstance(edge.target.node, Initial):
                self.diag.error(edge.transition.target_loc, f"transition {edge.transition.name} enters initial junction '{edge.target.name}'")
            if edge.transition.is_else and edge.source.outgoing.count(edge) and sum(
                    e.transition.is_else for e in edge.source.outgoing) > 1:
                self.diag.error(edge.transition.loc, f"more than one 'else' transition from '{edge.source.name}'")


def _describe(e: s.Expr) -> str:
    if isinstance(e, s.Name):
        return str(e.name)
    if isinstance(e, s.FieldAccess):
        return f"{_describe(e.base)}.{e.field}"
    return "the vector"



