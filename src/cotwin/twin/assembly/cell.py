"""A cell of several robots (`[[robots]]`): one scene, one physical world, each robot its own twin.

Each robot is a twin of its own models (cotwin.twin.assembly.system.TwinSystem: the shared d-model, its own
p-model and mapping, its own commands), and the cell puts them together:
- one world (cotwin.pmodel.shared.SharedWorld): every robot's MJCF attached at its base pose in the
  scene's frame, names scoped by the robot's name; the scene is built once, from the first robot's
  mapping (`[platform] scene`, `[scene]`); each robot's cell geometry is its calibration's with the
  plate moved by its base pose (the scene's frame seen from the robot), so that the same grid target is
  the same point of the cell for every robot;
- units: a command source per robot (`{controller}.NAME`), an instance of the same d-model FMU per robot
  (`{dmodel}.NAME`: one file, several instances) and one mapping unit for the cell (`{mapping}.cell`)
  hosting every robot's platform mapping, its ports scoped as `NAME.port`: in a step it runs every
  robot's operations, steps the world once, then reports every robot's events;
- commands: a plan whose columns are scoped by robot (`NAME.port`, e.g. `left.moveDiscreteCommand`); a
  row may leave a robot's cells empty (no command to it); or live from RabbitMQ, routed per robot: a
  source per robot (`{rabbitmq}.NAME`) takes the messages published with routing key `TO_COSIM.NAME`
  ([scenario] rabbitmq to_cosim, then the robot's name) and echoes on `FROM_COSIM.NAME`;
- contacts between two robots are what each mapping's `robot_contact()` tells (cotwin.mapping.runtime),
  e.g. its `collision` event: both d-models hear of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...config import did_you_mean
from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution, RunResult, ended_early
from ...cosim.observers import CSVWriter, Observer, Progress, RealTimePacer
from ...cosim.system import Connection, System
from ...cosim.units import Port, PythonUnit
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...files import read_text
from ..project import TwinProject, check_timing
from .scenario import Command, _column_at, _column_starts, data_rows, parse_value, plan_rows, row_time, scenario_ports
from .system import (DMODEL, MAPPING, CommandPorts, MachinePort, TwinSystem, UnitSpec, build_scene, load_models,
                     multimodel)

if TYPE_CHECKING:  # for the annotations: this module imports them where it uses them
    from .mapping_unit import MappingUnit
    from .outcomes import Summary

CELL_MAPPING = UnitSpec("{mapping}", "cell", "mapping.fmu", "mapping")


def source_of(name: str, source: UnitSpec) -> UnitSpec:
    """Robot `name`'s command source: the controller of its plan's columns or its RabbitMQ unit."""
    return UnitSpec(source.key, name, source.fmu, "source")


def routed(settings, name: str):
    """The broker settings of robot `name`'s commands: routing keys `TO_COSIM.NAME` and `FROM_COSIM.NAME`."""
    return replace(settings, to_cosim=f"{settings.to_cosim}.{name}", from_cosim=f"{settings.from_cosim}.{name}")


def dmodel_of(name: str) -> UnitSpec:
    return UnitSpec(DMODEL.key, name, DMODEL.fmu, "dmodel")


def robot_project(spec: TwinProject, robot) -> TwinProject:
    """One robot's project: the cell's settings with its own models and calibration, no scene (the cell
    has one), no source (the cell's plan gives each robot its commands; the broker's routing is its own)
    and its own part of `[cosim] log` (names scoped `NAME.variable` there)."""
    rabbitmq = routed(spec.rabbitmq, robot.name) if spec.rabbitmq is not None else None
    log = None if spec.log is None else [v.split(".", 1)[1] for v in spec.log if v.startswith(robot.name + ".")]
    return replace(spec, pmodel=robot.pmodel, mapping=robot.mapping, calibration=robot.calibration, scene="none",
                   scene_options={}, world=None, world_file=None, plan=None, rabbitmq=rabbitmq, log=log, panels=None,
                   pmodel_name=None, robots=())


