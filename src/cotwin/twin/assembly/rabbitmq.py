"""Live commands from RabbitMQ, wire-compatible with the INTO-CPS RabbitMQ FMU ("RMQ FMU").

Three parts, each with one job:
- `parse_message`: one message in, typed values out, or the reason it is refused;
- `CommandStream`: the RMQ FMU's time semantics over received messages: t0 is the newest timestamp
  held when every output first has a value; a message's simulation time is its time minus t0; a step
  to t+h applies, per variable in time order, the values with simulation time <= t+h that are strictly
  newer than the held one (later or equal times are dropped); it then needs every value to be at most
  `maxage` old, waiting up to `timeout_s` for fresh data, and never extrapolates;
- `RabbitMQBridge`: the AMQP link on its own thread (a direct exchange, non-durable, not auto-delete;
  a named queue bound to `to_cosim` that outlives a dropped connection, so commands published while the
  bridge reconnects are delivered afterwards; the ready message once bound; echoes on `from_cosim`).

`RabbitMQUnit` is the co-simulation unit over them (`rabbitmq.fmu` packages the same unit for Maestro).

Differences from the RMQ FMU, on purpose: every dropped or refused message is counted and logged with
its reason (logger `cotwin.rabbitmq`, at most 20 lines per 10 s, then "N more dropped messages not
logged"; the newest MAX_REFUSED reasons are kept in `CommandStream.refused`, all are counted in
`refused_count`); at most MAX_QUEUED values per variable wait for their time (a flood of messages
stamped in the future is refused, not held without bound); a message whose time is more than
`max_skew_s` from its arrival is refused (a skewed clock); a missing value ends the run with an error
naming the variable, the time and the age of what it had; and a message whose d-model input *event*
is `true` is a command (cotwin.twin.assembly.commands) with the arguments of that same message (one lacking
an argument is refused), applied one per step in the order of the messages' times, true in that one
step and not held until a `false` arrives, so each published command is delivered exactly once, with
its own arguments; the senders are told on `from_cosim` when a command is queued, applied (at which
step) or refused (docs/interop.md).
"""

from __future__ import annotations

import heapq
import json
import logging
import queue
import re
import threading
import time as wallclock
import uuid
from typing import Callable
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone

import pika

from ... import safejson
from ...cosim.units import INT32, Port, PythonUnit
from ...config import is_number
from ...diagnostics import CotwinError
from ...logcap import CappedLog
from ...mapping.amqp import connect, declare_exchange, redact
from ...service import BackgroundService
from .commands import CommandQueue, Occurrence, QueueFull
from ..project import RabbitMQSettings

log = logging.getLogger("cotwin.rabbitmq")

READY = {"internal_status": "ready", "internal_message": "waiting for input data for simulation"}
ANNOUNCE_SECONDS = 1.0  # the ready message is said again this often while the twin waits for its first values
_ISO = re.compile(r"^(\d{4})-(\d{2})-(\d{2})[T ](\d{2}):(\d{2}):(\d{2})(?:[.,](\d{1,9}))?(Z|z|[+-]\d{2}:?\d{2})$")
MAX_BYTES = 1 << 16  # a command message is a flat object of a few keys
MAX_REFUSED = 1000  # reasons of refused messages kept (all are counted)
MAX_QUEUED = 10_000  # values of one variable waiting for their simulation time
MAX_INBOX = 100_000  # messages received and not yet taken by the twin (it takes them every step)
MAX_APPLIED = 10_000  # values applied, remembered (a publisher refreshing every value for days would grow a list)
COMMANDS = "the twin's commands ([scenario] rabbitmq exchange, or --rabbitmq)"  # where an exchange's name comes from, for the errors
EVENTS = "the twin's alarms and what-ifs ([deviation] exchange)"
ECHO_SLACK = 2.0  # s beyond a twin's furthest time an echo may claim (delivery, the step it announces)
MAX_COMMANDS = 1000  # commands due and waiting for their step (one is applied per step); more are refused


