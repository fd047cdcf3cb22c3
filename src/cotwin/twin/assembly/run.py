"""Run one twin (`cotwin run`): its TwinSystem against the project's platform, a Maestro-format CSV and a
figure; and the units cotwin's Python FMUs carry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ...cosim.algorithm import algorithm as make_algorithm
from ...cosim.execution import Execution, RunResult, ended_early
from ...cosim.observers import CSVWriter, Observer, Progress, RealTimePacer, StateFile
from ...cosim.system import System
from ...diagnostics import CotwinError, Finding, Interrupted
from ...dmodel.program import time_readings
from .build import ARTEFACTS, dmodel_fmu, folder_lock
from ..project import TwinProject, check_timing, cycle_time_warnings, load_project
from .system import MAPPING, TwinSystem
from .outcomes import CommandLedger, not_applied, saturated_joints
from .waits import WaitWatch


RUN_FILES = ("outputs.csv", "outputs.partial.csv", "outputs.csv.part", "state", "figure.png", "path.png", *ARTEFACTS)


def dt_endpoint(system: TwinSystem):
    """The platform of the project's (digital) twin, as its [platform] endpoint names it
    (cotwin.twin.assembly.endpoints): the embedded simulator (calibrated when the project names a calibration), a
    robot behind the broker, or a kind registered from outside the core."""
    from .endpoints import make_endpoint

    return make_endpoint(system, "dt")


def simulated_endpoint(system: TwinSystem, timestep: float | None = None):
    """The embedded simulator of the twin's models, calibrated when the project names a calibration (the
    cell's geometry and the motion profile fitted to the PT): the DT, a what-if fork, a sweep's runs; its
    physics steps of `timestep` s (None: cotwin's 1 ms)."""
    from ...mapping.endpoint import SimulatedEndpoint
    from ...pmodel.simulator import PlatformSimulator

    from .convergence import estimates_payload, payload_simulator

    models = system.models
    calibration = models.calibration
    physics = {} if timestep is None else {"timestep": timestep}
    sim = payload_simulator(models.tree, models.scene, system.spec.base, tool=models.tool, **physics) \
        if estimates_payload(system.spec) \
        else PlatformSimulator(models.tree, models.scene, base=system.spec.base, **physics)  # [convergence]: a payload
    return SimulatedEndpoint(sim, calibration and calibration.profile, calibration and calibration.geometry)


def python_unit(project: str | Path, role: str, instance: str = ""):
    """A cotwin in-process unit of a twin project by role (inside cotwin's Python FMUs). In a cell of several
    robots the FMU's `instance` (its instance name's last part) names the robot whose command source it is."""
    spec = load_project(project)
    if spec.robots:
        from .cell import CellSystem

        return CellSystem(spec).python_unit(role, instance.rsplit(".", 1)[-1])
    system = TwinSystem(spec)
    if role == "mapping":
        return system.mapping_unit(lambda: dt_endpoint(system))
    if system.source is not None and role == system.source.instance:
        return system.source_unit()
    raise CotwinError(f"unknown unit role '{role}' for {project}")


@dataclass
class TwinRun:
    """What `run_twin` ran: the execution's result, where it wrote, and the units (for inspection)."""

    result: RunResult
    csv: Path
    figure: Path | None
    system: System
    units: dict[str, object] = field(default_factory=dict)
    blocked: list = field(default_factory=list)  # cotwin.twin.assembly.waits.Blocked: waits for answers that cannot come
    outcomes: object = None  # cotwin.twin.assembly.outcomes.Summary: what became of every command

    @property
    def mapping(self):
        return self.units["mapping"]


def run_twin(system: TwinSystem, out: str | Path, step: float | None = None, end: float | None = None,
             algorithm: str | None = None, realtime: bool | None = None, observers: list[Observer] | None = None,
             progress=None, plot: bool = True, endpoint=None, source=None, cc: str = "cc",
             restart: bool = False, fmi: int = 2, cycle_period: float | None = None, fused: bool = True) -> TwinRun:
    """Co-simulate the twin into `out` (outputs.csv, figure.png), building the d-model FMU if it is
    missing or stale. The folder is locked for the run; a failed run keeps the previous result. With
    `restart`, a failed step of the d-model FMU is retried in a new process from its last good state. With
    `fmi` 3 the d-model is the FMI 3.0 FMU, its cycle a clock ticking every `cycle_period` (default: the
    project's, else every step), a whole number of steps (cotwin.twin.assembly.clocked). `fused`: step in the fused
    loop where it applies (cotwin.cosim.fused, the same CSV byte for byte); False forces the master's
    step-by-step loop (the FMU path); the result's `stepping` says which ran."""
    out = Path(out)
    spec = system.spec
    end = spec.end if end is None else end
    step = spec.step if step is None else step
    check_timing(spec, step, end)
    if fmi == 3:
        from .clocked import clock_period

        if restart:
            raise CotwinError("restart-from-state is for FMI 2.0 FMUs: the FMI 3.0 d-model runs in cotwin's process")
        cycle_period = clock_period(spec, step, cycle_period)
    if endpoint is None:
        from .endpoints import check_endpoints

        check_endpoints(system, "dt")  # a kind no one registered: said before the d-model is built
    with folder_lock(out, RUN_FILES, spec.inputs):
        fmu = dmodel_fmu(system, out, cc, fmi=fmi)
        endpoint = endpoint if endpoint is not None else dt_endpoint(system)
        if fmi == 3:
            from .clocked import clocked_system

            cosim = clocked_system(system, fmu, endpoint, cycle_period, source)
        else:
            cosim = system.instantiate(fmu, endpoint, source=source, restart=restart)
        units = {u.role if u.role != "source" else "source": cosim.units[u.name] for u in system.units}
        writer = CSVWriter(out / "outputs.csv")
        watch, ledger = WaitWatch(system), CommandLedger(system)
        chain: list[Observer] = [writer, StateFile(out / "state"), watch, ledger, *(observers or [])]
        if progress is not None:
            chain.append(Progress(progress))
        if spec.realtime if realtime is None else realtime:
            chain.append(RealTimePacer())
        execution = Execution(cosim, make_algorithm(algorithm or spec.algorithm), step, 0.0, chain, fused=fused)
        try:
            result = execution.run(end)
        except (CotwinError, KeyboardInterrupt) as err:
            raise ended_early(err, execution.time, writer.kept()) from None
        figure = None
        try:
            if plot:
                from ...plot import figure as draw

                figure = draw(out / "outputs.csv", out / "figure.png", figure_panels(system),
                              title=f"{system.models.program.module.name}: step {step:g} s, {result.algorithm}")
                path = path_columns(system)
                if path is not None:
                    from ...plot import top_view

                    top_view(out / "outputs.csv", out / "path.png", system.models.scene, path,
                             title=f"{system.models.program.module.name} in "
                                   f"{system.models.scene.name or 'its world'}: {end:g} s")
        except KeyboardInterrupt:  # the run itself is done: say that its rows are all there
            raise Interrupted(f"interrupted while drawing the figure; the run is complete: {result.rows} row(s) "
                              f"to t = {result.end_time:g} s in {out / 'outputs.csv'}") from None
        return TwinRun(result, out / "outputs.csv", figure, cosim, units, watch.found,
                       ledger.summary(watch.found, not_applied(units.get("source")), saturated_joints(endpoint)))


def path_columns(system: TwinSystem) -> tuple[str, str] | None:
    """The columns of the robot's x and y in a world (monitored readings of its free base's pose), if any."""
    from ...pmodel.mjcf import pose_paths

    scene = system.models.scene
    if scene is None or not scene.walkable:
        return None
    x_path, y_path = pose_paths(system.models.tree)[:2]
    by_path = {path: name for name, path in system.spec.readings.items()}
    logged = system.log[MAPPING.name]
    if by_path.get(x_path) in logged and by_path.get(y_path) in logged:
        return f"{MAPPING.name}.{by_path[x_path]}", f"{MAPPING.name}.{by_path[y_path]}"
    return None


def figure_panels(system: TwinSystem) -> list[tuple[str, list[str], str]]:
    """The project's [figure] panels, or those of the paper's Fig. 16 chosen from the models: the commands
    and their values, the platform's events and the values they carry, the d-model's operation calls and
    their arguments, and the mapping's monitored variables."""
    from ...dmodel.ports import PortLayout

    if system.spec.panels is not None:
        units = {u.role: u.name for u in system.units} | {u.instance: u.name for u in system.units}
        return [(label, [f"{units.get(v.split('.')[0], v.split('.')[0])}.{v.split('.')[1]}" for v in names], style)
                for label, names, style in system.spec.panels]
    source = system.source.name if system.source is not None else None
    events = [p for p in system.source_ports if p in system.command_events]
    values = [p for p in system.source_ports if p not in system.command_events]
    layout = PortLayout(system.models.program)
    calls = [op.flag.name for op in layout.operations]
    args = list(dict.fromkeys(v.var.name for op in layout.operations for _, vs in op.args for v in vs))
    dmodel = "{dmodel}.dmodel"
    platform = [ev for ev in system.models.program.inputs if ev.name not in system.command_events
                and ev.name in {e.name for e in system.models.mapping_model.input_events}]
    return [("(1) commands [1 = sent]", [f"{source}.{p}" for p in events], "steps-post"),
            ("(2) command values [model units]", [f"{source}.{p}" for p in values], "steps-post"),
            ("(2b) platform event values [model units]",
             [f"{MAPPING.name}.{port}" for ev in platform for port, _ in ev.value_ports], "steps-post"),
            ("(3) d-model operation calls [1 = called]", [f"{dmodel}.{c}" for c in calls], "steps-post"),
            ("(3b) operation arguments [model units]", [f"{dmodel}.{a}" for a in args], "steps-post"),
            *monitored_panels(system, "(4)")]


#: the unit of a sensor's reading by its quantity (joint quantities take their joint's: rad or m)
QUANTITY_UNITS = {"gyro": "rad/s", "velocimeter": "m/s", "accelerometer": "m/s²", "closest_range": "m",
                  "range": "m", "closest_bearing": "deg", "effort": "N m"}
POSE_UNITS = {"x": "m", "y": "m", "z": "m", "yaw": "rad"}


def monitored_units(system: TwinSystem) -> dict[str, tuple[str, str]]:
    """Each monitored mapping variable's quantity and unit (q0: joint angle, rad; qd0: joint speed,
    rad/s; a reading: its sensor's), so that a figure draws each unit on its own axis."""
    from ...pmodel.mjcf import pose_paths
    from ...pmodel.tree import reading_path

    tree = system.models.tree
    kinds = {j.name: j.kind for j in tree.actuated}
    out: dict[str, tuple[str, str]] = {}
    for name, (joint, kind) in system.models.mirrors.items():  # the joints the mapping mirrors
        linear = kinds.get(joint) == "prismatic"
        out[name] = (("joint position", "m") if linear else ("joint angle", "rad")) if kind == "position" else \
            (("joint speed", "m/s") if linear else ("joint speed", "rad/s"))
    sensors = {reading_path(tree.name, s): s for s in tree.sensors}
    pose = dict(zip(pose_paths(tree), POSE_UNITS))
    for name, path in system.spec.readings.items():
        if path in pose:
            out[name] = (f"base {pose[path]}", POSE_UNITS[pose[path]])
        elif path in sensors:
            sensor = sensors[path]
            unit = QUANTITY_UNITS.get(sensor.quantity, "")
            if sensor.quantity in ("position", "velocity"):
                linear = kinds.get(sensor.joint) == "prismatic"
                unit = ("m" if linear else "rad") + ("/s" if sensor.quantity == "velocity" else "")
            out[name] = (sensor.quantity.replace("_", " "), unit)
    return out


def monitored_panels(system: TwinSystem, number: str) -> list[tuple[str, list[str], str]]:
    """The monitored variables, one panel per unit (angles apart from speeds), each labelled with it."""
    units = monitored_units(system)
    groups: dict[tuple[str, str], list[str]] = {}
    for v in system.log[MAPPING.name]:
        groups.setdefault(units.get(v, ("monitored", "")), []).append(f"{MAPPING.name}.{v}")
    letters = "abcdefghijklmnopqrstuvwxyz"
    return [(f"{number}{letters[k] if len(groups) > 1 else ''} {what}" + (f" [{unit}]" if unit else " [unit unknown]"),
             names, "default") for k, ((what, unit), names) in enumerate(groups.items())]


def load(project: str | Path | TwinProject, cells: bool = False, reader: str | None = None) -> TwinSystem:
    """The TwinSystem of a project file (or an already read project). A cell of several robots ([[robots]])
    is a CellSystem (cotwin.twin.assembly.cell) for a caller that takes one (`cells`), else a located error: what
    takes a twin of one robot cannot take it. `reader`: the command (load_project: one that ignores [pt] does not
    look for its log)."""
    spec = project if isinstance(project, TwinProject) else load_project(project, reader=reader)
    if spec.robots:
        if not cells:
            from ...diagnostics import Finding, Severity

            raise CotwinError([Finding(spec.location("robots"), Severity.ERROR, "[[robots]]: this takes a twin of "
                                       "one robot; a cell of several robots runs under `cotwin run` and `cotwin twin`")])
        from .cell import CellSystem

        return CellSystem(spec)
    return TwinSystem(spec)


def step_warnings(system: TwinSystem, step: float | None, cycle_period: float | None = None) -> list[Finding]:
    """What a run of `system` at a command's `step` (None: the project's own) says before it starts: a warning at
    the d-model's first reading of time when the step is not the project's and no cycle_period fixes the d-model's
    cycle (cotwin.twin.project.cycle_time_warnings); `cycle_period` given (an FMI 3.0 clock's) fixes it."""
    if step is None or cycle_period is not None:
        return []
    return cycle_time_warnings(system.spec, time_readings(system.models.program), step)


__all__ = ["MAPPING", "TwinRun", "dt_endpoint", "load", "python_unit", "run_twin", "step_warnings"]
