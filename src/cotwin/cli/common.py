"""What the `cotwin` commands share: the command group, option checks and how findings are printed."""

from __future__ import annotations

import math
import signal
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Protocol

import click

from ..diagnostics import CotwinError, Finding, Severity
from ..files import special_file

MAX_HORIZON = 86_400.0  # s: the longest a what-if looks ahead
MAX_VALUES = 100_000  # values of one --arg or --domain
MAX_REPORTED = 50  # findings printed at once: a file with thousands of problems says how many more


def report(findings, stream=None) -> None:
    stream = stream or sys.stderr
    findings = list(findings)
    for f in findings[:MAX_REPORTED]:
        click.echo(str(f), file=stream)
    if len(findings) > MAX_REPORTED:
        rest = findings[MAX_REPORTED:]
        errors = sum(f.severity is Severity.ERROR for f in rest)
        click.echo(f"... and {len(rest)} more problem(s) not shown ({errors} error(s))", file=stream)


ON_UNIT_FAILURE = click.option(
    "--on-unit-failure", type=click.Choice(["stop", "restart-from-state"]), default="stop", show_default=True,
    help="when an FMU crashes, hangs or fails a step: end the run (the rows so far kept), or retry the step once "
         "in a new process from the FMU's state after its last good step (FMUs that can save their state; every "
         "FMU then runs in a process of its own)")


def said_restarts(units) -> int:
    """Say which units were restarted from a state during the run (each restart was logged as it happened);
    how many restarts (each after a failed step: an error recovered)."""
    count = 0
    for unit in units:
        restarts = unit.restarts
        count += len(restarts or ())
        if restarts:
            times = ", ".join(f"{t:g}" for t, _ in restarts[:20]) + (", ..." if len(restarts) > 20 else "")
            click.echo(f"unit {unit.name}: restarted {len(restarts)} time(s) from its last good state, at t = {times} s",
                       err=True)
    return count


def _hint(param) -> str:
    """How the option is named in its errors (-o/--output, --junit)."""
    return "/".join(param.opts) if param is not None and param.opts else "-o/--output"


def output_path(ctx, param, value: str | None) -> str | None:
    """An -o option: a path, never the empty string (which would write into the current folder)."""
    if value is not None and not value.strip():
        raise click.BadParameter("an empty path: name the file or folder to write", param_hint=_hint(param))
    return value


def _file_on_the_way(path: Path) -> Path | None:
    """The first of `path` and its parents that exists as something other than a folder, if any."""
    for at in [*reversed(path.parents), path]:
        if at.exists() and not at.is_dir():
            return at
    return None


def _unwritable(folder: Path) -> str:
    """Why this user cannot write into `folder`: its file system is mounted read-only (which 'no permission' sent
    a root user to chmod in vain), or no permission."""
    import os

    try:
        read_only = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False
    return "a read-only file system" if read_only else "no permission"


def output_folder(ctx, param, value: str | None) -> str | None:
    """An -o option naming a folder to write into: refused before anything runs if it (or a folder it would
    be made in) is a file, or is a folder this user cannot write into."""
    import os

    value = output_path(ctx, param, value)
    if value is None:
        return None
    blocking = _file_on_the_way(Path(value))
    if blocking is not None:
        what = "is a file" if blocking == Path(value) else f"would be made inside {blocking}, a file"
        raise click.BadParameter(f"{value}: {what}, not a folder: name a folder to write into", param_hint="-o/--output")
    existing = next(p for p in [Path(value), *Path(value).parents] if p.exists())
    if not os.access(existing, os.W_OK | os.X_OK):
        raise click.BadParameter(f"{value}: cannot write into {existing} ({_unwritable(existing)})",
                                 param_hint="-o/--output")
    return value


