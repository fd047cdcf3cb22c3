"""What-if from live state and sweeps: a fork replays the live commands bit for bit, forking leaves the
live run untouched, requests over the broker are answered, sweeps give the same answers locally and
on Ray."""

from __future__ import annotations

import csv
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import uuid

import pytest

from cotwin.cosim.observers import Observer
from cotwin.diagnostics import CotwinError
from cotwin.twin.assembly.run import load, run_twin
from cotwin.twin.assembly.scenario import Command
from cotwin.twin.analysis.sweep import grid, run_sweep
from cotwin.twin.services.whatif import plan_from_json, predict

JOINTS = [f"q{i}" for i in range(6)]


@pytest.fixture(scope="module")
def system():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


class Fork(Observer):
    """Takes the state after `at` steps and, if asked, runs a what-if on it at once (inside the run)."""

    def __init__(self, at: int, system=None, plan=None):
        self.at, self.system, self.plan = at, system, plan
        self.state = None
        self.prediction = None

    def step_complete(self, execution) -> None:
        if execution.steps == self.at:
            self.state = execution.get_state()
            if self.system is not None:
                self.prediction = predict(self.system, self.plan, self.state, horizon=5.0)


def rows(path):
    return {r["time"]: r for r in csv.DictReader(open(path))}


def test_a_fork_replayed_with_the_live_commands_equals_the_straight_run_bit_for_bit(system, tmp_path):
    fork = Fork(at=50)
    run_twin(system, tmp_path, plot=False, observers=[fork])
    remaining = [Command(c.time - 5.0, c.values, c.where) for c in system.commands if c.time > 5.0]
    prediction = predict(system, remaining, fork.state, horizon=15.0, artefacts=tmp_path)
    live = rows(tmp_path / "outputs.csv")
    assert prediction.start == 5.0 and prediction.completion_time is not None
    assert len(prediction.trajectory["time"]) > 100
    for k, t in enumerate(prediction.trajectory["time"]):
        row = live[repr(round(t, 12))]
        assert [float(row[f"{{mapping}}.mapping.{q}"]) for q in JOINTS] == [prediction.trajectory[q][k] for q in JOINTS]
    assert [c.feasible for c in prediction.commands] == [True, True, True]
    assert all(c.accepted and c.done > c.delivered for c in prediction.commands)
    assert [s for _, _, s in prediction.states][-1] == "Idle"


def test_a_fork_of_a_state_saved_under_the_other_algorithm_goes_on_under_it(system, tmp_path):
    """A what-if (and a sweep's what-ifs) fork the DT as it ran: a state saved under gauss-seidel (the project
    says jacobi) is continued under gauss-seidel, bit for bit the straight run; asking for jacobi is refused."""
    from cotwin.cosim.state import StateError
    from cotwin.twin.analysis.sweep import failures

    assert system.spec.algorithm == "jacobi"
    fork = Fork(at=50)
    run_twin(system, tmp_path, algorithm="gauss-seidel", plot=False, observers=[fork])
    remaining = [Command(c.time - 5.0, c.values, c.where) for c in system.commands if c.time > 5.0]
    prediction = predict(system, remaining, fork.state, horizon=15.0, artefacts=tmp_path)
    live = rows(tmp_path / "outputs.csv")
    assert len(prediction.trajectory["time"]) > 100
    for k, t in enumerate(prediction.trajectory["time"]):
        row = live[repr(round(t, 12))]
        assert [float(row[f"{{mapping}}.mapping.{q}"]) for q in JOINTS] == [prediction.trajectory[q][k] for q in JOINTS]
    with pytest.raises(StateError, match="taken under gauss-seidel, this execution runs jacobi"):
        predict(system, remaining, fork.state, horizon=1.0, algorithm="jacobi", artefacts=tmp_path)
    plans = grid(system.models.program, "moveDiscreteCommand", {"target_X": [0, 1], "target_Y": [0], "target_Z": [0]})
    answers = run_sweep(system.spec.path, plans, fork.state, horizon=3.0, workers=1, artefacts=tmp_path)
    assert len(answers) == 2 and not failures(answers), answers


