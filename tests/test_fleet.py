"""Fleets of twins (cotwin fleet): located errors in fleet files, a fleet of 8 on Ray whose one twin fails and
is restarted from its last saved state while the others finish, and the overview page answering with each
twin's state. The one test on Ray starts its own on 127.0.0.1 and stops it at its end."""

from __future__ import annotations

import math
import os
import signal
import threading
import time
import urllib.request
from pathlib import Path

import pytest

from conftest import machine_lock
from cotwin.diagnostics import CotwinError

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ROOT / "examples" / "ur5e" / "replay.toml"


def write_log(path: Path, span: float = 12.0) -> Path:
    """An RTDE log of a UR5e at rest for 1 s, then moving its joints smoothly (10 Hz samples)."""
    header = "timestamp " + " ".join(f"actual_q_{k}" for k in range(6)) + " " + \
        " ".join(f"actual_qd_{k}" for k in range(6))
    home = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
    lines = [header]
    for n in range(int(span * 10) + 1):
        t = n / 10
        s = max(0.0, t - 1.0)
        q = [h + 0.3 * math.sin(0.5 * s) * (1 if k % 2 else -1) for k, h in enumerate(home)]
        qd = [0.15 * math.cos(0.5 * s) * (1 if k % 2 else -1) * (s > 0) for k in range(6)]
        lines.append(f"{t:.3f} " + " ".join(f"{v:.6f}" for v in q + qd))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def ray_local():
    """A local Ray for one test, the machine's only one meanwhile (conftest.machine_lock): held for the module,
    it kept every other test process's Ray test waiting through this file's long tests without Ray, that wait
    counted in its timeout."""
    ray = pytest.importorskip("ray")
    with machine_lock("ray"):
        ray.init(address="local", _node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=2,
                 logging_level="ERROR", log_to_driver=False, configure_logging=False)
        yield ray
        ray.shutdown()


def fleet_file(tmp: Path, twins: list[dict], fleet: str = "checkpoint_every = 5\nmax_restarts = 2\nrestart_delay = 0.2\n") -> Path:
    text = f"[fleet]\n{fleet}\n"
    for t in twins:
        text += "[[twin]]\n" + "".join(f"{k} = {v!r}\n".replace("'", '"') if not isinstance(v, bool) else
                                       f"{k} = {str(v).lower()}\n" for k, v in t.items()) + "\n"
    path = tmp / "fleet.toml"
    path.write_text(text)
    return path


@pytest.mark.timeout(900)  # its time includes waiting for the other Ray test (conftest.machine_lock)
def test_fleet_of_8_restarts_a_failed_twin_from_its_saved_state(tmp_path, ray_local):
    """One twin's process is killed mid-run (by PID): the supervisor says so, restarts it from its last saved
    state (not from 0) and it ends where an uninterrupted twin of the same project ends; the 7 others finish."""
    from cotwin.twin.analysis.fleet.record import fleet_events
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet

    log = write_log(tmp_path / "run.csv")
    twins = [{"name": f"arm-{k}", "project": str(PROJECT), "pt_log": str(log), "end": 3.0} for k in range(7)]
    twins.append({"name": "victim", "project": str(PROJECT), "pt_log": str(log), "end": 3.0, "realtime": True})
    spec = read_fleet(fleet_file(tmp_path, twins))
    said: list[str] = []
    fleet = Fleet(spec, tmp_path / "out", ray="auto", say=said.append)
    result: dict = {}
    runner = threading.Thread(target=lambda: result.update(fleet.run()))
    runner.start()
    killed = None
    deadline = time.monotonic() + 240
    while runner.is_alive() and time.monotonic() < deadline and killed is None:
        victim = next(t for t in fleet.overview()["twins"] if t["name"] == "victim")
        if victim["state"] == "running" and (victim.get("checkpoint_time") or 0) >= 1.0 and victim.get("pid"):
            killed = victim["checkpoint_time"]
            os.kill(victim["pid"], signal.SIGKILL)
        time.sleep(0.05)
    runner.join(240)
    assert killed is not None, "the victim never ran past its first saved states"
    twins_by = {t["name"]: t for t in result["twins"]}
    assert all(twins_by[f"arm-{k}"]["state"] == "done" and twins_by[f"arm-{k}"]["restarts"] == 0 for k in range(7))
    victim = twins_by["victim"]
    assert victim["state"] == "done" and victim["restarts"] == 1 and victim["time"] == pytest.approx(3.0)
    assert any("twin victim failed" in s and "restarting it from its state saved at t =" in s for s in said), said
    # the restart went on from the saved state: its rows start there, not at 0 ...
    restart = tmp_path / "out" / "victim" / "restart-1" / "dt" / "outputs.csv"
    rows = restart.read_text().splitlines()
    first = float(rows[1].split(",")[0])
    assert first >= killed - 1e-9 and first > 0.5
    # ... and it ends as an uninterrupted twin of the same project does
    here = rows[-1].split(",")
    there = (tmp_path / "out" / "arm-0" / "dt" / "outputs.csv").read_text().splitlines()[-1].split(",")
    assert here[0] == there[0]
    assert [float(v) for v in here[1:] if v not in ("true", "false", "")] == \
        pytest.approx([float(v) for v in there[1:] if v not in ("true", "false", "")], abs=1e-6)
    events = [(e["twin"], e["event"]) for e in fleet_events(f"sqlite:///{tmp_path / 'out' / 'history.sqlite'}")]
    assert ("victim", "failed") in events and ("victim", "restarting") in events
    assert sum(1 for e in events if e[1] == "done") == 8


