"""Commands that build and co-simulate a project: build, run, simulate."""

from __future__ import annotations

from pathlib import Path

import click

from ..diagnostics import CotwinError, Finding, Location, Severity
from ..files import check_outputs
from .common import (DASHBOARD_HELP, ON_UNIT_FAILURE, STRICT_HELP, Tally, address, check_finite, check_step_count,
                     check_timing, closing_tally, main, output_file, output_folder, plan_warnings, said_restarts,
                     serving_options, show_outcomes, start_dashboard, strict_exit)


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=output_folder, required=True, help="folder for the FMUs, SDF/URDF/MJCF and multimodel.json")
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
def build(project: str, out: str, cc: str) -> None:
    """Build every artefact of a twin project (cotwin.toml); unchanged artefacts are kept."""

    from ..twin.assembly.build import build as build_all, folder_lock
    from ..twin.assembly.run import load

    said = closing_tally()  # build.json's files kept (Record.settle) are warned of, counted
    system = load(project, cells=True, reader="cotwin build")
    with folder_lock(Path(out)):
        written = build_all(system, out, cc, warn=said.finding)
    for path in written.values():
        click.echo(f"{path}")
    said.close()


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=output_folder, required=True, help="folder for outputs.csv, figure.png and the artefacts")
@click.option("--step", type=click.FloatRange(min=0, min_open=True), help="communication step size (s)")
@click.option("--end", type=click.FloatRange(min=0, min_open=True), help="end time (s)")
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
@click.option("--realtime/--no-realtime", default=None, help="pace to wall-clock time (default: the project's)")
@click.option("--dashboard", "dashboard", metavar="HOST:PORT", callback=address, help=DASHBOARD_HELP)
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
@serving_options
@ON_UNIT_FAILURE
@click.option("--strict", is_flag=True, help=STRICT_HELP)
@click.option("--fmi", "version", type=click.Choice(["2", "3"]), default="2", show_default=True,
              help="3: the d-model as an FMI 3.0 FMU whose cycle is a clock (commands reach the robot in the step "
                   "they are issued, under either algorithm)")
@click.option("--cycle-period", type=click.FloatRange(min=0, min_open=True),
              help="with --fmi 3: seconds between d-model cycles, a whole number of steps [default: the step]")
@click.option("--fmu-path", is_flag=True, help="step through the master's step-by-step loop, not the fused loop "
                                               "(the same results; for comparison and other masters' view)")
def run(project: str, out: str, step: float | None, end: float | None, algorithm: str | None,
        realtime: bool | None, dashboard: tuple[str, int] | None, cc: str, serving: dict, strict: bool,
        on_unit_failure: str, version: str, cycle_period: float | None, fmu_path: bool) -> None:
    """Build if needed and co-simulate a twin project; write outputs.csv and figure.png."""

    from ..twin.assembly.run import load, run_twin, step_warnings
    from ..twin.project import load_project
    from ..twin.services.history import database_url
    from .progress import ProgressReport

    said = closing_tally()  # the errors and warnings shown, counted in the run's closing line, a failed run's too
    check_finite(step=step, end=end, **{"cycle-period": cycle_period})
    if cycle_period is not None and version != "3":
        raise click.BadParameter("only with --fmi 3 (an FMI 2.0 d-model takes [cosim] parameters cycle_period)",
                                 param_hint="--cycle-period")
    spec = load_project(project, reader="cotwin run", step=step, end=end)
    check_timing(spec, step, end)
    system = load(spec, cells=True)
    if not system.spec.robots:
        said.warn(step_warnings(system, step, cycle_period))
    said.warn(system.warnings)  # what cotwin check says of the models and the project (a joint out of limits...)
    reader = "cotwin run --dashboard" if dashboard and not system.spec.robots else "cotwin run"  # a cell: no history
    said.warn(system.spec.ignored_sections(reader))
    if system.spec.robots:
        if on_unit_failure != "stop":
            raise click.BadParameter("a cell of several robots cannot save its state yet, so a failed step cannot be "
                                     "retried from it", param_hint="--on-unit-failure")
        return _run_cell(system, out, step, end, algorithm, realtime, cc, dashboard, version, serving, strict, said)
    history = None  # one run records no history; the page lists the store's runs when there is one
    if system.spec.history_url is not None or (Path(out) / "history.sqlite").is_file():
        history = database_url(system.spec.history_url, Path(out))
    said.warn(plan_warnings(system, system.spec.end if end is None else end))
    dash = start_dashboard(system, dashboard, "run", history, serving=serving)
    try:
        with ProgressReport("co-simulating", "steps") as progress:
            ran = run_twin(system, out, step, end, algorithm, realtime, cc=cc,
                           observers=[dash.feed] if dash else None, progress=progress,
                           restart=on_unit_failure == "restart-from-state", fmi=int(version),
                           cycle_period=cycle_period, fused=not fmu_path)
    finally:
        if dash is not None:
            dash.stop()
    r = ran.result
    said.errors += said_restarts(ran.system.units.values())  # each restart recovered a failed step
    click.echo(f"{ran.csv}: {r.rows} rows to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f}; stepping: {r.describe_stepping()})")
    show_outcomes({"": ran.outcomes}, said)
    said.close()
    strict_exit({"": ran.outcomes}, strict)


