"""Live commands through RabbitMQ, as the RMQ FMU takes them: message parsing, its time semantics, a
publisher like the paper's driving a paced run on the real broker, bad messages, a silent publisher
and a connection closed by the broker."""

from __future__ import annotations

import csv
import json
import subprocess
import threading
import time
import uuid
from dataclasses import replace
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from cotwin.diagnostics import CotwinError
from cotwin.mapping.amqp import connect
from cotwin.pmodel import ik
from cotwin.twin.services.publisher import Publisher, idle_values
from cotwin.twin.assembly.rabbitmq import READY, CommandStream, Received, echo_message, parse_message, parse_time, port_types, read_echo
from cotwin.twin.assembly.run import load, run_twin
from cotwin.twin.assembly.scenario import read_plan

TYPES = {"moveDiscreteCommand": "Boolean", "MovementArgs_target_X": "Integer", "speed": "Real"}
T0 = datetime(2025, 1, 31, 16, 1, 3, tzinfo=timezone.utc)


def msg(dt: float, **values) -> bytes:
    return json.dumps({"time": (T0 + timedelta(seconds=dt)).isoformat(), **values}).encode()


def test_times_are_iso8601_with_a_zone():
    assert parse_time("2025-01-31T16:01:03.066+01:00") == datetime(2025, 1, 31, 15, 1, 3, 66000, tzinfo=timezone.utc)
    assert parse_time("2025-01-31T16:01:03Z") == T0
    assert parse_time("2025-01-31T16:01:03.123456789Z").microsecond == 123456
    for bad in ("2025-01-31T16:01:03", "yesterday", "2025-13-01T00:00:00Z", 17):
        with pytest.raises(ValueError):
            parse_time(bad)


def test_messages_are_typed_or_refused_with_a_reason():
    parsed = parse_message(msg(0, moveDiscreteCommand=True, MovementArgs_target_X=3.9, speed=1, other=2,
                               internal_status="x"), TYPES)
    assert parsed.values == {"moveDiscreteCommand": True, "MovementArgs_target_X": 3, "speed": 1.0}
    assert parsed.dropped == ("unknown key 'other' ignored",)
    parsed = parse_message(msg(0, moveDiscreteCommand=1, speed=0.5), TYPES)  # a wrongly typed value alone
    assert parsed.values == {"speed": 0.5} and "not a JSON Boolean" in parsed.dropped[0]
    for body, reason in [(b"\xff\xfe", "not UTF-8"), (b"{bad", "not JSON"), (b"[1]", "JSON object"),
                         (json.dumps({"speed": 1}).encode(), "no 'time'"), (msg(0, other=1), "no known variable"),
                         (b"[" * 50_000, "nested too deeply"), (msg(0, MovementArgs_target_X=2 ** 40), "no known variable"),
                         (b" " * 70_000, "bytes")]:
        with pytest.raises(ValueError, match=reason):
            parse_message(body, TYPES)


class Feed:
    """Messages handed to the stream as a broker would: whatever has arrived by now."""

    def __init__(self):
        self.items: list[bytes] = []

    def __call__(self, timeout):
        out, self.items = [Received(b, 0.0) for b in self.items], []
        if not out and timeout:
            time.sleep(min(timeout, 0.01))
        return out


def test_publishers_read_the_echo_and_the_ready_message_and_ignore_garbage():
    """What a publisher (cotwin publish, the dashboard's panel) learns from from_cosim."""
    assert read_echo(json.dumps(READY).encode()) == (True, None)
    ready, simstep = read_echo(json.dumps(echo_message({"x": 1.5, "open": True}, 2.0, 0.1)).encode())
    assert not ready and simstep == pytest.approx(2.1)
    for garbage in (b"\xff\xfe", b"[1, 2]", b'{"simstep": "NaN"}', b'{"simstep": null}', b'{"simstep": "1e400"}', b""):
        assert read_echo(garbage) == (False, None), garbage


