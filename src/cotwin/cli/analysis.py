"""Commands that look ahead or fit: whatif, sweep, calibrate."""

from __future__ import annotations

import sys
from contextlib import contextmanager
from pathlib import Path

import click

from .. import safejson
from ..diagnostics import CotwinError, Interrupted, Location, placed
from ..plaindata import StateError
from ..files import CAPS, check_outputs, output, read_bytes, write_text
from .common import (MAX_HORIZON, MAX_REPORTED, STRICT_HELP, Tally, check_finite, main, named_values, output_file,
                     report, show_outcomes, show_warnings, strict_exit, tool_point)


def located(err: CotwinError, path: str | None) -> CotwinError:
    """`err` with each finding that names no place put at `path` (the plan or state file it is about)."""
    return err if path is None else placed(err, Location(str(path), 0, 0))


@contextmanager
def about(path: str | None, *kinds: type):
    """Errors of `kinds` (default CotwinError) raised in the block, located at `path` when they name no place."""
    try:
        yield
    except tuple(kinds or (CotwinError,)) as err:
        raise located(err, path) from None


def plan_file(path: str, program):
    """A what-if plan: a plan CSV, a TOML command list or a JSON list of {time, event, args}."""
    from ..twin.assembly.scenario import read_scenario
    from ..twin.services.whatif import plan_from_json

    if path.endswith(".json"):
        try:
            data = safejson.loads(read_bytes(path, "plan"), CAPS["plan"])
        except safejson.Refused as err:
            raise click.BadParameter(f"{path}: {err}", param_hint="--plan") from None
        with about(path):
            return plan_from_json(data, program)
    return read_scenario(path, program)


@main.command()
@click.argument("project", type=click.Path())
@click.option("--plan", "plan", required=True, help="the hypothetical plan (CSV, TOML or JSON; times relative to the fork)")
@click.option("--from", "state", type=click.Path(), help="a saved DT state to fork (DIR/state of a run or a live twin)")
@click.option("--horizon", type=click.FloatRange(min=0, min_open=True, max=MAX_HORIZON), default=60.0, show_default=True,
              help="simulate at most this long (s)")
@click.option("--physics-step", "physics_step", type=float, default=None,
              help="the fork's physics step in s (0.0001 to 0.01; default cotwin's 0.001; measure a coarser one "
                   "against your robot's log first: docs/benchmarks.md)")
@click.option("-o", "--output", "out", callback=output_file, help="write the prediction as JSON here")
@click.option("--strict", is_flag=True, help=STRICT_HELP)
def whatif(project: str, plan: str, state: str | None, horizon: float, physics_step: float | None, out: str | None,
           strict: bool) -> None:
    """Predict what a plan would do: fork the DT (at a saved state, under the algorithm it ran, or at the
    start) and run the plan ahead of real time; prints each command's outcome and the completion time."""
    import json

    from ..twin.assembly.run import load
    from ..twin.services.whatif import physics_timing, predict

    check_finite(horizon=horizon)
    system = load(project, reader="cotwin whatif")
    physics_timing(system.spec.step, physics_step, "--physics-step")
    show_warnings(system.spec.ignored_sections("cotwin whatif"))  # [convergence], [pt]...: a live twin's
    if out:
        check_outputs([out], [*system.spec.inputs, plan, state])
    commands = plan_file(plan, system.models.program)
    blob = read_bytes(state, "state") if state is not None else None  # capped: a state is a few MiB
    from ..twin.assembly.outcomes import EventRoles, Summary, answers_feasibility

    from ..twin.assembly.scenario import no_event_rows, nothing_planned

    show_warnings(nothing_planned(Path(plan), commands))
    show_warnings(no_event_rows(commands, system.models.program))
    with about(state, StateError):
        prediction = predict(system, commands, blob, horizon=horizon, physics_step=physics_step)
    unknown = "feasibility unknown, " if answers_feasibility(system.models.program, EventRoles.of(system.spec)) else ""
    for c in prediction.commands:
        args = ", ".join(f"{k}={v}" for k, v in c.args.items())
        verdict = {True: "feasible, ", False: "NOT feasible, ", None: unknown}[c.feasible]
        click.echo(f"t = {c.time:g} s {c.event}({args}): {verdict}{_taken(c)}, {_done(c)}")
    for c in prediction.collisions:
        click.echo(f"collision: {c}")
    click.echo(f"completion: {_completion(prediction)} "
               f"(forked at t = {prediction.start:g} s, predicted to t = {prediction.end:g} s, {prediction.native_steps} of "
               f"{round((prediction.end - prediction.start) / prediction.step)} steps in the native loop, in "
               f"{prediction.wall_seconds:.2f} s)")
    if out:
        write_text(out, json.dumps(prediction.as_dict(), indent=1) + "\n", [*system.spec.inputs, plan, state])
    summary = {"": Summary(prediction.commands, prediction.blocked, prediction.saturated)}
    show_outcomes(summary, Tally(), per_command=False)  # each command said above; a what-if closes with no count
    strict_exit(summary, strict)


