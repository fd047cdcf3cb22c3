"""Commands of the live twin and its peers: twin, publish, plant, serve-robot, broker-permissions."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..diagnostics import CotwinError, Finding, Location, Severity
from ..twin.assembly.observing import TwinObserver
from .common import (DASHBOARD_HELP, ON_UNIT_FAILURE, STRICT_HELP, Tally, address, check_finite, check_timing,
                     closing_tally, exchange_name, history_url, interruptible, main, output_folder, plan_warnings,
                     said_restarts, serving_options, show_outcomes, start_dashboard, strict_exit)


@main.command()
@click.argument("project", type=click.Path())
@click.option("-o", "--output", "out", callback=output_folder, required=True, help="folder for pt/ and dt/ outputs.csv, deviation.json, figure.png")
@click.option("--step", type=click.FloatRange(min=0, min_open=True), help="communication step size (s)")
@click.option("--end", type=click.FloatRange(min=0, min_open=True), help="end time (s)")
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]))
@click.option("--realtime/--no-realtime", default=None, help="pace to wall-clock time (default: the project's)")
@click.option("--pt-log", type=click.Path(), help="replay this recorded log as the PT (overrides [pt])")
@click.option("--pt-url", metavar="URL", help="where the PT is (overrides [pt] url; opc.tcp://HOST:PORT is an OPC UA "
              "plant even without a [pt] table)")
@click.option("--rabbitmq", "exchange", callback=exchange_name, help="take commands live from RabbitMQ on this exchange (overrides [scenario])")
@click.option("--history", "history", callback=history_url, help="history database URL (default: [history] url, else DIR/history.sqlite)")
@click.option("--whatif", "whatif", is_flag=True, help="answer what-if requests sent over the broker (see docs)")
@click.option("--dashboard", "dashboard", metavar="HOST:PORT", callback=address, help=DASHBOARD_HELP)
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
@serving_options
@ON_UNIT_FAILURE
@click.option("--strict", is_flag=True, help=STRICT_HELP)
def twin(project: str, out: str, step: float | None, end: float | None, algorithm: str | None, realtime: bool | None,
         pt_log: str | None, pt_url: str | None, exchange: str | None, history: str | None, whatif: bool,
         dashboard: tuple[str, int] | None, cc: str, serving: dict, strict: bool, on_unit_failure: str) -> None:
    """Run a live twin: the project's physical twin ([pt]) and its digital twin in lockstep on one clock,
    with deviation checking, alarms and history."""
    from ..twin.services.history import database_url
    from ..twin.project import load_project
    from ..twin.assembly.run import load, step_warnings
    from ..twin.live.runtime import LiveTwin
    from .progress import ProgressReport

    said = closing_tally()  # the errors and warnings shown, counted in the twin's closing line, a failed twin's too
    check_finite(step=step, end=end)
    if pt_log is not None and not Path(pt_log).is_file():
        raise click.BadParameter(f"no file {pt_log}", param_hint="--pt-log")
    spec = load_project(project, pt_log, step=step, end=end)
    check_timing(spec, step, end)
    if exchange is not None:
        spec = spec.with_overrides(scenario_plan=None, scenario_commands=None, scenario_rabbitmq_exchange=exchange,
                                   realtime=True if realtime is None else realtime)
    if spec.robots:
        if on_unit_failure != "stop":
            raise click.BadParameter("a cell of several robots cannot save its state yet, so a failed step cannot be "
                                     "retried from it", param_hint="--on-unit-failure")
        return _cell_twin(spec, out, step, end, algorithm, realtime, pt_log, pt_url, history, whatif,
                          dashboard, cc, serving, strict, said)
    if pt_url is not None:
        spec = pt_with_url(spec, pt_url, pt_log is not None)
    if spec.pt is None:  # said before the models are read and the plan's warnings shown
        raise CotwinError([Finding(Location(str(spec.path), 0, 0), Severity.ERROR,
                                   "a live twin needs a PT: a [pt] table (endpoint = opcua | replay | broker | rtde), "
                                   "or --pt-log LOG (a recorded run) or --pt-url opc.tcp://HOST:PORT (an OPC UA plant)")])
    broker = spec.rabbitmq.url if spec.rabbitmq else "amqp://127.0.0.1:5672/%2F"
    system = load(spec)
    from ..twin.assembly.endpoints import endpoint_advice

    said.warn(step_warnings(system, step), plan_warnings(system, spec.end if end is None else end),
              endpoint_advice(system, "pt"))  # the last: what the PT's kind cannot carry
    dash = start_dashboard(system, dashboard, "twin", database_url(history or spec.history_url, Path(out)),
                           broker if whatif else None, serving)
    progress = ProgressReport("twin", "s").__enter__()
    try:
        live = LiveTwin(system, out, step=step, end=end, algorithm=algorithm, realtime=realtime, history_url=history,
                        observers=[*([dash.feed] if dash else ()), TwinProgress(progress)], cc=cc,
                        whatif_url=broker if whatif else None, restart=on_unit_failure == "restart-from-state")
        with interruptible(lambda: live.looping, lambda: live.stop_requested, live.stop):
            result = live.run()
        if dash is not None:
            dash.finish("stopped" if live.stop_requested else "done")
    except BaseException as err:
        if dash is not None:
            dash.finish("failed", str(err) or type(err).__name__)
        raise
    finally:
        progress.__exit__(None, None, None)
        if dash is not None:
            dash.stop()
    r = result.pt
    said.errors += said_restarts(unit for side in live.sides.values() for unit in side.execution.system.units.values())
    state = "stopped early" if r.steps < live.steps or live.stop_requested else "done"
    click.echo(f"{result.out}: PT and DT, {r.steps} steps each to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f}), {state}")
    click.echo(f"deviation: {result.deviation['alarms']} alarm(s); report {result.out / 'deviation.json'}; "
               f"history run {result.run_id} in {result.history_url.split('://', 1)[0]}")
    if result.convergence:
        from ..twin.assembly.convergence import summary

        click.echo(summary(result.convergence))
    ended(result, {name.upper(): side.summary() for name, side in result.sides.items()}, said, strict)


def ended(result, summaries: dict, said: Tally, strict: bool, named: bool = False) -> None:
    """How a twin's run ended, as a run's does: each side's outcomes, that its history store failed during the
    run if it did (an error: its outputs are whole, the store is not), the closing count, and its exit status
    (--strict's, else 1 for the failed store). `named`: the strict failures named (a cell's)."""
    if result.history_problem is not None:
        said.error(f"{result.history_problem}; the run's outputs in {result.out} are whole")
    show_outcomes(summaries, said)
    said.close()
    strict_exit(summaries, strict, named)
    if result.history_problem is not None:
        sys.exit(1)


def _cell_twin(spec, out: str, step, end, algorithm, realtime, pt_log, pt_url, history, whatif, dashboard,
               cc: str, serving: dict, strict: bool, said: Tally) -> None:
    """`cotwin twin` of a cell of several robots ([[robots]]): its perturbed plant as the PT (cotwin.twin.live.cell_live).
    An interrupt in the step loop ends the run after the step, its results kept as a finished run's; before
    the loop, or a second one, at once (rows so far kept as partial results), as a single robot's twin does.
    `said`: the twin's count of the errors and warnings shown."""
    import threading

    from ..twin.assembly.cell import CellSystem
    from ..twin.live.cell_live import run_cell_twin
    from ..twin.services.history import database_url
    from .progress import ProgressReport

    unsupported = [flag for flag, given in (("--pt-log", pt_log), ("--pt-url", pt_url), ("--whatif", whatif)) if given]
    if unsupported:
        raise click.UsageError(f"a cell of several robots is twinned with its own perturbed plant as the PT: "
                               f"{', '.join(unsupported)} not done yet")
    cell = CellSystem(spec)
    said.warn(plan_warnings(cell, spec.end if end is None else end))
    stop, looping = threading.Event(), threading.Event()

    class Looping(TwinObserver):
        def twin_started(self, twin) -> None:
            looping.set()

    dash = start_dashboard(cell, dashboard, "twin", database_url(history or spec.history_url, Path(out)), None, serving)
    try:
        with ProgressReport("twin", "s") as progress, interruptible(looping.is_set, stop.is_set, stop.set):
            result = run_cell_twin(cell, out, step, end, algorithm, realtime, history, cc,
                                   observers=[Looping(), *([dash.feed] if dash else ()), TwinProgress(progress)],
                                   stop=stop)
        if dash is not None:
            dash.finish("stopped" if result.stopped else "done")
    except BaseException as err:
        if dash is not None:
            dash.finish("failed", str(err) or type(err).__name__)
        raise
    finally:
        if dash is not None:
            dash.stop()
    r = result.pt
    click.echo(f"{result.out}: PT and DT, {r.steps} steps each to t = {r.end_time:g} s in {r.wall_seconds:.2f} s "
               f"(real-time factor {r.real_time_factor:.1f}), {'stopped early' if result.stopped else 'done'}")
    click.echo(f"deviation: {result.alarm_count} alarm(s); report {result.out / 'deviation.json'}; "
               f"history run {result.run_id} in {result.history_url.split('://', 1)[0]}")
    ended(result, {side.upper(): summary for side, summary in result.outcomes.items()}, said, strict, named=True)


