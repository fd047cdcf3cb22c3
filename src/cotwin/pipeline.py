"""A twin project (`cotwin.toml`): from the three models to FMUs, a Maestro multimodel and a run.

    [models]                       # paths relative to this file
    dmodel = "arm.rst"
    pmodel = "ur5e.pm"
    mapping = "mapping.pm"
    module = "FlexCellArm"         # optional: the d-model module
    [scenario]
    plan = "plan.csv"              # or: commands = "scenario.toml"
    [platform]
    endpoint = "mujoco"            # the embedded simulator (default), or "broker": a robot behind
    queue = "cotwin.robot"         #   RabbitMQ answering on this queue (cotwin.mapping.broker)
    url = "amqp://guest:guest@127.0.0.1:5672/%2F"
    bricks = [[8, 10]]             # optional: bricks on holes (X, Y)
    [cosim]
    step = 0.1
    end = 20.0
    algorithm = "jacobi"           # or "gauss-seidel"
    log = ["q0", "q1"]             # optional: mapping variables to log (default: all monitored)
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .diagnostics import CotwinError, Finding, Location, Severity

DMODEL, MAPPING, CONTROLLER = "{dmodel}.dmodel", "{mapping}.mapping", "{controller}.controller"
_KEYS = {"models": {"dmodel", "pmodel", "mapping", "module", "pmodel_name"},
         "scenario": {"plan", "commands"}, "platform": {"endpoint", "bricks", "queue", "url"},
         "cosim": {"step", "end", "algorithm", "log", "realtime"}}


def _err(path, message) -> CotwinError:
    return CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, message)])


@dataclass
class TwinProject:
    path: Path
    dmodel: Path
    pmodel: Path
    mapping: Path
    scenario: Path
    module: str | None = None
    pmodel_name: str | None = None
    endpoint: str = "mujoco"
    bricks: list[tuple[int, int]] = field(default_factory=list)
    step: float = 0.1
    end: float = 20.0
    algorithm: str = "jacobi"
    log: list[str] | None = None
    realtime: bool = False
    queue: str = "cotwin.robot"
    url: str = "amqp://guest:guest@127.0.0.1:5672/%2F"

    @property
    def model_files(self) -> list[Path]:
        return [self.dmodel, self.pmodel, self.mapping]


def _toml(tables: dict[str, dict]) -> str:
    """TOML for flat tables of strings, numbers and lists (JSON's quoting is valid TOML)."""
    lines = []
    for table, values in tables.items():
        lines.append(f"[{table}]")
        lines.extend(f"{key} = {json.dumps(value)}" for key, value in values.items())
    return "\n".join(lines) + "\n"


def python_unit(project: str | Path, role: str):
    """A cotwin in-process unit of a twin project by role (used inside cotwin's Python FMUs)."""
    twin = Twin(load_twin_project(project))
    controller = twin.controller_unit()
    if role == "controller":
        return controller
    if role == "mapping":
        return twin.mapping_unit(controller.command_events)
    raise CotwinError(f"unknown unit role '{role}'")


def load_twin_project(path: str | Path) -> TwinProject:
    """Read cotwin.toml, reporting unknown keys, wrong types and missing files with the file's name."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as err:
        raise _err(path, f"cannot read project file: {err}") from None
    except tomllib.TOMLDecodeError as err:
        line = getattr(err, "lineno", 1) or 1
        raise CotwinError([Finding(Location(str(path), line, getattr(err, "colno", 1) or 1), Severity.ERROR,
                                   f"bad TOML: {err.args[0] if err.args else err}")]) from None
    problems = []
    for section, values in data.items():
        if section not in _KEYS:
            problems.append(f"unknown section [{section}] (known: {', '.join(_KEYS)})")
            continue
        for key in values:
            if key not in _KEYS[section]:
                problems.append(f"unknown key '{key}' in [{section}] (known: {', '.join(sorted(_KEYS[section]))})")
    models, scenario = data.get("models", {}), data.get("scenario", {})
    platform, cosim = data.get("platform", {}), data.get("cosim", {})
    base = path.parent
    files = {}
    for key in ("dmodel", "pmodel", "mapping"):
        if key not in models:
            problems.append(f"[models] needs '{key}'")
        else:
            files[key] = base / models[key]
            if not files[key].is_file():
                problems.append(f"[models] {key}: no file {files[key]}")
    scen = scenario.get("plan") or scenario.get("commands")
    if scen is None:
        problems.append("[scenario] needs 'plan' (CSV) or 'commands' (TOML)")
    elif not (base / scen).is_file():
        problems.append(f"[scenario]: no file {base / scen}")
    for key, kind in (("step", (int, float)), ("end", (int, float))):
        if key in cosim and (not isinstance(cosim[key], kind) or isinstance(cosim[key], bool) or cosim[key] <= 0):
            problems.append(f"[cosim] {key} must be a positive number, got {cosim[key]!r}")
    if cosim.get("algorithm", "jacobi") not in ("jacobi", "gauss-seidel"):
        problems.append(f"[cosim] algorithm must be 'jacobi' or 'gauss-seidel', got {cosim['algorithm']!r}")
    if platform.get("endpoint", "mujoco") not in ("mujoco", "broker"):
        problems.append(f"[platform] endpoint {platform['endpoint']!r} is not known (known: mujoco, broker)")
    bricks = platform.get("bricks", [])
    if not (isinstance(bricks, list) and all(isinstance(b, list) and len(b) == 2 and all(isinstance(v, int) for v in b)
                                             for b in bricks)):
        problems.append("[platform] bricks must be a list of [X, Y] hole pairs")
        bricks = []
    if problems:
        raise CotwinError([Finding(Location(str(path), 1, 1), Severity.ERROR, p) for p in problems])
    return TwinProject(path, files["dmodel"], files["pmodel"], files["mapping"], base / scen, models.get("module"),
                       models.get("pmodel_name"), platform.get("endpoint", "mujoco"), [tuple(b) for b in bricks],
                       float(cosim.get("step", 0.1)), float(cosim.get("end", 20.0)), cosim.get("algorithm", "jacobi"),
                       cosim.get("log"), bool(cosim.get("realtime", False)), platform.get("queue", "cotwin.robot"),
                       platform.get("url", "amqp://guest:guest@127.0.0.1:5672/%2F"))


class Twin:
    """Everything built from a project: the checked models, the d-model program, tree, scene, units."""

    def __init__(self, twin: TwinProject):
        from .dmodel.program import build_program
        from .pmodel.scene import Brick, FlexCell
        from .pmodel.tree import build_tree
        from .robosim.check import load_checked
        from .robosim.pmodel_elements import Mapping as MappingModel
        from .cosim.scenario import read_scenario

        self.spec = twin
        self.project = load_checked(twin.model_files)
        self.program = build_program(self.project, twin.module)
        self.tree = build_tree(self.project, twin.pmodel_name)
        mappings = self.project.elements(MappingModel)
        self.scene = FlexCell.from_mapping(mappings[0], [Brick(f"brick{i + 1}", b) for i, b in enumerate(twin.bricks)])
        self.commands = read_scenario(twin.scenario, self.program)
        self.mapping_model = mappings[0]
        from .mapping.runtime import mirror_variables
        from .pmodel import ik

        arm = ik.arm_joints(self.tree, ik.find_tool(self.tree))
        self.monitored = list(mirror_variables([v.name for v in self.mapping_model.variables], arm))

    # ---- artefacts ----
    def build(self, out: str | Path) -> dict[str, Path]:
        from .dmodel.fmu import build_fmu
        from .pmodel.mjcf import to_mjcf
        from .pmodel.sdf import to_sdf
        from .pmodel.urdf import to_urdf

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        written = {"dmodel": build_fmu(self.program, out / "dmodel.fmu")}
        for name, text in ((f"{self.tree.name}.sdf", to_sdf(self.tree)), (f"{self.tree.name}.urdf", to_urdf(self.tree)),
                           (f"{self.tree.name}_scene.xml", to_mjcf(self.tree, self.scene))):
            (out / name).write_text(text)
            written[name] = out / name
        written.update(self.python_fmus(out))
        written["multimodel"] = out / "multimodel.json"
        written["multimodel"].write_text(json.dumps(self.multimodel(), indent=2) + "\n")
        return written

    def python_fmus(self, out: str | Path) -> dict[str, Path]:
        """mapping.fmu and controller.fmu: the in-process units packaged with pythonfmu (they need
        cotwin installed where they run), so the multimodel runs in Maestro or any FMI importer."""
        import shutil
        import tempfile

        from pythonfmu import FmuBuilder

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        written = {}
        spec = self.spec
        with tempfile.TemporaryDirectory(prefix="cotwin-pyfmu-") as tmp:
            stage = Path(tmp) / "twin"
            stage.mkdir()
            names = {}
            for key, path in (("dmodel", spec.dmodel), ("pmodel", spec.pmodel), ("mapping", spec.mapping),
                              ("scenario", spec.scenario)):
                shutil.copy(path, stage / path.name)
                names[key] = path.name
            scenario_key = "commands" if spec.scenario.suffix == ".toml" else "plan"
            models = {k: names[k] for k in ("dmodel", "pmodel", "mapping")} | ({"module": spec.module} if spec.module else {})
            (stage / "cotwin.toml").write_text(_toml({
                "models": models, "scenario": {scenario_key: names["scenario"]},
                "platform": {"bricks": [list(b) for b in spec.bricks]}, "cosim": {"step": spec.step, "end": spec.end}}))
            script = Path(__file__).parent / "cosim" / "pythonfmu_slave.py"
            for role in ("mapping", "controller"):
                (stage / "cotwin_unit.json").write_text(json.dumps({"role": role, "project": "twin/cotwin.toml"}))
                work = Path(tmp) / role
                work.mkdir()
                shutil.copy(script, work / "pythonfmu_slave.py")
                shutil.copytree(stage, work / "twin")
                shutil.copy(stage / "cotwin_unit.json", work / "cotwin_unit.json")
                fmu = FmuBuilder.build_FMU(work / "pythonfmu_slave.py", dest=work,
                                           project_files=[work / "twin", work / "cotwin_unit.json"])
                target = out / f"{role}.fmu"
                shutil.move(str(fmu), target)
                written[role] = target
        return written

    def units(self, dmodel_fmu: Path):
        from .cosim.units import FMUUnit

        controller = self.controller_unit()
        return controller, FMUUnit(DMODEL, dmodel_fmu), self.mapping_unit(controller.command_events)

    def controller_unit(self):
        from .cosim.scenario import ScenarioUnit

        return ScenarioUnit(CONTROLLER, self.program, self.commands)

    def mapping_unit(self, commands: set[str]):
        from .mapping.endpoint import SimulatedEndpoint
        from .mapping.runtime import Mapping
        from .mapping.unit import MappingUnit
        from .pmodel.simulator import PlatformSimulator

        if self.spec.endpoint == "broker":
            from .mapping.broker import BrokerEndpoint

            endpoint = BrokerEndpoint(self.tree, self.spec.queue, self.spec.url)
        else:
            endpoint = SimulatedEndpoint(PlatformSimulator(self.tree, self.scene))
        return MappingUnit(MAPPING, self.program, Mapping(self.project, endpoint), commands)

    def wiring(self):
        """Every connection of the twin, derived once from the models and used both by `run` and by
        the multimodel: scenario -> d-model commands, d-model calls -> mapping, mapping events ->
        d-model (the mapping's outputs are declared delayed: they break the d-model/mapping cycle)."""
        from .cosim.master import Connection
        from .cosim.scenario import scenario_ports
        from .dmodel.fmu import PortLayout
        from .mapping.unit import mapping_ports

        commands = {p for c in self.commands for p, _ in c.values}
        command_events = commands & {ev.name for ev in self.program.inputs}
        mapped = {ev.name for ev in self.mapping_model.input_events}
        dmodel_inputs = {v.name for v in PortLayout(self.program).variables if v.causality == "input"}
        out = [Connection(CONTROLLER, p, DMODEL, p) for p in scenario_ports(self.program) if p in commands]
        for port in mapping_ports(self.program, mapped, command_events, self.monitored):
            if port.causality == "input":
                out.append(Connection(DMODEL, port.name, MAPPING, port.name))
            elif port.name in dmodel_inputs:
                out.append(Connection(MAPPING, port.name, DMODEL, port.name))
        return out

    def log_variables(self) -> dict[str, list[str]]:
        names = self.spec.log if self.spec.log is not None else self.monitored
        unknown = [n for n in names if n not in self.monitored]
        if unknown:
            raise _err(self.spec.path, f"[cosim] log: unknown mapping variable(s) {', '.join(unknown)} "
                       f"(monitored: {', '.join(self.monitored) or 'none'})")
        return {MAPPING: list(names), DMODEL: [self.program.state_port(m) for m in self.program.machines]}

    def multimodel(self) -> dict:
        """The Maestro multimodel of this twin; `cotwin` holds what Maestro ignores (delays)."""
        connections: dict[str, list[str]] = {}
        for c in self.wiring():
            connections.setdefault(f"{c.source}.{c.output}", []).append(f"{c.target}.{c.input}")
        return {
            "fmus": {"{dmodel}": "dmodel.fmu", "{mapping}": "mapping.fmu", "{controller}": "controller.fmu"},
            "connections": connections,
            "parameters": {},
            "logVariables": self.log_variables(),
            "algorithm": {"type": "fixed-step", "size": self.spec.step},
            "startTime": 0.0,
            "endTime": self.spec.end,
            "simulationProgramDelay": self.spec.realtime,
            "cotwin": {"delayed": [MAPPING], "algorithm": self.spec.algorithm},
        }

    def run(self, out: str | Path, step: float | None = None, end: float | None = None,
            algorithm: str | None = None, progress=None, plot: bool = True):
        """Co-simulate; writes out/outputs.csv (and out/figure.png). Returns the master's result."""
        from .cosim.master import Master

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        fmu = out / "dmodel.fmu"
        if not fmu.is_file():
            self.build(out)
        controller, dmodel, mapping = self.units(fmu)
        master = Master([controller, dmodel, mapping], self.wiring(), step or self.spec.step, end or self.spec.end,
                        algorithm=algorithm or self.spec.algorithm, delayed={MAPPING}, log=self.log_variables(),
                        realtime=self.spec.realtime)
        self.last_mapping = mapping
        result = master.run(out / "outputs.csv", progress=progress)
        if plot:
            from .plot import figure

            figure(out / "outputs.csv", out / "figure.png", title=f"{self.program.module.name}: step {master.step_size:g} s, "
                   f"{master.algorithm}")
        return result
