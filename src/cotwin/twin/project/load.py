"""A twin project (`cotwin.toml`): the three models, where commands come from, the platform, the
co-simulation settings and, for a live twin, the physical twin, deviation checking and history.

Every key, with its type, default and meaning, is in docs/project.md, generated from the section
dataclasses of `cotwin.twin.project.sections` (`python -m cotwin.twin.project.doc`). `load_project` reads a file
into those settings, every problem reported at its key's line and column, all together
(cotwin.config), and resolves them against the models' files into a `TwinProject`; `with_overrides`
gives a project with some keys changed (a command's options), `to_toml` writes one back.
"""

from __future__ import annotations

import copy
import dataclasses
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from ...config import TomlFile, did_you_mean, dumps, is_number, raise_problems, shown
from ...cosim.isolated import DEFAULT_TIMEOUT
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...pmodel.perturbation import Perturbation
from ...settings import leaves, read, replace_path, tables
from .sections import (CYCLE_PERIOD, READ_ONLY_BY, SHAPES, STAND_IN_EXTENT, DeviationSettings, ProjectSettings,
                       RabbitMQSettings, _amqp_url, timing_problems)


@dataclass(frozen=True)
class PTSettings:
    """The physical twin as resolved ([pt], or a command's --pt-log): its log a path."""

    endpoint: str
    url: str | None = None
    log: Path | None = None
    queue: str = "cotwin.robot"
    offset: float | None = None  # replay: log time at co-simulation time 0 (default: aligned on the first motion)

@dataclass(frozen=True)
class RobotSpec:
    """One robot of a cell ([[robots]]) as resolved: its files found, its base pose in the scene's frame."""

    name: str
    pmodel: Path
    mapping: Path
    calibration: Path | None
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    index: int  # its place in [[robots]] (where its problems are reported)


