"""The TwinSystem: a twin project's co-simulation, derived once from its models and settings.

It names the units (a command source, the d-model FMU, the platform mapping), every connection
between them, the logged variables and the delayed units; `cotwin build` writes it as Maestro's
multimodel.json, `cotwin run` executes it, and the live runtime instantiates it twice (PT and DT),
so the three cannot disagree.

Connections come from the models alone: source -> d-model command events and their values; d-model
operation calls and arguments -> mapping; mapping platform events -> d-model (the mapping's outputs
are declared delayed, which breaks the d-model/mapping cycle under Gauss-Seidel); the mapping's
monitored variables -> the source, when the source echoes them (the RabbitMQ bridge, as Listing 5).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from ...config import did_you_mean
from ...cosim.isolated import DEFAULT_TIMEOUT
from ...cosim.system import Connection, System
from ...cosim.units import Unit
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...pmodel.ik import Tool
from ..project import TwinProject


@dataclass(frozen=True)
class MachinePort:
    """A d-model state machine as the twin's services see it: the unit and output port holding its state
    (the leaf state's index), the name it is recorded under (the machine's; `ROBOT.machine` in a cell) and
    its leaf states' names."""

    unit: str
    machine: str
    port: str
    leaves: tuple[str, ...]


@dataclass(frozen=True)
class CommandPorts:
    """A command source's ports as the twin's services record them: its event ports and the ports carrying
    the values, each with the name recorded (the port's; `ROBOT.port` in a cell)."""

    unit: str
    events: tuple[tuple[str, str], ...]  # (port, recorded name)
    values: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class UnitSpec:
    """One unit of the twin as Maestro names it: `{key}.instance`, from `fmu`; `role` says what it is."""

    key: str
    instance: str
    fmu: str
    role: str  # source | dmodel | mapping

    @property
    def name(self) -> str:
        return f"{self.key}.{self.instance}"


DMODEL = UnitSpec("{dmodel}", "dmodel", "dmodel.fmu", "dmodel")
MAPPING = UnitSpec("{mapping}", "mapping", "mapping.fmu", "mapping")
CONTROLLER = UnitSpec("{controller}", "controller", "controller.fmu", "source")
RABBITMQ = UnitSpec("{rabbitmq}", "rabbitmq", "rabbitmq.fmu", "source")


@dataclass
class TwinModels:
    """The checked models of a project and what is derived from them once."""

    project: object  # cotwin.robosim.project.Project
    program: object  # cotwin.dmodel.program.Program
    tree: object  # cotwin.pmodel.tree.KinematicTree
    mapping_model: object  # cotwin.robosim.pmodel_elements.Mapping
    scene: object | None
    monitored: list[str]
    calibration: object | None = None  # cotwin.twin.assembly.calibration.Calibration: [platform] calibration
    digests: dict[str, str] = field(default_factory=dict)  # model_digests: what a saved state names
    #: what `cotwin check` warns of in the models (their checker's and the p-model's tree's readings) and in the
    #: project against them, each once: `cotwin run` shows them as check does
    warnings: list[Finding] = field(default_factory=list)
    #: the mapping's variables mirroring joints -> (joint, "position" | "velocity"): q<i>/qd<i> on the joints
    #: [monitor] joints gives (by default the arm up to the cell geometry's [tool] link, as the mapping's IK takes
    #: it), found once here so that the log's units, the page's robot and the mapping agree
    mirrors: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: the arm's joints, from the base to the tool the cell geometry names ([tool] link, as the mapping's IK takes
    #: it; else cotwin.pmodel.ik.find_tool's default), in kinematic order: what a robot's log, its profile's joint
    #: order and a calibration count as the arm (a revolute jaw is no arm joint when the tool link is before it)
    arm: list[str] = field(default_factory=list)
    #: the arm's tool (its link, frame and fingers), found with `arm`; None where it could not be found (a robot
    #: without one)
    tool: Tool | None = None


def model_digests(spec: TwinProject, project) -> dict[str, str]:
    """What the DT is made from, by path relative to the project's folder (as in generated files): every
    model file, the calibration and the world file, each with the sha256 of its bytes; a saved state
    carries them, so that one restored into a DT of other models names the file that changed."""
    import hashlib
    import os

    root = spec.path.parent.resolve()
    files = [Path(f.path) for f in project.files if not str(f.path).startswith("<")]
    files += [p for p in (spec.calibration, spec.world_file) if p is not None]
    out = {}
    for path in dict.fromkeys(p.resolve() for p in files):
        out[Path(os.path.relpath(path, root)).as_posix()] = hashlib.sha256(path.read_bytes()).hexdigest()
    return dict(sorted(out.items()))


