"""The history store's commands: history list|export, dashboard."""

from __future__ import annotations

from pathlib import Path

import click

from .common import address, history_url, main, output_file, serving_options, start_dashboard


@main.group()
def history() -> None:
    """The twin's history store: list runs, export one as CSV."""


def history_db(db: str | None, folder: str | None) -> str:

    from ..twin.services.history import database_url

    if (db is None) == (folder is None):  # both: one of them would be ignored without a word
        raise click.UsageError("give --db URL or --dir DIR (a twin's output folder, with history.sqlite), one of them")
    if folder is not None and not (Path(folder) / "history.sqlite").is_file():
        raise click.BadParameter(f"no history.sqlite in {folder}", param_hint="--dir")
    return database_url(db, Path(folder) if folder else None)


@history.command("list")
@click.option("--db", callback=history_url, help="database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
def history_list(db: str | None, folder: str | None) -> None:
    """List the runs of a history store."""
    import datetime

    from ..twin.services.history import list_runs

    url = history_db(db, folder)
    found = list_runs(url)
    if not found:  # an empty store, or a database (an empty file) that is no cotwin history store
        from ..twin.services.history import redacted

        click.echo(f"error: no run in the history database {redacted(url)} (cotwin twin records its runs there)",
                   err=True)
        raise SystemExit(1)
    for run in found:
        started = datetime.datetime.fromtimestamp(run["started"]).isoformat(timespec="seconds")
        click.echo(f"{run['id']:>5}  {started}  {run['kind']:<5} {run['status']:<10} step {run['step']:g} s  "
                   f"{run['samples']} samples  {run['alarms']} alarm(s)  {run['project']}")


@history.command("export")
@click.argument("run_id", type=int)
@click.option("--db", callback=history_url, help="database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
@click.option("--side", default="dt", show_default=True, help="pt or dt")
@click.option("-o", "--output", "out", callback=output_file, required=True, help="the CSV to write")
def history_export(run_id: int, db: str | None, folder: str | None, side: str, out: str) -> None:
    """Export one side of a run as a Maestro-format CSV."""
    from ..twin.services.history import export_csv

    path = export_csv(history_db(db, folder), run_id, side, out)
    click.echo(str(path))


@main.command("dashboard")
@click.option("--db", callback=history_url, help="history database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
@click.option("--at", "address", default="127.0.0.1:8050", show_default=True, metavar="HOST:PORT", callback=address,
              help="where to serve the page")
@serving_options
def dashboard_command(db: str | None, folder: str | None, address: tuple[str, int], serving: dict) -> None:
    """Browse the runs of a history store in the dashboard (after the run), until interrupted."""
    import threading

    dash = start_dashboard(None, address, "history", history_db(db, folder), serving=serving)
    click.echo("(history only; Ctrl-C to stop)", err=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        dash.stop()
