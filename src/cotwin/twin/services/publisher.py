"""A command publisher that follows the RMQ FMU protocol as the paper's arm publisher does.

It binds its own queue to `from_cosim` on the twin's direct exchange, waits for the ready message
("waiting for input data for simulation"), then every `period` seconds of wall time publishes one
message on `to_cosim`, choosing it from the last `simstep` the co-simulation echoed: a planned command
once the echoed simulation time is within half a period of its time (each command once, in order),
otherwise the idle message (events false, values zero). Echoes are taken only where the twin could have
sent them (`EchoClock`: a forged one claiming the end is refused). It stops when told to, when the
echoed time passes `end`, or when the co-simulation has been silent for `silence` seconds after it
started; `run` returns which (`ended`), and the commands of the plan never sent are in `pending`.
"""

from __future__ import annotations

import json
import threading
import time as wallclock
from dataclasses import dataclass, field
from datetime import datetime, timezone

from ...diagnostics import CotwinError
from ...mapping.amqp import connect, declare_exchange
from ..project import RabbitMQSettings
from ..assembly.rabbitmq import COMMANDS, EchoClock
from ..assembly.scenario import Command


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


@dataclass
class Publisher:
    settings: RabbitMQSettings
    commands: list[Command]
    idle: dict[str, object]  # every command port with its resting value
    period: float = 0.5
    end: float | None = None
    silence: float = 5.0
    name: str = "cotwin publisher"
    sent: list[tuple[float, float, dict]] = field(default_factory=list)  # (wall, echoed sim time, message)
    ready: threading.Event = field(default_factory=threading.Event)
    ended: str | None = None  # why run() returned: "end" (the twin reached `end`), "silence" or "stopped"
    pending: list[Command] = field(default_factory=list)  # commands of the plan not sent when it returned
    clock: EchoClock | None = None  # what the echoes said (refused ones counted)

    def _message(self, values: dict[str, object]) -> dict:
        return {"time": now_iso(), **values}

    def run(self, stop: threading.Event | None = None, ready_timeout: float = 60.0) -> None:
        stop = stop or threading.Event()
        s = self.settings
        connection = connect(s.url, self.name)
        try:
            channel = connection.channel()
            declare_exchange(channel, s.exchange, "direct", s.url, COMMANDS)
            own = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
            channel.queue_bind(own, s.exchange, routing_key=s.from_cosim)
            clock = self.clock = EchoClock(s.maxage_ms / 1000, "publisher")
            started = wallclock.monotonic()

            def on_echo(ch, method, props, body):
                clock.take(body)

            channel.basic_consume(own, on_echo, auto_ack=True)
            self.ready.set()  # bound: the co-simulation may start now
            deadline = wallclock.monotonic() + ready_timeout
            self.ended = "stopped"
            while clock.ready_at is None and not stop.is_set():
                connection.process_data_events(time_limit=0.05)
                if wallclock.monotonic() > deadline:
                    raise CotwinError(f"no ready message on '{s.from_cosim}' within {ready_timeout:g} s")
            pending = self.pending = sorted(self.commands, key=lambda c: c.time)
            next_tick = wallclock.monotonic()
            while not stop.is_set():
                sim = clock.sim
                values = dict(self.idle)
                if pending and sim is not None and sim >= pending[0].time - self.period / 2:
                    values.update(dict(pending.pop(0).values))
                message = self._message(values)
                channel.basic_publish(s.exchange, s.to_cosim, json.dumps(message).encode())
                self.sent.append((wallclock.time(), sim if sim is not None else float("nan"), message))
                next_tick += self.period
                while not stop.is_set():
                    left = next_tick - wallclock.monotonic()
                    if left <= 0:
                        break
                    connection.process_data_events(time_limit=min(left, 0.05))
                sim = clock.sim
                if self.end is not None and sim is not None and sim >= self.end - 1e-9:
                    self.ended = "end"
                    break
                if wallclock.monotonic() - (clock.heard or clock.ready_at or started) > self.silence:
                    self.ended = "silence"
                    break
        finally:
            if self.clock is not None:
                self.clock.close()
            try:
                connection.close()
            except Exception:  # noqa: BLE001
                pass


def idle_values(types: dict[str, str]) -> dict[str, object]:
    return {p: (False if kind == "Boolean" else 0.0 if kind == "Real" else 0) for p, kind in types.items()}
