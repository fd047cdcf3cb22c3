"""The sections of a twin project (`cotwin.toml`) as typed settings: one frozen dataclass per table, each
key declared once with its kind, default and meaning (`cotwin.settings`); `docs/project.md` is generated
from them (`python -m cotwin.twin.project.doc`). A new section is a dataclass and one entry in SECTIONS.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from ...config import Key, did_you_mean, is_number, shown, unique, within
from ...cosim.execution import step_count
from ...cosim.isolated import DEFAULT_TIMEOUT
from ...diagnostics import CotwinError, Finding, Location, Severity
from ...pmodel.mjcf import TIMESTEP as PHYSICS_STEP
from ...pmodel.perturbation import SCHEMA as PLANT
from ...settings import setting

if TYPE_CHECKING:
    from .load import TwinProject

ENDPOINTS = ("mujoco", "broker")  # core's kinds (cotwin.twin.assembly.endpoints registers them and any other)
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


def off_physics(step: float, physics: float = PHYSICS_STEP) -> str | None:
    """Why `step` is not a whole number of physics steps of `physics` s (None when it is)."""
    ticks = step / physics
    if round(ticks) >= 1 and abs(ticks - round(ticks)) <= 1e-6 * ticks:
        return None
    nearest = max(1, round(ticks)) * physics
    return (f"{step!r} s is not a whole number of the simulator's {physics * 1000:g} ms physics steps "
            f"(nearest: {nearest:g} s)")


def timing_problems(step: float, end: float, cycle_period: float | None = None) -> list[tuple[str, str]]:
    """(key, message) for a step and end time a run cannot keep exactly: a step that is not a whole
    number of the simulator's physics steps, an end time that is not a whole number of steps (it would
    be rounded), more than MAX_STEPS steps, or a d-model cycle that does not divide the step."""
    out = []
    off = off_physics(step)
    if off is not None:
        out.append(("step", off))
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


def run_timing_message(spec: "TwinProject", key: str, message: str) -> str:
    """A `timing_problems` message as said of a run's own step or end (a command's option, a fleet entry's key):
    one about the project's cycle_period names it and where it is written."""
    if key != CYCLE_PERIOD:
        return message
    return f"[cosim] parameters {CYCLE_PERIOD} ({spec.location('cosim', 'parameters', CYCLE_PERIOD)}): {message}"


def cycle_time_warnings(spec: "TwinProject", readings: list[Location], step: float) -> list[Finding]:
    """A warning at the d-model's first reading of time when a run's step (`--step`) is not the project's and no
    cycle_period fixes the d-model's cycle: one cycle per step, so its `since` and `sinceEntry` count faster or
    slower in seconds than the project was written for."""
    period = cycle_period(spec)
    if not readings or (period is not None and period > 0) or math.isclose(step, spec.step, rel_tol=1e-9):
        return []  # (a cycle_period of 0: a cycle per step)
    ratio = spec.step / step
    shorter, pace = (f"{ratio:.3g} times shorter", f"{ratio:.3g} times sooner") if ratio > 1 else \
        (f"{1 / ratio:.3g} times longer", f"{1 / ratio:.3g} times later")
    others = f" (and {len(readings) - 1} other reading(s) of time)" if len(readings) > 1 else ""
    return [Finding(readings[0], Severity.WARNING,
                    f"the d-model counts time in cycles, one per step: at a step of {step:g} s a cycle is {shorter} "
                    f"than at the project's step of {spec.step:g} s, so this reading of time{others} reaches a value "
                    f"{pace} in seconds; give "
                    f"[cosim] parameters {CYCLE_PERIOD} = {spec.step:g} to keep its timing")]


def _name(value: str) -> str | None:
    return "must not be empty" if not value.strip() else None


def _robot_name(value: str) -> str | None:
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", value):
        return f"must be an identifier (letters, digits, '_'; it scopes names and plan columns), got {shown(value)}"
    return None