def check_cell_settings(spec: TwinProject) -> None:
    """What a cell's project may not say (yet), located: [figure] panels, [monitor] readings (a reading's path
    names one robot's p-model), a [cosim] log name not scoped by a robot of the cell."""
    problems = []
    if spec.plan is not None and spec.plan.suffix == ".toml":
        problems.append(Finding(spec.location("scenario", "commands"), Severity.ERROR, "[scenario] commands: a cell's "
                                "commands are a CSV plan whose columns are ROBOT.port ([scenario] plan)"))
    if spec.panels is not None:
        problems.append(Finding(spec.location("figure", "panels"), Severity.ERROR, "[figure] panels: a cell's figure is "
                                "chosen from its models (panels of its own are not done yet)"))
    if spec.readings:
        problems.append(Finding(spec.location("monitor", "readings"), Severity.ERROR, "[monitor] readings: not for a "
                                "cell of several robots yet (its robots' q<i>/qd<i> are monitored)"))
    for key, why in (("endpoint", "a cell's robots run in its own MuJoCo world"), ("queue", "a cell's robots run in "
                     "its own MuJoCo world"), ("url", "a cell's robots run in its own MuJoCo world"),
                     ("base", "a cell's robots stand fixed where their [[robots]] xyz/rpy put them"),
                     ("calibration", "each robot's calibration goes in its [[robots]] entry (calibration = FILE)")):
        if ("platform", key) in spec.locations:
            problems.append(Finding(spec.location("platform", key), Severity.ERROR, f"[platform] {key}: not read for a "
                                    f"cell of several robots ({why})"))
    names = {r.name for r in spec.robots}
    unscoped = [v for v in spec.log or () if v.split(".", 1)[0] not in names or "." not in v]
    if unscoped:
        problems.append(Finding(spec.location("cosim", "log"), Severity.ERROR, f"[cosim] log: {', '.join(unscoped)}: "
                                f"a cell's variables are named ROBOT.variable, ROBOT one of {', '.join(sorted(names))}"))
    if problems:
        raise CotwinError(problems)


def check_deviation_variables(spec: TwinProject, robots: list["CellRobot"]) -> None:
    """A cell's `[deviation] variables` name ROBOT.variable, as its [cosim] log and its alarms do, each a
    variable that robot's mapping monitors; located, all together."""
    if spec.deviation.variables is None:
        return
    monitored = {r.name: list(r.system.models.monitored) for r in robots}
    problems = []
    for name in spec.deviation.variables:
        robot, _, variable = name.partition(".")
        if robot not in monitored or not variable:
            problems.append(f"{name!r}: a cell's deviation variables are named ROBOT.variable, ROBOT one of "
                            f"{', '.join(monitored)}{did_you_mean(robot, list(monitored)) if variable else ''}")
        elif variable not in monitored[robot]:
            problems.append(f"{name!r}: robot {robot}'s mapping monitors no {variable!r}"
                            f"{did_you_mean(variable, monitored[robot])} ({', '.join(monitored[robot]) or 'none'})")
    if problems:
        raise CotwinError([Finding(spec.location("deviation", "variables"), Severity.ERROR, f"[deviation] variables: {p}")
                           for p in problems])


def base_pose(robot) -> np.ndarray:
    from ...pmodel.tree import transform

    return transform(robot.xyz, robot.rpy)


@dataclass
class CellRobot:
    """One robot of the cell: its settings ([[robots]]), its twin alone and its cell geometry."""

    spec: object  # cotwin.twin.project.load.RobotSpec
    system: TwinSystem
    pose: np.ndarray  # its base in the scene's frame
    geometry: object  # cotwin.pmodel.cell.CellGeometry: the plate seen from it

    @property
    def name(self) -> str:
        return self.spec.name

    def scoped(self, port: str) -> str:
        return f"{self.name}.{port}"

    @property
    def source(self) -> UnitSpec | None:
        """Its command source's unit ({controller}.NAME or {rabbitmq}.NAME), if it has one."""
        return source_of(self.name, self.system.source) if self.system.source is not None else None


