"""The page's command panel on the broker: a publisher that follows the RMQ FMU protocol as any external
publisher does (cotwin.twin.services.publisher): it binds its own queue to `from_cosim` on the twin's direct
exchange, waits for the twin's ready message, then every `period` of wall time publishes one message
on `to_cosim`: the idle values (events false, values zero), or in their place the command the page
asked for. The heartbeat is what lets a twin run from the page alone (the RMQ FMU needs every value
refreshed within `maxage`); with `heartbeat=False` it sends only the page's commands.

Commands are checked before they leave, so the page is told at once why a value is refused instead of
the twin dropping (or, for a double on an Integer, truncating) it: every value as a plan's would be
(`command_values`: every argument given, by its port name or its field name, 1.5 is not an integer, an
enumeration takes its literals, a nat is not negative, int32)
and then with the twin's own message parser. At most MAX_WAITING commands wait to leave (one leaves per
loop of the link thread); more are refused with QueueFull, which the server answers 429. Each command
carries an `internal_id` (ignored by RMQ-FMU readers); the twin says on `from_cosim` when it queued,
applied (at which step) or refused it, and `ticket(id)` tells what became of it.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time as wallclock
import uuid
from collections import deque
from dataclasses import dataclass

import pika

from .... import safejson
from ....diagnostics import CotwinError
from ....dmodel.program import Scalar
from ....mapping.amqp import connect, declare_exchange
from ....service import BackgroundService
from ...project import RabbitMQSettings
from ..publisher import idle_values, now_iso
from ...assembly.rabbitmq import COMMANDS, MAX_BYTES, EchoClock, parse_message
from ...assembly.scenario import command_values

log = logging.getLogger("cotwin.dashboard")


@dataclass(frozen=True)
class _CommandEvent:
    """A command event as the panel knows it: its name and value ports (as cotwin.dmodel.program.EventPort)."""

    name: str
    value_ports: list


class PagePublisher(BackgroundService):
    MAX_WAITING = 64  # commands queued and not yet published
    MAX_SENT = 1000  # messages remembered (a heartbeat every period for days would grow a list without bound)
    MAX_TICKETS = 1000  # commands whose fate is remembered

    def __init__(self, settings: RabbitMQSettings, types: dict[str, str], events: list[dict], period: float = 0.25,
                 heartbeat: bool = True, name: str = "cotwin dashboard", scalars: dict | None = None):
        self.settings = settings
        self.types = types  # every command port with its FMI type
        self.scalars = scalars or {}  # value port -> its d-model Scalar (RoboSim type), where known
        self.events = {e["name"]: _CommandEvent(e["name"], [(v["port"], self.scalars.get(v["port"]) or
                                                              Scalar(v["port"], types[v["port"]], (), None))
                                                             for v in e["values"]]) for e in events}
        self.idle = idle_values(types)
        self.period = period
        self.heartbeat = heartbeat
        BackgroundService.__init__(self, name)
        self.bound = threading.Event()  # our queue is bound: the twin may announce itself now
        self.twin_ready = threading.Event()  # the twin's ready message came
        self.sent: deque[tuple[float, dict]] = deque(maxlen=self.MAX_SENT)  # (wall time, message), the newest
        self.sent_count = 0
        self.error: str | None = None
        self.echoes = EchoClock(settings.maxage_ms / 1000 if settings else 1.0, "dashboard")  # what the echoes say
        self._pending: queue.Queue[dict] = queue.Queue(self.MAX_WAITING)
        self._lock = threading.Lock()
        self.tickets: dict[str, dict] = {}  # command id -> what became of it (`ticket`), the newest MAX_TICKETS
        self._started = False

    # ---- the page's side ----
    def command(self, event: str, values: dict) -> dict:
        """Queue the command `event` with its value ports; returns the message, ValueError saying why it
        would be refused (naming the input), queue.Full if too many wait to leave, or CotwinError if the
        link thread has stopped (nothing would leave)."""
        if event not in self.events:
            raise ValueError(f"{event[:80]!r} is not a command of this twin (commands: {', '.join(self.events) or 'none'})")
        typed, wrong = command_values(self.events[event], values)
        if wrong:
            raise ValueError("; ".join(message for _, message in wrong[:10]))
        ident = uuid.uuid4().hex[:16]
        message = {"time": now_iso(), **self.idle, **dict(typed), "internal_id": ident}
        parsed = parse_message(json.dumps(message).encode(), self.types, self.scalars)  # the twin's own check
        if parsed.dropped:
            raise ValueError("; ".join(parsed.dropped))
        if self.stopped:
            raise CotwinError(f"the page's command publisher has stopped ({self.error or 'its link ended'}): "
                              "commands cannot reach the twin")
        with self._lock:
            self._pending.put_nowait(message)
            self.tickets[ident] = {"id": ident, "status": "waiting to be published", "message": message}
            while len(self.tickets) > self.MAX_TICKETS:
                self.tickets.pop(next(iter(self.tickets)))
        return message

    def ticket(self, ident: str) -> dict | None:
        """What became of the command `ident` (`command` put it in its message's `internal_id`): its status
        (waiting to be published, published, queued by the twin, applied, refused) and the twin's word."""
        with self._lock:
            found = self.tickets.get(ident)
            return dict(found) if found is not None else None

    def _acknowledged(self, data: dict) -> None:
        """The twin's word on a command of ours (cotwin.twin.assembly.rabbitmq: queued, applied, refused)."""
        status = str(data.get("internal_status", ""))
        if not status.startswith("command "):
            return
        with self._lock:
            found = self.tickets.get(data.get("internal_id"))
            if found is not None and found["status"] not in ("applied", "refused"):
                found["status"] = status[len("command "):]
                found.update({k: data[k] for k in ("applied_at", "place", "internal_message") if k in data})

    # ---- the link thread ----
    def start(self, timeout: float = 10.0) -> "PagePublisher":
        """Connect and bind on the link thread (cotwin.service.BackgroundService); CotwinError if it cannot."""
        self._started = True
        return BackgroundService.start(self, timeout)

    def _cannot(self, why: str) -> CotwinError:
        return CotwinError(f"dashboard: cannot publish commands on RabbitMQ exchange '{self.settings.exchange}': {why}")

    def late(self, timeout: float) -> CotwinError:
        return self._cannot(f"no broker answer within {timeout:g} s")

    @property
    def stopped(self) -> bool:
        """The link thread was started and has ended or failed: a queued command would never leave."""
        return self.error is not None or (self._started and not self.running)

    def stop(self, timeout: float | None = 5.0) -> bool:
        return BackgroundService.stop(self, timeout)

    def _on_echo(self, channel, method, props, body) -> None:
        self.echoes.take(body)  # never raises: a bad echo is refused and counted
        if self.echoes.ready_at is not None:
            self.twin_ready.set()
        if b'"command ' in body[:4096]:  # the twin's word on a command (queued, applied, refused)
            try:
                data = safejson.loads_object(body, MAX_BYTES)
            except ValueError:
                return
            self._acknowledged(data)

    def serve(self) -> None:
        s = self.settings
        try:
            connection = connect(s.url, self.name)
            channel = connection.channel()
            declare_exchange(channel, s.exchange, "direct", s.url, COMMANDS)
            own = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
            channel.queue_bind(own, s.exchange, routing_key=s.from_cosim)
            channel.basic_consume(own, self._on_echo, auto_ack=True)
        except (pika.exceptions.AMQPError, CotwinError, OSError) as err:
            self.error = str(err) or type(err).__name__
            raise self._cannot(self.error) from None
        self.bound.set()
        self.ready()
        try:
            next_tick = wallclock.monotonic()
            while not self.stopping.is_set():
                connection.process_data_events(time_limit=0.02)
                if not self.twin_ready.is_set():
                    continue
                message = None
                try:
                    message = self._pending.get_nowait()
                    message["time"] = now_iso()  # stamped when it leaves, as a publisher does
                except queue.Empty:
                    if self.heartbeat and wallclock.monotonic() >= next_tick:
                        message = {"time": now_iso(), **self.idle}
                if message is not None:
                    channel.basic_publish(s.exchange, s.to_cosim, json.dumps(message).encode())
                    with self._lock:
                        found = self.tickets.get(message.get("internal_id"))
                        if found is not None and found["status"] == "waiting to be published":
                            found["status"] = "published"
                    self.sent.append((wallclock.time(), message))
                    self.sent_count += 1
                    next_tick = wallclock.monotonic() + self.period
        except (pika.exceptions.AMQPError, OSError) as err:
            self.error = f"the broker link was lost ({type(err).__name__})"
            log.warning("dashboard publisher: %s", self.error)
        except Exception as err:  # noqa: BLE001 - a cotwin bug: the page must say so, not answer "queued"
            self.error = f"it failed ({type(err).__name__}: {str(err)[:200]})"
            log.exception("dashboard publisher failed")
        finally:
            try:
                connection.close()
            except Exception:  # noqa: BLE001 - closing a dead link
                pass
