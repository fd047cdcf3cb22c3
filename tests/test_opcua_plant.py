"""The third endpoint kind: a stand-in robot cell (`cotwin plant`) served over OPC UA on loopback."""

from __future__ import annotations

import csv
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.opcua import OPCUAEndpoint
from cotwin.mapping.opcua_auth import default_credentials_file
from cotwin.mapping.perturbed import PerturbedEndpoint
from cotwin.pmodel.perturbation import Perturbation
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.twin.services.plant import Plant
from cotwin.twin.assembly.run import load, run_twin

ua = pytest.importorskip("asyncua").ua
ROOT = Path(__file__).resolve().parents[1]
PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"
THRESHOLD = 0.05  # rad: the deviation service's default absolute threshold


@pytest.fixture(scope="module")
def twin():
    return load(PROJECT)


@pytest.fixture(scope="module")
def serve(twin):
    """Start in-process plants on free loopback ports; every one is stopped at the end of the module."""
    plants: list[Plant] = []

    def start(perturbation: Perturbation = Perturbation(), free_running: bool = False) -> Plant:
        endpoint = PerturbedEndpoint.build(twin.models.tree, twin.models.scene, perturbation)
        plant = Plant(endpoint, "opc.tcp://127.0.0.1:0", free_running)
        plants.append(plant)
        return plant.start()

    yield start
    for plant in plants:
        plant.stop()
    assert not any(p.running for p in plants)


@pytest.fixture(scope="module")
def plant(serve):
    return serve()


@pytest.fixture()
def client(twin, plant):
    endpoint = OPCUAEndpoint(twin.models.tree, plant.url, timeout=5, reset=True)
    yield endpoint
    endpoint.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _moves(endpoint, steps: int = 25, dt: float = 0.1) -> list[dict[str, float]]:
    """A fixed motion: three joints commanded at 0.2 s, one more at 1.2 s; joints after each step."""
    endpoint.start()
    trace = []
    for k in range(steps):
        if k == 2:
            endpoint.command({"M1": 0.6, "M2": -0.9, "M3": 1.1})
        if k == 12:
            endpoint.command({"M4": -1.2})
        endpoint.advance(dt)
        trace.append(endpoint.joint_positions())
    return trace


def _max_deviation(a, b) -> float:
    return max(abs(x[j] - y[j]) for x, y in zip(a, b) for j in x)


# ---- the twin, unchanged, against the plant ----

def test_twin_runs_unchanged_against_the_plant_over_opcua(twin, plant, tmp_path):
    direct = run_twin(twin, tmp_path / "direct", end=8.0, plot=False)
    before = plant.calls
    with OPCUAEndpoint(twin.models.tree, plant.url, timeout=5, reset=True) as endpoint:
        remote = run_twin(twin, tmp_path / "remote", end=8.0, plot=False, endpoint=endpoint)
    assert plant.calls - before > 80  # every step went over OPC UA
    a = list(csv.DictReader(open(direct.csv)))
    b = list(csv.DictReader(open(remote.csv)))
    assert len(a) == len(b) == 81
    moved = False
    for ra, rb in zip(a, b):
        assert ra["{dmodel}.dmodel.state"] == rb["{dmodel}.dmodel.state"]
        for i in range(6):
            qa, qb = float(ra[f"{{mapping}}.mapping.q{i}"]), float(rb[f"{{mapping}}.mapping.q{i}"])
            assert qa == pytest.approx(qb, abs=1e-9)
            moved |= abs(qa) > 0.1
    assert moved  # the arm did move: the comparison is not between two idle runs