NEVER_DONE = ("not taken", "infeasible", "stopped")  # verdicts no longer horizon would change


def _done(c) -> str:
    """When a predicted command was done; one not taken, infeasible or stopped is never done, whatever the horizon."""
    if c.verdict == "completed":
        return f"done at t = {c.done:g} s"
    return "never done" if c.verdict in NEVER_DONE else "not done within the horizon"


def _completion(prediction) -> str:
    """When the whole plan was done: never when a command of it will never be (not taken, infeasible, stopped)."""
    if prediction.completion_time is not None:
        return f"t = {prediction.completion_time:g} s"
    never = sum(c.verdict in NEVER_DONE for c in prediction.commands)
    return f"never ({never} command(s) not taken, infeasible or stopped)" if never else "not within the horizon"


def _taken(c) -> str:
    """Whether the d-model took a predicted command: a command never applied (due after the fork's end) was
    not offered to it, so it cannot have ignored it."""
    if c.delivered is None:
        return "never applied (due after the prediction ended)"
    if c.accepted:
        return "accepted"
    if c.replaced is not None:
        return f"replaced by the one applied at t = {c.replaced:g} s before the d-model's cycle read it"
    return "ignored by the d-model" + (f" (in {c.busy})" if c.busy else "")


@main.command()
@click.argument("project", type=click.Path())
@click.option("--event", required=True, help="the command to sweep, e.g. moveDiscreteCommand")
@click.option("--arg", "args", multiple=True, metavar="NAME=LOW..HIGH", help="an argument's values (repeatable)")
@click.option("--from", "state", type=click.Path(), help="a saved DT state to fork every what-if from")
@click.option("--horizon", type=click.FloatRange(min=0, min_open=True, max=MAX_HORIZON), default=30.0, show_default=True,
              help="simulate each what-if at most this long (s)")
@click.option("--physics-step", "physics_step", type=float, default=None,
              help="each what-if's physics step in s (0.0001 to 0.01; default cotwin's 0.001; measure a coarser one "
                   "against your robot's log first: docs/benchmarks.md)")
@click.option("--workers", type=click.IntRange(min=1, max=1024), help="local processes (default: one per CPU)")
@click.option("--threads", type=click.IntRange(min=1, max=1024), default=1, show_default=True,
              help="what-ifs at once in this process instead of a pool of processes: no start-up per process, the "
                   "physics of each runs outside Python's lock; a crash inside an FMU ends the whole sweep")
