"""A twin project (`cotwin.toml`): the three models, where commands come from, the platform, the
co-simulation settings and, for a live twin, the physical twin, deviation checking and history.

    [models]                        # paths relative to this file
    dmodel = "arm.rst"
    pmodel = "ur5e.pm"
    mapping = "mapping.pm"
    module = "FlexCellArm"          # optional: the d-model module; pmodel_name likewise
    fmu = "dmodel.fmu"              # optional: a d-model FMU built elsewhere, run in place of the one
                                    #   cotwin builds from dmodel (its ports must be the module's)
    [scenario]                      # where commands come from: one of
    plan = "plan.csv"               #   a TwinManager plan (ms, port values)
    commands = "scenario.toml"      #   a TOML list of [[command]]
    rabbitmq = { exchange = "fmi_digital_twin_dt" }   # live, as the RMQ FMU takes them
                                    #   (url, to_cosim, from_cosim, maxage_ms, timeout_s, max_skew_s: see twin.rabbitmq;
                                    #   commands: the d-model events it sends, default those the
                                    #   mapping does not produce)
    [platform]                      # the DT's robot
    endpoint = "mujoco"             # the embedded simulator, or "broker": a robot behind RabbitMQ
    queue = "cotwin.robot"          #   (its request queue and broker url)
    scene = "auto"                  # around the robot: "flexcell" (built from the mapping's constants),
                                    #   "world" (a world file or [world] table), "none"; "auto": the
                                    #   world if one is given, else the Flex-cell if the mapping has
                                    #   its constants, else none
    bricks = [[8, 10]]              # Flex-cell: bricks standing on holes (X, Y)
    world = "arena.toml"            # a world to walk in (cotwin.pmodel.world), or a [world] table here
    base = "fixed"                  # the robot's base: fixed to the world, or "free" (a mobile robot)
    [[platform.stand_in]]           # a shape standing in for a mesh file the p-model names but that
    mesh = "meshes/base.stl"        #   cannot be read (as the p-model writes its name)
    shape = "box"                   #   box | cylinder | sphere | capsule
    size = [0.14, 0.14, 0.17]       #   box: length, width, height; cylinder, capsule: radius, length;
                                    #   sphere: radius (m)
    pos = [0.0, 0.0, 0.0]           #   in the mesh's frame (m); rpy = [roll, pitch, yaw] (rad)
    friction = 0.0                  #   its own sliding friction (0: a frictionless skid), optional
    [monitor]                       # the mapping's monitored variables (logged; compared PT vs DT)
    joints = "arm"                  # the joints its q<i>/qd<i> mirror: "arm" (base to tool), "actuated",
                                    #   or a list of names
    readings = { x = "robot::base.x" }  # more: name -> a platform reading by path
    [cosim]
    step = 0.1                      # a whole number of the simulator's 1 ms physics steps
    end = 20.0                      # a whole number of steps (never rounded), at most 1e8 of them
    algorithm = "jacobi"            # or "gauss-seidel"
    realtime = false                # pace to wall-clock time
    log = ["q0", "q1"]              # mapping variables to log (default: every monitored one)
    parameters = { seed = 7 }       # d-model FMU parameters (its random seed, constants without value;
                                    #   cycle_period, if given, divides the step into whole cycles)
    isolate = true                  # the d-model FMU in a process of its own (cotwin.cosim.isolated): a
                                    #   crash or hang in it is a located error (default: only an FMU
                                    #   cotwin did not build, [models] fmu)
    unit_timeout = 30.0             # s an isolated FMU's call may take before it counts as hanging
    [figure]                        # the figure of `cotwin run` (default: panels chosen from the models)
    panels = [{ label = "(1) lv", variables = ["dmodel.lv"] }]  # unit role . variable, per panel
    [pt]                            # the physical twin of `cotwin twin`
    endpoint = "opcua"              # opcua | replay | broker | rtde
    url = "opc.tcp://127.0.0.1:4840"
    log = "rtde_run1.csv"           # replay: the recorded log
    [deviation]
    variables = ["q0", "q1"]        # default: the logged variables
    absolute = 0.05                 # alarm when |PT - DT| > max(absolute, relative * |PT|)
    relative = 0.0
    lag_steps = 3                   # a DT lagging by at most this many steps is not deviating
    debounce_steps = 2              # consecutive deviating steps before an alarm is raised
    [history]
    url = "sqlite:///history.sqlite"  # or postgresql://...; default: DIR/history.sqlite
    [convergence]                   # a live twin's DT pulled towards its PT (cotwin.twin.convergence)
    resync = "on-alarm"             # "never" | "on-alarm" | "every N steps": PT joint state into the DT
    estimate = "payload"            # "none" | "payload": the tool's load from the PT's joint torques
    payload_std = 0.05              # kg: applied to the DT once the estimate's std is below this
    [plant]                         # the stand-in cell of `cotwin plant` (cotwin.pmodel.perturbation)
    seed = 7
    payload = 2.0                   # kg at the tool
    friction = { elbow_joint = 1.5 }  # Coulomb friction, N m (or N); a number: every joint
    damping = 2.0                   # scale of the joints' damping; or a table by joint
    latency_ms = 20                 # goals take effect this late
    noise = { position = 0.001 }    # Gaussian std by sensor quantity; a number: all

Every problem is reported at its key's line and column, all together (cotwin.config).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from ..config import Key, Schema, TomlFile, is_number, raise_problems, shown, unique, within
from ..diagnostics import CotwinError, Finding, Location, Severity
from ..cosim.execution import step_count
from ..cosim.isolated import DEFAULT_TIMEOUT
from ..pmodel.mjcf import TIMESTEP as PHYSICS_STEP
from ..pmodel.perturbation import SCHEMA as PLANT, Perturbation

ENDPOINTS = ("mujoco", "broker")
SCENES = ("auto", "flexcell", "world", "none")
PT_ENDPOINTS = ("opcua", "replay", "broker", "rtde")
MAX_CYCLES_PER_STEP = 10 ** 6  # d-model cycles in one step ([cosim] parameters cycle_period)
MAX_WAIT_S = 86_400.0  # s: the longest a twin waits for, or keeps, a broker message
MAX_LAG_STEPS = 10 ** 6  # [deviation] lag_steps and debounce_steps
CYCLE_PERIOD = "cycle_period"  # the d-model FMU's parameter: seconds per cycle (cotwin.dmodel.ports)
AMQP_MAX = 255  # bytes of an AMQP 0-9-1 short string: exchange, queue and routing-key names
_AMQP_NAME = re.compile(r"[A-Za-z0-9_.:-]+")


def amqp_name_problem(value: str) -> str | None:
    """Why `value` cannot name an exchange or queue the twin declares (RabbitMQ's rules), or None."""
    if not value:
        return "must not be empty"
    if len(value.encode("utf-8")) > AMQP_MAX:
        return f"is {len(value.encode('utf-8'))} bytes long; AMQP names hold at most {AMQP_MAX}"
    if not _AMQP_NAME.fullmatch(value):
        return f"may hold only letters, digits and '-', '_', '.', ':', got {value[:60]!r}"
    if value.startswith("amq."):
        return f"{value!r}: names starting with 'amq.' are reserved by the broker"
    return None


def routing_key_problem(value: str) -> str | None:
    """Why `value` cannot be a routing key of the twin's messages, or None."""
    if not value:
        return "must not be empty"
    if len(value.encode("utf-8")) > AMQP_MAX:
        return f"is {len(value.encode('utf-8'))} bytes long; AMQP routing keys hold at most {AMQP_MAX}"
    if not all(c.isprintable() and not c.isspace() for c in value):
        return f"may not hold spaces or control characters, got {value[:60]!r}"
    return None


def timing_problems(step: float, end: float, cycle_period: float | None = None) -> list[tuple[str, str]]:
    """(key, message) for a step and end time a run cannot keep exactly: a step that is not a whole
    number of the simulator's physics steps, an end time that is not a whole number of steps (it would
    be rounded), more than MAX_STEPS steps, or a d-model cycle that does not divide the step."""
    out = []
    ticks = step / PHYSICS_STEP
    if round(ticks) < 1 or abs(ticks - round(ticks)) > 1e-6 * ticks:
        nearest = max(1, round(ticks)) * PHYSICS_STEP
        out.append(("step", f"{step!r} s is not a whole number of the simulator's {PHYSICS_STEP * 1000:g} ms "
                            f"physics steps (nearest: {nearest:g} s)"))
    try:
        step_count(end, step)
    except CotwinError as err:
        out.append(("end", err.findings[0].message))
    if cycle_period is not None and cycle_period > 0:
        cycles = step / cycle_period
        if cycles > MAX_CYCLES_PER_STEP:
            out.append((CYCLE_PERIOD, f"{cycle_period!r} s makes {cycles:.3g} d-model cycles per step of {step:g} s, "
                                      f"more than {MAX_CYCLES_PER_STEP:.0e}"))
        elif round(cycles) < 1 or abs(cycles - round(cycles)) > 1e-6 * cycles:
            out.append((CYCLE_PERIOD, f"{cycle_period!r} s does not divide the step of {step:g} s into whole "
                                      "d-model cycles"))
    return out


def _pairs(value) -> str | None:
    if not all(isinstance(b, list) and len(b) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in b)
               for b in value):
        return "must be a list of [X, Y] hole pairs"
    twice = sorted({tuple(b) for b in value if value.count(b) > 1})
    if twice:
        return f"two bricks cannot stand on one hole: {', '.join(str(list(b)) for b in twice)}"
    return None