class TwinProgress(TwinObserver):
    """A live twin's observer that reports its simulated time against its end."""

    def __init__(self, report):
        self.report = report

    def twin_step(self, twin, k: int, t: float) -> None:
        self.report(round(t, 6), twin.end, f"step {k}")


def pt_with_url(spec, url: str, replayed: bool):
    """The project with --pt-url's URL as its [pt] url, checked as the project's own is."""
    from ..twin.project import pt_url_problem

    if replayed:
        raise click.UsageError("--pt-url and --pt-log name two different PTs: give one")
    pt = spec.pt
    if pt is None and not url.startswith("opc.tcp://"):
        raise click.BadParameter("the project has no [pt] table, so only an OPC UA plant (opc.tcp://HOST:PORT) "
                                 "can be named here", param_hint="--pt-url")
    endpoint = "opcua" if pt is None else pt.endpoint
    if endpoint == "replay":
        raise click.BadParameter("the project's PT replays a log ([pt] endpoint = \"replay\"), which has no url",
                                 param_hint="--pt-url")
    problem = pt_url_problem(endpoint, url)
    if problem is not None:
        raise click.BadParameter(f"{problem} (for [pt] endpoint '{endpoint}')", param_hint="--pt-url")
    return spec.with_overrides(pt_endpoint=endpoint, pt_url=url)