def test_overview_page_answers_with_each_twins_state(tmp_path):
    """The page (HTML and JSON) names every twin with its state while the fleet runs; a foreign Host is refused."""
    from cotwin.twin.analysis.fleet.page import FleetPage
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet

    log = write_log(tmp_path / "run.csv")
    spec = read_fleet(fleet_file(tmp_path, [
        {"name": "a", "project": str(PROJECT), "pt_log": str(log), "end": 1.0, "dashboard": "127.0.0.1:0"},
        {"name": "b", "project": str(PROJECT), "pt_log": str(log), "end": 1.0}]))
    fleet = Fleet(spec, tmp_path / "out", ray=None)
    page = FleetPage(fleet.overview, "127.0.0.1", 0).start()
    try:
        import json

        before = json.load(urllib.request.urlopen(page.url + "api/fleet", timeout=10))
        assert {t["name"]: t["state"] for t in before["twins"]} == {"a": "starting", "b": "starting"}
        fleet.run()
        after = json.load(urllib.request.urlopen(page.url + "api/fleet", timeout=10))
        assert {t["name"]: t["state"] for t in after["twins"]} == {"a": "done", "b": "done"}
        assert all(t["time"] == pytest.approx(1.0) and t["real_time_factor"] > 0 for t in after["twins"])
        links = {t["name"]: t["page"] for t in after["twins"]}
        assert links["a"].startswith("http://127.0.0.1:") and links["b"] is None  # a's own page, served while it ran
        text = urllib.request.urlopen(page.url, timeout=10).read().decode()
        assert f'<a href="{links["a"]}">open</a>' in text
        assert 'data-twin="a"' in text and 'data-twin="b"' in text and ">done<" in text
        foreign = urllib.request.Request(page.url + "api/fleet", headers={"Host": "198.51.100.7:80"})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(foreign, timeout=10)
        assert refused.value.code == 403
    finally:
        page.stop()


@pytest.mark.parametrize("entry, fleet, where, message", [
    ({"name": "a", "project": "nowhere.toml"}, "", (5, 1), "twin 'a': no project file"),
    ({"name": "a b", "project": str(PROJECT)}, "", (4, 1), "is not a twin name"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "missing.csv"}, "", (6, 1), "no log file"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "LOG", "end": 1.05}, "", (7, 1), "is not a whole number"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "LOG", "realtime": "yes"}, "", (7, 1), "true or false"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "LOG", "pt_url": "opc.tcp://127.0.0.1:4840"}, "", (7, 1),
     "pt_url and pt_log name two different PTs"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "LOG", "colour": "red"}, "", (7, 1), "unknown key 'colour'"),
    ({"name": "a", "project": str(PROJECT), "pt_log": "LOG"}, "max_restarts = -1\n", (2, 1), "max_restarts"),
])
def test_bad_fleet_files_give_located_errors(tmp_path, entry, fleet, where, message):
    from cotwin.twin.analysis.fleet.spec import read_fleet

    log = write_log(tmp_path / "run.csv", span=2.0)
    entry = {k: (str(log) if v == "LOG" else v) for k, v in entry.items()}
    path = fleet_file(tmp_path, [entry], fleet)
    with pytest.raises(CotwinError) as err:
        read_fleet(path)
    found = [f for f in err.value.findings if message in f.message]
    assert found, [str(f) for f in err.value.findings]
    assert found[0].location.path == str(path) and (found[0].location.line, found[0].location.column) == where


