"""A robot cell over OPC UA: the third kind of platform endpoint, and the protocol it speaks.

`OPCUAEndpoint` is what the mapping talks to; the server is `cotwin plant` (cotwin.twin.services.plant), or
any OPC UA server offering this address space (namespace `urn:cotwin:plant`, string node ids):

    Objects/
      <p-model name>                  ns;s=Robot            the robot (BaseObjectType)
        Time                          ns;s=Robot.Time       Double, s: the plant's clock
        Mode                          ns;s=Robot.Mode       String: "lockstep" | "free-running"
        Perturbation                  ns;s=Robot.Perturbation  String: JSON of the perturbation
        LastError                     ns;s=Robot.LastError  String: why the last call was refused
        Joints/<joint>/Position|Velocity|Goal   ns;s=Robot.Joints.<joint>.Position  Double (rad, m, rad/s, m/s)
        Sensors/<pmodel::link::sref.port>       ns;s=Robot.Sensors.<path>           Double
        Describe() -> Joints: String[], Actuators: String[], ActuatorJoints: String[], Sensors: String[],
                      Mode: String, Step: Double (physics step, s), Perturbation: String (JSON)
        State() -> STATE
        Command(Goals: String)                        -> STATE   goals as a JSON object {actuator: value}
        CommandJoints(Actuators: String[], Goals: Double[]) -> STATE   the same, structured
        Advance(Dt: Double)                           -> STATE   lockstep: simulate Dt s (0 <= Dt <= 10);
                                                                  free-running: wait until Time >= Time at call + Dt
        AdvanceTo(Time: Double)                       -> STATE   simulate (lockstep) or wait (free-running)
                                                                  until the plant's Time reaches Time
        Reset()                                       -> STATE   back to the initial state at Time 0
      STATE = Time: Double, Positions: Double[], Velocities: Double[], Sensors: Double[], Goals: Double[]
              (arrays in Describe's order of Joints and Sensors)

Actuators are named as the mapping names them (joint, servo or `pmodel::link::joint::aref.port`, the port being
the actuator's command input: cotwin.pmodel.tree.actuator_names, as the simulator names them).
A refused call returns Bad_InvalidArgument with the offending argument's own status (Bad_TypeMismatch,
Bad_OutOfRange, Bad_NoMatch) and a diagnostic naming the problem, or a Bad_ status of its own (e.g.
Bad_UserAccessDenied for an anonymous caller); the plant's LastError variable holds the same text.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import os
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass

from ..diagnostics import CotwinError, PicklableError
from ..pmodel.mjcf import pose_paths
from ..pmodel.tree import KinematicTree, reading_path
from ..service import LoopThread
from .opcua_auth import client_credentials, parse_url
from .platform import Endpoint

logging.getLogger("asyncua").addHandler(logging.NullHandler())  # a library logs; the application decides

NAMESPACE = "urn:cotwin:plant"
ROBOT = "Robot"
DT_MAX = 10.0  # s: the longest Advance
STATE = ("Time", "Positions", "Velocities", "Sensors", "Goals")
MODES = ("lockstep", "free-running")
MAX_GOALS_TEXT = 65_536  # characters of Command's JSON argument
MAX_GOAL = 1e6  # rad, m, rad/s...: the bound of a goal whose joint declares no limit
RANGE_SLACK = 1e-9  # of a range's width: rounding in a goal computed at a limit


class RequestError(PicklableError):
    """A refused call: the OPC UA status name, why, and the index of the argument at fault (if one is)."""

    def __init__(self, status: str, message: str, argument: int | None = None):
        super().__init__(message)
        self.status = status
        self.message = message
        self.argument = argument


def _is_real(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def parse_goals(text) -> dict[str, float]:
    """Command's JSON argument: an object of actuator -> finite number (at most MAX_GOALS_TEXT characters)."""
    if not isinstance(text, str):
        raise RequestError("BadTypeMismatch", f"Goals must be a String holding a JSON object, got {type(text).__name__}", 0)
    if len(text) > MAX_GOALS_TEXT:
        raise RequestError("BadOutOfRange", f"Goals is {len(text)} characters long, more than {MAX_GOALS_TEXT}", 0)
    try:
        goals = json.loads(text)
    except json.JSONDecodeError as err:
        raise RequestError("BadTypeMismatch", f"Goals is not JSON: {err.msg} at character {err.pos}", 0) from None
    except RecursionError:
        raise RequestError("BadTypeMismatch", "Goals is nested too deeply: a JSON object {actuator: value} "
                                              "holds numbers only", 0) from None
    if not isinstance(goals, dict):
        raise RequestError("BadTypeMismatch", "Goals must be a JSON object {actuator: value}", 0)
    return check_goals(goals, 0)