def test_forking_leaves_the_live_run_bit_for_bit_unchanged(system, tmp_path):
    plan = [Command(0.2, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 15), ("MovementArgs_target_Y", 0),
                          ("MovementArgs_target_Z", 3)), "test")]
    fork = Fork(at=30, system=system, plan=plan)
    run_twin(system, tmp_path / "forked", end=10.0, plot=False, observers=[fork])
    run_twin(system, tmp_path / "straight", end=10.0, plot=False)
    assert (tmp_path / "forked" / "outputs.csv").read_text() == (tmp_path / "straight" / "outputs.csv").read_text()
    assert fork.prediction.start == 3.0 and fork.prediction.commands[0].delivered is not None


def test_whatif_from_a_saved_state_on_the_command_line(system, tmp_path):
    from conftest import EXAMPLES

    out = tmp_path / "run"
    run = subprocess.run([sys.executable, "-m", "cotwin", "run", EXAMPLES / "ur5e" / "cotwin.toml", "-o", out,
                          "--end", "3"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    plan = tmp_path / "plan.json"
    # (5, 5, 1) is out of reach (a straight run says so too); (3, 20, 2) is reachable. The state at 3 s holds
    # the first move's answer (feasible): it must not be taken as the answer to the what-if's move (issue 19)
    for (x, y, z), feasible in (((5, 5, 1), False), ((3, 20, 2), True)):
        plan.write_text(json.dumps([{"time": 0.5, "event": "moveDiscreteCommand",
                                     "args": {"target_X": x, "target_Y": y, "target_Z": z}}]))
        proc = subprocess.run([sys.executable, "-m", "cotwin", "whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan",
                               plan, "--from", out / "state", "-o", tmp_path / "p.json"], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        said = "NOT feasible, accepted" if not feasible else "feasible, accepted"
        assert f"t = 3.5 s moveDiscreteCommand(MovementArgs_target_X={x}" in proc.stdout and said in proc.stdout
        answer = json.loads((tmp_path / "p.json").read_text())
        assert answer["start"] == 3.0 and answer["commands"][0]["feasible"] is feasible
    plan.write_text(json.dumps([{"time": -1, "event": "moveDiscreteCommand"}]))
    bad = subprocess.run([sys.executable, "-m", "cotwin", "whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan", plan],
                         capture_output=True, text=True)
    assert bad.returncode == 1 and "plan item 1: time must be a number" in bad.stderr and "Traceback" not in bad.stderr
    for item, message in [([{"time": 1, "event": "jump"}], "unknown event 'jump'"),
                          ([{"time": 1, "event": "moveDiscreteCommand", "args": {"target_X": 2 ** 40}}], "does not fit"),
                          ([{"time": 1, "event": "moveDiscreteCommand", "speed": 3}], "expected {time, event, args}"),
                          ([], "non-empty list")]:
        with pytest.raises(CotwinError, match=message):
            plan_from_json(item, system.models.program)




def test_whatif_requests_over_the_broker_are_answered_without_disturbing_the_twin(system, broker, tmp_path):
    import pika

    from cotwin.mapping.amqp import connect
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.live.runtime import LiveTwin

    exchange = f"cotwin_test_{uuid.uuid4().hex[:8]}"
    system.spec.deviation = type(system.spec.deviation)(exchange=exchange)
    answers: dict[str, dict] = {}

    def requester():
        connection = connect("amqp://127.0.0.1:5672/%2F", "cotwin test what-if client")
        channel = connection.channel()
        channel.exchange_declare(exchange, exchange_type="topic", durable=False, auto_delete=False)
        reply = channel.queue_declare("", exclusive=True).method.queue
        channel.basic_consume(reply, lambda ch, m, p, body: answers.__setitem__(p.correlation_id, json.loads(body)),
                              auto_ack=True)
        time.sleep(2.0)
        # late enough that the d-model is at rest whatever the live run was doing when forked
        plan = [{"time": 6.0, "event": "moveDiscreteCommand", "args": {"target_X": 8, "target_Y": 10, "target_Z": 3}}]
        channel.confirm_delivery()  # an unroutable request (the service not bound yet on a busy machine) is retried
        for cid, body in (("good", json.dumps({"plan": plan, "horizon": 12})), ("bad", b"\xff{"),
                          ("worse", json.dumps({"plan": [{"time": 1, "event": "fly"}]}))):
            for _ in range(100):
                try:
                    channel.basic_publish(exchange, "twin.whatif", body, pika.BasicProperties(
                        reply_to=reply, correlation_id=cid), mandatory=True)
                    break
                except pika.exceptions.UnroutableError:
                    time.sleep(0.2)
        deadline = time.monotonic() + 60
        while len(answers) < 3 and time.monotonic() < deadline:
            connection.process_data_events(time_limit=0.2)
        connection.close()

    thread = threading.Thread(target=requester, daemon=True)
    thread.start()
    pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    LiveTwin(system, tmp_path / "live", pt=pt, end=8.0, realtime=True, whatif_url="amqp://127.0.0.1:5672/%2F").run()
    thread.join(60)
    pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    LiveTwin(system, tmp_path / "quiet", pt=pt, end=8.0).run()
    assert (tmp_path / "live" / "dt" / "outputs.csv").read_text() == (tmp_path / "quiet" / "dt" / "outputs.csv").read_text()
    assert set(answers) == {"good", "bad", "worse"}
    good = answers["good"]
    assert "error" not in good, good
    assert 0.0 < good["start"] < 7.0 and good["commands"][0]["feasible"] is True and good["completion_time"] > good["start"]
    assert "bad what-if request" in answers["bad"]["error"] and "unknown event 'fly'" in answers["worse"]["error"]


@pytest.mark.timeout(900)  # its time includes waiting for the other Ray test (conftest.machine_lock)
def test_a_sweep_gives_the_same_answers_on_a_local_pool_and_on_ray(system, tmp_path, ray_alone):
    """On a Ray head of its own on 127.0.0.1, with token authentication (conftest: RAY_AUTH_MODE), joined
    by its address."""
    pytest.importorskip("ray", reason="Ray is an optional extra (pip install 'cotwin[ray]')")
    from conftest import EXAMPLES

    plans = grid(system.models.program, "moveDiscreteCommand", {"target_X": [0, 7, 15], "target_Y": [0, 23], "target_Z": [0]})
    local = run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=8.0, workers=2)
    one = run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=8.0, workers=1)
    assert local == one and len(local) == 6
    assert {r["feasible"] for r in local} == {True, False}  # some holes are out of reach from the base
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ray = shutil.which("ray", path=os.path.dirname(sys.executable)) or "ray"
    import tempfile

    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay short
    started = subprocess.run([ray, "start", "--head", f"--port={port}", "--num-cpus=2", "--include-dashboard=false",
                              "--disable-usage-stats", f"--temp-dir={temp}", "--node-ip-address=127.0.0.1"],
                             capture_output=True, text=True, timeout=180)
    try:
        assert started.returncode == 0, started.stderr[-2000:]
        on_ray = run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=8.0, ray=f"127.0.0.1:{port}")
    finally:
        subprocess.run([ray, "stop", "--force"], capture_output=True, timeout=120)
        shutil.rmtree(temp, ignore_errors=True)
    assert on_ray == local