def read_cell_plan(path: str | Path, program, robots: list[str]) -> dict[str, list[Command]]:
    """A cell's plan: `timestep` (ms), then columns `ROBOT.port` (a d-model input port); each row gives
    each robot whose cells it fills one command (an empty cell: none for that robot). Problems are located
    at their line and column, all together."""
    path = Path(path)
    ports = scenario_ports(program)
    lines, rows = plan_rows(path, read_text(path, "plan"))
    problems: list[Finding] = []

    def problem(line: int, column: int, message: str) -> None:
        problems.append(Finding(Location(str(path), line, column), Severity.ERROR, message))

    header = [h.strip() for h in rows[0]]
    starts = _column_starts(lines[0])  # where each cell of the header starts (characters, 1-based)
    column = lambda k: _column_at(starts, k)  # noqa: E731
    columns: dict[int, tuple[str, str]] = {}
    for k, h in enumerate(header[1:], start=1):
        robot, _, port = h.partition(".")
        if robot not in robots or not port:
            problem(1, column(k), f"column {h!r}: a cell's plan names ROBOT.port, ROBOT one of {', '.join(robots)}"
                                  f"{did_you_mean(robot, robots) if port else ''}")
        elif port not in ports:
            problem(1, column(k), f"column {h!r}: unknown d-model input '{port}'{did_you_mean(port, ports)} "
                                  f"(known: {', '.join(ports)})")
        elif h in header[1:k]:
            problem(1, column(k), f"column {h!r} appears twice")
        else:
            columns[k] = (robot, port)
    for ev in program.inputs:
        for robot in robots:
            given = {port for r, port in columns.values() if r == robot}
            missing = [port for port, _ in ev.value_ports if port not in given]
            if ev.name in given and missing:
                at = next(k for k, column in columns.items() if column == (robot, ev.name))
                problem(1, column(at), f"column '{robot}.{ev.name}' without its argument column(s) "
                              f"{', '.join(robot + '.' + m for m in missing)}")
    plans: dict[str, list[Command]] = {r: [] for r in robots}
    together: dict[str, list[list[int]]] = {r: [] for r in robots}  # per robot, columns given together
    grouped: set[int] = set()
    for ev in program.inputs:
        for robot in robots:
            at = {port: k for k, (r, port) in columns.items() if r == robot}
            if ev.name in at:
                group = [at[ev.name], *(at[port] for port, _ in ev.value_ports if port in at)]
                together[robot].append(group)
                grouped.update(group)
    for k, (robot, _) in columns.items():  # a column of no event's: on its own
        if k not in grouped:
            together[robot].append([k])
    for line, row in data_rows(lines, rows, len(header), problem):
        time_ms = row_time(row, line, problem)
        if time_ms is None:
            continue
        cells = _column_starts(lines[line - 1])
        values: dict[str, list] = {r: [] for r in robots}
        for robot, groups in together.items():  # an event and its arguments: all given (sent) or none (not sent)
            for group in groups:
                empty = [k for k in group if not row[k].strip()]
                if empty and len(empty) < len(group):
                    problem(line, cells[empty[0]] if empty[0] < len(cells) else 1,
                            f"{', '.join(repr(header[k]) for k in empty)} empty beside "
                            f"{', '.join(repr(header[k]) for k in group if k not in empty)}: an event and its "
                            f"arguments are given together (the event sent) or not at all")
                    continue
                for k in group if not empty else ():
                    cell, port = row[k].strip(), columns[k][1]
                    try:
                        values[robot].append((port, parse_value(cell, ports[port])))
                    except ValueError as err:
                        problem(line, cells[k] if k < len(cells) else 1, f"column '{header[k]}': '{cell[:40]}' {err}")
        for robot, given in values.items():
            if given:
                plans[robot].append(Command(time_ms / 1000.0, tuple(given), f"{path}:{line}:1"))
    if problems:
        raise CotwinError(problems)
    return {r: sorted(c, key=lambda c: c.time) for r, c in plans.items()}