@main.command()
@click.argument("project", type=click.Path())
@click.option("--plan", "plan", type=click.Path(), help="the commands to publish (default: the project's plan)")
@click.option("--period", type=click.FloatRange(min=0.01, max=3600), default=0.5, show_default=True,
              help="seconds of wall time between messages")
@click.option("--exchange", callback=exchange_name, help="the twin's exchange (default: the project's [scenario] rabbitmq exchange)")
@click.option("--robot", help="a cell of several robots ([[robots]]): publish this robot's commands (its plan columns "
              "ROBOT.port), routed to it (TO_COSIM.ROBOT)")
def publish(project: str, plan: str | None, period: float, exchange: str | None, robot: str | None) -> None:
    """Publish commands to a live twin over RabbitMQ, as the paper's arm publisher does: wait for the
    ready message, then every PERIOD send the command due at the echoed simulation time, else idle."""
    from dataclasses import replace

    from ..twin.project import RabbitMQSettings
    from ..twin.services.publisher import Publisher, idle_values
    from ..twin.assembly.rabbitmq import port_types
    from ..twin.assembly.run import load
    from ..twin.assembly.scenario import read_scenario

    check_finite(period=period)
    system = load(project, cells=True)
    settings = system.spec.rabbitmq or RabbitMQSettings(exchange or "fmi_digital_twin_dt")
    if exchange:
        settings = replace(settings, exchange=exchange)
    if plan is None and system.spec.plan is None:
        raise click.BadParameter("the project has no plan: give one with --plan", param_hint="--plan")
    if system.spec.robots:
        from ..twin.assembly.cell import read_cell_plan, routed

        names = [r.name for r in system.robots]
        if robot not in names:
            raise click.BadParameter(f"a cell's commands go to one robot: one of {', '.join(names)}",
                                     param_hint="--robot")
        program = system.program
        settings = routed(settings, robot)
        commands = read_cell_plan(plan or system.spec.plan, program, names)[robot]
        ports = next(r for r in system.robots if r.name == robot).system.live_ports()
    else:
        if robot is not None:
            raise click.BadParameter("only for a cell of several robots ([[robots]])", param_hint="--robot")
        program = system.models.program
        commands = read_scenario(plan or system.spec.plan, program)
        ports = system.live_ports()
    publisher = Publisher(settings, commands, idle_values(port_types(program, ports)), period=period,
                          end=system.spec.end)
    click.echo(f"publishing {len(commands)} command(s) on exchange {settings.exchange} ({settings.to_cosim}); "
               "waiting for the twin's ready message", err=True)
    publisher.run()
    clock = publisher.clock
    refused = f"; {clock.refused} echo(es) refused (see the log)" if clock is not None and clock.refused else ""
    click.echo(f"sent {len(publisher.sent)} message(s){refused}")
    if publisher.ended == "silence":
        heard = f"t = {clock.sim:g} s" if clock is not None and clock.sim is not None else "no time at all"
        unsent = f"; {len(publisher.pending)} command(s) of the plan never sent" if publisher.pending else ""
        raise CotwinError(f"the twin on exchange {settings.exchange} fell silent: no echo for {publisher.silence:g} s "
                          f"after {heard}{f' (its end is t = {system.spec.end:g} s)' if system.spec.end else ''}{unsent}")


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
@click.option("--reset-on-connect", is_flag=True, help="back to the initial posture at time 0 whenever an operator "
              "(a twin) connects, so that every twin run starts from the same posture")