def parse_time(text: str) -> datetime:
    """An ISO 8601 time with 0-9 fraction digits and a zone (Z or +hh:mm); ValueError otherwise."""
    m = _ISO.match(text) if isinstance(text, str) else None
    if m is None:
        raise ValueError(f"'time' {text!r} is not an ISO 8601 time with a zone (e.g. 2025-01-31T16:01:03.066+01:00)")
    year, month, day, hour, minute, second = (int(m.group(k)) for k in range(1, 7))
    fraction = m.group(7) or ""
    micro = int((fraction + "000000")[:6]) if fraction else 0
    zone = m.group(8)
    if zone in ("Z", "z"):
        tz = timezone.utc
    else:
        sign = 1 if zone[0] == "+" else -1
        digits = zone[1:].replace(":", "")
        hours, minutes = int(digits[:2]), int(digits[2:])
        if hours > 23 or minutes > 59:
            raise ValueError(f"'time' {text!r}: the zone {zone} is not an offset within +-23:59")
        tz = timezone(sign * timedelta(hours=hours, minutes=minutes))
    try:
        return datetime(year, month, day, hour, minute, second, micro, tzinfo=tz)
    except ValueError as err:
        raise ValueError(f"'time' {text!r}: {err}") from None


def port_types(program, ports: list[str]) -> dict[str, str]:
    """FMI types of a d-model's input ports, for the named ones."""
    from .scenario import scenario_ports

    types = scenario_ports(program)
    return {p: types[p] for p in ports}


def port_scalars(program) -> dict:
    """The d-model's input value ports with their Scalar (RoboSim type): what a message may hold
    beyond the FMI type (an enumeration's literals, a nat's sign)."""
    return {port: sc for ev in program.inputs for port, sc in ev.value_ports}


def port_arguments(program) -> dict[str, list[str]]:
    """The d-model's input events -> their value ports: the arguments a command message must carry."""
    return {ev.name: [port for port, _ in ev.value_ports] for ev in program.inputs}


@dataclass(frozen=True)
class Parsed:
    time: datetime
    values: dict[str, object]
    dropped: tuple[str, ...]  # reasons for values of this message that were not taken
    ident: str | None = None  # `internal_id`: the sender's name for its command, given back in acknowledgements


def parse_message(body: bytes, types: dict[str, str], scalars: dict | None = None) -> Parsed:
    """A message's time and typed values, or ValueError saying why the whole message is refused.
    Booleans take a JSON bool, Integers an int or a double (truncated, within int32), Reals a finite
    number; where `scalars` gives a port's RoboSim type, an enumeration also takes one of its literals
    by name and refuses an index beyond them, a nat refuses a negative value; a wrongly typed value is
    dropped (and said so) while the others are kept; unknown keys and keys starting with `internal_` or
    `simAtTime` are ignored."""
    data = safejson.loads_object(body, MAX_BYTES)  # the one policy of every message path
    if "time" not in data:
        raise ValueError("no 'time'")
    stamp = parse_time(data["time"])
    values: dict[str, object] = {}
    dropped: list[str] = []
    ident = data.get("internal_id")
    ident = ident if isinstance(ident, str) and 0 < len(ident) <= 64 else None
    for key, value in data.items():
        if key == "time" or key.startswith(("internal_", "simAtTime")):
            continue
        kind = types.get(key)
        if kind is None:
            dropped.append(f"unknown key {key[:80]!r} ignored")
            continue
        try:
            values[key] = _typed(value, kind, (scalars or {}).get(key))
        except ValueError as err:
            dropped.append(f"{key[:80]}: {err}")
    if not values:
        raise ValueError("no known variable (" + ("; ".join(dropped) if dropped else "only 'time'") + ")")
    return Parsed(stamp, values, tuple(dropped), ident)


def _typed(value, kind: str, sc=None):
    """A message's value as its port's FMI type (as the RMQ FMU types it), within the port's RoboSim type."""
    if sc is None:
        return _fmi_typed(value, kind)
    from .scenario import scalar_value

    try:
        return scalar_value(value, sc, _fmi_typed)
    except ValueError as err:
        said = str(err)
        raise ValueError(said if said.startswith(repr(value)[:40]) else f"{value!r:.40} {said}") from None