def output_file(ctx, param, value: str | None) -> str | None:
    """An -o option naming a file to write: refused before anything runs if it is a folder, or would be made
    inside a file, or in a folder this user cannot write into."""
    import os

    value = output_path(ctx, param, value)
    if value is None:
        return None
    path = Path(value)
    if path.is_dir():
        raise click.BadParameter(f"{value}: is a folder: name the file to write", param_hint=_hint(param))
    special = special_file(path)
    if special is not None:  # the output would be renamed over it: /dev/null replaced, run as root
        raise click.BadParameter(f"{value}: is {special}, not a file: name a file to write", param_hint=_hint(param))
    blocking = _file_on_the_way(path.parent)
    if blocking is not None:
        raise click.BadParameter(f"{value}: would be made inside {blocking}, a file", param_hint=_hint(param))
    existing = next(p for p in path.parents if p.exists())
    if not os.access(existing, os.W_OK | os.X_OK):
        raise click.BadParameter(f"{value}: cannot write into {existing} ({_unwritable(existing)})",
                                 param_hint=_hint(param))
    from ..twin.assembly.build import folder_holder

    holder = folder_holder(path.parent)
    if holder is not None:  # the run would put its own file of that name over this one, which said it was written
        raise click.BadParameter(f"{value}: {path.parent} is in use by another cotwin run ({holder}), which writes "
                                 "its files there: write elsewhere or wait for it to finish", param_hint=_hint(param))
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cotwin")
def main() -> None:
    """cotwin: RoboSim models to FMI-based digital twins."""


STRICT_HELP = ("exit with status 3 unless every command the run applied completed and no wait was blocked "
               "(docs/interop.md, Honest outcomes)")


class Outcomes(Protocol):
    """What a run says became of its commands (a single robot's cotwin.twin.assembly.outcomes.Summary, a cell's
    cotwin.twin.assembly.cell.CellOutcomes): its lines, its warnings, what `--strict` refuses."""

    def lines(self) -> list[str]: ...

    def warnings(self) -> list[str]: ...

    def strict_failures(self) -> list[str]: ...


def show_outcomes(summaries: dict[str, Outcomes], tally: Tally, per_command: bool = True) -> None:
    """Each summary's lines by label ('' or PT, DT), only its first (the counts) unless `per_command`, and its
    warnings (no command completed, blocked waits), counted in `tally`."""
    for label, summary in summaries.items():
        prefix = f"{label}: " if label else ""
        lines = summary.lines()
        for line in lines if per_command else lines[:1]:
            click.echo(prefix + line)
        for warning in summary.warnings():
            tally.warning(warning, prefix)


def strict_exit(summaries: dict[str, Outcomes], strict: bool, named: bool = False) -> None:
    """With `strict`, exit STRICT_EXIT if a command or wait of `summaries` did not end well, saying how many, or
    `named` each (a cell's, whose lines say each robot's counts, not its commands)."""
    from ..twin.assembly.outcomes import STRICT_EXIT

    failures = [f"{label}: {f}" if label else f for label, summary in summaries.items()
                for f in summary.strict_failures()]
    if strict and failures:
        said = "; ".join(failures) if named else f"{len(failures)} command(s) or wait(s) did not end well"
        click.echo(f"--strict: {said}; exit status {STRICT_EXIT}", err=True)
        sys.exit(STRICT_EXIT)


def exchange_name(ctx, param, value: str | None) -> str | None:
    """An exchange name option, checked as the project's are (cotwin.twin.project.amqp_name_problem)."""
    from ..twin.project import amqp_name_problem

    problem = None if value is None else amqp_name_problem(value)
    if problem:
        raise click.BadParameter(problem)
    return value


def history_url(ctx, param, value: str | None) -> str | None:
    """A history store's URL option (--history, --db), checked as the project's [history] url is."""
    from ..twin.project import history_url_problem

    problem = None if value is None else history_url_problem(value)
    if problem:
        raise click.BadParameter(problem)
    return value


def check_timing(spec, step: float | None, end: float | None) -> None:
    """--step and --end checked with the project's other timing (cotwin.twin.project.timing_problems)."""
    from ..twin.project import cycle_period, run_timing_message, timing_problems

    if step is None and end is None:
        return
    for key, message in timing_problems(spec.step if step is None else step, spec.end if end is None else end,
                                        cycle_period(spec)):
        raise click.BadParameter(run_timing_message(spec, key, message),
                                 param_hint="--end" if key == "end" and end is not None else "--step")


