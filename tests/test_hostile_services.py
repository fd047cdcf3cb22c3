"""The twin's services as a hostile client meets them: the dashboard's HTTP and websocket endpoints,
the history store behind it, the what-if service and the command stream on the broker. Each test is
one class of attack against the real servers on 127.0.0.1 and the real RabbitMQ; none may end in a
500, a traceback, a hang, a file created by a reader, or a log or memory that grows without bound."""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
import uuid
from dataclasses import replace
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pika
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly import rabbitmq
from cotwin.twin.services.dashboard import Dashboard
from cotwin.twin.services.dashboard.app import MAX_BODY, MAX_CONNECTIONS, MAX_WHATIFS
from cotwin.twin.services.history import STALE_AFTER, HistoryRecorder, list_runs, read_run
from cotwin.twin.assembly.run import load, run_twin

ROOT = Path(__file__).resolve().parents[1]
BROKER = "amqp://127.0.0.1:5672/%2F"
MOVE = "moveDiscreteCommand"
JSON_HEAD = "Host: 127.0.0.1\nContent-Type: application/json\n"


@pytest.fixture(scope="module")
def live(broker):
    """The live UR5e twin's system (commands from RabbitMQ) on an exchange of its own (without RabbitMQ
    the tests using it skip, saying so, instead of failing to connect)."""
    system = load(ROOT / "examples" / "ur5e" / "live.toml")
    name = f"cotwin_hostile_{uuid.uuid4().hex[:8]}"
    system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=name)
    system.spec.deviation = replace(system.spec.deviation, exchange=name + ".events")
    return system


def _request(url: str, body: bytes | None = None, method: str = "GET", timeout: float = 20):
    request = urllib.request.Request(url, body, {"Content-Type": "application/json"} if body is not None else {},
                                     method=method if body is None else "POST")
    try:
        with urllib.request.urlopen(request, timeout=timeout) as r:
            return r.status, _decoded(r.read())
    except urllib.error.HTTPError as err:
        return err.code, _decoded(err.read())


def _decoded(body: bytes):
    """JSON, as the app answers; uvicorn's own refusals (503 when too many connections) are text."""
    try:
        return json.loads(body or b"null")
    except ValueError:
        return body.decode("utf-8", "replace")


def _post(url: str, body) -> tuple[int, dict]:
    return _request(url, body if isinstance(body, bytes) else json.dumps(body).encode())


def _raw(port: int, head: str, body: bytes = b"", wait: float = 10.0) -> tuple[int, bytes, float]:
    """Send a raw HTTP request (headers as given, then `body`) and read the answer: (status, body, seconds)."""
    started = time.monotonic()
    with socket.create_connection(("127.0.0.1", port), timeout=wait) as sock:
        sock.sendall(head.replace("\n", "\r\n").encode() + b"\r\n" + body)
        answer = b""
        try:
            while b"\r\n\r\n" not in answer or len(answer.split(b"\r\n\r\n", 1)[1]) == 0:
                chunk = sock.recv(65536)
                if not chunk:
                    break
                answer += chunk
        except (ConnectionResetError, socket.timeout):
            pass
    status = int(answer.split(b" ", 2)[1]) if answer.startswith(b"HTTP/") else 0
    return status, answer.split(b"\r\n\r\n", 1)[-1], time.monotonic() - started


# ---- bodies -----------------------------------------------------------------------------------------

