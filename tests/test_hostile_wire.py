"""Messages from the wire as a hostile peer sends them: one JSON policy for every path (cotwin.safejson),
echoes on `from_cosim` that no twin sent, and a publisher thread of the page that must survive them or
say that it stopped. The broker tests use the real RabbitMQ on 127.0.0.1 on exchanges of their own."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
import uuid
from dataclasses import replace
from pathlib import Path

import pytest

from cotwin import safejson
from cotwin.twin.assembly.rabbitmq import READY, EchoClock, echo_message, parse_echo

ROOT = Path(__file__).resolve().parents[1]
BROKER = "amqp://127.0.0.1:5672/%2F"

HOSTILE = [
    (b'{"simstep": ' + b"1" * 400 + b"}", "a number of 400 digits"),
    (b"[" * 100_000, "nested too deeply"),
    (b"[" * 33 + b"]" * 33, "nested too deeply"),
    (b'{"a": [1e999]}', "beyond the range of a double"),
    (b'{"a": ' + b"1" * 300 + b'.5}', "a number of 302 characters"),
    (b'{"a": NaN}', "NaN is not a JSON number"),
    (b'{"a": -Infinity}', "-Infinity is not a JSON number"),
    (b'{"a": 1, "a": 2}', "the key 'a' appears twice"),
    (b'{"a": "\\ud800"}', "lone surrogate"),
    (b'{"\\udfff": 1}', "lone surrogate"),
    (b"\xff\xfe{}", "not UTF-8 (byte 0xff at 0)"),
    (b'{"a": ', "not JSON: Expecting value at line 1 column 7"),
    (b"x" * 2000, "2000 bytes, more than the 1024 accepted"),
]


@pytest.mark.parametrize("body, why", HOSTILE)
def test_one_json_policy_refuses_each_hostile_message_saying_why(body, why):
    with pytest.raises(safejson.Refused, match=why.replace("(", r"\(").replace(")", r"\)")):
        safejson.loads(body, 1024 if len(body) == 2000 else 1 << 20)


def test_the_json_policy_takes_what_cotwin_sends():
    message = {"plan": [{"time": 0.5, "event": "move", "args": {"x": -3, "y": 2.5e-7, "name": "é😀"}}],
               "big": 1.7976931348623157e308, "int": -(2 ** 63), "ok": [True, False, None]}
    assert safejson.loads(json.dumps(message).encode(), 1 << 16) == message
    assert safejson.loads("[" * 32 + "]" * 32, 100) is not None  # MAX_DEPTH itself
    assert safejson.loads(b'"\\ud83d\\ude00"', 100) == "😀"  # an escaped pair is one character
    with pytest.raises(safejson.Refused, match="expected a JSON object, got a list"):
        safejson.loads_object(b"[]", 100)


# ---- echoes ---------------------------------------------------------------------------------------

def _echo(sim: float) -> bytes:
    return json.dumps(echo_message({"q0": 0.1}, sim, 0.0)).encode()


def test_echoes_claim_only_a_time_a_twin_could_have_reached():
    clock = EchoClock(maxage=1.0)
    clock.take(_echo(0.5), now=100.0)
    assert clock.sim is None and clock.refused == 1  # a time before the twin said it was ready
    clock.take(json.dumps(READY).encode(), now=100.0)
    assert clock.ready_at == 100.0
    clock.take(_echo(0.1), now=100.2)
    assert clock.sim == pytest.approx(0.1)
    for forged in (_echo(1e6), b'{"simstep": "' + b"9" * 400 + b'"}', b'{"simstep": ' + b"1" * 400 + b"}",
                   b"[" * 100_000, b'{"simstep": "1e308"}', b'{"simstep": "-5"}', b'{"simstep": true}'):
        clock.take(forged, now=100.5)
    assert clock.sim == pytest.approx(0.1) and clock.refused == 8
    clock.take(_echo(0.05), now=100.6)  # back in time
    assert clock.sim == pytest.approx(0.1) and clock.refused == 9
    clock.take(_echo(5.0), now=103.0)  # 3 s after ready: at most 3 + maxage + the slack
    assert clock.sim == pytest.approx(5.0)
    assert parse_echo(json.dumps(READY).encode()) == (True, None)
    assert parse_echo(b'{"internal_message": "waiting for input data for simulation"}') == (False, None)


class FakeTwin:
    """The twin's side of the exchange: says it is ready and echoes, as a test (or an attacker) chooses."""

    def __init__(self, exchange: str):
        from cotwin.mapping.amqp import connect

        self.exchange = exchange
        self.connection = connect(BROKER, "cotwin test fake twin")
        self.channel = self.connection.channel()
        self.channel.exchange_declare(exchange, exchange_type="direct", durable=False, auto_delete=False)
        self.inbox = self.channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
        self.channel.queue_bind(self.inbox, exchange, routing_key="data.to_cosim")

    def commanded(self) -> bool:
        """A publisher has sent a command (so it heard the ready message)."""
        return self.channel.basic_get(self.inbox, auto_ack=True)[2] is not None

    def send(self, body: bytes | dict) -> None:
        self.channel.basic_publish(self.exchange, "data.from_cosim",
                                   body if isinstance(body, bytes) else json.dumps(body).encode())

    def close(self) -> None:
        self.channel.exchange_delete(self.exchange)
        self.connection.close()


