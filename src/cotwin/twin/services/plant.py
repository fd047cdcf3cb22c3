"""The plant: a stand-in physical robot cell served over OPC UA (`cotwin plant PROJECT --opcua URL`).

The project's models run in the embedded MuJoCo simulator behind a SimulatedEndpoint, perturbed as
the project's `[plant]` table (or a perturbation file, or flags) says (cotwin.pmodel.perturbation),
behind an asyncua server whose address space and methods cotwin.mapping.opcua documents.

Two clocks:
- lockstep (default): the plant's time moves only when a client calls Advance/AdvanceTo, as the broker
  robot does; the twin steps it like any endpoint, and PT and DT see the same steps.
- free-running (`--free-running`): the plant advances itself in real time, as a real cell does;
  Advance(Dt) waits until the plant's time reaches its time at the call plus Dt, AdvanceTo(T) until it
  reaches T (at once if it already has), and both return the state then. Commands apply at once.

Reset: the Reset method puts the cell back in the project's initial posture at time 0 (goals, pending
commands and the noise generator too); with `--reset-on-connect` the plant does so whenever an operator
session is activated, so that every twin run starts from the same posture as its DT.

Credentials and the port: a plant writes its generated operator credentials only once it listens
(cotwin.mapping.opcua_auth), so a second plant on a busy port touches nothing of the first one's; it
is refused naming the process that holds the port (cotwin.listeners).

Security (what is on by default): the server listens only on a loopback address (a non-loopback host
is refused); it offers no OPC UA message security (Basic256Sha256 needs certificates on both sides, a
later option), so it relies on the loopback rule for confidentiality. Anonymous sessions may browse,
read and subscribe; calling methods and writing need the operator login (cotwin.mapping.opcua_auth:
credentials from the environment, or a random password written to a file only this user can read).
Every call is checked; a bad one is refused with an OPC UA status naming the problem, never a crash.
"""

from __future__ import annotations

import asyncio
import errno
import json
import logging
import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ...diagnostics import CotwinError
from ...listeners import in_use_message
from ...mapping.opcua import (DT_MAX, NAMESPACE, ROBOT, RequestError, check_dt, check_goal_ranges, check_goals, check_time,
                             parse_goals)
from ...mapping.opcua_auth import PlantCredentials, is_loopback, opc_url, parse_url
from ...mapping.perturbed import PerturbedEndpoint
from ...pmodel.perturbation import Perturbation, check_joints, read_perturbation, read_table
from ...service import BackgroundService

log = logging.getLogger("cotwin.plant")
logging.getLogger("asyncua").addHandler(logging.NullHandler())

FREE_RUNNING_PERIOD = 0.005  # s of wall time between the free-running plant's advances
UNITS = {"revolute": ("rad", "rad/s"), "prismatic": ("m", "m/s")}


def _ua():
    from asyncua import ua

    return ua


class _Operators:
    """asyncua user manager: anonymous sessions are observers, the operator login drives the cell.
    `on_operator()` is called (on the server's loop) whenever an operator's session is activated."""

    def __init__(self, credentials, on_operator=None):
        self.credentials = credentials
        self.on_operator = on_operator

    def get_user(self, iserver, username=None, password=None, certificate=None):
        from asyncua.crypto.permission_rules import User, UserRole

        if username is None and password is None:  # (certificate: the channel's peer, if any; not an identity here)
            return User(role=UserRole.Anonymous)
        if self.credentials.matches(username, password):
            if self.on_operator is not None:
                self.on_operator()
            return User(role=UserRole.User, name=username)
        return None  # refused: Bad_UserAccessDenied at ActivateSession


def _ruleset():
    """Observers may read, browse and subscribe; operators may also call methods and write."""
    from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, UserRole

    ua = _ua()
    driving = {ua.NodeId(i) for i in (ua.ObjectIds.CallRequest_Encoding_DefaultBinary,
                                      ua.ObjectIds.WriteRequest_Encoding_DefaultBinary,
                                      ua.ObjectIds.HistoryReadRequest_Encoding_DefaultBinary)}
    user = {ua.NodeId(i) for i in USER_TYPES}

    class Rules(PermissionRuleset):
        def check_validity(self, who, action_type_id, body):
            if who.role is UserRole.User:
                return action_type_id in user
            if who.role is UserRole.Anonymous:
                return action_type_id in user - driving
            return False

    return Rules()


