"""The `cotwin` command."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import click

from .diagnostics import CotwinError, Severity


MAX_HORIZON = 86_400.0  # s: the longest a what-if looks ahead
MAX_VALUES = 100_000  # values of one --arg or --domain
MAX_REPORTED = 50  # findings printed at once: a file with thousands of problems says how many more


def _report(findings, stream=None) -> None:
    stream = stream or sys.stderr
    findings = list(findings)
    for f in findings[:MAX_REPORTED]:
        click.echo(str(f), file=stream)
    if len(findings) > MAX_REPORTED:
        rest = findings[MAX_REPORTED:]
        errors = sum(f.severity is Severity.ERROR for f in rest)
        click.echo(f"... and {len(rest)} more problem(s) not shown ({errors} error(s))", file=stream)


def _output(ctx, param, value: str | None) -> str | None:
    """An -o option: a path, never the empty string (which would write into the current folder)."""
    if value is not None and not value.strip():
        raise click.BadParameter("an empty path: name the file or folder to write", param_hint="-o/--output")
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cotwin")
def main() -> None:
    """cotwin: RoboSim models to FMI-based digital twins."""


@main.command()
@click.argument("paths", nargs=-1, required=True)
def check(paths: tuple[str, ...]) -> None:
    """Parse, resolve and type-check RoboSim models (files or folders of .rst and .pm)."""
    from .robosim.check import check_paths
    from .robosim.summary import summarise

    result = check_paths(paths)
    findings = list(result.findings)
    if result.ok:
        findings += [f for project in result.projects for f in _tree_findings(project)]
    _report(findings)
    if not result.ok:
        errors = sum(f.severity is Severity.ERROR for f in result.findings)
        click.echo(f"{errors} error(s)", file=sys.stderr)
        sys.exit(1)
    warnings = Counter(f.location.path for f in findings if f.severity is Severity.WARNING)
    for source in (f for project in result.projects for f in project.files):
        extra = f", {warnings[source.path]} warning(s)" if warnings[source.path] else ""
        click.echo(f"{source.path}: ok ({summarise(source)}{extra})")


def _tree_findings(project) -> list:
    """The readings a simulator takes of a project's p-models (cotwin.pmodel.tree_build's warnings: a wheel
    axis moved, an impossible inertia replaced...), for those that build."""
    from .diagnostics import CotwinError
    from .pmodel.tree import build_tree
    from .robosim.pmodel_elements import PModel

    pmodels = project.elements(PModel)
    used = {p.pmodel.last for pm in pmodels for p in pm.parts}
    out = []
    for pmodel in pmodels:
        if pmodel.name in used:
            continue
        try:
            tree = build_tree(project, "::".join(project.qualified_name(pmodel)))
        except CotwinError:
            continue  # a p-model the simulator cannot take says so when it is run
        out.extend(f for f in tree.findings if f.severity is Severity.WARNING and not f.location.path.startswith("<"))
    return out


@main.command("build-dmodel")
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module to build (default: the only one)")
@click.option("-o", "--output", callback=_output, required=True, help="the FMU file to write")
@click.option("--cc", default="cc", show_default=True, help="C compiler")
def build_dmodel(model: tuple[str, ...], module_name: str | None, output: str, cc: str) -> None:
    """Generate C from a d-model module and package it as an FMI 2.0 co-simulation FMU."""
    from .dmodel.fmu import build_fmu
    from .dmodel.program import build_program
    from .robosim.check import load_checked

    program = build_program(load_checked(model), module_name)
    path = build_fmu(program, output, cc=cc)
    click.echo(f"{path}: module {program.module.name}, {len(program.machines)} state machine(s), "
               f"{len(program.inputs)} input event(s), {len(program.operations)} operation(s)")


@main.command("export-pmodel")
@click.argument("model", nargs=-1, required=True)
@click.option("--pmodel", "pmodel_name", help="the p-model to export (default: the one not used as a part)")
@click.option("--format", "fmt", type=click.Choice(["sdf", "urdf", "mjcf"]), required=True)
@click.option("-o", "--output", callback=_output, required=True, help="the file to write")
def export_pmodel(model: tuple[str, ...], pmodel_name: str | None, fmt: str, output: str) -> None:
    """Write a p-model as SDF 1.6, URDF or MJCF (all three from one kinematic tree)."""
    from pathlib import Path

    from .pmodel.mjcf import to_mjcf
    from .pmodel.sdf import to_sdf
    from .pmodel.tree import build_tree
    from .pmodel.urdf import to_urdf
    from .robosim.check import load_checked

    tree = build_tree(load_checked(model), pmodel_name)
    text = {"sdf": to_sdf, "urdf": to_urdf, "mjcf": to_mjcf}[fmt](tree)
    path = Path(output)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    kinds = {k: sum(j.kind == k for j in tree.joints) for k in ("revolute", "prismatic", "fixed")}
    click.echo(f"{path}: {fmt} of p-model {tree.name}: {len(tree.links)} links, {kinds['revolute']} revolute, "
               f"{kinds['prismatic']} prismatic and {kinds['fixed']} fixed joints, {len(tree.sensors)} sensor ports")


def _exchange(ctx, param, value: str | None) -> str | None:
    """An exchange name option, checked as the project's are (cotwin.twin.project.amqp_name_problem)."""
    from .twin.project import amqp_name_problem

    problem = None if value is None else amqp_name_problem(value)
    if problem:
        raise click.BadParameter(problem)
    return value