def test_a_twin_named_twice_and_a_projects_own_problems_are_located(tmp_path):
    from cotwin.twin.analysis.fleet.spec import read_fleet

    log = write_log(tmp_path / "run.csv", span=2.0)
    broken = tmp_path / "broken.toml"
    broken.write_text(PROJECT.read_text().replace('step = 0.1', 'step = "fast"'))
    path = fleet_file(tmp_path, [{"name": "a", "project": str(PROJECT), "pt_log": str(log)},
                                 {"name": "a", "project": str(PROJECT), "pt_log": str(log)},
                                 {"name": "c", "project": str(broken), "pt_log": str(log)}])
    with pytest.raises(CotwinError) as err:
        read_fleet(path)
    said = [str(f) for f in err.value.findings]
    assert any(s.startswith(f"{path}:12:1:") and "already the name of twin 1" in s for s in said), said
    assert any(s.startswith(f"{path}:18:1:") and "twin 'c': its project" in s for s in said), said
    assert any(s.startswith(f"{broken}:") and "step" in s for s in said), said


def test_each_twins_alarms_go_to_the_broker_under_its_own_name(tmp_path, broker):
    """Alarms of a fleet's twins reach the broker with a routing key naming the twin, and say its name."""
    import json
    import uuid

    from cotwin.mapping.amqp import connect, declare_exchange
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet

    url = "amqp://127.0.0.1:5672/%2F"
    tag = uuid.uuid4().hex[:8]
    log = write_log(tmp_path / "run.csv", span=6.0)
    names = [f"left-{tag}", f"right-{tag}"]
    spec = read_fleet(fleet_file(tmp_path, [{"name": n, "project": str(PROJECT), "pt_log": str(log), "end": 5.0}
                                            for n in names], fleet=f'alarms = "{url}"\n'))
    connection = connect(url, "fleet test")
    try:
        channel = connection.channel()
        declare_exchange(channel, "cotwin.twin", "topic", url, "the test")
        queue = channel.queue_declare("", exclusive=True).method.queue
        for name in names:  # its own twins' only: under make test's workers, other tests' twins raise alarms there too
            channel.queue_bind(queue, "cotwin.twin", routing_key=f"twin.alarm.{name}")
        summary = Fleet(spec, tmp_path / "out", ray=None).run()
        assert all(t["state"] == "done" for t in summary["twins"])
        raised = {t["name"]: t["alarms"] for t in summary["twins"]}
        assert all(raised[n] > 0 for n in names), raised  # the generated PT strays from the plan's DT
        got: dict[str, list] = {}
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and sum(len(v) for v in got.values()) < sum(raised.values()):
            method, _, body = channel.basic_get(queue, auto_ack=True)
            if method is None:
                time.sleep(0.1)
                continue
            event = json.loads(body)
            got.setdefault(method.routing_key, []).append(event["twin"])
        for name in names:
            assert got.get(f"twin.alarm.{name}") == [name] * raised[name], got
    finally:
        connection.close()