class Plant(BackgroundService):
    """A robot cell over OPC UA, driven by the embedded simulator (see the module doc).

    `start()` returns once the server listens (its URL in `url`, the real port if 0 was asked);
    `stop()` closes it. Everything OPC UA runs on the plant's own thread and event loop; the simulator
    on one worker thread, so calls are applied one at a time in arrival order."""

    def __init__(self, endpoint: PerturbedEndpoint, url: str = "opc.tcp://127.0.0.1:4840",
                 free_running: bool = False, environ=os.environ, reset_on_connect: bool = False):
        host, port = parse_url(url)
        if not is_loopback(host):
            raise CotwinError(f"the plant serves on loopback addresses only (127.0.0.1, ::1), not '{host}': "
                              "OPC UA message security is not offered yet, so a plant on a network would be open "
                              "to anyone who can reach it")
        self.endpoint = endpoint
        self.host, self.port = host, port
        self.url = opc_url(host, port)  # with its port, also when the URL given leaves the default out
        self.free_running = free_running
        self.mode = "free-running" if free_running else "lockstep"
        self.reset_on_connect = reset_on_connect
        self.resets = 0
        self._environ = environ
        self._tree = endpoint.tree
        self.joints = [j.name for j in self._tree.actuated]
        self.actuators = {name: endpoint.joint(name) for name in endpoint.actuator_names()}
        self.sensors = sorted(endpoint.read_sensors())
        self.calls = 0
        self.refused = 0
        BackgroundService.__init__(self, f"plant {url}")
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._sim = ThreadPoolExecutor(max_workers=1, thread_name_prefix="plant-sim")
        self._credentials: PlantCredentials | None = None
        self._halted: str | None = None

    # ---- life cycle ----
    def start(self, timeout: float = 30.0) -> "Plant":
        """Serve on the plant's thread (cotwin.service.BackgroundService); CotwinError if it cannot. Starting a
        started plant does nothing (`with plant.start():` made a new account, and the served one's file was left)."""
        if not self.started:
            self._credentials = PlantCredentials(self._environ)
        return BackgroundService.start(self, timeout)

    def late(self, timeout: float) -> CotwinError:
        return CotwinError(f"the plant did not start serving on {self.url} within {timeout:g} s")

    def error_of(self, err: BaseException) -> CotwinError:
        if isinstance(err, OSError) and err.errno == errno.EADDRINUSE:
            return CotwinError(f"cannot serve the plant on {self.url}: {in_use_message(self.host, self.port)}")
        return CotwinError(f"cannot serve the plant on {self.url}: {_reason(err)}")

    def interrupt(self) -> None:
        loop = self._loop
        if loop is None or self._stopping is None or loop.is_closed():
            return  # not serving (yet), or its start failed and its loop is gone
        try:
            loop.call_soon_threadsafe(self._stopping.set)
        except RuntimeError:  # closed between the check and the call: nothing left to wake
            pass

    def stop(self, timeout: float | None = 10.0) -> bool:
        ended = BackgroundService.stop(self, timeout)
        self._sim.shutdown(wait=True, cancel_futures=True)
        if self._credentials is not None:
            self._credentials.close()
            self._credentials = None
        return ended

    @property
    def credentials_file(self) -> Path | None:
        """Where the generated operator credentials are (None when they come from the environment)."""
        return self._credentials.file if self._credentials is not None else None

    def __enter__(self) -> "Plant":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def serve(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())  # a failure: reported by start(), or logged once serving
        finally:
            self._loop = None  # stop() after a failed start has no loop to wake ("Event loop is closed")
            loop.close()

    async def _main(self) -> None:
        from asyncua import Server

        ua = _ua()
        self._stopping = asyncio.Event()
        self._advanced = asyncio.Condition()
        server = Server(user_manager=_Operators(self._credentials.credentials,
                                                self._operator_connected if self.reset_on_connect else None))
        await server.init()
        server.set_endpoint(opc_url(self.host, self.port) + "/")
        server.set_server_name(f"cotwin plant: {self._tree.name}")
        await server.set_application_uri(f"urn:cotwin:plant:{self._tree.name}")
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity], permission_ruleset=_ruleset())
        server.set_identity_tokens([ua.AnonymousIdentityToken, ua.UserNameIdentityToken])
        server.allow_remote_admin(False)
        self._server = server
        self._ns = await server.register_namespace(NAMESPACE)
        await self._build(server)
        await server.start()
        if self.port == 0:
            self.port = server.bserver.port
            self.url = opc_url(self.host, self.port)
        self._credentials.publish(self.url)  # the port is ours now: so is its credentials file
        await self._publish(await self._on_sim(self._snapshot))
        self.ready()
        ticker = asyncio.create_task(self._run_free()) if self.free_running else None
        try:
            await self._stopping.wait()
        finally:
            if ticker is not None:
                ticker.cancel()
            await _stop_clock(server)
            await server.stop()

    # ---- the address space ----
    def _id(self, *parts: str):
        return _ua().NodeId(".".join((ROBOT, *parts)), self._ns)

    async def _build(self, server) -> None:
        ua = _ua()
        ns = self._ns
        robot = await server.nodes.objects.add_object(self._id(), ua.QualifiedName(self._tree.name, ns))
        self._values: dict[str, object] = {}

        async def variable(parent, key: tuple[str, ...], name: str, value, kind, unit: str | None = None):
            node = await parent.add_variable(self._id(*key), ua.QualifiedName(name, ns), ua.Variant(value, kind))
            if unit:
                await node.add_property(self._id(*key, "Unit"), ua.QualifiedName("Unit", ns), unit)
            return node

        double, string = ua.VariantType.Double, ua.VariantType.String
        self._time_node = await variable(robot, ("Time",), "Time", 0.0, double, "s")
        await variable(robot, ("Mode",), "Mode", self.mode, string)
        await variable(robot, ("Perturbation",), "Perturbation", json.dumps(self._perturbation()), string)
        self._error_node = await variable(robot, ("LastError",), "LastError", "", string)
        joints = await robot.add_folder(self._id("Joints"), ua.QualifiedName("Joints", ns))
        kinds = {j.name: j.kind for j in self._tree.actuated}
        self._joint_nodes = {}
        for name in self.joints:
            obj = await joints.add_object(self._id("Joints", name), ua.QualifiedName(name, ns))
            position, velocity = UNITS.get(kinds[name], ("", ""))
            self._joint_nodes[name] = [
                (await variable(obj, ("Joints", name, q), q, 0.0, double, u)).nodeid
                for q, u in (("Position", position), ("Velocity", velocity), ("Goal", position))]
        sensors = await robot.add_folder(self._id("Sensors"), ua.QualifiedName("Sensors", ns))
        self._sensor_nodes = [(await variable(sensors, ("Sensors", s), s, 0.0, double)).nodeid for s in self.sensors]

        def arg(name: str, kind, description: str, array: bool = False):
            return ua.Argument(Name=name, DataType=ua.NodeId(kind.value), ValueRank=1 if array else -1,
                               ArrayDimensions=[0] if array else [], Description=ua.LocalizedText(description))

        state = [arg("Time", double, "the plant's time (s)"),
                 arg("Positions", double, "joint positions, in Describe's order of Joints", True),
                 arg("Velocities", double, "joint velocities, in Describe's order of Joints", True),
                 arg("Sensors", double, "sensor readings, in Describe's order of Sensors", True),
                 arg("Goals", double, "servo goals in force, in Describe's order of Joints", True)]
        methods = {
            "Describe": ([], [arg("Joints", string, "actuated joints", True),
                              arg("Actuators", string, "every name an actuator answers to", True),
                              arg("ActuatorJoints", string, "the joint each actuator moves", True),
                              arg("Sensors", string, "sensor ports by mapping path", True),
                              arg("Mode", string, "lockstep | free-running"),
                              arg("Step", double, "the physics step (s)"),
                              arg("Perturbation", string, "the perturbation (JSON)")], self._describe),
            "State": ([], state, self._state),
            "Command": ([arg("Goals", string, 'servo goals, a JSON object {"actuator": value}')], state, self._command),
            "CommandJoints": ([arg("Actuators", string, "actuator names", True),
                               arg("Goals", double, "their goals (rad or m)", True)], state, self._command_joints),
            "Advance": ([arg("Dt", double, f"seconds to advance, 0 to {DT_MAX:g}")], state, self._advance),
            "AdvanceTo": ([arg("Time", double, "the plant time to reach (s)")], state, self._advance_to),
            "Reset": ([], state, self._reset),
        }
        for name, (inputs, outputs, handler) in methods.items():
            await robot.add_method(self._id(name), ua.QualifiedName(name, ns), self._guarded(name, handler, inputs),
                                   inputs, outputs)

    def _perturbation(self) -> dict:
        p = self.endpoint.perturbation
        return p.as_dict() if isinstance(p, Perturbation) else {}

    # ---- calls ----
    def _guarded(self, name: str, handler, inputs: list):
        """The method as asyncua calls it: arguments counted and unwrapped, every failure a status."""
        ua = _ua()

        async def call(parent, *args):
            self.calls += 1
            try:
                if len(args) < len(inputs):
                    raise RequestError("BadArgumentsMissing", f"{name} takes {len(inputs)} argument(s) "
                                       f"({', '.join(a.Name for a in inputs)}), got {len(args)}")
                if len(args) > len(inputs):
                    raise RequestError("BadTooManyArguments", f"{name} takes {len(inputs)} argument(s), got {len(args)}")
                outputs = await handler(*[a.Value if isinstance(a, ua.Variant) else a for a in args])
            except RequestError as err:
                return await self._refuse(name, err, len(args))
            except CotwinError as err:
                return await self._refuse(name, RequestError("BadInvalidState", err.findings[0].message), len(args))
            except Exception as err:  # a bug of ours: refuse the call, keep serving
                log.exception("%s failed", name)
                return await self._refuse(name, RequestError("BadInternalError", f"internal error: {_reason(err)}"),
                                          len(args))
            await self._write(self._error_node.nodeid, "", ua.VariantType.String)
            return outputs

        return call

    async def _refuse(self, method: str, err: RequestError, count: int):
        ua = _ua()
        self.refused += 1
        text = f"{method}: {err.message}"
        await self._write(self._error_node.nodeid, text, ua.VariantType.String)
        result = ua.CallMethodResult()
        status = getattr(ua.StatusCodes, err.status)
        results = [ua.StatusCode(ua.StatusCodes.Good) for _ in range(count)]
        infos = [ua.DiagnosticInfo() for _ in range(count)]
        if err.argument is not None and err.argument < count:
            results[err.argument] = ua.StatusCode(status)
            infos[err.argument] = ua.DiagnosticInfo(AdditionalInfo=err.message)
            status = ua.StatusCodes.BadInvalidArgument
        result.StatusCode = ua.StatusCode(status)
        result.InputArgumentResults = results
        result.InputArgumentDiagnosticInfos = infos if err.argument is not None and err.argument < count else []
        return result

    async def _on_sim(self, fn, *args):
        return await asyncio.get_running_loop().run_in_executor(self._sim, fn, *args)

    def _snapshot(self) -> tuple:
        e = self.endpoint
        q, qd, goals, sensors = e.joint_positions(), e.joint_velocities(), e.goals(), e.read_sensors()
        return (float(e.time), [q[j] for j in self.joints], [qd[j] for j in self.joints],
                [sensors[s] for s in self.sensors], [goals.get(j, q[j]) for j in self.joints])

    async def _write(self, nodeid, value, kind) -> None:
        ua = _ua()
        await self._server.write_attribute_value(nodeid, ua.DataValue(ua.Variant(value, kind)))

    async def _publish(self, snapshot: tuple) -> list:
        """Write the snapshot into the variables; the STATE outputs of a call."""
        ua = _ua()
        double = ua.VariantType.Double
        t, q, qd, sensors, goals = snapshot
        await self._write(self._time_node.nodeid, t, double)
        for i, name in enumerate(self.joints):
            for node, value in zip(self._joint_nodes[name], (q[i], qd[i], goals[i])):
                await self._write(node, value, double)
        for node, value in zip(self._sensor_nodes, sensors):
            await self._write(node, value, double)
        return [ua.Variant(t, double), ua.Variant(q, double), ua.Variant(qd, double), ua.Variant(sensors, double),
                ua.Variant(goals, double)]

    async def _describe(self) -> list:
        ua = _ua()
        string = ua.VariantType.String
        return [ua.Variant(self.joints, string), ua.Variant(list(self.actuators), string),
                ua.Variant(list(self.actuators.values()), string), ua.Variant(self.sensors, string),
                ua.Variant(self.mode, string), ua.Variant(self.endpoint.sim.timestep, ua.VariantType.Double),
                ua.Variant(json.dumps(self._perturbation()), string)]

    async def _state(self) -> list:
        return await self._publish(await self._on_sim(self._snapshot))

    def _check_names(self, goals: dict[str, float], argument: int) -> None:
        for name in goals:
            if name not in self.actuators:
                raise RequestError("BadNoMatch", f"unknown actuator '{name}' (actuators: "
                                   f"{', '.join(a for a in self.actuators if '::' not in a)}, or their mapping paths)",
                                   argument)

    def _check_ranges(self, goals: dict[str, float], argument: int) -> None:
        joints = {j.name: j for j in self._tree.actuated}
        check_goal_ranges(goals, {name: joints[self.actuators[name]] for name in goals}, argument)

    async def _apply(self, goals: dict[str, float]) -> list:
        def apply():
            self.endpoint.command(goals)
            return self._snapshot()

        return await self._publish(await self._on_sim(apply))

    async def _command(self, text) -> list:
        goals = parse_goals(text)
        self._check_names(goals, 0)
        self._check_ranges(goals, 0)
        return await self._apply(goals)

    async def _command_joints(self, names, values) -> list:
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise RequestError("BadTypeMismatch", "Actuators must be an array of Strings", 0)
        if not isinstance(values, list):
            raise RequestError("BadTypeMismatch", "Goals must be an array of Doubles", 1)
        if len(names) != len(values):
            raise RequestError("BadInvalidArgument", f"{len(names)} actuator(s) but {len(values)} goal(s)", 1)
        if len(set(names)) != len(names):
            raise RequestError("BadInvalidArgument", "an actuator is named twice", 0)
        self._check_names(dict.fromkeys(names), 0)
        goals = check_goals(dict(zip(names, values)), 1)
        self._check_ranges(goals, 1)
        return await self._apply(goals)

    async def _advance(self, dt) -> list:
        dt = check_dt(dt)
        if self.free_running:
            return await self._wait_until(self.endpoint.time + dt)
        return await self._publish(await self._on_sim(self._step, dt))

    async def _advance_to(self, t) -> list:
        now = self.endpoint.time
        if self.free_running:
            if not (isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t)):
                raise RequestError("BadTypeMismatch", f"Time must be a finite Double, got {t!r}", 0)
            if t - now > DT_MAX:
                raise RequestError("BadOutOfRange", f"Time {t!r} is more than {DT_MAX:g} s after the plant's {now:g}", 0)
            return await self._wait_until(float(t))
        t = check_time(t, now)
        return await self._publish(await self._on_sim(self._step, max(0.0, t - now)))

    def _step(self, dt: float) -> tuple:
        self.endpoint.advance(dt)
        return self._snapshot()

    def _reset_now(self) -> tuple:
        """Back to the project's initial posture at time 0 (on the simulator's thread)."""
        self.endpoint.reset()
        self.resets += 1
        return self._snapshot()

    async def _reset(self) -> list:
        snapshot = await self._on_sim(self._reset_now)
        self._anchor = (time.monotonic(), 0.0)
        return await self._publish(snapshot)

    def _operator_connected(self) -> None:
        """--reset-on-connect: a new operator session starts from the initial posture. Queued on the
        simulator's thread now, before any call of that session can be, and published when done."""
        future = asyncio.wrap_future(self._sim.submit(self._reset_now))
        self._anchor = (time.monotonic(), 0.0)
        log.info("operator connected: the plant is reset to its initial posture")

        async def publish() -> None:
            await self._publish(await future)

        asyncio.get_running_loop().create_task(publish())

    # ---- free running ----
    async def _run_free(self) -> None:
        """Advance the simulation with the wall clock, in whole physics steps, and wake the waiters."""
        step = self.endpoint.sim.timestep
        self._anchor = (time.monotonic(), self.endpoint.time)
        try:
            while True:
                wall0, sim0 = self._anchor
                behind = sim0 + (time.monotonic() - wall0) - self.endpoint.time
                if behind >= step:
                    snapshot = await self._on_sim(self._step, math.floor(behind / step + 1e-9) * step)
                    await self._publish(snapshot)
                    async with self._advanced:
                        self._advanced.notify_all()
                await asyncio.sleep(FREE_RUNNING_PERIOD)
        except CotwinError as err:  # e.g. unstable physics: the cell has stopped; say so to every waiter
            self._halted = f"the free-running plant stopped at t = {self.endpoint.time:.3f} s: {err.findings[0].message}"
            log.error("%s", self._halted)
            async with self._advanced:
                self._advanced.notify_all()

    async def _wait_until(self, t: float) -> list:
        half = self.endpoint.sim.timestep / 2
        async with self._advanced:
            await self._advanced.wait_for(lambda: self.endpoint.time >= t - half or self._halted)
        if self._halted:
            raise RequestError("BadInvalidState", self._halted)
        return await self._state()

    # ---- the command line ----
    def serve_until_signalled(self, announce=print) -> None:
        """Serve until SIGINT or SIGTERM (the main thread's), then stop cleanly."""
        import signal

        done = threading.Event()
        previous = {s: signal.signal(s, lambda *_: done.set()) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self.start()
            announce(self)
            while not done.wait(0.5):
                if not self.running:
                    raise CotwinError(f"the plant on {self.url} stopped unexpectedly")
        finally:
            self.stop()
            for s, handler in previous.items():
                signal.signal(s, handler)


def _reason(err: BaseException) -> str:
    if isinstance(err, OSError) and err.strerror:
        return err.strerror
    return f"{type(err).__name__}: {err}" if str(err) else type(err).__name__


def load_plant(project, url: str | None = None, free_running: bool = False,
               perturbation_file: str | Path | None = None, reset_on_connect: bool = False, **options) -> Plant:
    """The plant of a twin project (not started): its models in the simulator with the perturbation of
    the project's [plant] table, over which a perturbation file and then `options` (Perturbation fields
    that are not None) take precedence. The URL defaults to the project's [pt] url, else port 4840."""
    from ...config import TomlFile
    from ..assembly.run import load

    system = load(project)
    spec = system.spec
    perturbation = spec.plant or Perturbation()  # its joints checked with the project's other problems (load)
    if perturbation_file is not None:
        file = TomlFile(perturbation_file, "perturbation file")
        perturbation = read_table(file) or Perturbation()
        check_joints(perturbation, system.models.tree, file)
    perturbation = perturbation.with_options(**options)
    if url is None:
        url = spec.pt.url if spec.pt is not None and spec.pt.endpoint == "opcua" and spec.pt.url else \
            "opc.tcp://127.0.0.1:4840"
    endpoint = PerturbedEndpoint.build(system.models.tree, system.models.scene, perturbation, spec.base,
                                       system.models.tool)  # its payload at the project's tool
    return Plant(endpoint, url, free_running, reset_on_connect=reset_on_connect)


__all__ = ["Plant", "load_plant", "read_perturbation"]


async def _stop_clock(server) -> None:
    """Cancel the server's once-a-second clock task: asyncua's stop waits for its next tick, so every plant
    stop took up to a second (an asyncua without that task stops as before)."""
    try:
        clock = server.iserver.time_task
    except AttributeError:
        return
    if clock is None or clock.done():
        return
    clock.cancel()
    await asyncio.wait({clock})
    server.iserver.time_task = None