def _fmi_typed(value, kind: str):
    if kind == "Boolean":
        if isinstance(value, bool):
            return value
        raise ValueError(f"{value!r:.40} is not a JSON Boolean")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{value!r:.40} is not a number")
    if not is_number(value):  # also an integer too large for any float
        raise ValueError(f"{value!r:.40} is not finite")
    if kind == "Integer":
        value = int(value)  # a double is truncated, as the RMQ FMU does
        if not INT32[0] <= value <= INT32[1]:
            raise ValueError(f"{value} does not fit an FMI Integer (int32)")
        return value
    return float(value)


@dataclass
class Received:
    body: bytes
    wall: float  # time.time() at receipt


@dataclass
class _Held:
    sim: float  # simulation time of the held value
    value: object


VALUE_DROPPED = "value dropped (the rest of its message taken)"  # a refusal of one value, not of its message


@dataclass
class CommandStream:
    """The RMQ FMU's time semantics (see module doc) over messages taken from `receive(timeout)`."""

    types: dict[str, str]
    events: set[str]
    receive: object  # callable(timeout_s) -> list[Received]; raises CotwinError when the link is lost
    maxage: float = 1.0  # s
    timeout: float = 60.0  # s
    cancelled: object = None  # callable() -> bool: a run asked to stop; waiting for messages ends at once
    max_skew: float | None = None  # s: a message whose time is further than this from its arrival is refused
    t0: datetime | None = None
    refused: deque = field(default_factory=lambda: deque(maxlen=MAX_REFUSED))  # (wall time, reason), the newest
    refused_count: int = 0  # every refusal, kept or not
    scalars: dict | None = None  # port -> Scalar (RoboSim type), see parse_message
    applied: deque = field(default_factory=lambda: deque(maxlen=MAX_APPLIED))  # (sim, var, value, step end), the newest
    arguments: dict[str, list[str]] | None = None  # event -> its value ports (None: no event carries any)
    origin: str = "to_cosim"  # where its messages come from, as an error says it (exchange and routing key)
    announce: object = None  # callable() -> None: say again that the twin is ready (while waiting for the first values)

    def __post_init__(self) -> None:
        self.pending: list[tuple[datetime, dict[str, object], bytes]] = []  # before t0 is known
        self.queues: dict[str, list[tuple[float, object, bool]]] = {v: [] for v in self.types}  # (sim, value, quiet)
        self.held: dict[str, _Held] = {}
        self._last: tuple[float, dict[str, object]] | None = None
        self.latest_wall: float | None = None
        self.log = CappedLog(log, "dropped messages")
        self.arguments = {e: list((self.arguments or {}).get(e, [])) for e in self.events}
        self.bound = {port for ports in self.arguments.values() for port in ports}  # carried by their event
        self.due: list[tuple[float, int, Occurrence]] = []  # commands not yet due (a heap)
        self.commands = CommandQueue(MAX_COMMANDS)  # due, applied one per step
        self.carried: dict[str, object] = {}  # the value ports of the last command applied
        self.acks: deque[dict] = deque(maxlen=MAX_REFUSED)  # what to tell the senders (CommandStream.take_acks)
        self._sequence = 0

    def _refuse(self, reason: str, body: bytes = b"", what: str = "message dropped") -> None:
        """Count and log a refusal: of the whole message, or (`what`) of one of its values, the rest taken."""
        excerpt = body[:80].decode("utf-8", "replace") if body else ""
        self.refused.append((wallclock.time(), reason))
        self.refused_count += 1
        self.log.warning("%s: %s%s", what, reason, f" [{excerpt!r}]" if excerpt else "")

    def _take(self, messages: list[Received]) -> None:
        for m in messages:
            try:
                parsed = parse_message(m.body, self.types, self.scalars)
            except ValueError as err:
                self._refuse(str(err), m.body)
                continue
            skew = parsed.time.timestamp() - m.wall
            if self.max_skew is not None and abs(skew) > self.max_skew:
                self._refuse(f"its 'time' {parsed.time.isoformat()} is {skew:+.1f} s from when it arrived (at most "
                             f"max_skew_s = {self.max_skew:g} s: is the publisher's clock set?)", m.body)
                continue
            for reason in parsed.dropped:
                self._refuse(reason, m.body, VALUE_DROPPED)
            self.latest_wall = m.wall
            if self.t0 is None:
                self.pending.append((parsed.time, parsed.values, m.body))
            else:
                self._queue(parsed.time, parsed.values, parsed.ident)

    def _queue(self, stamp: datetime, values: dict[str, object], ident: str | None = None) -> None:
        """A message's commands (its events with their own arguments) and its values, each to wait for
        its simulation time."""
        sim = (stamp - self.t0).total_seconds()
        quiet = set()  # values taken as a command's: an equal time is no reason to complain
        for event in (e for e in self.events if values.get(e) is True):
            ports = self.arguments[event]
            missing = [p for p in ports if p not in values]
            if missing:
                self._refuse_command(f"{event} at t = {sim:.3f} s without {', '.join(missing)}: a command takes its "
                                     "arguments from its own message", ident, event, stamp)
                continue
            self._sequence += 1
            heapq.heappush(self.due, (sim, self._sequence, Occurrence(
                event, tuple((p, values[p]) for p in ports), stamp.isoformat(), sim, ident)))
            quiet.update([event, *ports])
        for var, value in values.items():
            if len(self.queues[var]) >= MAX_QUEUED:
                self._refuse(f"{var} at t = {sim:.3f} s: {MAX_QUEUED} values of it already wait for their time")
                continue
            self.queues[var].append((sim, value, var in quiet or var in self.events))

    def _refuse_command(self, reason: str, ident: str | None, event: str, stamp: datetime) -> None:
        self._refuse(f"command {reason}")
        self.acks.append({"internal_status": "command refused", "internal_message": reason, "event": event,
                          "message_time": stamp.isoformat(), **({"internal_id": ident} if ident else {})})

    def take_acks(self) -> list[dict]:
        """What happened to the commands since the last call (queued, applied, refused), for their senders."""
        out = list(self.acks)
        self.acks.clear()
        return out

    def start(self) -> None:
        """Wait (up to the timeout) until every variable has a value; t0 := the newest time then held."""
        deadline = wallclock.monotonic() + self.timeout
        latest: dict[str, tuple[datetime, object]] = {}
        announced = wallclock.monotonic()
        while True:
            for stamp, values, _ in self.pending:
                for var, value in values.items():
                    if var not in latest or stamp > latest[var][0]:
                        latest[var] = (stamp, value)
            self.pending.clear()
            missing = [v for v in self.types if v not in latest]
            if not missing:
                break
            left = deadline - wallclock.monotonic()
            if left <= 0:
                raise CotwinError(f"no value for {', '.join(missing)} within {self.timeout:g} s of waiting for the "
                                  f"first complete set of commands (is a publisher sending on {self.origin}?)")
            self._wait(min(left, 0.5), f"for the first value of {', '.join(missing)}")
            if self.announce is not None and wallclock.monotonic() - announced >= ANNOUNCE_SECONDS:
                self.announce()  # a publisher started after the first ready message hears it now
                announced = wallclock.monotonic()
        self.t0 = max(stamp for stamp, _ in latest.values())
        for var, (stamp, value) in latest.items():
            self.held[var] = _Held((stamp - self.t0).total_seconds(), value)
        self.carried = {port: self.held[port].value for port in self.bound}

    def values_for(self, t: float, h: float) -> dict[str, object]:
        """The variables' values for the step from t to t + h (computed once per step: units sharing
        the stream in lockstep get the same values)."""
        if self._last is not None and self._last[0] == t:
            return self._last[1]
        if self.t0 is None:
            self.start()
        until = t + h
        self._take(self.receive(0.0))
        fired = self._apply(until, t + h)
        deadline = wallclock.monotonic() + self.timeout
        while True:
            stale = [(v, held) for v, held in self.held.items() if until - held.sim > self.maxage + 1e-9]
            if not stale:
                break
            left = deadline - wallclock.monotonic()
            if left <= 0:
                v, held = stale[0]
                raise CotwinError(f"RabbitMQ: no fresh value of '{v}' for the step to t = {until:g} s: the newest "
                                  f"is from t = {held.sim:g} s, {until - held.sim:.3f} s old (maxage "
                                  f"{self.maxage:g} s), and none came within {self.timeout:g} s")
            self._wait(min(left, 0.2), f"for a fresh value of '{stale[0][0]}'")
            fired |= self._apply(until, t + h)
        # one command per step, with its own arguments (even if a `false` and other values followed within the step)
        command = self.commands.take(t + h)
        if command is not None:
            self.carried.update(command.values)
            self.acks.append({"internal_status": "command applied", "event": command.event, "applied_at": t + h,
                              "message_time": command.origin, **({"internal_id": command.ident} if command.ident else {})})
        out = {v: (command is not None and command.event == v) if v in self.events else
               self.carried[v] if v in self.bound else held.value for v, held in self.held.items()}
        self._last = (t, out)
        return out

    def finish(self) -> None:
        """At the end of a run: say how many refusals were counted but not logged."""
        self.log.close()

    def _wait(self, seconds: float, what: str) -> None:
        """Take what arrives within `seconds`; a run asked to stop ends here, as Ctrl-C would."""
        if self.cancelled is not None and self.cancelled():
            raise KeyboardInterrupt(f"stopped while waiting {what}")
        self._take(self.receive(seconds))

    def _apply(self, until: float, step_end: float) -> set[str]:
        """Apply queued values with simulation time <= until and accept the commands due by then into the
        queue of those applied one per step (refused when it is full); return the events accepted."""
        for var, items in self.queues.items():
            if not items:
                continue
            items.sort(key=lambda x: x[0])
            keep = []
            for sim, value, quiet in items:
                if sim > until + 1e-9:
                    keep.append((sim, value, quiet))
                    continue
                held = self.held.get(var)
                if held is not None and sim <= held.sim:
                    if not quiet:
                        self._refuse(f"{var} at t = {sim:.3f} s is not newer than the value held (t = {held.sim:.3f} s)",
                                     what=VALUE_DROPPED)
                    continue
                self.held[var] = _Held(sim, value)
                self.applied.append((sim, var, value, step_end))
            self.queues[var] = keep
        accepted = set()
        while self.due and self.due[0][0] <= until + 1e-9:
            _, _, command = heapq.heappop(self.due)
            try:
                place = self.commands.offer(command)
            except QueueFull as full:
                self._refuse_command(f"{command.event} at t = {command.due:.3f} s: {full}", command.ident,
                                     command.event, parse_time(command.origin))
                continue
            accepted.add(command.event)
            if place > 0:
                self.acks.append({"internal_status": "command queued", "event": command.event, "place": place,
                                  "message_time": command.origin,
                                  **({"internal_id": command.ident} if command.ident else {})})
        return accepted


