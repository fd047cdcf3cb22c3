"""No stranger on the twin's links, on the real RabbitMQ: the twin through TLS with credentials from the
environment and least-privilege accounts, a rogue responder refused, the robot server surviving random
messages, and faults (broker closing the link, robot server killed, garbage replies) giving clear errors
with the rows so far intact. No password in any message."""

from __future__ import annotations

import csv
import json
import logging
import os
import random
import select
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pika
import pytest

from cotwin.cosim.observers import Observer
from cotwin.diagnostics import CotwinError
from cotwin.mapping.amqp import connect
from cotwin.mapping.broker import BrokerEndpoint, RobotServer
from cotwin.mapping.endpoint import SimulatedEndpoint
from cotwin.mapping.robot_protocol import OPS, reply_headers, request_headers
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.twin.assembly.broker_access import rabbitmqctl_script, roles
from cotwin.twin.project import load_project
from cotwin.twin.assembly.run import load, run_twin
from rabbit_tls import PKI, TLSBroker, close_connection, tools_missing

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ROOT / "examples" / "ur5e" / "cotwin.toml"
COTWIN_VARS = [v for v in os.environ if v.startswith("COTWIN_") and v != "COTWIN_CACHE"]  # the session's own cache stays


@pytest.fixture(scope="module")
def tls(broker, tmp_path_factory):
    """A TLS listener on the running broker, a throwaway vhost and one user per role (documented permissions)."""
    missing = tools_missing()
    if missing:
        if os.environ.get("CI"):
            pytest.fail(missing)
        pytest.skip(missing)
    prefix = f"cotwin-test-{uuid.uuid4().hex[:6]}-"
    server = TLSBroker(PKI(tmp_path_factory.mktemp("pki")), roles(load_project(PROJECT), prefix)).start()
    yield server
    server.stop()


@pytest.fixture()
def clean_env(monkeypatch):
    for v in COTWIN_VARS:
        monkeypatch.delenv(v, raising=False)
    return monkeypatch


@pytest.fixture()
def twin():
    return load(PROJECT)


def simulated(twin) -> SimulatedEndpoint:
    return SimulatedEndpoint(PlatformSimulator(twin.models.tree, twin.models.scene))


def serve_in_thread(server: RobotServer) -> threading.Thread:
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    assert server.connected.wait(10)
    return thread


def serve_in_process(queue: str, url: str, env: dict[str, str]) -> subprocess.Popen:
    """`cotwin serve-robot` in its own process with only `env` as its COTWIN_* settings; waits until ready."""
    base = {k: v for k, v in os.environ.items() if not k.startswith("COTWIN_")}
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "serve-robot", str(PROJECT), "--queue", queue, "--url", url],
                            env={**base, **env}, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.5)
        if ready and proc.stdout.readline().strip() == "ready":
            return proc
        if proc.poll() is not None:
            break
    proc.kill()
    raise AssertionError(f"the robot server did not start: {proc.stderr.read()}")


class AtRow(Observer):
    """Calls `action` once, after `row` steps."""

    def __init__(self, row: int, action):
        self.row, self.action, self.steps = row, action, 0

    def step_complete(self, execution) -> None:
        self.steps += 1
        if self.steps == self.row:
            self.action()


