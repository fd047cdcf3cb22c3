"""Commands on models: check, build-dmodel, export-pmodel, verify."""

from __future__ import annotations

import sys
import time
from collections import Counter
from pathlib import Path

import click

from ..diagnostics import CotwinError, Severity
from ..files import check_outputs, write_text
from .common import check_finite, main, named_values, output_file, report, value_domains


@main.command()
@click.argument("paths", nargs=-1, required=True)
def check(paths: tuple[str, ...]) -> None:
    """Parse, resolve and type-check RoboSim models (files or folders of .rst and .pm, or a project file
    .toml: its models, each robot's own set for a cell of several robots)."""
    from ..robosim.check import CheckResult, check_paths
    from ..robosim.summary import summarise

    paths = tuple(cell_project(p) or p for p in paths)
    projects = [p for p in paths if p.endswith(".toml")]
    sets = [tuple(p for p in paths if not p.endswith(".toml"))] if len(projects) < len(paths) else []
    problems: list = []
    for project in projects:
        try:
            sets += model_sets(project)
        except CotwinError as err:
            problems += err.findings
    results = [check_paths(files) for files in sets]
    result = CheckResult([p for r in results for p in r.projects], problems + [f for r in results for f in r.findings])
    findings = list(dict.fromkeys(result.findings))  # a d-model shared by a cell's robots says its problems once
    ok = result.ok
    if ok:
        findings += [f for project in result.projects for f in tree_findings(project)]
        twins = [twin_problems(project) for project in projects]  # the project against its models: its plan, ...
        findings += [f for found in twins for f in found]
        ok = not any(f.severity is Severity.ERROR for found in twins for f in found)
    findings = list(dict.fromkeys(findings))  # the models' warnings again from the project's twin: once
    report(findings)
    if not ok:
        errors = sum(f.severity is Severity.ERROR for f in findings)
        click.echo(f"{errors} error(s)", file=sys.stderr)
        hint = [p for p in paths if not p.endswith(".toml") and Path(p).is_dir() and any(Path(p).glob("*.toml"))]
        if hint:
            click.echo(f"note: {', '.join(hint)} holds project files whose models may lie elsewhere: check a project "
                       f"with `cotwin check {Path(hint[0]) / 'cotwin.toml'}` (each robot's models of a cell apart)",
                       file=sys.stderr)
        sys.exit(1)
    warnings = Counter(f.location.path for f in findings if f.severity is Severity.WARNING)
    shown = set()
    for source in (f for project in result.projects for f in project.files):
        if source.path in shown:  # a d-model shared by a cell's robots
            continue
        shown.add(source.path)
        extra = f", {warnings[source.path]} warning(s)" if warnings[source.path] else ""
        click.echo(f"{source.path}: ok ({summarise(source)}{extra})")


def twin_problems(project: str) -> list:
    """What a project says against its models once they check (its plan's columns and rows, its tables'
    names of joints and variables, a cell's robots...): the checks `cotwin run` makes before it runs, and the
    warnings it and `cotwin twin` show (what the PT's endpoint cannot carry, EndpointKind.advice)."""
    from ..twin.assembly.endpoints import endpoint_advice
    from ..twin.assembly.run import load
    from ..twin.assembly.system import TwinSystem

    import os
    from dataclasses import replace

    try:  # the models' warnings at their paths as check names them (normalised), so that each is said once
        system = load(project, cells=True)
        found = list(system.warnings)
        if type(system) is TwinSystem and system.spec.pt is not None:
            found += endpoint_advice(system, "pt")
        return [replace(f, location=replace(f.location, path=os.path.normpath(f.location.path))) for f in found]
    except CotwinError as err:
        return list(err.findings)