def _timing(spec, step: float | None, end: float | None) -> None:
    """--step and --end checked with the project's other timing (cotwin.twin.project.timing_problems)."""
    from .twin.project import CYCLE_PERIOD, cycle_period, timing_problems

    if step is None and end is None:
        return
    for key, message in timing_problems(spec.step if step is None else step, spec.end if end is None else end,
                                        cycle_period(spec)):
        if key == CYCLE_PERIOD:
            message += " ([cosim] parameters cycle_period)"
        raise click.BadParameter(message, param_hint="--end" if key == "end" and end is not None else "--step")


def _address(ctx, param, value: str | None) -> tuple[str, int] | None:
    """A --dashboard HOST:PORT option."""
    if value is None:
        return None
    from .twin.dashboard.app import parse_address

    try:
        return parse_address(value)
    except ValueError as err:
        raise click.BadParameter(str(err)) from None


DASHBOARD_HELP = "serve the live dashboard at HOST:PORT (e.g. 127.0.0.1:8050) while the run lasts"


def _dashboard(system, address, mode: str, history_url: str | None, whatif_url: str | None = None):
    """The started dashboard of a run (or None); says where it is."""
    if address is None:
        return None
    from .twin.dashboard import Dashboard

    dash = Dashboard(system, *address, mode=mode, history_url=history_url, whatif_url=whatif_url).start()
    click.echo(f"dashboard: {dash.url}", err=True)
    return dash


def _show_warnings(findings) -> None:
    for f in findings:
        if f.severity is Severity.WARNING:
            click.echo(str(f), err=True)


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=_output, required=True, help="folder for the FMUs, SDF/URDF/MJCF and multimodel.json")
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
def build(project: str, out: str, cc: str) -> None:
    """Build every artefact of a twin project (cotwin.toml); unchanged artefacts are kept."""
    from pathlib import Path

    from .twin.build import build as build_all, folder_lock
    from .twin.run import load

    system = load(project)
    with folder_lock(Path(out)):
        written = build_all(system, out, cc)
    for path in written.values():
        click.echo(f"{path}")


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=_output, required=True, help="folder for outputs.csv, figure.png and the artefacts")
@click.option("--step", type=click.FloatRange(min=0, min_open=True), help="communication step size (s)")
@click.option("--end", type=click.FloatRange(min=0, min_open=True), help="end time (s)")
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
@click.option("--realtime/--no-realtime", default=None, help="pace to wall-clock time (default: the project's)")
@click.option("--dashboard", "dashboard", metavar="HOST:PORT", callback=_address, help=DASHBOARD_HELP)
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
def run(project: str, out: str, step: float | None, end: float | None, algorithm: str | None,
        realtime: bool | None, dashboard: tuple[str, int] | None, cc: str) -> None:
    """Build if needed and co-simulate a twin project; write outputs.csv and figure.png."""
    from pathlib import Path

    from rich.progress import Progress

    from .twin.history import database_url
    from .twin.run import load, run_twin

    _finite(step=step, end=end)
    system = load(project)
    _timing(system.spec, step, end)
    history = None  # one run records no history; the page lists the store's runs when there is one
    if system.spec.history_url is not None or (Path(out) / "history.sqlite").is_file():
        history = database_url(system.spec.history_url, Path(out))
    from .twin.scenario import after_end

    _show_warnings(after_end(system.commands, system.spec.end if end is None else end))
    dash = _dashboard(system, dashboard, "run", history)
    try:
        with Progress(transient=True, disable=not sys.stderr.isatty()) as bar:
            task = bar.add_task("co-simulating", total=1)
            ran = run_twin(system, out, step, end, algorithm, realtime, cc=cc,
                           observers=[dash.feed] if dash else None,
                           progress=lambda k, n: bar.update(task, completed=k, total=n))
    finally:
        if dash is not None:
            dash.stop()
    r = ran.result
    click.echo(f"{ran.csv}: {r.rows} rows to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f})")