def history_url_problem(value: str) -> str | None:
    """Why `value` cannot name a history store: not a SQLite file's or PostgreSQL's URL, or a SQLite database in
    memory (`sqlite:///`, `sqlite:///:memory:`), whose history would be gone when the command ends."""
    if not value.startswith(("sqlite:///", "postgresql://", "postgresql+", "postgres://")):
        return f"{value[:40]!r} is not a sqlite:///FILE or postgresql://... URL"
    if value.startswith("sqlite:///") and value[len("sqlite:///"):].split("?", 1)[0] in ("", ":memory:"):
        return f"{value[:40]!r} is a database in memory, lost when the command ends: name a file (sqlite:///FILE)"
    return None


def cycle_period(spec: "TwinProject") -> float | None:
    """The d-model's cycle_period the project sets in [cosim] parameters, if a number."""
    period = spec.parameters.get(CYCLE_PERIOD)
    return period if isinstance(period, (int, float)) and not isinstance(period, bool) else None


def check_timing(spec: "TwinProject", step: float, end: float) -> None:
    """A run's step and end time (the project's or given by a caller) as `timing_problems` wants them."""

    if not (step > 0 and end > 0):  # also nan
        raise CotwinError(f"need a positive step and end time (step {step!r}, end {end!r})")
    found = timing_problems(step, end, cycle_period(spec))
    if found:  # the caller's values (the project's own were checked where they are written)
        raise CotwinError([f"{spec.path}: {'[cosim] parameters ' if key == CYCLE_PERIOD else ''}{key}: {message}"
                           for key, message in found])


def _amqp_url(value: str) -> str | None:
    if not value.startswith(("amqp://", "amqps://")):
        return f"'{value}' is not an amqp:// or amqps:// URL"
    from ...mapping.amqp import url_has_password, url_problem

    if url_has_password(value):
        return ("a password in the project file is refused: give credentials in the environment "
                "(COTWIN_AMQP_USER, COTWIN_AMQP_PASSWORD) or a file (COTWIN_AMQP_CREDENTIALS)")
    problem = url_problem(value)
    if problem is None and urlsplit(value).port == 0:
        return "the broker's port 0 is no port: give one in 1..65535 (default 5672, amqps 5671)"
    return problem


SHAPES = {"box": ("length", "width", "height"), "cylinder": ("radius", "length"), "capsule": ("radius", "length"),
          "sphere": ("radius",)}


def _triple(value) -> str | None:
    if len(value) != 3 or not all(is_number(v) for v in value):
        return f"must be a list of 3 numbers, got {shown(value)}"
    if not all(abs(v) <= 10.0 for v in value):
        return f"must be 3 numbers within 10 (m, rad), got {value!r}"
    return None


STAND_IN_EXTENT = 10.0  # m: a stand-in is a part of a robot, its size and offset at most this


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
    """Why the d-model's parameters are not numbers or Booleans; cycle_period is checked at its own value, against
    the step (cotwin.twin.project.load), so that one wrong value is one error."""
    bad = [k for k, v in value.items() if k != CYCLE_PERIOD and (isinstance(v, (dict, list, str)) or
                                                                 (isinstance(v, float) and not math.isfinite(v)))]
    if bad:
        return f"each parameter is a number or a Boolean: {', '.join(bad)}"
    return None



URL = "amqp://127.0.0.1:5672/%2F"  # the local broker


def _section(cls):
    return dataclasses.dataclass(frozen=True)(cls)


@_section
class Models:
    """Paths are relative to the project file."""

    dmodel: str = setting("the d-model (RoboSim .rst)", Key("str", required=True), path=True)
    pmodel: str | None = setting("the p-model (.pm); required unless [[robots]] names a cell's robots",
                                 Key("str"), path=True)
    mapping: str | None = setting("the platform mapping (.pm); required unless [[robots]] names a cell's robots",
                                  Key("str"), path=True)
    module: str | None = setting("the d-model module (default: the file's only one)", Key("str", check=_name))
    pmodel_name: str | None = setting("the p-model's name (default: the file's only one)", Key("str", check=_name))
    fmu: str | None = setting("a d-model FMU built elsewhere, run in place of the one cotwin builds from dmodel "
                              "(its ports must be the module's)", Key("str"), path=True)