def test_a_waiting_twin_says_it_is_ready_again_so_a_late_publisher_hears_it(monkeypatch):
    """A publisher started after the twin's first ready message waits for one: while the twin waits for its
    first complete set of values it says it is ready again (every ANNOUNCE_SECONDS), and its error names where
    it listens (exchange and routing key), not a generic 'to_cosim'."""
    import cotwin.twin.assembly.rabbitmq as rabbitmq

    monkeypatch.setattr(rabbitmq, "ANNOUNCE_SECONDS", 0.1)
    said = []
    stream = CommandStream(TYPES, {"moveDiscreteCommand"}, lambda timeout: time.sleep(min(timeout, 0.05)) or [],
                           timeout=0.6, announce=lambda: said.append(time.monotonic()),
                           origin="exchange 'x', routing key 'data.to_cosim.left'")
    with pytest.raises(CotwinError, match="routing key 'data.to_cosim.left'"):
        stream.start()
    assert len(said) >= 3


def test_stream_follows_the_rmq_fmu_time_semantics():
    feed = Feed()
    stream = CommandStream(TYPES, {"moveDiscreteCommand"}, feed, maxage=1.0, timeout=0.3)
    feed.items = [msg(0.0, moveDiscreteCommand=False, MovementArgs_target_X=0), msg(0.2, speed=2.0)]
    stream.start()
    assert stream.t0 == T0 + timedelta(seconds=0.2)  # the newest time of the first complete set
    feed.items = [msg(0.5, moveDiscreteCommand=True, MovementArgs_target_X=7), msg(0.4, MovementArgs_target_X=9),
                  msg(0.9, speed=3.0)]  # 0.3 / 0.2 / 0.7 s of simulation time
    first = stream.values_for(0.0, 0.1)
    assert first == {"moveDiscreteCommand": False, "MovementArgs_target_X": 0, "speed": 2.0}  # nothing due yet
    second = stream.values_for(0.1, 0.3)  # to 0.4 s: the X = 9 at 0.2 s, then the event at 0.3 s
    assert second == {"moveDiscreteCommand": True, "MovementArgs_target_X": 7, "speed": 2.0}
    assert stream.values_for(0.1, 0.3) is second  # computed once per step (PT and DT share it)
    third = stream.values_for(0.4, 0.4)
    assert third == {"moveDiscreteCommand": False, "MovementArgs_target_X": 7, "speed": 3.0}  # an event fires once
    feed.items = [msg(1.25, moveDiscreteCommand=True), msg(1.26, moveDiscreteCommand=False)]
    assert stream.values_for(0.8, 0.3)["moveDiscreteCommand"] is True  # a command followed at once by idle
    feed.items = [msg(0.7, speed=9.0)]  # 0.5 s: older than the held 0.7 s value
    stream.values_for(1.1, 0.1)
    assert stream.held["speed"].value == 3.0 and any("not newer" in r for _, r in stream.refused)
    with pytest.raises(CotwinError, match=r"no fresh value of '\w+' for the step to t = 3 s: the newest is from "
                                          r"t = [\d.]+ s, [\d.]+ s old"):
        stream.values_for(2.9, 0.1)


# ---- on the real broker ----------------------------------------------------------------------



def live_system(exchange: str, **cosim):
    from conftest import EXAMPLES

    system = load(EXAMPLES / "ur5e" / "live.toml")
    system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=exchange, **cosim.pop("rabbitmq", {}))
    for key, value in cosim.items():
        setattr(system.spec, key, value)
    return system


def start_publisher(system, commands, **options) -> tuple[Publisher, threading.Event, threading.Thread]:
    types = port_types(system.models.program, system.source_ports)
    publisher = Publisher(system.spec.rabbitmq, commands, idle_values(types), **options)
    stop = threading.Event()
    thread = threading.Thread(target=publisher.run, args=(stop,), daemon=True)
    thread.start()
    assert publisher.ready.wait(10)
    return publisher, stop, thread


# the plan's four holes, in its order, 2.5 s apart (its closest pair's spacing) instead of over 15 s: each move
# still ends at its hole before the next begins, and a paced run of 11 s instead of 20 keeps the suite short
PACED_TIMES, PACED_END = (1.0, 3.5, 6.0, 8.5), 11.0


