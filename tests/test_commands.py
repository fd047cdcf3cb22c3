"""Every accepted command is applied, once, in order, with its own arguments (issue 19 items 2 and 9):
the plan's controller, the RabbitMQ bridge (against the real broker, with the paper's publisher
pattern) and the page's panel queue command events, one per step, and say at which step each was."""

from __future__ import annotations

import csv
import json
import threading
import time
import urllib.error
import urllib.request
import uuid
from dataclasses import replace
from datetime import datetime, timedelta, timezone

import pytest

from cotwin.twin.assembly.rabbitmq import CommandStream, Received, port_arguments, port_types
from cotwin.twin.assembly.run import load, run_twin

MOVE = "moveDiscreteCommand"
ARGS = ("MovementArgs_target_X", "MovementArgs_target_Y", "MovementArgs_target_Z")
T0 = datetime(2025, 1, 31, 16, 1, 3, tzinfo=timezone.utc)


@pytest.fixture(scope="module")
def live():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "live.toml")


def idle(**extra) -> dict:
    return {MOVE: False, **{a: 0 for a in ARGS}, "openGripperCommand": False, "closeGripperCommand": False, **extra}


def move(x: int, y: int, z: int) -> dict:
    return {MOVE: True, **dict(zip(ARGS, (x, y, z)))}


class Feed:
    def __init__(self):
        self.items: list[bytes] = []

    def __call__(self, timeout):
        out, self.items = [Received(b, 0.0) for b in self.items], []
        return out

    def send(self, dt: float, values: dict) -> None:
        self.items.append(json.dumps({"time": (T0 + timedelta(seconds=dt)).isoformat(), **values}).encode())


def stream_of(live, **options) -> tuple[CommandStream, Feed]:
    program = live.models.program
    feed = Feed()
    stream = CommandStream(port_types(program, live.source_ports), live.command_events, feed, maxage=5.0, timeout=0.2,
                           arguments=port_arguments(program), **options)
    feed.send(0.0, idle())
    stream.start()
    return stream, feed


def test_a_command_takes_its_arguments_from_its_own_message(live):
    """The paper's publisher: the move, then at once its idle message with zero arguments. Both fall in
    one step: the event is applied with the move's arguments, not the idle message's (issue 19 item 2)."""
    stream, feed = stream_of(live)
    feed.send(1.00, move(0, 23, 1))
    feed.send(1.01, idle())
    out = stream.values_for(0.9, 0.5)
    assert out[MOVE] is True and [out[a] for a in ARGS] == [0, 23, 1]
    out = stream.values_for(1.4, 0.5)  # no command: the arguments shown stay the last command's
    assert out[MOVE] is False and [out[a] for a in ARGS] == [0, 23, 1]
    # an event without its arguments is refused, said to the sender; one whose type has none is applied
    feed.send(2.0, {"time_note": 1, MOVE: True})
    feed.send(2.1, {"openGripperCommand": True})
    out = stream.values_for(1.9, 0.5)
    assert out[MOVE] is False and out["openGripperCommand"] is True
    assert any("moveDiscreteCommand at t = 2.000 s without MovementArgs_target_X, MovementArgs_target_Y, "
               "MovementArgs_target_Z: a command takes its arguments from its own message" in r for _, r in stream.refused)
    acks = stream.take_acks()
    assert [a["internal_status"] for a in acks] == ["command applied", "command refused", "command applied"]