@_section
class RabbitMQSettings:
    """Commands taken live, as the RMQ FMU of the paper takes them."""

    exchange: str = setting("the exchange the twin's messages go through", Key("str", required=True,
                                                                                check=amqp_name_problem))
    url: str = setting("the broker (credentials from the environment, never here)", Key("str", URL, check=_amqp_url))
    to_cosim: str = setting("routing key of commands to the co-simulation",
                            Key("str", "data.to_cosim", check=routing_key_problem))
    from_cosim: str = setting("routing key of the co-simulation's echoes",
                              Key("str", "data.from_cosim", check=routing_key_problem))
    maxage_ms: float = setting("ms a command is still taken after its time",
                               Key("positive", 1000, check=within(0, MAX_WAIT_S * 1000, "ms")))
    timeout_s: float = setting("s the twin waits for the publisher's first message",
                               Key("positive", 60, check=within(0, MAX_WAIT_S, "s")))
    max_skew_s: float = setting("a message whose time is further than this (s) from its arrival is refused "
                                "(clock skew)", Key("positive", 60, check=within(0, MAX_WAIT_S, "s")))
    commands: tuple[str, ...] | None = setting("the d-model input events taken from the broker (default: those "
                                               "the mapping does not produce)",
                                               Key("list[str]", check=unique("command")))


@_section
class Scenario:
    """One source at most; none: the d-model runs on its own."""

    plan: str | None = setting("a TwinManager plan (CSV: ms, port values)", Key("str"), path=True)
    commands: str | None = setting("a TOML list of [[command]]", Key("str"), path=True)
    rabbitmq: RabbitMQSettings | None = setting("commands taken live from RabbitMQ", section=RabbitMQSettings,
                                                optional=True)


@_section
class StandIn:
    """A shape standing in for a mesh file the p-model names but that cannot be read."""

    mesh: str = setting("the mesh file as the p-model writes its name", Key("str", required=True))
    shape: str = setting("the shape", Key("str", required=True, choices=tuple(SHAPES)))
    size: tuple = setting("box: length, width, height; cylinder, capsule: radius, length; sphere: radius (m)",
                          Key("list", required=True))
    pos: tuple = setting("position in the mesh's frame (m)", Key("list", [0.0, 0.0, 0.0], check=_triple))
    rpy: tuple = setting("roll, pitch, yaw in the mesh's frame (rad)", Key("list", [0.0, 0.0, 0.0], check=_triple))
    friction: float | None = setting("its own sliding friction (0: a frictionless skid; default: the p-model's)",
                                     Key("nonnegative", check=within(0, 100)))


@_section
class Platform:
    """The digital twin's robot and what is around it."""

    endpoint: str = setting('an endpoint kind by name (cotwin.twin.assembly.endpoints): the embedded simulator ("mujoco"), '
                            'a robot behind RabbitMQ ("broker"), or one a package registers', Key("str", "mujoco", check=_name))
    queue: str = setting("broker: the robot's request queue", Key("str", "cotwin.robot", check=amqp_name_problem))
    url: str = setting("broker: the broker's URL", Key("str", URL, check=_amqp_url))
    scene: str = setting('around the robot: a scene kind by name (cotwin.pmodel.scenes: "none", "floor", "world" '
                         '(a world file or [world] table), or one an installed package registers); "auto": the '
                         "world if one is given, else a registered kind that fits the mapping, else a floor under a free base "
                         "(a mobile robot would fall for ever), else none",
                         Key("str", "auto", check=_name))
    calibration: str | None = setting("a calibration file (docs/calibration.md)", Key("str"), path=True)
    world: str | None = setting("a world file (cotwin.pmodel.world); or a [world] table here", Key("str"), path=True)
    base: str = setting('the robot\'s base: fixed to the world, or "free" (a mobile robot)',
                        Key("str", "fixed", choices=("fixed", "free")))
    stand_in: tuple[StandIn, ...] = setting("shapes standing in for unreadable meshes", items=StandIn)


