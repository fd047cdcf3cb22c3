"""The twin's history: every PT and DT sample (simulated and wall time), command, d-model state change
and alarm of a run, in SQLite (embedded, the default) or PostgreSQL, through SQLAlchemy Core.

Tables: `runs` (one per run), `samples` (run, side, step, time, wall, values as JSON), `commands`,
`states` (d-model state changes), `alarms` (deviation events) and `corrections` (the DT corrected towards
the PT: cotwin.twin.assembly.convergence). Writes are queued and committed in
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
import time as wallclock
from pathlib import Path

import sqlalchemy as sa

from ...cosim.algorithm import UNSET
from ...diagnostics import CotwinError
from ...files import check_outputs, output
from ...service import BackgroundService

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

corrections = sa.Table(  # the DT corrected towards the PT (cotwin.twin.assembly.convergence): resyncs, estimates applied
    "corrections", metadata,
    sa.Column("run", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("time", sa.Float, nullable=False),
    sa.Column("wall", sa.Float, nullable=False),
    sa.Column("kind", sa.String(32), nullable=False),  # resync | payload
    sa.Column("reason", sa.Text, nullable=False),
    sa.Column("size", sa.Float, nullable=False),  # resync: largest joint difference removed; payload: kg added
    sa.Column("event", sa.Text, nullable=False),  # the whole correction as JSON
)


def sqlite_path(url: str) -> Path | None:
    """The file of a SQLite store's URL (None for another database, or an in-memory one)."""
    try:
        parsed = sa.engine.make_url(url)
    except (sa.exc.ArgumentError, ValueError):
        return None
    database = parsed.database or ""
    if parsed.get_backend_name() != "sqlite" or database in ("", ":memory:") or database.startswith("file:"):
        return None
    return Path(database)


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


SCHEMA = "cotwin"  # PostgreSQL: cotwin's tables, in a schema of their own beside other applications' tables


def engine_for(url: str, create: bool = True) -> sa.Engine:
    """An engine on the store at `url` whose tables are cotwin's (see `_ours`): in PostgreSQL those of the
    schema `cotwin` (made by a recorder; a store made before it had one is read from `public`). With
    `create=False` (readers) a SQLite file must already exist and nothing is created."""
    if not create:
        _must_exist(url)
    try:
        engine = sa.create_engine(url, future=True)
        with engine.connect() as conn:
            schema = _schema(conn, create)
    except (sa.exc.SQLAlchemyError, ImportError, ValueError) as err:
        raise failed("open", url, err) from None
    if schema is not None:
        engine = engine.execution_options(schema_translate_map={None: schema})
    try:
        with engine.connect() as conn:
            _ours(conn, schema, url)
    except sa.exc.SQLAlchemyError as err:
        raise failed("read", url, err) from None
    return engine


def _schema(conn, create: bool) -> str | None:
    """Where cotwin's tables are in this database: None (SQLite: the file is the store) or a schema."""
    if conn.dialect.name != "postgresql":
        return None
    inspector = sa.inspect(conn)
    if create:
        try:
            _take_turns(conn)
            conn.execute(sa.schema.CreateSchema(SCHEMA, if_not_exists=True))
            conn.commit()
        except sa.exc.SQLAlchemyError as err:
            raise CotwinError(f"cannot make the schema '{SCHEMA}' for cotwin's history in {conn.engine.url.database}: "
                              f"{str(err.orig if hasattr(err, 'orig') else err).splitlines()[0][:160]} (create it: "
                              f"CREATE SCHEMA {SCHEMA} AUTHORIZATION <the user>)") from None
        return SCHEMA
    if not inspector.has_table("runs", schema=SCHEMA) and inspector.has_table("runs", schema="public") \
            and _missing(inspector, "runs", "public") == []:
        return "public"  # a store written before cotwin had its own schema
    return SCHEMA


TABLES_LOCK = 0x636F7477696E  # "cotwin": the PostgreSQL advisory lock on which the makers of its schema and tables queue


def create_tables(engine: sa.Engine, *schemas: sa.MetaData) -> None:
    """cotwin's history tables (and those of `schemas`), made once however many twins start at once on a new
    store: PostgreSQL's CREATE ... IF NOT EXISTS run by two sessions at once fails in one of them (a unique
    violation in its catalogue), so the makers take turns."""
    with engine.begin() as conn:
        _take_turns(conn)
        for tables in (metadata, *schemas):
            tables.create_all(conn)