def cell_project(path: str) -> str | None:
    """A folder's cotwin.toml when it is a cell of several robots (its folder holds one mapping and one p-model
    per robot, which checked as one set name each other's robot unknown), else None: the folder checks as one set."""
    from ..twin.project import load_project

    project = Path(path) / "cotwin.toml"
    if not Path(path).is_dir() or not project.is_file():
        return None
    try:
        return str(project) if load_project(str(project)).robots else None
    except CotwinError:
        return None  # not a readable project: the folder checks as one set, as before


def model_sets(project: str) -> list[tuple[str, ...]]:
    """The model files a project's twin is made of, one set per robot (a cell's robots share the d-model)."""
    from ..twin.project import load_project

    import os

    spec = load_project(project)
    files = [(spec.dmodel, r.pmodel, r.mapping) for r in spec.robots] if spec.robots else [tuple(spec.model_files)]
    return [tuple(os.path.normpath(f) for f in group) for group in files]


def tree_findings(project) -> list:
    """The readings a simulator takes of a project's p-models (cotwin.pmodel.tree_build's warnings: a wheel
    axis moved, an impossible inertia replaced...), for those that build."""
    from ..pmodel.tree import build_tree
    from ..robosim.pmodel_elements import PModel
    from ..twin.assembly.system import tree_warnings

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
        out.extend(tree_warnings(tree))
    return out


def models_read(paths: tuple[str, ...]) -> list[str | Path]:
    """The paths given and the model files in the folders among them: an output named like one of those
    (`-o models/arm.pm` with `models` given) would replace a model the command reads."""
    from ..robosim.project import model_files

    return [*paths, *model_files(paths)[0]]


@main.command("build-dmodel")
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module to build (default: the only one)")
@click.option("-o", "--output", callback=output_file, required=True, help="the FMU file to write")
@click.option("--cc", default="cc", show_default=True, help="C compiler")
@click.option("--fmi", "version", type=click.Choice(["2", "3"]), default="2", show_default=True,
              help="FMI version: 3 makes the d-model's cycle a clock (Co-Simulation with Event Mode)")
@click.option("--cycle-period", type=click.FloatRange(min=1e-6, max=86_400),
              help="FMI 3.0: the clock's default interval in seconds (the parameter cycle_period) [default: 0.1]")
def build_dmodel(model: tuple[str, ...], module_name: str | None, output: str, cc: str, version: str,
                 cycle_period: float | None) -> None:
    """Generate C from a d-model module and package it as an FMI 2.0 (default) or 3.0 co-simulation FMU."""
    from ..dmodel.fmu import build_fmu
    from ..dmodel.program import build_program
    from ..robosim.check import load_checked

    check_finite(**{"cycle-period": cycle_period})
    check_outputs([output], models_read(model))
    if cycle_period is not None and version != "3":
        raise click.BadParameter("the FMI 2.0 FMU takes cycle_period as a parameter when run (0: one cycle per "
                                 "step); --cycle-period sets the FMI 3.0 clock's default", param_hint="--cycle-period")
    program = build_program(load_checked(model), module_name)
    if version == "3":
        from ..dmodel.fmi3 import DEFAULT_PERIOD, build_fmu3

        path = build_fmu3(program, output, cc=cc, period=cycle_period or DEFAULT_PERIOD)
    else:
        path = build_fmu(program, output, cc=cc)
    click.echo(f"{path}: FMI {version}.0, module {program.module.name}, {len(program.machines)} state machine(s), "
               f"{len(program.inputs)} input event(s), {len(program.operations)} operation(s)"
               + (f", clock cycle every {cycle_period or DEFAULT_PERIOD:g} s" if version == "3" else ""))