class RabbitMQBridge(BackgroundService):
    """The AMQP link of a live twin, on its own thread (see module doc; cotwin.service.BackgroundService).
    `receive` hands the messages received so far to the co-simulation thread, and the link's failure when
    it was lost for good; `publish` is thread-safe."""

    def __init__(self, settings: RabbitMQSettings, name: str = "cotwin bridge", expires_s: float = 600.0):
        BackgroundService.__init__(self, name)
        self.settings = settings
        self.queue_name = f"cotwin.{settings.exchange}.{uuid.uuid4().hex[:12]}"
        self.expires_ms = int(expires_s * 1000)
        self.inbox: queue.Queue[Received] = queue.Queue(MAX_INBOX)
        self.overflowed = 0  # messages dropped because the twin had not taken MAX_INBOX others yet
        self.log = CappedLog(log, "messages dropped on arrival")
        self.outbox: deque[tuple[str, bytes]] = deque()
        self.connected = threading.Event()
        self.reconnects = 0
        self._connection = None
        self._channel = None

    # ---- the link thread ----
    def _open(self) -> None:
        s = self.settings
        self._connection = connect(s.url, f"{self.name} on {s.exchange}")  # named per exchange: RabbitMQ shows which twin it is
        channel = self._connection.channel()
        declare_exchange(channel, s.exchange, "direct", s.url, COMMANDS)
        channel.queue_declare(self.queue_name, durable=False, auto_delete=False,
                              arguments={"x-expires": self.expires_ms})
        channel.queue_bind(self.queue_name, s.exchange, routing_key=s.to_cosim)
        channel.basic_consume(self.queue_name, self._on_message, auto_ack=True)
        self._channel = channel

    def _on_message(self, channel, method, props, body) -> None:
        try:
            self.inbox.put_nowait(Received(body, wallclock.time()))
        except queue.Full:  # a flood faster than the twin steps: memory stays bounded, the drop is counted
            self.overflowed += 1
            self.log.warning("message dropped on arrival: %d wait for the twin already", MAX_INBOX)

    def _flush(self) -> None:
        while self.outbox:
            key, body = self.outbox[0]
            self._channel.basic_publish(self.settings.exchange, key, body)
            self.outbox.popleft()

    @property
    def error(self) -> CotwinError | None:
        """Why the link ended (lost and not restored in time), if it did."""
        return self.error_of(self.failure) if self.failure is not None else None

    def serve(self) -> None:
        """The link: messages in, the outbox out, reconnecting when lost (CotwinError when it stays lost)."""
        self.ready()  # connected by start(), in the caller's thread
        lost_at: float | None = None
        while not self.stopping.is_set():
            try:
                if self._connection is None or not self._connection.is_open:
                    self._open()
                    if lost_at is not None:
                        self.reconnects += 1
                        log.warning("reconnected to %s after %.1f s", redact(self.settings.url),
                                    wallclock.monotonic() - lost_at)
                    lost_at = None
                    self.connected.set()
                self._flush()
                self._connection.process_data_events(time_limit=0.02)
            except (pika.exceptions.AMQPError, CotwinError, OSError) as err:
                self.connected.clear()
                self._connection = None
                now = wallclock.monotonic()
                if lost_at is None:
                    lost_at = now
                    log.warning("lost the broker connection (%s); reconnecting", type(err).__name__)
                if now - lost_at > self.settings.timeout_s:
                    raise CotwinError(f"RabbitMQ: the link to {redact(self.settings.url)} was lost and not "
                                      f"restored within {self.settings.timeout_s:g} s ({type(err).__name__})") from None
                self.stopping.wait(0.2)
        try:
            if self._connection is not None and self._connection.is_open:
                self._flush()
                self._connection.close()
        except Exception:  # noqa: BLE001 - closing a dead link
            pass

    # ---- the co-simulation side ----
    def start(self, timeout: float | None = 30.0) -> "RabbitMQBridge":
        """Connect, bind and announce readiness (once); CotwinError if the broker cannot be reached."""
        if self.started:
            return self
        self._open()  # in the caller's thread first, so a wrong URL is reported at once
        self.connected.set()
        BackgroundService.start(self, timeout)
        self.publish(self.settings.from_cosim, READY)
        return self

    def publish(self, routing_key: str, message: dict) -> None:
        self.outbox.append((routing_key, json.dumps(message, sort_keys=True).encode()))

    def receive(self, timeout: float) -> list[Received]:
        self.check()
        out = []
        try:
            out.append(self.inbox.get(timeout=timeout) if timeout > 0 else self.inbox.get_nowait())
            while True:
                out.append(self.inbox.get_nowait())
        except queue.Empty:
            pass
        return out

    def close(self) -> None:
        if self.started:
            self.stop(5)
        elif self._connection is not None:
            try:
                self._connection.close()
            except Exception:  # noqa: BLE001
                pass
        self.log.close()