def test_a_ray_address_nobody_listens_at_is_refused_at_once(system, tmp_path):
    """Ray retries an unreachable head for minutes (a sweep looked hung): cotwin says so at once."""
    pytest.importorskip("ray", reason="Ray is an optional extra (pip install 'cotwin[ray]')")
    from conftest import EXAMPLES

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nobody listens there
    plans = grid(system.models.program, "moveDiscreteCommand", {"target_X": [0], "target_Y": [0], "target_Z": [0]})
    started = time.monotonic()
    with pytest.raises(CotwinError, match=f"cannot reach the Ray cluster at '127.0.0.1:{port}'"):
        run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=2.0, ray=f"127.0.0.1:{port}", artefacts=tmp_path)
    with pytest.raises(CotwinError, match="a Ray address is 'auto', 'HOST:PORT'"):
        run_sweep(EXAMPLES / "ur5e" / "cotwin.toml", plans, horizon=2.0, ray="somewhere", artefacts=tmp_path)
    assert time.monotonic() - started < 60


def test_a_join_refused_for_its_token_says_what_to_set(monkeypatch):
    """Ray's refusal of a driver without the head's token names what to set: the mode when it is not on, else
    where Ray looks for the token; any other failure gets no hint."""
    from cotwin.twin.analysis.sweep import join_hint

    class AuthenticationError(Exception):  # Ray's, by name (the hint reads the chain's type names)
        pass

    refused = AuthenticationError("Token authentication is enabled but no authentication token was found")
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    assert "set RAY_AUTH_MODE=token" in join_hint("127.0.0.1:1", refused)
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    assert "RAY_AUTH_TOKEN" in join_hint("127.0.0.1:1", refused) and "the head's" in join_hint("127.0.0.1:1", refused)
    assert join_hint("127.0.0.1:1", ConnectionError("refused")) == ""



