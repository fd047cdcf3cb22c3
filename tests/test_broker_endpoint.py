"""The second endpoint kind: the robot behind the real RabbitMQ broker, in lockstep."""

from __future__ import annotations

import csv
import json
import threading
import uuid

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.broker import BrokerEndpoint, RobotServer, validate_request
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.twin.assembly.run import load, run_twin
from cotwin.pmodel.simulator import PlatformSimulator




@pytest.fixture()
def twin():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


@pytest.fixture()
def robot(broker, twin, monkeypatch):
    """A robot (the MuJoCo platform) answering on its own queue in a thread; the twin and the server
    share the link's secret through the environment, as deployed."""
    monkeypatch.setenv("COTWIN_ROBOT_SECRET", uuid.uuid4().hex)
    queue = f"cotwin.test.{uuid.uuid4().hex[:8]}"
    server = RobotServer(SimulatedEndpoint(PlatformSimulator(twin.models.tree, twin.models.scene)), queue)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    assert server.connected.wait(10)
    yield server
    server.stop()
    thread.join(5)


def test_twin_runs_unchanged_against_a_robot_behind_the_broker(twin, robot, tmp_path):
    direct = run_twin(twin, tmp_path / "direct", end=8.0, plot=False)
    twin.spec.endpoint, twin.spec.queue = "broker", robot.queue
    remote = run_twin(twin, tmp_path / "remote", end=8.0, plot=False)
    remote.mapping.mapping.endpoint.close()
    assert robot.requests > 80  # every step went through the broker
    a = list(csv.DictReader(open(direct.csv)))
    b = list(csv.DictReader(open(remote.csv)))
    assert len(a) == len(b) == 81
    for ra, rb in zip(a, b):
        assert ra["{dmodel}.dmodel.state"] == rb["{dmodel}.dmodel.state"]
        for i in range(6):
            assert float(ra[f"{{mapping}}.mapping.q{i}"]) == pytest.approx(float(rb[f"{{mapping}}.mapping.q{i}"]), abs=1e-9)


def test_ill_formed_requests_get_errors_naming_the_field(twin, robot):
    endpoint = BrokerEndpoint(twin.models.tree, robot.queue)
    try:
        with pytest.raises(CotwinError, match="goal 'M1' must be a finite number"):
            endpoint.call({"op": "command", "goals": {"M1": "fast"}})
        with pytest.raises(CotwinError, match="unknown field.*speed"):
            endpoint.call({"op": "advance", "dt": 0.1, "speed": 2})
        with pytest.raises(CotwinError, match=r"dt must be a number of seconds in \[0, 10\]"):
            endpoint.call({"op": "advance", "dt": 1e6})
        with pytest.raises(CotwinError, match="unknown actuator 'M9'"):
            endpoint.call({"op": "command", "goals": {"M9": 0.1}})
        with pytest.raises(CotwinError, match="unknown op 'fly'"):
            endpoint.call({"op": "fly"})
        state = endpoint.call({"op": "state"})  # still serving after the bad ones
        assert "ur5e::base_link::PS1.output_position" in state["sensors"]
    finally:
        endpoint.close()


def test_request_validation_without_a_broker():
    assert validate_request({"op": "advance", "dt": 0.5}) == {"op": "advance", "dt": 0.5}
    for bad, text in [([], "JSON object"), ({"op": "command"}, "missing field"), ({"op": "advance", "dt": True}, "dt must"),
                      ({"op": "command", "goals": {"M1": float("nan")}}, "finite number")]:
        with pytest.raises(CotwinError, match=text):
            validate_request(bad)
    assert json.dumps(validate_request({"op": "state"}))