def address(ctx, param, value: str | None) -> tuple[str, int] | None:
    """A --dashboard HOST:PORT option."""
    if value is None:
        return None
    from ..twin.services.dashboard.app import parse_address

    try:
        return parse_address(value)
    except ValueError as err:
        raise click.BadParameter(str(err)) from None


DASHBOARD_HELP = "serve the live dashboard at HOST:PORT (e.g. 127.0.0.1:8050) while the run lasts"


def serving_options(command):
    """The dashboard's --dashboard-access FILE, --tls-cert FILE and --tls-key FILE, handed to the command as
    `serving` (keyword arguments of Dashboard; docs/security.md)."""
    import functools

    @functools.wraps(command)
    def wrapper(*args, dashboard_access=None, tls_cert=None, tls_key=None, **kwargs):
        if (tls_cert is None) != (tls_key is None):
            raise click.UsageError("--tls-cert and --tls-key go together")
        return command(*args, serving={"access": dashboard_access,
                                       "tls": (tls_cert, tls_key) if tls_cert is not None else None}, **kwargs)

    for option in reversed((
            click.option("--dashboard-access", type=click.Path(), metavar="FILE",
                         help="who may use the dashboard (made with cotwin dashboard-access); needed to serve it "
                              "beyond loopback"),
            click.option("--tls-cert", type=click.Path(), metavar="FILE", help="serve the dashboard over TLS with "
                                                                                "this certificate (PEM)"),
            click.option("--tls-key", type=click.Path(), metavar="FILE", help="the certificate's private key (PEM)"))):
        wrapper = option(wrapper)
    return wrapper


def start_dashboard(system, address, mode: str, history_url: str | None, whatif_url: str | None = None,
                    serving: dict | None = None):
    """The started dashboard of a run (or None); says where it is."""
    if address is None:
        if serving and (serving["access"] or serving["tls"]):
            raise click.UsageError("--dashboard-access and --tls-cert go with --dashboard HOST:PORT")
        return None
    from ..twin.services.dashboard import Dashboard

    dash = Dashboard(system, *address, mode=mode, history_url=history_url, whatif_url=whatif_url,
                     **(serving or {})).start()
    click.echo(f"dashboard: {dash.url}{' (log in: access file ' + str(serving['access']) + ')' if serving and serving['access'] else ''}",
               err=True)
    return dash


def show_warnings(findings: Iterable[Finding]) -> int:
    """Print the warnings among `findings`; how many (a command's closing count says them: Tally.warn)."""
    shown = 0
    for f in findings:
        if f.severity is Severity.WARNING:
            click.echo(str(f), err=True)
            shown += 1
    return shown


def said_counts(errors: int, warnings: int) -> None:
    """A command's closing line: how many errors and warnings it had (0 and 0 said too: nothing went unsaid)."""
    click.echo(f"{errors} error(s), {warnings} warning(s)", err=True)


class Tally:
    """The errors and warnings a command shows the user, each counted as it is shown, for its closing line
    (said_counts): every warning said is in the count."""

    def __init__(self) -> None:
        self.errors = 0
        self.warnings = 0
        self.closed = False

    def warn(self, *groups: Iterable[Finding]) -> None:
        """Show the warnings among each group of findings, counted."""
        for findings in groups:
            self.warnings += show_warnings(findings)

    def finding(self, finding: Finding) -> None:
        """Show one finding, counted by its severity (a `warn` callback's: cotwin.twin.assembly.build.build)."""
        click.echo(str(finding), err=True)
        self.errors += finding.severity is Severity.ERROR
        self.warnings += finding.severity is Severity.WARNING

    def warning(self, message: str, prefix: str = "") -> None:
        """Show a warning that is no finding (a run's outcomes: no command completed...), `prefix` its side's."""
        click.echo(f"{prefix}warning: {message}", err=True)
        self.warnings += 1

    def error(self, message: str) -> None:
        """Show an error the command ends on without raising (a twin's failed history store), counted."""
        click.echo(f"error: {message}", err=True)
        self.errors += 1

    def close(self) -> None:
        """The closing line, said once."""
        if not self.closed:
            self.closed = True
            said_counts(self.errors, self.warnings)