def test_state_reaches_the_variables_an_engineer_browses(twin, plant, client):
    client.start()
    client.command({"M1": 0.3})
    client.advance(0.5)
    import asyncio

    from asyncua import Client

    async def browse():
        async with Client(plant.url, timeout=5) as anonymous:  # anonymous: an observer
            ns = await anonymous.get_namespace_index("urn:cotwin:plant")
            robot = anonymous.get_node(ua.NodeId("Robot", ns))
            name = (await robot.read_browse_name()).Name
            t = await anonymous.get_node(ua.NodeId("Robot.Time", ns)).read_value()
            q = await anonymous.get_node(ua.NodeId("Robot.Joints.shoulder_pan_joint.Position", ns)).read_value()
            goal = await anonymous.get_node(ua.NodeId("Robot.Joints.shoulder_pan_joint.Goal", ns)).read_value()
            sensor = await anonymous.get_node(
                ua.NodeId("Robot.Sensors.ur5e::base_link::PS1.output_position", ns)).read_value()
            children = {(await c.read_browse_name()).Name for c in await robot.get_children()}
            return name, t, q, goal, sensor, children

    name, t, q, goal, sensor, children = asyncio.run(browse())
    assert name == "ur5e"
    assert t == pytest.approx(client.time) and t == pytest.approx(0.5)
    assert q == pytest.approx(client.joint_positions()["shoulder_pan_joint"])
    assert sensor == pytest.approx(q, abs=1e-3)  # MuJoCo senses at the start of its last physics step
    assert goal == pytest.approx(0.3)
    assert {"Time", "Joints", "Sensors", "Mode", "Describe", "Command", "Advance", "AdvanceTo", "State"} <= children


# ---- perturbations ----

def test_a_perturbation_beyond_the_threshold_shows_one_within_it_does_not(twin, serve):
    nominal = _moves(SimulatedEndpoint(PlatformSimulator(twin.models.tree, twin.models.scene)))
    heavy = serve(Perturbation(payload=4.0, latency_ms=150, damping=3.0))
    light = serve(Perturbation(payload=0.05, noise={"position": 1e-4}, seed=3))
    with OPCUAEndpoint(twin.models.tree, heavy.url, timeout=5) as beyond, \
            OPCUAEndpoint(twin.models.tree, light.url, timeout=5) as within:
        assert beyond.layout.perturbation["payload"] == 4.0
        far, near = _max_deviation(nominal, _moves(beyond)), _max_deviation(nominal, _moves(within))
    assert far > 2 * THRESHOLD
    assert 0 < near < THRESHOLD / 5


# ---- bad requests, access, a vanishing plant ----

@pytest.mark.parametrize("method, args, message", [
    ("Command", [ua.Variant("{not json", ua.VariantType.String)], r"Goals is not JSON.*BadTypeMismatch"),
    ("Command", [ua.Variant("[1, 2]", ua.VariantType.String)], r"Goals must be a JSON object"),
    ("Command", [ua.Variant('{"M9": 0.1}', ua.VariantType.String)], r"unknown actuator 'M9'.*BadNoMatch"),
    ("Command", [ua.Variant('{"M1": "fast"}', ua.VariantType.String)], r"goal 'M1' must be a number"),
    ("Command", [ua.Variant('{"M1": NaN}', ua.VariantType.String)], r"goal 'M1' must be a finite number.*BadOutOfRange"),
    ("Command", [ua.Variant(3.0, ua.VariantType.Double)], r"Goals must be a String"),
    ("CommandJoints", [ua.Variant(["M1", "M2"], ua.VariantType.String), ua.Variant([0.1], ua.VariantType.Double)],
     r"2 actuator\(s\) but 1 goal\(s\)"),
    ("CommandJoints", [ua.Variant(["M1"], ua.VariantType.String), ua.Variant([math.inf], ua.VariantType.Double)],
     r"goal 'M1' must be a finite number"),
    ("Advance", [ua.Variant(1e6, ua.VariantType.Double)], r"Dt must be in \[0, 10\] s.*BadOutOfRange"),
    ("Advance", [ua.Variant(-0.1, ua.VariantType.Double)], r"Dt must be in \[0, 10\] s"),
    ("Advance", [ua.Variant(math.nan, ua.VariantType.Double)], r"Dt must be in \[0, 10\] s"),
    ("Advance", [ua.Variant("0.1", ua.VariantType.String)], r"Dt must be a Double.*BadTypeMismatch"),
    ("Advance", [], r"Advance takes 1 argument\(s\) \(Dt\), got 0.*BadArgumentsMissing"),
    ("Advance", [ua.Variant(0.1, ua.VariantType.Double)] * 2, r"BadTooManyArguments"),
    ("AdvanceTo", [ua.Variant(-5.0, ua.VariantType.Double)], r"Time must be within"),
    # hostile goals (issue 22): nested JSON was "internal error", 1e308 rad was accepted
    ("Command", [ua.Variant("[" * 50_000, ua.VariantType.String)], r"Goals is nested too deeply.*BadTypeMismatch"),
    ("Command", [ua.Variant('{"M1": {"M1": {"M1": 0.1}}}', ua.VariantType.String)],
     r"goal 'M1' must be a number, got dict.*BadTypeMismatch"),
    ("Command", [ua.Variant(" " * 70_000 + "{}", ua.VariantType.String)], r"Goals is 70002 characters long"),
    ("Command", [ua.Variant('{"M2": 1e308}', ua.VariantType.String)],
     r"goal 'M2' = 1e\+308 rad is outside joint shoulder_lift_joint's range \[-6.28319, 6.28319\] rad.*BadOutOfRange"),
    ("CommandJoints", [ua.Variant(["M1"], ua.VariantType.String), ua.Variant([-1e308], ua.VariantType.Double)],
     r"goal 'M1' = -1e\+308 rad is outside joint shoulder_pan_joint's range"),
    ("CommandJoints", [ua.Variant(["LFM"], ua.VariantType.String), ua.Variant([0.05], ua.VariantType.Double)],
     r"goal 'LFM' = 0.05 m is outside joint left_finger_joint's range \[0, 0.019\] m"),
])
def test_bad_requests_are_refused_with_a_status_naming_the_problem(client, plant, method, args, message):
    client.start()
    refused = plant.refused
    with pytest.raises(CotwinError, match=message):
        client.call(method, *args)
    assert plant.refused == refused + 1
    client.refresh()  # still serving
    client.command({"M1": 0.1})