def rows(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


# ---- TLS, credentials, least privilege ---------------------------------------------------------

def test_the_twin_runs_through_tls_with_credentials_from_the_environment(tls, twin, clean_env, tmp_path):
    secret = uuid.uuid4().hex
    robot = serve_in_process("cotwin.robot", tls.url(), tls.env("robot", COTWIN_ROBOT_SECRET=secret))
    try:
        for key, value in tls.env("twin", COTWIN_ROBOT_SECRET=secret).items():
            clean_env.setenv(key, value)
        direct = run_twin(load(PROJECT), tmp_path / "direct", end=3.0, plot=False)
        twin.spec.endpoint, twin.spec.url = "broker", tls.url("127.0.0.1")  # the certificate names the IP too
        remote = run_twin(twin, tmp_path / "tls", end=3.0, plot=False)
        remote.mapping.mapping.endpoint.close()
    finally:
        robot.send_signal(signal.SIGTERM)  # stopping is a local act
        out, err = robot.communicate(timeout=20)
    assert robot.returncode == 0, err
    assert "served" in err and "refused 0 unauthenticated" in err
    a, b = rows(direct.csv), rows(remote.csv)
    assert len(a) == len(b) == 31
    moved = max(abs(float(r["{mapping}.mapping.q0"]) - float(a[0]["{mapping}.mapping.q0"])) for r in a)
    assert moved > 0.1  # the arm moved, and identically through the broker
    for ra, rb in zip(a, b):
        for i in range(6):
            assert float(ra[f"{{mapping}}.mapping.q{i}"]) == pytest.approx(float(rb[f"{{mapping}}.mapping.q{i}"]), abs=1e-9)


def _error(call) -> str:
    with pytest.raises(CotwinError) as err:
        call()
    return str(err.value)


def test_tls_and_credential_failures_are_clear_and_never_show_a_password(tls, clean_env, caplog, tmp_path):
    caplog.set_level(logging.DEBUG)  # pika's and cotwin's own logs are searched for secrets too
    twin = tls.env("twin")
    password = twin["COTWIN_AMQP_PASSWORD"]
    no_ca = {k: v for k, v in twin.items() if k != "COTWIN_AMQP_CA"}
    no_cert = {k: v for k, v in twin.items() if k not in ("COTWIN_AMQP_CERT", "COTWIN_AMQP_KEY")}
    cases = [
        (tls.url(), no_ca, "could not be verified \\(self-signed certificate in certificate chain\\).*COTWIN_AMQP_CA"),
        (tls.url(), {**twin, "COTWIN_AMQP_SERVER_NAME": "broker.example"}, "Hostname mismatch"),
        (tls.url(), no_cert, "client certificate.*set COTWIN_AMQP_CERT"),
        (tls.url(), {**twin, "COTWIN_AMQP_PASSWORD": password + "x"}, "refused the credentials of user 'cotwin-test-"),
        (f"amqps://localhost:{tls.port}/%2F", twin, "may not use virtual host '/'"),
        (f"amqp://127.0.0.1:{tls.port}/v", twin, "closed the connection during the handshake .*use amqps://"),
        ("amqps://127.0.0.1:5672/%2F", twin, "does not speak TLS on this port"),
        (f"amqps://cotwin:{password}@localhost:{tls.port}/v", twin, "holds user information"),
        ("amqps://127.0.0.1:1/v", twin, "connection refused"),
    ]
    messages = []
    for url, env, expected in cases:
        text = _error(lambda: connect(url, "cotwin test", env))
        assert __import__("re").search(expected, text), (expected, text)
        messages.append(text)
    # through the robot link and the project file as well
    text = _error(lambda: BrokerEndpoint(None, "q", tls.url(), environ={**no_ca, "COTWIN_ROBOT_SECRET": "s" * 20}))
    messages.append(text)
    bad = tmp_path / "cotwin.toml"
    bad.write_text(PROJECT.read_text().replace("[platform]", f'[platform]\nurl = "amqps://u:{password}@h/v"'))
    assert "[platform]" in PROJECT.read_text()
    text = _error(lambda: load_project(bad))
    assert "password in the project file is refused" in text
    messages.append(text)
    for text in messages:
        assert password not in text
    assert password not in caplog.text


def _open(tls, role):
    connection = connect(tls.url(), f"cotwin test {role}", tls.env(role))
    return connection, connection.channel()


def _refused(action) -> int:
    with pytest.raises(pika.exceptions.ChannelClosedByBroker) as err:
        action()
    return err.value.reply_code


def test_each_role_can_do_its_job_and_nothing_else(tls, clean_env):
    from cotwin.twin.project import RabbitMQSettings
    from cotwin.twin.assembly.rabbitmq import EventPublisher, RabbitMQBridge

    exchange = "fmi_digital_twin_dt"
    for key, value in tls.env("twin").items():
        clean_env.setenv(key, value)
    twin, tch = _open(tls, "twin")
    tch.exchange_declare("cotwin.twin", exchange_type="topic", durable=False, auto_delete=False)
    bridge = RabbitMQBridge(RabbitMQSettings(exchange, url=tls.url()), "cotwin test bridge").start()
    monitor, mch = _open(tls, "monitor")
    alarms = mch.queue_declare("", exclusive=True).method.queue
    mch.queue_bind(alarms, "cotwin.twin", routing_key="#")
    publisher, pch = _open(tls, "publisher")
    robot, rch = _open(tls, "robot")
    try:
        pch.basic_publish(exchange, "data.to_cosim", b'{"time": "2025-01-01T00:00:00Z", "x": 1}')
        deadline = time.monotonic() + 10
        got = []
        while not got and time.monotonic() < deadline:
            got = bridge.receive(0.2)
        assert got and b'"x": 1' in got[0].body  # publisher -> exchange -> the twin's queue
        events = EventPublisher(tls.url(), "cotwin.twin", "cotwin test alarms")
        events.publish("twin.alarm", {"variable": "q0"})
        events.close()
        assert events.sent == 1
        method = None
        while method is None and time.monotonic() < deadline:
            method, _, body = mch.basic_get(alarms, auto_ack=True)
            monitor.process_data_events(0.1)
        assert method is not None and json.loads(body) == {"variable": "q0"}  # twin -> alarms -> monitor
        rch.queue_declare("cotwin.robot", exclusive=True)  # the robot server's own queue
        # ... and nothing else: no account can read or take another role's queues
        twin_queue = bridge.queue_name
        assert _refused(lambda: publisher.channel().basic_consume(twin_queue, lambda *a: None)) == 403
        assert _refused(lambda: publisher.channel().queue_declare("cotwin.robot.evil")) == 403
        assert _refused(lambda: robot.channel().basic_consume(twin_queue, lambda *a: None)) == 403
        assert _refused(lambda: monitor.channel().basic_consume(twin_queue, lambda *a: None)) == 403
        assert _refused(lambda: twin.channel().basic_consume("cotwin.robot", lambda *a: None)) in (403, 405)
        assert _refused(lambda: twin.channel().queue_declare("cotwin.robot", exclusive=True)) == 403
        assert _refused(lambda: publisher.channel().exchange_declare("cotwin.twin", exchange_type="topic")) == 403
    finally:
        bridge.close()
        for c in (twin, monitor, publisher, robot):
            if c.is_open:
                c.close()


def _confirmed(connection):
    channel = connection.channel()
    channel.confirm_delivery()  # a refused publish then fails at once
    return channel


def test_what_if_requests_come_only_from_the_whatif_role_and_none_can_forge_alarms(tls, clean_env, tmp_path):
    from cotwin.twin.services.whatif import WhatIfService

    for key, value in tls.env("twin").items():
        clean_env.setenv(key, value)
    service = WhatIfService(tls.url(), "cotwin.twin", PROJECT, tmp_path)  # in the twin, as the twin's user
    asker, channel = _open(tls, "whatif")
    try:
        replies = channel.queue_declare("", exclusive=True).method.queue
        channel.confirm_delivery()
        channel.basic_publish("cotwin.twin", "twin.whatif", b'{"plan": []}',
                              pika.BasicProperties(reply_to=replies, correlation_id="q1"))
        deadline, method = time.monotonic() + 10, None
        while method is None and time.monotonic() < deadline:
            method, props, body = channel.basic_get(replies, auto_ack=True)
            asker.process_data_events(0.1)
        assert method is not None and props.correlation_id == "q1"
        assert json.loads(body) == {"error": "bad what-if request: plan must be a non-empty list"}
        # the what-if role may not forge an alarm, the monitor may not ask, the publisher may not touch either
        assert _refused(lambda: _confirmed(asker).basic_publish("cotwin.twin", "twin.alarm", b"{}")) == 403
        for role in ("monitor", "publisher"):
            connection, _ = _open(tls, role)
            assert _refused(lambda: _confirmed(connection).basic_publish("cotwin.twin", "twin.whatif", b"{}")) == 403
            connection.close()
    finally:
        asker.close()
        service.close()


def test_the_documented_commands_name_the_same_permissions():
    script = rabbitmqctl_script(load_project(PROJECT), "cotwin")
    docs = (ROOT / "docs" / "security.md").read_text()
    for line in script.splitlines():
        if line.startswith(("rabbitmqctl set_permissions", "rabbitmqctl set_topic_permissions", "rabbitmqctl add_vhost")):
            assert line in docs, f"docs/security.md lacks: {line}"


# ---- impostors ---------------------------------------------------------------------------------

def test_a_rogue_responder_is_refused(broker, twin, clean_env, tmp_path):
    secret = uuid.uuid4().hex
    clean_env.setenv("COTWIN_ROBOT_SECRET", secret)
    queue = f"cotwin.test.{uuid.uuid4().hex[:8]}"
    server = RobotServer(simulated(twin), queue)
    thread = serve_in_thread(server)
    rogue = connect("amqp://127.0.0.1/%2F", "cotwin test rogue")
    try:  # a second server cannot take the queue, nor consume from it
        assert _refused(lambda: rogue.channel().queue_declare(queue, exclusive=True)) == 405
        assert _refused(lambda: rogue.channel().basic_consume(queue, lambda *a: None)) == 405
        assert _refused(lambda: rogue.channel().queue_delete(queue)) == 405
    finally:
        server.stop()
        thread.join(5)
    # a rogue that takes the queue first: the real server refuses to start, and the twin refuses its replies
    channel = rogue.channel()
    channel.queue_declare(queue, exclusive=True)
    forged = {"ok": True, "actuators": ["M1"], "sensors": []}

    def answer(ch, method, props, body):
        out = json.dumps(forged).encode()
        ch.basic_publish("", props.reply_to, out, pika.BasicProperties(
            correlation_id=props.correlation_id, headers=reply_headers(b"a-guessed-secret-16", queue, props.correlation_id, out)))

    channel.basic_consume(queue, answer, auto_ack=True)
    stop = threading.Event()
    pump = threading.Thread(target=lambda: [rogue.process_data_events(0.05) for _ in iter(stop.is_set, True)],
                            daemon=True)
    pump.start()
    try:
        assert "held by another connection" in _error(lambda: RobotServer(simulated(twin), queue).serve())
        twin.spec.endpoint, twin.spec.queue = "broker", queue
        text = _error(lambda: run_twin(twin, tmp_path, end=1.0, plot=False))
        assert "failed authentication: another process is answering on the robot's queue" in text
        assert not (tmp_path / "outputs.csv").exists()  # nothing taken from the impostor
    finally:
        stop.set()
        pump.join(5)
        rogue.close()


def test_stop_is_not_taken_from_the_wire(broker, twin, clean_env):
    clean_env.setenv("COTWIN_ROBOT_SECRET", uuid.uuid4().hex)
    server = RobotServer(simulated(twin), f"cotwin.test.{uuid.uuid4().hex[:8]}")
    thread = serve_in_thread(server)
    client = BrokerEndpoint(twin.models.tree, server.queue, timeout=5)
    try:
        assert "unknown op 'stop'" in _error(lambda: client.call({"op": "stop"}))
        assert client.call({"op": "state"})["ok"] and thread.is_alive()
    finally:
        client.close()
        server.stop()
        thread.join(5)
    assert not thread.is_alive()  # the local call stops it


# ---- fuzz: 10,000 random messages --------------------------------------------------------------

def _random_value(rng: random.Random, depth: int = 0):
    kinds = ["int", "float", "str", "bool", "none", "list", "dict", "big", "neg"]
    kind = rng.choice(kinds if depth < 3 else kinds[:5])
    return {"int": lambda: rng.choice([-3, -1, 0, 11, 42]), "float": lambda: rng.choice([0.0, 0.002, 0.01, 1e308, -0.5, 11.0]),
            "str": lambda: rng.choice(["", "0.1", "M1", "\u0000", "\ud800x", "é" * 3]), "bool": lambda: rng.random() < 0.5,
            "none": lambda: None, "list": lambda: [_random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))],
            "dict": lambda: {rng.choice(["M1", "x", "dt", "op"]): _random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))},
            "big": lambda: 10 ** 30, "neg": lambda: -1e-9}[kind]()


