"""The fleet's own records in the fleet's history store: which run is which twin's attempt, and every
start, failure, restart and end (table `fleet_twins`, beside cotwin.twin.services.history's tables)."""

from __future__ import annotations

import time as wallclock

import sqlalchemy as sa

from ....diagnostics import CotwinError

metadata = sa.MetaData()
fleet_twins = sa.Table(
    "fleet_twins", metadata,
    sa.Column("fleet", sa.String(256), nullable=False),
    sa.Column("twin", sa.String(64), nullable=False),
    sa.Column("attempt", sa.Integer, nullable=False),
    sa.Column("run", sa.Integer),  # the twin's run in `runs` (None: it failed before it recorded one)
    sa.Column("event", sa.String(32), nullable=False),  # started | failed | restarting | given up | done | stopped | history incomplete
    sa.Column("time", sa.Float),  # the twin's simulated time (restarting: the saved state's)
    sa.Column("wall", sa.Float, nullable=False),
    sa.Column("message", sa.Text),
)


class FleetRecorder:
    """Writes the fleet's events (few: one per start, failure or end) as they happen."""

    def __init__(self, url: str, fleet: str, on_error=None):
        """`on_error(problem)` is told of the first event that could not be written (the fleet goes on)."""
        from ...services.history import create_tables, engine_for

        self.engine = engine_for(url)
        self.fleet = fleet
        try:
            create_tables(self.engine, metadata)  # once, before the twins' recorders start
        except sa.exc.SQLAlchemyError as err:
            raise CotwinError(f"cannot make the fleet's table in the history database: {str(err).splitlines()[0][:200]}") \
                from None
        self.error: Exception | None = None
        self.lost = 0  # events not written
        self.on_error = on_error

    def event(self, twin: str, attempt: int, run: int | None, event: str, time: float | None,
              message: str | None) -> None:
        try:
            with self.engine.begin() as conn:
                conn.execute(fleet_twins.insert().values(fleet=self.fleet, twin=twin, attempt=attempt, run=run,
                                                         event=event, time=time, wall=wallclock.time(),
                                                         message=message))
        except sa.exc.SQLAlchemyError as err:  # the fleet goes on; said when it happens and in the summary
            self.lost += 1
            first = self.error is None
            if first:
                self.error = err
            if self.on_error is not None and first:
                self.on_error(self.problem())

    def problem(self) -> str | None:
        """What went wrong writing the fleet's events (None: nothing), in a line."""
        if self.error is None:
            return None
        return (f"the fleet's events are incomplete in its history store ({self.lost} not written, the first "
                f"failure: {str(self.error).splitlines()[0][:200]})")

    def close(self) -> None:
        self.engine.dispose()


def fleet_events(url: str, fleet: str | None = None) -> list[dict]:
    """The recorded events (of one fleet, or all), oldest first."""
    from ...services.history import _reading

    def read(engine) -> list[dict]:
        schema = engine.get_execution_options().get("schema_translate_map", {}).get(None)  # PostgreSQL: cotwin's
        if not sa.inspect(engine).has_table("fleet_twins", schema=schema):
            return []
        query = sa.select(fleet_twins).order_by(fleet_twins.c.wall)
        if fleet is not None:
            query = query.where(fleet_twins.c.fleet == fleet)
        with engine.connect() as conn:
            return [dict(r._mapping) for r in conn.execute(query)]

    return _reading(url, read)
