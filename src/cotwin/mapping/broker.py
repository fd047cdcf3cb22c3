"""A robot behind a message broker: the second kind of platform endpoint, over AMQP (RabbitMQ).

`BrokerEndpoint` is what the mapping talks to; `RobotServer` sits next to the robot (here any other
endpoint, e.g. the MuJoCo simulator on another machine) and answers. Lockstep request/reply on one
queue, JSON both ways:

  {"op": "describe"}                      -> {"ok": true, "actuators": [...], "sensors": [...]}
  {"op": "command", "goals": {name: x}}   -> {"ok": true, ...state}
  {"op": "advance", "dt": seconds}        -> {"ok": true, ...state}
  {"op": "state"}                         -> {"ok": true, "time": t, "sensors": {...}, "joints": {...}, "velocities": {...}}
  anything else                           -> {"ok": false, "error": "which field is wrong and why"}
"""

from __future__ import annotations

import json
import math
import threading
import uuid

import pika

from ..diagnostics import CotwinError
from .amqp import connect

DEFAULT_URL = "amqp://127.0.0.1:5672/%2F"
_FIELDS = {"describe": set(), "command": {"goals"}, "advance": {"dt"}, "state": set(), "stop": set()}


def validate_request(message: object) -> dict:
    """A request, or CotwinError naming the unknown or ill-typed field."""
    if not isinstance(message, dict):
        raise CotwinError("request: expected a JSON object")
    op = message.get("op")
    if op not in _FIELDS:
        raise CotwinError(f"request: unknown op {op!r} (known: {', '.join(_FIELDS)})")
    extra = set(message) - _FIELDS[op] - {"op"}
    if extra:
        raise CotwinError(f"request {op}: unknown field(s) {', '.join(sorted(extra))}")
    missing = _FIELDS[op] - set(message)
    if missing:
        raise CotwinError(f"request {op}: missing field(s) {', '.join(sorted(missing))}")
    if op == "advance":
        dt = message["dt"]
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) or not 0 <= dt <= 10:
            raise CotwinError(f"request advance: dt must be a number of seconds in [0, 10], got {dt!r}")
    if op == "command":
        goals = message["goals"]
        if not isinstance(goals, dict):
            raise CotwinError("request command: goals must be an object {actuator: value}")
        for name, value in goals.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise CotwinError(f"request command: goal {name!r} must be a finite number, got {value!r}")
    return message


class RobotServer:
    """Serves an endpoint on a queue until stopped (run it in a thread or its own process)."""

    def __init__(self, endpoint, queue: str, url: str = DEFAULT_URL):
        self.endpoint = endpoint
        self.queue = queue
        self.url = url
        self.ready = threading.Event()
        self._stop = threading.Event()
        self.requests = 0

    def state(self) -> dict:
        return {"ok": True, "time": self.endpoint.time, "sensors": self.endpoint.read_sensors(),
                "joints": self.endpoint.joint_positions(), "velocities": self.endpoint.joint_velocities()}

    def handle(self, body: bytes) -> dict:
        try:
            request = validate_request(json.loads(body))
        except json.JSONDecodeError as err:
            return {"ok": False, "error": f"request: bad JSON ({err.msg})"}
        except CotwinError as err:
            return {"ok": False, "error": err.findings[0].message}
        try:
            op = request["op"]
            if op == "describe":
                return {"ok": True, "actuators": sorted(self.endpoint.actuator_names()),
                        "sensors": sorted(self.endpoint.read_sensors())}
            if op == "command":
                self.endpoint.command(request["goals"])
            elif op == "advance":
                self.endpoint.advance(float(request["dt"]))
            elif op == "stop":
                self._stop.set()
            return self.state()
        except CotwinError as err:
            return {"ok": False, "error": err.findings[0].message}

    def serve(self) -> None:
        connection = connect(self.url, f"cotwin robot server {self.queue}")
        channel = connection.channel()
        channel.queue_declare(queue=self.queue, auto_delete=True)
        self.ready.set()
        try:
            for method, props, body in channel.consume(self.queue, inactivity_timeout=0.2):
                if self._stop.is_set():
                    break
                if method is None:
                    continue
                self.requests += 1
                reply = self.handle(body)
                channel.basic_publish("", props.reply_to, json.dumps(reply).encode(),
                                      pika.BasicProperties(correlation_id=props.correlation_id))
                channel.basic_ack(method.delivery_tag)
        finally:
            try:
                channel.cancel()
                connection.close()
            except Exception:
                pass

    def stop(self) -> None:
        self._stop.set()


class BrokerEndpoint:
    """The mapping's view of a robot behind the broker (the same interface as SimulatedEndpoint)."""

    def __init__(self, tree, queue: str, url: str = DEFAULT_URL, timeout: float = 10.0):
        self.tree = tree
        self.queue = queue
        self.timeout = timeout
        self.connection = connect(url, f"cotwin robot client {queue}")
        self.channel = self.connection.channel()
        result = self.channel.queue_declare(queue="", exclusive=True)
        self.reply_queue = result.method.queue
        self.channel.basic_consume(self.reply_queue, self._on_reply, auto_ack=True)
        self._replies: dict[str, dict] = {}
        self._state: dict = {}
        described = self.call({"op": "describe"})
        self.actuators = set(described["actuators"])
        self.time = 0.0

    def _on_reply(self, channel, method, props, body) -> None:
        self._replies[props.correlation_id] = json.loads(body)

    def call(self, request: dict) -> dict:
        cid = str(uuid.uuid4())
        self.channel.basic_publish("", self.queue, json.dumps(request).encode(),
                                   pika.BasicProperties(reply_to=self.reply_queue, correlation_id=cid))
        self.connection.process_data_events(time_limit=0)
        waited = 0.0
        while cid not in self._replies:
            self.connection.process_data_events(time_limit=0.05)
            waited += 0.05
            if waited > self.timeout:
                raise CotwinError(f"the robot on queue '{self.queue}' did not answer {request['op']} within {self.timeout:g} s")
        reply = self._replies.pop(cid)
        if not reply.get("ok"):
            raise CotwinError(f"the robot refused {request['op']}: {reply.get('error')}")
        if "time" in reply:
            self._state = reply
            self.time = reply["time"]
        return reply

    # ---- the endpoint interface ----
    def start(self) -> None:
        self.call({"op": "state"})

    def stop(self) -> None:
        pass

    def joint(self, name: str) -> str:
        if name not in self.actuators:
            raise CotwinError(f"the robot on queue '{self.queue}' has no actuator '{name}'")
        return name

    def command(self, goals: dict[str, float]) -> None:
        self.call({"op": "command", "goals": goals})

    def advance(self, dt: float) -> None:
        self.call({"op": "advance", "dt": dt})

    def read_sensors(self) -> dict[str, float]:
        return dict(self._state.get("sensors", {}))

    def joint_positions(self) -> dict[str, float]:
        return dict(self._state.get("joints", {}))

    def joint_velocities(self) -> dict[str, float]:
        return dict(self._state.get("velocities", {}))

    def close(self) -> None:
        try:
            self.connection.close()
        except Exception:
            pass