def announcer(bridge: "RabbitMQBridge", settings) -> Callable[[], None]:
    """Say the ready message again on `from_cosim` (a publisher ignores it once it has heard one)."""
    return lambda: bridge.publish(settings.from_cosim, READY)


def origin(settings) -> str:
    """Where a twin's commands come from, as its errors name it: the exchange and the routing key."""
    return f"exchange {settings.exchange!r}, routing key {settings.to_cosim!r}"


def echo_message(inputs: dict[str, object], t: float, h: float) -> dict:
    """What the RMQ FMU publishes at the start of a step: its inputs, the wall-clock time and
    `simstep` (t + h in ms, as a string); Booleans as 1/0 (keys sorted when sent)."""
    out = {k: (int(v) if isinstance(v, bool) else v) for k, v in inputs.items()}
    out["time"] = datetime.now(timezone.utc).isoformat(timespec="milliseconds")
    out["simstep"] = f"{(t + h) * 1000:.6f}"
    return out


_SIMSTEP = re.compile(r"^[0-9]{1,15}(\.[0-9]{1,9})?$")  # ms, as echo_message writes it (up to ~30 000 years)


def parse_echo(body: bytes) -> tuple[bool, float | None]:
    """A message on `from_cosim`: whether it is the ready message, and the simulated time it announces
    (`simstep`, a decimal number of ms, in s; None where it has none); ValueError saying why it is no echo."""
    data = safejson.loads_object(body, MAX_BYTES)
    ready = data.get("internal_status") == READY["internal_status"] and \
        READY["internal_message"] in str(data.get("internal_message", ""))[:200]
    if "simstep" not in data:
        return ready, None
    simstep = data["simstep"]
    text = simstep if isinstance(simstep, str) else repr(simstep) if is_number(simstep) else None
    if text is None or not _SIMSTEP.match(text):
        raise ValueError(f"'simstep' {str(simstep)[:40]!r} is not a number of milliseconds (e.g. \"1500.000000\")")
    return ready, float(text) / 1000.0


