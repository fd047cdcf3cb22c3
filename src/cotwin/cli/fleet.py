"""The fleet command: many live twins together (cotwin.twin.analysis.fleet)."""

from __future__ import annotations

import click

from ..diagnostics import CotwinError
from .common import address, history_url, main, output_folder


@main.command()
@click.argument("fleet_file", metavar="FLEET.toml", type=click.Path())
@click.option("-o", "--output", "out", callback=output_folder, required=True,
              help="folder for each twin's DIR/NAME, fleet.json and the history store")
@click.option("--ray", "ray", default="auto", show_default=True, metavar="auto|ADDRESS|off",
              help="where the twins run: a local Ray started here on 127.0.0.1 and stopped at the end (auto), a Ray "
                   "cluster (HOST:PORT or ray://HOST:PORT), or threads of this process (off)")
@click.option("--history", callback=history_url, help="history database URL for every twin (default: [fleet] history, else DIR/history.sqlite)")
@click.option("--page", "page", metavar="HOST:PORT", callback=address,
              help="serve the fleet's overview page at HOST:PORT (loopback) while the fleet runs")
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMUs")
def fleet(fleet_file: str, out: str, ray: str, history: str | None, page: tuple[str, int] | None, cc: str) -> None:
    """Run a fleet of live twins (each a project, as `cotwin twin` runs it) on Ray: one history store, alarms
    per twin on the broker, an overview page, and a supervisor restarting a failed twin from its last saved
    state. Exits 1 if a twin was given up or its history could not be wholly recorded."""
    import signal

    from ..twin.analysis.fleet.spec import read_fleet
    from ..twin.analysis.fleet.supervisor import Fleet

    spec = read_fleet(fleet_file)
    if ray != "off" and ray != "auto":
        from ..twin.analysis.sweep import _reachable

        _reachable(ray)
    runner = Fleet(spec, out, ray=None if ray == "off" else ray, history=history, cc=cc,
                   say=lambda message: click.echo(message, err=True))
    served = None
    if page is not None:
        from ..twin.analysis.fleet.page import FleetPage

        served = FleetPage(runner.overview, *page).start()
        click.echo(f"fleet page: {served.url}", err=True)

    def interrupt(*_) -> None:
        if runner.stop_requested:
            raise KeyboardInterrupt
        runner.stop()
        click.echo("stopping every twin after its step (interrupt again to stop at once)", err=True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, interrupt)
    try:
        summary = runner.run()
    finally:
        if served is not None:
            served.stop()
    given_up = []
    for t in summary["twins"]:
        rtf = t.get("real_time_factor")
        pace = f"real-time factor {rtf:.2f}" if rtf is not None else "no step"
        if t.get("realtime"):
            pace += f", worst lag {t.get('worst_lag') or 0.0:.2f} s" + (" (could not keep real time)"
                                                                        if (t.get("worst_lag") or 0) > 0.2 else "")
        click.echo(f"{t['name']}: {t['state']} at t = {t.get('time') or 0.0:g} s ({pace}); {t.get('alarms') or 0} "
                   f"alarm(s); {t['restarts']} restart(s)")
        if t["state"] == "failed":
            given_up.append(t["name"])
        for problem in t.get("history_problems") or []:  # its store failed: its outputs are whole, its history is not
            attempt = problem["attempt"]
            folder = runner.out / t["name"] / (f"restart-{attempt}" if attempt else "")
            click.echo(f"twin {t['name']}{f' (restart {attempt})' if attempt else ''}: {problem['message']}; its "
                       f"outputs in {folder} are whole", err=True)
    click.echo(f"fleet {summary['fleet']}: {len(summary['twins'])} twin(s); summary {runner.out / 'fleet.json'}; "
               f"history {summary['history']}")
    incomplete = [t["name"] for t in summary["twins"] if t.get("history_problems")]
    if summary.get("events_problem"):  # said when it happened; again here, beside the summary
        click.echo(f"fleet {summary['fleet']}: {summary['events_problem']}", err=True)
        incomplete.append("the fleet's events")
    if given_up or incomplete:
        said = ([f"twin(s) given up: {', '.join(given_up)}"] if given_up else []) + \
            ([f"incomplete history: {', '.join(incomplete)}"] if incomplete else [])
        raise CotwinError(f"{'; '.join(said)} (see the messages above)")