def _structured(rng: random.Random, actuators: list[str]) -> tuple[bytes, bool, float]:
    """A mutated request, whether it is valid (an oracle written apart from the server's), and its dt."""
    op = rng.choice([*OPS, *OPS, "stop", "", "ADVANCE", None, 3])
    message: dict = {"op": op} if rng.random() > 0.05 else {}
    if op == "advance" or rng.random() < 0.1:
        message["dt"] = rng.choice([0.0, 0.002, 0.01, 0.01, -0.001, 10.5, True, "0.01", None, [0.01],
                                    _random_value(rng)])
    if op == "command" or rng.random() < 0.1:
        names = [rng.choice(actuators + ["M9", "", "joint?"]) for _ in range(rng.randint(0, 3))]
        message["goals"] = ({n: rng.choice([0.1, -0.2, 0, float("nan"), "1", None, True, 1e400]) for n in names}
                            if rng.random() > 0.1 else _random_value(rng))
    if rng.random() < 0.05:
        message[rng.choice(["speed", "reply_to", "op2"])] = 1
    body = json.dumps(message).encode()  # NaN and Infinity go out as JSON can't take them
    fields = {k for k in message if k != "op"}
    valid = isinstance(op, str) and op in OPS and "op" in message and fields == OPS[op]
    if valid and op == "advance":
        dt = message["dt"]
        valid = type(dt) in (int, float) and 0 <= dt <= 10
    if valid and op == "command":
        goals = message["goals"]
        valid = (isinstance(goals, dict) and bool(goals) and all(n in actuators for n in goals)
                 and all(type(v) in (int, float) and abs(v) < float("inf") and v == v for v in goals.values()))
    return body, valid, float(message["dt"]) if valid and op == "advance" else 0.0