@dataclass
class TwinProject:
    """A project resolved for running: its files found, its world, stand-ins and plant built. `settings` are
    the sections as written (the source of `with_overrides` and `to_toml`)."""

    path: Path
    dmodel: Path
    pmodel: Path
    mapping: Path
    module: str | None = None
    pmodel_name: str | None = None
    plan: Path | None = None  # a plan CSV or a TOML command list
    rabbitmq: RabbitMQSettings | None = None
    endpoint: str = "mujoco"
    queue: str = "cotwin.robot"
    url: str = "amqp://127.0.0.1:5672/%2F"
    scene: str = "auto"
    scene_options: dict = field(default_factory=dict)  # [scene]: the scene kind's own keys
    calibration: Path | None = None
    step: float = 0.1
    end: float = 20.0
    algorithm: str = "jacobi"
    realtime: bool = False
    log: list[str] | None = None
    pt: PTSettings | None = None
    deviation: DeviationSettings = field(default_factory=DeviationSettings)
    history_url: str | None = None
    plant: Perturbation | None = None  # [plant]: how `cotwin plant` perturbs the cell
    world: object | None = None  # cotwin.pmodel.world.World: [platform] world or [world]
    world_file: Path | None = None  # where it was read from ([platform] world), if a file
    base: str = "fixed"
    stand_ins: dict = field(default_factory=dict)  # mesh file as written -> [cotwin.pmodel.tree.StandIn]
    mirror_joints: object = "arm"  # [monitor] joints
    readings: dict[str, str] = field(default_factory=dict)  # [monitor] readings
    outcome_events: dict[str, tuple[str, ...]] = field(default_factory=dict)  # [outcomes]: role -> events, as written
    parameters: dict[str, object] = field(default_factory=dict)  # [cosim] parameters of the d-model FMU
    panels: list[tuple[str, list[str], str]] | None = None  # [figure] panels: (label, unit.variable, style)
    convergence: object | None = None  # [convergence] (project.sections.Convergence): the DT pulled towards its PT
    fmu: Path | None = None  # [models] fmu: a d-model FMU built elsewhere, run in place of the one built from dmodel
    isolate: bool | None = None  # [cosim] isolate: the d-model FMU in a process of its own (None: if cotwin did not build it)
    unit_timeout: float = DEFAULT_TIMEOUT  # [cosim] unit_timeout: s an isolated FMU's call may take
    locations: dict = field(default_factory=dict)  # key path -> Location where it was written (later checks)
    raw: dict = field(default_factory=dict)  # the tables as written that staged copies carry (world, stand_in, figure)
    settings: Any = None  # ProjectSettings: the sections as written
    file: TomlFile | None = field(default=None, repr=False)  # the file read (its data and where each key is)
    pt_log: Path | None = None  # a command's --pt-log, in place of [pt] log
    reader: str | None = None  # the command that read it (load_project)
    run_timing: tuple[float | None, float | None] = (None, None)  # a command's --step and --end (load_project)
    profile: Path | None = None  # [robot] profile: the controller's conventions (cotwin.mapping.profile)
    robots: tuple[RobotSpec, ...] = ()  # [[robots]]: a cell of several (pmodel, mapping: the first one's)

    @property
    def model_files(self) -> list[Path]:
        return [self.dmodel, self.pmodel, self.mapping]

    @property
    def scenario(self) -> Path | None:
        return self.plan

    @property
    def inputs(self) -> list[Path]:
        """Every file the project reads (no output of a run may replace one of them)."""
        found = [self.path, *self.model_files, self.plan, self.pt.log if self.pt else None, self.calibration,
                 self.world_file, self.profile, *(p for r in self.robots for p in (r.pmodel, r.mapping, r.calibration))]
        return [p for p in found if p is not None]

    def location(self, *key) -> Location:
        """Where `key` (or its nearest written parent) is in the project file, for checks made after
        loading (against the models); the file's start when not known."""
        for n in range(len(key), 0, -1):
            if key[:n] in self.locations:
                return self.locations[key[:n]]
        return Location(str(self.path), 1, 1)

    def ignored_sections(self, command: str) -> list[Finding]:
        """A warning at each table of the project file that `command` (e.g. "cotwin run", or with the option
        that makes it read more: "cotwin run --dashboard") does not read
        (READ_ONLY_BY): a [convergence] in a project co-simulated by `cotwin run` would otherwise be
        silently without effect."""
        data = self.file.data if self.file is not None else {}
        return sorted(Finding(self.location(section), Severity.WARNING,
                              f"[{section}] applies only to {', '.join(readers)}: {command} ignores it")
                      for section, readers in READ_ONLY_BY.items()
                      if section in data and command not in readers)

    def plant_problems(self, tree) -> list[Finding]:
        """[plant]'s joints against the robot's kinematic tree (`tree`): an error at each joint it names that
        the p-model does not have (see _plant_problems)."""
        return _plant_problems(self.plant, tree, lambda key: self.location(*key))

    def with_overrides(self, **changes) -> "TwinProject":
        """This project with some keys set (None: left out), checked as if written in the file. A change is
        named SECTION_KEY (pt_url, scenario_rabbitmq_exchange) or by a key only one section has (step,
        end, realtime); a Path is taken as it is, not relative to the project file."""
        if self.file is None:
            raise CotwinError(f"{self.path}: a project made in code, not read by load_project, has no settings "
                              "to override")
        data = copy.deepcopy(self.file.data)
        current = tables(self.current_settings())  # what a caller set since loading is kept
        for section in ("scenario", "platform", "cosim", "deviation", "history", "convergence"):
            if section in current:
                data[section] = copy.deepcopy(current[section])
            else:
                data.pop(section, None)
        for name, value in changes.items():
            path = override_path(name)
            table = data
            for key in path[:-1]:
                table = table.setdefault(key, {})
            if value is None:
                table.pop(path[-1], None)
            else:
                table[path[-1]] = _as_toml(value)
        file = copy.copy(self.file)
        file.data = data
        return _load(file, self.pt_log, self.reader, self.run_timing)

    def current_settings(self):
        """The settings as this project now holds them: the file's, with the fields a caller may have set
        since loading (the scenario's broker, the platform, timing, deviation, history, convergence) laid
        over them, so that what is written (a build's staged copy) is what runs."""
        s = self.settings
        if s is None:
            raise CotwinError(f"{self.path}: a project made in code, not read by load_project, has no settings "
                              "to write")
        return dataclasses.replace(
            s, scenario=dataclasses.replace(s.scenario, rabbitmq=self.rabbitmq),
            platform=dataclasses.replace(s.platform, endpoint=self.endpoint, queue=self.queue, url=self.url,
                                         scene=self.scene),
            cosim=dataclasses.replace(s.cosim, step=self.step, end=self.end, algorithm=self.algorithm,
                                      realtime=self.realtime, log=None if self.log is None else tuple(self.log),
                                      parameters=dict(self.parameters), isolate=self.isolate,
                                      unit_timeout=self.unit_timeout),
            deviation=self.deviation, history=dataclasses.replace(s.history, url=self.history_url),
            convergence=self.convergence)

    def to_toml(self, sections: tuple[str, ...] | None = None, rebase: Callable[[Path], str | None] | None = None,
                header: str = "") -> str:
        """The project's settings as TOML (only keys set away from their defaults); `sections` limits the
        tables written, `rebase` maps each file the project names (resolved) to the name written."""
        settings = self.current_settings()
        if rebase is not None:
            for path, spec in leaves(ProjectSettings).items():
                value = _get(settings, path)
                if spec.path and value is not None and (sections is None or path[0] in sections):
                    settings = replace_path(settings, path, rebase((self.path.parent / value).resolve()))
            if settings.robots and (sections is None or "robots" in sections):  # [[robots]]: each one's files
                settings = dataclasses.replace(settings, robots=tuple(dataclasses.replace(r, **{
                    key: rebase((self.path.parent / getattr(r, key)).resolve()) for key in ("pmodel", "mapping",
                                                                                         "calibration")
                    if getattr(r, key) is not None}) for r in settings.robots))
        written = tables(settings)
        return dumps({k: v for k, v in written.items() if sections is None or k in sections}, header)


