"""Hostile input to the twin's run time and its recorded data: RTDE logs that lie, replay offsets past a
log's end, project paths gone missing, Ctrl-C while waiting for the broker, runs failing midway, broker
messages from another time or in a flood. Each must end in a located error or a logged refusal, never a
traceback, a hang or a silently wrong result, and keep what was already computed."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import EXAMPLES, ROOT, cotwin_in_process
from cotwin.diagnostics import CotwinError
from cotwin.mapping import rtde

RUN1 = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"


def cotwin(*args) -> subprocess.CompletedProcess:
    """`cotwin ARGS` in this process: the tests using it check messages, files and exit status (the ones
    about signals and a twin ending midway start their own processes below)."""
    return cotwin_in_process(*args)


@pytest.fixture
def run1() -> tuple[list[str], list[list[str]]]:
    """The recorded UR5e run's header and rows, to mutate."""
    if not RUN1.is_file():
        pytest.skip(f"the recorded UR5e run is not at {RUN1} (only in the project workspace)")
    lines = RUN1.read_text().splitlines()
    return lines[0].split(), [line.split() for line in lines[1:]]


def _write(path: Path, header: list[str], rows: list[list[str]]) -> Path:
    path.write_text("\n".join([" ".join(header), *(" ".join(r) for r in rows)]) + "\n")
    return path


def _error(path: Path) -> str:
    with pytest.raises(CotwinError) as err:
        rtde.read_rtde(path)
    return str(err.value)


MUTATIONS = {  # name: (how a row set is spoilt, what the error says, the line it is at)
    "nan": (lambda h, r: r[5].__setitem__(h.index("actual_q_0"), "nan"), "'nan' is not a finite number", 7),
    "inf": (lambda h, r: r[5].__setitem__(h.index("actual_q_2"), "-inf"), "'-inf' is not a finite number", 7),
    "inf current": (lambda h, r: r[5].__setitem__(h.index("actual_current_0"), "inf"), "'inf' is not a finite", 7),
    "huge angle": (lambda h, r: r[5].__setitem__(h.index("actual_q_0"), "1e300"), "beyond any UR arm's", 7),
    "huge speed": (lambda h, r: r[9].__setitem__(h.index("actual_qd_4"), "-4e4"), "beyond any UR arm's", 11),
    "backwards": (lambda h, r: r[10].__setitem__(0, r[8][0]), "timestamps must increase", 12),
    "repeated": (lambda h, r: r[10].__setitem__(0, r[9][0]), "timestamps must increase", 12),
    "jump": (lambda h, r: r[-1].__setitem__(0, "1e300"), "a jump of 1e+300 s", 242),
    "ragged": (lambda h, r: r[7].pop(), "117 values for 118 columns", 9),
}


@pytest.mark.parametrize("name", MUTATIONS)
def test_impossible_rtde_values_are_located_errors(run1, tmp_path, name):
    header, rows = run1
    spoil, message, line = MUTATIONS[name]
    spoil(header, rows)
    log = _write(tmp_path / "log.csv", header, rows)
    error = _error(log)
    assert error.startswith(f"{log}:{line}:") and message in error


def test_broken_rtde_files_are_located_errors(run1, tmp_path):
    header, rows = run1
    cases = {
        "header only": (" ".join(header) + "\n", ":1:1: error: the log has 0 sample(s)"),
        "missing column": (" ".join(h for h in header if h != "actual_q_3") + "\n", "no column(s) actual_q_3"),
        "binary": (None, "not UTF-8 text"),
        "a flood of columns": (" ".join(["timestamp"] * 50_000) + "\n", ":1:211: error: stopped after 20 errors"),
    }
    for name, (text, message) in cases.items():
        path = tmp_path / f"{name}.csv"
        if text is None:
            path.write_bytes(" ".join(header).encode() + b"\n" + bytes(range(128, 256)) * 10)
        else:
            path.write_text(text)
        error = _error(path)
        assert message in error and len(error.splitlines()) <= 22, name
    big = tmp_path / "big.csv"  # sparse: the size says enough, nothing is read
    with big.open("wb") as f:
        f.truncate(rtde.MAX_BYTES + 1)
    started = time.monotonic()
    assert "MiB, over the 512 MiB cotwin reads" in _error(big) and time.monotonic() - started < 1.0


@pytest.fixture
def copied(tmp_path) -> Path:
    """The UR5e example copied elsewhere: replay.toml's relative [pt] log now points nowhere."""
    shutil.copytree(EXAMPLES / "ur5e", tmp_path / "ur5e")
    return tmp_path / "ur5e"