def _garbage(rng: random.Random) -> bytes:
    return rng.choice([
        lambda: rng.randbytes(rng.randint(0, 200)),
        lambda: b'{"op": "state\xff"}',
        lambda: b"[" * 50_000,
        lambda: b'{"a":' * 10_000,
        lambda: b"x" * 200_000 if rng.random() < 0.05 else b"",
        lambda: b'{"op": "advance", "dt": NaN}',
        lambda: b'{"op": "advance", "dt": ' + b"9" * 5000 + b"}",
        lambda: json.dumps(_random_value(rng)).encode(),
        lambda: b'{"op": "state"}{"op": "state"}',
        lambda: b"\xef\xbb\xbf{}",
    ])()


def test_the_robot_server_survives_10000_random_messages(broker, twin, clean_env, caplog):
    caplog.set_level(logging.WARNING, logger="cotwin.broker")
    secret = uuid.uuid4().hex
    clean_env.setenv("COTWIN_ROBOT_SECRET", secret)
    queue = f"cotwin.test.fuzz.{uuid.uuid4().hex[:8]}"
    server = RobotServer(simulated(twin), queue)
    thread = serve_in_thread(server)
    actuators = sorted(server.endpoint.actuator_names())
    fuzzer = connect("amqp://127.0.0.1/%2F", "cotwin test fuzzer")
    channel = fuzzer.channel()
    mine = channel.queue_declare("", exclusive=True).method.queue
    rng = random.Random(20240610)
    expected: dict[str, tuple[bool, str]] = {}  # correlation id -> (should be accepted, kind)
    accepted_dt = 0.0
    sent = 0
    t0 = time.perf_counter()
    last_signed = None
    answerable = 0
    for i in range(10_000):
        cid = f"fuzz-{i}"
        roll = rng.random()
        headers: object = None
        if roll < 0.6:  # from someone holding the secret: the body's checks are what is tested
            body, valid, dt = _structured(rng, actuators) if rng.random() < 0.75 else (_garbage(rng), False, 0.0)
            headers = request_headers(secret.encode(), queue, cid, mine, body)
            reply_to, kind = mine, "signed"
            last_signed = (body, headers, cid)
        else:  # from a stranger: any properties
            valid, dt = False, 0.0
            body = _garbage(rng) if rng.random() < 0.5 else _structured(rng, actuators)[0]
            reply_to = rng.choice([mine, mine, mine, None, queue, "amq.gen-nobody", "cotwin.fmi_digital_twin_dt.x"])
            headers = rng.choice([None, {}, {"cotwin-mac": "00" * 32, "cotwin-sent": repr(time.time())},
                                  {"cotwin-mac": 5, "cotwin-sent": "nan"}, {"cotwin-mac": {"x": [1, b"\xff"]}},
                                  "replay"])
            kind = "stranger"
            if headers == "replay" and last_signed is not None:  # a signed request sent again
                body, headers, cid = last_signed
                reply_to, kind = mine, "replay"
            elif headers == "replay":
                headers = None
            if rng.random() < 0.1:
                cid = rng.choice([None, "", "x" * 200])
        props = pika.BasicProperties(reply_to=reply_to, correlation_id=cid, headers=headers)
        channel.basic_publish("", queue, body, props)
        sent += 1
        if reply_to == mine and isinstance(cid, str) and 0 < len(cid) <= 128:
            answerable += 1
            if kind == "replay":
                expected[cid + "#replay"] = (False, kind)
            else:
                expected[cid] = (valid, kind)
                accepted_dt += dt
        if i % 500 == 0:
            fuzzer.process_data_events(0)
    replies: dict[str, list[dict]] = {}

    def on_reply(ch, method, props, body):
        replies.setdefault(props.correlation_id, []).append(json.loads(body))

    channel.basic_consume(mine, on_reply, auto_ack=True)
    deadline = time.monotonic() + 120
    while sum(len(v) for v in replies.values()) < answerable and time.monotonic() < deadline and thread.is_alive():
        fuzzer.process_data_events(0.1)
    seconds = time.perf_counter() - t0
    fuzzer.close()

    silent = wrongly_refused = 0
    for cid, (valid, kind) in expected.items():
        got = replies.get(cid.removesuffix("#replay"), [])
        reply = got[-1] if kind == "replay" and len(got) > 1 else (got[0] if got else None)
        assert reply is not None, f"no reply to {cid} ({kind})"
        if reply["ok"] and not valid:
            silent += 1
        if not reply["ok"] and valid:
            wrongly_refused += 1
    tracebacks = len([r for r in caplog.records if r.exc_info])
    client = BrokerEndpoint(twin.models.tree, queue, timeout=10)  # still serving, and nothing moved it silently
    state = client.call({"op": "state"})
    client.close()
    server.stop()
    thread.join(5)
    print(f"\nfuzz: {sent} messages in {seconds:.1f} s ({sent / seconds:.0f}/s); {len(expected)} answerable, "
          f"{sum(1 for v, k in expected.values() if v)} valid; server: {server.requests} authenticated, "
          f"{server.refused} refused, {server.dropped} dropped; crashes 0, tracebacks {tracebacks}, "
          f"internal errors {server.internal_errors}, silent acceptances {silent}, wrongly refused {wrongly_refused}")
    assert silent == 0 and wrongly_refused == 0 and tracebacks == 0 and server.internal_errors == 0
    assert server.requests + server.refused + server.dropped == sent + 2  # and the last client's describe, state
    assert state["time"] == pytest.approx(accepted_dt, abs=1e-6)