def _take_turns(conn) -> None:
    """Wait for TABLES_LOCK until the end of `conn`'s transaction (PostgreSQL; SQLite locks its file itself)."""
    if conn.dialect.name == "postgresql":
        conn.execute(sa.text("SELECT pg_advisory_xact_lock(:key)"), {"key": TABLES_LOCK})


def _missing(inspector, table: str, schema: str | None) -> list[str]:
    have = {c["name"] for c in inspector.get_columns(table, schema=schema)}
    return [c.name for c in metadata.tables[table].columns if c.name not in have]


def _ours(conn, schema: str | None, url: str) -> None:
    """CotwinError naming the table if a table of cotwin's name here is another application's (it lacks
    cotwin's columns): writing or reading it would fail half-way, or read someone else's rows."""
    inspector = sa.inspect(conn)
    for name in metadata.tables:
        if inspector.has_table(name, schema=schema):
            missing = _missing(inspector, name, schema)
            if missing:
                where = f"{schema}.{name}" if schema else name
                raise CotwinError(f"the history database {redacted(url)} has a table '{where}' that is not cotwin's "
                                  f"(it has no column {', '.join(missing[:5])}): give cotwin a database of its own "
                                  f"({'another SQLite file' if schema is None else 'or drop that table'})")


def _must_exist(url: str) -> None:
    """CotwinError if `url` is a SQLite file that does not exist (connecting would create it)."""
    path = sqlite_path(url)
    if path is not None and not path.is_file():
        raise CotwinError(f"no history database at {path}")


def _reading(url: str, what):
    """`what(engine)` on the store at `url`, opened for reading; a database error becomes a CotwinError."""
    engine = engine_for(url, create=False)
    try:
        return what(engine)
    except sa.exc.SQLAlchemyError as err:
        raise failed("read", url, err) from None
    finally:
        engine.dispose()


def failed(verb: str, url: str, err: Exception) -> CotwinError:
    """The error of a store that could not be opened, read or written: the store (no password) and the cause."""
    return CotwinError(f"cannot {verb} the history database {redacted(url)}: {_cause(err)}")


def _cause(err: Exception) -> str:
    """A database error in one line: its kind and the first line of its words."""
    return f"{type(err).__name__}: {(str(err).splitlines() or [''])[0][:200]}"


def redacted(url: str) -> str:
    try:
        return sa.engine.make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001
        return "<history url>"


class HistoryRecorder(BackgroundService):
    """Records one run; every `record_*` call is queued and returns at once, written by the recorder's
    thread (cotwin.service.BackgroundService) in batches."""

    def __init__(self, url: str, project: str, kind: str, step: float, algorithm: str,
                 columns: dict[str, list[str]], batch_seconds: float = 0.5):
        self.engine, self.url = engine_for(url), url
        self.columns = columns
        try:
            create_tables(self.engine)
            with self.engine.begin() as conn:
                self.run_id = conn.execute(runs.insert().values(
                    project=project, kind=kind, started=wallclock.time(), status="running", step=step,
                    algorithm=algorithm, columns=json.dumps(columns))).inserted_primary_key[0]
        except sa.exc.SQLAlchemyError as err:  # e.g. a read-only file: said before the twin starts
            self.engine.dispose()
            raise failed("write", url, err) from None
        self.batch_seconds = batch_seconds
        self._queue: queue.Queue = queue.Queue()
        self.error: Exception | None = None  # the first write that failed
        self.lost = 0  # records not written
        self._last_state: dict[tuple[str, str], int] = {}
        BackgroundService.__init__(self, "cotwin history")
        self.start()

    def serve(self) -> None:
        self.ready()
        self._write()

    def interrupt(self) -> None:
        self._queue.put(None)  # the writer ends once it has written what came before

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
                    self.error = self.error or err
                    self.lost += sum(len(rows) for rows in pending.values())
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

    def record_correction(self, event: dict) -> None:
        self._queue.put((corrections, {"run": self.run_id, "step": event["step"], "time": event["time"],
                                       "wall": wallclock.time(), "kind": event["kind"], "reason": event["reason"],
                                       "size": event["size"], "event": json.dumps(event)}))

    def close(self, status: str = "done", message: str | None = None) -> None:
        """Write what is queued and the run's end; a store that fails (gone, full, read-only) is said by `problem`,
        never raised: the run's own results are kept either way."""
        self.stop(None)
        self.error = self.error or self.failure  # the writer's thread failed: the run's history is incomplete
        try:
            with self.engine.begin() as conn:
                conn.execute(runs.update().where(runs.c.id == self.run_id).values(
                    ended=wallclock.time(), status=status if self.error is None else "incomplete",
                    message=message if self.error is None else f"history writes failed: {self.error}"))
        except sa.exc.SQLAlchemyError as err:
            self.error = self.error or err
        finally:
            self.engine.dispose()

    @property
    def problem(self) -> str | None:
        """Why the run's history is incomplete (None if every record and its end were written)."""
        if self.error is None:
            return None
        lost = f"{self.lost} record(s) not written, " if self.lost else ""
        return (f"the history of run {self.run_id} in {redacted(self.url)} is incomplete ({lost}the first failure: "
                f"{_cause(self.error)})")