def _name(value: str) -> str | None:
    return "must not be empty" if not value.strip() else None


def _history_url(value: str) -> str | None:
    if not value.startswith(("sqlite:///", "postgresql://", "postgresql+", "postgres://")):
        return f"{value[:40]!r} is not a sqlite:///FILE or postgresql://... URL"
    return None


def cycle_period(spec: "TwinProject") -> float | None:
    """The d-model's cycle_period the project sets in [cosim] parameters, if a number."""
    period = spec.parameters.get(CYCLE_PERIOD)
    return period if isinstance(period, (int, float)) and not isinstance(period, bool) else None


def check_timing(spec: "TwinProject", step: float, end: float) -> None:
    """A run's step and end time (the project's or given by a caller) as `timing_problems` wants them."""
    from ..diagnostics import CotwinError

    if not (step > 0 and end > 0):  # also nan
        raise CotwinError(f"need a positive step and end time (step {step!r}, end {end!r})")
    found = timing_problems(step, end, cycle_period(spec))
    if found:  # the caller's values (the project's own were checked where they are written)
        raise CotwinError([f"{spec.path}: {'[cosim] parameters ' if key == CYCLE_PERIOD else ''}{key}: {message}"
                           for key, message in found])


def _amqp_url(value: str) -> str | None:
    if not value.startswith(("amqp://", "amqps://")):
        return f"'{value}' is not an amqp:// or amqps:// URL"
    from ..mapping.amqp import url_has_password, url_problem

    if url_has_password(value):
        return ("a password in the project file is refused: give credentials in the environment "
                "(COTWIN_AMQP_USER, COTWIN_AMQP_PASSWORD) or a file (COTWIN_AMQP_CREDENTIALS)")
    problem = url_problem(value)
    if problem is None and urlsplit(value).port == 0:
        return "the broker's port 0 is no port: give one in 1..65535 (default 5672, amqps 5671)"
    return problem