def check_goals(goals: dict, argument: int) -> dict[str, float]:
    for name, value in goals.items():
        if not _is_real(value):
            shown = type(value).__name__ if isinstance(value, (dict, list)) else repr(value)
            raise RequestError("BadTypeMismatch", f"goal '{name}' must be a number, got {shown:.80}", argument)
        if not math.isfinite(value):
            raise RequestError("BadOutOfRange", f"goal '{name}' must be a finite number, got {value!r}", argument)
    return {name: float(value) for name, value in goals.items()}


def goal_range(joint) -> tuple[float, float, str]:
    """The goals a joint's servo takes (low, high, unit): a position within the joint's limits, a speed
    or an effort within its velocity or effort limit; MAX_GOAL either way where the p-model gives none."""
    from ..pmodel.tree import servo_mode

    mode = servo_mode(joint)
    base = "rad" if joint.kind == "revolute" else "m"
    if mode == "position":
        low = joint.lower if joint.lower is not None else -MAX_GOAL
        high = joint.upper if joint.upper is not None else MAX_GOAL
        return low, high, base
    bound = joint.velocity if mode == "velocity" else joint.effort
    unit = f"{base}/s" if mode == "velocity" else ("N m" if joint.kind == "revolute" else "N")
    return (-bound, bound, unit) if bound else (-MAX_GOAL, MAX_GOAL, unit)


def check_goal_ranges(goals: dict[str, float], joints: dict[str, object], argument: int) -> None:
    """Every goal within its joint's range (goal_range), as a robot controller refuses a target beyond
    a joint limit rather than clip it; `joints` maps an actuator name to its joint."""
    for name, value in goals.items():
        joint = joints[name]
        low, high, unit = goal_range(joint)
        slack = RANGE_SLACK * max(1.0, high - low)
        if not low - slack <= value <= high + slack:
            raise RequestError("BadOutOfRange", f"goal '{name}' = {value:g} {unit} is outside joint {joint.name}'s "
                                                f"range [{low:g}, {high:g}] {unit}", argument)


def check_dt(dt) -> float:
    if not _is_real(dt):
        raise RequestError("BadTypeMismatch", f"Dt must be a Double (seconds), got {type(dt).__name__}", 0)
    if not (math.isfinite(dt) and 0 <= dt <= DT_MAX):
        raise RequestError("BadOutOfRange", f"Dt must be in [0, {DT_MAX:g}] s, got {dt!r}", 0)
    return float(dt)


def check_time(t, now: float) -> float:
    if not _is_real(t):
        raise RequestError("BadTypeMismatch", f"Time must be a Double (seconds), got {type(t).__name__}", 0)
    if not (math.isfinite(t) and 0 <= t - now + 1e-9 <= DT_MAX):
        raise RequestError("BadOutOfRange", f"Time must be within [{now:g}, {now + DT_MAX:g}] s (the plant's time "
                                            f"and at most {DT_MAX:g} s ahead), got {t!r}", 0)
    return float(t)


@dataclass(frozen=True)
class Layout:
    """What Describe says: the names the plant uses and in which order its arrays come."""

    joints: tuple[str, ...]
    actuators: dict[str, str]  # actuator name -> joint
    sensors: tuple[str, ...]
    mode: str
    step: float
    perturbation: dict