class CellSystem:
    """The co-simulation of a cell of several robots (see the module doc)."""

    def __init__(self, spec: TwinProject):
        from ...pmodel.cell import CellGeometry
        from ...pmodel.tree import inverse

        if not spec.robots:
            raise CotwinError(f"{spec.path}: a cell names its robots in [[robots]]")
        check_cell_settings(spec)
        self.spec = spec
        alone, problems = [], []
        # [outcomes] is checked against the shared d-model alone: its problems are the cell's, said once
        whole = {spec.location("outcomes", role) for role in spec.outcome_events}
        for r in spec.robots:  # every robot's models, their problems together, each said of its robot
            try:
                alone.append((r, load_models(robot_project(spec, r))))
            except CotwinError as err:  # the shared d-model's own problems once, the rest said of their robot
                shared = str(spec.dmodel)
                problems += [f if f.location.path == shared or f.location in whole else
                             replace(f, message=f"robot {r.name} ({Path(r.mapping).name} on {Path(r.pmodel).name}): "
                                                f"{f.message}") for f in err.findings]
        if problems:
            raise CotwinError(list(dict.fromkeys(problems)))
        programs = [m.program for _, m in alone]
        first = programs[0]
        for (r, m) in alone[1:]:
            if m.program.module.name != first.module.name:
                raise CotwinError(f"{spec.path}: robot {r.name}'s d-model module is {m.program.module.name}, "
                                  f"not {first.module.name}: a cell's robots share one d-model")
        names = [r.name for r in spec.robots]
        plans = read_cell_plan(spec.plan, first, names) if spec.plan is not None else {n: [] for n in names}
        self.robots: list[CellRobot] = []
        for r, models in alone:
            system = TwinSystem(robot_project(spec, r), models, plans[r.name] if spec.plan is not None else None)
            geometry = models.calibration.geometry if models.calibration is not None else CellGeometry()
            pose = base_pose(r)
            self.robots.append(CellRobot(r, system, pose, geometry.with_plate(inverse(pose) @ geometry.plate_pose())))
        check_deviation_variables(spec, self.robots)
        if spec.plant is not None:  # its joints, located at the project's [plant] (perturbed_world applies it)
            from ...pmodel.perturbation import cell_joint_problems
            from ...pmodel.shared import PlacedRobot

            problems = cell_joint_problems(spec.plant, [PlacedRobot(r.name, r.system.models.tree, r.pose)
                                                        for r in self.robots], lambda key: spec.location("plant", key))
            if problems:
                raise CotwinError(problems)
        self.scene = build_scene(spec, alone[0][1].mapping_model)
        self.program = first
        self.commands = [c for robot in self.robots for c in robot.system.commands]
        self.units: list[UnitSpec] = []
        self.connections: list[Connection] = []
        self.log: dict[str, list[str]] = {CELL_MAPPING.name: []}
        self.parameters: dict[str, dict] = {}
        for robot in self.robots:
            self._add(robot)
        self.units.append(CELL_MAPPING)
        self.delayed = {CELL_MAPPING.name}

    def _add(self, robot: CellRobot) -> None:
        system = robot.system
        names = {DMODEL.name: dmodel_of(robot.name).name, MAPPING.name: CELL_MAPPING.name}
        if system.source is not None:
            names[system.source.name] = robot.source.name
            self.units.append(robot.source)
        self.units.append(dmodel_of(robot.name))

        def port(unit: str, name: str) -> str:
            return robot.scoped(name) if unit == MAPPING.name else name

        self.connections += [Connection(names[c.source], port(c.source, c.output), names[c.target],
                                        port(c.target, c.input)) for c in system.connections]
        self.log[CELL_MAPPING.name] += [robot.scoped(v) for v in system.log[MAPPING.name]]
        self.log[names[DMODEL.name]] = list(system.log[DMODEL.name])
        for unit, values in system.parameters.items():
            self.parameters[names[unit]] = dict(values)

    @property
    def warnings(self) -> list:
        """What each robot's models and the project against them warn of (TwinModels.warnings), the shared
        d-model's once."""
        return list(dict.fromkeys(f for robot in self.robots for f in robot.system.warnings))

    @property
    def digests(self) -> dict[str, str]:
        return {k: v for robot in self.robots for k, v in robot.system.models.digests.items()}

    def world(self, perturbation=None):
        """A fresh world of the cell's robots and scene; with a perturbation (cotwin.pmodel.perturbation), the
        perturbed plant of every robot in it (payload, friction, damping): a live twin's PT."""
        from ...pmodel.shared import PlacedRobot, SharedWorld

        robots = [PlacedRobot(r.name, r.system.models.tree, r.pose) for r in self.robots]
        if perturbation is not None:
            from ...pmodel.perturbation import perturbed_world

            return perturbed_world(robots, self.scene, perturbation,
                                   tools={r.name: r.system.models.tool for r in self.robots})  # each project's tool
        return SharedWorld(robots, self.scene)

    def mapping_unit(self, world, perturbation=None) -> "CellMappingUnit":
        """Every robot's platform mapping against its view of `world`, in one unit; with a perturbation, each
        robot's endpoint adds its latency and noise (cotwin.mapping.perturbed; robot k's noise seeded with the
        perturbation's seed + k), as a plant's robots do."""
        from dataclasses import replace as changed

        from ...mapping.endpoint import SimulatedEndpoint
        from ...mapping.perturbed import PerturbedEndpoint
        from ...mapping.runtime import Mapping
        from .mapping_unit import MappingUnit

        units = {}
        for k, robot in enumerate(self.robots):
            models = robot.system.models
            profile = models.calibration.profile if models.calibration is not None else None
            endpoint = SimulatedEndpoint(world.view(robot.name), profile, robot.geometry)
            if perturbation is not None:
                endpoint = PerturbedEndpoint(endpoint, changed(perturbation, seed=perturbation.seed + k))
            mapping = Mapping(models.project, endpoint, geometry=robot.geometry, mirrors=self.spec.mirror_joints,
                              monitor=self.spec.readings)
            units[robot.name] = MappingUnit(MAPPING.name, models.program, mapping, robot.system.command_events)
        return CellMappingUnit(CELL_MAPPING.name, world, units)

    def state_machines(self) -> list[MachinePort]:
        """Every robot's d-model state machines, each in its robot's d-model instance, named `ROBOT.machine`."""
        return [replace(m, unit=dmodel_of(robot.name).name, machine=robot.scoped(m.machine))
                for robot in self.robots for m in robot.system.state_machines()]

    def command_ports(self) -> list[CommandPorts]:
        """Every robot's command source's ports, in its robot's source instance, recorded as `ROBOT.port`."""
        return [CommandPorts(robot.source.name, *(tuple((p, robot.scoped(name)) for p, name in ports)
                                                  for ports in (c.events, c.values)))
                for robot in self.robots for c in robot.system.command_ports()]

    def source_ports(self) -> list[str]:
        """Every robot's command source's ports, together: one source FMU serves every robot's instance."""
        return list(dict.fromkeys(p for robot in self.robots for p in robot.system.source_ports))

    def python_unit(self, role: str, instance: str):
        """The unit a Python FMU of the cell carries (cotwin.twin.assembly.fmu_slave): the cell's mapping, or robot
        `instance`'s command source (any other instance, e.g. a packager's, gets the first robot's) with every
        robot's source ports, so that one FMU file describes them all."""
        if role == "mapping":
            return self.mapping_unit(self.world())
        robot = next((r for r in self.robots if r.name == instance), self.robots[0])
        if robot.source is None or role != robot.system.source.instance:
            raise CotwinError(f"unknown unit role '{role}' for the cell {self.spec.path}")
        from .scenario import ScenarioUnit

        if robot.system.source.instance == "controller":
            return ScenarioUnit(robot.source.name, self.program, robot.system.commands, self.source_ports())
        return robot.system.source_unit()

    def multimodel(self, realtime: bool | None = None) -> dict:
        """Maestro's multimodel.json of the cell: one FMU per kind ({dmodel}, {controller} or {rabbitmq},
        {mapping}), instantiated once per robot where it is the robot's (the d-model FMU's reuse, as Maestro
        writes it); the `cotwin` key (which Maestro ignores) holds the delays."""
        return multimodel(self.spec, self.units, self.connections, self.parameters, self.log, self.delayed, realtime, {})

    def instantiate(self, dmodel_fmu: str | Path, world=None, perturbation=None, sources: dict | None = None) -> System:
        """A fresh, checked co-simulation of the cell (in `world`, by default a fresh nominal one; its robots'
        endpoints perturbed by `perturbation`'s latency and noise, if given): the same d-model FMU
        instantiated once per robot; each robot's command source from `sources` (by robot, e.g. a live twin's
        shared broker streams), else a fresh one of its own."""
        from ...cosim.isolated import fmu_unit

        units = []
        for robot in self.robots:
            if robot.system.source is not None:
                source = sources[robot.name] if sources is not None else robot.system.source_unit()
                source.name = robot.source.name
                units.append(source)
            units.append(fmu_unit(dmodel_of(robot.name).name, dmodel_fmu, robot.system.isolated,
                                  self.spec.unit_timeout))
        units.append(self.mapping_unit(world if world is not None else self.world(), perturbation))
        return System.of(units, self.connections, delayed=self.delayed, log=self.log, parameters=self.parameters,
                         models=self.digests)