def _step_count(step: float, span: float, hint: str | None, source: str) -> None:
    """A run the master can keep exactly (cosim's step_count), refused before any FMU is loaded, at the
    option that set it (`hint`) or else at the multimodel (`source`)."""
    from .cosim.execution import step_count

    try:
        step_count(span, step)
    except CotwinError as err:
        message = err.findings[0].message
        if hint is None:
            raise CotwinError(f"{source}: {message}") from None
        raise click.BadParameter(message, param_hint=hint) from None


def _finite(**options) -> None:
    import math

    for name, value in options.items():
        if value is not None and not math.isfinite(value):
            raise click.BadParameter(f"{value!r} is not a finite number", param_hint=f"--{name}")


@main.command()
@click.argument("multimodel", type=click.Path())
@click.option("-o", "--output", "out", callback=_output, default=None, help="the CSV to write (default: outputs.csv beside it)")
@click.option("--step", type=click.FloatRange(min=0, min_open=True))
@click.option("--end", type=click.FloatRange(min=0, min_open=True))
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
def simulate(multimodel: str, out: str | None, step: float | None, end: float | None, algorithm: str | None) -> None:
    """Run any Maestro multimodel JSON with cotwin's master (FMUs through FMPy)."""
    from pathlib import Path

    from .cosim.multimodel import execution_for, read_multimodel

    _finite(step=step, end=end)
    mm = read_multimodel(multimodel)
    _step_count(mm.step if step is None else step, (mm.end if end is None else end) - mm.start,
                "--end" if end is not None else "--step" if step is not None else None, multimodel)
    csv_path = Path(out) if out else Path(multimodel).parent / "outputs.csv"
    execution = execution_for(mm, csv_path, step, algorithm)
    try:
        result = execution.run(mm.end if end is None else end)
    except (CotwinError, KeyboardInterrupt) as err:  # say where the rows computed so far are
        from .cosim.execution import ended_early

        raise ended_early(err, execution.time, execution.observers[0].kept()) from None
    click.echo(f"{csv_path}: {result.rows} rows to t = {result.end_time:g} s in {result.wall_seconds:.2f} s")


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=_output, required=True, help="folder for pt/ and dt/ outputs.csv, deviation.json, figure.png")
@click.option("--step", type=click.FloatRange(min=0, min_open=True), help="communication step size (s)")
@click.option("--end", type=click.FloatRange(min=0, min_open=True), help="end time (s)")
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
@click.option("--realtime/--no-realtime", default=None, help="pace to wall-clock time (default: the project's)")
@click.option("--pt-log", type=click.Path(), help="replay this recorded log as the PT (overrides [pt])")
@click.option("--rabbitmq", "exchange", callback=_exchange, help="take commands live from RabbitMQ on this exchange (overrides [scenario])")
@click.option("--history", "history", help="history database URL (default: [history] url, else DIR/history.sqlite)")
@click.option("--whatif", "whatif", is_flag=True, help="answer what-if requests sent over the broker (see docs)")
@click.option("--dashboard", "dashboard", metavar="HOST:PORT", callback=_address, help=DASHBOARD_HELP)
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
def twin(project: str, out: str, step: float | None, end: float | None, algorithm: str | None, realtime: bool | None,
         pt_log: str | None, exchange: str | None, history: str | None, whatif: bool, dashboard: tuple[str, int] | None,
         cc: str) -> None:
    """Run a live twin: the project's physical twin ([pt]) and its digital twin in lockstep on one clock,
    with deviation checking, alarms and history."""
    import signal
    from dataclasses import replace
    from pathlib import Path

    from .twin.history import database_url
    from .twin.project import PTSettings, RabbitMQSettings, load_project
    from .twin.run import load
    from .twin.runtime import LiveTwin

    _finite(step=step, end=end)
    if pt_log is not None and not Path(pt_log).is_file():
        raise click.BadParameter(f"no file {pt_log}", param_hint="--pt-log")
    spec = load_project(project, pt_log)
    _timing(spec, step, end)
    if pt_log is not None:
        spec.pt = replace(spec.pt, endpoint="replay", log=Path(pt_log)) if spec.pt else PTSettings("replay", log=Path(pt_log))
    if exchange is not None:
        spec.plan = None
        spec.rabbitmq = replace(spec.rabbitmq, exchange=exchange) if spec.rabbitmq else RabbitMQSettings(exchange)
        spec.realtime = True if realtime is None else realtime
    broker = spec.rabbitmq.url if spec.rabbitmq else "amqp://127.0.0.1:5672/%2F"
    system = load(spec)
    from .twin.scenario import after_end

    _show_warnings(after_end(system.commands, spec.end if end is None else end))
    dash = _dashboard(system, dashboard, "twin", database_url(history or spec.history_url, Path(out)),
                      broker if whatif else None)
    try:
        live = LiveTwin(system, out, step=step, end=end, algorithm=algorithm, realtime=realtime, history_url=history,
                        observers=[dash.feed] if dash else (), cc=cc, whatif_url=broker if whatif else None)

        def interrupt(*_) -> None:
            """In the step loop, end after the step (results kept as a finished run's); before it (waiting for
            the broker, building) or at a second signal, at once (rows so far kept as partial results)."""
            if not live.looping or live._stop:
                raise KeyboardInterrupt
            live.stop()
            click.echo("stopping after this step (interrupt again to stop at once)", err=True)

        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, interrupt)
        result = live.run()
        if dash is not None:
            dash.finish("stopped" if live._stop else "done")
    except BaseException as err:
        if dash is not None:
            dash.finish("failed", str(err) or type(err).__name__)
        raise
    finally:
        if dash is not None:
            dash.stop()
    r = result.pt
    state = "stopped early" if r.steps < live.steps or live._stop else "done"
    click.echo(f"{result.out}: PT and DT, {r.steps} steps each to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f}), {state}")
    click.echo(f"deviation: {result.deviation['alarms']} alarm(s); report {result.out / 'deviation.json'}; "
               f"history run {result.run_id} in {result.history_url.split('://', 1)[0]}")