@main.command("export-pmodel")
@click.argument("model", nargs=-1, required=True)
@click.option("--pmodel", "pmodel_name", help="the p-model to export (default: the one not used as a part)")
@click.option("--format", "fmt", type=click.Choice(["sdf", "urdf", "mjcf"]), required=True)
@click.option("-o", "--output", callback=output_file, required=True, help="the file to write")
def export_pmodel(model: tuple[str, ...], pmodel_name: str | None, fmt: str, output: str) -> None:
    """Write a p-model as SDF 1.6, URDF or MJCF (all three from one kinematic tree)."""

    from ..pmodel.mjcf import to_mjcf
    from ..pmodel.sdf import to_sdf
    from ..pmodel.tree import build_tree
    from ..pmodel.urdf import to_urdf
    from ..robosim.check import load_checked

    inputs = models_read(model)
    check_outputs([output], inputs)
    tree = build_tree(load_checked(model), pmodel_name)
    text = {"sdf": to_sdf, "urdf": to_urdf, "mjcf": to_mjcf}[fmt](tree)
    path = write_text(output, text, inputs)
    kinds = {k: sum(j.kind == k for j in tree.joints) for k in ("revolute", "prismatic", "fixed")}
    click.echo(f"{path}: {fmt} of p-model {tree.name}: {len(tree.links)} links, {kinds['revolute']} revolute, "
               f"{kinds['prismatic']} prismatic and {kinds['fixed']} fixed joints, {len(tree.sensors)} sensor ports")


@main.command()
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module to verify (default: the only one)")
@click.option("--domain", "domains", multiple=True, metavar="PORT=LOW..HIGH",
              help="values of an event's value port, e.g. MovementArgs_target_X=0..15 (repeatable)")
@click.option("--max-states", default=100_000, show_default=True, type=click.IntRange(min=1, max=10 ** 8),
              help="stop exploring after this many states")
@click.option("--random", "random_values", metavar="V1,V2,...", help="the values Mathematics::random() takes in "
              "the search, each draw a choice, each in [0, 1) (default: 0,0.5)")
def verify(model: tuple[str, ...], module_name: str | None, domains: tuple[str, ...], max_states: int,
           random_values: str | None) -> None:
    """Explore every state of a d-model module under every input combination; check the core
    properties (timelock, determinism, divergence, repeated outputs) and reachability. Exit 0: all
    hold; 1: a violation (or, in a complete search, something unreachable); 3: the search stopped at
    --max-states, or at a counter that grows without bound, or tried only sample values (0 and 1) of an input a
    condition reads (give them with --domain), without finding a violation (not verified); 130: interrupted
    (Ctrl-C) without a violation found so far (what it found is reported all the same)."""
    from ..dmodel.program import build_program
    from ..dmodel.verify import RANDOM_VALUES, format_report, verify as explore
    from ..robosim.check import load_checked
    from .progress import ProgressReport

    program = build_program(load_checked(model), module_name)
    resolved = value_domains(program, domains)
    draws = RANDOM_VALUES if random_values is None else tuple(named_values(f"random={random_values}", "--random", random_values)[1])
    impossible = [v for v in draws if not 0 <= v < 1]  # explored, they found what no run of the model can do
    if impossible:
        raise click.BadParameter(f"{impossible[0]:g}: random() draws from [0, 1) (as the FMU does): give values in it",
                                 param_hint="--random")
    with ProgressReport("verifying", "states") as progress:
        started = time.monotonic()

        def report_progress(states: int, cycles: int, frontier: int) -> None:
            rate = cycles / max(time.monotonic() - started, 1e-9)
            progress(states, None, f"limit {max_states}, {cycles} cycles ({rate:,.0f} cycles/s), "
                                   f"{frontier} states to expand")

        report = explore(program, resolved, max_states=max_states, random_values=draws, progress=report_progress)
    click.echo(format_report(program, report))
    if report.violations or (report.complete and not report.ok):
        sys.exit(1)
    if report.interrupted:  # nothing wrong found before the interrupt, which verifies nothing
        click.echo("interrupted: the search did not end, nothing is verified", err=True)
        sys.exit(130)
    # a complete search of sampled values found nothing wrong for them, which verifies nothing beyond them
    sys.exit(0 if report.ok and not report.sampled else 3)