_closing: Tally | None = None  # the Tally of the command running, closed by cotwin.cli.entry if it ends in an error


def closing_tally() -> Tally:
    """A Tally for the command now running that closes with its count however it ends: the command closes it
    when it ends well, cotwin.cli.entry (`close_failed`) after the error that ended it."""
    global _closing
    _closing = Tally()
    return _closing


def close_failed(findings: Iterable[Finding] = ()) -> None:
    """After the error that ended the command was shown (its `findings`, or a message): the command's closing
    count, if it keeps one (closing_tally), with the errors in it: each at a place of the inputs (a project's
    problems, counted as `report` counts them), else one however many lines said it (a failed run's cause and
    where its rows are); the warnings said with it counted too. Then no command is running."""
    global _closing
    tally, _closing = _closing, None
    if tally is None:
        return
    findings = list(findings)
    errors = [f for f in findings if f.severity is Severity.ERROR]
    tally.errors += max(1, sum(not f.location.path.startswith("<") for f in errors))
    tally.warnings += sum(f.severity is Severity.WARNING for f in findings)
    tally.close()


def no_command_running() -> None:
    """Forget the Tally of a command before (cotwin.cli.entry, run again in one process)."""
    global _closing
    _closing = None


def plan_warnings(system, end: float) -> list[Finding]:
    """What a run says of its plan before it starts (cotwin.twin.assembly.scenario): nothing planned, commands
    after `end`, commands out of order, rows of no event; a cell's robots' each said once."""
    from ..twin.assembly.scenario import after_end, no_event_rows, nothing_planned, plan_order

    twins = [r.system for r in system.robots] if system.spec.robots else [system]
    return [*nothing_planned(system.spec.plan, system.commands), *after_end(system.commands, end),
            *dict.fromkeys(f for t in twins for f in plan_order(t.commands, t.command_events)),
            *dict.fromkeys(f for t in twins for f in no_event_rows(t.commands, t.models.program))]


def check_step_count(step: float, span: float, hint: str | None, source: str) -> None:
    """A run the master can keep exactly (cosim's step_count), refused before any FMU is loaded, at the
    option that set it (`hint`) or else at the multimodel (`source`)."""
    from ..cosim.execution import step_count

    try:
        step_count(span, step)
    except CotwinError as err:
        message = err.findings[0].message
        if hint is None:
            raise CotwinError(f"{source}: {message}") from None
        raise click.BadParameter(message, param_hint=hint) from None


def check_finite(**options) -> None:
    import math

    for name, value in options.items():
        if value is not None and not math.isfinite(value):
            raise click.BadParameter(f"{value!r} is not a finite number", param_hint=f"--{name}")