def _has_runs(engine) -> bool:
    schema = engine.get_execution_options().get("schema_translate_map", {}).get(None)
    return sa.inspect(engine).has_table("runs", schema=schema)


def list_runs(url: str, now: float | None = None) -> list[dict]:
    """Every run of the store with its sample and raised-alarm counts (see the module doc on `interrupted`)."""
    def read(engine) -> list[dict]:
        if not _has_runs(engine):
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


PAGE = 5_000  # samples fetched from the store at a time (a reader holds a page, never a whole run)
MAX_RECORD = 1 << 22  # characters of one stored JSON record (a sample of thousands of variables is ~100 KiB)


def _json(text, what: str):
    """A JSON record as the recorder wrote it (NaN included: a diverged value is one), or ValueError saying
    why it is not one (the store may be shared with, or damaged by, something else)."""
    if not isinstance(text, str) or len(text) > MAX_RECORD:
        raise ValueError(f"{what} is not a JSON text of at most {MAX_RECORD} characters")
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError(f"{what} is nested too deeply") from None
    except ValueError as err:
        raise ValueError(f"{what} is not JSON ({err})") from None


def _side_samples(conn, run_id: int, side: str, max_points: int | None = None):
    """(time, values) of one side of a run in step order, fetched PAGE at a time; with `max_points`, at most
    that many, evenly spaced with the last kept, chosen by the database."""
    where = sa.and_(samples.c.run == run_id, samples.c.side == side)
    query = sa.select(samples.c.time, samples.c["values"]).where(where).order_by(samples.c.step)
    if max_points is not None:
        count = conn.execute(sa.select(sa.func.count()).select_from(samples).where(where)).scalar() or 0
        stride = max(1, -(-count // max(1, max_points - 1)))
        if stride > 1:  # numbered on the index (run, side, step) alone; only the chosen rows' values are read
            numbered = sa.select(samples.c.step, sa.func.row_number().over(order_by=samples.c.step).label("k")) \
                .where(where).subquery()
            chosen = sa.select(numbered.c.step).where(sa.or_((numbered.c.k - 1) % stride == 0, numbered.c.k == count))
            query = query.where(samples.c.step.in_(chosen))
    for row in conn.execution_options(yield_per=PAGE).execute(query):
        values = _json(row[1], f"a sample of side {side}")
        if type(values) is not list:
            raise ValueError(f"a sample of side {side} is not a list of values")
        yield row[0], values


def read_run(url: str, run_id: int, now: float | None = None, max_points: int | None = None,
             max_events: int | None = None) -> dict:
    """A run's record, its samples per side (a list of (time, values)), commands, states and alarms. With
    `max_points`, at most that many samples per side, evenly spaced (chosen in the database: a long run
    costs a reader what a short one does); with `max_events`, at most that many of each kind of event (the
    first ones). `counts` says how many the store holds of each."""
    if isinstance(run_id, bool) or not isinstance(run_id, int) or not 0 < run_id <= MAX_RUN_ID:
        raise CotwinError(f"no run {run_id} in the history {redacted(url)} (run ids are 1, 2, ...)")

    def read(engine) -> dict:
        with engine.connect() as conn:
            run, columns = _record(conn, url, run_id, now)
            counts = {}
            out = {"run": run, "columns": columns, "samples": {}, "counts": counts}
            try:
                sides = [r[0] for r in conn.execute(sa.select(samples.c.side).where(samples.c.run == run_id).distinct())]
                for side in sorted(sides):
                    out["samples"][side] = list(_side_samples(conn, run_id, side, max_points))
                    counts[side] = conn.execute(sa.select(sa.func.count()).select_from(samples).where(
                        samples.c.run == run_id, samples.c.side == side)).scalar()
                out["alarms"] = [_json(r.event, "an alarm") for r in _events(conn, alarms, run_id, alarms.c.time,
                                                                             max_events, counts)]
            except ValueError as err:  # JSON written by something else than the recorder
                raise CotwinError(f"run {run_id} in the history {redacted(url)} is damaged: {err}") from None
            out["commands"] = [dict(r) for r in _events(conn, commands, run_id, commands.c.step, max_events, counts)]
            out["states"] = [dict(r) for r in _events(conn, states, run_id, states.c.step, max_events, counts)]
            schema = engine.get_execution_options().get("schema_translate_map", {}).get(None)
            out["corrections"] = [dict(r) for r in _events(conn, corrections, run_id, corrections.c.step, max_events,
                                                           counts)] \
                if sa.inspect(conn).has_table("corrections", schema=schema) else []  # a store made before them
        return out

    return _reading(url, read)


def _record(conn, url: str, run_id: int, now: float | None = None) -> tuple[dict, dict]:
    """A run's row (aged) and its columns per side, or CotwinError: no such run, or a damaged one."""
    if not _has_runs(conn):
        raise CotwinError(f"no run {run_id} in the history {redacted(url)} (it holds no runs)")
    run = conn.execute(sa.select(runs).where(runs.c.id == run_id)).mappings().first()
    if run is None:
        raise CotwinError(f"no run {run_id} in the history {redacted(url)}")
    try:
        columns = _json(run["columns"], "its columns")
    except ValueError as err:
        raise CotwinError(f"run {run_id} in the history {redacted(url)} is damaged: {err}") from None
    if not isinstance(columns, dict) or not all(isinstance(c, list) for c in columns.values()):
        raise CotwinError(f"run {run_id} in the history {redacted(url)} is damaged: its columns are not a JSON "
                          "object of lists")
    return _aged(conn, dict(run), now), columns


def _events(conn, table: sa.Table, run_id: int, order, limit: int | None, counts: dict) -> list:
    query = sa.select(table).where(table.c.run == run_id).order_by(order)
    if limit is not None:
        counts[table.name] = conn.execute(sa.select(sa.func.count()).select_from(table).where(
            table.c.run == run_id)).scalar()
        query = query.limit(limit)
    return list(conn.execute(query).mappings())


def export_csv(url: str, run_id: int, side: str, path: str | Path) -> Path:
    """One side of a run as a Maestro-format CSV (the same columns and spelling as the run wrote), read from
    the store a page at a time; never written over the store itself."""
    if isinstance(run_id, bool) or not isinstance(run_id, int) or not 0 < run_id <= MAX_RUN_ID:
        raise CotwinError(f"no run {run_id} in the history {redacted(url)} (run ids are 1, 2, ...)")
    store = sqlite_path(url)
    check_outputs([path], [store])

    def write(engine) -> Path:
        with engine.connect() as conn:
            _, columns = _record(conn, url, run_id)
            if side not in columns:
                raise CotwinError(f"run {run_id} has no side '{side}' (it has {', '.join(columns)})")
            return _write_side(conn, url, run_id, side, columns[side], path, store)

    return _reading(url, write)


def _write_side(conn, url: str, run_id: int, side: str, columns: list, path, store) -> Path:
    from ...cosim.observers import format_value

    with output(path, [store], text=True, newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time", *columns])
        try:
            for t, values in _side_samples(conn, run_id, side):
                writer.writerow([format_value(round(t, 12)), *(format_value(v) for v in values)])
        except (ValueError, TypeError) as err:
            raise CotwinError(f"run {run_id} in the history {redacted(url)} is damaged: {err}") from None
    return Path(path)