def test_the_command_reports_a_bad_fleet_file_at_its_place_without_a_traceback(tmp_path):
    import subprocess
    import sys

    path = fleet_file(tmp_path, [{"name": "a", "project": "nowhere.toml"}])
    done = subprocess.run([sys.executable, "-m", "cotwin", "fleet", str(path), "-o", str(tmp_path / "out"), "--ray", "off"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert f"{path}:8:1: error: twin 'a': no project file" in done.stderr and "Traceback" not in done.stderr


def test_a_twin_whose_plant_is_killed_is_restarted_once_the_plant_is_back(tmp_path, monkeypatch):
    """The PT of one twin is an OPC UA plant, killed by PID mid-run and served again: the supervisor restarts
    that twin (afresh, saying why: a remote PT cannot save its state) and it finishes, as does the other."""
    import socket
    import subprocess
    import sys

    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet

    pytest.importorskip("asyncua")
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))  # the plants' operator credentials, read by the twin
    cell = ROOT / "examples" / "ur5e" / "twin.toml"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        url = f"opc.tcp://127.0.0.1:{s.getsockname()[1]}"
    cotwin = str(Path(sys.executable).parent / "cotwin")

    def serve() -> subprocess.Popen:
        plant = subprocess.Popen([cotwin, "plant", str(cell), "--opcua", url, "--reset-on-connect"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = plant.stdout.readline()
        assert line.startswith("serving"), line + plant.stderr.read()
        return plant

    log = write_log(tmp_path / "run.csv")
    spec = read_fleet(fleet_file(tmp_path, [
        {"name": "cell", "project": str(cell), "pt_url": url, "end": 4.0, "realtime": True},
        {"name": "arm", "project": str(PROJECT), "pt_log": str(log), "end": 2.0}],
        fleet="checkpoint_every = 5\nmax_restarts = 15\nrestart_delay = 2.0\n"))  # a plant starts in seconds
    said: list[str] = []
    plants = [serve()]
    try:
        fleet = Fleet(spec, tmp_path / "out", ray=None, say=said.append)
        result: dict = {}
        runner = threading.Thread(target=lambda: result.update(fleet.run()))
        runner.start()
        deadline = time.monotonic() + 120
        while runner.is_alive() and time.monotonic() < deadline:
            twin = next(t for t in fleet.overview()["twins"] if t["name"] == "cell")
            if twin["state"] == "running" and (twin.get("time") or 0) >= 1.0:
                break
            time.sleep(0.05)
        plants[0].kill()
        plants[0].wait(10)
        plants.append(serve())
        runner.join(180)
        twins = {t["name"]: t for t in result["twins"]}
        assert twins["arm"]["state"] == "done" and twins["arm"]["restarts"] == 0
        assert twins["cell"]["state"] == "done" and twins["cell"]["restarts"] >= 1, twins["cell"]
        assert any("twin cell failed" in s and "restarting it afresh (its states cannot be saved" in s for s in said), said
        assert (tmp_path / "out" / "cell" / f"restart-{twins['cell']['restarts']}" / "dt" / "outputs.csv").is_file()
    finally:
        for plant in plants:
            plant.kill()
            plant.wait(10)
            plant.stdout.close()
            plant.stderr.close()


def test_without_ray_the_fleet_names_the_extra_and_the_way_without_it(monkeypatch):
    import sys

    from cotwin.twin.analysis.fleet.supervisor import RayHosts

    monkeypatch.setitem(sys.modules, "ray", None)  # as where the ray extra is not installed
    with pytest.raises(CotwinError, match=r"pip install 'cotwin\[ray\]'.*--ray off"):
        RayHosts("auto")


def test_a_fleet_records_into_one_postgresql_store(tmp_path, postgres_database):
    """Every twin's run and the fleet's own events go to the one PostgreSQL store the fleet names."""
    from cotwin.twin.analysis.fleet.record import fleet_events
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet
    from cotwin.twin.services.history import database_url, list_runs

    url, _ = postgres_database
    log = write_log(tmp_path / "run.csv", span=3.0)
    spec = read_fleet(fleet_file(tmp_path, [{"name": n, "project": str(PROJECT), "pt_log": str(log), "end": 1.0}
                                            for n in ("a", "b")], fleet=f'history = "{url}"\n'))
    summary = Fleet(spec, tmp_path / "out", ray=None).run()
    assert all(t["state"] == "done" for t in summary["twins"])
    assert not (tmp_path / "out" / "history.sqlite").exists()
    runs = list_runs(database_url(url))
    events = fleet_events(database_url(url))
    assert {e["twin"] for e in events if e["event"] == "done"} == {"a", "b"}
    assert {e["run"] for e in events if e["event"] == "done"} == {r["id"] for r in runs}


def test_every_project_problem_of_a_fleet_names_its_twin_and_a_duplicate_entry_is_still_checked(tmp_path):
    """A project's problems are located in the project file and each says which twin (and which entry of
    the fleet file) it belongs to, whatever order they are printed in; an entry with a wrong key or a name
    given twice still has its project checked (fixing the name must not reveal a new round of errors)."""
    from cotwin.twin.analysis.fleet.spec import read_fleet

    log = write_log(tmp_path / "run.csv", span=2.0)
    broken = tmp_path / "broken.toml"
    broken.write_text(PROJECT.read_text().replace('step = 0.1', 'step = "fast"')
                      .replace("[platform]", "[scene]\ncolour = 1\n\n[platform]\nscene = \"floor\"", 1))
    path = fleet_file(tmp_path, [{"name": "a", "project": str(PROJECT), "pt_log": str(log)},
                                 {"name": "a", "project": str(broken), "pt_log": str(log), "realtime": "yes"}])
    with pytest.raises(CotwinError) as err:
        read_fleet(path)
    in_project = [f for f in err.value.findings if f.location.path == str(broken)]
    assert {f.message.split(": ", 1)[1].split(" ")[0] for f in in_project} >= {"[cosim]", "[scene]"}, in_project
    entry = [f for f in err.value.findings if "already the name of twin 1" in f.message][0].location.line
    assert all(f.message.startswith(f"twin 'a' (project of {path}:") for f in in_project), in_project
    assert all(f.location.line > entry for f in err.value.findings if f.location.path == str(path)
               and "its project" in f.message)


def test_the_models_problems_of_every_project_of_a_fleet_come_together_naming_their_twins(tmp_path):
    """Problems found once the models are read ([cosim] log naming no variable) are reported for every
    project at once, each naming the twins of its project; nothing is run."""
    from cotwin.twin.analysis.fleet.spec import read_fleet
    from cotwin.twin.analysis.fleet.supervisor import Fleet

    import shutil

    log = write_log(tmp_path / "run.csv", span=2.0)
    shutil.copytree(PROJECT.parent, tmp_path / "ur5e")
    projects = []
    for name in ("one", "two"):
        path = tmp_path / "ur5e" / f"{name}.toml"
        path.write_text(PROJECT.read_text().replace("[cosim]", f'[cosim]\nlog = ["no_{name}"]'))
        projects.append(path)
    spec = read_fleet(fleet_file(tmp_path, [{"name": "a", "project": str(projects[0]), "pt_log": str(log)},
                                            {"name": "b", "project": str(projects[1]), "pt_log": str(log)},
                                            {"name": "c", "project": str(projects[0]), "pt_log": str(log)}]))
    with pytest.raises(CotwinError) as err:
        Fleet(spec, tmp_path / "out", ray=None).run()
    said = {f.location.path: f.message for f in err.value.findings}
    assert said[str(projects[0])].startswith("twins 'a', 'c' (") and "no_one" in said[str(projects[0])]
    assert said[str(projects[1])].startswith("twin 'b' (") and "no_two" in said[str(projects[1])]


def test_a_twin_whose_history_store_refuses_its_writes_is_reported_by_name_and_the_others_go_on(tmp_path, postgres_database):
    """The fleet's PostgreSQL store starts refusing one twin's samples mid-run (a trigger raising for that twin's
    run once it holds a few): that twin runs to its end as the other does, and the fleet's summary (fleet.json),
    its messages and its exit status say that this twin's history is incomplete and why."""
    import json
    import shutil
    import subprocess
    import sys
    import psycopg

    from cotwin.twin.services.history import create_tables, database_url, engine_for

    url, name = postgres_database
    engine = engine_for(database_url(url))
    create_tables(engine)
    engine.dispose()
    with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}", autocommit=True) as conn:
        conn.execute("""CREATE FUNCTION cotwin.refuse() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN
            IF NEW.run IN (SELECT id FROM cotwin.runs WHERE project LIKE '%/refused/%')
               AND (SELECT count(*) FROM cotwin.samples WHERE run = NEW.run) >= 4 THEN
                RAISE EXCEPTION 'this store takes no more samples of run %', NEW.run;
            END IF;
            RETURN NEW; END $$""")
        conn.execute("CREATE TRIGGER refuse BEFORE INSERT ON cotwin.samples FOR EACH ROW EXECUTE FUNCTION cotwin.refuse()")
    refused = tmp_path / "refused"  # b's project, by another path than a's: the trigger tells its runs apart
    shutil.copytree(PROJECT.parent, refused)
    log = write_log(tmp_path / "run.csv", span=3.0)
    path = fleet_file(tmp_path, [{"name": "a", "project": str(PROJECT), "pt_log": str(log), "end": 1.5},
                                 {"name": "b", "project": str(refused / PROJECT.name), "pt_log": str(log),
                                  "end": 1.5}])
    done = subprocess.run([sys.executable, "-m", "cotwin", "fleet", str(path), "-o", str(tmp_path / "out"),
                           "--ray", "off", "--history", url], capture_output=True, text=True, timeout=600)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    summary = json.loads((tmp_path / "out" / "fleet.json").read_text())
    twins = {t["name"]: t for t in summary["twins"]}
    assert twins["a"]["state"] == twins["b"]["state"] == "done" and twins["a"]["time"] == twins["b"]["time"]
    assert not twins["a"]["history_problems"]
    [problem] = twins["b"]["history_problems"]
    assert "is incomplete" in problem["message"] and "this store takes no more samples" in problem["message"]
    said = [line for line in done.stderr.splitlines() if line.startswith("twin b: ")]
    assert said and all("history" in line and "this store takes no more samples" in line for line in said)
    assert not any(line.startswith("twin a: ") for line in done.stderr.splitlines())
    assert "incomplete history: b" in done.stderr
    from cotwin.twin.analysis.fleet.record import fleet_events

    assert [e["twin"] for e in fleet_events(database_url(url)) if e["event"] == "history incomplete"] == ["b"]


def test_each_restart_and_give_up_is_said_once_on_the_command_line(tmp_path):
    """The supervisor said a restart in the command's voice and logged it too; with no logging set up the
    logger printed to stderr as well, so every restart and give-up came twice."""
    import subprocess
    import sys

    log = write_log(tmp_path / "run.csv", span=3.0)
    lines = log.read_text().splitlines()
    lines[8] = lines[8].split()[0] + " nan" * 12  # a PT sample that is no number: the twin fails at once
    log.write_text("\n".join(lines) + "\n")
    path = fleet_file(tmp_path, [{"name": "a", "project": str(PROJECT), "pt_log": str(log), "end": 1.5}],
                      fleet="checkpoint_every = 5\nmax_restarts = 1\nrestart_delay = 0.2\n")
    done = subprocess.run([sys.executable, "-m", "cotwin", "fleet", str(path), "-o", str(tmp_path / "out"), "--ray", "off"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
    said = [line for line in done.stderr.splitlines() if line.startswith("twin a failed")]
    assert len(said) == 2 and "restarting it afresh" in said[0] and "given up after 1 restart(s)" in said[1], said


def test_the_fleets_own_events_refused_by_its_store_are_said_and_fail_the_command(tmp_path, postgres_database):
    """The store refuses the fleet's record of a twin's end (a trigger on fleet_twins): the fleet said nothing of
    it (the error was kept "for the end" and never read); now it is said when it happens, in fleet.json and in the
    exit status, and the twin's own outputs and history are whole."""
    import json
    import subprocess
    import sys
    import psycopg

    from cotwin.twin.analysis.fleet.record import metadata
    from cotwin.twin.services.history import create_tables, database_url, engine_for

    url, name = postgres_database
    engine = engine_for(database_url(url))
    create_tables(engine, metadata)
    engine.dispose()
    with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}", autocommit=True) as conn:
        conn.execute("""CREATE FUNCTION cotwin.refuse_end() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN
            IF NEW.event = 'done' THEN RAISE EXCEPTION 'this store takes no ends'; END IF;
            RETURN NEW; END $$""")
        conn.execute("CREATE TRIGGER refuse BEFORE INSERT ON cotwin.fleet_twins FOR EACH ROW EXECUTE FUNCTION cotwin.refuse_end()")
    log = write_log(tmp_path / "run.csv", span=3.0)
    path = fleet_file(tmp_path, [{"name": "a", "project": str(PROJECT), "pt_log": str(log), "end": 1.0}])
    done = subprocess.run([sys.executable, "-m", "cotwin", "fleet", str(path), "-o", str(tmp_path / "out"),
                           "--ray", "off", "--history", url], capture_output=True, text=True, timeout=600)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
    summary = json.loads((tmp_path / "out" / "fleet.json").read_text())
    assert summary["twins"][0]["state"] == "done" and not summary["twins"][0]["history_problems"]
    assert "1 not written" in summary["events_problem"] and "this store takes no ends" in summary["events_problem"]
    said = [line for line in done.stderr.splitlines() if "the fleet's events are incomplete" in line]
    assert len(said) == 2 and "the fleet goes on" in said[0], done.stderr[-3000:]  # when it happened, and at the end
    assert "incomplete history: the fleet's events" in done.stderr