# ---- faults --------------------------------------------------------------------------------------

def test_a_broker_closing_the_link_mid_run_is_a_clear_error_with_the_rows_kept(broker, twin, clean_env, tmp_path):
    clean_env.setenv("COTWIN_ROBOT_SECRET", uuid.uuid4().hex)
    queue = f"cotwin.test.{uuid.uuid4().hex[:8]}"
    server = RobotServer(simulated(twin), queue)
    thread = serve_in_thread(server)
    twin.spec.endpoint, twin.spec.queue = "broker", queue
    try:
        run_twin(twin, tmp_path, end=1.0, plot=False)  # a previous good result
        before = (tmp_path / "outputs.csv").read_bytes()
        cut = AtRow(10, lambda: close_connection(f"cotwin robot client {queue}"))
        text = _error(lambda: run_twin(twin, tmp_path, end=5.0, plot=False, observers=[cut]))
    finally:
        server.stop()
        thread.join(5)
    assert f"the link to the robot on queue '{queue}' at amqp://127.0.0.1:5672/%2F was lost during" in text
    assert "ConnectionClosedByBroker" in text and "outputs.partial.csv" in text
    assert (tmp_path / "outputs.csv").read_bytes() == before
    assert len(rows(tmp_path / "outputs.partial.csv")) == 11  # the initial row and ten steps