def test_commands_due_in_one_step_are_applied_in_the_next_steps_in_order_and_a_full_queue_refuses(live, monkeypatch):
    """Two stamped in the same millisecond and three more in one step: each applied in a step of its own,
    in order (issue 19 item 9: only the newest per step was taken, equal stamps dropped as not newer)."""
    import cotwin.twin.assembly.rabbitmq as rabbitmq

    stream, feed = stream_of(live)
    for k, dt in enumerate((1.0, 1.0, 1.02, 1.03, 1.04)):
        feed.send(dt, {**move(k, k, 0), "internal_id": f"c{k}"})
    applied = []
    for step in range(7):
        out = stream.values_for(0.9 + 0.1 * step, 0.1)
        if out[MOVE]:
            applied.append(out["MovementArgs_target_X"])
    assert applied == [0, 1, 2, 3, 4] and not any("not newer" in r for _, r in stream.refused)
    acks = [a for a in stream.take_acks() if a["internal_status"] == "command applied"]
    assert [a["internal_id"] for a in acks] == [f"c{k}" for k in range(5)]
    assert [round(a["applied_at"], 6) for a in acks] == [1.0, 1.1, 1.2, 1.3, 1.4]
    # a bounded queue: beyond it a command is refused and the sender told, never silently dropped
    monkeypatch.setattr(rabbitmq, "MAX_COMMANDS", 2)
    stream, feed = stream_of(live)
    for k in range(4):
        feed.send(1.0 + 0.001 * k, {**move(k, 1, 0), "internal_id": f"q{k}"})
    stream.values_for(0.9, 0.2)
    acks = stream.take_acks()
    refused = [a for a in acks if a["internal_status"] == "command refused"]
    assert [a["internal_id"] for a in refused] == ["q2", "q3"]
    assert "2 commands wait to be applied, one per step" in refused[0]["internal_message"]


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_plans_commands_due_in_one_step_are_all_applied_and_completed(live, tmp_path, algorithm):
    """A plan whose close, open and move fall in one step of 0.5 s: one per step, in order, none lost (the
    d-model may still be closing the gripper when the open comes, and then ignores that one)."""
    from cotwin.twin.assembly.scenario import Command

    plan = [Command(1.0, (("closeGripperCommand", True),), "close"), Command(1.1, (("openGripperCommand", True),), "open"),
            Command(1.2, ((MOVE, True), *zip(ARGS, (0, 23, 1))), "move")]
    ran = run_twin(live.with_plan(plan), tmp_path, step=0.5, end=6.0, algorithm=algorithm, plot=False, realtime=False)
    applied = [(a.command.event, a.time) for a in ran.units["source"].queue.applied]
    assert [e for e, _ in applied] == ["closeGripperCommand", "openGripperCommand", MOVE]
    assert [t for _, t in applied] == [1.5, 2.0, 2.5]
    executed = [op for _, op, _ in ran.mapping.executed]
    assert executed[0] == "pick" and "movediscrete" in executed


# ---- on the real broker: the paper's publisher pattern, paced ------------------------------------------------

def publish_pattern(settings, moves: dict[int, tuple], ticks: int, period: float, ready: threading.Event,
                    done: threading.Event, sent: list) -> None:
    """Every `period` s of wall time: the move planned for that tick (if any), then at once the idle message."""
    from cotwin.mapping.amqp import connect

    connection = connect(settings.url, "cotwin test publisher")
    try:
        channel = connection.channel()
        channel.exchange_declare(settings.exchange, exchange_type="direct", durable=False, auto_delete=False)
        own = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
        channel.queue_bind(own, settings.exchange, routing_key=settings.from_cosim)
        twin_ready = []
        channel.basic_consume(own, lambda ch, m, p, body: twin_ready.append(b"waiting for input data" in body),
                              auto_ack=True)
        ready.set()
        deadline = time.monotonic() + 30
        while not any(twin_ready) and time.monotonic() < deadline:
            connection.process_data_events(time_limit=0.05)
        start = time.monotonic()
        for k in range(ticks):
            now = datetime.now(timezone.utc)
            if k in moves:
                message = {"time": now.isoformat(), **move(*moves[k])}
                channel.basic_publish(settings.exchange, settings.to_cosim, json.dumps(message).encode())
                sent.append(message)
            message = {"time": (now + timedelta(milliseconds=1)).isoformat(), **idle()}
            channel.basic_publish(settings.exchange, settings.to_cosim, json.dumps(message).encode())
            while time.monotonic() < start + (k + 1) * period and not done.is_set():
                connection.process_data_events(time_limit=0.02)
    finally:
        connection.close()


