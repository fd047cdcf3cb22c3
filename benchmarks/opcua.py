"""The OPC UA plant on loopback: wall time of one lockstep Advance (median, p99) at co-simulation steps of
0.01 and 0.1 s, as the twin's mapping sees it (one call per step, the state in its reply); peer: the same
advance on the embedded SimulatedEndpoint in the same run, and the broker endpoint when RabbitMQ runs."""

from __future__ import annotations

import secrets
import socket
import statistics
import sys
import threading
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from cotwin.mapping.endpoint import SimulatedEndpoint  # noqa: E402
from cotwin.mapping.opcua import OPCUAEndpoint  # noqa: E402
from cotwin.mapping.perturbed import PerturbedEndpoint  # noqa: E402
from cotwin.pmodel.perturbation import Perturbation  # noqa: E402
from cotwin.pmodel.simulator import PlatformSimulator  # noqa: E402
from cotwin.twin.services.plant import Plant  # noqa: E402
from cotwin.twin.assembly.run import load  # noqa: E402
from figures import figure  # noqa: E402

STEPS = 400


def timed(endpoint, dt: float) -> list[float]:
    endpoint.start()
    endpoint.command({"M1": 0.8, "M2": -1.0, "M3": 1.2})
    samples = []
    for _ in range(STEPS):
        t0 = time.perf_counter()
        endpoint.advance(dt)
        endpoint.joint_positions()
        samples.append(time.perf_counter() - t0)
    return samples


def figures(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    return statistics.median(ordered) * 1000, ordered[int(0.99 * (len(ordered) - 1))] * 1000


def broker_up() -> bool:
    try:
        with socket.create_connection(("127.0.0.1", 5672), timeout=1):
            return True
    except OSError:
        return False


def main() -> None:
    models = load(ROOT / "examples" / "ur5e" / "cotwin.toml").models
    t0 = time.perf_counter()
    plant = Plant(PerturbedEndpoint.build(models.tree, models.scene, Perturbation()), "opc.tcp://127.0.0.1:0").start()
    started = time.perf_counter() - t0
    try:
        t0 = time.perf_counter()
        client = OPCUAEndpoint(models.tree, plant.url, timeout=10, reset=True)
        connected = time.perf_counter() - t0
        print(f"plant start (asyncua address space) {started * 1000:.0f} ms; client connect + Describe "
              f"{connected * 1000:.0f} ms")
        for dt in (0.01, 0.1):
            direct = figures(timed(SimulatedEndpoint(PlatformSimulator(models.tree, models.scene)), dt))
            remote = figures(timed(client, dt))
            figure(f"OPC UA Advance, step {dt:g} s, median", remote[0], "ms", peer="embedded endpoint",
                   peer_value=direct[0], p99_ms=remote[1], peer_p99_ms=direct[1], samples=STEPS)
            line = (f"step {dt:g} s: OPC UA Advance median {remote[0]:.2f} ms, p99 {remote[1]:.2f} ms; "
                    f"embedded {direct[0]:.2f} / {direct[1]:.2f} ms; overhead median {remote[0] - direct[0]:.2f} ms")
            if broker_up():
                from cotwin.mapping.broker import BrokerEndpoint, RobotServer

                queue = f"cotwin.bench.{uuid.uuid4().hex[:8]}"
                secret = secrets.token_bytes(32)  # the robot link is authenticated (docs/security.md)
                server = RobotServer(SimulatedEndpoint(PlatformSimulator(models.tree, models.scene)), queue,
                                     secret=secret)
                thread = threading.Thread(target=server.serve, daemon=True)
                thread.start()
                server.ready.wait(10)
                broker = BrokerEndpoint(models.tree, queue, secret=secret)
                peer = figures(timed(broker, dt))
                broker.close()
                server.stop()
                thread.join(5)
                figure(f"broker endpoint advance, step {dt:g} s, median", peer[0], "ms", p99_ms=peer[1], samples=STEPS)
                line += f"; broker (RabbitMQ) {peer[0]:.2f} / {peer[1]:.2f} ms, OPC UA/broker {remote[0] / peer[0]:.2f}"
            print(line)
        client.close()
    finally:
        plant.stop()


if __name__ == "__main__":
    main()
