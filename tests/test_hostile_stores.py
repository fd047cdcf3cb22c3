"""The twin's stores and servers as a hostile neighbour meets them: a long run read by many pages at once,
clients that never finish a request, another application's table or exchange of the twin's names in the
shared PostgreSQL and RabbitMQ. The real services on 127.0.0.1, with names of their own."""

from __future__ import annotations

import json
import socket
import sqlite3
import time
import urllib.error
import urllib.request
import uuid
from dataclasses import replace
from pathlib import Path

import pytest

from cotwin.diagnostics import CotwinError
from cotwin.twin.services.dashboard import Dashboard
from cotwin.twin.services.dashboard.app import MAX_CONNECTIONS
from cotwin.twin.services.history import HistoryRecorder, list_runs, read_run

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["{mapping}.mapping.q0", "{mapping}.mapping.q1"]


def _long_run(path: Path, count: int) -> tuple[str, int]:
    """A store holding one run of `count` samples per side (and as many commands), written in bulk."""
    from cotwin.twin.services.history import commands, samples

    url = f"sqlite:///{path}"
    recorder = HistoryRecorder(url, "p.toml", "twin", 0.01, "jacobi", {"pt": COLUMNS, "dt": COLUMNS})
    rows = [{"run": recorder.run_id, "side": side, "step": k, "time": k * 0.01, "wall": 0.0,
             "values": json.dumps([k * 1.0, -k * 1.0])} for side in ("pt", "dt") for k in range(count)]
    with recorder.engine.begin() as conn:
        conn.execute(samples.insert(), rows)
        conn.execute(commands.insert(), [{"run": recorder.run_id, "step": k, "time": k * 0.01, "wall": 0.0,
                                          "port": "go", "value": "true"} for k in range(count)])
    recorder.close()
    return url, recorder.run_id


def _get(url: str, timeout: float = 60) -> tuple[int, dict | str]:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        body = err.read()
        try:
            return err.code, json.loads(body)
        except ValueError:
            return err.code, body.decode("utf-8", "replace")


def test_a_long_run_is_read_in_bounded_pages(tmp_path):
    url, run = _long_run(tmp_path / "history.sqlite", 20_000)
    data = read_run(url, run, max_points=500, max_events=100)
    for side in ("pt", "dt"):
        times = [t for t, _ in data["samples"][side]]
        assert len(times) <= 500 and times[0] == 0.0 and times[-1] == pytest.approx(199.99)  # first and last kept
        gaps = {round(b - a, 6) for a, b in zip(times, times[1:-1])}
        assert len(gaps) == 1  # evenly spaced
        assert all(values == [pytest.approx(t * 100), pytest.approx(-t * 100)] for t, values in data["samples"][side])
    assert data["counts"] == {"pt": 20_000, "dt": 20_000, "commands": 20_000, "states": 0, "alarms": 0,
                              "corrections": 0}
    assert len(data["commands"]) == 100 and data["commands"][0]["step"] == 0
    with Dashboard(None, port=0, mode="history", history_url=url) as dash:
        code, page = _get(dash.url + f"api/history/{run}")
    assert code == 200 and len(page["sides"]["dt"]["time"]) <= 4001 and page["counts"]["dt"] == 20_000
    assert len(page["sides"]["dt"]["values"]["q0"]) == len(page["sides"]["dt"]["time"])
    full = read_run(url, run)  # unbounded, as an export or a test asks for it
    assert len(full["samples"]["dt"]) == 20_000 and len(full["commands"]) == 20_000


def test_a_client_that_never_finishes_its_request_head_is_closed_and_the_page_served_again(tmp_path):
    url, _ = _long_run(tmp_path / "history.sqlite", 10)
    dash = Dashboard(None, port=0, mode="history", history_url=url)
    dash.header_seconds = 1.0
    with dash:
        held = [socket.create_connection(("127.0.0.1", dash.port)) for _ in range(MAX_CONNECTIONS + 10)]
        for sock in held[:20]:
            sock.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # a head that never ends
        try:
            started = time.monotonic()
            code = 0
            while code != 200 and time.monotonic() - started < 15:
                try:
                    code = _get(dash.url + "api/status", timeout=5)[0]
                except OSError:
                    code = 0
                time.sleep(0.2)
            assert code == 200  # once the idle ones are closed, the page is served again
            sock = held[0]
            sock.settimeout(5)
            answer = sock.recv(200)
            assert answer.startswith(b"HTTP/1.1 408") and sock.recv(200) == b""  # told why, then closed
            # a client sending its head one byte at a time gets the same time in all, not per byte
            slow = socket.create_connection(("127.0.0.1", dash.port))
            slow.settimeout(5)
            started = time.monotonic()
            closed = False
            for byte in b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX: " + b"y" * 100:
                try:
                    slow.sendall(bytes([byte]))
                except OSError:
                    closed = True
                    break
                time.sleep(0.1)
            assert closed or slow.recv(200).startswith(b"HTTP/1.1 408")
            assert time.monotonic() - started < 10
        finally:
            for sock in held:
                sock.close()