def override_path(name: str) -> tuple[str, ...]:
    """The key path a `with_overrides` name stands for."""
    paths = leaves(ProjectSettings)
    exact = [p for p in paths if "_".join(p) == name]
    if exact:
        return exact[0]
    bare = [p for p in paths if len(p) == 2 and p[1] == name]
    if len(bare) == 1:
        return bare[0]
    known = "; ".join("_".join(p) for p in paths if paths[p].section is None)
    raise TypeError(f"no project setting {name!r}{' (several sections have it)' if bare else ''}; known: {known}")


def _get(settings, path: tuple):
    for key in path:
        settings = getattr(settings, key, None) if settings is not None else None
    return settings


def _as_toml(value):
    if isinstance(value, Path):
        return str(value.resolve())
    if isinstance(value, tuple):
        return [_as_toml(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_toml(v) for k, v in value.items()}
    return value



def load_project(path: str | Path, pt_log: str | Path | None = None, reader: str | None = None,
                 step: float | None = None, end: float | None = None) -> TwinProject:
    """Read and check cotwin.toml; every problem is reported at its key, all together. `pt_log` (a command's
    --pt-log) replaces [pt] log, which is then not looked for: the PT replays it. `reader`: the command reading
    it (as READ_ONLY_BY names them); one that ignores [pt] does not look for its log either (a replay project
    copied without its recording still runs, predicts and sweeps its DT). `step`, `end`: a command's --step and
    --end, which its run takes in place of [cosim]'s: a timing problem one of them is part of (a cycle_period
    that does not divide the step) is the command's to say with the values the run takes (cotwin.cli.common.
    check_timing), not the project's with the values it replaces."""
    return _load(TomlFile(path, "project file"), None if pt_log is None else Path(pt_log), reader, (step, end))


def file_problem(path: Path) -> str | None:
    """Why `path` is not a file to read (no such file, a folder, a name the system refuses: too long, ...), or
    None; the path cut to 200 characters in the message."""
    shown = str(path) if len(str(path)) <= 200 else str(path)[:200] + "..."
    try:
        if path.is_file():
            return None
        return f"{shown} is a folder, not a file" if path.is_dir() else f"no file {shown}"
    except OSError as err:
        return f"{shown} cannot be looked up: {err.strerror or err}"
    except ValueError as err:  # a NUL in the name
        return f"{shown} cannot be looked up: {err}"


def _load(file: TomlFile, pt_log: Path | None, reader: str | None = None,
          run_timing: tuple[float | None, float | None] = (None, None)) -> TwinProject:
    """The project `file.data` describes, resolved against the files it names (see load_project: `reader`, and
    `run_timing`, its `step` and `end`)."""
    if "models" not in file.data and isinstance(file.data.get("twin"), list):  # a fleet file given for a project
        raise CotwinError([Finding(file.location(("twin",)), Severity.ERROR, "this is a fleet file ([[twin]] entries "
                                   "naming projects), not a twin project: run it with `cotwin fleet "
                                   f"{file.path.name} -o DIR`, or give one of the projects it names")])
    problems: list[Finding] = []
    s = read(ProjectSettings, file.data, file, (), problems)
    base = file.path.parent

    def existing(table: str, key: str, value: str | None) -> Path | None:
        if value is None:
            return None
        target = base / value
        what = file_problem(target)
        if what is not None:
            problems.append(Finding(file.location((table, key)), Severity.ERROR, f"[{table}] {key}: {what}"))
        return target

    models = s.models
    files = {k: existing("models", k, getattr(models, k, None)) for k in ("dmodel", "pmodel", "mapping")}
    robots = _robots(file, s.robots, problems)
    for key in ("pmodel", "mapping"):
        if models is None:  # [models] is not a table: reported where it is read
            break
        if robots and getattr(models, key) is not None:
            problems.append(Finding(file.location(("models", key)), Severity.ERROR,
                                    f"[models] {key}: a cell's robots name their own ([[robots]] {key})"))
        elif not robots and getattr(models, key) is None:
            problems.append(Finding(file.location(("models",)), Severity.ERROR, f"[models] needs '{key}'"))
    if robots:
        files["pmodel"], files["mapping"] = robots[0].pmodel, robots[0].mapping
    fmu = existing("models", "fmu", getattr(models, "fmu", None))
    scenario, platform, cosim, monitor = s.scenario, s.platform, s.cosim, s.monitor
    sources = [k for k in ("plan", "commands", "rabbitmq") if getattr(scenario, k) is not None]
    if len(sources) > 1:
        problems.append(Finding(file.location(("scenario",)), Severity.ERROR,
                                f"[scenario] takes one source of commands, got {', '.join(sources)}"))
    plan = existing("scenario", sources[0], getattr(scenario, sources[0])) \
        if sources and sources[0] != "rabbitmq" else None
    reads_pt = reader is None or reader in READ_ONLY_BY["pt"]
    pt = _pt(file, s.pt, pt_log, existing if reads_pt else (lambda table, key, value: None if value is None else
                                                            base / value), problems)
    calibration = existing("platform", "calibration", platform.calibration)
    profile = existing("robot", "profile", s.robot.profile)
    world, world_file = _world(file, s, existing, problems)
    stand_ins = _stand_ins(file, platform.stand_in, problems)
    panels = _panels(file, s.figure.panels, problems) if "panels" in _table(file.data, "figure") else None
    _scene(file, s, problems)
    _timing(file, cosim, problems, run_timing)
    if s.pt is not None:  # [pt] as written, against its own endpoint (a --pt-log replays in its place)
        problems.extend(_pt_keys(file, s.pt))
    plant = Perturbation.from_table(dataclasses.asdict(s.plant)) if s.plant is not None else None
    if any(p.severity is Severity.ERROR for p in problems):  # a cell's [plant] is its robots' (perturbed_world)
        against = None if plant is None or robots else (lambda tree: _plant_problems(plant, tree, file.location))
        problems.extend(_model_errors([files[k] for k in ("dmodel", "pmodel", "mapping")], against,
                                      models.pmodel_name if models is not None else None, stand_ins))
    raise_problems(problems)
    spec = TwinProject(
        file.path, files["dmodel"], files["pmodel"], files["mapping"], models.module, models.pmodel_name,
        plan, scenario.rabbitmq, platform.endpoint, platform.queue, platform.url, platform.scene,
        copy.deepcopy(_table(file.data, "scene")), calibration, float(cosim.step), float(cosim.end),
        cosim.algorithm, cosim.realtime, None if cosim.log is None else list(cosim.log), pt, s.deviation,
        s.history.url, plant)
    spec.world, spec.world_file, spec.base, spec.stand_ins = world, world_file, platform.base, stand_ins
    spec.mirror_joints = list(monitor.joints) if isinstance(monitor.joints, tuple) else monitor.joints
    spec.readings = dict(monitor.readings)
    spec.outcome_events = {role: tuple(events) for role, events in dataclasses.asdict(s.outcomes).items()
                           if events is not None}
    spec.parameters, spec.panels = dict(cosim.parameters), panels
    spec.fmu = fmu
    spec.isolate, spec.unit_timeout = cosim.isolate, float(cosim.unit_timeout)
    spec.convergence = s.convergence
    spec.profile = profile
    spec.robots = tuple(robots)
    if world_file is not None:
        spec.world_file = world_file.path
    spec.locations = {key: file.location(key) for key in file.where}
    spec.raw = {"world": world.table if world is not None else None,
                "stand_in": [_thawed(item) for item in platform.stand_in], "figure": _table(file.data, "figure")}
    spec.settings, spec.file, spec.pt_log, spec.reader, spec.run_timing = s, file, pt_log, reader, run_timing
    return spec


def _model_errors(paths: list[Path | None], against_tree: Callable[[Any], list[Finding]] | None = None,
                  pmodel_name: str | None = None, stand_ins: dict | None = None) -> list[Finding]:
    """The errors of the model files a project names (read when the project itself has errors, so that the
    models' are reported with them rather than once the project is fixed), then those `against_tree` finds
    in the project against the p-model's kinematic tree (the [plant] joints); none if a file is missing.
    A tree that cannot be built adds nothing here: its errors come when the project is read without errors."""
    from ...pmodel.tree import build_tree
    from ...robosim.check import load_checked

    if not all(p is not None and file_problem(p) is None for p in paths):
        return []
    try:
        project = load_checked(paths)
    except CotwinError as err:
        return [f for f in err.findings if f.severity is Severity.ERROR]
    if against_tree is None:
        return []
    try:
        tree = build_tree(project, pmodel_name, stand_ins)
    except CotwinError:
        return []
    return against_tree(tree)


def _plant_problems(plant: Perturbation | None, tree, locate: Callable[[tuple], Location]) -> list[Finding]:
    """[plant]'s joints against the p-model's actuated joints: an error at each it names that the robot lacks.
    A project's problem whatever the command (as [plant]'s types are), reported with the project's others
    (by load_project when it has errors, else by the twin's models, cotwin.twin.assembly.system), so that
    `cotwin plant` does not find it in a round of its own once the rest is fixed."""
    from ...pmodel.perturbation import joint_problems

    return [] if plant is None else joint_problems(plant, tree, lambda key: locate(("plant", *key)))


def _robots(file: TomlFile, items: tuple, problems: list[Finding]) -> list[RobotSpec]:
    """[[robots]] resolved: names used once, files that exist."""
    out, seen = [], set()
    for i, r in enumerate(items):
        if r.name in seen:
            problems.append(Finding(file.location(("robots", i, "name")), Severity.ERROR,
                                    f"[[robots]] name: two robots are called {r.name!r}"))
        seen.add(r.name)
        paths = {}
        for key in ("pmodel", "mapping", "calibration"):
            value = getattr(r, key)
            paths[key] = None if value is None else file.path.parent / value
            what = None if value is None else file_problem(paths[key])
            if what is not None:
                problems.append(Finding(file.location(("robots", i, key)), Severity.ERROR,
                                        f"[[robots]] {key} of {r.name}: {what}"))
        out.append(RobotSpec(r.name, paths["pmodel"], paths["mapping"], paths["calibration"],
                             tuple(float(v) for v in r.xyz), tuple(float(v) for v in r.rpy), i))
    return out


def _table(data: dict, key: str) -> dict:
    value = data.get(key)
    return value if isinstance(value, dict) else {}


def _thawed(item) -> dict:
    from ...settings import tables as written

    return written(item)


def _pt(file: TomlFile, pt, pt_log: Path | None, existing, problems: list[Finding]) -> PTSettings | None:
    """[pt] resolved: its log found, or a command's --pt-log replayed in its place."""
    if pt_log is not None:
        return PTSettings("replay", pt.url, pt_log, pt.queue, pt.offset) if pt is not None else \
            PTSettings("replay", log=pt_log)
    if pt is None or pt.endpoint is None:
        return None
    if pt.endpoint in ("opcua", "rtde") and not pt.url:
        problems.append(Finding(file.location(("pt", "endpoint")), Severity.ERROR,
                                f"[pt] endpoint {pt.endpoint!r} needs a url"))
    if pt.endpoint == "replay" and not pt.log:
        problems.append(Finding(file.location(("pt", "endpoint")), Severity.ERROR,
                                "[pt] endpoint 'replay' needs log = \"<recorded log>\""))
    return PTSettings(pt.endpoint, pt.url, existing("pt", "log", pt.log), pt.queue, pt.offset)


def _timing(file: TomlFile, cosim, problems: list[Finding],
            run_timing: tuple[float | None, float | None] = (None, None)) -> None:
    """[cosim] step, end and the d-model's cycle_period checked together (`timing_problems`), when each
    was read well (a wrong value is already reported, and its default would mislead), and where a command's
    step or end (`run_timing`) does not take part: what the run does not take is not a problem of the run."""
    raw = _table(file.data, "cosim")
    parameters = raw.get("parameters") if isinstance(raw.get("parameters"), dict) else {}
    if "cosim" in file.data and not isinstance(file.data["cosim"], dict):
        return  # [cosim] itself is wrong (and reported)
    if any(key in raw and raw[key] != getattr(cosim, key) for key in ("step", "end")):
        return  # its step or end is wrong (and reported)
    period = parameters.get(CYCLE_PERIOD)
    where = ("cosim", "parameters", CYCLE_PERIOD)
    if period is not None and (not is_number(period) or period < 0):
        problems.append(Finding(file.location(where), Severity.ERROR, f"[cosim] parameters {CYCLE_PERIOD} must be "
                                f"a number >= 0 (s per d-model cycle; 0: one cycle per step), got {shown(period)}"))
        period = None
    step, end = run_timing
    for key, message in timing_problems(float(cosim.step), float(cosim.end), period):
        if step is not None or key == "end" and end is not None:
            continue  # the command's step takes part in each problem, its end in the end's: it says them
        at = where if key == CYCLE_PERIOD else ("cosim", key)
        name = f"parameters {key}" if key == CYCLE_PERIOD else key
        problems.append(Finding(file.location(at), Severity.ERROR, f"[cosim] {name}: {message}"))


PT_KEYS = {"opcua": ("url",), "rtde": ("url",), "replay": ("log", "offset"), "broker": ("queue", "url")}


def _pt_keys(file: TomlFile, pt) -> list[Finding]:
    """[pt] keys its endpoint takes (one it would ignore is an error) and its url, checked as that
    endpoint reads it."""
    raw = file.data.get("pt")
    if pt.endpoint not in PT_KEYS or not isinstance(raw, dict):
        return []  # the endpoint itself is wrong (and reported)
    out = [Finding(file.location(("pt", key)), Severity.ERROR, f"[pt] {key} does not apply to endpoint "
                   f"'{pt.endpoint}' (it takes {', '.join(PT_KEYS[pt.endpoint])})")
           for key in raw if key != "endpoint" and key not in PT_KEYS[pt.endpoint]]
    problem = None if pt.url is None else pt_url_problem(pt.endpoint, pt.url)
    if problem is not None:
        out.append(Finding(file.location(("pt", "url")), Severity.ERROR, f"[pt] url: {problem}"))
    return out


def pt_url_problem(endpoint: str, url: str) -> str | None:
    """What is wrong with a PT url for this endpoint kind ([pt] url, cotwin twin --pt-url), if anything:
    opcua: opc.tcp://HOST:PORT with a port in 1..65535; broker: an AMQP URL; rtde: a robot's host."""
    from ...diagnostics import CotwinError
    from ...mapping.opcua_auth import parse_url

    if endpoint == "opcua":
        try:
            _, port = parse_url(url)
        except CotwinError as err:
            return err.findings[0].message
        return None if 1 <= port <= 65535 else f"port {port} is not in 1..65535"
    if endpoint == "broker":
        return _amqp_url(url)
    if endpoint == "rtde" and not re.fullmatch(r"(rtde://)?[A-Za-z0-9_.\-\[\]:]+", url):
        return f"{url[:60]!r} is not a robot's host (rtde://HOST or HOST)"
    return None


def _world(file: TomlFile, s, existing, problems: list[Finding]):
    """The project's world: a file named by [platform] world, or a [world] table (not both)."""
    from ...pmodel.world import read_world

    named, table = s.platform.world, s.world
    if named is not None and table is not None:
        problems.append(Finding(file.location(("world",)), Severity.ERROR,
                                "give the world as [platform] world = \"<file>\" or as a [world] table, not both"))
        return None, None
    if s.platform.scene == "world" and named is None and table is None:
        problems.append(Finding(file.location(("platform", "scene")), Severity.ERROR,
                                "[platform] scene = \"world\" needs a world: [platform] world = \"<file>\" "
                                "or a [world] table"))
    try:
        if named is not None:
            path = existing("platform", "world", named)
            if path is None or file_problem(path) is not None:
                return None, None
            world_file = TomlFile(path, "world file")
            return read_world(world_file), world_file
        if table is not None:
            return read_world(file, ("world",)), None
    except CotwinError as err:
        problems.extend(err.findings)
    return None, None


def _scene(file: TomlFile, s, problems: list[Finding]) -> None:
    """[platform] scene and the [scene] keys, checked with the rest of the file (not in a later round, once
    the models are read): a kind named must be known and read every [scene] key, and a world given goes to
    a "world" scene. "auto" without a world chooses a kind from the mapping, checked when the models are
    read; here a [scene] key that no kind reads is already an error."""
    from ...pmodel import scenes

    if not isinstance(file.data.get("scene", {}), dict):
        return  # [scene] itself is wrong (and reported)
    options = _table(file.data, "scene")
    world = ("[platform] world", ("platform", "world")) if s.platform.world is not None else \
        ("[world]", ("world",)) if s.world is not None else None  # given, whether or not it could be read
    name = "world" if s.platform.scene == "auto" and world else s.platform.scene
    if name == "auto":
        read = sorted({k for kind in scenes.scene_kinds().values() for k in kind.options})
        problems.extend(Finding(file.location(("scene", key)), Severity.ERROR,
                                f"[scene] {key}: no scene kind reads it (keys read: {', '.join(read) or 'none'})"
                                f"{did_you_mean(key, read)}") for key in options if key not in read)
        return
    try:
        kind = scenes.scene_kind(name, file.location(("platform", "scene")))
    except CotwinError as err:
        problems.extend(err.findings)
        return
    problems.extend(scenes.unread_options(kind, s.platform.scene, options, lambda *key: file.location(key)))
    if world is not None and kind.name != "world":
        problems.append(Finding(file.location(world[1]), Severity.ERROR, f"{world[0]}: the scene is '{kind.name}' "
                                f"([platform] scene = \"{s.platform.scene}\"), which would ignore it"))


def _stand_ins(file: TomlFile, items: tuple, problems: list[Finding]) -> dict:
    """[[platform.stand_in]] as the kinematic tree takes them: mesh file as written -> its stand-ins."""
    from ...pmodel.tree import StandIn, transform

    out: dict = {}
    for i, item in enumerate(items):
        at = ("platform", "stand_in", i)
        if item.shape not in SHAPES or item.mesh is None or not isinstance(item.size, tuple):
            continue  # reported where it is read
        names = SHAPES[item.shape]
        size = item.size
        if len(size) != len(names) or not all(is_number(x) and 0 < x <= STAND_IN_EXTENT for x in size):
            problems.append(Finding(file.location(at + ("size",)), Severity.ERROR,
                                    f"[[platform.stand_in]] size of a {item.shape} is {len(names)} positive number(s) "
                                    f"({', '.join(names)}) of at most {STAND_IN_EXTENT:g} m, got {shown(list(size))}"))
            continue
        out.setdefault(item.mesh, []).append(StandIn(item.shape, dict(zip(names, map(float, size))),
                                                     transform(tuple(item.pos), tuple(item.rpy)), item.friction))
    return out


def _panels(file: TomlFile, items: tuple, problems: list[Finding]):
    out = []
    for i, item in enumerate(items):
        at = ("figure", "panels", i)
        bad = [name for name in item.variables or () if name.count(".") != 1 or not all(name.split("."))]
        if bad:
            problems.append(Finding(file.location(at + ("variables",)), Severity.ERROR,
                                    f"[figure] panel variables are written unit.variable (dmodel.lv, mapping.x), "
                                    f"got {', '.join(map(repr, bad))}"))
        elif item.variables is not None:
            out.append((item.label, list(item.variables), item.style))
    return out