def _plan_file(path: str, program):
    """A what-if plan: a plan CSV, a TOML command list or a JSON list of {time, event, args}."""
    import json
    from pathlib import Path

    from .twin.scenario import read_scenario
    from .twin.whatif import plan_from_json

    if path.endswith(".json"):
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as err:
            raise click.BadParameter(f"{path}: {err}", param_hint="--plan") from None
        return plan_from_json(data, program)
    return read_scenario(path, program)


@main.command()
@click.argument("project", type=click.Path())
@click.option("--plan", "plan", required=True, help="the hypothetical plan (CSV, TOML or JSON; times relative to the fork)")
@click.option("--from", "state", type=click.Path(), help="a saved DT state to fork (DIR/state of a run or a live twin)")
@click.option("--horizon", type=click.FloatRange(min=0, min_open=True, max=MAX_HORIZON), default=60.0, show_default=True,
              help="simulate at most this long (s)")
@click.option("-o", "--output", "out", callback=_output, help="write the prediction as JSON here")
def whatif(project: str, plan: str, state: str | None, horizon: float, out: str | None) -> None:
    """Predict what a plan would do: fork the DT (at a saved state, or at the start) and run the plan
    ahead of real time; prints each command's outcome and the completion time."""
    import json
    from pathlib import Path

    from .twin.run import load
    from .twin.whatif import predict

    _finite(horizon=horizon)
    system = load(project)
    commands = _plan_file(plan, system.models.program)
    blob = None
    if state is not None:
        try:
            blob = Path(state).read_bytes()
        except OSError as err:
            raise click.BadParameter(f"{state}: {err.strerror}", param_hint="--from") from None
    prediction = predict(system, commands, blob, horizon=horizon)
    for c in prediction.commands:
        args = ", ".join(f"{k}={v}" for k, v in c.args.items())
        verdict = {True: "feasible", False: "NOT feasible", None: "feasibility unknown"}[c.feasible]
        done = f"done at t = {c.done:g} s" if c.done is not None else "not done within the horizon"
        click.echo(f"t = {c.time:g} s {c.event}({args}): {verdict}, "
                   f"{'accepted' if c.accepted else 'ignored by the d-model'}, {done}")
    for c in prediction.collisions:
        click.echo(f"collision: {c}")
    click.echo(f"completion: {'t = %g s' % prediction.completion_time if prediction.completion_time is not None else 'not within the horizon'} "
               f"(forked at t = {prediction.start:g} s, predicted to t = {prediction.end:g} s in {prediction.wall_seconds:.2f} s)")
    if out:
        Path(out).write_text(json.dumps(prediction.as_dict(), indent=1) + "\n")