# ---- the client ----------------------------------------------------------------------------------

class OPCUAEndpoint(Endpoint):
    """The mapping's view of a robot cell served over OPC UA (the same interface as SimulatedEndpoint).

    Every call has a timeout (`timeout` seconds, plus the wait of a free-running Advance); every reply is
    checked (types, lengths, finite values, names the p-model knows). A plant that stops answering or
    goes away is a CotwinError naming the URL and the call. `reset=True` resets the plant at start."""

    def __init__(self, tree: KinematicTree, url: str, timeout: float = 10.0, reset: bool = False,
                 environ=os.environ):
        if not (_is_real(timeout) and math.isfinite(timeout) and timeout > 0):
            raise CotwinError(f"OPC UA timeout must be a positive number of seconds, got {timeout!r}")
        host, port = parse_url(url)
        self.tree = tree
        self.url = url
        self.timeout = float(timeout)
        self.reset = reset
        try:
            self._credentials = client_credentials(url, environ)
        except CotwinError:  # no credentials file: say first that nobody listens, if nobody does
            problem = _unreachable(host, port, self.timeout)
            if problem is not None:
                raise CotwinError(f"the plant at {url} failed connect: {problem}") from None
            raise
        self._loop_thread = LoopThread(f"opcua client {url}").start()  # the client's calls run there
        self._loop = self._loop_thread.loop
        self._client = None
        self._state: dict = {}
        self.time = 0.0
        self._target: float | None = None
        self.calls = 0
        try:
            self._run(self._connect(), "connect")
            self.layout = self._describe()
        except BaseException:
            self.close()
            raise

    # ---- plumbing ----
    async def _connect(self):
        from asyncua import Client, ua

        client = Client(self.url, timeout=self.timeout, watchdog_intervall=max(self.timeout, 1.0))
        client.name = "cotwin OPCUAEndpoint"
        client.set_user(self._credentials.user)
        client.set_password(self._credentials.password)
        await client.connect()
        self._client = client
        try:
            self._ns = await client.get_namespace_index(NAMESPACE)
        except ValueError:
            raise CotwinError(f"the OPC UA server at {self.url} is not a cotwin plant (no namespace {NAMESPACE})") from None
        self._robot = ua.NodeId(ROBOT, self._ns)
        self._methods = {name: ua.NodeId(f"{ROBOT}.{name}", self._ns) for name in
                         ("Describe", "State", "Command", "CommandJoints", "Advance", "AdvanceTo", "Reset")}
        self._last_error = ua.NodeId(f"{ROBOT}.LastError", self._ns)

    def _run(self, coroutine, what: str, timeout: float | None = None):
        future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        limit = self.timeout if timeout is None else timeout
        try:
            return future.result(limit)
        except FutureTimeout:
            future.cancel()
            raise CotwinError(f"the plant at {self.url} did not answer {what} within {limit:g} s") from None
        except CotwinError:
            raise
        except Exception as err:
            raise CotwinError(f"the plant at {self.url} failed {what}: {_describe_error(err)}") from None

    async def _call(self, method: str, args: list) -> list:
        from asyncua import ua

        request = ua.CallMethodRequest(ObjectId=self._robot, MethodId=self._methods[method], InputArguments=args)
        result = (await self._client.uaclient.call([request]))[0]
        if not result.StatusCode.is_good():
            statuses = [result.StatusCode.name] + [s.name for s in result.InputArgumentResults or [] if not s.is_good()]
            raise CotwinError(f"the plant at {self.url} refused {method}: "
                              f"{await self._reason(method, result)} ({', '.join(statuses)})")
        return [v.Value for v in result.OutputArguments or []]

    async def _reason(self, method: str, result) -> str:
        """The diagnostic of the argument at fault, else the plant's LastError (without the method's name)."""
        for status, info in zip(result.InputArgumentResults or [], result.InputArgumentDiagnosticInfos or []):
            if not status.is_good() and info is not None and info.AdditionalInfo:
                return info.AdditionalInfo
        if result.StatusCode.name == "BadUserAccessDenied":
            return "access denied (the operator credentials were not accepted)"
        try:
            text = await self._client.get_node(self._last_error).read_value()
        except Exception:
            text = None
        if isinstance(text, str) and text:
            return text.removeprefix(f"{method}: ")
        return "no reason given"

    def call(self, method: str, *args, timeout: float | None = None) -> list:
        """Call one of the robot's methods with already typed arguments (ua.Variant); its outputs."""
        if self._client is None:
            raise CotwinError(f"the OPC UA connection to {self.url} is closed")
        self.calls += 1
        return self._run(self._call(method, list(args)), method, timeout)

    def _describe(self) -> Layout:
        out = self.call("Describe")
        if len(out) != 7:
            raise self._bad("Describe", f"expected 7 outputs, got {len(out)}")
        joints, actuators, actuator_joints, sensors, mode, step, perturbation = out
        for name, value in (("Joints", joints), ("Actuators", actuators), ("ActuatorJoints", actuator_joints),
                            ("Sensors", sensors)):
            if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
                raise self._bad("Describe", f"{name} must be a list of names")
            if name != "ActuatorJoints" and len(set(value)) != len(value):
                raise self._bad("Describe", f"{name} has duplicates")
        if len(actuators) != len(actuator_joints):
            raise self._bad("Describe", "Actuators and ActuatorJoints differ in length")
        ours = [j.name for j in self.tree.actuated]
        if sorted(joints) != sorted(ours):
            raise CotwinError(f"the plant at {self.url} has joints {', '.join(joints)}; p-model {self.tree.name} "
                              f"has {', '.join(ours)}")
        known = {reading_path(self.tree.name, s) for s in self.tree.sensors} | \
            set(pose_paths(self.tree))
        unknown = [s for s in sensors if s not in known]
        if unknown:
            raise CotwinError(f"the plant at {self.url} reports sensors p-model {self.tree.name} does not have: "
                              f"{', '.join(unknown)}")
        if set(actuator_joints) - set(joints):
            raise self._bad("Describe", "an actuator moves a joint not in Joints")
        if mode not in MODES:
            raise self._bad("Describe", f"Mode must be one of {', '.join(MODES)}, got {mode!r}")
        if not (_is_real(step) and math.isfinite(step) and step > 0):
            raise self._bad("Describe", f"Step must be a positive number, got {step!r}")
        try:
            described = json.loads(perturbation) if isinstance(perturbation, str) else None
        except json.JSONDecodeError:
            described = None
        if not isinstance(described, dict):
            raise self._bad("Describe", "Perturbation must be a JSON object")
        return Layout(tuple(joints), dict(zip(actuators, actuator_joints)), tuple(sensors), mode, float(step), described)

    def _bad(self, method: str, why: str) -> CotwinError:
        return CotwinError(f"the plant at {self.url} sent an ill-formed reply to {method}: {why}")

    def _take_state(self, method: str, out: list) -> dict:
        if len(out) != len(STATE):
            raise self._bad(method, f"expected {len(STATE)} outputs ({', '.join(STATE)}), got {len(out)}")
        t, positions, velocities, sensors, goals = out
        if not (_is_real(t) and math.isfinite(t) and t >= 0):
            raise self._bad(method, f"Time must be a finite number >= 0, got {t!r}")
        arrays = {"Positions": (positions, self.layout.joints), "Velocities": (velocities, self.layout.joints),
                  "Sensors": (sensors, self.layout.sensors), "Goals": (goals, self.layout.joints)}
        for name, (values, names) in arrays.items():
            if not isinstance(values, list) or len(values) != len(names):
                raise self._bad(method, f"{name} must hold {len(names)} numbers")
            bad = next((n for n, v in zip(names, values) if not (_is_real(v) and math.isfinite(v))), None)
            if bad is not None:
                raise self._bad(method, f"{name}: '{bad}' is not a finite number")
        self._state = {"time": float(t), "joints": dict(zip(self.layout.joints, map(float, positions))),
                       "velocities": dict(zip(self.layout.joints, map(float, velocities))),
                       "sensors": dict(zip(self.layout.sensors, map(float, sensors))),
                       "goals": dict(zip(self.layout.joints, map(float, goals)))}
        self.time = float(t)
        return self._state

    def _state_call(self, method: str, *args, timeout: float | None = None) -> dict:
        return self._take_state(method, self.call(method, *args, timeout=timeout))

    # ---- the endpoint interface ----
    def start(self) -> None:
        state = self._state_call("Reset" if self.reset else "State")
        self._target = state["time"]

    def stop(self) -> None:
        pass

    def joint(self, name: str) -> str:
        if name not in self.layout.actuators:
            raise CotwinError(f"the plant at {self.url} has no actuator '{name}'")
        return self.layout.actuators[name]

    def actuator_names(self) -> list[str]:
        return list(self.layout.actuators)

    def command(self, goals: dict[str, float]) -> None:
        from asyncua import ua

        for name in goals:
            self.joint(name)
        names = list(goals)
        values = [float(goals[n]) for n in names]
        bad = next((n for n, v in zip(names, values) if not math.isfinite(v)), None)
        if bad is not None:
            raise CotwinError(f"actuator '{bad}': goal {goals[bad]!r} is not a finite number")
        self._state_call("CommandJoints", ua.Variant(names, ua.VariantType.String),
                         ua.Variant(values, ua.VariantType.Double))

    def advance(self, dt: float) -> None:
        from asyncua import ua

        if not (_is_real(dt) and math.isfinite(dt) and 0 <= dt <= DT_MAX):
            raise CotwinError(f"cannot advance the plant at {self.url} by {dt!r} s (0 to {DT_MAX:g} s)")
        if self.layout.mode == "lockstep":
            self._state_call("Advance", ua.Variant(float(dt), ua.VariantType.Double))
            return
        # free-running: the plant keeps its own clock; wait for it to reach our next step's time
        self._target = (self.time if self._target is None else self._target) + dt
        wait = max(0.0, self._target - self.time)
        self._state_call("AdvanceTo", ua.Variant(self._target, ua.VariantType.Double), timeout=self.timeout + wait)

    def refresh(self) -> dict:
        """The plant's state now (State), e.g. to watch a free-running plant."""
        return self._state_call("State")

    def read_sensors(self) -> dict[str, float]:
        return dict(self._state.get("sensors", {}))

    def joint_positions(self) -> dict[str, float]:
        return dict(self._state.get("joints", {}))

    def joint_velocities(self) -> dict[str, float]:
        return dict(self._state.get("velocities", {}))

    def goals(self) -> dict[str, float]:
        return dict(self._state.get("goals", {}))

    def close(self) -> None:
        """Disconnect (bounded by the timeout) and end the client's thread."""
        client, self._client = self._client, None
        if client is not None:
            future = asyncio.run_coroutine_threadsafe(client.disconnect(), self._loop)
            try:
                future.result(min(self.timeout, 5.0))
            except Exception:
                future.cancel()
        self._loop_thread.stop(5)

    def __enter__(self) -> "OPCUAEndpoint":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _unreachable(host: str, port: int, timeout: float) -> str | None:
    """Why nothing answers at host:port (e.g. connection refused), or None when something listens."""
    import socket

    try:
        socket.create_connection((host, port), timeout=min(timeout, 5.0)).close()
    except OSError as err:
        return _describe_error(err)
    return None


def _describe_error(err: BaseException) -> str:
    """A library's exception as one line: connection refused, closed channel, bad status."""
    if isinstance(err, ConnectionRefusedError):
        return "connection refused (is the plant running?)"
    if isinstance(err, (asyncio.TimeoutError, TimeoutError)):
        return "timed out"
    if isinstance(err, OSError):
        return f"connection lost ({err.strerror or type(err).__name__})"
    name = type(err).__name__
    text = str(err).strip()
    if name.startswith("Bad"):
        return f"{name}: {text}" if text and text != name else name
    return f"{name}: {text}" if text else name