@click.option("--ray", "ray", help="run on Ray: 'auto' (the local cluster) or a cluster address")
@click.option("-o", "--output", "out", callback=output_file, required=True, help="the CSV of answers to write")
def sweep(project: str, event: str, args: tuple[str, ...], state: str | None, horizon: float,
          physics_step: float | None, workers: int | None, threads: int, ray: str | None, out: str) -> None:
    """Run one what-if per combination of argument values, in parallel (e.g. every hole of the plate:
    --event moveDiscreteCommand --arg target_X=0..15 --arg target_Y=0..23 --arg target_Z=0)."""
    import csv
    import os
    import time

    from ..twin.assembly.run import load
    from ..twin.analysis.sweep import ERROR, SweepInterrupted, failures, grid, run_sweep, sweep_shape, tally, unswept
    from ..twin.services.whatif import physics_timing
    from .progress import ProgressReport

    check_finite(horizon=horizon)
    if threads > 1 and (ray is not None or workers not in (None, 1)):
        raise click.UsageError("--threads runs the what-ifs in this process: not with --workers or --ray")
    if ray is not None and workers is not None:  # dropped without a word before
        raise click.UsageError("--workers sizes the local pool of processes: Ray places the what-ifs on its own workers")
    ranges: dict[str, list] = {}
    for name, values in (named_values(a, "--arg") for a in args):
        if name in ranges:
            raise click.BadParameter(f"argument {name!r} is given twice", param_hint="--arg")
        ranges[name] = values
    system = load(project, reader="cotwin sweep")
    physics_timing(system.spec.step, physics_step, "--physics-step")
    show_warnings(system.spec.ignored_sections("cotwin sweep"))  # [convergence], [pt]...: a live twin's
    inputs = [*system.spec.inputs, state]
    check_outputs([out], inputs)
    plans = grid(system.models.program, event, ranges)
    missing = unswept(system.models.program, event, ranges)
    if missing:  # sent as 0 in every what-if, a value no column shows
        click.echo(f"warning: --arg gives no values for {', '.join(missing)}: every what-if sends "
                   f"{'it' if len(missing) == 1 else 'them'} as 0 (the port's start value); to say so, "
                   f"--arg {missing[0]}=0", err=True)
    blob = read_bytes(state, "state") if state else None
    started = time.perf_counter()
    def write(path, rows: list[dict]) -> None:
        ordered = [r for r in rows if ERROR not in r] + [r for r in rows if ERROR in r]  # answers' columns first
        columns = list(dict.fromkeys(k for r in ordered for k in r))
        with output(path, inputs, text=True, newline="") as f:
            writer = csv.DictWriter(f, columns, lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows)

    try:
        with ProgressReport("sweeping", "what-ifs") as progress:
            with about(state, StateError):
                rows = run_sweep(system, plans, blob, horizon=horizon, workers=workers, ray=ray, progress=progress,
                                 physics_step=physics_step, threads=threads,
                                 warn=lambda message: click.echo(f"warning: --threads {threads}: {message}", err=True))
    except SweepInterrupted as err:  # the what-ifs answered are kept beside the output
        partial = Path(out).with_name(Path(out).stem + ".partial.csv")
        if err.rows:
            write(partial, err.rows)
        stopped = Interrupted(f"{err.findings[0].message}; " + (f"the {len(err.rows)} answered are in {partial}"
                                                                  if err.rows else "none was answered")
                              + f"; {err.total - len(err.rows)} not run")
        if err.running:  # threads left in their what-ifs: the interpreter's exit under them crashed (SIGSEGV)
            from ..twin.analysis.scratch import remove_left

            report(stopped.findings)
            sys.stdout.flush()
            sys.stderr.flush()
            remove_left()  # the scratch folder those threads hold, which no atexit hook removes after os._exit
            os._exit(130)
        raise stopped from None
    wall = time.perf_counter() - started
    write(out, rows)
    bad = failures(rows)
    for k, row in bad[:MAX_REPORTED]:
        where = ", ".join(f"{name}={value}" for name, value in row.items() if name != ERROR)
        click.echo(f"what-if {k + 1} of {len(rows)} ({where}) failed: {row[ERROR]}", err=True)
    if len(bad) > MAX_REPORTED:
        click.echo(f"... and {len(bad) - MAX_REPORTED} more failed what-if(s) (the {ERROR} column of {out})", err=True)
    used, processes = sweep_shape(threads, workers, len(plans))  # as run_sweep ran them (--threads 1024 on 4: 4)
    ran_on = ("Ray" if ray else f"this process, {used} threads" if used > 1 else "this process" if processes <= 1
              else f"local pool of {processes} processes")
    click.echo(f"{out}: {len(rows)} what-ifs in {wall:.1f} s ({ran_on}), {tally(rows)}"
               + (f", {len(bad)} FAILED" if bad else ""))
    if bad:
        sys.exit(1)


