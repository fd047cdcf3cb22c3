"""Every command a user runs, end to end, as a user runs it: `python -m cotwin ...` in another working
directory, on a copy of the example project (or a model of our own), checking what lasts: the exit
code, the files written and their structure, the essential messages. Servers (the OPC UA plant, the
dashboard) are ours, started on free loopback ports and stopped by PID; broker names are unique."""

from __future__ import annotations

import csv
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
import uuid
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import EXAMPLES, ROOT


def cotwin(*args, cwd: Path, timeout: float = 300, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


def clean(proc: subprocess.CompletedProcess) -> bool:
    return "Traceback" not in proc.stderr and "internal error" not in proc.stderr


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def get(url: str, timeout: float = 10) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as response:
            return response.status, response.read().decode("utf-8", "replace")
    except urllib.error.HTTPError as err:
        return err.code, err.read().decode("utf-8", "replace")


def page_of(port: int, server: subprocess.Popen, patience: float) -> tuple[int, str] | None:
    """The page served at the port once it answers (None if the server ends or `patience` s pass first)."""
    deadline = time.monotonic() + patience
    while time.monotonic() < deadline and server.poll() is None:
        try:
            return get(f"http://127.0.0.1:{port}/", timeout=2)
        except OSError:
            time.sleep(0.3)
    return None


def stop(process: subprocess.Popen, sig: int) -> str:
    """Stop a server we started (its PID): the signal, then a kill if it does not end; its stderr."""
    process.send_signal(sig)
    try:
        process.wait(20)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(10)
    errors = process.stderr.read()
    process.stdout.close()
    process.stderr.close()
    return errors


@pytest.fixture
def project(tmp_path) -> Path:
    """The UR5e example copied into a folder of its own (runs elsewhere: the user's working directory)."""
    target = tmp_path / "project"
    shutil.copytree(EXAMPLES / "ur5e", target, ignore=shutil.ignore_patterns("*.fmu", "out"))
    return target


@pytest.fixture
def workdir(tmp_path) -> Path:
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    return folder


@pytest.fixture
def plant(project, tmp_path):
    """`cotwin plant` serving the project's perturbed cell over OPC UA on a free port; the project's [pt]
    pointed at it. Yields (url, environment with its credentials folder)."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    toml = project / "twin.toml"
    toml.write_text(toml.read_text().replace('url = "opc.tcp://127.0.0.1:4840"', f'url = "{url}"'))
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    process = subprocess.Popen([sys.executable, "-m", "cotwin", "plant", str(toml), "--opcua", url], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith(f"serving ur5e on {url}"), line + process.stderr.read()
        yield url, env
    finally:
        stop(process, signal.SIGTERM)


# ---- models ------------------------------------------------------------------------------------------

def test_build_succeeds_with_every_artefact_and_a_multimodel_that_names_them(project, workdir):
    out = workdir / "out"
    proc = cotwin("build", project / "cotwin.toml", "-o", out, cwd=workdir)
    assert proc.returncode == 0 and clean(proc), proc.stderr[-2000:]
    written = [Path(line) for line in proc.stdout.split()]
    assert written and all(p.is_file() for p in written)
    names = {p.name for p in out.iterdir()}
    assert {"dmodel.fmu", "build.json", "multimodel.json"} <= names
    assert any(n.endswith(".sdf") for n in names) and any(n.endswith(".urdf") for n in names)
    mm = json.loads((out / "multimodel.json").read_text())
    assert {"fmus", "connections", "algorithm"} <= set(mm) and mm["fmus"]
    for path in mm["fmus"].values():  # every FMU it names is there, wherever the command ran from
        assert (out / path).is_file() or Path(path).is_file(), path
    again = cotwin("build", project / "cotwin.toml", "-o", out, cwd=workdir)
    assert again.returncode == 0 and clean(again)


def test_verify_succeeds_on_a_sound_model_and_fails_on_a_timelock(workdir, tmp_path):
    proc = cotwin("verify", EXAMPLES / "ur5e" / "arm.rst", cwd=workdir)
    assert proc.returncode == 0 and clean(proc), proc.stdout[-2000:] + proc.stderr[-2000:]
    assert re.search(r"\d+ states", proc.stdout)
    model = tmp_path / "lock.rst"
    model.write_text("""interface E { event go }
stm M { cycleDef cycle == 1 input context { uses E } output context { }
	initial i state A { } state B { }
	transition t0 { from i to A }
	transition t1 { from A to B exec condition $go }
	transition t2 { from A to A exec condition not $go } }
controller C { cycleDef cycle == 1 uses E sref m = M connection C on go to m on go }
module Mod { cycleDef cycle == 1 robotic platform P { uses E } cref c = C connection P on go to c on go (_async) }
""")
    failed = cotwin("verify", model, cwd=workdir)
    assert failed.returncode == 1 and clean(failed), failed.stderr[-2000:]
    assert "timelock" in failed.stdout.lower()


@pytest.mark.parametrize("fmt", ["sdf", "urdf", "mjcf"])
def test_export_pmodel_writes_a_model_of_our_own_in_each_format(workdir, tmp_path, fmt):
    """tests/models/pmodel/arm.pm: our own p-models (not the paper's), exported from another folder; the
    file holds three, so the one to export is named (and not naming it is an error that lists them)."""
    model = ROOT / "tests" / "models" / "pmodel" / "arm.pm"
    out = tmp_path / f"arm.{fmt}"
    unnamed = cotwin("export-pmodel", model, "--format", fmt, "-o", out, cwd=workdir)
    assert unnamed.returncode == 1 and clean(unnamed) and "--pmodel" in unnamed.stderr and "Hand" in unnamed.stderr
    proc = cotwin("export-pmodel", model, "--pmodel", "Hand", "--format", fmt, "-o", out, cwd=workdir)
    assert proc.returncode == 0 and clean(proc), proc.stderr[-2000:]
    root = ET.parse(out).getroot()
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    tree = build_tree(load_checked([model]), "Hand")
    movable = {j.name for j in tree.actuated}
    if fmt == "urdf":
        joints = {j.get("name") for j in root.iter("joint") if j.get("type") != "fixed"}
    elif fmt == "sdf":
        joints = {j.get("name") for j in root.iter("joint") if j.get("type") != "fixed"}
    else:
        import mujoco

        model_mj = mujoco.MjModel.from_xml_path(str(out))
        joints = {model_mj.joint(k).name for k in range(model_mj.njnt)}
    assert movable and movable <= {n.split("::")[-1] for n in joints}, (movable, joints)


# ---- analysis -----------------------------------------------------------------------------------------

def test_sweep_writes_one_row_per_plan(project, workdir):
    out = workdir / "sweep.csv"
    proc = cotwin("sweep", project / "cotwin.toml", "--event", "moveDiscreteCommand", "--arg", "target_X=0..1",
                  "--arg", "target_Y=22..23", "--arg", "target_Z=1", "--horizon", "8", "--workers", "1", "-o", out,
                  cwd=workdir, timeout=600)
    assert proc.returncode == 0 and clean(proc), proc.stderr[-2000:]
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == 4
    column = {arg: next(c for c in rows[0] if c.endswith(arg)) for arg in ("target_X", "target_Y", "target_Z")}
    assert "feasible" in rows[0]
    assert {(r[column["target_X"]], r[column["target_Y"]]) for r in rows} == {("0", "22"), ("0", "23"), ("1", "22"), ("1", "23")}
    assert {r[column["target_Z"]] for r in rows} == {"1"}


# ---- live --------------------------------------------------------------------------------------------

def test_twin_with_an_opcua_pt_and_its_served_page_then_its_history(project, workdir, plant):
    """`cotwin twin` against the plant over OPC UA, its page served while it runs; then the history of
    that run listed, exported (--dir) and browsed with `cotwin dashboard`."""
    url, env = plant
    out = workdir / "live"
    port = free_port()
    twin = subprocess.Popen([sys.executable, "-m", "cotwin", "twin", str(project / "twin.toml"), "-o", str(out), "--end", "6",
                             "--realtime", "--dashboard", f"127.0.0.1:{port}"], cwd=workdir, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        page = page_of(port, twin, 120)
        stdout, stderr = twin.communicate(timeout=300)
    finally:
        if twin.poll() is None:
            twin.kill()
            twin.wait(10)
    assert twin.returncode == 0 and "Traceback" not in stderr, stderr[-3000:]
    assert page is not None and page[0] < 500 and "<html" in page[1].lower(), page
    assert "PT and DT" in stdout and "deviation:" in stdout
    for side in ("pt", "dt"):
        rows = list(csv.DictReader(open(out / side / "outputs.csv")))
        assert len(rows) == 61 and float(rows[-1]["time"]) == pytest.approx(6.0)
    report = json.loads((out / "deviation.json").read_text())
    assert set(report["variables"]) == {f"q{i}" for i in range(6)}

    listed = cotwin("history", "list", "--dir", out, cwd=workdir)
    assert listed.returncode == 0 and clean(listed) and "twin" in listed.stdout, listed.stderr
    run_id = re.search(r"^\s*(\d+)", listed.stdout, re.MULTILINE).group(1)
    exported = workdir / "pt.csv"
    proc = cotwin("history", "export", run_id, "--dir", out, "--side", "pt", "-o", exported, cwd=workdir)
    assert proc.returncode == 0 and clean(proc), proc.stderr
    assert exported.read_text() == (out / "pt" / "outputs.csv").read_text()
    missing = cotwin("history", "export", "999", "--dir", out, "-o", workdir / "x.csv", cwd=workdir)
    assert missing.returncode == 1 and clean(missing) and "999" in missing.stderr

    port = free_port()
    dash = subprocess.Popen([sys.executable, "-m", "cotwin", "dashboard", "--dir", str(out), "--at", f"127.0.0.1:{port}"],
                            cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        answer = page_of(port, dash, 60)
        assert answer is not None and answer[0] < 500 and "<html" in answer[1].lower(), (answer, dash.poll())
    finally:
        errors = stop(dash, signal.SIGINT)
    assert f"127.0.0.1:{port}" in errors and "Traceback" not in errors, errors[-2000:]


def test_publish_drives_a_live_twin_that_answers_a_whatif(project, workdir, plant, broker):
    """The live demo's three processes: the plant (PT), `cotwin twin --rabbitmq --whatif` and `cotwin
    publish` sending the plan; a what-if asked over the broker while the twin runs is answered."""
    import pika

    from cotwin.mapping.amqp import connect

    url, env = plant
    exchange = f"cotwin_e2e_{uuid.uuid4().hex[:8]}"
    alarms = f"cotwin_e2e_twin_{uuid.uuid4().hex[:8]}"
    toml = project / "twin.toml"
    # the plan's four holes 2.5 s apart (its closest spacing) instead of over 15 s: a paced run of 11 s, not 20
    # (the publisher follows the project's end)
    assert "end = 20.0\n" in toml.read_text()
    toml.write_text(toml.read_text().replace("end = 20.0\n", "end = 11.0\n") + f'exchange = "{alarms}"\n')  # [deviation] is the file's last table
    plan = (project / "plan.csv").read_text().splitlines()
    (project / "plan.csv").write_text("\n".join([plan[0]] + [f"{ms}," + line.split(",", 1)[1] for ms, line in
                                                             zip((1000, 3500, 6000, 8500), plan[1:], strict=True)]) + "\n")
    out = workdir / "live"
    twin = subprocess.Popen([sys.executable, "-m", "cotwin", "twin", str(toml), "-o", str(out), "--rabbitmq", exchange,
                             "--whatif", "--end", "11"], cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    answers: dict[str, dict] = {}

    def ask():
        connection = connect("amqp://127.0.0.1:5672/%2F", "cotwin e2e what-if client")
        channel = connection.channel()
        channel.exchange_declare(alarms, exchange_type="topic", durable=False, auto_delete=False)
        reply = channel.queue_declare("", exclusive=True).method.queue
        channel.basic_consume(reply, lambda ch, m, p, body: answers.__setitem__(p.correlation_id, json.loads(body)),
                              auto_ack=True)
        channel.confirm_delivery()
        plan = [{"time": 1.0, "event": "moveDiscreteCommand", "args": {"target_X": 8, "target_Y": 10, "target_Z": 0}}]
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # until the twin's what-if service is bound
            try:
                channel.basic_publish(alarms, "twin.whatif", json.dumps({"plan": plan, "horizon": 8}).encode(),
                                      pika.BasicProperties(reply_to=reply, correlation_id="q"), mandatory=True)
                break
            except pika.exceptions.UnroutableError:
                time.sleep(0.3)
        while "q" not in answers and time.monotonic() < deadline:
            connection.process_data_events(time_limit=0.2)
        connection.close()

    asker = threading.Thread(target=ask, daemon=True)
    asker.start()
    try:
        published = cotwin("publish", toml, "--exchange", exchange, "--period", "0.2", cwd=workdir, timeout=300, env=env)
        stdout, stderr = twin.communicate(timeout=300)
    finally:
        if twin.poll() is None:
            twin.kill()
            twin.wait(10)
    asker.join(60)
    assert published.returncode == 0 and clean(published), published.stderr[-2000:]
    assert re.search(r"sent \d+ message", published.stdout)
    assert twin.returncode == 0 and "Traceback" not in stderr, stderr[-3000:]
    rows = list(csv.DictReader(open(out / "dt" / "outputs.csv")))
    calls = "{dmodel}.dmodel.movediscrete"  # the d-model asks the platform to move once per command it takes
    assert sum(r[calls] == "true" for r in rows) == 4  # the plan's four commands, each applied once
    assert "q" in answers and "error" not in answers["q"], answers
    assert answers["q"]["commands"][0]["feasible"] is True


# ---- broker access -------------------------------------------------------------------------------------

def test_broker_permissions_prints_a_vhost_and_one_least_privilege_user_per_role(project, workdir):
    vhost, prefix = f"v{uuid.uuid4().hex[:6]}", "e2e-"
    proc = cotwin("broker-permissions", project / "twin.toml", "--vhost", vhost, "--prefix", prefix, cwd=workdir)
    assert proc.returncode == 0 and clean(proc), proc.stderr
    commands = [shlex.split(line) for line in proc.stdout.splitlines() if line.startswith("rabbitmqctl")]
    assert commands[0] == ["rabbitmqctl", "add_vhost", vhost]
    users = [c[2] for c in commands if c[1] == "add_user"]
    assert set(users) == {f"{prefix}{role}" for role in ("twin", "robot", "publisher", "monitor", "whatif")}
    for user in users:
        [permissions] = [c for c in commands if c[1] == "set_permissions" and user in c]
        assert permissions[2:5] == ["-p", vhost, user]
        for pattern in permissions[5:8]:
            regex = re.compile(pattern)
            assert pattern.startswith("^") and pattern.endswith("$") and not regex.fullmatch("amq.rabbitmq.log")
    [twin] = [c for c in commands if c[1] == "set_permissions" and c[4] == f"{prefix}twin"]
    assert re.fullmatch(twin[6], "fmi_digital_twin_dt")  # the twin writes to its command exchange
    [publisher] = [c for c in commands if c[1] == "set_permissions" and c[4] == f"{prefix}publisher"]
    assert not re.fullmatch(publisher[6], "cotwin.robot")  # and the publisher cannot reach the robot


def test_a_run_closes_with_how_many_errors_and_warnings_it_had(tmp_path):
    """`cotwin run` ended on its outcomes with no count of what went wrong: a warning scrolled away among the
    command lines left the run looking clean. Its last line now counts the errors and warnings it said."""
    from conftest import cotwin_in_process

    clean = cotwin_in_process("run", EXAMPLES / "ur5e" / "cotwin.toml", "-o", tmp_path / "clean", cwd=tmp_path)
    assert clean.returncode == 0, clean.stderr
    assert clean.stderr.strip().splitlines()[-1] == "0 error(s), 0 warning(s)"
    short = cotwin_in_process("run", EXAMPLES / "ur5e" / "cotwin.toml", "--end", "6", "-o", tmp_path / "short",
                              cwd=tmp_path)  # the plan's last commands come after the end: warned of
    assert short.returncode == 0, short.stderr
    said = sum("warning:" in line for line in short.stderr.splitlines())
    assert said >= 1 and short.stderr.strip().splitlines()[-1] == f"0 error(s), {said} warning(s)", short.stderr


def test_a_failed_run_closes_with_its_count_too_the_error_one_of_them(tmp_path):
    """A run that ended in an error closed with no count: the warnings said before the error went uncounted. The
    C compiler fails after the plan's two warnings (its last commands come after the end): the count still closes
    the run, the error that ended it one error."""
    from conftest import cotwin_in_process

    failed = cotwin_in_process("run", EXAMPLES / "ur5e" / "cotwin.toml", "--end", "6", "--cc", "false",
                               "-o", tmp_path / "out", cwd=tmp_path)
    assert failed.returncode == 1 and "error: the C compiler 'false' failed" in failed.stderr, failed.stderr
    said = sum(": warning: " in line for line in failed.stderr.splitlines())
    assert said == 2 and failed.stderr.strip().splitlines()[-1] == "1 error(s), 2 warning(s)", failed.stderr


def test_a_live_twin_that_fails_closes_with_its_count_as_a_run_does(tmp_path):
    """`cotwin twin` printed no closing count, nor when it failed. The turtlebot's live twin at --step 0.01 warns
    that its d-model counts time in cycles, then cannot reach its plant: the warning and the error counted."""
    from conftest import cotwin_in_process

    copy = tmp_path / "turtlebot"
    shutil.copytree(EXAMPLES / "turtlebot", copy)
    absent = "opc.tcp://127.0.0.1:9"  # the discard port: nothing listens there
    failed = cotwin_in_process("twin", copy / "live.toml", "-o", tmp_path / "out", "--pt-url", absent,
                               "--step", "0.01", "--end", "0.1")
    assert failed.returncode == 1 and "failed connect" in failed.stderr, failed.stderr
    assert "warning: the d-model counts time in cycles" in failed.stderr
    assert failed.stderr.strip().splitlines()[-1] == "1 error(s), 1 warning(s)", failed.stderr


def test_a_live_twin_closes_with_how_many_errors_and_warnings_it_had(tmp_path):
    """`cotwin twin` ended on its outcomes with no count, where `cotwin run` closes with one: the plan's four
    commands come after the half second replayed, each warned of, and counted."""
    from conftest import cotwin_in_process

    log = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"
    if not log.is_file():
        pytest.skip(f"the recorded UR5e run is not at {log} (only in the project workspace)")
    twin = cotwin_in_process("twin", EXAMPLES / "ur5e" / "replay.toml", "-o", tmp_path / "out", "--end", "0.5",
                             "--pt-log", log, cwd=tmp_path)
    assert twin.returncode == 0, twin.stderr
    said = sum("warning:" in line for line in twin.stderr.splitlines())
    assert said == 4 and twin.stderr.strip().splitlines()[-1] == "0 error(s), 4 warning(s)", twin.stderr