def test_a_plan_row_raising_two_events_or_none_is_predicted_occurrence_by_occurrence(system, tmp_path):
    """A TwinManager plan CSV's row may raise two events (both applied, one step apart) or none (its arguments
    only): the what-if waits for every occurrence the plan raises, not one per row. It ended once the first
    row's two occurrences were applied, at the time of the last row, whose move it neither applied nor listed;
    a row raising nothing made it wait to its horizon, then fail (StopIteration). Native, step by step and on
    Forks alike."""
    from cotwin.twin.assembly.scenario import read_plan
    from cotwin.twin.services.whatif import Forks

    header = "timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z," \
             "openGripperCommand\n"
    (tmp_path / "two.csv").write_text(header + "500,true,3,20,2,true\n3000,true,8,10,0,false\n")
    (tmp_path / "none.csv").write_text(header + "500,true,3,20,2,false\n1000,false,1,1,1,false\n")
    two, none = (read_plan(tmp_path / name, system.models.program) for name in ("two.csv", "none.csv"))
    answers = {}
    for name, plan in (("two", two), ("none", none)):
        found = [predict(system, plan, None, horizon=10.0, artefacts=tmp_path, fused=fused).as_dict()
                 for fused in (True, False)]
        with Forks(system, None, artefacts=tmp_path) as forks:
            found += [forks.predict(plan, horizon=10.0).as_dict() for _ in range(2)]
        for answer in found:
            answer.pop("wall_seconds"), answer.pop("native_steps")
            assert answer == found[0]
        answers[name] = found[0]
    commands = answers["two"]["commands"]
    assert [(c["event"], c["delivered"] is not None) for c in commands] == \
        [("moveDiscreteCommand", True), ("openGripperCommand", True), ("moveDiscreteCommand", True)]
    assert commands[1]["args"] == {} and commands[2]["args"]["MovementArgs_target_X"] == 8
    assert commands[2]["done"] is not None and answers["two"]["end"] > 3.5
    assert [c["event"] for c in answers["none"]["commands"]] == ["moveDiscreteCommand"]
    assert answers["none"]["completion_time"] is not None and answers["none"]["end"] < 5.0
    short = predict(system, two, None, horizon=2.5, artefacts=tmp_path)  # the last move not applied: listed so
    assert [c.delivered is None for c in short.commands] == [False, False, True] and short.commands[2].args == \
        {"MovementArgs_target_X": 8, "MovementArgs_target_Y": 10, "MovementArgs_target_Z": 0}
