"""The page's command panel on the broker: a publisher that follows the RMQ FMU protocol as any external
publisher does (cotwin.twin.publisher): it binds its own queue to `from_cosim` on the twin's direct
exchange, waits for the twin's ready message, then every `period` of wall time publishes one message
on `to_cosim`: the idle values (events false, values zero), or in their place the command the page
asked for. The heartbeat is what lets a twin run from the page alone (the RMQ FMU needs every value
refreshed within `maxage`); with `heartbeat=False` it sends only the page's commands.

Commands are checked before they leave, so the page is told at once why a value is refused instead of
the twin dropping (or, for a double on an Integer, truncating) it: every value as a plan's would be
(`scalar_value`: 1.5 is not an integer, an enumeration takes its literals, a nat is not negative, int32)
and then with the twin's own message parser. At most MAX_WAITING commands wait to leave (one leaves per
loop of the link thread); more are refused with QueueFull, which the server answers 429.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time as wallclock
from collections import deque

import pika

from ...diagnostics import CotwinError
from ...mapping.amqp import connect, declare_exchange
from ..project import RabbitMQSettings
from ..publisher import idle_values, now_iso
from ..rabbitmq import COMMANDS, EchoClock, parse_message
from ..scenario import scalar_value, typed_value

log = logging.getLogger("cotwin.dashboard")


class PagePublisher:
    MAX_WAITING = 64  # commands queued and not yet published
    MAX_SENT = 1000  # messages remembered (a heartbeat every period for days would grow a list without bound)

    def __init__(self, settings: RabbitMQSettings, types: dict[str, str], events: list[dict], period: float = 0.25,
                 heartbeat: bool = True, name: str = "cotwin dashboard", scalars: dict | None = None):
        self.settings = settings
        self.types = types  # every command port with its FMI type
        self.scalars = scalars or {}  # value port -> its d-model Scalar (RoboSim type), where known
        self.events = {e["name"]: [v["port"] for v in e["values"]] for e in events}
        self.idle = idle_values(types)
        self.period = period
        self.heartbeat = heartbeat
        self.name = name
        self.bound = threading.Event()  # our queue is bound: the twin may announce itself now
        self.twin_ready = threading.Event()  # the twin's ready message came
        self.sent: deque[tuple[float, dict]] = deque(maxlen=self.MAX_SENT)  # (wall time, message), the newest
        self.sent_count = 0
        self.error: str | None = None
        self.echoes = EchoClock(settings.maxage_ms / 1000 if settings else 1.0, "dashboard")  # what the echoes say
        self._pending: queue.Queue[dict] = queue.Queue(self.MAX_WAITING)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = False

    # ---- the page's side ----
    def command(self, event: str, values: dict) -> dict:
        """Queue the command `event` with its value ports; returns the message, ValueError saying why it
        would be refused (naming the input), queue.Full if too many wait to leave, or CotwinError if the
        link thread has stopped (nothing would leave)."""
        if event not in self.events:
            raise ValueError(f"{event[:80]!r} is not a command of this twin (commands: {', '.join(self.events) or 'none'})")
        ports = self.events[event]
        unknown = [k for k in values if k not in ports]
        missing = [p for p in ports if p not in values]
        if unknown or missing:
            raise ValueError("; ".join([*(f"{k[:80]!r} is not a value of {event}" for k in unknown[:10]),
                                        *(f"no value for '{p}'" for p in missing)]))
        typed, wrong = {}, []
        for port, value in values.items():
            try:
                typed[port] = scalar_value(value, self.scalars[port]) if port in self.scalars \
                    else typed_value(value, self.types[port])
            except ValueError as err:
                wrong.append(f"{port}: {value!r:.40} {err}")
        if wrong:
            raise ValueError("; ".join(wrong))
        message = {"time": now_iso(), **self.idle, event: True, **typed}
        parsed = parse_message(json.dumps(message).encode(), self.types, self.scalars)  # the twin's own check
        if parsed.dropped:
            raise ValueError("; ".join(parsed.dropped))
        if self.stopped:
            raise CotwinError(f"the page's command publisher has stopped ({self.error or 'its link ended'}): "
                              "commands cannot reach the twin")
        self._pending.put_nowait(message)
        return message

    # ---- the link thread ----
    def start(self, timeout: float = 10.0) -> "PagePublisher":
        self._started = True
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()
        if not self.bound.wait(timeout) or self.error:
            self.stop()
            raise CotwinError(f"dashboard: cannot publish commands on RabbitMQ exchange '{self.settings.exchange}': "
                              f"{self.error or 'no broker answer within %g s' % timeout}")
        return self

    @property
    def stopped(self) -> bool:
        """The link thread was started and has ended or failed: a queued command would never leave."""
        return self.error is not None or (self._started and (self._thread is None or not self._thread.is_alive()))

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None

    def _on_echo(self, channel, method, props, body) -> None:
        self.echoes.take(body)  # never raises: a bad echo is refused and counted
        if self.echoes.ready_at is not None:
            self.twin_ready.set()

    def _run(self) -> None:
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
            self.bound.set()
            return
        self.bound.set()
        try:
            next_tick = wallclock.monotonic()
            while not self._stop.is_set():
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