def multimodel(spec: TwinProject, units, connections, parameters: dict, log: dict, delayed, realtime: bool | None,
               cotwin: dict) -> dict:
    """Maestro's multimodel.json of a co-simulation (a twin's or a cell's); its `cotwin` key (which Maestro
    ignores) holds the delays, the algorithm and `cotwin`'s further settings."""
    wired: dict[str, list[str]] = {}
    for c in connections:
        wired.setdefault(f"{c.source}.{c.output}", []).append(f"{c.target}.{c.input}")
    return {
        "fmus": {u.key: u.fmu for u in units},
        "connections": wired,
        "parameters": {f"{unit}.{name}": value for unit, values in parameters.items() for name, value in values.items()},
        "logVariables": log,
        "algorithm": {"type": "fixed-step", "size": spec.step},
        "startTime": 0.0,
        "endTime": spec.end,
        "simulationProgramDelay": spec.realtime if realtime is None else realtime,
        "cotwin": {"delayed": sorted(delayed), "algorithm": spec.algorithm, **cotwin},
    }


def load_models(spec: TwinProject, plant: bool = False) -> TwinModels:
    """The checked models of a project, every problem found in them and in the project against them reported
    together. With `plant`, the project's [plant] is this robot's (a project of one robot, as TwinSystem
    loads it): the joints it names are checked too, so that `cotwin plant` reports them with the rest. A
    cell's robots share its [plant] (a joint named applies to the robots that have it), checked against
    them all by cotwin.pmodel.perturbation.perturbed_world."""
    from ...dmodel.program import build_program
    from ...mapping.runtime import (declares_mirrors, ik_arm_problem, ik_joints_left_out, kinematics_result_problem,
                                    mirror_variables, mirrored_joints, uses_kinematics)
    from ...pmodel.cell import CellGeometry
    from ...pmodel import ik
    from ...mapping.profile import profile_rays
    from ...pmodel.tree import build_tree
    from ...robosim.check import load_checked_warned
    from ...robosim.pmodel_elements import Mapping as MappingModel

    project, warnings = load_checked_warned(spec.model_files)
    program = build_program(project, spec.module)
    tree = build_tree(project, spec.pmodel_name, spec.stand_ins, profile_rays(spec.profile))  # the robot's scanner
    warnings += tree_warnings(tree)
    problems: list[Finding] = []  # the checks below report together (with the plan's, see the end)
    if plant:  # a project's problem for every command, as [plant]'s types are (cotwin plant applies it)
        problems += spec.plant_problems(tree)
    unused = sorted(set(spec.stand_ins) - tree.stood_in)
    if unused:
        problems.append(Finding(spec.location("platform", "stand_in"), Severity.ERROR,
                                f"[[platform.stand_in]] for {', '.join(unused)}: p-model {tree.name} names no such "
                                "mesh that cannot be read"))
    mappings = project.elements(MappingModel)
    if len(mappings) != 1:
        raise CotwinError([Finding(Location(str(spec.mapping), 1, 1), Severity.ERROR,
                                   f"a twin needs exactly one mapping, found {len(mappings)}")])
    mapping = mappings[0]
    calibration = None
    if spec.calibration is not None:
        from .calibration import Calibration

        calibration = _gather(problems, lambda: Calibration.read(spec.calibration), None)
    scene = _gather(problems, lambda: build_scene(spec, mapping, calibration), None)
    variables = [v.name for v in mapping.variables]
    # the arm: from the base to the tool the cell geometry names (the calibration's, else the scene's: its [tool] link),
    # as the mapping's IK takes it (cotwin.mapping.runtime.FunctionRegistry); found once, for every use below
    geometry = calibration.geometry if calibration is not None else scene.geometry if scene is not None else None
    geometry = geometry or CellGeometry()
    tool = _gather(problems, lambda: geometry.find_tool(tree), None)
    arm = ik.arm_joints(tree, tool) if tool is not None else []
    if calibration is not None and tool is not None:  # it names this arm's joints
        _gather(problems, lambda: calibration.geometry.check_joints(arm), None)
    if tool is not None and (uses_kinematics(mapping) or declares_mirrors(variables) and spec.mirror_joints == "arm"):
        problem = kinematics_result_problem(project, mapping, tree.name, tool.link, arm)  # as a run sets up its IK
        if problem is not None:
            problems.append(problem)
    if tool is not None:  # the IK's arm is the one the mapping drives (a robot of two arms: the other's gripper)
        problem = ik_arm_problem(mapping, tree, tool.link, arm)
        if problem is not None:
            problems.append(problem)
        left_out = ik_joints_left_out(mapping, tree, tool.link, arm)
        if left_out is not None:
            warnings.append(left_out)
    actuated = [j.name for j in tree.actuated]
    unknown = [j for j in spec.mirror_joints if j not in actuated] if isinstance(spec.mirror_joints, list) else []
    if unknown:  # said at the key, with the nearest joint
        problems.append(Finding(spec.location("monitor", "joints"), Severity.ERROR,
                                f"[monitor] joints: {', '.join(unknown)} "
                                f"{'is not an actuated joint' if len(unknown) == 1 else 'are not actuated joints'} of p-model "
                                f"{tree.name}{did_you_mean(unknown[0], actuated)} (joints: {', '.join(actuated)})"))
    tool_link = geometry.tool_link or None  # the mapping's arm
    listed = not unknown and tool is not None  # a tool link the p-model lacks is said above, at its key
    joints = mirrored_joints(tree, spec.mirror_joints, tool_link=tool_link) \
        if declares_mirrors(variables) and listed else []
    mirrors = mirror_variables(variables, joints)
    problems += reading_clashes(spec, taken_names(program, mapping, [*variables, *mirrors]))
    problems += reading_path_problems(spec, tree)
    problems += outcome_event_problems(spec, program)
    own = mirror_warnings(spec, mapping, tree, joints, tool_link) if listed else []  # the project's against the models
    warnings += own
    warnings += [w for w in [free_base_arm_warning(spec, tree, arm)] if w is not None]
    if problems:
        if spec.plan is not None:  # its problems too, not in a round of their own once these are fixed
            from .scenario import read_scenario

            _gather(problems, lambda: read_scenario(spec.plan, program), None)
        raise CotwinError(problems + own)
    monitored = [*mirrors, *spec.readings]
    return TwinModels(project, program, tree, mapping, scene, monitored, calibration, model_digests(spec, project),
                      list(dict.fromkeys(warnings)), mirrors, arm, tool)


