"""The twin's history: every PT and DT sample (simulated and wall time), command, d-model state change
and alarm of a run, in SQLite (embedded, the default) or PostgreSQL, through SQLAlchemy Core.

Tables: `runs` (one per run), `samples` (run, side, step, time, wall, values as JSON), `commands`,
`states` (d-model state changes) and `alarms` (deviation events). Writes are queued and committed in
batches by a writer thread, so recording never holds the twin up; `close()` waits for the queue.
`export_csv` writes a run's side back as a Maestro-format CSV (what `cotwin history export` does).

Reading never creates or changes a store: a SQLite file that does not exist is an error, not a new empty
database. A run still marked `running` whose newest record (its start, a sample, a command or an alarm)
is older than `STALE_AFTER` seconds is shown as `interrupted` (the process that recorded it ended without
closing it, e.g. killed with SIGKILL); the stored row is left as it is.
"""

from __future__ import annotations

import csv
import json
import queue
import threading
import time as wallclock
from pathlib import Path

import sqlalchemy as sa

from ..cosim.algorithm import UNSET
from ..diagnostics import CotwinError

metadata = sa.MetaData()
runs = sa.Table(
    "runs", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("project", sa.String(1024), nullable=False),
    sa.Column("kind", sa.String(32), nullable=False),  # run | twin
    sa.Column("started", sa.Float, nullable=False),  # wall time (s since the epoch)
    sa.Column("ended", sa.Float),
    sa.Column("status", sa.String(32), nullable=False),  # running | done | failed
    sa.Column("step", sa.Float, nullable=False),
    sa.Column("algorithm", sa.String(32), nullable=False),
    sa.Column("columns", sa.Text, nullable=False),  # JSON: side -> [column names]
    sa.Column("message", sa.Text),
)
samples = sa.Table(
    "samples", metadata,
    sa.Column("run", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
    sa.Column("side", sa.String(8), nullable=False),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("time", sa.Float, nullable=False),
    sa.Column("wall", sa.Float, nullable=False),
    sa.Column("values", sa.Text, nullable=False),  # JSON list in the run's column order
    sa.Index("samples_by_run", "run", "side", "step"),
)
commands = sa.Table(
    "commands", metadata,
    sa.Column("run", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("time", sa.Float, nullable=False),
    sa.Column("wall", sa.Float, nullable=False),
    sa.Column("port", sa.String(256), nullable=False),
    sa.Column("value", sa.Text, nullable=False),
)
states = sa.Table(
    "states", metadata,
    sa.Column("run", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
    sa.Column("side", sa.String(8), nullable=False),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("time", sa.Float, nullable=False),
    sa.Column("machine", sa.String(256), nullable=False),
    sa.Column("state", sa.Integer, nullable=False),
    sa.Column("name", sa.String(256), nullable=False),
)
alarms = sa.Table(
    "alarms", metadata,
    sa.Column("run", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
    sa.Column("time", sa.Float, nullable=False),
    sa.Column("wall", sa.Float, nullable=False),
    sa.Column("variable", sa.String(256), nullable=False),
    sa.Column("state", sa.String(16), nullable=False),
    sa.Column("event", sa.Text, nullable=False),
)


def database_url(url: str | None, folder: Path | None = None) -> str:
    """A SQLAlchemy URL: `postgresql://` uses psycopg 3; the default is DIR/history.sqlite."""
    if url is None:
        if folder is None:
            raise CotwinError("no history database: give a URL (sqlite:///file or postgresql://...)")
        return f"sqlite:///{Path(folder).resolve() / 'history.sqlite'}"
    if url.startswith("postgresql://") or url.startswith("postgres://"):
        return "postgresql+psycopg://" + url.split("://", 1)[1]
    return url


STALE_AFTER = 120.0  # s without a record after which a `running` run is shown as interrupted
MAX_RUN_ID = (1 << 63) - 1  # the largest id SQLite and PostgreSQL store


def engine_for(url: str, create: bool = True) -> sa.Engine:
    """An engine on the store at `url`; with `create=False` (readers) a SQLite file must already exist."""
    if not create:
        _must_exist(url)
    try:
        engine = sa.create_engine(url, future=True)
        with engine.connect():
            pass
    except (sa.exc.SQLAlchemyError, ImportError, ValueError) as err:
        raise CotwinError(f"cannot open the history database {_redact(url)}: {type(err).__name__}: "
                          f"{str(err).splitlines()[0][:200]}") from None
    return engine


def _must_exist(url: str) -> None:
    """CotwinError if `url` is a SQLite file that does not exist (connecting would create it)."""
    try:
        parsed = sa.engine.make_url(url)
    except (sa.exc.ArgumentError, ValueError):
        return  # engine_for reports it
    database = parsed.database or ""
    if parsed.get_backend_name() == "sqlite" and database not in ("", ":memory:") \
            and not database.startswith("file:") and not Path(database).is_file():
        raise CotwinError(f"no history database at {database}")


def _reading(url: str, what):
    """`what(engine)` on the store at `url`, opened for reading; a database error becomes a CotwinError."""
    engine = engine_for(url, create=False)
    try:
        return what(engine)
    except sa.exc.SQLAlchemyError as err:
        raise CotwinError(f"cannot read the history database {_redact(url)}: {type(err).__name__}: "
                          f"{str(err).splitlines()[0][:200]}") from None
    finally:
        engine.dispose()


def _redact(url: str) -> str:
    try:
        return sa.engine.make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001
        return "<history url>"


class HistoryRecorder:
    """Records one run; every `record_*` call is queued and returns at once."""

    def __init__(self, url: str, project: str, kind: str, step: float, algorithm: str,
                 columns: dict[str, list[str]], batch_seconds: float = 0.5):
        self.engine = engine_for(url)
        metadata.create_all(self.engine)
        self.columns = columns
        with self.engine.begin() as conn:
            self.run_id = conn.execute(runs.insert().values(
                project=project, kind=kind, started=wallclock.time(), status="running", step=step,
                algorithm=algorithm, columns=json.dumps(columns))).inserted_primary_key[0]
        self.batch_seconds = batch_seconds
        self._queue: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._write, name="cotwin history", daemon=True)
        self._thread.start()
        self.error: Exception | None = None
        self._last_state: dict[tuple[str, str], int] = {}

    def _write(self) -> None:
        pending: dict[sa.Table, list[dict]] = {}
        done = False
        while not done:
            deadline = wallclock.monotonic() + self.batch_seconds
            while True:
                try:
                    item = self._queue.get(timeout=max(0.0, deadline - wallclock.monotonic()))
                except queue.Empty:
                    break
                if item is None:
                    done = True
                    break
                table, row = item
                if table is samples:
                    row["values"] = json.dumps([None if v is UNSET else v for v in row["values"]])
                pending.setdefault(table, []).append(row)
            if pending:
                try:
                    with self.engine.begin() as conn:
                        for table, rows in pending.items():
                            conn.execute(table.insert(), rows)
                except sa.exc.SQLAlchemyError as err:  # keep the twin running; report at close
                    self.error = err
                pending = {}

    def record_sample(self, side: str, step: int, t: float, values) -> None:
        """Queue a sample (a sequence of values; encoded by the writer thread, off the twin's)."""
        self._queue.put((samples, {"run": self.run_id, "side": side, "step": step, "time": t, "wall": wallclock.time(),
                                   "values": values}))

    def record_command(self, step: int, t: float, port: str, value) -> None:
        self._queue.put((commands, {"run": self.run_id, "step": step, "time": t, "wall": wallclock.time(),
                                    "port": port, "value": json.dumps(value)}))

    def record_state(self, side: str, step: int, t: float, machine: str, state: int, name: str) -> None:
        key = (side, machine)
        if self._last_state.get(key) == state:
            return
        self._last_state[key] = state
        self._queue.put((states, {"run": self.run_id, "side": side, "step": step, "time": t, "machine": machine,
                                  "state": state, "name": name}))

    def record_alarm(self, event: dict) -> None:
        self._queue.put((alarms, {"run": self.run_id, "time": event["time"], "wall": wallclock.time(),
                                  "variable": event["variable"], "state": event["state"], "event": json.dumps(event)}))

    def close(self, status: str = "done", message: str | None = None) -> None:
        self._queue.put(None)
        self._thread.join()
        with self.engine.begin() as conn:
            conn.execute(runs.update().where(runs.c.id == self.run_id).values(
                ended=wallclock.time(), status=status if self.error is None else "incomplete",
                message=message if self.error is None else f"history writes failed: {self.error}"))
        self.engine.dispose()


def list_runs(url: str, now: float | None = None) -> list[dict]:
    """Every run of the store with its sample and raised-alarm counts (see the module doc on `interrupted`)."""
    def read(engine) -> list[dict]:
        if not sa.inspect(engine).has_table("runs"):
            return []
        with engine.connect() as conn:
            rows = conn.execute(sa.select(runs).order_by(runs.c.id)).mappings().all()
            counts = dict(conn.execute(sa.select(samples.c.run, sa.func.count()).group_by(samples.c.run)).all())
            alarm_counts = dict(conn.execute(sa.select(alarms.c.run, sa.func.count()).where(alarms.c.state == "raised")
                                             .group_by(alarms.c.run)).all())
            return [_aged(conn, dict(r), now) | {"samples": counts.get(r["id"], 0), "alarms": alarm_counts.get(r["id"], 0)}
                    for r in rows]

    return _reading(url, read)


def _aged(conn, run: dict, now: float | None) -> dict:
    """`run`, shown as interrupted if it is still marked running but nothing was recorded for STALE_AFTER s."""
    if run["status"] != "running":
        return run
    newest = [conn.execute(sa.select(sa.func.max(t.c.wall)).where(t.c.run == run["id"])).scalar()
              for t in (samples, commands, alarms)]
    last = max([run["started"], *(w for w in newest if w is not None)])
    now = wallclock.time() if now is None else now
    if now - last <= STALE_AFTER:
        return run
    when = wallclock.strftime("%Y-%m-%d %H:%M:%S", wallclock.localtime(last))
    return run | {"status": "interrupted", "message": f"still marked running, but nothing recorded since {when}: the "
                                                      "twin that recorded it ended without closing it (killed?)"}


def read_run(url: str, run_id: int, now: float | None = None) -> dict:
    """A run's record, samples per side (list of (time, values)), commands, states and alarms."""
    if isinstance(run_id, bool) or not isinstance(run_id, int) or not 0 < run_id <= MAX_RUN_ID:
        raise CotwinError(f"no run {run_id} in the history {_redact(url)} (run ids are 1, 2, ...)")

    def read(engine) -> dict:
        if not sa.inspect(engine).has_table("runs"):
            raise CotwinError(f"no run {run_id} in the history {_redact(url)} (it holds no runs)")
        with engine.connect() as conn:
            run = conn.execute(sa.select(runs).where(runs.c.id == run_id)).mappings().first()
            if run is None:
                raise CotwinError(f"no run {run_id} in the history {_redact(url)}")
            try:
                out = {"run": _aged(conn, dict(run), now), "columns": json.loads(run["columns"]), "samples": {}}
                for row in conn.execute(sa.select(samples.c.side, samples.c.time, samples.c["values"])
                                        .where(samples.c.run == run_id).order_by(samples.c.side, samples.c.step)):
                    out["samples"].setdefault(row.side, []).append((row.time, json.loads(row[2])))
                out["alarms"] = [json.loads(r.event) for r in conn.execute(
                    sa.select(alarms).where(alarms.c.run == run_id).order_by(alarms.c.time))]
            except ValueError as err:  # JSON written by something else than the recorder
                raise CotwinError(f"run {run_id} in the history {_redact(url)} is damaged: {err}") from None
            out["commands"] = [dict(r) for r in conn.execute(sa.select(commands).where(commands.c.run == run_id)
                                                             .order_by(commands.c.step)).mappings()]
            out["states"] = [dict(r) for r in conn.execute(sa.select(states).where(states.c.run == run_id)
                                                           .order_by(states.c.step)).mappings()]
        return out

    return _reading(url, read)


def export_csv(url: str, run_id: int, side: str, path: str | Path) -> Path:
    """One side of a run as a Maestro-format CSV (the same columns and spelling as the run wrote)."""
    from ..cosim.observers import format_value

    data = read_run(url, run_id)
    if side not in data["columns"]:
        raise CotwinError(f"run {run_id} has no side '{side}' (it has {', '.join(data['columns'])})")
    path = Path(path)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time", *data["columns"][side]])
        for t, values in data["samples"].get(side, []):
            writer.writerow([format_value(round(t, 12)), *(format_value(v) for v in values)])
    return path