def read_echo(body: bytes) -> tuple[bool, float | None]:
    """`parse_echo`, with (False, None) for a message that is no echo."""
    try:
        return parse_echo(body)
    except ValueError:
        return False, None


class EchoClock:
    """What a publisher believes of the twin's simulated time, from the messages on `from_cosim`.

    Anyone who may publish on the twin's exchange can write there, so an echo is taken only where a twin
    could have sent it: a time is heard only after the ready message, never goes back, and is never
    further than the twin can be. A twin's clock starts (t0) at a command stamped after it bound its
    queue, that is before it said it was ready, and it never runs more than `maxage` past the newest
    command, so its time is at most the wall time since the ready message plus `maxage` (and a step, and
    ECHO_SLACK for delivery). Refused echoes are counted and logged (capped)."""

    def __init__(self, maxage: float, name: str = "publisher"):
        self.maxage = maxage
        self.ready_at: float | None = None  # time.monotonic() of the first ready message
        self.sim: float | None = None  # the newest simulated time taken (s)
        self.heard: float | None = None  # time.monotonic() when it was taken
        self.refused = 0
        self.log = CappedLog(log, f"echoes refused by the {name}")

    def take(self, body: bytes, now: float | None = None) -> None:
        now = wallclock.monotonic() if now is None else now
        try:
            ready, sim = parse_echo(body)
        except ValueError as err:
            return self._refuse(str(err), body)
        if ready and self.ready_at is None:
            self.ready_at = now
        if sim is None:
            return None
        if self.ready_at is None:
            return self._refuse(f"an echo of t = {sim:g} s before the twin said it was ready", body)
        if self.sim is not None and sim < self.sim:
            return self._refuse(f"an echo of t = {sim:g} s after one of t = {self.sim:g} s (time goes forward)", body)
        furthest = now - self.ready_at + self.maxage + ECHO_SLACK
        if sim > furthest:
            return self._refuse(f"an echo of t = {sim:g} s only {now - self.ready_at:.1f} s after the twin said it was "
                                f"ready: no twin can be past t = {furthest:.1f} s yet", body)
        self.sim, self.heard = sim, now
        return None

    def _refuse(self, reason: str, body: bytes) -> None:
        self.refused += 1
        self.log.warning("echo refused: %s [%r]", reason, bytes(body[:80]).decode("utf-8", "replace"))

    def close(self) -> None:
        self.log.close()