RABBITMQ = Schema({
    "exchange": Key("str", required=True, check=amqp_name_problem),
    "url": Key("str", "amqp://127.0.0.1:5672/%2F", check=_amqp_url),
    "to_cosim": Key("str", "data.to_cosim", check=routing_key_problem),
    "from_cosim": Key("str", "data.from_cosim", check=routing_key_problem),
    "maxage_ms": Key("positive", 1000, check=within(0, MAX_WAIT_S * 1000, "ms")),
    "timeout_s": Key("positive", 60, check=within(0, MAX_WAIT_S, "s")),
    "max_skew_s": Key("positive", 60, check=within(0, MAX_WAIT_S, "s")),
    "commands": Key("list[str]", check=unique("command")),
})

SHAPES = {"box": ("length", "width", "height"), "cylinder": ("radius", "length"), "capsule": ("radius", "length"),
          "sphere": ("radius",)}


def _triple(value) -> str | None:
    if len(value) != 3 or not all(is_number(v) for v in value):
        return f"must be a list of 3 numbers, got {shown(value)}"
    if not all(abs(v) <= 10.0 for v in value):
        return f"must be 3 numbers within 10 (m, rad), got {value!r}"
    return None


STAND_IN_EXTENT = 10.0  # m: a stand-in is a part of a robot, its size and offset at most this
STAND_IN = Schema({"mesh": Key("str", required=True), "shape": Key("str", required=True, choices=tuple(SHAPES)),
                   "size": Key("list", required=True), "pos": Key("list", [0.0, 0.0, 0.0], check=_triple),
                   "rpy": Key("list", [0.0, 0.0, 0.0], check=_triple),
                   "friction": Key("nonnegative", check=within(0, 100))})