def test_a_robot_server_killed_mid_run_is_a_clear_error_with_the_rows_kept(broker, twin, clean_env, tmp_path):
    secret = uuid.uuid4().hex
    clean_env.setenv("COTWIN_ROBOT_SECRET", secret)
    queue = f"cotwin.test.{uuid.uuid4().hex[:8]}"
    robot = serve_in_process(queue, "amqp://127.0.0.1:5672/%2F", {"COTWIN_ROBOT_SECRET": secret})
    twin.spec.endpoint, twin.spec.queue = "broker", queue
    try:
        kill = AtRow(10, lambda: (robot.kill(), robot.wait(10), time.sleep(0.3)))
        start = time.monotonic()
        text = _error(lambda: run_twin(twin, tmp_path, end=5.0, plot=False, observers=[kill]))
        assert time.monotonic() - start < 15  # told at once, not after the reply timeout
    finally:
        robot.kill()
        robot.communicate(timeout=10)
    assert (f"no robot server is serving queue '{queue}'" in text or "went away while answering" in text), text
    assert "outputs.partial.csv" in text
    assert len(rows(tmp_path / "outputs.partial.csv")) == 11


GARBAGE = [
    (b"not json", "sent an invalid reply to describe: not JSON"),
    (b'{"ok": true, "actuators": "M1", "sensors": []}', "'actuators' must be a list of names"),
    (b'{"ok": true, "actuators": ["M1"], "sensors": [], "extra": 1}', "expected exactly ok, actuators, sensors"),
    (b'\xff\xfe', "not UTF-8"),
    (b'{"ok": 1}', "'ok' must be true or false"),
]