class CellMappingUnit(PythonUnit):
    """Every robot's mapping unit (cotwin.twin.assembly.mapping_unit) in one, over one world: ports scoped by robot;
    in a step each robot acts (its operations), the world steps once, each robot reports."""

    def __init__(self, name: str, world, units: dict[str, MappingUnit]):
        ports = [Port(f"{robot}.{p.name}", p.type, p.causality) for robot, unit in units.items()
                 for p in unit.ports.values()]
        super().__init__(name, ports)
        self.world = world
        self.units = units  # robot -> its mapping unit
        # (scoped name, the robot's name) of every input and output, made once: the step reads them all
        self.inputs = {robot: [(f"{robot}.{p.name}", p.name) for p in unit.ports.values() if p.causality == "input"]
                       for robot, unit in units.items()}
        self.outputs = {robot: [(f"{robot}.{p.name}", p.name) for p in unit.ports.values() if p.causality == "output"]
                        for robot, unit in units.items()}
        self.endpoints = [unit.mapping.endpoint for unit in units.values()]
        from ...mapping.endpoint import advance_shared  # MuJoCo's side: loaded with a world, not with the cell

        self._advance = advance_shared

    def instantiate(self, start: float) -> None:
        super().instantiate(start)
        for unit in self.units.values():
            unit.instantiate(start)
        self._collect()

    def step(self, t: float, h: float) -> None:
        values = self.values
        for robot, unit in self.units.items():
            unit.values.update({name: values[scoped] for scoped, name in self.inputs[robot]})
            unit.act(t)
        self._advance(self.world, self.endpoints, h)
        for unit in self.units.values():
            unit.mapping.step(0.0)  # the world has moved: readings and mirrors refreshed
            unit.reached(t + h)
        self.time = t + h
        self._collect()

    def _collect(self) -> None:
        values = self.values
        for robot, unit in self.units.items():
            own = unit.values
            for scoped, name in self.outputs[robot]:
                if name in own:
                    values[scoped] = own[name]

    def terminate(self) -> None:
        for unit in self.units.values():
            unit.terminate()

    # ---- state: every robot's mapping unit's (each holds the whole world's MuJoCo state, taken at one
    # time: restoring them in turn sets the same world) and the world's contact bookkeeping ----
    STATE_KEYS = (*PythonUnit.STATE_KEYS, "robots", "world")

    def snapshot(self) -> dict:
        world = self.world
        return {**super().snapshot(), "robots": {name: unit.snapshot() for name, unit in self.units.items()},
                "world": {"contacts": list(world.contacts), "touching": sorted(world._touching),
                          "touched": {name: sorted(robots) for name, robots in world.touched.items()}}}

    def restore(self, snapshot: dict) -> None:
        """Continue from a snapshot, checked first (cotwin.plaindata): the same robots, each robot's unit's own
        checks, the world's contacts naming robots of the cell."""
        from ...plaindata import fields, of_type

        what = f"unit {self.name}"
        fields(snapshot, what, self.STATE_KEYS)
        robots = fields(of_type(snapshot["robots"], dict, f"{what}'s robots"), f"{what}'s robots", list(self.units))
        world = fields(of_type(snapshot["world"], dict, f"{what}'s world"), f"{what}'s world",
                       ("contacts", "touching", "touched"))
        names = [r.name for r in self.world.robots]
        contacts = of_type(world["contacts"], list, f"{what}'s contacts")
        for entry in contacts:
            if entry.__class__ is not tuple or len(entry) != 3 or entry[1] not in names or entry[2] not in names:
                raise CotwinError(f"the saved state's {what}: contact {entry!r:.80} is not (time, robot, robot)")
        touching = [tuple(pair) for pair in of_type(world["touching"], list, f"{what}'s touching")]
        if any(len(p) != 2 or not all(i.__class__ is int and 0 <= i < len(names) for i in p) for p in touching):
            raise CotwinError(f"the saved state's {what}: robots touching {touching!r:.80} are not pairs of robots")
        touched = fields(of_type(world["touched"], dict, f"{what}'s touched"), f"{what}'s touched", names)
        super().restore(snapshot)
        for name, unit in self.units.items():
            unit.restore(robots[name])
        state = self.world
        state.contacts = [tuple(entry) for entry in contacts]
        state._touching = set(touching)
        state.touched = {name: set(of_type(touched[name], list, f"{what}'s touched by {name}")) for name in names}
        state._steps = int(round(state.data.time / state.timestep))  # the contact checks' cadence