def outcome_event_problems(spec: TwinProject, program) -> list[Finding]:
    """[outcomes] names that are no input event of the d-model: an error at the key with the nearest event (a name
    misspelt would leave every command of that role judged as if it had none), or, for one of its output events
    (which only the d-model sends), what to do instead."""
    events = [ev.name for ev in program.inputs]
    sent = {ev.name for ev in program.outputs}
    out = []
    for role, named in spec.outcome_events.items():
        for event in (e for e in named if e in sent and e not in events):  # said as a step to take
            out.append(Finding(spec.location("outcomes", role), Severity.ERROR,
                               f"[outcomes] {role}: {event} is an output event of d-model module "
                               f"{program.module.name}: the d-model sends it, the platform never does, so it "
                               f"answers no command; remove it from [outcomes] {role} or name an input event "
                               f"(its input events: {', '.join(events)})"))
        unknown = [e for e in named if e not in events and e not in sent]
        if unknown:
            what = "is not an input event" if len(unknown) == 1 else "are not input events"
            out.append(Finding(spec.location("outcomes", role), Severity.ERROR,
                               f"[outcomes] {role}: {', '.join(unknown)} {what} "
                               f"of d-model module {program.module.name}{did_you_mean(unknown[0], events)} "
                               f"(its input events: {', '.join(events)})"))
    out += outcome_role_clashes(spec)
    return out


def outcome_role_clashes(spec: TwinProject) -> list[Finding]:
    """[outcomes] events named in two roles: an error at the later key (an event both infeasible and feasible was
    judged infeasible in silence, whatever the project meant)."""
    out, seen = [], {}
    for role, named in spec.outcome_events.items():
        for event in named:
            if event in seen:
                out.append(Finding(spec.location("outcomes", role), Severity.ERROR,
                                   f"[outcomes] {role}: {event} is already named in [outcomes] {seen[event]}: "
                                   f"an event has one role (name it in one list)"))
            else:
                seen[event] = role
    return out