def test_a_garbage_reply_from_the_robot_server_is_a_clear_error(broker, clean_env):
    """A server holding the secret but answering garbage (a broken robot server): named, never taken."""
    secret = uuid.uuid4().hex
    clean_env.setenv("COTWIN_ROBOT_SECRET", secret)
    queue = f"cotwin.test.{uuid.uuid4().hex[:8]}"
    connection = connect("amqp://127.0.0.1/%2F", "cotwin test broken server")
    channel = connection.channel()
    channel.queue_declare(queue, exclusive=True)
    answers = iter(GARBAGE)

    def answer(ch, method, props, body):
        out = next(answers)[0]
        ch.basic_publish("", props.reply_to, out, pika.BasicProperties(
            correlation_id=props.correlation_id, headers=reply_headers(secret.encode(), queue, props.correlation_id, out)))

    channel.basic_consume(queue, answer, auto_ack=True)
    stop = threading.Event()
    pump = threading.Thread(target=lambda: [connection.process_data_events(0.05) for _ in iter(stop.is_set, True)],
                            daemon=True)
    pump.start()
    try:
        for _, expected in GARBAGE:
            text = _error(lambda: BrokerEndpoint(None, queue, timeout=5))
            assert expected in text and f"the robot on queue '{queue}'" in text, text
    finally:
        stop.set()
        pump.join(5)
        connection.close()


class Hasty(SimulatedEndpoint):
    """A broken robot: after a few advances its clock runs twice as fast as asked."""

    def __init__(self, simulator):
        super().__init__(simulator)
        self.advances = 0

    def advance(self, dt: float) -> None:
        self.advances += 1
        super().advance(dt * 2 if self.advances > 5 else dt)


def test_a_robot_whose_time_runs_off_ends_the_run_clearly_with_the_rows_kept(broker, twin, clean_env, tmp_path):
    clean_env.setenv("COTWIN_ROBOT_SECRET", uuid.uuid4().hex)
    server = RobotServer(Hasty(PlatformSimulator(twin.models.tree, twin.models.scene)), f"cotwin.test.{uuid.uuid4().hex[:8]}")
    thread = serve_in_thread(server)
    twin.spec.endpoint, twin.spec.queue = "broker", server.queue
    try:
        text = _error(lambda: run_twin(twin, tmp_path, end=2.0, plot=False))
    finally:
        server.stop()
        thread.join(5)
    assert "sent an invalid reply to advance: the robot's time went from 0.5 s to 0.7 s (expected 0.6 s" in text
    assert len(rows(tmp_path / "outputs.partial.csv")) >= 5


def test_the_robot_server_reconnects_when_the_broker_drops_it(broker, twin, clean_env):
    clean_env.setenv("COTWIN_ROBOT_SECRET", uuid.uuid4().hex)
    server = RobotServer(simulated(twin), f"cotwin.test.{uuid.uuid4().hex[:8]}")
    thread = serve_in_thread(server)
    try:
        assert close_connection(f"cotwin robot server {server.queue}")
        deadline = time.monotonic() + 10
        while server.reconnects == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.reconnects == 1 and server.connected.wait(10) and thread.is_alive()  # back on its queue
        client = BrokerEndpoint(twin.models.tree, server.queue, timeout=5)
        assert client.call({"op": "state"})["ok"]
        client.close()
    finally:
        server.stop()
        thread.join(5)