def _live(exchange: str):
    from cotwin.twin.assembly.run import load

    system = load(ROOT / "examples" / "ur5e" / "live.toml")
    system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=exchange)
    system.spec.deviation = replace(system.spec.deviation, exchange=exchange + ".events")
    return system


def test_a_flood_of_forged_echoes_does_not_end_cotwin_publish(broker):
    from cotwin.twin.project import RabbitMQSettings
    from cotwin.twin.services.publisher import Publisher, idle_values
    from cotwin.twin.assembly.rabbitmq import port_types
    from cotwin.twin.assembly.scenario import read_scenario

    exchange = f"cotwin_forged_{uuid.uuid4().hex[:8]}"
    system = _live(exchange)
    program = system.models.program
    commands = read_scenario(ROOT / "examples" / "ur5e" / "plan.csv", program)
    publisher = Publisher(RabbitMQSettings(exchange), commands, idle_values(port_types(program, system.source_ports)),
                          period=0.1, end=20.0, silence=3.0)
    stop = threading.Event()
    runner = threading.Thread(target=publisher.run, args=(stop,), daemon=True)
    twin = FakeTwin(exchange)
    try:
        runner.start()
        assert publisher.ready.wait(10)
        twin.send(READY)
        started = time.monotonic()
        sim = 0.0
        while time.monotonic() - started < 2.0:  # the real twin echoes its time, a forger claims the end
            sim += 0.1
            twin.send(_echo(sim))
            for forged in (_echo(20.0), _echo(1e9), b'{"simstep": ' + b"1" * 400 + b"}"):
                twin.send(forged)
            time.sleep(0.1)
        time.sleep(0.3)
        assert runner.is_alive(), f"the publisher stopped ({publisher.ended}) at forged echoes"
        assert publisher.clock.sim == pytest.approx(sim, abs=0.3)
        assert publisher.clock.refused >= 3 * 15
    finally:
        stop.set()
        runner.join(10)
        twin.close()
    assert publisher.ended == "stopped"


def test_cotwin_publish_says_when_the_twin_fell_silent_before_the_end(broker, tmp_path):
    exchange = f"cotwin_silent_{uuid.uuid4().hex[:8]}"
    twin = FakeTwin(exchange)
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "publish", str(ROOT / "examples" / "ur5e" / "live.toml"),
                             "--plan", str(ROOT / "examples" / "ur5e" / "plan.csv"), "--exchange", exchange,
                             "--period", "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None and not twin.commanded():
            twin.send(READY)  # until the publisher is bound and hears it
            time.sleep(0.2)
        for _ in range(10):  # the twin echoes once, then falls silent while a forger claims the end
            twin.send(_echo(0.1))
            twin.send(_echo(1e9))
            time.sleep(0.05)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        twin.close()
    assert proc.returncode == 1, (out, err)
    assert "fell silent" in err and "after t = 0.1 s" in err and "never sent" in err and "Traceback" not in err
    assert "echo(es) refused" in out


def _request(url: str, body: dict | None = None) -> tuple[int, dict]:
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(url, data, {"Content-Type": "application/json"} if data else {})
    try:
        with urllib.request.urlopen(request, timeout=20) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


def test_the_pages_publisher_survives_hostile_echoes_and_says_when_it_stopped(broker):
    from cotwin.twin.services.dashboard import Dashboard

    exchange = f"cotwin_echo_{uuid.uuid4().hex[:8]}"
    command = {"event": "moveDiscreteCommand",
               "values": {"MovementArgs_target_X": 1, "MovementArgs_target_Y": 2, "MovementArgs_target_Z": 0}}
    twin = FakeTwin(exchange)
    try:
        with Dashboard(_live(exchange), port=0, mode="twin") as dash:
            twin.send(READY)
            for body in (b'{"simstep": ' + b"1" * 400 + b"}", b"[" * 100_000, b'{"simstep": 1, "simstep": 2}',
                         b"\xff", _echo(1e9)):
                twin.send(body)
            deadline = time.monotonic() + 10
            while dash.publisher.echoes.refused < 5 and time.monotonic() < deadline:
                time.sleep(0.05)
            code, status = _request(dash.url + "api/status")
            assert code == 200 and status["broker"]["running"] and status["broker"]["error"] is None, status
            assert status["broker"]["echoes_refused"] == 5 and status["broker"]["twin_ready"]
            code, answer = _request(dash.url + "api/command", command)
            assert code == 202 and "queued" in answer  # accepted: the stand-in twin never applies it
            # whatever stops the link thread, the page says so and refuses commands instead of queueing them
            dash.publisher.echoes.take = None  # a bug: calling it raises in the link thread
            twin.send(_echo(0.1))
            deadline = time.monotonic() + 10
            while not dash.publisher.stopped and time.monotonic() < deadline:
                time.sleep(0.05)
            code, status = _request(dash.url + "api/status")
            assert not status["broker"]["running"] and "TypeError" in status["broker"]["error"], status
            code, answer = _request(dash.url + "api/command", command)
            assert code == 503 and "has stopped" in answer["error"] and "queued" not in answer
    finally:
        twin.close()