@dataclass
class RobotOutcome:
    """What became of one robot's commands in a cell's run."""

    name: str
    commands: int = 0  # commands its source applied
    completed: int = 0  # of them, those completed (cotwin.twin.assembly.outcomes: taken, done, back at rest)
    infeasible: int = 0  # of them, those an answer said cannot be done (events named nonfeasible*, infeasible*, ...)
    collisions: list[float] = field(default_factory=list)  # when its d-model heard of a collision (steps it began)
    planned: int | None = None  # its plan's commands (None: they come from the broker)

    def line(self) -> str:
        hit = f"collision reported at t = {', '.join(f'{t:g}' for t in self.collisions)} s" if self.collisions \
            else "no collision"
        refused = f", {self.infeasible} infeasible" if self.infeasible else ""
        left = self.planned - self.commands if self.planned is not None else 0
        waiting = f" ({left} of its plan's {self.planned} not applied before the end)" if left > 0 else ""
        return (f"{self.name}: {self.commands} command(s) applied{waiting}, {self.completed} move(s) completed"
                f"{refused}, {hit}")


class CellOutcomes(Observer):
    """Per robot: the commands its source applied, what became of each (a CommandLedger per robot, on its own
    d-model instance and its ports of the cell's mapping: completed, infeasible, ...), and the steps its d-model
    was told of a collision (an event of its mapping that stops a move: [outcomes] stops, else one whose name says
    so, cotwin.twin.assembly.outcomes.EventRoles). Nothing here knows a d-model's event names: any d-model's
    commands are judged as a single robot's."""

    def __init__(self, cell: CellSystem):
        from .outcomes import CommandLedger

        self.cell = cell
        self.robots = {r.name: RobotOutcome(r.name, planned=len(r.system.commands) if cell.spec.plan is not None else None)
                       for r in cell.robots}
        self.ledgers = {r.name: CommandLedger(r.system, self._units(r), r.scoped) for r in cell.robots}
        self.summaries: dict[str, Summary] = {}  # robot -> what became of its commands, made once as the run ended
        # per robot, made once (the observer runs every step): its source, command events and scoped stopping events
        self._watch = [(r.name, r.source.name if r.source is not None else None, sorted(r.system.command_events),
                        [r.scoped(ev.name) for ev in r.system.models.mapping_model.input_events
                         if self.ledgers[r.name].roles.stops(ev.name)
                         and ev.name in {i.name for i in r.system.models.program.inputs}])
                       for r in cell.robots]
        self._before: dict[str, bool] = {}

    @staticmethod
    def _units(robot: CellRobot) -> dict[str, str]:
        """The cell's names of the units of the robot's twin alone (as CellSystem._add names them)."""
        units = {DMODEL.name: dmodel_of(robot.name).name, MAPPING.name: CELL_MAPPING.name}
        if robot.system.source is not None:
            units[robot.system.source.name] = robot.source.name
        return units

    def simulation_initialized(self, execution) -> None:
        for ledger in self.ledgers.values():
            ledger.simulation_initialized(execution)

    def step_complete(self, execution) -> None:
        units = execution.system.units
        answers = units[CELL_MAPPING.name].values
        for name, source, events, stops in self._watch:
            out = self.robots[name]
            if source in units:
                commanded = units[source].values
                out.commands += sum(1 for e in events if commanded.get(e) is True)
            ledger = self.ledgers[name]
            ledger.step_complete(execution)
            verdicts = [o.verdict for o in ledger.outcomes]
            out.completed, out.infeasible = verdicts.count("completed"), verdicts.count("infeasible")
            hit = any(answers.get(e) is True for e in stops)
            if hit and not self._before.get(name):
                out.collisions.append(round(execution.time, 9))
            self._before[name] = hit

    def simulation_ended(self, execution, error) -> None:
        """Each robot's summary, made once: its commands' outcomes and its joints pushing at their effort limit
        as the run ended, read from its platform's simulator (outcomes.saturated_joints, as a single robot's run
        and live twin read them); none where the cell's mapping is not this process's CellMappingUnit (an FMU
        in another master)."""
        from .outcomes import saturated_joints

        mapping = execution.system.units.get(CELL_MAPPING.name)
        hosted = mapping.units if isinstance(mapping, CellMappingUnit) else {}
        for name, ledger in self.ledgers.items():
            robot = hosted.get(name)
            self.summaries[name] = ledger.summary(
                saturated=saturated_joints(robot.mapping.endpoint) if robot is not None else ())

    def lines(self) -> list[str]:
        return [r.line() for r in self.robots.values()]

    def warnings(self) -> list[str]:
        """Per robot, named: its commands that never completed with joints at their effort limit at the end
        (outcomes.Summary.saturation, what a single robot's run says); none before the run ended."""
        said = {name: summary.saturation() for name, summary in self.summaries.items()}
        return [f"{name}: {saturation}" for name, saturation in said.items() if saturation is not None]

    def strict_failures(self) -> list[str]:
        """What `--strict` refuses, per robot: commands applied that no completed move answered (stopped by a
        collision, infeasible or still under way at the end), and collisions."""
        out = []
        for r in self.robots.values():
            if r.completed < r.commands:
                out.append(f"{r.name}: {r.commands - r.completed} of {r.commands} command(s) not completed")
            if r.planned is not None and r.commands < r.planned:
                out.append(f"{r.name}: {r.planned - r.commands} of its plan's {r.planned} command(s) not applied")
            if r.collisions:
                out.append(f"{r.name}: collision reported at t = {', '.join(f'{t:g}' for t in r.collisions)} s")
        return out