# ---- another application's names ------------------------------------------------------------------

@pytest.fixture
def postgres(postgres_database):
    """A fresh database on the loopback PostgreSQL, dropped afterwards (conftest.postgres_database)."""
    return postgres_database


def test_another_applications_runs_table_in_postgresql_is_left_alone(postgres, tmp_path):
    import psycopg

    from cotwin.twin.services.history import database_url, export_csv

    url, name = postgres
    with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}", autocommit=True) as conn:
        conn.execute("CREATE TABLE runs (id serial PRIMARY KEY, batch text NOT NULL)")
        conn.execute("CREATE TABLE samples (id serial PRIMARY KEY, reading real)")
        conn.execute("INSERT INTO runs (batch) VALUES ('lot 7')")
    store = database_url(url)
    recorder = HistoryRecorder(store, "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS})
    recorder.record_sample("dt", 0, 0.0, [0.5, 1.5])
    recorder.close()
    [run] = list_runs(store)
    assert run["samples"] == 1 and run["status"] == "done"
    assert read_run(store, run["id"])["samples"]["dt"] == [(0.0, [0.5, 1.5])]
    export_csv(store, run["id"], "dt", tmp_path / "dt.csv")
    assert (tmp_path / "dt.csv").read_text().splitlines()[1] == "0.0,0.5,1.5"
    with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}") as conn:
        assert conn.execute("SELECT batch FROM public.runs").fetchall() == [("lot 7",)]  # theirs, untouched
        assert conn.execute("SELECT count(*) FROM cotwin.runs").fetchone() == (1,)  # ours, beside it


def test_a_store_of_cotwins_tables_in_public_is_still_read(postgres):
    """A store written before cotwin had a schema of its own: its tables are in `public`."""
    import psycopg

    from cotwin.twin.services.history import database_url, metadata

    url, name = postgres
    store = database_url(url)
    import sqlalchemy as sa

    engine = sa.create_engine(store)
    metadata.create_all(engine)  # as the recorder did, in public
    with engine.begin() as conn:
        conn.execute(sa.text("INSERT INTO runs (project, kind, started, status, step, algorithm, columns) VALUES "
                             "('old.toml', 'twin', 0, 'done', 0.1, 'jacobi', '{\"dt\": [\"x\"]}')"))
    engine.dispose()
    [run] = list_runs(store)
    assert run["project"] == "old.toml"
    with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}") as conn:
        assert conn.execute("SELECT count(*) FROM information_schema.schemata WHERE schema_name = 'cotwin'"
                            ).fetchone() == (0,)  # reading made nothing