@_section
class CellRobot:
    """Each has its own instance of the shared d-model FMU, its own mapping and its own commands."""

    name: str = setting("its name: the scope of its names in the shared world, of its units ({dmodel}.NAME) and of "
                        "its plan columns (NAME.port)", Key("str", required=True, check=_robot_name))
    pmodel: str = setting("its p-model (.pm)", Key("str", required=True), path=True)
    mapping: str = setting("its platform mapping (.pm)", Key("str", required=True), path=True)
    calibration: str | None = setting("its cell geometry (docs/calibration.md: tool, IK reference); its [plate] is "
                                      "where the scene's frame is in its own, laid over its base pose", Key("str"),
                                      path=True)
    xyz: tuple = setting("its base's position in the scene's frame (m)", Key("list", [0.0, 0.0, 0.0], check=_triple))
    rpy: tuple = setting("its base's roll, pitch, yaw in the scene's frame (rad)",
                         Key("list", [0.0, 0.0, 0.0], check=_triple))


@_section
class Monitor:
    """The mapping's monitored variables (logged; compared PT vs DT)."""

    joints: Any = setting('the joints its q<i>/qd<i> mirror: "arm" (base to tool), "actuated", or a list of names',
                          Key("any", "arm", check=_joints))
    readings: dict = setting("more monitored values: name -> a platform reading by path (robot::base.x)",
                             Key("table", {}, check=_readings))


def _events(value) -> str | None:
    return unique("event", empty=True)(value)


@_section
class Outcomes:
    """Which input events answer a command infeasible or feasible, or stop it. A key left out: by their names (the
    defaults below), never an event another key lists; an empty list: no event has that role (`stops = []`: no
    event stops a move, not even one named collision)."""

    infeasible: tuple[str, ...] | None = setting(
        "input events answering that a command cannot be done (default: those named nonfeasible*, infeasible*, "
        "unreachable*)", Key("list[str]", check=_events))
    feasible: tuple[str, ...] | None = setting(
        "input events answering that a command can be done (default: those named feasible*, reachable*)",
        Key("list[str]", check=_events))
    stops: tuple[str, ...] | None = setting(
        "input events that stop a move, which is then no completion (default: those a word of whose name is "
        "collision, fault, emergency or protective)", Key("list[str]", check=_events))


@_section
class Cosim:
    """How the co-simulation runs."""

    step: float = setting("s per communication step: a whole number of the simulator's 1 ms physics steps",
                          Key("positive", 0.1))
    end: float = setting("s simulated: a whole number of steps (never rounded), at most 1e8 of them",
                         Key("positive", 20.0))
    algorithm: str = setting("the master algorithm", Key("str", "jacobi", choices=("jacobi", "gauss-seidel")))
    realtime: bool = setting("pace to wall-clock time", Key("bool", False))
    log: tuple[str, ...] | None = setting("mapping variables to log (default: every monitored one)",
                                          Key("list[str]", check=unique("variable", empty=True)))
    parameters: dict = setting("d-model FMU parameters: its random seed, constants without value; cycle_period, "
                               "if given, divides the step into whole cycles (else a cycle a step: a run at another "
                               "step changes what the d-model's since and sinceEntry mean in seconds; cotwin run "
                               "warns of it)", Key("table", {}, check=_parameters))
    isolate: bool | None = setting("the d-model FMU in a process of its own (cotwin.cosim.isolated), a crash or "
                                   "hang in it a located error (default: only an FMU cotwin did not build)",
                                   Key("bool"))
    unit_timeout: float = setting("s an isolated FMU's call may take before it counts as hanging",
                                  Key("positive", DEFAULT_TIMEOUT))


@_section
class Panel:
    """One panel of the figure."""

    label: str = setting("its label", Key("str", ""))
    variables: tuple[str, ...] = setting("unit role . variable (dmodel.lv, mapping.x)",
                                         Key("list[str]", required=True, check=unique("variable")))
    style: str = setting("how values are drawn", Key("str", "default", choices=("default", "steps-post")))


@_section
class Figure:
    """The figure of `cotwin run` (default: panels chosen from the models)."""

    panels: tuple[Panel, ...] = setting("the panels, top to bottom", items=Panel)