def test_a_replay_offset_past_the_logs_end_is_refused_naming_it_and_the_duration(run1, copied, caplog):
    import logging

    from cotwin.twin.project import load_project
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin, pt_endpoint

    toml = copied / "replay.toml"
    text = toml.read_text().replace('log = "../../../shared/data/ur5e/rtde_run1.csv"', f'log = "{RUN1}"')
    for offset in (9000.0, 5061.708):  # far past the end; at its last sample
        toml.write_text(text.replace("[pt]", f"[pt]\noffset = {offset}"))
        with pytest.raises(CotwinError) as err:
            pt_endpoint(load(load_project(toml)))
        assert (f"[pt] offset: the replay offset {offset} s is past the end of the log {RUN1}, whose time runs "
                "from 5037.71 to 5061.71 s (24 s long)") in str(err.value)
    toml.write_text(text.replace("[pt]", "[pt]\noffset = 5055.0"))
    system = load(load_project(toml))
    replayed = pt_endpoint(system)
    assert replayed.recording_time() == 5055.0
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):  # 6.7 s of log left for an 8 s run: said
        LiveTwin(system, copied / "out", end=8.0)._warn_if_outlasting(replayed)
        LiveTwin(system, copied / "out", end=6.5)._warn_if_outlasting(replayed)
    assert [r.getMessage() for r in caplog.records] == [
        f"the replayed log {RUN1} ends at t = 6.708 s of the run, which goes on to 8 s: its last sample holds from "
        "then on"]


def test_pt_log_replaces_the_projects_missing_log_and_calibrate_names_the_key(run1, copied, tmp_path):
    toml = copied / "replay.toml"
    header, rows = run1
    rows[5][header.index("actual_q_1")] = "1e300"
    bad = _write(tmp_path / "bad.csv", header, rows)
    proc = cotwin("twin", toml, "-o", tmp_path / "out", "--end", "0.5", "--pt-log", bad)
    errors = [line for line in proc.stderr.splitlines() if ": error: " in line]
    assert proc.returncode == 1 and errors == [f"{bad}:7:395: error: column 'actual_q_1': 1e+300 rad is beyond any "
                                               "UR arm's (at most 12.5664 rad)"] and "Traceback" not in proc.stderr
    proc = cotwin("twin", toml, "-o", tmp_path / "out", "--end", "0.5", "--pt-log", RUN1)
    assert proc.returncode == 0, proc.stderr
    assert len(list(csv.reader(open(tmp_path / "out" / "pt" / "outputs.csv")))) == 7
    proc = cotwin("calibrate", toml, "--check", RUN1)  # no --pt-log: the project's [pt] log is needed
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"{toml}:17:1: error: [pt] log: no file {copied}/../../../shared/data/ur5e/rtde_run1.csv" in proc.stderr


def test_a_replay_project_without_its_recording_still_runs_predicts_and_sweeps_its_dt(copied, tmp_path):
    """[pt] log is looked for only by the commands that read [pt]: `cotwin run`, `whatif` and `sweep` ignore [pt]
    (and say so) and ran into "[pt] log: no file" on a replay project copied without its recording; `cotwin twin`
    still refuses it at the key."""
    toml = copied / "replay.toml"
    proc = cotwin("run", toml, "-o", tmp_path / "run", "--end", "0.3")
    assert proc.returncode == 0 and "[pt] applies only to" in proc.stderr and "[pt] log" not in proc.stderr, proc.stderr
    proc = cotwin("whatif", toml, "--plan", copied / "plan.csv", "--horizon", "0.5")
    assert proc.returncode == 0 and "[pt] log" not in proc.stderr, proc.stderr
    proc = cotwin("sweep", toml, "--event", "moveDiscreteCommand", "--arg", "target_X=0", "--arg", "target_Y=0",
                  "--arg", "target_Z=0", "--horizon", "0.5", "--workers", "1", "-o", tmp_path / "s.csv")
    assert proc.returncode == 0 and "[pt] log" not in proc.stderr, proc.stderr
    proc = cotwin("twin", toml, "-o", tmp_path / "twin", "--end", "0.3")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"{toml}:17:1: error: [pt] log: no file {copied}/../../../shared/data/ur5e/rtde_run1.csv" in proc.stderr


# ---- on the real broker ----------------------------------------------------------------------