def test_a_paper_like_publisher_drives_a_paced_run_to_the_plan_holes(broker, tmp_path):
    from conftest import EXAMPLES

    results = {}

    def run(algorithm):
        system = live_system(f"cotwin_test_{uuid.uuid4().hex[:8]}", algorithm=algorithm, end=PACED_END)
        planned = read_plan(EXAMPLES / "ur5e" / "plan.csv", system.models.program)
        commands = [replace(c, time=t) for c, t in zip(planned, PACED_TIMES, strict=True)]
        publisher, stop, thread = start_publisher(system, commands, end=system.spec.end)
        try:
            results[algorithm] = (system, commands, run_twin(system, tmp_path / algorithm, plot=False), publisher)
        except Exception as err:  # noqa: BLE001 - reported by the main thread
            results[algorithm] = err
        finally:
            stop.set()
            thread.join(5)

    threads = [threading.Thread(target=run, args=(a,)) for a in ("jacobi", "gauss-seidel")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    for algorithm, outcome in results.items():
        assert not isinstance(outcome, Exception), f"{algorithm}: {outcome}"
        system, commands, ran, publisher = outcome
        assert ran.result.rows == 111 and ran.result.wall_seconds >= PACED_END - 0.1  # paced to wall time
        planned = [tuple(v for k, v in c.values if k.startswith("MovementArgs")) for c in commands]
        executed = [(a["target_X"], a["target_Y"], a["target_Z"]) for _, op, a in ran.mapping.executed
                    if op == "movediscrete"]
        assert list(dict.fromkeys(executed)) == planned  # the same four holes, in order
        sent = [s for _, s, m in publisher.sent if m["moveDiscreteCommand"]]
        assert [round(s, 1) for s in sent] == pytest.approx([c.time for c in commands], abs=0.3)
        tree, scene = system.models.tree, system.models.scene
        tool = ik.find_tool(tree)
        arm = ik.arm_joints(tree, tool)
        rows = list(csv.DictReader(open(ran.csv)))
        starts = [t for t, op, _ in ran.mapping.executed if op == "movediscrete"] + [PACED_END]
        for target, following in zip(planned, [s for s in starts[1:] if s not in starts[:1]]):
            row = [r for r in rows if float(r["time"]) <= following + 1e-9][-1]
            q = {j: float(row[f"{{mapping}}.mapping.q{i}"]) for i, j in enumerate(arm)}
            assert np.linalg.norm(ik.tool_pose(tree, tool, q)[:3, 3] - np.array(scene.hole(*target))) < 0.002


def test_bad_messages_are_dropped_with_a_reason_and_the_run_goes_on(broker, tmp_path):
    from conftest import EXAMPLES

    system = live_system(f"cotwin_test_{uuid.uuid4().hex[:8]}", end=3.0)
    commands = read_plan(EXAMPLES / "ur5e" / "plan.csv", system.models.program)[:1]
    publisher, stop, thread = start_publisher(system, commands, end=3.0)
    rabbit = system.spec.rabbitmq
    connection = connect(rabbit.url, "cotwin test rogue")
    channel = connection.channel()
    stamp = datetime.now(timezone.utc)
    bad = [b"\xff\xfe\x00", b"{not json", json.dumps({"moveDiscreteCommand": True}).encode(),
           json.dumps({"time": stamp.isoformat(), "moveDiscreteCommand": "yes"}).encode(),
           json.dumps({"time": "2020-01-01T00:00:00Z", "moveDiscreteCommand": True,
                       "MovementArgs_target_X": 15, "MovementArgs_target_Y": 0, "MovementArgs_target_Z": 0}).encode(),
           json.dumps({"time": stamp.isoformat(), "jump": True}).encode(), b"[" * 50_000]

    echoes = channel.queue_declare("", exclusive=True).method.queue
    channel.queue_bind(echoes, rabbit.exchange, routing_key=rabbit.from_cosim)

    def rogue():  # once the twin steps, past its t0 (a fixed sleep raced its FMU build on a busy machine)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            _, _, body = channel.basic_get(echoes, auto_ack=True)
            if body is not None and read_echo(body)[1] is not None:
                break
            time.sleep(0.05)
        for body in bad:
            channel.basic_publish(rabbit.exchange, rabbit.to_cosim, body)
        connection.close()

    threading.Thread(target=rogue, daemon=True).start()
    try:
        ran = run_twin(system, tmp_path, plot=False)
    finally:
        stop.set()
        thread.join(5)
    refused = " | ".join(r for _, r in ran.units["source"].stream.refused)
    for reason in ("not UTF-8", "not JSON", "no 'time'", "not a JSON Boolean", "from when it arrived", "unknown key 'jump'",
                   "nested too deeply"):
        assert reason in refused
    executed = [a for _, op, a in ran.mapping.executed if op == "movediscrete"]
    assert executed and all(a["target_X"] == 0 for a in executed)  # the stale (15, 0, 0) was never applied
    assert ran.result.rows == 31


def test_a_silent_publisher_ends_the_run_with_a_clear_error_and_keeps_the_rows(broker, tmp_path):
    system = live_system(f"cotwin_test_{uuid.uuid4().hex[:8]}", end=10.0, rabbitmq={"timeout_s": 1.5})
    publisher, stop, thread = start_publisher(system, [], end=None)

    def silence():  # 2 s after the twin is ready and the publisher sends (not after it bound: the twin's start varies)
        deadline = time.monotonic() + 60
        while not publisher.sent and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(2.0)
        stop.set()

    threading.Thread(target=silence, daemon=True).start()
    with pytest.raises(CotwinError) as err:
        run_twin(system, tmp_path, plot=False)
    text = str(err.value)
    assert "no fresh value of" in text and "s old (maxage 1 s)" in text and "none came within 1.5 s" in text
    rows = list(csv.reader(open(tmp_path / "outputs.partial.csv")))
    assert len(rows) > 20 and "outputs.partial.csv" in text
    thread.join(5)


def _close_connection(name: str) -> bool:
    listing = subprocess.run(["rabbitmqctl", "-q", "list_connections", "pid", "client_properties"],
                             capture_output=True, text=True, timeout=30)
    for line in listing.stdout.splitlines():
        if name in line:
            pid = line.split("\t", 1)[0]
            subprocess.run(["rabbitmqctl", "-q", "close_connection", pid, "test: closed by the broker"],
                           capture_output=True, timeout=30)
            return True
    return False


def test_the_bridge_reconnects_and_loses_no_command_published_meanwhile(broker, tmp_path):
    if subprocess.run(["which", "rabbitmqctl"], capture_output=True).returncode:
        pytest.skip("rabbitmqctl is not on PATH: cannot close a connection from the broker's side")
    from conftest import EXAMPLES

    system = live_system(f"cotwin_test_{uuid.uuid4().hex[:8]}", end=9.0)
    commands = read_plan(EXAMPLES / "ur5e" / "plan.csv", system.models.program)[:2]  # at 1.0 and 5.5 s
    publisher, stop, thread = start_publisher(system, commands, end=9.0)
    closed = []

    def close_at_five():  # while the second command is due
        time.sleep(5.0)
        closed.append(_close_connection(f"cotwin {{rabbitmq}}.rabbitmq on {system.spec.rabbitmq.exchange}"))

    threading.Thread(target=close_at_five, daemon=True).start()
    try:
        ran = run_twin(system, tmp_path, plot=False)
    finally:
        stop.set()
        thread.join(5)
    assert closed == [True]
    source = ran.units["source"]
    executed = [(a["target_X"], a["target_Y"], a["target_Z"]) for _, op, a in ran.mapping.executed
                if op == "movediscrete"]
    assert list(dict.fromkeys(executed)) == [(0, 23, 1), (3, 20, 2)]
    assert source.stream.applied and ran.result.rows == 91
    assert source.reconnects >= 1


def test_rabbitmq_fmu_in_the_multimodel_takes_live_commands(broker, tmp_path):
    from fmpy.validation import validate_fmu

    from cotwin.cosim.multimodel import execution_for, read_multimodel
    from cotwin.twin.assembly.build import build
    from cotwin.twin.assembly.scenario import Command

    system = live_system(f"cotwin_test_{uuid.uuid4().hex[:8]}", end=3.0)
    build(system, tmp_path)
    assert validate_fmu(str(tmp_path / "rabbitmq.fmu")) == []
    mm = read_multimodel(tmp_path / "multimodel.json")
    assert mm.realtime  # the project is paced, so is its multimodel (simulationProgramDelay)
    command = Command(1.0, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 3), ("MovementArgs_target_Y", 20),
                            ("MovementArgs_target_Z", 2)), "test")
    publisher, stop, thread = start_publisher(system, [command], end=3.0)
    try:
        execution_for(mm, tmp_path / "fmus.csv").run(3.0)
    finally:
        stop.set()
        thread.join(5)
    rows = list(csv.DictReader(open(tmp_path / "fmus.csv")))
    fired = [r for r in rows if r["{rabbitmq}.rabbitmq.moveDiscreteCommand"] == "true"]
    assert len(fired) == 1 and fired[0]["{rabbitmq}.rabbitmq.MovementArgs_target_Y"] == "20"
    assert any(r["{dmodel}.dmodel.movediscrete"] == "true" for r in rows)