PANEL = Schema({"label": Key("str", ""), "variables": Key("list[str]", required=True, check=unique("variable")),
                "style": Key("str", "default", choices=("default", "steps-post"))})


def _joints(value) -> str | None:
    if value in ("arm", "actuated"):
        return None
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return unique("joint")(value)
    return f'must be "arm", "actuated" or a list of joint names, got {value!r}'


def _readings(value) -> str | None:
    bad = [k for k, v in value.items() if not isinstance(v, str) or not v.strip()]
    if bad:
        return f"each reading is a path (a string): {', '.join(map(repr, bad))}"
    if "" in value:
        return "a reading needs a name"
    return None


def _parameters(value) -> str | None:
    bad = [k for k, v in value.items() if isinstance(v, (dict, list, str)) or
           (isinstance(v, float) and not math.isfinite(v))]
    if bad:
        return f"each parameter is a number or a Boolean: {', '.join(bad)}"
    return None


SCHEMA = Schema({
    "models": Key("table", required=True, table=Schema({
        "dmodel": Key("str", required=True), "pmodel": Key("str", required=True), "mapping": Key("str", required=True),
        "module": Key("str", check=_name), "pmodel_name": Key("str", check=_name), "fmu": Key("str")})),
    "scenario": Key("table", {}, table=Schema({
        "plan": Key("str"), "commands": Key("str"), "rabbitmq": Key("table", table=RABBITMQ)})),
    "platform": Key("table", {}, table=Schema({
        "endpoint": Key("str", "mujoco", choices=ENDPOINTS), "queue": Key("str", "cotwin.robot", check=amqp_name_problem),
        "url": Key("str", "amqp://127.0.0.1:5672/%2F", check=_amqp_url), "bricks": Key("list", [], check=_pairs),
        "scene": Key("str", "auto", choices=SCENES), "calibration": Key("str"), "world": Key("str"),
        "base": Key("str", "fixed", choices=("fixed", "free")), "stand_in": Key("list", [])})),
    "world": Key("table"),  # read by cotwin.pmodel.world
    "monitor": Key("table", {}, table=Schema({"joints": Key("any", "arm", check=_joints),
                                               "readings": Key("table", {}, check=_readings)})),
    "cosim": Key("table", {}, table=Schema({
        "step": Key("positive", 0.1), "end": Key("positive", 20.0),
        "algorithm": Key("str", "jacobi", choices=("jacobi", "gauss-seidel")),
        "realtime": Key("bool", False), "log": Key("list[str]", check=unique("variable", empty=True)),
        "parameters": Key("table", {}, check=_parameters), "isolate": Key("bool"),
        "unit_timeout": Key("positive", DEFAULT_TIMEOUT)})),
    "figure": Key("table", {}, table=Schema({"panels": Key("list")})),
    "pt": Key("table", table=Schema({
        "endpoint": Key("str", required=True, choices=PT_ENDPOINTS), "url": Key("str"), "log": Key("str"),
        "queue": Key("str", "cotwin.robot", check=amqp_name_problem), "offset": Key("number")})),
    "deviation": Key("table", {}, table=Schema({
        "variables": Key("list[str]", check=unique("variable")), "absolute": Key("nonnegative", 0.05),
        "relative": Key("nonnegative", 0.0),
        "lag_steps": Key("int", 3, check=within(0, MAX_LAG_STEPS, "steps")),
        "debounce_steps": Key("int", 2, check=within(1, MAX_LAG_STEPS, "steps")),
        "exchange": Key("str", "cotwin.twin", check=amqp_name_problem),
        "routing_key": Key("str", "twin.alarm", check=routing_key_problem)})),
    "history": Key("table", {}, table=Schema({"url": Key("str", check=_history_url)})),
    "plant": Key("table", table=PLANT),
    "convergence": Key("table"),  # read by cotwin.twin.convergence
})