@_section
class Robot:
    """The real robot's controller: how its joints and base frame relate to the p-model's."""

    profile: str | None = setting("a robot profile file: joint offsets and base frame (docs/live-twin.md); "
                                  "absent: the identity, with a warning when a log or robot is read",
                                  Key("str"), path=True)


@_section
class PT:
    """The physical twin of `cotwin twin`."""

    endpoint: str = setting('how the PT is reached: an endpoint kind by name (cotwin.twin.assembly.endpoints): "opcua", '
                            '"replay", "broker", "rtde" (each takes only its own keys below), or one a package '
                            'registers', Key("str", required=True, check=_name))
    url: str | None = setting("opcua: opc.tcp://HOST:PORT; rtde: the robot's host; broker: an AMQP URL", Key("str"))
    log: str | None = setting("replay: the recorded log", Key("str"), path=True)
    queue: str = setting("broker: the robot's request queue", Key("str", "cotwin.robot", check=amqp_name_problem))
    offset: float | None = setting("replay: log time at co-simulation time 0 (default: aligned on the first "
                                   "motion)", Key("number"))


@_section
class DeviationSettings:
    """PT against DT: when they deviate, and where alarms go."""

    variables: tuple[str, ...] | None = setting("the variables compared (default: the logged ones)",
                                                Key("list[str]", check=unique("variable")))
    absolute: float = setting("alarm when |PT - DT| > max(absolute, relative * |PT|)", Key("nonnegative", 0.05))
    relative: float = setting("see absolute", Key("nonnegative", 0.0))
    lag_steps: int = setting("a DT lagging by at most this many steps is not deviating",
                             Key("int", 3, check=within(0, MAX_LAG_STEPS, "steps")))
    debounce_steps: int = setting("consecutive deviating steps before an alarm is raised",
                                  Key("int", 2, check=within(1, MAX_LAG_STEPS, "steps")))
    exchange: str = setting("the exchange alarms and twin events are published on",
                            Key("str", "cotwin.twin", check=amqp_name_problem))
    routing_key: str = setting("the alarms' routing key", Key("str", "twin.alarm", check=routing_key_problem))


@_section
class History:
    """Where a live twin's history is kept."""

    url: str | None = setting("sqlite:///FILE or postgresql://... (default: OUT/history.sqlite)",
                              Key("str", check=history_url_problem))


PLANT_MEANINGS = {"seed": "the random seed of the plant's noise", "payload": "kg at the tool",
                  "friction": "Coulomb friction, N m (or N): a table by joint, or a number for every joint",
                  "damping": "scale of the joints' damping: a table by joint, or a number for every joint",
                  "latency_ms": "ms before a goal takes effect",
                  "noise": "Gaussian std by sensor quantity (position, ...), or a number for all"}


@_section
class Plant:
    """The stand-in cell of `cotwin plant` (cotwin.pmodel.perturbation)."""

    seed: int = setting(PLANT_MEANINGS["seed"], PLANT.keys["seed"])
    payload: float = setting(PLANT_MEANINGS["payload"], PLANT.keys["payload"])
    friction: Any = setting(PLANT_MEANINGS["friction"], PLANT.keys["friction"])
    damping: Any = setting(PLANT_MEANINGS["damping"], PLANT.keys["damping"])
    latency_ms: float = setting(PLANT_MEANINGS["latency_ms"], PLANT.keys["latency_ms"])
    noise: Any = setting(PLANT_MEANINGS["noise"], PLANT.keys["noise"])


RESYNC = re.compile(r"every\s+(\d+)\s+steps?")
RESYNC_WORDS = ("never", "on-alarm")
MAX_EVERY = 10 ** 6


def _resync(value: str) -> str | None:
    if value in ("never", "on-alarm"):
        return None
    match = RESYNC.fullmatch(value.strip())
    if match is None:
        return f'must be "never", "on-alarm" or "every N steps", got {shown(value)}{did_you_mean(value, RESYNC_WORDS)}'
    if not 1 <= int(match.group(1)) <= MAX_EVERY:
        return f"every N steps takes N in 1..{MAX_EVERY}, got {match.group(1)}"
    return None