def test_client_checks_goals_and_names_before_sending(client):
    with pytest.raises(CotwinError, match="has no actuator 'M9'"):
        client.joint("M9")
    with pytest.raises(CotwinError, match="goal nan is not a finite number"):
        client.command({"M1": math.nan})
    with pytest.raises(CotwinError, match="cannot advance"):
        client.advance(math.inf)


def test_anonymous_sessions_watch_but_cannot_drive_and_wrong_passwords_are_refused(twin, plant):
    import asyncio

    from asyncua import Client

    async def anonymous_call():
        async with Client(plant.url, timeout=5) as c:
            ns = await c.get_namespace_index("urn:cotwin:plant")
            await c.get_node(ua.NodeId("Robot.Time", ns)).read_value()
            robot = c.get_node(ua.NodeId("Robot", ns))
            await robot.call_method(ua.NodeId("Robot.Advance", ns), ua.Variant(0.1, ua.VariantType.Double))

    with pytest.raises(ua.uaerrors.BadUserAccessDenied):
        asyncio.run(anonymous_call())
    env = {"COTWIN_OPCUA_USER": "cotwin", "COTWIN_OPCUA_PASSWORD": "guess"}
    with pytest.raises(CotwinError, match=f"the plant at {plant.url} failed connect: .*BadUserAccessDenied"):
        OPCUAEndpoint(twin.models.tree, plant.url, timeout=5, environ=env)


def test_a_plant_only_serves_loopback(twin):
    endpoint = PerturbedEndpoint.build(twin.models.tree, None, Perturbation())
    with pytest.raises(CotwinError, match="loopback addresses only"):
        Plant(endpoint, "opc.tcp://0.0.0.0:4840")
    with pytest.raises(CotwinError, match="expected opc.tcp://"):
        Plant(endpoint, "http://127.0.0.1:4840")


def test_nothing_listening_is_a_clear_error(twin, tmp_path):
    """Connection refused, whether credentials are configured or not (without them it said "no operator
    credentials", as if the plant were up)."""
    url = f"opc.tcp://127.0.0.1:{_free_port()}"
    env = {"COTWIN_OPCUA_USER": "cotwin", "COTWIN_OPCUA_PASSWORD": "x"}
    refused = rf"the plant at {url} failed connect: connection refused \(is the plant running\?\)"
    with pytest.raises(CotwinError, match=refused):
        OPCUAEndpoint(twin.models.tree, url, timeout=2, environ=env)
    with pytest.raises(CotwinError, match=refused):
        OPCUAEndpoint(twin.models.tree, url, timeout=2, environ={"XDG_RUNTIME_DIR": str(tmp_path)})