@dataclass(frozen=True)
class RabbitMQSettings:
    exchange: str
    url: str = "amqp://127.0.0.1:5672/%2F"
    to_cosim: str = "data.to_cosim"
    from_cosim: str = "data.from_cosim"
    maxage_ms: float = 1000
    timeout_s: float = 60
    max_skew_s: float = 60  # a message whose time is further than this from its arrival is refused (clock skew)
    commands: tuple[str, ...] | None = None  # d-model input events taken from the broker (default: external ones)


@dataclass(frozen=True)
class PTSettings:
    endpoint: str
    url: str | None = None
    log: Path | None = None
    queue: str = "cotwin.robot"
    offset: float | None = None  # replay: log time at co-simulation time 0 (default: aligned on the first motion)


@dataclass(frozen=True)
class DeviationSettings:
    variables: tuple[str, ...] | None = None
    absolute: float = 0.05
    relative: float = 0.0
    lag_steps: int = 3
    debounce_steps: int = 2
    exchange: str = "cotwin.twin"
    routing_key: str = "twin.alarm"


@dataclass
class TwinProject:
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
    bricks: list[tuple[int, int]] = field(default_factory=list)
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
    parameters: dict[str, object] = field(default_factory=dict)  # [cosim] parameters of the d-model FMU
    panels: list[tuple[str, list[str], str]] | None = None  # [figure] panels: (label, unit.variable, style)
    fmu: Path | None = None  # [models] fmu: a d-model FMU built elsewhere, run in place of the one built from dmodel
    isolate: bool | None = None  # [cosim] isolate: the d-model FMU in a process of its own (None: if cotwin did not build it)
    unit_timeout: float = DEFAULT_TIMEOUT  # [cosim] unit_timeout: s an isolated FMU's call may take
    convergence: object | None = None  # cotwin.twin.convergence.ConvergenceSettings: [convergence]
    locations: dict = field(default_factory=dict)  # key path -> Location where it was written (later checks)
    raw: dict = field(default_factory=dict)  # the tables as written that staged copies carry (world, stand_in, figure)

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
                 self.world_file]
        return [p for p in found if p is not None]

    def location(self, *key) -> Location:
        """Where `key` (or its nearest written parent) is in the project file, for checks made after
        loading (against the models); the file's start when not known."""
        for n in range(len(key), 0, -1):
            if key[:n] in self.locations:
                return self.locations[key[:n]]
        return Location(str(self.path), 1, 1)