def test_the_papers_publisher_pattern_binds_each_command_to_its_arguments_at_every_step(broker, tmp_path):
    """Issue 19 item 2 on RabbitMQ: a move message and at once the idle message, every 0.5 s, paced; at a
    step of 0.5 s both fall in one step, at 0.25 s two in one step and none in the next, at 0.1 s two in one
    and none in four. Every move reaches the d-model once, with its own arguments, under both algorithms."""
    from conftest import EXAMPLES

    moves = {2: (0, 23, 1), 7: (3, 20, 2), 12: (8, 10, 0)}  # ticks of 0.5 s: about 1, 3.5 and 6 s (a move takes < 2 s)
    results = {}

    def run(step, algorithm):
        system = load(EXAMPLES / "ur5e" / "live.toml")
        system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=f"cotwin_events_{uuid.uuid4().hex[:8]}")
        ready, done, sent = threading.Event(), threading.Event(), []
        publisher = threading.Thread(target=publish_pattern, args=(system.spec.rabbitmq, moves, 20, 0.5, ready, done,
                                                                    sent), daemon=True)
        publisher.start()
        try:
            assert ready.wait(10)
            results[(step, algorithm)] = (run_twin(system, tmp_path / f"{step}-{algorithm}", step=step, end=9.0,
                                                   algorithm=algorithm, plot=False, realtime=True), sent)
        except Exception as err:  # noqa: BLE001 - reported by the main thread
            results[(step, algorithm)] = err
        finally:
            done.set()
            publisher.join(10)

    threads = [threading.Thread(target=run, args=(s, a)) for s in (0.1, 0.25, 0.5) for a in ("jacobi", "gauss-seidel")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    for (step, algorithm), outcome in sorted(results.items()):
        assert not isinstance(outcome, Exception), f"step {step}, {algorithm}: {outcome}"
        ran, sent = outcome
        assert len(sent) == 3
        rows = list(csv.DictReader(open(ran.csv)))
        source = "{rabbitmq}.rabbitmq."
        delivered = [tuple(int(r[source + a]) for a in ARGS) for r in rows if r[source + MOVE] == "true"]
        assert delivered == list(moves.values()), (step, algorithm)  # once each, never (0, 0, 0)
        executed = [(a["target_X"], a["target_Y"], a["target_Z"]) for _, op, a in ran.mapping.executed
                    if op == "movediscrete"]
        assert executed == list(moves.values()), (step, algorithm)


# ---- the page's panel -------------------------------------------------------------------------------------------

def _post(url: str, body: dict) -> tuple[int, dict]:
    request = urllib.request.Request(url, json.dumps(body).encode(), {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


def test_five_commands_posted_back_to_back_from_the_page_are_each_applied_once_and_say_when(broker, tmp_path):
    """Issue 19 item 9: five posted at once all got 200 and two were applied. Now each answer says the step
    that applied it: five different steps, in a row, each command once."""
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.services.dashboard.app import Dashboard
    from cotwin.twin.live.runtime import LiveTwin

    from conftest import EXAMPLES

    system = load(EXAMPLES / "ur5e" / "live.toml")
    name = f"cotwin_page_{uuid.uuid4().hex[:8]}"
    system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=name)
    system.spec.deviation = replace(system.spec.deviation, exchange=name + ".events")
    models = system.models
    pt = SimulatedEndpoint(PlatformSimulator(models.tree, models.scene))
    with Dashboard(system, port=0, mode="twin") as dash:
        twin = LiveTwin(system, tmp_path, pt=pt, end=8.0, observers=[dash.feed])
        runner = threading.Thread(target=twin.run, daemon=True)
        runner.start()
        deadline = time.monotonic() + 20
        while not dash.publisher.twin_ready.is_set() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # the twin steps (t0 set by the panel's first idle messages)
        answers: list = [None] * 5

        def post(k):
            answers[k] = _post(dash.url + "api/command", {"event": "openGripperCommand" if k % 2 else MOVE,
                                                          "values": {} if k % 2 else dict(zip(ARGS, (k, 20, 1)))})
        posters = [threading.Thread(target=post, args=(k,)) for k in range(5)]
        for p in posters:
            p.start()
        for p in posters:
            p.join(30)
        runner.join(30)
    assert [code for code, _ in answers] == [200] * 5, answers
    times = sorted(round(a["applied"]["time"], 6) for _, a in answers)
    assert len(set(times)) == 5 and all(round(b - a, 6) == 0.1 for a, b in zip(times, times[1:]))
    rows = list(csv.DictReader(open(tmp_path / "dt" / "outputs.csv")))
    events = [(round(float(r["time"]), 6), e) for r in rows for e in (MOVE, "openGripperCommand")
              if r["{rabbitmq}.rabbitmq." + e] == "true"]
    assert sorted(t for t, _ in events) == times  # each applied once, where the answer said
