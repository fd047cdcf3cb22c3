"""The live twin: latency from a command published on RabbitMQ to the servo target set in the DT (paced
at step 0.01 s, goal: p99 at most one step plus 2 ms, over 100 commands so that a p99 is not just the
maximum), and the PT+DT lockstep real-time factor without pacing, beside one twin alone (the peer)
measured in the same run."""

from __future__ import annotations

import json
import socket
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.mapping.amqp import connect  # noqa: E402
from cotwin.mapping.endpoint import SimulatedEndpoint  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.twin.assembly.rabbitmq import READY  # noqa: E402
from cotwin.twin.assembly.run import load, run_twin  # noqa: E402
from cotwin.twin.live.runtime import LiveTwin  # noqa: E402
from figures import figure, goal, shown, spread  # noqa: E402


class TimedEndpoint(SimulatedEndpoint):
    """The DT's simulator, noting the wall time at which each servo target arrives."""

    def __init__(self, sim):
        super().__init__(sim)
        self.commanded: list[float] = []

    def command(self, goals):
        self.commanded.append(time.time())
        super().command(goals)


def latency(algorithm: str, step: float = 0.01, commands: int = 100, period: float = 1.5) -> tuple[list[float], int]:
    """Latencies of `commands` moves between neighbouring holes, each published at a random phase once the
    arm has settled from the previous one (a first move from home to the plate is not counted); returns
    the latencies and how many commands got no servo target within half a second."""
    system = load(ROOT / "examples" / "ur5e" / "live.toml")
    exchange = f"cotwin_bench_{uuid.uuid4().hex[:8]}"
    settings = replace(system.spec.rabbitmq, exchange=exchange)
    system.spec.rabbitmq = settings
    system.spec.algorithm = algorithm
    end = 2.5 + commands * period + 1.0
    endpoint = TimedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    published: list[float] = []
    ready = threading.Event()

    def publisher():
        connection = connect(settings.url, "cotwin bench publisher")
        channel = connection.channel()
        channel.exchange_declare(exchange, exchange_type="direct", durable=False, auto_delete=False)
        own = channel.queue_declare("", exclusive=True).method.queue
        channel.queue_bind(own, exchange, routing_key=settings.from_cosim)
        got = threading.Event()
        channel.basic_consume(own, lambda *a: got.set() if READY["internal_message"].encode() in a[3] else None,
                              auto_ack=True)
        ready.set()
        while not got.is_set():
            connection.process_data_events(time_limit=0.05)
        idle = {"moveDiscreteCommand": False, "MovementArgs_target_X": 0, "MovementArgs_target_Y": 0,
                "MovementArgs_target_Z": 0, "openGripperCommand": False, "closeGripperCommand": False}
        start = time.monotonic()
        rng = np.random.default_rng(1)
        due = [0.5] + [2.5 + k * period + rng.uniform(0, step) for k in range(commands)]
        sent = 0
        while time.monotonic() - start < end:
            message = dict(idle)
            tick = time.monotonic() - start
            if sent < len(due) and tick >= due[sent]:
                message.update(moveDiscreteCommand=True, MovementArgs_target_X=7 + sent % 2, MovementArgs_target_Y=12,
                               MovementArgs_target_Z=1)
                sent += 1
            now = time.time()
            message["time"] = datetime.fromtimestamp(now, timezone.utc).isoformat()
            channel.basic_publish(exchange, settings.to_cosim, json.dumps(message).encode())
            if message["moveDiscreteCommand"]:
                published.append(now)
            next_tick = min(due[sent:] + [tick + 0.1])
            while (left := next_tick - (time.monotonic() - start)) > 0:  # echoes end process_data_events early
                connection.process_data_events(time_limit=min(left, 0.05))
        connection.close()

    thread = threading.Thread(target=publisher, daemon=True)
    thread.start()
    ready.wait(10)
    with tempfile.TemporaryDirectory() as tmp:
        run_twin(system, tmp, step=step, end=end, realtime=True, plot=False, endpoint=endpoint)
    thread.join(5)
    out, missed = [], 0
    for p in published[1:]:  # the first servo target set after each publication
        later = [c - p for c in endpoint.commanded if c >= p]
        if later and later[0] < 0.5:
            out.append(later[0])
        else:
            missed += 1
    return out, missed


def lockstep(step: float) -> tuple[float, float]:
    system = load(ROOT / "examples" / "ur5e" / "cotwin.toml")
    with tempfile.TemporaryDirectory() as tmp:
        alone = run_twin(system, Path(tmp) / "one", step=step, plot=False).result
        pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
        both = LiveTwin(system, Path(tmp) / "two", pt=pt, step=step).run()
    return alone.real_time_factor, both.pt.real_time_factor


def broker_up() -> bool:
    try:
        with socket.create_connection(("127.0.0.1", 5672), timeout=1):
            return True
    except OSError:
        return False


def main() -> None:
    for step in (0.1, 0.01):
        alone, both = lockstep(step)
        figure(f"PT+DT lockstep, step {step:g} s, no pacing: real-time factor", both, "x", peer="one twin alone",
               peer_value=alone)
        print(f"20 s experiment, step {step:g} s, no pacing: PT+DT lockstep real-time factor {both:.1f}x "
              f"(one twin alone {alone:.1f}x; lockstep/alone = {both / alone:.2f})")
    if not broker_up():
        print("latency: not measured (no RabbitMQ on 127.0.0.1:5672)")
        goal("command latency p99 (RabbitMQ not running)", None, 12.0, at_most=True, unit=" ms")
        return
    for algorithm in ("gauss-seidel", "jacobi"):
        values, missed = latency(algorithm)
        s = spread([v * 1000 for v in values])
        figure(f"command published -> servo target, step 10 ms paced, {algorithm}", s["p99"], "ms (p99)", **s,
               not_served=missed)
        print(f"command published -> servo target in the DT, step 10 ms paced, {algorithm}: over {s['n']} commands "
              f"median {shown(s['median'])} ms, p90 {shown(s['p90'])} ms, p99 {shown(s['p99'])} ms, max {shown(s['max'])} ms"
              f"{f', {missed} not served' if missed else ''} "
              f"(p99 {goal(f'command latency p99, {algorithm}', s['p99'], 12.0, at_most=True, unit=' ms')}: one step + 2 ms; "
              f"every command served {goal(f'commands not served, {algorithm}', missed, 0, at_most=True)})")


if __name__ == "__main__":
    main()