@_section
class Convergence:
    """A live twin's DT pulled towards its PT (cotwin.twin.assembly.convergence)."""

    resync: str = setting('when the PT\'s joint state is put into the DT: "never", "on-alarm" (every step with an '
                          'alarm raised or open) or "every N steps"', Key("str", "never", check=_resync))
    estimate: str = setting('"payload": the mass at the tool estimated from the PT\'s joint torques at rest',
                            Key("str", "none", choices=("none", "payload")))
    payload_std: float = setting("kg: the estimate is applied to the DT once its standard deviation is below this",
                                 Key("positive", 0.05, check=within(0, 1000, "kg")))
    rest_speed: float = setting("rad/s (m/s): torques are taken only while every joint is slower than this",
                                Key("positive", 0.002, check=within(0, 100, "rad/s")))

    @property
    def mode(self) -> str:
        """never | on-alarm | every"""
        return "every" if RESYNC.fullmatch(self.resync.strip()) else self.resync

    @property
    def every(self) -> int:
        """resync = "every N steps": N (else 0)."""
        match = RESYNC.fullmatch(self.resync.strip())
        return int(match.group(1)) if match else 0

    @property
    def active(self) -> bool:
        return self.resync != "never" or self.estimate != "none"

    def as_dict(self) -> dict:
        return {"resync": self.resync, "estimate": self.estimate, "payload_std": self.payload_std,
                "rest_speed": self.rest_speed}


# The project file's tables in order: adding a section is a dataclass above (or in its own module) and one
# entry here.
SECTIONS: dict[str, Any] = {
    "models": setting("The three models.", Key("table", required=True), section=Models),
    "robots": setting("A cell of several robots in one scene (the scene built from the first one's mapping); "
                      "absent: the one robot of [models].", items=CellRobot),
    "scenario": setting("Where commands come from.", section=Scenario),
    "platform": setting("The DT's robot.", section=Platform),
    "world": setting("A world to walk in, written here instead of a file named by [platform] world; its keys are "
                     "those of a world file (cotwin.pmodel.world).", Key("table")),
    "scene": setting("The scene's own keys, read by the kind [platform] scene names (docs/scenes.md); a key "
                     "that kind does not read is an error.", Key("table")),
    "monitor": setting("What the mapping monitors.", section=Monitor),
    "outcomes": setting("What the d-model's events say of its commands.", section=Outcomes),
    "cosim": setting("The co-simulation.", section=Cosim),
    "figure": setting("The run's figure.", section=Figure),
    "robot": setting("The real robot's conventions.", section=Robot),
    "pt": setting("The physical twin; absent: `cotwin twin` needs --pt-log or --pt-url.", section=PT, optional=True),
    "deviation": setting("Deviation checking.", section=DeviationSettings),
    "history": setting("History.", section=History),
    "plant": setting("A perturbed plant.", section=Plant, optional=True),
    "convergence": setting("The DT pulled towards its PT (a live twin).", section=Convergence, optional=True),
}


# Sections only some commands read (every other section is read by every command that runs the project): a
# command that runs a project holding one of them warns, at the table, that it ignores it (`ignored_sections`);
# a reader is a command with the option that makes it read the section, if any.
LIVE_TWIN = ("cotwin twin", "cotwin fleet")
READ_ONLY_BY: dict[str, tuple[str, ...]] = {
    "pt": (*LIVE_TWIN, "cotwin plant", "cotwin test --pt project"),
    "deviation": LIVE_TWIN,
    "convergence": LIVE_TWIN,
    "plant": ("cotwin plant", "cotwin twin of a cell ([[robots]]: its PT)"),
    "history": (*LIVE_TWIN, "cotwin run --dashboard"),  # one run records no history; its page lists the store's
}


def project_settings(sections: dict[str, Any]) -> type:
    """The dataclass of a whole project file: one field per section, in order."""
    cls = dataclasses.make_dataclass("ProjectSettings", [(name, Any, f) for name, f in sections.items()],
                                     frozen=True)
    cls.__doc__ = "A project file as written: its sections' settings."
    cls.SECTIONS = sections  # type: ignore[attr-defined]
    return cls


ProjectSettings = project_settings(SECTIONS)