def _twin(exchange: str, out: Path, *options) -> subprocess.Popen:
    """`cotwin twin` of the replay example taking its commands live from `exchange`."""
    return subprocess.Popen([sys.executable, "-m", "cotwin", "twin", EXAMPLES / "ur5e" / "replay.toml", "-o", out,
                             "--pt-log", RUN1, "--rabbitmq", exchange, *map(str, options)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _await_ready(exchange: str, timeout: float = 60.0) -> None:
    """Until the twin says on from_cosim that it is bound and waiting for data."""
    from cotwin.mapping.amqp import connect
    from cotwin.twin.assembly.rabbitmq import read_echo

    connection = connect("amqp://127.0.0.1:5672/%2F", "cotwin test ready")
    try:
        channel = connection.channel()
        channel.exchange_declare(exchange, exchange_type="direct", durable=False, auto_delete=False)
        own = channel.queue_declare("", exclusive=True, auto_delete=True).method.queue
        channel.queue_bind(own, exchange, routing_key="data.from_cosim")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            _, _, body = channel.basic_get(own, auto_ack=True)
            if body is not None and read_echo(body)[0]:
                return
            connection.process_data_events(time_limit=0.1)
        pytest.fail(f"the twin sent no ready message on {exchange} within {timeout:g} s")
    finally:
        connection.close()


def _publisher(exchange: str, count: int):
    """Publish idle values until `count` were sent, then fall silent (a publisher that died)."""
    import threading

    from cotwin.twin.project import RabbitMQSettings
    from cotwin.twin.services.publisher import Publisher, idle_values
    from cotwin.twin.assembly.rabbitmq import port_types
    from cotwin.twin.assembly.run import load

    system = load(EXAMPLES / "ur5e" / "live.toml")
    publisher = Publisher(RabbitMQSettings(exchange), [], idle_values(port_types(system.models.program,
                                                                                system.source_ports)), period=0.1)
    stop = threading.Event()
    threading.Thread(target=publisher.run, args=(stop,), daemon=True).start()
    deadline = time.monotonic() + 60
    while len(publisher.sent) < count and time.monotonic() < deadline:
        time.sleep(0.05)
    stop.set()
    return publisher


def _interrupt(proc: subprocess.Popen) -> tuple[str, float]:
    started = time.monotonic()
    os.kill(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    return err, time.monotonic() - started


def _rows(path: Path) -> list[list[str]]:
    rows = list(csv.reader(open(path)))
    assert rows[0][0] == "time" and all(len(r) == len(rows[0]) for r in rows), path
    return rows[1:]


def test_ctrl_c_while_waiting_for_the_broker_stops_at_once_keeping_the_rows(broker, run1, tmp_path):
    exchange, out = f"cotwin_hostile_{os.getpid()}_{time.monotonic_ns()}", tmp_path / "out"
    proc = _twin(exchange, out, "--end", "30")  # nothing publishes: the twin waits (timeout_s 60) for a first value
    try:
        _await_ready(exchange)
        time.sleep(0.5)
        err, took = _interrupt(proc)
    finally:
        proc.kill()
    assert proc.returncode == 130 and took < 5 and "Traceback" not in err
    assert "interrupted at t = 0 s; no rows computed" in err
    proc = _twin(exchange, out, "--end", "30")  # a publisher sends 15 messages, then falls silent mid-run
    try:
        _publisher(exchange, 15)
        time.sleep(2.0)  # the twin now waits for a fresh value (maxage 1 s)
        err, took = _interrupt(proc)
    finally:
        proc.kill()
    assert proc.returncode == 130 and took < 5 and "Traceback" not in err
    for side in ("pt", "dt"):
        partial = out / side / "outputs.partial.csv"
        assert f"row(s) computed are in {partial}" in err and len(_rows(partial)) > 5
        assert not (out / side / "outputs.csv").exists()


def test_a_twin_failing_midway_names_its_partial_results(broker, run1, copied, tmp_path):
    exchange, out = f"cotwin_hostile_{os.getpid()}_{time.monotonic_ns()}", tmp_path / "out"
    toml = copied / "replay.toml"
    toml.write_text(toml.read_text().replace('plan = "plan.csv"',
                                             f'rabbitmq = {{ exchange = "{exchange}", timeout_s = 1.0 }}'))
    proc = subprocess.Popen([sys.executable, "-m", "cotwin", "twin", toml, "-o", out, "--pt-log", RUN1, "--end", "30",
                             "--realtime"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _publisher(exchange, 15)  # then silent: no fresh value within maxage + timeout_s ends the run
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 1 and "Traceback" not in err and "no fresh value of" in err
    for side in ("pt", "dt"):
        partial = out / side / "outputs.partial.csv"
        assert f"{side.upper()}: the " in err and f"row(s) computed are in {partial}" in err and len(_rows(partial)) > 5


def test_broker_messages_hours_off_are_refused_and_a_flood_of_them_is_not_logged_one_by_one(broker, caplog):
    import json
    import logging
    from datetime import datetime, timedelta, timezone

    from cotwin.mapping.amqp import connect
    from cotwin.twin.project import RabbitMQSettings
    from cotwin.twin.assembly.rabbitmq import CommandStream, RabbitMQBridge

    settings = RabbitMQSettings(f"cotwin_hostile_{os.getpid()}_{time.monotonic_ns()}", timeout_s=10)
    assert settings.max_skew_s == 60
    types = {"moveDiscreteCommand": "Boolean", "MovementArgs_target_X": "Integer"}
    bridge = RabbitMQBridge(settings, "cotwin test skew").start()
    stream = CommandStream(types, {"moveDiscreteCommand"}, bridge.receive, 1.0, 10.0, max_skew=settings.max_skew_s)
    connection = connect(settings.url, "cotwin test flood")
    try:
        channel = connection.channel()
        now = datetime.now(timezone.utc)
        for k in range(300):  # a publisher whose clock is three hours behind, and one from the future
            stamp = now - timedelta(hours=3) if k % 2 else now + timedelta(hours=5)
            body = {"time": stamp.isoformat(), "moveDiscreteCommand": True, "MovementArgs_target_X": 15}
            channel.basic_publish(settings.exchange, settings.to_cosim, json.dumps(body).encode())
        good = {"time": datetime.now(timezone.utc).isoformat(), "moveDiscreteCommand": False, "MovementArgs_target_X": 2}
        channel.basic_publish(settings.exchange, settings.to_cosim, json.dumps(good).encode())
        with caplog.at_level(logging.WARNING, logger="cotwin.rabbitmq"):
            stream.start()
            stream.finish()
    finally:
        connection.close()
        bridge.close()
    assert stream.held["MovementArgs_target_X"].value == 2 and stream.refused_count == 300  # the 15s never applied
    reasons = [r for _, r in stream.refused]
    assert any("s from when it arrived (at most max_skew_s = 60 s" in r and "-1080" in r for r in reasons)
    assert any("+1800" in r for r in reasons)
    logged = [r.getMessage() for r in caplog.records if r.name == "cotwin.rabbitmq"]
    assert 20 < len(logged) <= 22 and logged[-1].startswith("280 more dropped messages not logged")


def test_an_end_time_between_steps_is_refused_before_anything_runs(run1, tmp_path):
    from cotwin.twin.assembly.run import load, run_twin
    from cotwin.twin.live.runtime import LiveTwin

    for start, project, end in ((run_twin, "cotwin.toml", 1.05), (LiveTwin, "replay.toml", 0.05)):
        with pytest.raises(CotwinError) as err:  # 1.05 s ended silently at 1 s; 0.05 s ran no step at all
            start(load(EXAMPLES / "ur5e" / project), tmp_path / project, end=end, step=0.1)
        assert (f"end: {end:g} s is not a whole number of steps of 0.1 s (it would be rounded): give 1 or 1.1"
                if end == 1.05 else "end: 0.05 s is shorter than one step of 0.1 s") in str(err.value)
        assert not (tmp_path / project).exists()  # refused before building anything
    from cotwin.cosim.execution import step_count

    for end, step in ((1e308, 0.1), (1.0, 1e-300)):  # inf steps (an OverflowError), 1e300 steps (a hang)
        with pytest.raises(CotwinError, match="steps of .* more than 1e[+]08"):
            step_count(end, step)


def test_broker_messages_that_say_two_things_or_name_no_real_zone_are_refused_with_the_reason():
    from cotwin.twin.assembly.rabbitmq import parse_message

    types = {"MovementArgs_target_X": "Integer"}
    for body, reason in ((b'{"time": "2026-01-01T00:00:00Z", "MovementArgs_target_X": 1, "MovementArgs_target_X": 9}',
                          "key 'MovementArgs_target_X' appears twice"),
                         (b'{"time": "2026-01-01T00:00:00+99:99", "MovementArgs_target_X": 1}',
                          "the zone +99:99 is not an offset within +-23:59")):
        with pytest.raises(ValueError) as err:
            parse_message(body, types)
        assert reason in str(err.value)


def test_commands_a_run_never_sends_are_named_not_dropped_silently():
    from cotwin.twin.assembly.run import load
    from cotwin.twin.assembly.scenario import after_end

    commands = load(EXAMPLES / "ur5e" / "cotwin.toml").commands  # the plan's commands at 1, 5.5, 8 and 15 s
    late = [str(f) for f in after_end(commands, 8.0)]
    plan = EXAMPLES / "ur5e" / "plan.csv"
    assert late == [f"{plan}:4:1: warning: this command at 8 s is after the run's end (8 s): it is never sent",
                    f"{plan}:5:1: warning: this command at 15 s is after the run's end (8 s): it is never sent"]
    assert after_end(commands, 15.1) == []


def test_a_second_interrupt_while_a_stopped_twin_ends_leaves_both_sides_and_its_history_whole(run1, copied, tmp_path):
    """Ctrl-C then Ctrl-C again 50 ms later: the second landed while the first was ending the run (an FMU being
    terminated). The PT's rows stayed in outputs.csv.part, the DT's became outputs.csv, the history run stayed
    'running', and the error said 'PT: no rows computed; DT: no rows computed' of a run that had computed 6 steps."""
    from cotwin.twin.assembly.observing import TwinObserver
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin
    from cotwin.twin.project import load_project
    from cotwin.twin.services.history import list_runs

    class SecondInterrupt(TwinObserver):
        """Stops the twin at step 5 (a first Ctrl-C) and interrupts the PT's units as they end (a second)."""

        def twin_step(self, twin, k: int, t: float) -> None:
            if k == 5:
                twin.stop()
                unit = next(iter(twin.sides["pt"].execution.system.units.values()))
                ending = unit.terminate

                def interrupted() -> None:
                    ending()
                    raise KeyboardInterrupt

                unit.terminate = interrupted

    system = load(load_project(copied / "replay.toml", str(RUN1)))
    live = LiveTwin(system, tmp_path / "out", end=2.0, observers=[SecondInterrupt()])
    with pytest.raises(CotwinError) as err:
        live.run()
    for side in ("pt", "dt"):
        assert f"{side.upper()}: the 6 row(s) computed are in {tmp_path / 'out' / side / 'outputs.csv'}" in str(err.value)
        assert not (tmp_path / "out" / side / "outputs.csv.part").exists()
    assert [run["status"] for run in list_runs(f"sqlite:///{tmp_path / 'out' / 'history.sqlite'}")] == ["stopped"]


def test_a_twin_stopped_as_asked_keeps_its_figure_as_a_finished_runs(run1, copied, tmp_path):
    """Ctrl-C in the steps ends the run after the step, "its results kept as a finished run's" (docs/live-twin.md):
    the outputs and deviation.json were, but not figure.png."""
    from cotwin.twin.assembly.observing import TwinObserver
    from cotwin.twin.assembly.run import load
    from cotwin.twin.live.runtime import LiveTwin
    from cotwin.twin.project import load_project

    class CtrlC(TwinObserver):
        def twin_step(self, twin, k: int, t: float) -> None:
            if k == 5:
                twin.stop()

    system = load(load_project(copied / "replay.toml", str(RUN1)))
    result = LiveTwin(system, tmp_path / "out", end=2.0, observers=[CtrlC()]).run()
    assert result.pt.steps == 5 and (tmp_path / "out" / "deviation.json").is_file()
    assert (tmp_path / "out" / "figure.png").is_file()


def test_a_value_refused_from_a_message_whose_others_are_taken_is_not_called_a_dropped_message(caplog):
    """An unknown key or a wrongly typed value in a message was logged "message dropped: ..." while the
    message's other values were taken: whoever read the log looked for a lost command that was applied."""
    import json
    import logging
    from datetime import datetime, timezone

    from cotwin.twin.assembly.rabbitmq import CommandStream, Received

    body = json.dumps({"time": datetime.now(timezone.utc).isoformat(), "moveDiscreteCommand": False,
                       "MovementArgs_target_X": 2, "MovementArgs_target_Y": "3", "bogus": 1}).encode()
    sent = [[Received(body, time.time())]]
    types = {"moveDiscreteCommand": "Boolean", "MovementArgs_target_X": "Integer", "MovementArgs_target_Y": "Integer"}
    stream = CommandStream(types, {"moveDiscreteCommand"}, lambda timeout: sent.pop() if sent else [], 1.0, 1.0)
    with caplog.at_level(logging.WARNING, logger="cotwin.rabbitmq"), pytest.raises(CotwinError):
        stream.start()  # MovementArgs_target_Y never gets a value
    logged = [r.getMessage() for r in caplog.records if r.name == "cotwin.rabbitmq" and
              ("bogus" in r.getMessage() or "is not a number" in r.getMessage())]
    assert len(logged) == 2 and all(m.startswith("value dropped (the rest of its message taken): ") for m in logged), logged
