"""A robot behind a message broker: the second kind of platform endpoint, over AMQP (RabbitMQ).

`BrokerEndpoint` is what the mapping talks to; `RobotServer` sits next to the robot (here any other
endpoint, e.g. the MuJoCo simulator on another machine) and answers. Lockstep request/reply, JSON both
ways, on the server's request queue (declared exclusive: no second consumer, no impostor can take it):

  {"op": "describe"}                      -> {"ok": true, "actuators": [...], "sensors": [...]}
  {"op": "command", "goals": {name: x}}   -> {"ok": true, ...state}
  {"op": "advance", "dt": seconds}        -> {"ok": true, ...state}
  {"op": "state"}                         -> {"ok": true, "time": t, "sensors": {...}, "joints": {...}, "velocities": {...}}
  anything else                           -> {"ok": false, "error": "which field is wrong and why"}

Every message is authenticated and checked as `robot_protocol` says; stopping the server is a local
call (`RobotServer.stop`, or a signal to `cotwin serve-robot`), never a message.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time as wallclock
import uuid
from typing import Mapping

import pika

from ..diagnostics import CotwinError
from ..logcap import CappedLog
from ..service import BackgroundService
from .amqp import connect, redact, scrub
from .platform import Endpoint
from .robot_protocol import (MAX_REPLY, MAX_REQUEST, OPS, REPLY_QUEUE, ReplayGuard, RobotView, check_reply,
                             check_request, decode, load_secret, reply_headers, request_headers, validate_reply,
                             validate_request)

log = logging.getLogger("cotwin.broker")

DEFAULT_URL = "amqp://127.0.0.1:5672/%2F"
LOG_BURST, LOG_WINDOW = 20, 60.0  # refused messages logged per window (a flood must not flood the log)
_LINK_ERRORS = (pika.exceptions.AMQPError, OSError)

__all__ = ["BrokerEndpoint", "DEFAULT_URL", "OPS", "RobotServer", "validate_request"]


class RobotServer(BackgroundService):
    """Serves an endpoint on a queue until `stop()`: on its own thread (`start()`, cotwin.service), or
    `serve()` called in a thread or process of the caller's. It answers every message it can with a reply
    or an error, and no message stops or crashes it. `connected` is set while it is on its queue."""

    def __init__(self, endpoint, queue: str, url: str = DEFAULT_URL, secret: bytes | None = None,
                 environ: Mapping[str, str] | None = None, reconnect_s: float = 60.0):
        BackgroundService.__init__(self, f"cotwin robot server {queue}")
        self.endpoint = endpoint
        self.queue = queue
        self.url = url
        self.environ = environ
        self.secret = secret if secret is not None else load_secret(os.environ if environ is None else environ)
        self.reconnect_s = reconnect_s
        self.connected = threading.Event()
        self.guard = ReplayGuard()
        self._known: set[str] | None = None
        self.requests = 0  # authenticated requests answered
        self.refused = 0  # answered with "not authenticated"
        self.dropped = 0  # could not be answered (no or foreign reply queue, no correlation id)
        self.reconnects = 0
        self.internal_errors = 0  # an endpoint failure other than a CotwinError (logged with its traceback)
        self._warnings = CappedLog(log, f"refused messages of robot server {queue}", LOG_BURST, LOG_WINDOW)

    def _warn(self, reason: str) -> None:
        """Log a refused message, at most LOG_BURST per LOG_WINDOW (then say how many were not logged)."""
        self._warnings.warning("robot server %s: %s", self.queue, reason)

    # ---- one message ----
    def state(self) -> dict:
        return {"ok": True, "time": self.endpoint.time, "sensors": self.endpoint.read_sensors(),
                "joints": self.endpoint.joint_positions(), "velocities": self.endpoint.joint_velocities()}

    def _actuators(self) -> set[str] | None:
        if self._known is None:
            names = self.endpoint.actuator_names()
            self._known = set(names) if names is not None else set()
        return self._known or None

    def handle(self, body: bytes) -> bytes:
        """The reply body to an authenticated request body; never raises."""
        try:
            request = validate_request(decode(body, MAX_REQUEST, "request"), self._actuators())
            op = request["op"]
            if op == "describe":
                reply = {"ok": True, "actuators": sorted(self.endpoint.actuator_names()),
                         "sensors": sorted(self.endpoint.read_sensors())}
            else:
                if op == "command":
                    self.endpoint.command({str(k): float(v) for k, v in request["goals"].items()})
                elif op == "advance":
                    self.endpoint.advance(float(request["dt"]))
                reply = self.state()
            try:
                return json.dumps(reply, allow_nan=False).encode()
            except ValueError:
                raise CotwinError(f"the robot's state after {op} holds a non-finite value") from None
        except CotwinError as err:
            reply = {"ok": False, "error": "; ".join(f.message for f in err.findings)}
        except Exception as err:  # noqa: BLE001 - an endpoint's bug must not take the server down
            self.internal_errors += 1
            log.exception("robot server %s: internal error", self.queue)
            reply = {"ok": False, "error": f"internal error of the robot server ({type(err).__name__}); see its log"}
        return json.dumps(reply).encode()

    def respond(self, props, body) -> tuple[str, str, bytes, dict] | None:
        """(reply queue, correlation id, reply body, headers) for a delivered message, or None when it
        cannot be answered (it is then logged and dropped); never raises."""
        try:
            reply_to, cid = getattr(props, "reply_to", None), getattr(props, "correlation_id", None)
            if not (isinstance(reply_to, str) and REPLY_QUEUE.match(reply_to)
                    and isinstance(cid, str) and 0 < len(cid) <= 128):
                self.dropped += 1
                self._warn("message dropped (no reply queue of its own or no correlation id)")
                return None
            body = body if isinstance(body, bytes) else b""
            problem = check_request(self.secret, self.queue, cid, reply_to, getattr(props, "headers", None), body,
                                    self.guard)
            if problem is not None:
                self.refused += 1
                self._warn(problem)
                out = json.dumps({"ok": False, "error": problem}).encode()
            else:
                self.requests += 1
                out = self.handle(body)
            return reply_to, cid, out, reply_headers(self.secret, self.queue, cid, out)
        except Exception:  # noqa: BLE001 - nothing a message holds may stop the server
            self.internal_errors += 1
            log.exception("robot server %s: internal error", self.queue)
            return None

    # ---- the link ----
    def _on_message(self, channel, method, props, body) -> None:
        answer = self.respond(props, body)
        if answer is not None:
            reply_to, cid, out, headers = answer
            try:
                channel.basic_publish("", reply_to, out, pika.BasicProperties(correlation_id=cid, headers=headers,
                                                                              content_type="application/json"))
            except _LINK_ERRORS:
                raise  # the link is gone: serve() reconnects
            except Exception:  # noqa: BLE001 - a reply that cannot be encoded must not stop the server
                self.internal_errors += 1
                log.exception("robot server %s: cannot send a reply", self.queue)
        channel.basic_ack(method.delivery_tag)

    def _open(self):
        connection = connect(self.url, f"cotwin robot server {self.queue}", self.environ)
        try:
            channel = connection.channel()
            channel.queue_declare(queue=self.queue, exclusive=True)
            channel.basic_qos(prefetch_count=32)
            channel.basic_consume(self.queue, self._on_message)
            return connection
        except pika.exceptions.ChannelClosedByBroker as err:
            _close(connection)
            if err.reply_code == 405:
                raise CotwinError(f"the robot queue '{self.queue}' on {redact(self.url)} is held by another connection "
                                  "(a second robot server, or an impostor): only one server may answer on it") from None
            if err.reply_code == 403:
                raise CotwinError(f"the broker user may not declare or read the robot queue '{self.queue}' on "
                                  f"{redact(self.url)} (see docs/security.md for its permissions)") from None
            raise CotwinError(f"cannot serve on '{self.queue}' at {redact(self.url)}: {scrub(err.reply_text)}") from None
        except _LINK_ERRORS as err:
            _close(connection)
            raise CotwinError(f"lost the broker at {redact(self.url)} while setting up ({type(err).__name__})") from None

    def serve(self) -> None:
        """Answer requests until stopped; a lost broker is reconnected to for up to `reconnect_s`.
        CotwinError if the first connection fails, the queue is taken, or the broker stays away."""
        connection = self._open()
        lost_at: float | None = None
        try:
            while not self.stopping.is_set():
                try:
                    if connection is None:
                        connection = self._open()
                        self.reconnects += 1
                        log.warning("robot server %s: reconnected after %.1f s", self.queue, wallclock.monotonic() - lost_at)
                        lost_at = None
                    self.connected.set()
                    self.ready()
                    connection.process_data_events(time_limit=0.2)
                except _LINK_ERRORS + (CotwinError,) as err:
                    self.connected.clear()
                    _close(connection)
                    connection = None
                    now = wallclock.monotonic()
                    if lost_at is None:
                        lost_at = now
                        reason = "; ".join(f.message for f in err.findings) if isinstance(err, CotwinError) else type(err).__name__
                        log.warning("robot server %s: lost the broker (%s); reconnecting", self.queue, reason)
                    if now - lost_at > self.reconnect_s:
                        raise CotwinError(f"robot server {self.queue}: the broker at {redact(self.url)} stayed away "
                                          f"for {self.reconnect_s:g} s") from None
                    self.stopping.wait(0.5)
        finally:
            self.connected.clear()
            _close(connection)
            self._warnings.close()  # how many refusals were counted but not logged

    def stop(self, timeout: float | None = 10.0) -> bool:
        """Stop serving: from another thread, or a signal handler (a local call; a thread of its own, started
        by `start`, is joined)."""
        return BackgroundService.stop(self, timeout)


def _close(connection) -> None:
    if connection is not None:
        try:
            connection.close()
        except Exception:  # noqa: BLE001 - closing a link that may be dead already
            pass


class BrokerEndpoint(Endpoint):
    """The mapping's view of a robot behind the broker (the same interface as SimulatedEndpoint).
    Only authenticated replies are taken, each checked against what the robot described."""

    def __init__(self, tree, queue: str, url: str = DEFAULT_URL, timeout: float = 10.0, secret: bytes | None = None,
                 environ: Mapping[str, str] | None = None):
        self.tree = tree
        self.queue = queue
        self.url = url
        self.timeout = timeout
        self.secret = secret if secret is not None else load_secret(os.environ if environ is None else environ)
        self.view = RobotView(joints={j.name for j in tree.joints} if tree is not None else None)
        self._pending: str | None = None
        self._reply: tuple[object, bytes] | None = None
        self._returned = False
        self.stray = 0  # replies to no pending request (late, or someone else's)
        self.connection = connect(url, f"cotwin robot client {queue}", environ)
        try:
            self.channel = self.connection.channel()
            self.reply_queue = self.channel.queue_declare(queue="", exclusive=True).method.queue
            self.channel.basic_consume(self.reply_queue, self._on_reply, auto_ack=True)
            self.channel.add_on_return_callback(self._on_return)
        except _LINK_ERRORS as err:
            self.close()
            raise CotwinError(f"cannot set up the reply queue on {redact(url)} ({scrub(type(err).__name__ + ': ' + str(err))})") from None
        self._probe = None
        self._last: dict = {}
        try:
            self.call({"op": "describe"})
        except CotwinError:
            self.close()
            raise
        self.actuators = self.view.actuators

    @property
    def time(self) -> float:
        return self.view.time if self.view.time is not None else 0.0

    def _on_reply(self, channel, method, props, body) -> None:
        if self._pending is not None and props.correlation_id == self._pending and self._reply is None:
            self._reply = (props, body)
        else:
            self.stray += 1

    def _on_return(self, channel, method, props, body) -> None:
        if props.correlation_id == self._pending:
            self._returned = True

    def _server_gone(self) -> bool:
        """Whether the robot's queue has disappeared (its server died): a passive declare on its own channel."""
        try:
            if self._probe is None or not self._probe.is_open:
                self._probe = self.connection.channel()
            self._probe.queue_declare(self.queue, passive=True)
            return False
        except pika.exceptions.ChannelClosedByBroker as err:
            self._probe = None
            return err.reply_code == 404

    def _where(self) -> str:
        return f"the robot on queue '{self.queue}' at {redact(self.url)}"

    def call(self, request: dict) -> dict:
        """Send one request and return its checked reply; CotwinError on any failure, naming it."""
        op = request.get("op")
        try:
            body = json.dumps(request, allow_nan=False).encode()
        except (TypeError, ValueError) as err:
            raise CotwinError(f"request {op}: {err}") from None
        cid = uuid.uuid4().hex
        self._pending, self._reply, self._returned = cid, None, False
        try:
            self.channel.basic_publish(
                "", self.queue, body,
                pika.BasicProperties(reply_to=self.reply_queue, correlation_id=cid, content_type="application/json",
                                     headers=request_headers(self.secret, self.queue, cid, self.reply_queue, body)),
                mandatory=True)
            start = wallclock.monotonic()
            next_probe = start + 1.0
            while self._reply is None:
                self.connection.process_data_events(time_limit=0.05)
                now = wallclock.monotonic()
                if self._returned:
                    raise CotwinError(f"no robot server is serving queue '{self.queue}' at {redact(self.url)} "
                                      f"(the broker returned the {op} request)")
                if self._reply is None and now >= next_probe:
                    next_probe = now + 1.0
                    if self._server_gone():
                        raise CotwinError(f"{self._where()} went away while answering {op} (its queue is gone)")
                if self._reply is None and now - start > self.timeout:
                    raise CotwinError(f"{self._where()} did not answer {op} within {self.timeout:g} s")
        except _LINK_ERRORS as err:
            reason = type(err).__name__ + (f": {err}" if str(err) else "")
            raise CotwinError(f"the link to {self._where()} was lost during {op} ({scrub(reason)})") from None
        finally:
            self._pending = None
        props, reply_body = self._reply
        if not check_reply(self.secret, self.queue, cid, getattr(props, "headers", None), reply_body):
            raise CotwinError(f"a reply to {op} on queue '{self.queue}' failed authentication: another process is "
                              "answering on the robot's queue, or the robot server has another COTWIN_ROBOT_SECRET")
        try:
            reply = decode(reply_body, MAX_REPLY, f"reply to {op}")
            dt = float(request.get("dt", 0.0)) if op == "advance" else 0.0
            validate_reply(op, reply, self.view, dt)
        except CotwinError as err:
            text = "; ".join(f.message for f in err.findings)
            if text.startswith("the robot refused"):
                raise
            raise CotwinError(f"{self._where()} sent an invalid {text}") from None
        if op != "describe":
            self._last = reply
        return reply

    # ---- the endpoint interface ----
    def start(self) -> None:
        self.call({"op": "state"})

    def stop(self) -> None:
        """The twin is done with the robot: close its link (the robot server goes on serving; it is
        stopped where it runs, never from the wire)."""
        self.close()

    def actuator_names(self) -> list[str]:
        return sorted(self.view.actuators)

    def joint(self, name: str) -> str:
        if name not in self.view.actuators:
            raise CotwinError(f"{self._where()} has no actuator '{name}'")
        return name

    def command(self, goals: dict[str, float]) -> None:
        self.call({"op": "command", "goals": goals})

    def advance(self, dt: float) -> None:
        self.call({"op": "advance", "dt": dt})

    def _values(self, key: str) -> dict[str, float]:
        return dict(self._last.get(key, {}))

    def read_sensors(self) -> dict[str, float]:
        return self._values("sensors")

    def joint_positions(self) -> dict[str, float]:
        return self._values("joints")

    def joint_velocities(self) -> dict[str, float]:
        return self._values("velocities")

    def close(self) -> None:
        _close(getattr(self, "connection", None))
