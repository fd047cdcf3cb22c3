"""The platform-mapping interface of the paper (`InputEvent`, `Operation`, `Mapping` with
`start_mapping`, `get_event`, `execute_operation`, `stop_mapping`), driven by the mapping model.

Readings of the mapping (see also docs/robosim-notation.md, section 8):
- `execute_operation(op, args)`: the d-model's arguments bind the operation's parameters; its local
  `var`s are evaluated in order, then its `action x = e` assign mapping variables, then each
  equation `actuator.port == e` (a path `pmodel::link::joint::aref.port`) sends e to that actuator;
- `get_event(e)`: e's definition holds iff all its equations and predicates hold (a conjunction),
  evaluated over the mapping's variables and the platform's sensors (`pmodel::link::sref.port`);
- `report()`: which events *occur* in the step just made (docs/interop.md, "Events are events"): an
  event whose definition reads a variable some operation assigns is an *answer* and occurs in a step
  when it holds and it did not hold at the end of the previous step, or an operation executed in the
  step assigned a variable it reads (the question was asked anew), or the value it carries changed;
  any other event is an *observation* of the platform's sensors and occurs in every step it holds
  (each step is a new sample). So an answer is never a previous request's, and is true in one step;
  the d-model takes one event per cycle of a waiting state, so at most one answer is delivered per
  step: answers that come in the same step (a short move is both feasible and completed within a
  step of 0.5 s) follow in the next steps, in the order they came, with the values they came with,
  and a request asking one anew drops the previous request's that still waits;
- an input event `e?x` whose equations include `x == v` carries the value of v: it occurs when v is a
  finite number (a sensor reporting no measurement gives inf or NaN, as ROS does) and its other
  equations and predicates hold with x bound to that value;
- functions the models leave abstract come from a registry: the math functions, and an arm's
  kinematics (`inverse_kinematics`, `reachable`), set up on the first call only, so that a mapping
  not calling them needs no arm; `robot_contact()`: did the robot touch another robot of its world in
  the step just made (a cell of several robots, cotwin.pmodel.shared);
- mapping variables q0..qN and qd0..qdN mirror the positions and velocities of the mirrored joints
  (by default the arm's, in kinematic order), so they can be logged as in the paper; further
  monitored variables may mirror platform readings by path (`monitor`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import fields

from ..config import nearest_first
from ..diagnostics import CotwinError, Finding, Severity
from ..plaindata import count, fields as state_fields, finite, like, of_type
from ..pmodel import ik
from ..pmodel.grippers import beyond
from ..pmodel.ikcache import SolutionCache
from ..pmodel.cell import CellGeometry
from ..robosim import syntax as s
from ..robosim.check_mapping import mapping_targets
from ..robosim.evaluator import ClosureCompiler, Evaluator, index
from ..robosim.operators import MATH
from ..robosim.values import EvalError
from ..robosim.declarations import EnumDecl
from ..robosim.pmodel_elements import Mapping as MappingModel
from ..robosim.check_mapping import MAPPING_FIRST_INDEX
from ..robosim.types import EnumTy, TypeResolver, VectorTy
from ..diagnostics import Diagnostics

MIRROR_PREFIXES = (("q", "position"), ("qd", "velocity"))
ik_log = logging.getLogger("cotwin.ik")  # what the IK reaches for an arm of fewer than 6 joints


def mirror_variables(variables: list[str], joints: list[str]) -> dict[str, tuple[str, str]]:
    """Mapping variables q<i> / qd<i> -> (i-th mirrored joint, position | velocity): q0.. first, then qd0.."""
    names = set(variables)
    out = {}
    for prefix, kind in MIRROR_PREFIXES:
        for i, joint in enumerate(joints):
            if f"{prefix}{i}" in names:
                out[f"{prefix}{i}"] = (joint, kind)
    return out


def declares_mirrors(variables: list[str]) -> bool:
    """Does the mapping declare any q<i>/qd<i> variable (so that its mirrored joints matter)?"""
    return any(v[len(prefix):].isdigit() for v in variables for prefix, _ in MIRROR_PREFIXES
               if v.startswith(prefix) and len(v) > len(prefix))


def mirrored_joints(tree, which="arm", tool: str = "fingertips", tool_link: str | None = None) -> list[str]:
    """The joints q<i>/qd<i> mirror: "arm" (the actuated joints from the base to the tool, cotwin.pmodel.ik: the
    link a cell geometry's [tool] link names, as the mapping's IK takes it, else the default tool's), "actuated"
    (every actuated joint, in the tree's order), or a list of joint names."""
    if which == "arm":
        return ik.arm_joints(tree, ik.find_tool(tree, tool, tool_link))
    if which == "actuated":
        return [j.name for j in tree.actuated]
    known = {j.name for j in tree.actuated}
    unknown = [j for j in which if j not in known]
    if unknown:
        raise CotwinError(f"mirrored joints {', '.join(unknown)} "
                          f"{'is not an actuated joint' if len(unknown) == 1 else 'are not actuated joints'} of p-model {tree.name} "
                          f"(joints: {', '.join(sorted(known))})")
    return list(which)


KINEMATICS_FUNCTIONS = ("inverse_kinematics", "reachable")


def uses_kinematics(model: MappingModel) -> bool:
    """Does the mapping call a kinematics function (`inverse_kinematics`, `reachable`) anywhere, so that a run
    sets up its arm's kinematics (FunctionRegistry)?"""
    exprs = [v.init for v in model.variables if v.init is not None]
    for op in model.operations:
        exprs += [v.init for v in op.variables if v.init is not None]
        exprs += [*op.equations, *(value for _, value, _ in op.actions)]
    for ev in model.input_events:
        exprs += [v.init for v in ev.variables if v.init is not None]
        exprs += [*ev.equations, *ev.predicates]
    return any(isinstance(node, s.Call) and isinstance(node.function, s.Name)
               and node.function.name.last in KINEMATICS_FUNCTIONS for e in exprs for node in s.walk(e))


def kinematics_result_problem(project, model: MappingModel, pmodel: str, tool_link: str,
                              arm: list[str]) -> Finding | None:
    """The mapping's declared `inverse_kinematics(...): vector(real, N)` must have one value per arm joint:
    with fewer, the last joints would never be commanded (and the tool miss its target while moves
    'complete'); with more, the values past the arm's would be read as nothing. An error at the function's
    declaration, or None. `arm`: the joints from p-model `pmodel`'s base to the tool link, in kinematic order."""
    source = project.file_of(model)
    fn = project.visible_functions(source).get("inverse_kinematics")
    if fn is None:
        return None
    ty = TypeResolver(project, source, Diagnostics()).resolve(fn.result)
    if not isinstance(ty, VectorTy) or ty.size is None or ty.size == len(arm):
        return None
    return Finding(fn.loc, Severity.ERROR,
                   f"inverse_kinematics is declared to return {ty}, but p-model {pmodel}'s arm from its base to "
                   f"the tool link {tool_link} has {len(arm)} moving joints ({', '.join(arm) or 'none'}): declare "
                   f"vector(real, {len(arm)}) and command every one of them, or, if the tool is another link (a "
                   f"gripper's joint is no arm joint), name it by [tool] link in the cell geometry ([platform] "
                   f"calibration, docs/calibration.md)")


def commanded_joints(model: MappingModel) -> dict[str, object]:
    """The joints the mapping's operations command (`P::L::J::ACT.port == e`), each with where its first such
    equation is, in the mapping's order."""
    out: dict[str, object] = {}
    for op in model.operations:
        for eq in op.equations:
            path = _actuator_port(eq)
            if path is not None:
                out.setdefault(path.split("::")[2], eq.left.base.loc)
    return out


def calls_inverse_kinematics(model: MappingModel) -> bool:
    """Does an operation of the mapping call `inverse_kinematics` (so that its values drive joints)?"""
    exprs = [e for op in model.operations for e in (*(v.init for v in op.variables if v.init is not None),
                                                    *op.equations, *(value for _, value, _ in op.actions))]
    return any(isinstance(node, s.Call) and isinstance(node.function, s.Name)
               and node.function.name.last == "inverse_kinematics" for e in exprs for node in s.walk(e))


def ik_arm_problem(model: MappingModel, tree, tool_link: str, arm: list[str]) -> Finding | None:
    """A mapping calling `inverse_kinematics` that commands joints of the p-model but none of the arm the IK
    solves for (base to `tool_link`): the values solved for one arm would drive another's joints (a robot of two
    arms, the IK's default tool the other arm's gripper), every move 'completing' with the tool elsewhere. An
    error at the first equation commanding a joint, naming both arms, or None."""
    if not arm or not calls_inverse_kinematics(model):
        return None
    actuated = {j.name for j in tree.actuated}
    commanded = {j: loc for j, loc in commanded_joints(model).items() if j in actuated}
    if not commanded or set(commanded) & set(arm):
        return None
    by_name = {j.name: j for j in tree.joints}
    parent_of = {j.child: j.parent for j in tree.joints}

    def depth(link: str) -> int:  # joints from the root to the link
        return 0 if link not in parent_of else 1 + depth(parent_of[link])

    turning = [j for j in commanded if by_name[j].kind in ("revolute", "continuous")] or list(commanded)
    last = max(turning, key=lambda j: depth(by_name[j].child))  # the commanded arm joint furthest from the base
    grippers = beyond(tree, last)
    suggestion = f"{grippers[0]} (the gripper {last} moves)" if grippers else \
        f"{by_name[last].child} (the link {last} moves) or a link fixed beyond it"
    return Finding(next(iter(commanded.values())), Severity.ERROR,
                   f"mapping {model.name} commands {', '.join(commanded)} of p-model {tree.name}, but "
                   f"inverse_kinematics solves for the arm from its base to the tool link {tool_link} "
                   f"({', '.join(arm)}), none of whose "
                   f"joints it commands: the values solved for one arm would move the other. Name the tool of the "
                   f"arm it commands by [tool] link in the cell geometry ([platform] calibration, "
                   f"docs/calibration.md), e.g. {suggestion}")


def ik_joints_left_out(model: MappingModel, tree, tool_link: str, arm: list[str]) -> Finding | None:
    """An operation calling `inverse_kinematics` that commands some of the IK's arm joints but not others: the IK
    solves with every joint of the arm, so a joint left where it is puts the tool off the target while the move
    'completes' (a 6-joint arm's operation reused on a 7-joint arm). A warning at the operation's first command,
    or None."""
    if not arm:
        return None
    for op in model.operations:
        exprs = [*(v.init for v in op.variables if v.init is not None), *op.equations,
                 *(value for _, value, _ in op.actions)]
        if not any(isinstance(node, s.Call) and isinstance(node.function, s.Name)
                   and node.function.name.last == "inverse_kinematics" for e in exprs for node in s.walk(e)):
            continue
        commanded: dict[str, object] = {}
        for eq in op.equations:
            path = _actuator_port(eq)
            if path is not None:
                commanded.setdefault(path.split("::")[2], eq.left.base.loc)
        missing = [j for j in arm if j not in commanded]
        if missing and len(missing) < len(arm):  # none commanded: stored for another operation, or ik_arm_problem's
            return Finding(next(iter(commanded.values())), Severity.WARNING,
                           f"operation {op.name} calls inverse_kinematics but does not command {', '.join(missing)} of "
                           f"the arm it solves for (p-model {tree.name}, base to the tool link {tool_link}: "
                           f"{', '.join(arm)}): a joint left where it is puts the tool off the target the IK reached")
    return None


class FunctionRegistry:
    """Implementations of functions the models leave abstract, bound to the platform's kinematics and
    the cell's geometry: `inverse_kinematics(x, y, z)` takes the point the mapping computes in the
    plate's (grid) frame, places it in the robot's frame and solves for the tool pose there (as much of it as
    the arm's joints fix: cotwin.pmodel.ik); `reachable` judges by the same."""

    def __init__(self, endpoint, geometry: CellGeometry | None = None):
        self.endpoint = endpoint
        self.tree = endpoint.tree
        self.geometry = geometry or endpoint.geometry or CellGeometry()
        self.tool = self.geometry.find_tool(self.tree)
        self.arm = ik.arm_joints(self.tree, self.tool)
        self.geometry.check_joints(self.arm)
        reference = dict(zip(self.arm, self.geometry.reference)) if self.geometry.reference is not None else None
        self.solver = ik.Solver(self.tree, self.tool, reference, self.geometry.joint_offsets)
        self._cache: dict[tuple, ik.IKResult] = {}
        self.stored = SolutionCache(self.solver.fingerprint())  # solutions of earlier runs, exact
        self.requests: list[tuple[float, float, float]] = []  # grid points asked of inverse_kinematics, in order
        self._told = False  # an arm of fewer than 6 joints is told once what the IK reaches for it

    def _solve(self, x, y, z) -> ik.IKResult:
        if not self.arm:
            raise CotwinError(f"inverse_kinematics: p-model {self.tree.name} has no moving joint from its base to the "
                              f"tool link {self.tool.link}: nothing to solve for (docs/new-robot.md)")
        if not self._told and self.solver.task != "pose":
            self._told = True
            ik_log.warning("inverse_kinematics: p-model %s's arm from its base to the tool link %s has %d moving joints "
                           "(%s): it reaches %s of the cell geometry's [tool] (docs/new-robot.md)", self.tree.name,
                           self.tool.link, len(self.arm), ", ".join(self.arm), ik.REACHES[self.solver.task])
        key = (round(float(x), 9), round(float(y), 9), round(float(z), 9))
        if key not in self._cache:
            geometry = self.geometry  # a grid point's target is the same run after run: its stored name kept
            target = (geometry.plate_xyz, geometry.plate_rpy, geometry.tool_rpy, key)
            name = _TARGETS.get(target)
            if name is None:
                if len(_TARGETS) >= 4096:
                    _TARGETS.clear()
                name = _TARGETS[target] = SolutionCache.key(geometry.target_pose(key).ravel())
            known = self.stored.get(name)
            if known is not None:
                self._cache[key] = ik.IKResult(**known)
            else:
                self._cache[key] = self.solver.branch(geometry.target_pose(key))
                found = self._cache[key]
                self.stored.put(name, {"q": {j: float(v) for j, v in found.q.items()},
                                       "position_error": float(found.position_error),
                                       "angle_error": float(found.angle_error), "iterations": int(found.iterations)})
        return self.solver.near(self._cache[key], self.endpoint.joint_positions())

    def inverse_kinematics(self, x, y, z):
        """Joint values (arm joints, kinematic order) putting the tool frame at grid point (x, y, z); an error for a
        point that is not finite (no posture puts the tool there: the solver's answer would be a posture anyway)."""
        if not all(math.isfinite(float(v)) for v in (x, y, z)):
            raise CotwinError(f"inverse_kinematics({float(x)!r}, {float(y)!r}, {float(z)!r}): the target is not a "
                              "finite point, so no posture reaches it (guard the call with reachable(x, y, z))")
        self.requests.append((float(x), float(y), float(z)))
        result = self._solve(x, y, z)
        return tuple(result.q[j] for j in self.arm)

    def reachable(self, x, y, z) -> bool:
        """Whether the tool frame can be put at grid point (x, y, z) (as the arm's task counts it); a point that is
        not finite (a range sensor seeing nothing reads inf) is not reachable."""
        if not all(math.isfinite(float(v)) for v in (x, y, z)):
            return False
        return self._solve(x, y, z).ok(position_tol=1e-3, angle_tol=1e-2)

    def functions(self) -> dict:
        return {"inverse_kinematics": self.inverse_kinematics, "reachable": self.reachable, **MATH}

    # ---- state: a target's solution is reused whenever it comes again, so the cache is state ----
    def snapshot(self) -> dict:
        return {key: {f.name: getattr(result, f.name) for f in fields(result)} for key, result in self._cache.items()}

    def restore(self, snapshot: dict) -> None:
        """The solutions a saved state holds, checked first: grid points of three finite numbers, each with
        a finite value for every arm joint (and only joints of this tree), errors and an iteration count."""
        of_type(snapshot, dict, "inverse kinematics solutions")
        names = [f.name for f in fields(ik.IKResult)]
        joints = {j.name for j in self.tree.joints}
        cache = {}
        for key, values in snapshot.items():
            if key.__class__ is not tuple or len(key) != 3:
                raise CotwinError(f"the saved state's inverse kinematics are keyed by a grid point, not {key!r:.60}")
            key = tuple(finite(v, "inverse kinematics grid point") for v in key)
            what = f"inverse kinematics solution at {key}"
            values = state_fields(values, what, names)
            q = of_type(values["q"], dict, f"{what}'s joints")
            if not set(self.arm) <= set(q) or not set(q) <= joints:
                raise CotwinError(f"the saved state's {what} is for joints {', '.join(map(str, q))[:200]}, not this "
                                  f"arm's {', '.join(self.arm)}")
            cache[key] = ik.IKResult(q={j: finite(v, f"{what}'s {j}") for j, v in q.items()},
                                     position_error=finite(values["position_error"], f"{what}'s position error", 0.0),
                                     angle_error=finite(values["angle_error"], f"{what}'s angle error", 0.0),
                                     iterations=count(values["iterations"], f"{what}'s iterations"))
        self._cache = cache


_TARGETS: dict[tuple, str] = {}  # (plate pose, tool orientation, grid point) -> its target's SolutionCache key


class _MappingNames:
    """How mapping expressions look names up: the operation's or event's local scope, then the
    mapping's variables; `E::lit` is an enumeration literal; a path `pmodel::link::sensor.port` is a
    sensor reading of the platform; functions come from the registry. Vectors index from 0 here, as
    cotwin's mapping notation has always read them (d-models follow RoboChart and count from 1)."""

    FIRST_INDEX = MAPPING_FIRST_INDEX  # the checker counts alike (cotwin.robosim.check_mapping)

    @staticmethod
    def sensor_key(e: s.FieldAccess) -> str | None:
        if isinstance(e.base, s.Name) and len(e.base.name.parts) >= 3:
            return f"{e.base.name}.{e.field}"
        return None


class _MappingEvaluator(Evaluator):
    """The interpreting form (the reference the compiled closures are compared with)."""

    def __init__(self, runtime: "Mapping", scope: dict):
        super().__init__()
        self.rt = runtime
        self.scope = scope

    def name(self, e: s.Name):
        if len(e.name.parts) > 1:
            return self.rt.enum_value(e.name)
        n = e.name.last
        if n in self.scope:
            return self.scope[n]
        if n in self.rt.variables:
            return self.rt.variables[n]
        raise CotwinError(f"{e.loc}: '{n}' has no value")

    def field(self, e: s.FieldAccess):
        key = _MappingNames.sensor_key(e)
        if key is not None:
            return self.rt.sensor(key, e.loc)
        return super().field(e)

    def function(self, e: s.Call):
        return self.rt.function(e)

    def first_index(self, e: s.IndexAccess) -> int:
        return _MappingNames.FIRST_INDEX


class _MappingCompiler(ClosureCompiler):
    """The compiled form: each expression becomes a closure over the scope dict, once."""

    def __init__(self, runtime: "Mapping"):
        self.rt = runtime

    def compile_name(self, e: s.Name):
        rt = self.rt
        if len(e.name.parts) > 1:
            value = rt.enum_value(e.name)
            return lambda scope: value
        n, loc = e.name.last, e.loc

        def run(scope):
            if n in scope:
                return scope[n]
            variables = rt.variables
            if n in variables:
                return variables[n]
            raise CotwinError(f"{loc}: '{n}' has no value")
        return run

    def compile_field(self, e: s.FieldAccess):
        key = _MappingNames.sensor_key(e)
        if key is None:
            return None
        rt, loc = self.rt, e.loc

        def run(scope):  # the step's readings read once per step (Mapping.sensor_readings), then a look-up
            readings = rt._readings
            if readings is None:
                readings = rt.sensor_readings()
            if key in readings:
                return readings[key]
            return rt.sensor(key, loc)  # a located error naming the missing sensor
        return run

    def compile_call(self, e: s.Call):
        rt, found = self.rt, []

        def run(scope):  # the registry's function looked up at its first call (an unknown one fails there)
            if found:
                return found[0]
            function = rt.function(e)
            found.append(function)
            return function
        return run

    def visit_IndexAccess(self, e: s.IndexAccess):
        base, position, loc = self.visit(e.base), self.visit(e.index), e.loc
        first = _MappingNames.FIRST_INDEX
        return lambda scope: index(base(scope), position(scope), loc, first)

    def fallback(self, scope) -> Evaluator:
        return _MappingEvaluator(self.rt, scope)


class _Env:
    """Evaluates mapping expressions: compiled to closures once (the default), or interpreted."""

    def __init__(self, runtime: "Mapping", compiled: bool = True):
        self.rt = runtime
        self.compiled = compiled
        self._closures: dict[int, object] = {}
        self._compiler = _MappingCompiler(runtime)

    def eval(self, e: s.Expr, scope: dict):
        try:
            if not self.compiled:
                return _MappingEvaluator(self.rt, scope).visit(e)
            run = self._closures.get(id(e))
            if run is None:
                run = self._closures[id(e)] = self._compiler.compile(e)
            return run(scope)
        except EvalError as err:
            raise CotwinError(f"{err.loc or e.loc}: {err.message}") from None
        except (TypeError, ValueError, AttributeError, KeyError, IndexError) as err:
            raise CotwinError(f"{e.loc}: the expression cannot be evaluated: {err}") from None


def _reads_only(condition: s.Expr, names: frozenset) -> bool:
    """Whether a condition reads plain variables, all of them among `names`, and no field, call or sensor."""
    found = [n for n in s.walk(condition) if isinstance(n, (s.Name, s.FieldAccess, s.Call, s.IndexAccess))]
    plain = [n for n in found if isinstance(n, s.Name) and len(n.name.parts) == 1]
    return bool(plain) and not any(isinstance(n, (s.FieldAccess, s.Call)) for n in found) and \
        all(n.name.last in names for n in plain)


class InputEvent:
    """An input event of the platform: occurs when all its equations hold; `e?x` with an equation
    `x == v` (or `v == x`) carries the value of v, and occurs only when that value is a measurement
    (a finite number, or a non-numeric value)."""

    def __init__(self, runtime: "Mapping", model):
        self.runtime = runtime
        self.model = model
        self.name = model.name
        self.definition: s.Expr | None = None  # v of `x == v`, x being the bound name
        conditions = []
        for eq in model.equations:
            value = _definition(eq, model.bind) if model.bind and self.definition is None else None
            if value is not None:
                self.definition = value
            else:
                conditions.append(eq)
        self.conditions = (*conditions, *model.predicates)
        if model.bind and self.definition is None:
            raise CotwinError(f"{model.loc}: input event {model.name} binds '{model.bind}' but no equation "
                              f"'{model.bind} == ...' says what its value is")
        self.value = None
        self._requests: dict[frozenset, list] = {}  # false_request_part's conditions, per set of names they may read
        local = {v.name for v in model.variables} | ({model.bind} if model.bind else set())
        expressions = [*model.equations, *model.predicates, *(v.init for v in model.variables if v.init is not None)]
        #: the mapping variables its definition reads (an answer when an operation assigns one of them)
        self.reads = frozenset(n.name.last for e in expressions for n in s.walk(e)
                               if isinstance(n, s.Name) and len(n.name.parts) == 1 and n.name.last not in local
                               and n.name.last in runtime.declared)

    def false_request_part(self, readable: frozenset[str]) -> s.Expr | None:
        """A condition of its definition that reads only `readable` names (the variables operations assign and
        constants), no sensor, function or local name, and is false now: then no motion of the platform makes
        the event occur, only an operation that assigns one of those variables (None if there is no such
        condition)."""
        candidates = self._requests.get(readable)
        if candidates is None:  # the conditions of that form, found once (the names are the model's), with the
            # variables each reads: its truth is a function of their values, kept per values (a wait judged at
            # every native stretch asks it again and again while no operation runs)
            candidates = self._requests[readable] = [
                (c, sorted({n.name.last for n in s.walk(c) if isinstance(n, s.Name) and len(n.name.parts) == 1}), {})
                for e in self.conditions for c in s.conjuncts(e) if _reads_only(c, readable)]
        variables = self.runtime.variables
        for condition, names, known in candidates:
            key = tuple((v.__class__, v) for v in map(variables.get, names))  # True and 1 are not one key
            try:
                true = known.get(key)
            except TypeError:  # a value that is no key (a vector): asked anew
                true = key = None
            if true is None:
                true = bool(self.runtime.env.eval(condition, {}))
                if key is not None and len(known) < 64:
                    known[key] = true
            if not true:
                return condition
        return None

    def occurs(self) -> bool:
        """Whether its definition holds now (the paper's `get_event`); `Mapping.report` says whether it
        occurs in the step."""
        env = self.runtime.env
        scope = {}
        for var in self.model.variables:
            if var.init is not None:
                scope[var.name] = env.eval(var.init, scope)
        if self.definition is not None:
            value = env.eval(self.definition, scope)
            if isinstance(value, float) and not math.isfinite(value):
                return False  # no measurement (a range sensor seeing nothing reports inf)
            scope[self.model.bind] = value
            self.value = value
            return all(bool(env.eval(c, scope)) for c in self.conditions)
        return bool(self.conditions) and all(bool(env.eval(c, scope)) for c in self.conditions)


def _source_text(expr: s.Expr, limit: int = 80) -> str:
    """An expression as written (from its line in the source file, to the line's end), for messages."""
    try:
        with open(expr.loc.path, encoding="utf-8") as f:
            line = f.read().splitlines()[expr.loc.line - 1]
    except (OSError, IndexError, UnicodeDecodeError):
        return "..."
    text = line[expr.loc.column - 1:].strip().rstrip("{").strip()
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _definition(eq: s.Expr, bind: str) -> s.Expr | None:
    """v when eq is `bind == v` or `v == bind`."""
    if not (isinstance(eq, s.Binary) and eq.op == "=="):
        return None
    for this, other in ((eq.left, eq.right), (eq.right, eq.left)):
        if isinstance(this, s.Name) and len(this.name.parts) == 1 and this.name.last == bind:
            return other
    return None


log = logging.getLogger("cotwin.twin")
LIMIT_SLACK = 1e-9  # a goal this far beyond a limit (rad or m) is the limit written another way, not beyond it
HOLD_SLACK = 1e-6  # a goal this near its joint's position (rad or m) holds the joint where it is


class Operation:
    """An operation of the platform: sets mapping variables and commands actuators."""

    def __init__(self, runtime: "Mapping", model, params: list[str]):
        self.runtime = runtime
        self.model = model
        self.name = model.name
        self.params = params
        self.commands: list[tuple[str, s.Expr]] = []
        self.constraints: list[s.Expr] = []
        self.where: dict[str, object] = {}  # actuator path -> the equation commanding it
        self.beyond_said: set[str] = set()  # actuator paths whose goal beyond the joint's limits was said
        for eq in model.equations:
            target = _actuator_port(eq)
            if target is not None:
                self.commands.append((target, eq.right))
                self.where[target] = eq.left.base.loc  # the actuator path, where the equation starts
            else:
                self.constraints.append(eq)

    def execute(self, args) -> None:
        rt = self.runtime
        if isinstance(args, dict):
            unknown = [k for k in args if k not in self.params]
            if unknown:
                raise CotwinError(f"operation {self.name}: unknown argument(s) {', '.join(unknown)}")
            scope = {p: args.get(p, 0) for p in self.params}
        else:
            args = list(args or ())
            if len(args) != len(self.params):
                raise CotwinError(f"operation {self.name} takes {len(self.params)} argument(s), got {len(args)}")
            scope = dict(zip(self.params, args))
        for var in self.model.variables:
            scope[var.name] = rt.env.eval(var.init, scope) if var.init is not None else 0
        for target, value, _ in self.model.actions:
            root = s.root_name(target)
            if not isinstance(target, s.Name) or root is None:
                raise CotwinError(f"{target.loc}: only mapping variables can be assigned by an action")
            if root.name.last not in rt.variables:
                raise CotwinError(f"{target.loc}: '{root.name}' is not a mapping variable")
            rt.variables[root.name.last] = rt.env.eval(value, scope)
            rt.asked.add(root.name.last)
        goals = {path: float(rt.env.eval(value, scope)) for path, value in self.commands}
        if goals:
            self._say_beyond_limits(goals)
            rt.endpoint.command(goals)

    def _say_beyond_limits(self, goals: dict[str, float]) -> None:
        """Warn (once per actuator) of a position goal outside its joint's limits: the simulated joint stops at
        the limit (a real controller refuses the goal), so an event waiting for the joint to get there never
        comes, and the run would only say that the command never completed. A goal where the joint already is
        (an operation holding the arm where it stands, its goal the joint's reading, which the simulated joint
        at its limit exceeds by a hair) is no such mistake: nothing is said of it."""
        rt = self.runtime
        where: dict[str, float] | None = None  # the joints' positions, read once and only for a goal beyond
        for path, goal in goals.items():
            if path in self.beyond_said or not math.isfinite(goal):
                continue
            joint = rt.joint_limits(path)
            if joint is None:
                continue
            name, lower, upper, unit = joint
            if (lower is not None and goal < lower - LIMIT_SLACK) or (upper is not None and goal > upper + LIMIT_SLACK):
                if where is None:
                    positions = getattr(rt.endpoint, "joint_positions", None)
                    where = positions() if positions is not None else {}
                if name in where and abs(goal - where[name]) <= HOLD_SLACK:
                    continue
                self.beyond_said.add(path)
                low = "-inf" if lower is None else f"{lower:g}"
                high = "inf" if upper is None else f"{upper:g}"
                stop = lower if lower is not None and goal < lower else upper
                log.warning("%s: warning: operation %s commands joint %s to %g %s, beyond its limits [%s, %s]: it "
                            "stops at %g, and an event waiting for it to get to %g never comes", self.where[path],
                            self.name, name, goal, unit, low, high, stop, goal)


def _actuator_port(eq: s.Expr) -> str | None:
    if isinstance(eq, s.Binary) and eq.op == "==" and isinstance(eq.left, s.FieldAccess) \
            and isinstance(eq.left.base, s.Name) and len(eq.left.base.name.parts) == 4:
        return f"{eq.left.base.name}.{eq.left.field}"
    return None


class Mapping:
    """The platform-mapping interface: one instance per mapping model and endpoint."""

    def __init__(self, project, endpoint, mapping_name: str | None = None, geometry=None, compiled: bool = True,
                 mirrors="arm", monitor: dict[str, str] | None = None):
        """`geometry` (a CellGeometry) places the cell for the IK registry, whatever the endpoint; without
        it the endpoint's own geometry is used, if it has one. `compiled=False` evaluates expressions
        with the interpreting evaluator instead of closures (the reference, for tests and benchmarks).
        `mirrors`: the joints the mapping's q<i>/qd<i> variables mirror (`mirrored_joints`); `monitor`:
        further monitored variables, name -> a platform reading's path (read after every step)."""
        mappings = project.elements(MappingModel)
        if mapping_name is not None:
            model = project.lookup("mapping", mapping_name)
        elif len(mappings) == 1:
            model = mappings[0]
        else:
            model = None
        if model is None:
            raise CotwinError("choose a mapping: " + ", ".join(m.name for m in mappings) if mappings else "no mapping model")
        self.project = project
        self.model = model
        self.endpoint = endpoint
        self.source = project.file_of(model)
        module, pmodel, members = mapping_targets(project, model, self.source)
        if members is None or pmodel is None:
            raise CotwinError(f"mapping {model.name}: its d-model module or p-model is missing")
        self.members = members
        self.pmodel = pmodel
        self.resolver = TypeResolver(project, self.source, Diagnostics())
        self._geometry = geometry
        self._registry: FunctionRegistry | None = None
        self.functions = {**MATH, "inverse_kinematics": self._kinematics("inverse_kinematics"),
                          "reachable": self._kinematics("reachable"), "robot_contact": self.robot_contact}
        self.env = _Env(self, compiled)
        self.declared = {v.name for v in model.variables}
        self.asked: set[str] = set()  # variables operations assigned since the last report
        self.held: dict[str, tuple[bool, object]] = {}  # event -> (held, value) at the last report
        self.pending: dict[str, object] = {}  # answers that came and wait for their step, in order -> value
        self.reports = 0  # steps reported
        self.delivered: dict[str, int] = {}  # answer -> the report that last delivered it
        self.events = {ev.name: InputEvent(self, ev) for ev in model.input_events}
        #: mapping variable -> the operations assigning it
        self.assigners: dict[str, list[str]] = {}
        for op in model.operations:
            for target, _, _ in op.actions:
                root = s.root_name(target)
                if root is not None and op.name not in self.assigners.setdefault(root.name.last, []):
                    self.assigners[root.name.last].append(op.name)
        #: answers: events reading a variable an operation assigns (see `report`)
        self.answers = {name for name, ev in self.events.items() if ev.reads & set(self.assigners)}
        #: what a request condition may read besides sensors: what operations assign, and the constants
        self._requestable = frozenset(self.assigners) | frozenset(v.name for v in model.variables if v.is_const)
        self.operations = {op.name: Operation(self, op, [p.name for p in members.operations[op.name].params])
                           for op in model.operations if op.name in members.operations}
        self.variables: dict[str, object] = {}
        self._readings: dict[str, float] | None = None
        names = [v.name for v in model.variables]
        if not declares_mirrors(names):
            joints = []
        elif mirrors == "arm":
            joints = self.registry.arm  # the arm the kinematics functions solve for (its tool from the geometry)
        else:
            joints = mirrored_joints(endpoint.tree, mirrors)
        self._mirrors = mirror_variables(names, joints)
        self._mirror_q = [(var, joint) for var, (joint, kind) in self._mirrors.items() if kind == "position"]
        self._mirror_qd = [(var, joint) for var, (joint, kind) in self._mirrors.items() if kind != "position"]
        self.monitor = dict(monitor or {})
        clash = [n for n in self.monitor if n in self._mirrors]
        if clash:
            raise CotwinError(f"monitored variable(s) {', '.join(clash)} already mirror joints")
        for path, _ in (c for op in self.operations.values() for c in op.commands):
            endpoint.joint(path)  # every commanded actuator exists on the endpoint
        if compiled:  # each event's whole definition as one generated function (cotwin.mapping.generated)
            from .generated import compile_event

            for ev in self.events.values():
                ev.occurs = compile_event(ev, self.env._compiler)
        self.started = False
        self._shape_cache: dict | None = None  # _shapes, worked out on first use
        self._limits: dict[str, tuple | None] = {}  # actuator path -> joint_limits, worked out on first use

    @property
    def registry(self) -> FunctionRegistry:
        """The arm's kinematics functions, set up on first use (a mapping that never calls them needs no arm)."""
        if self._registry is None:
            registry = FunctionRegistry(self.endpoint, self._geometry)
            self._check_kinematics_result(registry)
            self._registry = registry
        return self._registry

    def _check_kinematics_result(self, registry: FunctionRegistry) -> None:
        """`kinematics_result_problem` at run time: the last line of defence (cotwin check and load_models
        report it before, cotwin.twin.assembly.system)."""
        problem = kinematics_result_problem(self.project, self.model, registry.tree.name, registry.tool.link,
                                            registry.arm) or ik_arm_problem(self.model, registry.tree,
                                                                            registry.tool.link, registry.arm)
        if problem is not None:
            raise CotwinError([problem])

    def _kinematics(self, name: str):
        def call(*args):
            return getattr(self.registry, name)(*args)
        call.__name__ = name
        return call

    def robot_contact(self) -> bool:
        """`robot_contact()`: did the robot touch another robot of its world in the step just made
        (cotwin.pmodel.shared)? Always false for a robot alone in its world."""
        if not self.endpoint.senses_contacts:
            raise CotwinError(f"mapping {self.model.name} calls robot_contact(), which its platform "
                              f"({type(self.endpoint).__name__}) cannot tell")
        return bool(self.endpoint.robot_contacts())

    def sensor(self, key: str, loc):
        readings = self.sensor_readings()
        if key not in readings:
            raise CotwinError(f"{loc}: the platform does not provide sensor '{key}'")
        return readings[key]

    def function(self, call: s.Call):
        name = call.function.name.last if isinstance(call.function, s.Name) else "?"
        fn = self.functions.get(name)
        if fn is None:
            raise CotwinError(f"{call.loc}: function '{name}' has no implementation in cotwin's registry")
        return fn

    def enum_value(self, name: s.QName) -> int:
        decl = self.project.lookup("type", s.QName(name.parts[:-1]), self.source)
        if not isinstance(decl, EnumDecl) or decl.literal(name.last) is None:
            raise CotwinError(f"{name.loc}: unknown name '{name}'")
        return [lit.name for lit in decl.literals].index(name.last)

    # ---- the paper's API ----
    def start_mapping(self) -> None:
        self.endpoint.start()
        self.variables = {}
        for var in self.model.variables:
            ty, init = self.resolver.declared(var)
            if init is not None:
                self.variables[var.name] = self.env.eval(init, {})
            elif isinstance(ty, EnumTy):
                self.variables[var.name] = 0
            else:
                self.variables[var.name] = {"boolean": False, "real": 0.0}.get(str(ty), 0)
        self._sync()
        self.asked.clear()
        self.held.clear()
        self.pending.clear()
        self.delivered.clear()
        self.started = True

    def get_event(self, name: str, args=None) -> bool:
        if name not in self.events:
            raise CotwinError(f"mapping {self.model.name} has no input event '{name}'")
        return self.events[name].occurs()

    def report(self) -> dict[str, tuple[bool, object]]:
        """Which events occur in the step just made, with the value each carries (see the module doc):
        observations whenever their definition holds; an answer when it comes (comes to hold, is asked
        anew, or carries a new value), at most one answer per step, those that come together delivered
        in the following steps in the order they came. Called once per step, after `step`."""
        out: dict[str, tuple[bool, object]] = {}
        asked, came = [], []
        held, pending, requested, answers = self.held, self.pending, self.asked, self.answers
        nothing = (False, None)
        for name, ev in self.events.items():
            if ev.occurs():
                state = (True, ev.value)
            else:
                state = nothing
            if name in answers:
                before, old = held.get(name, nothing)
                again = not ev.reads.isdisjoint(requested)
                if again:  # asked anew: an occurrence still waiting is the previous request's answer
                    pending.pop(name, None)
                if state[0] and (again or not before or state[1] != old):
                    (asked if again else came).append((name, state[1]))
                out[name] = nothing
            else:
                out[name] = state
            held[name] = state
        requested.clear()
        for name, value in asked + came:  # caused by an operation at the step's start, then by the platform
            pending[name] = value
        self.reports += 1
        if pending:
            name = next(iter(pending))
            out[name] = (True, pending.pop(name))
            self.delivered[name] = self.reports
        return out

    def never(self, name: str) -> str | None:
        """Why the event never occurs (every condition of its definition the literal `false`), or None."""
        ev = self.events[name]
        if ev.conditions and all(isinstance(c, s.Literal) and c.value is False for c in ev.conditions):
            return f"the mapping defines it as never occurring ({ev.model.loc})"
        return None

    def cannot_come(self, name: str, read_after: int = 2) -> str | None:
        """Why the answer `name` cannot occur unless an operation runs (None if it may, or is no answer):
        a condition of it on what operations assign is false, or it holds still and occurred already, delivered
        `read_after` reports ago or more (the d-model has read it by then: two under FMI 2.0, the step after it
        also under Jacobi; none when asked just after a clocked d-model's tick, which read what came before)."""
        if name not in self.answers or name in self.pending:
            return None
        ev = self.events[name]
        false = ev.false_request_part(self._requestable)
        if false is not None:
            reads = sorted(n.name.last for n in s.walk(false) if isinstance(n, s.Name) and n.name.last in self.assigners)
            by = sorted({op for v in reads for op in self.assigners[v]})
            return (f"its condition `{_source_text(false)}` ({false.loc}) is false and only an operation "
                    f"({', '.join(by)}) changes {', '.join(reads)}")
        if self.held.get(name, (False, None))[0] and \
                self.reports - self.delivered.get(name, self.reports - read_after) >= read_after:
            return ("it holds still and occurred already: it occurs again only when it stops holding or an operation "
                    f"assigns {', '.join(sorted(ev.reads & set(self.assigners)))}")
        return None

    def stays_possible(self, name: str) -> bool:
        """Whether the answer `name` may come now and stays so over any steps made without an operation until
        it comes: it waits for no step (not pending), does not hold (it comes by coming to hold, so it cannot
        hold without having come) or is asked anew by an operation just run (then it comes at the next report if
        it holds), and no condition of it on what operations assign is false (those variables change only when
        an operation runs). `cannot_come` says None at each such step."""
        if name not in self.answers or name in self.pending:
            return False
        if self.held.get(name, (False, None))[0] and self.events[name].reads.isdisjoint(self.asked):
            return False
        return self.events[name].false_request_part(self._requestable) is None

    def event_value(self, name: str):
        """The value the event carried when it last occurred (None before, or for an event without one)."""
        if name not in self.events:
            raise CotwinError(f"mapping {self.model.name} has no input event '{name}'")
        return self.events[name].value

    def joint_limits(self, path: str) -> tuple[str, float | None, float | None, str] | None:
        """The joint an actuator path commands by position, with its limits and their unit (None: no such joint,
        one driven by speed or effort, or one without limits)."""
        cache = self._limits
        if path not in cache:
            from ..pmodel.tree import servo_mode

            name = self.endpoint.joint(path)
            joint = next((j for j in self.endpoint.tree.joints if j.name == name), None)
            positioned = joint is not None and servo_mode(joint) == "position" and \
                (joint.lower is not None or joint.upper is not None)
            cache[path] = (name, joint.lower, joint.upper, "m" if joint.kind == "prismatic" else "rad") \
                if positioned else None
        return cache[path]

    def execute_operation(self, name: str, args=None) -> None:
        if name not in self.operations:
            raise CotwinError(f"mapping {self.model.name} has no operation '{name}'")
        self.operations[name].execute(args or ())

    def stop_mapping(self) -> None:
        self.endpoint.stop()
        if self._registry is not None:
            self._registry.stored.save()
        self.started = False

    @property
    def mirrors(self) -> dict[str, tuple[str, str]]:
        """Mirrored variables: name -> (joint, "position" or "velocity"), in the order `monitored` lists them."""
        return dict(self._mirrors)

    def reported_elsewhere(self, reports: int, held: dict[str, bool], came: list[str],
                           earlier: tuple[str, int] | None = None) -> None:
        """`reports` steps made and reported by a native loop (cotwin.mapping.cstep) with nothing asked: the
        events that held at the last of them, the answers that came in it (the first delivered, the others
        waiting, in order), and `earlier`: an answer delivered alone in an earlier one (its name and the step
        counted from 1); the sensor readings and mirrored variables read again."""
        if earlier is not None:
            self.delivered[earlier[0]] = self.reports + earlier[1]
        if reports:
            self.asked.clear()  # the first report read what operations run before it asked
        self.reports += reports
        for name, occurs in held.items():
            self.held[name] = (True, self.events[name].value) if occurs else (False, None)
        if came:
            self.delivered[came[0]] = self.reports
            for name in came[1:]:
                self.pending[name] = self.events[name].value
        self._sync()

    # ---- time ----
    def step(self, dt: float) -> None:
        """Let the platform run for dt seconds, then refresh sensor readings and mirrored variables."""
        self.endpoint.advance(dt)
        self._sync()

    def _sync(self) -> None:
        self._readings = None
        if self._mirrors:
            variables = self.variables
            if self._mirror_q:
                q = self.endpoint.joint_positions()
                for var, joint in self._mirror_q:
                    variables[var] = q.get(joint, 0.0)
            if self._mirror_qd:
                velocities = self.endpoint.joint_velocities()
                for var, joint in self._mirror_qd:
                    variables[var] = velocities.get(joint, 0.0)
        if self.monitor:
            readings = self.sensor_readings()
            for var, path in self.monitor.items():
                if path not in readings:
                    raise CotwinError(f"monitored variable {var}: the platform has no reading '{path}' "
                                      f"(the nearest: {nearest_first(path, readings)})")
                self.variables[var] = readings[path]

    def sensor_readings(self) -> dict[str, float]:
        if self._readings is None:
            self._readings = self.endpoint.read_sensors()
        return self._readings

    @property
    def monitored(self) -> list[str]:
        """Mapping variables worth logging: the q/qd mirrors, in order, then the monitored readings."""
        return [*self._mirrors, *self.monitor]

    # ---- state (what-if forks and rollbacks) ----
    STATE_KEYS = ("variables", "started", "functions", "endpoint")  # of a snapshot
    OPTIONAL_STATE_KEYS = ("events", "held", "asked", "pending", "reports", "delivered")  # the answers' bookkeeping

    def snapshot(self) -> dict:
        """The runtime's state as plain data: its variables, whether it was started, the functions'
        cached solutions and the endpoint's state (an endpoint that cannot save one is an error)."""
        if not self.endpoint.saves_state:
            raise CotwinError(f"mapping {self.model.name}: its platform ({type(self.endpoint).__name__}) cannot save "
                              "its state, so the mapping cannot either")
        return {"variables": dict(self.variables), "started": self.started,
                "functions": self._registry.snapshot() if self._registry is not None else {},
                "events": {name: ev.value for name, ev in self.events.items()}, "endpoint": self.endpoint.snapshot(),
                "held": dict(self.held), "asked": sorted(self.asked), "pending": list(self.pending.items()),
                "reports": self.reports, "delivered": dict(self.delivered)}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked against this mapping first: its variables (each shaped as its
        declared type), its events, the functions' solutions and the platform's state. An event's value is
        checked by the unit that reads it (it knows the d-model's event types)."""
        what = f"mapping {self.model.name}"
        state_fields(snapshot, what, self.STATE_KEYS, self.OPTIONAL_STATE_KEYS)
        variables = like(snapshot["variables"], self._shapes(), f"{what}'s variables")
        started = of_type(snapshot["started"], bool, f"{what}'s started")
        events = of_type(snapshot.get("events", {}), dict, f"{what}'s events")
        unknown = [name for name in events if name not in self.events]
        if unknown:
            raise CotwinError(f"the saved state's {what} has events {', '.join(map(str, unknown))[:200]}, which it "
                              f"does not define")
        of_type(snapshot["functions"], dict, f"{what}'s function solutions")
        self.endpoint.restore(snapshot["endpoint"])
        if snapshot["functions"] or self._registry is not None:
            self.registry.restore(snapshot["functions"])
        held, asked, pending, reports, delivered = self._answers_state(snapshot, what)
        for name, value in events.items():
            self.events[name].value = value
        self.variables = dict(variables)
        self.held, self.asked, self.pending, self.reports, self.delivered = held, asked, pending, reports, delivered
        self.started = started
        self._readings = None

    def _answers_state(self, snapshot: dict, what: str) -> tuple:
        """The answers' bookkeeping of `report` in a snapshot, checked: events this mapping defines, answers
        among them where only answers may be, report counts that do not run ahead of `reports`."""
        reports = count(snapshot.get("reports", 0), f"{what}'s reports")
        held = {}
        for name, entry in of_type(snapshot.get("held", {}), dict, f"{what}'s held events").items():
            if name not in self.events or not isinstance(entry, (tuple, list)) or len(entry) != 2:
                raise CotwinError(f"the saved state's {what} holds {name!r:.60} as an event, which it does not "
                                  "define (or not as a pair of held and value)")
            held[name] = (of_type(entry[0], bool, f"{what}'s {name} held"), entry[1])
        asked = set(of_type(snapshot.get("asked", []), (list, tuple), f"{what}'s asked variables"))
        unknown = [v for v in asked if v not in self.variables and v not in self.assigners]
        if unknown:
            raise CotwinError(f"the saved state's {what} was asked about {', '.join(map(repr, unknown))[:200]}, "
                              "which no operation of it assigns")
        pending = {}
        for entry in of_type(snapshot.get("pending", []), (list, tuple), f"{what}'s pending answers"):
            if not isinstance(entry, (tuple, list)) or len(entry) != 2 or entry[0] not in self.answers:
                raise CotwinError(f"the saved state's {what} has a pending answer {entry!r:.60}, not one of its "
                                  f"answers ({', '.join(sorted(self.answers)) or 'none'})")
            pending[entry[0]] = entry[1]
        delivered = {}
        for name, at in of_type(snapshot.get("delivered", {}), dict, f"{what}'s delivered answers").items():
            if name not in self.answers:
                raise CotwinError(f"the saved state's {what} delivered {name!r:.60}, which is not one of its answers")
            delivered[name] = count(at, f"{what}'s report delivering {name}", reports)
        return held, asked, pending, reports, delivered

    def _shapes(self) -> dict:
        """Every variable's value shape (cotwin.plaindata.like): its declared type's default value, a number
        for the mirrors and the monitored readings; None (anything) where the type gives no shape. Worked out
        once per mapping (a sweep restores its fork's mapping per what-if)."""
        if self._shape_cache is None:
            self._shape_cache = self._work_out_shapes()
        return self._shape_cache

    def _work_out_shapes(self) -> dict:
        from ..dmodel.program import default_value
        from ..robosim.types import INT, NAT

        shapes: dict = {}
        for var in self.model.variables:
            ty, _ = self.resolver.declared(var)
            value = default_value(ty, self.resolver)
            shapes[var.name] = None if value == 0 and value.__class__ is int and ty not in (INT, NAT) \
                and not isinstance(ty, EnumTy) else value
        for name in (*self._mirrors, *self.monitor):
            shapes[name] = 0.0
        return shapes