class RabbitMQUnit(PythonUnit):
    """The command source of a live twin: outputs the commands as the RMQ FMU does (see module doc),
    inputs are echoed on `from_cosim` every step (the monitored joints, as in the paper)."""

    def __init__(self, name: str, types: dict[str, str], echoed: list[str], settings: RabbitMQSettings,
                 bridge: RabbitMQBridge | None = None, stream: CommandStream | None = None,
                 events: set[str] | None = None, echo: bool = True, scalars: dict | None = None,
                 arguments: dict[str, list[str]] | None = None):
        ports = [Port(p, kind, "output") for p, kind in types.items()]
        ports += [Port(v, "Real", "input") for v in echoed]
        super().__init__(name, ports)
        self.types = types
        self.echoed = list(echoed)
        self.settings = settings
        self.events = set(events) if events is not None else {p for p, k in types.items() if k == "Boolean"}
        self.bridge = bridge
        self.stream = stream
        self.scalars = scalars
        self.arguments = arguments
        self.echo = echo
        self.reconnects = 0
        self._own_bridge = bridge is None

    @property
    def command_queue(self):
        """The commands applied one per step (cotwin.twin.assembly.commands.CommandQueue), once the stream exists."""
        return self.stream.commands if self.stream is not None else None

    @property
    def epoch(self) -> float | None:
        """Wall-clock time of simulation time 0: the publisher's t0 (for real-time pacing)."""
        return self.stream.t0.timestamp() if self.stream is not None and self.stream.t0 is not None else None

    def initialize(self) -> None:
        """Bind and announce readiness in initialisation mode, as the RMQ FMU does, then wait for the
        first complete set of values."""
        if self.bridge is None:
            self.bridge = RabbitMQBridge(self.settings, f"cotwin {self.name}")
        self.bridge.start()
        if self.stream is None:
            self.stream = CommandStream(self.types, self.events, self.bridge.receive, self.settings.maxage_ms / 1000,
                                        self.settings.timeout_s, scalars=self.scalars,
                                        max_skew=self.settings.max_skew_s, arguments=self.arguments,
                                        origin=origin(self.settings), announce=announcer(self.bridge, self.settings))
        if self.stream.t0 is None:
            self.stream.start()
        self.values.update({v: held.value if v not in self.events else False for v, held in self.stream.held.items()})

    def step(self, t: float, h: float) -> None:
        if self.echo:
            self.bridge.publish(self.settings.from_cosim, echo_message({v: self.values[v] for v in self.echoed}, t, h))
        self.values.update(self.stream.values_for(t, h))
        if self.echo:  # the senders hear what became of their commands (the side that echoes tells them)
            for ack in self.stream.take_acks():
                self.bridge.publish(self.settings.from_cosim, {**ack, "time": datetime.now(timezone.utc).isoformat(
                    timespec="milliseconds")})

    def terminate(self) -> None:
        if self.stream is not None:
            self.stream.finish()
        if self.bridge is not None:
            self.reconnects = self.bridge.reconnects
        if self._own_bridge and self.bridge is not None:
            self.bridge.close()
            self.bridge = None