def named_values(text: str, hint: str, given: str | None = None) -> tuple[str, list]:
    """NAME=LOW..HIGH (integers) or NAME=v1,v2,... (numbers) from an option; finite values only, at least
    one and at most MAX_VALUES of them. `given`: what the user wrote, where the option takes the values alone
    and the caller named them (a refusal quotes it, not a NAME= they never typed)."""
    quoted = (text if given is None else given)[:80]
    from ..config import is_number

    name, sep, values = text.partition("=")
    if not sep or not name or not values:
        raise click.BadParameter(f"'{quoted}': expected " + ("NAME=LOW..HIGH or NAME=v1,v2,..." if given is None
                                                             else "LOW..HIGH or v1,v2,..."), param_hint=hint)
    try:
        if ".." in values:
            low, high = (int(v) for v in values.split("..", 1))
            out = None
        else:
            out = [int(v) if v.strip().lstrip("-").isdigit() else float(v) for v in values.split(",")]
    except ValueError:
        if ".." in values:  # a bound such as 1e308 or 2.5 is a number, but no integer of a LOW..HIGH domain
            for bound in values.split("..", 1):
                try:
                    int(bound)
                    continue
                except ValueError:
                    pass
                try:
                    number = float(bound)
                except ValueError:
                    continue
                if math.isnan(number):
                    continue
                shown = bound.strip()[:40]
                if not math.isfinite(number) or abs(number) >= 2 ** 53:
                    raise click.BadParameter(f"'{quoted}': the range is too large: bound {shown} is beyond what an "
                                             f"integer domain LOW..HIGH can hold (at most {MAX_VALUES} values)",
                                             param_hint=hint) from None
                raise click.BadParameter(f"'{quoted}': bound {shown} is not written as an integer (LOW..HIGH "
                                         "takes integers; NAME=v1,v2,... takes other numbers)", param_hint=hint) from None
        raise click.BadParameter(f"'{quoted}': values must be numbers", param_hint=hint) from None
    count = high - low + 1 if out is None else len(out)
    if count < 1:
        raise click.BadParameter(f"'{quoted}': {name} takes no value (an empty range: LOW..HIGH needs LOW <= HIGH)",
                                 param_hint=hint)
    if count > MAX_VALUES:
        raise click.BadParameter(f"'{quoted}': {name} takes {count if count < 10 ** 12 else 'countless'} values, more than "
                                 f"{MAX_VALUES}",
                                 param_hint=hint)
    out = list(range(low, high + 1)) if out is None else out
    if not all(is_number(v) for v in out):  # also an integer too large for any float
        raise click.BadParameter(f"'{quoted}': values must be finite numbers", param_hint=hint)
    return name, out


def tool_point(text: str) -> tuple[float, float, float]:
    import math

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) and abs(v) <= 10.0 for v in values):
        raise click.BadParameter(f"{text[:80]!r}: flange, fingertips or three numbers X,Y,Z (m, within 10 m of the "
                                 "tool link)", param_hint="--tool")
    return values


def value_domains(program, domains: tuple[str, ...]) -> dict[str, list]:
    """--domain PORT=LOW..HIGH options of a d-model command, each naming a value port of an input event, or
    the event itself where it carries one value (closestDistance for its port closest_distance)."""
    parsed = dict(named_values(d, "--domain") for d in domains)
    ports = {port: port for ev in program.inputs for port, _ in ev.value_ports}
    ports.update({ev.name: ev.value_ports[0][0] for ev in program.inputs if len(ev.value_ports) == 1})
    unknown = [name for name in parsed if name not in ports]
    if unknown:
        known = [port for ev in program.inputs for port, _ in ev.value_ports]
        raise click.BadParameter(f"{', '.join(unknown)}: not a value port of an input event of module "
                                 f"{program.module.name} (ports: {', '.join(known) or 'none'})", param_hint="--domain")
    resolved = {ports[name]: values for name, values in parsed.items()}
    if len(resolved) < len(parsed):
        raise click.BadParameter("a port is given twice (by its name and by its event's)", param_hint="--domain")
    from ..dmodel.verify import port_domain

    scalars = {port: sc for ev in program.inputs for port, sc in ev.value_ports}
    try:  # values of the port's type only: a Boolean 2 or an int 0.5 would be explored as if a run could send it
        return {port: port_domain(port, scalars[port], values) for port, values in resolved.items()}
    except CotwinError as err:
        raise click.BadParameter(err.findings[0].message, param_hint="--domain") from None


@contextmanager
def interruptible(looping: Callable[[], bool], stopping: Callable[[], bool], stop: Callable[[], None]):
    """SIGINT and SIGTERM for a live twin's run: in its step loop (`looping`), the run ends after the step (`stop`;
    its results kept as a finished run's); before the loop (waiting for the broker, building) or at a second
    signal (`stopping`), at once (KeyboardInterrupt: the rows so far kept as partial results). The handlers
    that were there are put back after (a command run in-process leaves its host's as they were)."""
    def interrupt(*_) -> None:
        if not looping() or stopping():
            raise KeyboardInterrupt
        stop()
        click.echo("stopping after this step (interrupt again to stop at once)", err=True)

    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in before:
        signal.signal(sig, interrupt)
    try:
        yield
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