def test_request_bodies_are_bounded_plain_json_objects_or_refused_naming_the_problem(live, capfd):
    with Dashboard(live, port=0, mode="twin", whatif_url=BROKER) as dash:
        url = dash.url + "api/command"
        # a 100 MB body announced: refused before it is read
        head = f"POST /api/command HTTP/1.1\n{JSON_HEAD}Content-Length: {100 << 20}\n"
        status, body, seconds = _raw(dash.port, head, b"{" * 4096)
        assert status == 413 and b"larger than" in body and seconds < 5
        # sent in chunks without a length: cut off at the limit
        chunk = b"a" * 65536
        chunks = b"".join(b"%x\r\n%s\r\n" % (len(chunk), chunk) for _ in range(MAX_BODY // len(chunk) + 2))
        status, body, _ = _raw(dash.port, f"POST /api/command HTTP/1.1\n{JSON_HEAD}Transfer-Encoding: chunked\n", chunks)
        assert status == 413
        # a length that lies (more announced than sent): refused when the body does not come
        dash.body_seconds = 0.5
        status, body, seconds = _raw(dash.port, f"POST /api/command HTTP/1.1\n{JSON_HEAD}Content-Length: 100\n", b"{}")
        assert status == 408 and b"did not arrive" in body and seconds < 5
        for sent, why in ((b"{\"event\": ", "not JSON: Expecting value at line 1 column 11"),
                          (b"\xff\xfe", "not UTF-8"),
                          (b"[" * 100_000, "nested too deeply"),
                          (json.dumps({"event": MOVE, "values": {"MovementArgs_target_X": float("nan")}}).encode(),
                           "NaN is not a JSON number"),
                          (b'{"event": "x", "values": {"a": Infinity}}', "Infinity is not a JSON number"),
                          (json.dumps({"event": MOVE, "values": {}, "priority": 9}).encode(), "unknown key 'priority'"),
                          (json.dumps({"event": 7}).encode(), "'event' must be a name"),
                          (json.dumps({"event": MOVE, "values": [1, 2]}).encode(), "'values' must be an object"),
                          (b"[]", "expected {\"event\"")):
            code, answer = _post(url, sent)
            assert code == 400 and why in answer["error"], (sent[:40], answer)
        code, answer = _post(dash.url + "api/whatif", {"plan": [], "horizon": 5, "speed": 2})
        assert code == 422 and "unknown key 'speed'" in answer["error"]
        code, answer = _post(dash.url + "api/whatif", b'{"plan": [{"time": NaN, "event": "x"}]}')
        assert code == 400 and "NaN" in answer["error"]
        assert _request(dash.url + "api/status")[0] == 200  # still serving
        capfd.readouterr()
        for _ in range(100):  # not HTTP at all: the server's warning about each is capped
            assert _raw(dash.port, "GARBAGE\n")[0] == 400
        assert capfd.readouterr().err.count("Invalid HTTP request") <= 20
        # connections held open without finishing a request: bounded, and served again once they go
        held = [socket.create_connection(("127.0.0.1", dash.port)) for _ in range(MAX_CONNECTIONS + 10)]
        for sock in held:
            sock.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        try:
            assert _request(dash.url + "api/status")[0] == 503
        finally:
            for sock in held:
                sock.close()
        deadline = time.monotonic() + 10
        while _request(dash.url + "api/status")[0] != 200 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _request(dash.url + "api/status")[0] == 200


def test_another_site_in_the_browser_cannot_command_the_twin_or_read_its_stream(live):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect as ws_connect

    good = {"event": MOVE, "values": {"MovementArgs_target_X": 1, "MovementArgs_target_Y": 2, "MovementArgs_target_Z": 0}}
    body = json.dumps(good).encode()
    with Dashboard(live, port=0, mode="twin", whatif_url=BROKER) as dash:
        here = f"127.0.0.1:{dash.port}"
        for headers, code, why in (({"Content-Type": "text/plain"}, 415, "must be sent as application/json"),
                                   ({}, 415, "not 'application/x-www-form-urlencoded'"),
                                   ({"Content-Type": "application/json", "Origin": "http://evil.example"}, 403,
                                    "Origin 'http://evil.example' is not this server"),
                                   ({"Content-Type": "application/json", "Host": f"rebound.example:{dash.port}",
                                     "Origin": f"http://rebound.example:{dash.port}"}, 403,
                                    "Host 'rebound.example"),
                                   ({"Content-Type": "application/json", "Host": "[::1"}, 403, "Host '[::1' is not an address"),
                                   ({"Content-Type": "application/json", "Origin": f"http://{here}"}, 200, None)):
            for path in ("api/command", "api/whatif"):
                request = urllib.request.Request(dash.url + path, body, headers)
                try:
                    with urllib.request.urlopen(request, timeout=10) as r:
                        got, answer = r.status, json.loads(r.read())
                except urllib.error.HTTPError as err:
                    got, answer = err.code, json.loads(err.read())
                if why is None:  # the page's own request
                    assert got == (202 if path == "api/command" else 422), answer  # accepted: no twin to apply it yet
                else:
                    assert got == code and why in answer["error"], (path, headers, answer)
        assert len([m for _, m in dash.publisher.sent]) == 0 and dash.publisher._pending.qsize() == 1
        with ws_connect(f"ws://{here}/ws", origin="http://evil.example", open_timeout=10) as ws, \
                pytest.raises(ConnectionClosed) as closed:
            ws.recv(10)
        assert closed.value.rcvd.code == 1008 and "evil.example" in closed.value.rcvd.reason
        with ws_connect(f"ws://{here}/ws", origin=f"http://{here}", open_timeout=10) as ws:
            assert json.loads(ws.recv(10))["type"] == "hello"


# ---- the history store ------------------------------------------------------------------------------

def _recorded(path: Path) -> tuple[str, int]:
    url = f"sqlite:///{path}"
    recorder = HistoryRecorder(url, "p.toml", "twin", 0.1, "jacobi", {"dt": ["{mapping}.mapping.q0"]}, batch_seconds=0.05)
    for k in range(5):
        recorder.record_sample("dt", k, 0.1 * k, [0.01 * k])
    recorder.close()
    return url, recorder.run_id


def test_history_urls_out_of_range_are_refused_and_readers_never_create_a_store(tmp_path):
    url, run_id = _recorded(tmp_path / "history.sqlite")
    with Dashboard(None, port=0, mode="history", history_url=url) as dash:
        assert _request(dash.url + f"api/history/{run_id}")[0] == 200
        for path, code, why in (("-1", 400, "not a run id"), ("abc", 400, "not a run id"), ("1.5", 400, "not a run id"),
                                ("%F0%9F%98%80", 400, "not a run id"), ("0", 404, "no run 0"),
                                ("9" * 25, 404, "no run 9999"), (str((1 << 63) - 1), 404, "no run"),
                                (str(1 << 63), 404, "no run"), ("7", 404, "no run 7")):
            code_got, answer = _request(dash.url + f"api/history/{path}")
            assert (code_got, why in answer["error"]) == (code, True), (path, answer)
        import sqlite3

        with sqlite3.connect(tmp_path / "history.sqlite") as db:  # a store damaged by something else
            db.execute("INSERT INTO runs (project, kind, started, status, step, algorithm, columns) "
                       "VALUES ('p', 'twin', 0, 'done', 0.1, 'jacobi', '[1, 2]')")
            for _ in range(2):
                db.execute("INSERT INTO runs (project, kind, started, status, step, algorithm, columns) "
                           "VALUES ('p', 'twin', 0, 'done', 0.1, 'jacobi', '{\"dt\": [\"{mapping}.mapping.q0\"]}')")
            db.execute("INSERT INTO samples VALUES (3, 'dt', 0, 0.0, 0.0, '[]')")  # narrower than its columns
            db.execute("INSERT INTO samples VALUES (4, 'dt', 1, 0.1, 0.0, '[1.0, ')")  # not JSON
        for damaged in (2, 3, 4):
            code, answer = _request(dash.url + f"api/history/{damaged}")
            assert code == 404 and "damaged" in answer["error"], answer
        assert _request(dash.url + "api/history")[0] == 200
    missing = tmp_path / "nowhere" / "history.sqlite"
    other = tmp_path / "typo.sqlite"
    with Dashboard(None, port=0, mode="history", history_url=f"sqlite:///{other}") as dash:
        code, answer = _request(dash.url + "api/history")
        assert code == 200 and answer["runs"] == [] and "no history database" in answer["error"]
        code, answer = _request(dash.url + "api/history/1")
        assert code == 404 and "no history database" in answer["error"]
    for reader in (lambda u: list_runs(u), lambda u: read_run(u, 1)):
        with pytest.raises(CotwinError, match="no history database"):
            reader(f"sqlite:///{missing}")
    assert not other.exists() and not missing.parent.exists()  # nothing created by reading
    garbage = tmp_path / "garbage.sqlite"
    garbage.write_bytes(b"this is not a database\n" * 100)
    with pytest.raises(CotwinError, match="cannot read the history database"):
        list_runs(f"sqlite:///{garbage}")
    assert garbage.read_bytes() == b"this is not a database\n" * 100


RECORDER = """
import sys, time
from cotwin.twin.services.history import HistoryRecorder
r = HistoryRecorder(sys.argv[1], "p.toml", "twin", 0.1, "jacobi", {"dt": ["{mapping}.mapping.q0"]}, batch_seconds=0.05)
for k in range(3):
    r.record_sample("dt", k, 0.1 * k, [float(k)])
time.sleep(0.5)
print(r.run_id, flush=True)
time.sleep(600)
"""


def test_a_run_whose_twin_was_killed_is_shown_interrupted_not_running(tmp_path):
    url = f"sqlite:///{tmp_path / 'history.sqlite'}"
    proc = subprocess.Popen([sys.executable, "-c", RECORDER, url], stdout=subprocess.PIPE, text=True)
    try:
        run_id = int(proc.stdout.readline())
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()
    [run] = list_runs(url)
    assert (run["id"], run["status"], run["samples"]) == (run_id, "running", 3)  # just now: may be alive
    later = time.time() + STALE_AFTER + 5
    [run] = list_runs(url, now=later)
    assert run["status"] == "interrupted" and "ended without closing it" in run["message"]
    data = read_run(url, run_id, now=later)
    assert data["run"]["status"] == "interrupted" and len(data["samples"]["dt"]) == 3  # the samples are kept


# ---- what-if --------------------------------------------------------------------------------------------

def test_whatif_requests_without_reply_to_are_dropped_and_logged_and_the_count_is_safe(live, caplog):
    from cotwin.mapping.amqp import connect
    from cotwin.twin.services.whatif import WhatIfService

    exchange = f"cotwin_hostile_wi_{uuid.uuid4().hex[:8]}"
    service = WhatIfService(BROKER, exchange, ROOT / "examples" / "ur5e" / "live.toml")
    caplog.set_level(logging.WARNING, "cotwin.whatif")
    try:
        connection = connect(BROKER, "cotwin hostile what-if client")
        channel = connection.channel()
        reply = channel.queue_declare("", exclusive=True).method.queue
        answers = {}
        channel.basic_consume(reply, lambda ch, m, p, body: answers.__setitem__(p.correlation_id, json.loads(
            body, parse_constant=lambda c: pytest.fail(f"{c} in an answer"))), auto_ack=True)
        plan = json.dumps({"plan": [{"time": 1, "event": MOVE}], "horizon": 5}).encode()
        channel.basic_publish(exchange, "twin.whatif", plan, pika.BasicProperties(reply_to="victim", correlation_id="v"))
        for k in range(300):
            channel.basic_publish(exchange, "twin.whatif", plan, pika.BasicProperties(correlation_id=f"void{k}"))
        for cid, body in (("nan", b'{"plan": [{"time": 1, "event": "x"}], "horizon": NaN}'),
                          ("extra", json.dumps({"plan": [1], "sudo": True}).encode())):
            channel.basic_publish(exchange, "twin.whatif", body, pika.BasicProperties(reply_to=reply, correlation_id=cid))
        # a fork that diverged: its answer is still JSON (null where it has NaN)
        service._reply(pika.BasicProperties(reply_to=reply, correlation_id="diverged"),
                       {"trajectory": {"q0": [0.5, float("nan"), float("inf")]}})
        deadline = time.monotonic() + 20
        while len(answers) < 3 and time.monotonic() < deadline:
            connection.process_data_events(time_limit=0.1)
        connection.close()
        assert answers["diverged"] == {"trajectory": {"q0": [0.5, None, None]}}
        assert "NaN is not a JSON number" in answers["nan"]["error"] and "unknown key 'sudo'" in answers["extra"]["error"]
        assert service.dropped == 301 and service.pending == 0 and service.requests.empty()  # nothing forked for them
        logged = [r.getMessage() for r in caplog.records if r.name == "cotwin.whatif"]
        assert any("no reply_to" in m for m in logged) and any("'victim' is not a broker-named" in m for m in logged)
        assert len(logged) <= service.log.burst + 1  # the log is not flooded
        # the pending count, from the broker's thread, the twin's and the pool's at once, never overshoots
        props = pika.BasicProperties(reply_to="amq.gen-nobody", correlation_id="race")
        valid = json.dumps({"plan": [{"time": 1, "event": MOVE}], "horizon": 1}).encode()
        seen = []

        def hammer():
            for _ in range(400):
                service._on_request(None, None, props, valid)
                seen.append(service.pending)

        def drain():
            for _ in range(3000):
                try:
                    service.requests.get_nowait()
                    service._release()
                except Exception:  # noqa: BLE001 - queue.Empty
                    time.sleep(0)

        threads = [threading.Thread(target=hammer) for _ in range(4)] + [threading.Thread(target=drain)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        while not service.requests.empty():
            service.requests.get_nowait()
            service._release()
        assert max(seen) <= service.MAX_PENDING and service.pending == 0
    finally:
        service.close(wait=1)


def test_a_flood_of_whatifs_from_the_page_is_answered_429_not_queued(live, capfd):
    with Dashboard(live, port=0, mode="twin", whatif_url=BROKER) as dash:
        plan = {"plan": [{"time": 0.5, "event": MOVE, "args": {"target_X": 1, "target_Y": 2, "target_Z": 0}}],
                "horizon": 2}
        dash.whatif_timeout = 2.0  # no twin answers on this exchange: the page is told so
        assert _post(dash.url + "api/whatif", plan)[0] == 504
        dash.whatif_timeout = 120.0
        codes = []
        waiting = [threading.Thread(target=lambda: codes.append(_post(dash.url + "api/whatif", plan)[0]))
                   for _ in range(MAX_WHATIFS)]
        for t in waiting:
            t.start()
        deadline = time.monotonic() + 5
        while dash.whatifs < MAX_WHATIFS and time.monotonic() < deadline:
            time.sleep(0.02)
        started = time.monotonic()
        flood = [_post(dash.url + "api/whatif", plan) for _ in range(20)]
        assert {code for code, _ in flood} == {429} and "already running" in flood[0][1]["error"]
        assert time.monotonic() - started < 3  # answered at once, not queued behind the others
        capfd.readouterr()
        stopping = time.monotonic()
    for t in waiting:  # the dashboard stopped: the page's what-ifs end with it, not 120 s later
        t.join(10)
    assert codes == [503] * MAX_WHATIFS and dash.whatifs == 0 and time.monotonic() - stopping < 5
    assert "Exception in ASGI application" not in capfd.readouterr().err


# ---- the command panel ----------------------------------------------------------------------------------

def test_page_commands_are_typed_strictly_bounded_and_refused_once_the_twin_ended(live, monkeypatch):
    with Dashboard(live, port=0, mode="twin") as dash:
        url = dash.url + "api/command"
        good = {"MovementArgs_target_X": 3, "MovementArgs_target_Y": 4, "MovementArgs_target_Z": 1}
        for values, why in (({**good, "MovementArgs_target_X": 1.5}, "MovementArgs_target_X: 1.5 is not an integer"),
                            ({**good, "MovementArgs_target_Y": 2 ** 40}, "MovementArgs_target_Y: 1099511627776 does not fit"),
                            ({**good, "MovementArgs_target_Z": True}, "MovementArgs_target_Z: True is not a number"),
                            ({**good, "MovementArgs_target_Z": "1"}, "MovementArgs_target_Z: '1' is not a number"),
                            ({**good, "speed": 2}, "event moveDiscreteCommand has no argument 'speed'")):
            code, answer = _post(url, {"event": MOVE, "values": values})
            assert code == 422 and why in answer["error"], answer
        code, answer = _post(url, {"event": MOVE, "values": good})
        assert code == 202 and answer["queued"]["MovementArgs_target_X"] == 3 and not answer["twin_ready"]
        assert _request(url + "/" + answer["id"])[1]["status"] == "waiting to be published"
        # no twin takes them: at most MAX_WAITING wait, the rest are told to come back
        codes = [_post(url, {"event": MOVE, "values": good})[0] for _ in range(dash.publisher.MAX_WAITING + 10)]
        assert codes.count(202) == dash.publisher.MAX_WAITING - 1 and set(codes[dash.publisher.MAX_WAITING - 1:]) == {429}
        dash.finish("stopped")
        code, answer = _post(url, {"event": MOVE, "values": good})
        assert code == 409 and "the twin has stopped" in answer["error"]
    # what the panel has sent is remembered within a bound, however long it heartbeats
    from cotwin.twin.services.dashboard.commands import PagePublisher
    from cotwin.twin.assembly.rabbitmq import port_types

    monkeypatch.setattr(PagePublisher, "MAX_SENT", 10)
    types = port_types(live.models.program, live.source_ports)
    panel = PagePublisher(live.spec.rabbitmq, types, [], period=0.0).start()
    panel.twin_ready.set()
    time.sleep(1.0)
    panel.stop()
    assert panel.sent_count > 20 and len(panel.sent) == 10 and panel.error is None


def test_plan_values_take_the_models_literals_and_refuse_others_naming_the_argument(tmp_path):
    from cotwin.dmodel.program import build_program
    from cotwin.robosim.check import check_paths
    from cotwin.twin.services.whatif import plan_from_json

    (tmp_path / "m.rst").write_text("""enumeration Dir { North East South West }
datatype Goal { dir: Dir count: nat fast: boolean }
interface In { event go: Goal }
interface Out { event out: int }
stm M {
	cycleDef cycle == 1
	input context { uses In } output context { uses Out }
	var g: Goal
	initial i
	state A { }
	transition t0 { from i to A }
	transition t1 { from A to A exec condition $go?g action $out!g.count }
	transition t2 { from A to A exec condition not $go }
}
controller C { cycleDef cycle == 1 uses In uses Out sref m = M
	connection C on go to m on go connection m on out to C on out }
module Mod { cycleDef cycle == 1 robotic platform P { uses In uses Out } cref c = C
	connection P on go to c on go (_async) connection c on out to P on out (_async) }
""")
    result = check_paths([tmp_path])
    program = build_program(result.project, "Mod")
    [command] = plan_from_json([{"time": 1, "event": "go", "args": {"dir": "South", "count": 4, "fast": True}}], program)
    assert dict(command.values) == {"go": True, "Goal_dir": 2, "Goal_count": 4, "Goal_fast": True}
    [command] = plan_from_json([{"time": 1, "event": "go", "args": {"dir": 3, "count": 0, "fast": False}}], program)
    assert dict(command.values)["Goal_dir"] == 3
    with pytest.raises(CotwinError, match="plan item 1: event go carries Goal_count, Goal_fast: a command gives every"):
        plan_from_json([{"time": 1, "event": "go", "args": {"dir": 3}}], program)  # never an earlier command's
    for args, why in (({"dir": "Up"}, "argument dir: 'Up' is not a literal of Dir (North, East, South, West"),
                      ({"dir": 4}, "argument dir: 4 is not a literal of Dir"),
                      ({"dir": 1.0}, "argument dir: 1.0 is not an integer"),
                      ({"count": -1}, "argument count: -1 is negative (the input is a nat)"),
                      ({"fast": 1}, "argument fast: 1 is not true or false"),
                      ({"fast": "true"}, "argument fast: 'true' is not true or false")):
        with pytest.raises(CotwinError, match=f"plan item 1: {why}".replace("(", r"\(").replace(")", r"\)")):
            plan_from_json([{"time": 1, "event": "go", "args": args}], program)
    # the page's panel: literals by name (a select), checked before anything is published
    from cotwin.twin.services.dashboard.commands import PagePublisher
    from cotwin.twin.assembly.rabbitmq import port_types

    [go] = program.inputs
    ports = [port for port, _ in go.value_ports]
    panel = PagePublisher(None, port_types(program, ["go", *ports]), [{"name": "go", "values": [{"port": p} for p in ports]}],
                          scalars=dict(go.value_ports))
    message = panel.command("go", {"Goal_dir": "West", "Goal_count": 2, "Goal_fast": False})
    assert (message["Goal_dir"], message["Goal_count"], message["go"]) == (3, 2, True)
    with pytest.raises(ValueError, match="Goal_dir: 'Up' is not a literal of Dir.*Goal_count: -2 is negative"):
        panel.command("go", {"Goal_dir": "Up", "Goal_count": -2, "Goal_fast": False})
    # and the twin's own reader of broker messages: literals by name, refused beyond them, naming the key
    from cotwin.twin.assembly.rabbitmq import parse_message, port_scalars

    types, scalars = port_types(program, ["go", *ports]), port_scalars(program)
    stamp = datetime.now(timezone.utc).isoformat()
    parsed = parse_message(json.dumps({"time": stamp, "go": True, "Goal_dir": "East", "Goal_count": 2.0,
                                       "Goal_fast": True}).encode(), types, scalars)
    assert parsed.values == {"go": True, "Goal_dir": 1, "Goal_count": 2, "Goal_fast": True} and not parsed.dropped
    parsed = parse_message(json.dumps({"time": stamp, "go": True, "Goal_dir": 9, "Goal_count": -1,
                                       "Goal_fast": "yes"}).encode(), types, scalars)
    assert parsed.values == {"go": True} and parsed.dropped == (  # worded as a plan's values are
        "Goal_dir: 9 is not a literal of Dir (North, East, South, West, or their index 0..3)",
        "Goal_count: -1 is negative (the input is a nat)",
        "Goal_fast: 'yes' is not a JSON Boolean")


# ---- a stopped twin ---------------------------------------------------------------------------------------

def test_a_stopped_twin_keeps_its_last_figure_and_state_and_the_streams_stay_bounded(tmp_path, monkeypatch):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect as ws_connect

    from cotwin.twin.services.dashboard import app
    from cotwin.twin.services.dashboard.feed import Ring

    system = load(ROOT / "examples" / "ur5e" / "cotwin.toml")
    with Dashboard(system, port=0, mode="run") as dash:
        dash.feed.events = Ring(2)  # a long run's events, in small
        run_twin(system, tmp_path, end=3.0, observers=[dash.feed], plot=False)
        assert dash.feed.events.count > 2 and len(list(dash.feed.events)) == 2
        dash.finish("stopped")  # already done: the state it ended in stays
        for _ in range(2):
            code, status = _request(dash.url + "api/status")
            assert code == 200 and status["state"] == "done" and status["time"] == pytest.approx(3.0)
        monkeypatch.setattr(app, "MAX_CLIENTS", 1)
        ws_url = dash.url.replace("http", "ws") + "ws"
        with ws_connect(ws_url, open_timeout=10) as ws:  # a page opened afterwards
            hello = json.loads(ws.recv(10))
            with ws_connect(ws_url, open_timeout=10) as extra, pytest.raises(ConnectionClosed) as closed:
                extra.recv(10)
            assert closed.value.rcvd.code == 1013
        assert hello["type"] == "hello" and hello["status"]["state"] == "done" and len(hello["samples"]) >= 2
        assert hello["samples"][-1][0] == pytest.approx(3.0) and hello["sides"] == ["twin"]
        assert len(hello["events"]) == 2 and hello["events_skipped"] == dash.feed.events.count - 2
        assert _request(dash.url + "api/model")[0] == 200


# ---- a flood of bad broker messages ------------------------------------------------------------------------

def test_a_flood_of_bad_broker_messages_is_counted_but_neither_fills_the_log_nor_memory(live, caplog, monkeypatch):
    from cotwin.mapping.amqp import connect
    from cotwin.twin.assembly.rabbitmq import CommandStream, RabbitMQBridge, port_types

    monkeypatch.setattr(rabbitmq, "MAX_QUEUED", 50)
    settings = live.spec.rabbitmq
    types = port_types(live.models.program, live.source_ports)
    bridge = RabbitMQBridge(settings, "cotwin hostile bridge").start()
    stream = CommandStream(types, {MOVE}, bridge.receive, timeout=5)
    stream.t0 = datetime.now(timezone.utc)
    caplog.set_level(logging.WARNING, "cotwin.rabbitmq")
    try:
        connection = connect(settings.url, "cotwin hostile flooder")
        channel = connection.channel()
        future = (stream.t0 + timedelta(days=365)).isoformat()
        bad = [b"{not json\n2026-01-01 CRITICAL forged line", json.dumps({"time": future, "jump": 1}).encode()]
        for k in range(3000):
            channel.basic_publish(settings.exchange, settings.to_cosim, bad[k % 2])
        for k in range(120):  # valid, but for a year from now: they would wait for ever
            channel.basic_publish(settings.exchange, settings.to_cosim, json.dumps({"time": future, MOVE: True}).encode())
        connection.close()
        deadline = time.monotonic() + 30
        while stream.refused_count < 3070 and time.monotonic() < deadline:
            stream._take(bridge.receive(0.2))
    finally:
        bridge.close()
    assert stream.refused_count == 3000 + 70  # every bad one, and the valid ones beyond the queue's bound
    assert len(stream.refused) == rabbitmq.MAX_REFUSED and len(stream.queues[MOVE]) == 50
    assert any("50 values of it already wait" in r for _, r in stream.refused)
    logged = [r.getMessage() for r in caplog.records if r.name == "cotwin.rabbitmq"]
    assert len(logged) <= stream.log.burst and not any("\nforged" in m for m in logged)  # one line each, escaped
    stream.log.close()
    summary = [r.getMessage() for r in caplog.records if r.name == "cotwin.rabbitmq"][-1]
    assert f"{3070 - stream.log.burst} more dropped messages not logged" in summary
    # a flood faster than the twin takes it: what waits for the twin is bounded too
    monkeypatch.setattr(rabbitmq, "MAX_INBOX", 100)
    slow = RabbitMQBridge(settings, "cotwin hostile slow bridge").start()
    try:
        connection = connect(settings.url, "cotwin hostile flooder")
        channel = connection.channel()
        for _ in range(300):
            channel.basic_publish(settings.exchange, settings.to_cosim, bad[0])
        connection.close()
        deadline = time.monotonic() + 20
        while slow.inbox.qsize() + slow.overflowed < 300 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert (slow.inbox.qsize(), slow.overflowed) == (100, 200)
    finally:
        slow.close()
    # what was applied is remembered within a bound too, however long a publisher keeps refreshing
    monkeypatch.setattr(rabbitmq, "MAX_APPLIED", 5)
    quiet = CommandStream(types, {MOVE}, lambda timeout: [], timeout=5)
    quiet.t0 = stream.t0
    quiet._take([rabbitmq.Received(json.dumps({"time": (quiet.t0 + timedelta(seconds=0.01 * k)).isoformat(),
                                               MOVE: k % 2 == 0}).encode(), time.time()) for k in range(40)])
    assert quiet._apply(1.0, 1.0) == {MOVE} and len(quiet.applied) == 5 and quiet.held[MOVE].sim == pytest.approx(0.39)


# ---- the twin's saved state --------------------------------------------------------------------------------

def test_a_saved_state_reads_robosim_values_back_and_holds_no_other_class():
    import pickle

    from cotwin.cosim.state import MAGIC, StateError, pack, unpack
    from cotwin.robosim.values import FrozenRecord, MatrixValue, SeqValue, SetValue, TupleValue, VectorValue

    held = {"goal": VectorValue((0.1, 0.2, 0.3)), "pose": MatrixValue((VectorValue((1.0, 0.0)), VectorValue((0.0, 1.0)))),
            "pair": TupleValue((1, True)), "queue": SeqValue((2, 3)), "seen": SetValue({1, 2}),
            "records": SetValue({FrozenRecord((("x", 1), ("y", 2)))}), "mode": 2, "busy": False}
    back = unpack(pack("Mapping", held), "Mapping")
    assert back == held and all(type(back[k]) is type(v) for k, v in held.items())
    assert type(back["pose"][0]) is VectorValue
    for evil in (pickle.dumps(("Mapping", {"x": __import__("os").getcwd})), pickle.dumps(("Mapping", CotwinError("x")))):
        with pytest.raises(StateError, match="damaged cotwin state"):  # no pickle is read (tests/test_state_format.py)
            unpack(MAGIC + evil, "Mapping")
    with pytest.raises(StateError, match="holds only plain data, not a cotwin.diagnostics.CotwinError"):
        pack("Mapping", CotwinError("x"))


def test_a_request_path_cannot_forge_lines_or_escapes_in_the_refusal_log(tmp_path, caplog):
    """GET /api/history/1%0Afake... wrote the decoded path into the log: a line break (a forged line, e.g. a
    login that never happened) and terminal escapes (ESC [31m) reached whoever reads the log."""
    url, _ = _recorded(tmp_path / "history.sqlite")
    caplog.set_level(logging.WARNING, logger="cotwin.dashboard")
    with Dashboard(None, port=0, mode="history", history_url=url) as dash:
        code, _ = _request(dash.url + "api/history/1%0Adashboard%20login%20of%20admin%1b%5b31m%E2%80%A8")
        assert code == 400
    logged = [r.getMessage() for r in caplog.records if r.name == "cotwin.dashboard"]
    assert logged and all(m.isprintable() for m in logged), logged
    assert any("GET /api/history/1\\ndashboard login of admin\\x1b[31m\\u2028 from 127.0.0.1: 400" in m for m in logged)