@dataclass
class CellRun:
    result: RunResult
    csv: Path
    system: System
    outcomes: CellOutcomes
    contacts: list  # (time, robot, robot) when a contact between two robots began
    figure: Path | None = None


def cell_panels(cell: CellSystem) -> list[tuple[str, list[str], str]]:
    """The figure of a cell's run, chosen from its models, two panels per robot: its commands with the
    platform events its mapping reports to its d-model, and its monitored variables."""
    panels = []
    for k, robot in enumerate(cell.robots, start=1):
        system = robot.system
        commands = [f"{robot.source.name}.{p}" for p in system.source_ports if p in system.command_events] \
            if robot.source is not None else []
        mapped = {ev.name for ev in system.models.mapping_model.input_events}
        events = [f"{CELL_MAPPING.name}.{robot.scoped(ev.name)}" for ev in system.models.program.inputs
                  if ev.name in mapped and ev.name not in system.command_events]
        panels.append((f"({k}a) {robot.name}: commands, events [1 = true]", commands + events, "steps-post"))
        monitored = [f"{CELL_MAPPING.name}.{robot.scoped(v)}" for v in system.log[MAPPING.name]]
        if monitored:
            panels.append((f"({k}b) {robot.name}: monitored [rad, rad/s]", monitored, "default"))
    return panels