class EventPublisher(BackgroundService):
    """Publishes the twin's events (deviation alarms) as JSON on a topic exchange, from its own thread:
    the twin never waits for the broker; events that cannot be delivered are logged and dropped (they
    are also in the history and in deviation.json)."""

    def __init__(self, url: str, exchange: str, name: str = "cotwin events"):
        BackgroundService.__init__(self, name)
        self.url, self.exchange = url, exchange
        self._queue: queue.Queue = queue.Queue(maxsize=10_000)
        self.sent = 0
        self.failed = 0
        self.start()

    def publish(self, routing_key: str, event: dict) -> None:
        try:
            self._queue.put_nowait((routing_key, json.dumps(event, sort_keys=True).encode()))
        except queue.Full:
            self.failed += 1

    def serve(self) -> None:
        self.ready()
        connection = channel = None
        while True:
            item = self._queue.get()
            if item is None:
                break
            try:
                if connection is None or not connection.is_open:
                    connection = connect(self.url, self.name)
                    channel = connection.channel()
                    declare_exchange(channel, self.exchange, "topic", self.url, EVENTS)
                channel.basic_publish(self.exchange, item[0], item[1])
                self.sent += 1
            except (pika.exceptions.AMQPError, CotwinError, OSError) as err:
                self.failed += 1
                connection = None
                log.warning("event not published on %s (%s)", self.exchange,
                            err.findings[0].message if isinstance(err, CotwinError) else type(err).__name__)
        if connection is not None and connection.is_open:
            try:
                connection.close()
            except Exception:  # noqa: BLE001
                pass

    def interrupt(self) -> None:
        self._queue.put(None)  # the events queued before are published first

    def close(self) -> None:
        self.stop(10)