def _named_values(text: str, hint: str) -> tuple[str, list]:
    """NAME=LOW..HIGH (integers) or NAME=v1,v2,... (numbers) from an option; finite values only, at least
    one and at most MAX_VALUES of them."""
    from .config import is_number

    name, sep, values = text.partition("=")
    if not sep or not name or not values:
        raise click.BadParameter(f"'{text}': expected NAME=LOW..HIGH or NAME=v1,v2,...", param_hint=hint)
    try:
        if ".." in values:
            low, high = (int(v) for v in values.split("..", 1))
            out = None
        else:
            out = [int(v) if v.strip().lstrip("-").isdigit() else float(v) for v in values.split(",")]
    except ValueError:
        raise click.BadParameter(f"'{text[:80]}': values must be numbers", param_hint=hint) from None
    count = high - low + 1 if out is None else len(out)
    if count < 1:
        raise click.BadParameter(f"'{text[:80]}': {name} takes no value (an empty range: LOW..HIGH needs LOW <= HIGH)",
                                 param_hint=hint)
    if count > MAX_VALUES:
        raise click.BadParameter(f"'{text[:80]}': {name} takes {count if count < 10 ** 12 else 'countless'} values, more than "
                                 f"{MAX_VALUES}",
                                 param_hint=hint)
    out = list(range(low, high + 1)) if out is None else out
    if not all(is_number(v) for v in out):  # also an integer too large for any float
        raise click.BadParameter(f"'{text[:80]}': values must be finite numbers", param_hint=hint)
    return name, out


@main.command()
@click.argument("project", type=click.Path())
@click.option("--event", required=True, help="the command to sweep, e.g. moveDiscreteCommand")
@click.option("--arg", "args", multiple=True, metavar="NAME=LOW..HIGH", help="an argument's values (repeatable)")
@click.option("--from", "state", type=click.Path(), help="a saved DT state to fork every what-if from")
@click.option("--horizon", type=click.FloatRange(min=0, min_open=True, max=MAX_HORIZON), default=30.0, show_default=True,
              help="simulate each what-if at most this long (s)")
@click.option("--workers", type=click.IntRange(min=1, max=1024), help="local processes (default: one per CPU)")
@click.option("--ray", "ray", help="run on Ray: 'auto' (the local cluster) or a cluster address")
@click.option("-o", "--output", "out", callback=_output, required=True, help="the CSV of answers to write")
def sweep(project: str, event: str, args: tuple[str, ...], state: str | None, horizon: float, workers: int | None,
          ray: str | None, out: str) -> None:
    """Run one what-if per combination of argument values, in parallel (e.g. every hole of the plate:
    --event moveDiscreteCommand --arg target_X=0..15 --arg target_Y=0..23 --arg target_Z=0)."""
    import csv
    import time
    from pathlib import Path

    from .twin.run import load
    from .twin.sweep import grid, run_sweep

    _finite(horizon=horizon)
    ranges: dict[str, list] = {}
    for name, values in (_named_values(a, "--arg") for a in args):
        if name in ranges:
            raise click.BadParameter(f"argument {name!r} is given twice", param_hint="--arg")
        ranges[name] = values
    system = load(project)
    plans = grid(system.models.program, event, ranges)
    blob = Path(state).read_bytes() if state else None
    started = time.perf_counter()
    rows = run_sweep(project, plans, blob, horizon=horizon, workers=workers, ray=ray)
    wall = time.perf_counter() - started
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with open(out, "w", newline="") as f:
        writer = csv.DictWriter(f, columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    feasible = sum(1 for r in rows if r.get("feasible"))
    click.echo(f"{out}: {len(rows)} what-ifs in {wall:.1f} s ({'Ray' if ray else 'local pool'}), {feasible} feasible")


@main.command()
@click.argument("project", type=click.Path())
@click.option("--pt-log", type=click.Path(), help="the PT's recorded run of the project's plan (a UR RTDE log) to fit")
@click.option("-o", "--output", "out", callback=_output, type=click.Path(), help="the calibration file to write (with --pt-log)")
@click.option("--calibration", type=click.Path(), help="the calibration to check (with --check; default: the one "
              "just fitted, else the project's)")
@click.option("--check", "check_log", type=click.Path(), help="another recorded run to replay on the calibrated DT")
@click.option("--tool", default="flange", show_default=True, help="the tool point the PT targets: flange, "
              "fingertips or X,Y,Z (m, tool link frame); kept unless the log shows several tool orientations")
@click.option("--log-start", type=click.FloatRange(min=-1e9, max=1e9), default=0.0, show_default=True,
              help="co-simulation time of the log's first row (s), for the commands' latencies")
def calibrate(project: str, pt_log: str | None, out: str | None, calibration: str | None, check_log: str | None,
              tool: str, log_start: float) -> None:
    """Fit the DT to a recorded PT run (plate pose, tool, movej profile, latencies, servo lag) and print the
    per-joint RMSE before and after; or replay another recorded run on a calibrated DT (--check)."""
    import math

    from .mapping.rtde import read_arm_log
    from .pmodel.cell import CellGeometry
    from .twin import calibration as cal
    from .twin.project import load_project
    from .twin.run import load

    if pt_log is None and check_log is None:
        raise click.UsageError("give --pt-log LOG -o FILE to fit, or --calibration FILE --check LOG to check")
    if pt_log is not None and out is None:
        raise click.UsageError("--pt-log needs -o FILE: where to write the calibration")
    for option, path in (("--pt-log", pt_log), ("--check", check_log), ("--calibration", calibration)):
        if path is not None and not Path(path).is_file():
            raise click.BadParameter(f"no file {path}", param_hint=option)
    if not math.isfinite(log_start):
        raise click.BadParameter(f"{log_start!r} is not a finite number", param_hint="--log-start")
    point = tool if tool in ("flange", "fingertips") else _point(tool)
    system = load(load_project(project, pt_log))  # the log to fit replaces [pt] log
    twin, program, commands = cal.project_twin(system)
    fitted = None
    if pt_log is not None:
        report = cal.calibrate(twin, program, commands, read_arm_log(pt_log), CellGeometry(tool=point), log_start)
        fitted = report.calibration
        fitted.write(out, f"cotwin calibration of {Path(project).name}, fitted on {Path(pt_log).name} "
                          "(cotwin calibrate)")
        click.echo("\n".join(report.lines()))
        click.echo(f"wrote {out}")
    if check_log is not None:
        chosen = cal.Calibration.read(calibration) if calibration is not None else fitted or system.models.calibration
        if chosen is None:
            raise click.UsageError("--check needs a calibration: --calibration FILE, --pt-log to fit one, or a "
                                   "project with [platform] calibration")
        click.echo("\n".join(cal.check(twin, program, commands, read_arm_log(check_log), chosen).lines()))


def _point(text: str) -> tuple[float, float, float]:
    import math

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) and abs(v) <= 10.0 for v in values):
        raise click.BadParameter(f"{text[:80]!r}: flange, fingertips or three numbers X,Y,Z (m, within 10 m of the "
                                 "tool link)", param_hint="--tool")
    return values