def run_cell(cell: CellSystem, out: str | Path, step: float | None = None, end: float | None = None,
             algorithm: str | None = None, realtime: bool | None = None, observers: list[Observer] | None = None,
             progress=None, cc: str = "cc", plot: bool = True) -> CellRun:
    """Co-simulate the cell into `out` (outputs.csv and figure.png), building the d-model FMU once for every
    robot."""
    from .build import dmodel_fmu, folder_lock
    from .run import RUN_FILES

    out = Path(out)
    spec = cell.spec
    end = spec.end if end is None else end
    step = spec.step if step is None else step
    check_timing(spec, step, end)
    with folder_lock(out, RUN_FILES, spec.inputs):
        fmu = dmodel_fmu(cell.robots[0].system, out, cc)
        cosim = cell.instantiate(fmu)
        writer = CSVWriter(out / "outputs.csv")
        outcomes = CellOutcomes(cell)
        chain: list[Observer] = [writer, outcomes, *(observers or [])]
        if progress is not None:
            chain.append(Progress(progress))
        if spec.realtime if realtime is None else realtime:
            chain.append(RealTimePacer())
        execution = Execution(cosim, make_algorithm(algorithm or spec.algorithm), step, 0.0, chain)
        try:
            result = execution.run(end)
        except (CotwinError, KeyboardInterrupt) as err:
            raise ended_early(err, execution.time, writer.kept()) from None
        world = cosim.units[CELL_MAPPING.name].world
        figure = None
        if plot:
            from ...plot import figure as draw

            figure = draw(out / "outputs.csv", out / "figure.png", cell_panels(cell),
                          title=f"{cell.program.module.name} x {len(cell.robots)}: step {step:g} s, {result.algorithm}")
        return CellRun(result, out / "outputs.csv", cosim, outcomes, list(world.contacts), figure)