def load_project(path: str | Path, pt_log: str | Path | None = None) -> TwinProject:
    """Read and check cotwin.toml; every problem is reported at its key, all together. `pt_log` (a command's
    --pt-log) replaces [pt] log, which is then not looked for."""
    file = TomlFile(path, "project file")
    problems: list[Finding] = []
    data = SCHEMA.read(file.data, file, (), problems)
    base = file.path.parent

    def existing(table: str, key: str, value: str | None) -> Path | None:
        if value is None:
            return None
        target = base / value
        if not target.is_file():
            problems.append(Finding(file.location((table, key)), Severity.ERROR, f"[{table}] {key}: no file {target}"))
        return target

    models = data["models"] or {}
    files = {k: existing("models", k, models.get(k)) for k in ("dmodel", "pmodel", "mapping")}
    fmu = existing("models", "fmu", models.get("fmu"))
    scenario = data["scenario"] or {}
    sources = [k for k in ("plan", "commands", "rabbitmq") if scenario.get(k) is not None]
    if len(sources) > 1:
        problems.append(Finding(file.location(("scenario",)), Severity.ERROR,
                                f"[scenario] takes one source of commands, got {', '.join(sources)}"))
    plan = existing("scenario", sources[0], scenario[sources[0]]) if sources and sources[0] != "rabbitmq" else None
    rabbitmq = None
    if scenario.get("rabbitmq"):
        raw = dict(scenario["rabbitmq"])
        raw["commands"] = tuple(raw["commands"]) if raw.get("commands") is not None else None
        rabbitmq = RabbitMQSettings(**raw)
    platform, cosim = data["platform"] or {}, data["cosim"] or {}
    pt = None
    if data["pt"]:
        raw = data["pt"] | ({"endpoint": "replay", "log": None} if pt_log is not None else {})
        if raw["endpoint"] in ("opcua", "rtde") and not raw.get("url"):
            problems.append(Finding(file.location(("pt", "endpoint")), Severity.ERROR,
                                    f"[pt] endpoint {raw['endpoint']!r} needs a url"))
        if raw["endpoint"] == "replay" and not raw.get("log") and pt_log is None:
            problems.append(Finding(file.location(("pt", "endpoint")), Severity.ERROR,
                                    "[pt] endpoint 'replay' needs log = \"<recorded log>\""))
        log = Path(pt_log) if pt_log is not None else existing("pt", "log", raw.get("log"))
        pt = PTSettings(raw["endpoint"], raw.get("url"), log, raw["queue"], raw.get("offset"))
    dev = data["deviation"] or {}
    deviation = DeviationSettings(**{k: (tuple(v) if k == "variables" and v is not None else v)
                                     for k, v in dev.items()}) if dev else DeviationSettings()
    calibration = existing("platform", "calibration", platform.get("calibration"))
    world, world_file = _world(file, platform, data, existing, problems)
    stand_ins = _stand_ins(file, platform.get("stand_in") or [], problems)
    panels = _panels(file, (data["figure"] or {}).get("panels"), problems)
    monitor = data["monitor"] or {}
    _timing(file, cosim, problems)
    if pt is not None:
        problems.extend(_pt_keys(file, pt))
    from .convergence import read_convergence

    convergence = read_convergence(file, problems)
    raise_problems(problems)
    spec = TwinProject(
        file.path, files["dmodel"], files["pmodel"], files["mapping"], models.get("module"), models.get("pmodel_name"),
        plan, rabbitmq, platform["endpoint"], platform["queue"], platform["url"], platform["scene"],
        [tuple(b) for b in platform["bricks"]], calibration, float(cosim["step"]), float(cosim["end"]),
        cosim["algorithm"], cosim["realtime"], cosim["log"], pt, deviation, (data["history"] or {}).get("url"),
        Perturbation.from_table(data["plant"]) if data["plant"] else None)
    spec.world, spec.world_file, spec.base, spec.stand_ins = world, world_file, platform["base"], stand_ins
    spec.mirror_joints, spec.readings = monitor.get("joints", "arm"), dict(monitor.get("readings") or {})
    spec.parameters, spec.panels = dict(cosim.get("parameters") or {}), panels
    spec.fmu = fmu
    spec.convergence = convergence
    spec.isolate, spec.unit_timeout = cosim.get("isolate"), float(cosim["unit_timeout"])
    if world_file is not None:
        spec.world_file = world_file.path
    spec.locations = {key: file.location(key) for key in file.where}
    spec.raw = {"world": world.table if world is not None else None,
                "stand_in": list(platform.get("stand_in") or []), "figure": data["figure"] or {}}
    return spec


def _timing(file: TomlFile, cosim: dict, problems: list[Finding]) -> None:
    """[cosim] step, end and the d-model's cycle_period checked together (`timing_problems`), when each
    was read well (a wrong value is already reported, and its default would mislead)."""
    raw = file.data.get("cosim") if isinstance(file.data.get("cosim"), dict) else {}
    parameters = raw.get("parameters") if isinstance(raw.get("parameters"), dict) else {}
    if any(key not in cosim or key in raw and raw[key] != cosim[key] for key in ("step", "end")):
        return  # [cosim] itself, or its step or end, is wrong (and reported)
    period = parameters.get(CYCLE_PERIOD)
    where = ("cosim", "parameters", CYCLE_PERIOD)
    if period is not None and (not is_number(period) or period < 0):
        problems.append(Finding(file.location(where), Severity.ERROR, f"[cosim] parameters {CYCLE_PERIOD} must be "
                                f"a number >= 0 (s per d-model cycle; 0: one cycle per step), got {period!r}"))
        period = None
    for key, message in timing_problems(float(cosim["step"]), float(cosim["end"]), period):
        at = where if key == CYCLE_PERIOD else ("cosim", key)
        name = f"parameters {key}" if key == CYCLE_PERIOD else key
        problems.append(Finding(file.location(at), Severity.ERROR, f"[cosim] {name}: {message}"))