def reading_path_problems(spec: TwinProject, tree) -> list[Finding]:
    """[monitor] readings whose path is no reading of the p-model (cotwin.pmodel.mjcf.reading_paths: its sensor
    ports, a free base's pose): an error at each one's key with the nearest paths, found before the run (whose
    first step said it with every path of the platform and no place)."""
    from ...config import nearest_first
    from ...pmodel.mjcf import pose_paths, reading_paths

    if not spec.readings:
        return []
    known = reading_paths(tree, free_base=spec.base == "free")
    pose = set(pose_paths(tree))
    return [Finding(spec.location("monitor", "readings", name), Severity.ERROR,
                    f"[monitor] readings {name}: " + (
                        f"'{path}' is the pose of a free base, and p-model {tree.name}'s is fixed: set [platform] "
                        f"base = \"free\" (a mobile robot) or read a sensor (the nearest: "
                        if path in pose else f"p-model {tree.name} has no reading '{path}' (the nearest: ") +
                    f"{nearest_first(path, known - pose)})")
            for name, path in spec.readings.items() if path not in known]


def mirror_warnings(spec: TwinProject, mapping, tree, joints: list[str], tool_link: str | None = None) -> list[Finding]:
    """Joints that would silently show nothing: `[monitor] joints` written for a mapping that declares no q<i>/qd<i>
    (nothing mirrors them, so nothing of them is logged or compared), or a q<i>/qd<i> past the mirrored joints
    (`joints`, cotwin.mapping.runtime.mirrored_joints) that no operation assigns: neither set nor logged. Each
    one warning, at the key or at the first such variable. `tool_link`: the cell geometry's [tool] link (the arm's end)."""
    from ...mapping.runtime import MIRROR_PREFIXES, declares_mirrors, mirror_variables, mirrored_joints
    from ...robosim import syntax as s

    variables = [v.name for v in mapping.variables]
    if not declares_mirrors(variables):
        if ("monitor", "joints") not in spec.locations:
            return []
        try:
            named = mirrored_joints(tree, spec.mirror_joints, tool_link=tool_link)
        except CotwinError:  # an arm without a tool: the joints cannot be listed
            named = []
        which = f" ({', '.join(named)})" if named else ""
        first = "var " + (", ".join(f"q{i}: real" for i in range(max(len(named), 1))) if len(named) <= 3 else
                          f"q0: real, ..., q{len(named) - 1}: real")
        return [Finding(spec.location("monitor", "joints"), Severity.WARNING,
                        f"[monitor] joints: mapping {mapping.name} declares no variable q0, q1, ... (positions) or "
                        f"qd0, qd1, ... (velocities), so no joint{which} is mirrored, logged or compared: declare "
                        f"`{first}` in the mapping (q<i> the i-th joint [monitor] joints gives, qd<i> its "
                        f"velocity) or remove [monitor] joints")]
    mirrored = mirror_variables(variables, joints)
    assigned = {root.name.last for op in mapping.operations for target, _, _ in op.actions
                for root in [s.root_name(target)] if root is not None}
    idle = [v for v in mapping.variables if v.name not in mirrored and v.name not in assigned
            and any(v.name.startswith(p) and v.name[len(p):].isdigit() for p, _ in MIRROR_PREFIXES)]
    if not idle:
        return []
    said = "[monitor] joints gives" if ("monitor", "joints") in spec.locations else \
        "[monitor] joints (by default the arm's) gives"
    count = len(joints)
    return [Finding(idle[0].loc, Severity.WARNING,
                    f"mapping variable(s) {', '.join(v.name for v in idle)} mirror no joint: {said} {count} of p-model "
                    f"{tree.name}'s ({', '.join(joints) or 'none'}), one per q<i> and qd<i> from 0; these are "
                    f"neither set nor logged: remove them or name more joints in [monitor] joints")]


def free_base_arm_warning(spec: TwinProject, tree, arm: list[str]) -> Finding | None:
    """An arm on a free base (a mobile manipulator: TIAGo) is not weight-compensated as a fixed arm is
    (cotwin.pmodel.mjcf): MuJoCo's gravcomp pushes a body up through every joint above it, the free base's too, so it
    would lift the whole robot by its arm's weight; compensating the arm's joints alone takes their gravity torques
    anew at every physics step. Said at [platform] base, naming the robot and its arm; None for a fixed base or a
    free one without an arm (a wheeled or legged base: fewer than ik.ARM_JOINTS joints to its tool)."""
    from ...pmodel import ik

    if spec.base != "free" or len(arm) < ik.ARM_JOINTS:
        return None
    return Finding(spec.location("platform", "base"), Severity.WARNING,
                   f"p-model {tree.name} is a free-base mobile arm: its arm ({', '.join(arm)}) is not weight-compensated "
                   "as an arm on a fixed base is (MuJoCo's gravity compensation would also lift the free base by the "
                   "arm's weight); its servos carry the weight, so a joint sags by its load over its servo's stiffness "
                   "and a move may never come within the mapping's tolerance: give those joints stiffer servos (Kp on "
                   "their ServoMotor, docs/pmodel-notation.md) or a looser tolerance")