def test_a_plant_without_its_credentials_file_is_named_as_such(twin, serve, tmp_path):
    """A plant that listens but whose credentials this user cannot find: that is what is said."""
    plant = serve()
    with pytest.raises(CotwinError, match="no operator credentials for the plant at"):
        OPCUAEndpoint(twin.models.tree, plant.url, timeout=2, environ={"XDG_RUNTIME_DIR": str(tmp_path / "elsewhere")})


@pytest.fixture()
def plant_process(tmp_path):
    """`cotwin plant` in its own process on a free port, killed at the end whatever happens."""
    port = _free_port()
    url = f"opc.tcp://127.0.0.1:{port}"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    process = subprocess.Popen([str(Path(sys.executable).parent / "cotwin"), "plant", str(PROJECT), "--opcua", url,
                                "--payload", "1.5", "--seed", "4"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith(f"serving ur5e on {url} (lockstep"), line + process.stderr.read()
        yield process, url, env
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(10)
        process.stdout.close()
        process.stderr.close()


def test_cli_serves_until_sigterm_and_cleans_up(twin, plant_process):
    process, url, env = plant_process
    credentials = default_credentials_file(url, env)
    assert credentials.is_file() and credentials.stat().st_mode & 0o077 == 0
    with OPCUAEndpoint(twin.models.tree, url, timeout=5, environ=env) as endpoint:
        endpoint.start()
        endpoint.command({"M2": -0.5})
        endpoint.advance(0.5)
        assert endpoint.layout.perturbation["payload"] == 1.5
        assert endpoint.time == pytest.approx(0.5)
    process.send_signal(signal.SIGTERM)
    assert process.wait(10) == 0
    assert "stopped after" in process.stdout.read()
    assert not credentials.exists()


def test_a_vanished_plant_is_a_clear_error_not_a_hang(twin, plant_process):
    process, url, env = plant_process
    endpoint = OPCUAEndpoint(twin.models.tree, url, timeout=2, environ=env)
    try:
        endpoint.start()
        endpoint.advance(0.1)
        process.kill()
        process.wait(10)
        began = time.monotonic()
        with pytest.raises(CotwinError, match=f"the plant at {url} (failed|did not answer) Advance"):
            endpoint.advance(0.1)
        assert time.monotonic() - began < 10  # bounded by the 2 s timeout (and a loaded machine), not a hang
    finally:
        endpoint.close()


# ---- free running ----

def test_free_running_plant_keeps_its_own_clock(twin, serve):
    plant = serve(free_running=True)
    with OPCUAEndpoint(twin.models.tree, plant.url, timeout=5) as endpoint:
        assert endpoint.layout.mode == "free-running"
        endpoint.start()
        t0, began = endpoint.time, time.monotonic()
        endpoint.command({"M1": 0.2})
        for _ in range(5):
            endpoint.advance(0.1)
        wall = time.monotonic() - began
        assert endpoint.time - t0 == pytest.approx(0.5, abs=0.03)  # the plant's clock, not ours
        assert 0.45 <= wall < 3.0  # it ran in real time: waiting for its clock, never ahead of it
        time.sleep(0.3)
        assert endpoint.refresh()["time"] - t0 >= 0.75  # it goes on without us


def test_a_server_that_is_not_a_plant_is_named_as_such(twin):
    import asyncio
    import threading

    from asyncua import Server

    port, up, loop = _free_port(), threading.Event(), asyncio.new_event_loop()
    done = asyncio.Event()

    async def main():  # a bare asyncua server: another OPC UA device, not a cotwin plant
        server = Server()
        await server.init()
        server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
        async with server:
            up.set()
            await done.wait()

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    try:
        assert up.wait(30)
        env = {"COTWIN_OPCUA_USER": "someone", "COTWIN_OPCUA_PASSWORD": "x"}
        with pytest.raises(CotwinError, match=f"the OPC UA server at opc.tcp://127.0.0.1:{port} is not a cotwin plant"):
            OPCUAEndpoint(twin.models.tree, f"opc.tcp://127.0.0.1:{port}", timeout=5, environ=env)
    finally:
        loop.call_soon_threadsafe(done.set)
        thread.join(10)
        loop.close()


@pytest.mark.parametrize("perturbation, alarmed", [
    # position noise included: the IK's branch does not depend on the measured joints (only the base's
    # turn follows them), so noisy encoders do not make the PT pick another solution than the DT
    (Perturbation(payload=0.05, friction=0.05, noise={"velocity": 1e-3, "position": 1e-3}, seed=2), False),
    (Perturbation(payload=4.0, latency_ms=300, damping=3.0), True),
])
def test_live_twin_with_the_plant_as_pt_alarms_beyond_the_threshold_only(twin, serve, tmp_path, perturbation, alarmed):
    from cotwin.twin.live.runtime import LiveTwin

    plant = serve(perturbation)
    with OPCUAEndpoint(twin.models.tree, plant.url, timeout=5, reset=True) as pt:
        result = LiveTwin(twin, tmp_path, pt=pt, end=8.0).run()
    assert result.pt.steps == result.dt.steps == 80
    assert (result.deviation["alarms"] > 0) == alarmed, result.deviation
    import csv

    def delivered(side):  # the steps in which the source handed the d-model a command
        rows = csv.DictReader(open(tmp_path / side / "outputs.csv"))
        return [r["time"] for r in rows if r["{controller}.controller.moveDiscreteCommand"] == "true"]

    assert delivered("pt") == delivered("dt") == ["1.1", "5.6"]  # the plan's commands before 8 s, once each


def test_a_server_that_never_answers_is_a_timeout_without_asyncios_leftovers_in_the_log(twin, caplog):
    """A port that accepts but never speaks (not a plant, or a plant hung): the connect timed out as it should,
    but the connect task given up on was left pending when the client's loop closed, and asyncio printed
    "Task was destroyed but it is pending!" with the coroutine's repr (logged: on the user's stderr from the CLI)."""
    import gc

    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    url = f"opc.tcp://127.0.0.1:{silent.getsockname()[1]}"
    try:
        with pytest.raises(CotwinError, match=f"the plant at {url} did not answer connect within 1 s"):
            OPCUAEndpoint(twin.models.tree, url, timeout=1, environ={"COTWIN_OPCUA_USER": "cotwin",
                                                                     "COTWIN_OPCUA_PASSWORD": "not-a-plant-1234"})
        gc.collect()
    finally:
        silent.close()
    assert not [r for r in caplog.records if "Task was destroyed" in r.getMessage()]


def test_a_plant_on_the_ipv6_loopback_and_a_free_port_serves_and_says_its_url(twin):
    """opc.tcp://[::1]:0 (the IPv6 loopback the plant allows, a free port) failed at start: its URL was spelt
    opc.tcp://::1:PORT, which no one can read back ("Port could not be cast to integer value"), and asyncio's
    pending tasks followed on stderr. A URL without a port was said without it (the default 4840 served).
    `with plant.start():` made a second account, and left the served one's credentials file behind."""
    from cotwin.mapping.opcua_auth import parse_url

    try:
        socket.create_server(("::1", 0), family=socket.AF_INET6).close()
    except OSError:
        pytest.skip("no IPv6 loopback here")
    plant = Plant(PerturbedEndpoint.build(twin.models.tree, twin.models.scene, Perturbation()), "opc.tcp://[::1]:0")
    with plant.start():  # started twice (start, then the with): the account served is the one its file holds
        assert parse_url(plant.url) == ("::1", plant.port) and plant.port > 0
        assert plant.url == f"opc.tcp://[::1]:{plant.port}"
        credentials = plant.credentials_file
        assert credentials is not None and credentials.is_file()
        with OPCUAEndpoint(twin.models.tree, plant.url, timeout=5) as endpoint:
            assert endpoint.layout.joints
    assert not credentials.exists()  # removed at stop, not left behind
    unstarted = Plant(PerturbedEndpoint.build(twin.models.tree, twin.models.scene, Perturbation()), "opc.tcp://127.0.0.1")
    assert unstarted.url == "opc.tcp://127.0.0.1:4840"