PT_KEYS = {"opcua": ("url",), "rtde": ("url",), "replay": ("log", "offset"), "broker": ("queue", "url")}


def _pt_keys(file: TomlFile, pt: PTSettings) -> list[Finding]:
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
    from ..diagnostics import CotwinError
    from ..mapping.opcua_auth import parse_url

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


def _world(file: TomlFile, platform: dict, data: dict, existing, problems: list[Finding]):
    """The project's world: a file named by [platform] world, or a [world] table (not both)."""
    from ..diagnostics import CotwinError
    from ..pmodel.world import read_world

    named, table = platform.get("world"), data.get("world")
    if named is not None and table is not None:
        problems.append(Finding(file.location(("world",)), Severity.ERROR,
                                "give the world as [platform] world = \"<file>\" or as a [world] table, not both"))
        return None, None
    if platform.get("scene") == "world" and named is None and table is None:
        problems.append(Finding(file.location(("platform", "scene")), Severity.ERROR,
                                "[platform] scene = \"world\" needs a world: [platform] world = \"<file>\" "
                                "or a [world] table"))
    try:
        if named is not None:
            path = existing("platform", "world", named)
            if path is None or not path.is_file():
                return None, None
            world_file = TomlFile(path, "world file")
            return read_world(world_file), world_file
        if table is not None:
            return read_world(file, ("world",)), None
    except CotwinError as err:
        problems.extend(err.findings)
    return None, None


def _stand_ins(file: TomlFile, items: list, problems: list[Finding]) -> dict:
    from ..pmodel.tree import StandIn, transform

    out: dict = {}
    for i, item in enumerate(items):
        at = ("platform", "stand_in", i)
        if not isinstance(item, dict):
            problems.append(Finding(file.location(at), Severity.ERROR, "each [[platform.stand_in]] must be a table"))
            continue
        before = len(problems)
        v = STAND_IN.read(item, file, at, problems)
        if len(problems) > before:
            continue
        names = SHAPES[v["shape"]]
        size = v["size"]
        if len(size) != len(names) or not all(is_number(x) and 0 < x <= STAND_IN_EXTENT for x in size):
            problems.append(Finding(file.location(at + ("size",)), Severity.ERROR,
                                    f"[[platform.stand_in]] size of a {v['shape']} is {len(names)} positive number(s) "
                                    f"({', '.join(names)}) of at most {STAND_IN_EXTENT:g} m, got {shown(size)}"))
            continue
        out.setdefault(v["mesh"], []).append(StandIn(v["shape"], dict(zip(names, map(float, size))),
                                                     transform(tuple(v["pos"]), tuple(v["rpy"])), v.get("friction")))
    return out


def _panels(file: TomlFile, items: list | None, problems: list[Finding]):
    if items is None:
        return None
    out = []
    for i, item in enumerate(items):
        at = ("figure", "panels", i)
        if not isinstance(item, dict):
            problems.append(Finding(file.location(at), Severity.ERROR, "each [figure] panel must be a table"))
            continue
        before = len(problems)
        v = PANEL.read(item, file, at, problems)
        bad = [name for name in v.get("variables") or [] if name.count(".") != 1 or not all(name.split("."))]
        if bad:
            problems.append(Finding(file.location(at + ("variables",)), Severity.ERROR,
                                    f"[figure] panel variables are written unit.variable (dmodel.lv, mapping.x), "
                                    f"got {', '.join(map(repr, bad))}"))
        if len(problems) == before:
            out.append((v["label"], list(v["variables"]), v["style"]))
    return out
