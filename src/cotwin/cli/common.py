"""What the `cotwin` commands share: the command group, option checks and how findings are printed."""

from __future__ import annotations

import sys

import click

from ..diagnostics import CotwinError, Severity

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


def output_path(ctx, param, value: str | None) -> str | None:
    """An -o option: a path, never the empty string (which would write into the current folder)."""
    if value is not None and not value.strip():
        raise click.BadParameter("an empty path: name the file or folder to write", param_hint="-o/--output")
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cotwin")
def main() -> None:
    """cotwin: RoboSim models to FMI-based digital twins."""


def exchange_name(ctx, param, value: str | None) -> str | None:
    """An exchange name option, checked as the project's are (cotwin.twin.project.amqp_name_problem)."""
    from ..twin.project import amqp_name_problem

    problem = None if value is None else amqp_name_problem(value)
    if problem:
        raise click.BadParameter(problem)
    return value


def check_timing(spec, step: float | None, end: float | None) -> None:
    """--step and --end checked with the project's other timing (cotwin.twin.project.timing_problems)."""
    from ..twin.project import CYCLE_PERIOD, cycle_period, timing_problems

    if step is None and end is None:
        return
    for key, message in timing_problems(spec.step if step is None else step, spec.end if end is None else end,
                                        cycle_period(spec)):
        if key == CYCLE_PERIOD:
            message += " ([cosim] parameters cycle_period)"
        raise click.BadParameter(message, param_hint="--end" if key == "end" and end is not None else "--step")


def address(ctx, param, value: str | None) -> tuple[str, int] | None:
    """A --dashboard HOST:PORT option."""
    if value is None:
        return None
    from ..twin.dashboard.app import parse_address

    try:
        return parse_address(value)
    except ValueError as err:
        raise click.BadParameter(str(err)) from None


DASHBOARD_HELP = "serve the live dashboard at HOST:PORT (e.g. 127.0.0.1:8050) while the run lasts"


def start_dashboard(system, address, mode: str, history_url: str | None, whatif_url: str | None = None):
    """The started dashboard of a run (or None); says where it is."""
    if address is None:
        return None
    from ..twin.dashboard import Dashboard

    dash = Dashboard(system, *address, mode=mode, history_url=history_url, whatif_url=whatif_url).start()
    click.echo(f"dashboard: {dash.url}", err=True)
    return dash


def show_warnings(findings) -> None:
    for f in findings:
        if f.severity is Severity.WARNING:
            click.echo(str(f), err=True)


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


def named_values(text: str, hint: str) -> tuple[str, list]:
    """NAME=LOW..HIGH (integers) or NAME=v1,v2,... (numbers) from an option; finite values only, at least
    one and at most MAX_VALUES of them."""
    from ..config import is_number

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
    """--domain PORT=LOW..HIGH options of a d-model command, each naming a value port of an input event."""
    parsed = dict(named_values(d, "--domain") for d in domains)
    known = [port for ev in program.inputs for port, _ in ev.value_ports]
    unknown = [name for name in parsed if name not in known]
    if unknown:
        raise click.BadParameter(f"{', '.join(unknown)}: not a value port of an input event of module "
                                 f"{program.module.name} (ports: {', '.join(known) or 'none'})", param_hint="--domain")
    return parsed