@main.command()
@click.argument("project", type=click.Path())
@click.option("--pt-log", type=click.Path(), help="the PT's recorded run of the project's plan (a UR RTDE log) to fit")
@click.option("-o", "--output", "out", callback=output_file, type=click.Path(), help="the calibration file to write (with --pt-log)")
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

    from ..mapping.profile import robot_convention
    from ..mapping.rtde import read_arm_log
    from ..pmodel.cell import CellGeometry
    from ..twin.assembly import calibration as cal
    from ..twin.project import load_project
    from ..twin.assembly.run import load
    from .progress import ProgressReport

    if pt_log is None and check_log is None:
        raise click.UsageError("give --pt-log LOG -o FILE to fit, or --calibration FILE --check LOG to check")
    if pt_log is not None and out is None:
        raise click.UsageError("--pt-log needs -o FILE: where to write the calibration")
    for option, path in (("--pt-log", pt_log), ("--check", check_log), ("--calibration", calibration)):
        if path is not None and not Path(path).is_file():
            said = (f"{path} is a folder, not a file" if Path(path).is_dir() else
                    f"{path} is not a regular file" if Path(path).exists() else f"no file {path}")
            raise click.BadParameter(said, param_hint=option)
    if not math.isfinite(log_start):
        raise click.BadParameter(f"{log_start!r} is not a finite number", param_hint="--log-start")
    point = tool if tool in ("flange", "fingertips") else tool_point(tool)
    system = load(load_project(project, pt_log))  # the log to fit replaces [pt] log
    if out is not None:  # the project's own calibration too: a fit never replaces what it started from
        check_outputs([out], [*system.spec.inputs, pt_log, check_log, calibration])
    twin, program, commands = cal.project_twin(system)
    arm = system.models.arm  # up to the cell geometry's [tool] link, as the mapping's IK counts the arm
    convention = robot_convention(system.spec.profile, len(arm), system.spec.location("robot", "profile"))
    fitted = None
    if pt_log is not None:
        with ProgressReport("calibrating", "stages") as progress:
            report = cal.calibrate(twin, program, commands, read_arm_log(pt_log, convention),
                                   CellGeometry(tool=point, tool_link=twin.geometry.tool_link if twin.geometry else ""),
                                   log_start, progress=progress)
        fitted = report.calibration
        late = [x for x in fitted.timing.latencies if not -cal.SECONDS <= x <= cal.SECONDS]
        if late:  # what Calibration.read refuses is not written (a file no project or --check could use)
            raise click.BadParameter(
                f"{log_start:g} s puts the log's moves {late[0]:g} s after the plan's commands (latencies must be "
                f"within [{-cal.SECONDS:g}, {cal.SECONDS:g}] s): give the co-simulation time of the log's first row",
                param_hint="--log-start")
        early = [x for x in fitted.timing.latencies if x < 0]
        if early:
            click.echo(f"warning: with --log-start {log_start:g} s, {len(early)} move(s) start before the plan "
                       f"commands them (latency {min(early):.3f} s): is --log-start the co-simulation time of the "
                       "log's first row?", err=True)
        fitted.write(out, f"cotwin calibration of {Path(project).name}, fitted on {Path(pt_log).name} "
                          "(cotwin calibrate)")
        click.echo("\n".join(report.lines()))
        click.echo(f"wrote {out}")
    if check_log is not None:
        chosen = cal.Calibration.read(calibration) if calibration is not None else fitted or system.models.calibration
        if chosen is None:
            raise click.UsageError("--check needs a calibration: --calibration FILE, --pt-log to fit one, or a "
                                   "project with [platform] calibration")
        click.echo("\n".join(cal.check(twin, program, commands, read_arm_log(check_log, convention), chosen).lines()))