def _run_cell(cell, out: str, step: float | None, end: float | None, algorithm: str | None, realtime: bool | None,
              cc: str, dashboard, version: str, serving: dict, strict: bool, said: Tally) -> None:
    """`cotwin run` of a cell of several robots ([[robots]]): each robot's outcomes and the contacts between them;
    `said`: the run's count of the errors and warnings shown."""
    from ..twin.assembly.cell import run_cell
    from .progress import ProgressReport

    if version != "2":
        raise click.UsageError("a cell of several robots runs with --fmi 2 (not done yet with 3)")
    said.warn(plan_warnings(cell, cell.spec.end if end is None else end))
    dash = start_dashboard(cell, dashboard, "run", None, serving=serving)
    try:
        with ProgressReport("co-simulating", "steps") as progress:
            ran = run_cell(cell, out, step, end, algorithm, realtime, progress=progress, cc=cc,
                           observers=[dash.feed] if dash else None)
    finally:
        if dash is not None:
            dash.stop()
    r = ran.result
    click.echo(f"{ran.csv}: {r.rows} rows to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f})")
    show_outcomes({"": ran.outcomes}, said)
    for time, first, second in ran.contacts:
        click.echo(f"contact: {first} and {second} at t = {time:.3f} s")
    said.warn(contacts_from_the_start(cell.spec, ran.contacts, step or cell.spec.step))
    said.close()
    strict_exit({"": ran.outcomes}, strict, named=True)  # its lines count each robot's moves: the failures named


def contacts_from_the_start(spec, contacts, step: float) -> list[Finding]:
    """Robots that touch within the run's first step: placed in one another (their [[robots]] xyz/rpy overlap,
    or their home postures cross), which a run reports as an ordinary collision, every move refused after it."""
    where = Location(str(spec.path), 1, 1)
    return [Finding(where, Severity.WARNING,
                    f"{first} and {second} touch from the start (t = {time:.3f} s): their bases overlap or their "
                    f"home postures cross; move them apart ([[robots]] xyz/rpy)")
            for time, first, second in contacts if time <= step]


@main.command()
@click.argument("multimodel", type=click.Path())
@click.option("-o", "--output", "out", callback=output_file, default=None, help="the CSV to write (default: outputs.csv beside it)")
@click.option("--step", type=click.FloatRange(min=0, min_open=True))
@click.option("--end", type=click.FloatRange(min=0, min_open=True))
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
@ON_UNIT_FAILURE
def simulate(multimodel: str, out: str | None, step: float | None, end: float | None, algorithm: str | None,
             on_unit_failure: str) -> None:
    """Run any Maestro multimodel JSON with cotwin's master (FMUs through FMPy)."""

    from ..cosim.multimodel import execution_for, read_multimodel

    check_finite(step=step, end=end)
    mm = read_multimodel(multimodel)
    check_step_count(mm.step if step is None else step, (mm.end if end is None else end) - mm.start,
                "--end" if end is not None else "--step" if step is not None else None, multimodel)
    csv_path = Path(out) if out else Path(multimodel).parent / "outputs.csv"
    check_outputs([csv_path, csv_path.with_name(csv_path.name + ".part")], [multimodel, *mm.fmus.values()])
    execution = execution_for(mm, csv_path, step, algorithm, restart=on_unit_failure == "restart-from-state")
    try:
        result = execution.run(mm.end if end is None else end)
    except (CotwinError, KeyboardInterrupt) as err:  # say where the rows computed so far are
        from ..cosim.execution import ended_early

        raise ended_early(err, execution.time, execution.observers[0].kept()) from None
    said_restarts(execution.system.units.values())
    click.echo(f"{csv_path}: {result.rows} rows to t = {result.end_time:g} s in {result.wall_seconds:.2f} s")