def test_a_sqlite_file_of_another_application_is_named_not_written(tmp_path):
    path = tmp_path / "app.db"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE runs (id INTEGER PRIMARY KEY, batch TEXT)")
        db.execute("INSERT INTO runs (batch) VALUES ('lot 7')")
    for attempt in (lambda: HistoryRecorder(f"sqlite:///{path}", "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS}),
                    lambda: list_runs(f"sqlite:///{path}"), lambda: read_run(f"sqlite:///{path}", 1)):
        with pytest.raises(CotwinError, match="has a table 'runs' that is not cotwin's \\(it has no column project"):
            attempt()
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall() == [("runs",)]


def test_history_list_of_a_store_without_runs_says_so_and_fails(tmp_path):
    """An empty file, or a SQLite database of other tables, listed nothing and exited 0: as if it held no run
    of a store that does. It says there is no run (exit 1), and leaves the file as it was."""
    from conftest import cotwin_in_process

    empty = tmp_path / "empty.db"
    empty.write_bytes(b"")
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE t (x)")
    for path in (empty, other):
        before = path.read_bytes()
        proc = cotwin_in_process("history", "list", "--db", f"sqlite:///{path}")
        assert proc.returncode == 1 and proc.stdout == "", proc.stdout
        assert f"no run in the history database sqlite:///{path}" in proc.stderr
        assert path.read_bytes() == before


def test_a_predeclared_exchange_of_another_type_is_a_located_error(broker, tmp_path):
    from cotwin.mapping.amqp import connect
    from cotwin.twin.project import RabbitMQSettings
    from cotwin.twin.services.publisher import Publisher
    from cotwin.twin.assembly.rabbitmq import RabbitMQBridge
    from cotwin.twin.assembly.run import load

    name = f"cotwin_fanout_{uuid.uuid4().hex[:8]}"
    link = connect("amqp://127.0.0.1:5672/%2F", "cotwin test another application")
    channel = link.channel()
    channel.exchange_declare(name, exchange_type="fanout")
    channel.exchange_declare(name + ".events", exchange_type="direct")
    why = f"the exchange '{name}' exists already and is not the direct exchange cotwin uses (it is a fanout exchange"
    try:
        with pytest.raises(CotwinError, match=r"\[scenario\] rabbitmq exchange, or --rabbitmq") as refused:
            RabbitMQBridge(RabbitMQSettings(name)).start()
        assert why in str(refused.value)
        with pytest.raises(CotwinError, match="fanout exchange"):
            Publisher(RabbitMQSettings(name), [], {}).run()
        system = load(ROOT / "examples" / "ur5e" / "live.toml")
        system.spec.rabbitmq = replace(system.spec.rabbitmq, exchange=name)
        with pytest.raises(CotwinError, match="cannot publish commands .*fanout exchange"):
            Dashboard(system, port=0, mode="twin").start()
        from cotwin.twin.services.whatif import WhatIfService

        with pytest.raises(CotwinError, match=r"not the topic exchange cotwin uses \(it is a direct exchange.*"
                                              r"\[deviation\] exchange"):
            WhatIfService("amqp://127.0.0.1:5672/%2F", name + ".events", ROOT / "examples" / "ur5e" / "live.toml")
    finally:
        channel.exchange_delete(name)
        channel.exchange_delete(name + ".events")
        link.close()


@pytest.mark.parametrize("args", [("twin", "examples/ur5e/replay.toml", "-o", "{out}", "--history"),
                                  ("fleet", "fleet.toml", "-o", "{out}", "--history"),
                                  ("history", "list", "--db"), ("dashboard", "--db")])
@pytest.mark.parametrize("url, message", [
    ("sqlite://", "'sqlite://' is not a sqlite:///FILE or postgresql://... URL"),
    ("sqlite:///:memory:", "'sqlite:///:memory:' is a database in memory, lost when the command ends"),
    ("history.sqlite", "'history.sqlite' is not a sqlite:///FILE"),
])
def test_a_history_url_option_in_memory_or_of_another_scheme_is_refused_at_the_option(tmp_path, args, url, message):
    """`cotwin twin --history sqlite://` ran, recorded its run in memory (a traceback from SQLAlchemy's pool on
    stderr) and lost it at exit; `foo://x` or a bare file name ran the models first and ended on SQLAlchemy's
    words. Every history URL option is checked as the project's [history] url is, before anything runs."""
    from conftest import cotwin_in_process

    proc = cotwin_in_process(*(a.format(out=tmp_path / "out") for a in args), url, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    option = args[-1]
    assert f"Invalid value for '{option}': {message}" in proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


def test_a_projects_history_url_in_memory_is_refused_at_its_key(tmp_path):
    from cotwin.twin.project import load_project

    project = tmp_path / "p.toml"
    text = (ROOT / "examples/ur5e/cotwin.toml").read_text().replace('"arm.rst"', f'"{ROOT}/examples/ur5e/arm.rst"')
    for name in ("ur5e.pm", "mapping.pm", "plan.csv", "ur.profile.toml"):
        text = text.replace(f'"{name}"', f'"{ROOT}/examples/ur5e/{name}"')
    project.write_text(text + '\n[history]\nurl = "sqlite:///"\n')
    with pytest.raises(CotwinError, match=r"p.toml:\d+:\d+: .*'sqlite:///' is a database in memory"):
        load_project(project)


def test_a_store_another_writer_holds_locked_is_a_located_error_before_the_run(tmp_path):
    """A SQLite store another process holds a write lock on (or a read-only one) raised SQLAlchemy's
    OperationalError from the recorder: `cotwin twin` called it a cotwin bug (exit 70)."""
    path = tmp_path / "h.sqlite"
    HistoryRecorder(f"sqlite:///{path}", "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS}).close()
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")  # another writer's transaction
    try:
        with pytest.raises(CotwinError, match=f"cannot write the history database sqlite:///{path}: "
                                              "OperationalError: .*database is locked"):
            HistoryRecorder(f"sqlite:///{path}", "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS})
    finally:
        holder.execute("ROLLBACK")
        holder.close()


def test_a_store_lost_midway_is_said_not_raised(postgres):
    """A PostgreSQL store that went away during the run (here: dropped) made `close()` raise, and the twin
    ended with an internal error instead of its summary and figure; records lost on the way were not said."""
    import psycopg

    from cotwin.twin.services.history import database_url

    url, name = postgres
    recorder = HistoryRecorder(database_url(url), "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS}, batch_seconds=0.05)
    recorder.record_sample("dt", 0, 0.0, [0.5, 1.5])
    time.sleep(0.3)
    with psycopg.connect("host=127.0.0.1 user=postgres dbname=postgres", autocommit=True) as conn:
        conn.execute(f'DROP DATABASE "{name}" WITH (FORCE)')
    recorder.record_sample("dt", 1, 0.1, [0.6, 1.6])
    time.sleep(0.3)
    recorder.close()
    assert recorder.problem is not None
    assert recorder.problem.startswith(f"the history of run {recorder.run_id} in postgresql+psycopg://postgres@"
                                       f"127.0.0.1:5432/{name} is incomplete (1 record(s) not written, the first "
                                       "failure: OperationalError")


def test_a_twin_whose_store_failed_midway_says_its_history_is_incomplete(postgres, tmp_path):
    """The twin's connection to its PostgreSQL store cut during the run: the records of that batch were lost,
    the run was marked incomplete in the store, but `cotwin twin` printed its usual summary and exited 0."""
    import threading

    import psycopg

    from conftest import cotwin_in_process

    url, name = postgres
    log = ROOT.parent / "shared" / "data" / "ur5e" / "rtde_run1.csv"
    if not log.is_file():
        pytest.skip(f"the recorded UR5e run is not at {log} (only in the project workspace)")

    def cut() -> None:  # once samples arrive, end the twin's sessions (as a restarted server or a network cut does)
        with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}", autocommit=True) as conn:
            for _ in range(600):
                if conn.execute("SELECT to_regclass('cotwin.samples') IS NOT NULL").fetchone()[0] and \
                        conn.execute("SELECT count(*) FROM cotwin.samples").fetchone()[0] > 0:
                    break
                time.sleep(0.1)
            conn.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = %s AND "
                         "pid <> pg_backend_pid()", (name,))

    cutter = threading.Thread(target=cut)
    cutter.start()
    proc = cotwin_in_process("twin", ROOT / "examples/ur5e/replay.toml", "-o", tmp_path / "out", "--end", "4",
                             "--realtime", "--pt-log", log, "--history", url)
    cutter.join()
    assert proc.returncode == 1, proc.stderr
    assert "is incomplete (" in proc.stderr and "the run's outputs in" in proc.stderr, proc.stderr
    assert (tmp_path / "out" / "pt" / "outputs.csv").is_file() and (tmp_path / "out" / "figure.png").is_file()


def test_twins_starting_together_on_a_new_postgresql_store_all_record(postgres):
    """Three `cotwin twin` started at once on a new PostgreSQL database: one or two failed with a unique
    violation in PostgreSQL's catalogue ("pg_type_typname_nsp_index"), since CREATE SCHEMA/TABLE IF NOT EXISTS
    run by sessions at the same moment is not safe; the makers of the tables take turns now."""
    import threading

    import psycopg

    from cotwin.twin.services.history import database_url

    url, name = postgres
    for _ in range(3):  # a race: a few rounds on a store made anew
        with psycopg.connect(f"host=127.0.0.1 user=postgres dbname={name}", autocommit=True) as conn:
            conn.execute("DROP SCHEMA IF EXISTS cotwin CASCADE")
        start, failures, recorders = threading.Barrier(8), [], []

        def record() -> None:
            start.wait()
            try:
                recorders.append(HistoryRecorder(database_url(url), "p.toml", "twin", 0.1, "jacobi", {"dt": COLUMNS}))
            except CotwinError as err:
                failures.append(str(err))

        threads = [threading.Thread(target=record) for _ in range(8)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        for recorder in recorders:
            recorder.close()
        assert failures == [] and len(recorders) == 8


@pytest.mark.parametrize("command", [("history", "list"), ("history", "export", "1", "-o", "{tmp}/e.csv"), ("dashboard",)])
def test_a_store_given_twice_is_refused_not_half_ignored(tmp_path, command):
    """--db and --dir together: --db was read and --dir ignored without a word (history export wrote another
    store's run 1)."""
    from conftest import cotwin_in_process

    url, _ = _long_run(tmp_path / "history.sqlite", 3)
    other, _ = _long_run(tmp_path / "other.sqlite", 5)
    proc = cotwin_in_process(*(a.format(tmp=tmp_path) for a in command), "--db", other, "--dir", tmp_path)
    assert proc.returncode == 2 and "give --db URL or --dir DIR" in proc.stderr and "one of them" in proc.stderr
    assert not (tmp_path / "e.csv").exists()