def plant(project: str, url: str | None, perturbation_file: str | None, seed: int | None, payload: float | None,
          latency_ms: float | None, noise: float | None, free_running: bool, reset_on_connect: bool) -> None:
    """Serve a stand-in robot cell over OPC UA: the project's models in the simulator, perturbed as its
    [plant] table and these options say, until SIGINT or SIGTERM."""
    from ..twin.services.plant import load_plant

    check_finite(payload=payload, latency_ms=latency_ms, noise=noise)
    cell = load_plant(project, url, free_running, perturbation_file, reset_on_connect, seed=seed, payload=payload,
                      latency_ms=latency_ms, noise=noise)

    def announce(served) -> None:
        p = served.endpoint.perturbation
        click.echo(f"serving {served.endpoint.tree.name} on {served.url} ({served.mode}"
                   f"{', reset on connect' if served.reset_on_connect else ''}; perturbation: "
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

    from ..mapping.amqp import redact, url_problem
    from ..mapping.broker import RobotServer
    from ..mapping.endpoint import SimulatedEndpoint
    from ..pmodel.simulator import PlatformSimulator
    from ..twin.assembly.run import load

    system = load(project)
    url = url or system.spec.url
    if url_problem(url):
        raise click.BadParameter(url_problem(url), param_hint="--url")
    queue = queue or system.spec.queue
    simulator = PlatformSimulator(system.models.tree, system.models.scene, base=system.spec.base)
    server = RobotServer(SimulatedEndpoint(simulator), queue, url)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: server.stopping.set())  # the server's thread ends after its current message
    try:
        server.start(timeout=None)  # on its own thread (cotwin.service): until it is on its queue, or fails
    except CotwinError:
        if server.failure is not None:
            raise
    else:
        click.echo(f"serving the robot on queue {queue} at {redact(url)} (stop: Ctrl-C or SIGTERM)", err=True)
        click.echo("ready", err=False)
        sys.stdout.flush()
    while not server.wait(0.2):
        pass
    server.check()  # the broker stayed away
    click.echo(f"served {server.requests} request(s); refused {server.refused} unauthenticated, dropped "
               f"{server.dropped} unanswerable", err=True)


def broker_name(ctx, param, value: str) -> str:
    """A vhost or user name for rabbitmqctl: not empty (RabbitMQ refuses it) and one printable line."""
    if not value.strip() or not value.isprintable():
        raise click.BadParameter(f"{value!r}: a name of printable characters, not empty")
    return value


@main.command("broker-permissions")
@click.argument("project", type=click.Path())
@click.option("--vhost", default="cotwin", show_default=True, callback=broker_name,
              help="the virtual host of the twin's links")
@click.option("--prefix", default="cotwin-", show_default=True, help="user names: PREFIX + role")
def broker_permissions(project: str, vhost: str, prefix: str) -> None:
    """Print the rabbitmqctl commands creating a vhost and one least-privilege user per role (twin,
    robot server, publisher, alarms monitor) for this project's exchanges and queues."""
    from ..twin.assembly.broker_access import rabbitmqctl_script
    from ..twin.project import load_project

    click.echo(rabbitmqctl_script(load_project(project), vhost, prefix), nl=False)