@main.group()
def history() -> None:
    """The twin's history store: list runs, export one as CSV."""


def _db(db: str | None, folder: str | None) -> str:
    from pathlib import Path

    from .twin.history import database_url

    if db is None and folder is None:
        raise click.UsageError("give --db URL or --dir DIR (a twin's output folder, with history.sqlite)")
    if folder is not None and not (Path(folder) / "history.sqlite").is_file():
        raise click.BadParameter(f"no history.sqlite in {folder}", param_hint="--dir")
    return database_url(db, Path(folder) if folder else None)


@history.command("list")
@click.option("--db", help="database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
def history_list(db: str | None, folder: str | None) -> None:
    """List the runs of a history store."""
    import datetime

    from .twin.history import list_runs

    for run in list_runs(_db(db, folder)):
        started = datetime.datetime.fromtimestamp(run["started"]).isoformat(timespec="seconds")
        click.echo(f"{run['id']:>5}  {started}  {run['kind']:<5} {run['status']:<10} step {run['step']:g} s  "
                   f"{run['samples']} samples  {run['alarms']} alarm(s)  {run['project']}")


@history.command("export")
@click.argument("run_id", type=int)
@click.option("--db", help="database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
@click.option("--side", default="dt", show_default=True, help="pt or dt")
@click.option("-o", "--output", "out", callback=_output, required=True, help="the CSV to write")
def history_export(run_id: int, db: str | None, folder: str | None, side: str, out: str) -> None:
    """Export one side of a run as a Maestro-format CSV."""
    from .twin.history import export_csv

    path = export_csv(_db(db, folder), run_id, side, out)
    click.echo(str(path))


@main.command("dashboard")
@click.option("--db", help="history database URL (sqlite:///file, postgresql://...)")
@click.option("--dir", "folder", type=click.Path(), help="a twin's output folder (its history.sqlite)")
@click.option("--at", "address", default="127.0.0.1:8050", show_default=True, metavar="HOST:PORT", callback=_address,
              help="where to serve the page")
def dashboard_command(db: str | None, folder: str | None, address: tuple[str, int]) -> None:
    """Browse the runs of a history store in the dashboard (after the run), until interrupted."""
    import threading

    from .twin.dashboard import Dashboard

    dash = Dashboard(None, *address, mode="history", history_url=_db(db, folder)).start()
    click.echo(f"dashboard: {dash.url} (history only; Ctrl-C to stop)", err=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        dash.stop()


@main.command()
@click.argument("project", type=click.Path())
@click.option("--plan", "plan", type=click.Path(), help="the commands to publish (default: the project's plan)")
@click.option("--period", type=click.FloatRange(min=0.01, max=3600), default=0.5, show_default=True,
              help="seconds of wall time between messages")
@click.option("--exchange", callback=_exchange, help="the twin's exchange (default: the project's [scenario] rabbitmq exchange)")
def publish(project: str, plan: str | None, period: float, exchange: str | None) -> None:
    """Publish commands to a live twin over RabbitMQ, as the paper's UR5e publisher does: wait for the
    ready message, then every PERIOD send the command due at the echoed simulation time, else idle."""
    from dataclasses import replace

    from .twin.project import RabbitMQSettings
    from .twin.publisher import Publisher, idle_values
    from .twin.rabbitmq import port_types
    from .twin.run import load
    from .twin.scenario import read_scenario

    _finite(period=period)
    system = load(project)
    settings = system.spec.rabbitmq or RabbitMQSettings(exchange or "fmi_digital_twin_dt")
    if exchange:
        settings = replace(settings, exchange=exchange)
    program = system.models.program
    if plan is None and system.spec.plan is None:
        raise click.BadParameter("the project has no plan: give one with --plan", param_hint="--plan")
    commands = read_scenario(plan or system.spec.plan, program)
    ports = system.live_ports()
    publisher = Publisher(settings, commands, idle_values(port_types(program, ports)), period=period,
                          end=system.spec.end)
    click.echo(f"publishing {len(commands)} command(s) on exchange {settings.exchange} ({settings.to_cosim}); "
               "waiting for the twin's ready message", err=True)
    publisher.run()
    click.echo(f"sent {len(publisher.sent)} message(s)")


@main.command()
@click.argument("project", type=click.Path())
@click.option("--opcua", "url", metavar="URL", help="where to serve, e.g. opc.tcp://127.0.0.1:4840 (loopback only; "
              "default: the project's [pt] url, else port 4840)")
@click.option("--perturbation", "perturbation_file", type=click.Path(), help="a TOML file of [plant] keys "
              "(instead of the project's [plant] table)")
@click.option("--seed", type=click.IntRange(min=0, max=2 ** 63 - 1), help="seed of the sensor noise")
@click.option("--payload", type=click.FloatRange(min=0, max=1000), metavar="KG", help="a mass at the tool (kg)")
@click.option("--latency-ms", type=click.FloatRange(min=0, max=10_000), metavar="MS", help="goals take effect this late")
@click.option("--noise", type=click.FloatRange(min=0, max=1000), metavar="STD", help="Gaussian noise on every measurement")
@click.option("--free-running", is_flag=True, help="advance in real time; Advance waits for the plant's clock")
def plant(project: str, url: str | None, perturbation_file: str | None, seed: int | None, payload: float | None,
          latency_ms: float | None, noise: float | None, free_running: bool) -> None:
    """Serve a stand-in robot cell over OPC UA: the project's models in the simulator, perturbed as its
    [plant] table and these options say, until SIGINT or SIGTERM."""
    from .twin.plant import load_plant

    _finite(payload=payload, latency_ms=latency_ms, noise=noise)
    cell = load_plant(project, url, free_running, perturbation_file, seed=seed, payload=payload,
                      latency_ms=latency_ms, noise=noise)

    def announce(served) -> None:
        p = served.endpoint.perturbation
        click.echo(f"serving {served.endpoint.tree.name} on {served.url} ({served.mode}; perturbation: "
                   f"{'none' if p.nominal else p.as_dict()})")
        if served.credentials_file is not None:
            click.echo(f"operator credentials for local clients: {served.credentials_file}")
        click.echo("stop with Ctrl-C", err=True)

    cell.serve_until_signalled(announce)
    click.echo(f"stopped after {cell.calls} call(s), {cell.refused} refused")


@main.command("serve-robot")
@click.argument("project", type=click.Path())
@click.option("--queue", help="the request queue (default: the project's [platform] queue)")
@click.option("--url", help="the broker (default: the project's [platform] url)")
def serve_robot(project: str, queue: str | None, url: str | None) -> None:
    """Serve the project's platform (the MuJoCo simulator) as a robot behind the broker, for twins
    whose [platform] endpoint is "broker". Needs COTWIN_ROBOT_SECRET (shared with the twin); broker
    credentials as for every link (docs/security.md). Stops on Ctrl-C or SIGTERM, never on a message."""
    import signal
    import threading

    from .mapping.amqp import redact, url_problem
    from .mapping.broker import RobotServer
    from .mapping.endpoint import SimulatedEndpoint
    from .pmodel.simulator import PlatformSimulator
    from .twin.run import load

    system = load(project)
    url = url or system.spec.url
    if url_problem(url):
        raise click.BadParameter(url_problem(url), param_hint="--url")
    queue = queue or system.spec.queue
    simulator = PlatformSimulator(system.models.tree, system.models.scene, base=system.spec.base)
    server = RobotServer(SimulatedEndpoint(simulator), queue, url)
    failure: list[CotwinError] = []

    def serve() -> None:
        try:
            server.serve()
        except CotwinError as err:
            failure.append(err)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: server.stop())
    thread = threading.Thread(target=serve, name="robot server", daemon=True)
    thread.start()
    while thread.is_alive() and not server.ready.wait(0.2):
        pass
    if server.ready.is_set():
        click.echo(f"serving the robot on queue {queue} at {redact(url)} (stop: Ctrl-C or SIGTERM)", err=True)
        click.echo("ready", err=False)
        sys.stdout.flush()
    while thread.is_alive():
        thread.join(0.2)
    if failure:
        raise failure[0]
    click.echo(f"served {server.requests} request(s); refused {server.refused} unauthenticated, dropped "
               f"{server.dropped} unanswerable", err=True)


@main.command("broker-permissions")
@click.argument("project", type=click.Path())
@click.option("--vhost", default="cotwin", show_default=True, help="the virtual host of the twin's links")
@click.option("--prefix", default="cotwin-", show_default=True, help="user names: PREFIX + role")
def broker_permissions(project: str, vhost: str, prefix: str) -> None:
    """Print the rabbitmqctl commands creating a vhost and one least-privilege user per role (twin,
    robot server, publisher, alarms monitor) for this project's exchanges and queues."""
    from .twin.broker_access import rabbitmqctl_script
    from .twin.project import load_project

    click.echo(rabbitmqctl_script(load_project(project), vhost, prefix), nl=False)


@main.command()
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module to verify (default: the only one)")
@click.option("--domain", "domains", multiple=True, metavar="PORT=LOW..HIGH",
              help="values of an event's value port, e.g. MovementArgs_target_X=0..15 (repeatable)")
@click.option("--max-states", default=100_000, show_default=True, type=click.IntRange(min=1, max=10 ** 8),
              help="stop exploring after this many states")
def verify(model: tuple[str, ...], module_name: str | None, domains: tuple[str, ...], max_states: int) -> None:
    """Explore every state of a d-model module under every input combination; check the core
    properties (timelock, determinism, divergence, repeated outputs) and reachability."""
    from .dmodel.program import build_program
    from .dmodel.verify import format_report, verify as explore
    from .robosim.check import load_checked

    program = build_program(load_checked(model), module_name)
    parsed = dict(_named_values(d, "--domain") for d in domains)
    known = [port for ev in program.inputs for port, _ in ev.value_ports]
    unknown = [name for name in parsed if name not in known]
    if unknown:
        raise click.BadParameter(f"{', '.join(unknown)}: not a value port of an input event of module "
                                 f"{program.module.name} (ports: {', '.join(known) or 'none'})", param_hint="--domain")
    report = explore(program, parsed, max_states=max_states)
    click.echo(format_report(program, report))
    sys.exit(0 if report.ok else 1)


def _terminate(signum, frame) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def entry() -> None:
    """Entry point: every error escaping a command is reported as a message, never a traceback.
    SIGTERM ends a run like Ctrl-C: units are ended properly and the rows so far are kept."""
    import signal

    signal.signal(signal.SIGTERM, _terminate)
    try:
        main(standalone_mode=False)
    except CotwinError as err:
        _report(err.findings)
        sys.exit(130 if getattr(err, "interrupted", False) else 1)
    except OSError as err:  # a file or folder that cannot be read or written
        click.echo(f"error: {err.strerror or err}{f': {err.filename}' if err.filename else ''}", err=True)
        sys.exit(1)
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("interrupted", err=True)
        sys.exit(130)
    except click.ClickException as err:
        err.show()
        sys.exit(err.exit_code)
    except RecursionError:
        click.echo("error: the input is nested too deeply to process", err=True)
        sys.exit(1)
    except Exception as err:  # noqa: BLE001 - a bug of cotwin's: say so in one line, keep the details
        import tempfile
        import traceback

        with tempfile.NamedTemporaryFile("w", prefix="cotwin-crash-", suffix=".txt", delete=False) as f:
            traceback.print_exc(file=f)
        click.echo(f"internal error: {type(err).__name__}: {str(err)[:300]} (a cotwin bug; details in {f.name})",
                   err=True)
        sys.exit(70)