def tree_warnings(tree) -> list[Finding]:
    """The warnings a simulator's reading of a p-model gives (cotwin.pmodel.tree_build: a joint's zero position
    outside its limits, an impossible inertia replaced...) that name a place in the project's files."""
    return [f for f in tree.findings if f.severity is Severity.WARNING and not f.location.path.startswith("<")]


def taken_names(program, mapping, variables: list[str]) -> dict[str, tuple[str, str]]:
    """The names a [monitor] reading cannot have, each with the kind of clash and what already has it: a
    reading is a monitored variable of the mapping and an output of the mapping's unit, so neither one of the
    mapping's `variables` (q<i>/qd<i> mirrors included) nor a port of that unit (a d-model operation, an
    argument port of one, a mapping event: a reading `z` beside goto(x, y, z) would be wired twice). A variable
    is said before a port of the same name, an event before an argument before an operation."""
    taken = {op.name: ("port", f"operation {op.name}") for op in program.operations}
    taken.update({port: ("port", f"an argument of operation {op.name}") for op in program.operations
                  for args in op.arg_ports for port, _ in args})
    taken.update({ev.name: ("port", f"event {ev.name}") for ev in mapping.input_events})
    taken.update({name: ("variable", f"variable {name}") for name in variables})
    return taken


def reading_clashes(spec: TwinProject, taken: dict[str, tuple[str, str]]) -> list[Finding]:
    """[monitor] readings named like something `taken` (taken_names): one error per kind of clash, at the key
    of its first reading."""
    clashes: dict[str, list[str]] = {}
    for name in spec.readings:
        if name in taken:
            clashes.setdefault(taken[name][0], []).append(name)
    out = []
    for kind, names in clashes.items():
        if kind == "variable":
            message = f"[monitor] readings {', '.join(names)}: the mapping has variables of these names"
        else:
            message = ("[monitor] readings " + ", ".join(f"{n} (already {taken[n][1]})" for n in names) +
                       ": each reading needs a name of its own (e.g. " + repr(f"{names[0]}_reading") + ")")
        out.append(Finding(spec.location("monitor", "readings", names[0]), Severity.ERROR, message))
    return out


def build_scene(spec: TwinProject, mapping, calibration=None):
    """The scene around the robot: the kind `[platform] scene` names (cotwin.pmodel.scenes, "auto": the
    world if the project gives one, else a registered kind that fits the mapping, else a floor under a free
    base, else none), built from
    the mapping, the `[scene]` table and the calibrated cell geometry."""
    from ...pmodel import scenes

    request = scenes.SceneRequest(mapping, dict(spec.scene_options), calibration.geometry if calibration else None,
                                  spec.world, spec.path.parent, spec.location, free_base=spec.base == "free")
    kind = scenes.choose_kind(spec.scene, request, spec.location("platform", "scene"))
    if spec.world is not None and kind.name != "world":
        what, at = ("[platform] world", spec.location("platform", "world")) if spec.world_file else \
            ("[world]", spec.location("world"))
        raise CotwinError([Finding(at, Severity.ERROR, f"{what}: the scene is '{kind.name}' ([platform] scene = "
                                   f"\"{spec.scene}\"), which would ignore it")])
    return scenes.build_scene(kind.name, request)


def external_events(program, mapping_model) -> list[str]:
    """The d-model input events that come from outside the platform: those the mapping does not define,
    or defines as never occurring (every condition the literal `false`)."""
    from ...robosim import syntax as s

    def never(ev) -> bool:
        conditions = (*ev.equations, *ev.predicates)
        return bool(conditions) and all(isinstance(c, s.Literal) and c.value is False for c in conditions)

    defined = {ev.name: ev for ev in mapping_model.input_events}
    return [ev.name for ev in program.inputs if ev.name not in defined or never(defined[ev.name])]


def _gather(problems: list[Finding], make, fallback):
    """`make()`, or `fallback` with its error's findings added to `problems` (reported with the others)."""
    try:
        return make()
    except CotwinError as err:
        problems.extend(err.findings)
        return fallback


class TwinSystem:
    """Units, connections, logged variables and delayed units of a twin project (see module doc)."""

    def __init__(self, spec: TwinProject, models: TwinModels | None = None, commands=None):
        """`commands` (a list of scenario Commands) replaces the project's source of commands with that
        plan over every port a live source carries (what-if forks and sweeps)."""
        from ...dmodel.ports import PortLayout
        from .mapping_unit import mapping_ports
        from .scenario import read_scenario, scenario_ports

        self.spec = spec
        self.models = models or load_models(spec, plant=True)  # a cell gives its robots' models
        program = self.models.program
        mapped = {ev.name for ev in self.models.mapping_model.input_events}
        command_ports = scenario_ports(program)
        problems: list[Finding] = []  # the plan's, the log's, the parameters' and the panels': reported together
        if commands is not None:
            self.commands = list(commands)
            used = {p for c in self.commands for p, _ in c.values}
            self.source_ports = list(dict.fromkeys([*self.live_ports(), *(p for p in command_ports if p in used)]))
            self.source = CONTROLLER
        elif spec.plan is not None:
            self.commands = _gather(problems, lambda: read_scenario(spec.plan, program), [])
            used = {p for c in self.commands for p, _ in c.values}
            self.source_ports = [p for p in command_ports if p in used]
            self.source = CONTROLLER
        elif spec.rabbitmq is not None:
            self.commands = []
            self.source_ports = self.live_ports()
            self.source = RABBITMQ
        else:  # an autonomous robot: no commands from outside
            self.commands = []
            self.source_ports = []
            self.source = None
        self.command_events = set(self.source_ports) & {ev.name for ev in program.inputs}
        self.units = [u for u in (self.source, DMODEL, MAPPING) if u is not None]
        layout = PortLayout(program)
        dmodel_inputs = {v.name for v in layout.variables if v.causality == "input"}
        connections = []
        if self.source is not None:
            connections += [Connection(self.source.name, p, DMODEL.name, p) for p in self.source_ports]
        for port in mapping_ports(program, mapped, self.command_events, self.models.monitored):
            if port.causality == "input":
                connections.append(Connection(DMODEL.name, port.name, MAPPING.name, port.name))
            elif port.name in dmodel_inputs:
                connections.append(Connection(MAPPING.name, port.name, DMODEL.name, port.name))
        if self.source is RABBITMQ:  # the bridge publishes the monitored variables back (Listing 5)
            connections += [Connection(MAPPING.name, v, RABBITMQ.name, v) for v in self.models.monitored]
        self.connections = connections
        inputs = {ev.name for ev in program.inputs}
        # the d-model's input events the mapping raises (the platform's answers and observations), in connection order
        self.platform_events = [c.output for c in connections if c.source == MAPPING.name and c.target == DMODEL.name
                                and c.output in inputs]
        self.delayed = {MAPPING.name}
        self.log = _gather(problems, self._log_variables, None)
        shown = not problems  # the panels are checked against what a run shows: the plan's ports, the log
        self.parameters = _gather(problems, lambda: self._parameters(layout), {})
        if shown:
            _gather(problems, self._check_panels, None)
        if problems:
            raise CotwinError(problems)

    @property
    def warnings(self) -> list[Finding]:
        """What the twin's models and the project against them warn of (TwinModels.warnings)."""
        return self.models.warnings

    def with_plan(self, commands) -> "TwinSystem":
        """This twin with `commands` as its source (the same models, derived once)."""
        return TwinSystem(self.spec, self.models, commands)

    @property
    def seed_port(self) -> str | None:
        """The d-model FMU's parameter seeding its random source (uninterpreted functions, random()), if any."""
        return next((p.port for p in self.models.program.parameters if p.machine < 0), None)

    def with_seed(self, seed: int) -> "TwinSystem":
        """This twin with another seed of its d-model's random source (another random walk)."""
        if self.seed_port is None:
            raise CotwinError(f"{self.spec.path}: the d-model draws no random values: it has no seed")
        return self.with_parameters(**{self.seed_port: int(seed)})

    def with_parameters(self, **values) -> "TwinSystem":
        """This twin with d-model parameters set (e.g. `seed=3`: another random walk), the same models."""
        spec = replace(self.spec, parameters={**self.spec.parameters, **values})
        plan = self.commands if self.source is CONTROLLER and self.spec.plan is None else None  # a what-if's
        return TwinSystem(spec, self.models, plan)

    def in_world(self, world) -> "TwinSystem":
        """This twin's models in another world (cotwin.pmodel.world.World), everything else the same."""
        spec = replace(self.spec, world=world, world_file=None, scene="world",
                       raw={**self.spec.raw, "world": world.table})
        return TwinSystem(spec, replace(self.models, scene=world))

    def live_ports(self) -> list[str]:
        """The ports a live (RabbitMQ) source carries: the events of `[scenario] rabbitmq commands` (default:
        the d-model inputs the mapping does not produce) and their value ports."""
        program, spec = self.models.program, self.spec
        names = spec.rabbitmq.commands if spec.rabbitmq is not None and spec.rabbitmq.commands is not None else \
            external_events(program, self.models.mapping_model)
        unknown = [n for n in names if n not in {ev.name for ev in program.inputs}]
        if unknown:
            raise CotwinError([Finding(spec.location("scenario", "rabbitmq", "commands"), Severity.ERROR,
                                       f"[scenario] rabbitmq commands: {', '.join(unknown)} are not input events "
                                       f"of the d-model{did_you_mean(unknown[0], [ev.name for ev in program.inputs])} "
                                       f"(it has {', '.join(ev.name for ev in program.inputs)})")])
        return [p for ev in program.inputs if ev.name in names for p in [ev.name, *(port for port, _ in ev.value_ports)]]

    def _log_variables(self) -> dict[str, list[str]]:
        monitored = self.models.monitored
        names = self.spec.log if self.spec.log is not None else monitored
        unknown = [n for n in names if n not in monitored]
        if unknown:
            raise CotwinError([Finding(self.spec.location("cosim", "log"), Severity.ERROR,
                                       f"[cosim] log: unknown mapping variable(s) {', '.join(unknown)}"
                                       f"{did_you_mean(unknown[0], monitored)} "
                                       f"(monitored: {', '.join(monitored) or 'none'})")])
        program = self.models.program
        return {MAPPING.name: list(names), DMODEL.name: [program.state_port(m) for m in program.machines]}

    def _parameters(self, layout) -> dict[str, dict[str, object]]:
        """[cosim] parameters: values of the d-model FMU's parameters (its random seed, constants without a
        value), checked against its ports."""
        given = self.spec.parameters
        if not given:
            return {}
        ports = {v.name: v for v in layout.variables if v.causality == "parameter"}
        problems = []
        for name, value in given.items():
            port = ports.get(name)
            at = self.spec.location("cosim", "parameters", name)
            if port is None:
                problems.append(Finding(at, Severity.ERROR, f"[cosim] parameters: the d-model has no parameter "
                                                            f"'{name}'{did_you_mean(name, ports)} "
                                                            f"(it has {', '.join(ports) or 'none'})"))
            elif port.fmi_type == "Boolean" and not isinstance(value, bool) or \
                    port.fmi_type == "Integer" and (isinstance(value, bool) or not isinstance(value, int)) or \
                    port.fmi_type == "Real" and (isinstance(value, bool) or not isinstance(value, (int, float))):
                problems.append(Finding(at, Severity.ERROR, f"[cosim] parameters: {name} takes "
                                        f"a{'n' if port.fmi_type[0] in 'I' else ''} {port.fmi_type}, not {value!r}"))
            elif port.fmi_type == "Integer" and not -2 ** 31 <= value < 2 ** 31:
                problems.append(Finding(at, Severity.ERROR, f"[cosim] parameters: {name} is an FMI Integer "
                                        f"(32 bits): {value} is out of its range"))
        if problems:
            raise CotwinError(problems)
        return {DMODEL.name: {name: (float(v) if ports[name].fmi_type == "Real" else v) for name, v in given.items()}}

    def columns(self) -> dict[str, set[str]]:
        """The variables each unit shows in a result (its connected outputs and logged variables)."""
        out: dict[str, set[str]] = {u.name: set() for u in self.units}
        for c in self.connections:
            out[c.source].add(c.output)
        for unit, names in self.log.items():
            out[unit].update(names)
        return out

    def _check_panels(self) -> None:
        """[figure] panels name variables a run shows (unit role or instance . variable), else an error
        at the panel: a misspelt name would draw an empty panel."""
        if self.spec.panels is None:
            return
        units = {u.role: u.name for u in self.units} | {u.instance: u.name for u in self.units}
        columns = self.columns()
        problems = []
        for i, (_, names, _) in enumerate(self.spec.panels):
            for name in names:
                unit, variable = name.split(".")
                if unit not in units:
                    message = f"unit '{unit}' is not one of this twin's{did_you_mean(unit, units)} ({', '.join(units)})"
                elif variable not in columns[units[unit]]:
                    message = (f"{unit} shows no variable '{variable}'{did_you_mean(variable, sorted(columns[units[unit]]))} "
                               f"(it shows "
                               f"{', '.join(sorted(columns[units[unit]])) or 'none'})")
                else:
                    continue
                problems.append(Finding(self.spec.location("figure", "panels", i, "variables"), Severity.ERROR,
                                        f"[figure] panel {i + 1} variable {name!r}: {message}"))
        if problems:
            raise CotwinError(problems)

    # ---- descriptions ----
    def state_machines(self) -> list[MachinePort]:
        """Every state machine of the d-model, where its state is read (the history and the page record them)."""
        program = self.models.program
        return [MachinePort(DMODEL.name, m.name, program.state_port(m), tuple(program.leaf_names(m)))
                for m in program.machines]

    def command_ports(self) -> list[CommandPorts]:
        """The command source's ports (none for an autonomous robot): what the history records of each command."""
        if self.source is None:
            return []
        return [CommandPorts(self.source.name, tuple((p, p) for p in self.source_ports if p in self.command_events),
                             tuple((p, p) for p in self.source_ports if p not in self.command_events))]

    def multimodel(self, realtime: bool | None = None) -> dict:
        """Maestro's multimodel.json; the `cotwin` key (which Maestro ignores) holds the delays."""
        extra = {**({"isolate": {DMODEL.name: self.isolated}} if self.isolated else {}),
                 **({"unit_timeout": self.spec.unit_timeout} if self.spec.unit_timeout != DEFAULT_TIMEOUT else {})}
        return multimodel(self.spec, self.units, self.connections, self.parameters, self.log, self.delayed,
                          realtime, extra)

    @property
    def isolated(self) -> bool:
        """Whether the d-model FMU runs in a process of its own: [cosim] isolate, else when cotwin did not
        build it ([models] fmu)."""
        return self.spec.isolate if self.spec.isolate is not None else self.spec.fmu is not None

    # ---- instances ----
    def mapping_unit(self, endpoint) -> Unit:
        """The platform mapping against `endpoint`, or against what `endpoint()` returns when the unit is
        instantiated (a function: describing the unit then never connects to the robot)."""
        from ...mapping.runtime import Mapping
        from .mapping_unit import MappingUnit

        models = self.models
        geometry = models.calibration.geometry if models.calibration is not None else None  # any endpoint's IK
        options = {"geometry": geometry, "mirrors": self.spec.mirror_joints, "monitor": self.spec.readings}
        if callable(endpoint):
            return MappingUnit(MAPPING.name, models.program, lambda: Mapping(models.project, endpoint(), **options),
                               self.command_events, {ev.name for ev in models.mapping_model.input_events},
                               models.monitored)
        return MappingUnit(MAPPING.name, models.program, Mapping(models.project, endpoint, **options),
                           self.command_events)

    def source_unit(self, bridge=None, stream=None, echo: bool = True) -> Unit | None:
        """The command source: the scenario's controller, or the RabbitMQ unit reading from `bridge`
        and `stream` (made from the project's settings when not given; a live twin shares one of each
        between its PT and DT, so both get every command in the same step)."""
        from .scenario import ScenarioUnit

        if self.source is CONTROLLER:
            return ScenarioUnit(CONTROLLER.name, self.models.program, self.commands, self.source_ports)
        if self.source is RABBITMQ:
            from .rabbitmq import RabbitMQUnit, port_arguments, port_scalars, port_types

            program = self.models.program
            return RabbitMQUnit(RABBITMQ.name, port_types(program, self.source_ports), self.models.monitored,
                                self.spec.rabbitmq, bridge=bridge, stream=stream, events=self.command_events, echo=echo,
                                scalars=port_scalars(program), arguments=port_arguments(program))
        return None

    def instantiate(self, dmodel_fmu: str | Path, endpoint, source: Unit | None = None,
                    dmodel: Unit | None = None, restart: bool = False) -> System:
        """A fresh, checked co-simulation of this twin against `endpoint` (the platform). The d-model FMU
        runs in a process of its own when [cosim] isolate says so (by default when cotwin did not build
        it: [models] fmu) or when `restart` (a failed step is retried in a new process from its last good
        state)."""
        from ...cosim.isolated import fmu_unit

        units = []
        if self.source is not None:
            units.append(source if source is not None else self.source_unit())
        units.append(dmodel if dmodel is not None else fmu_unit(DMODEL.name, dmodel_fmu, self.isolated,
                                                                 self.spec.unit_timeout, restart))
        units.append(self.mapping_unit(endpoint))
        return System.of(units, self.connections, delayed=self.delayed, log=self.log, parameters=self.parameters,
                         models=self.models.digests)


    def units_by_role(self, system: System) -> dict[str, Unit]:
        return {u.role: system.units[u.name] for u in self.units}
