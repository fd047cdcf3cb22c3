"""Commands on generated tests: testgen (a suite from a d-model), test (run it), mutants (its worth)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..files import check_outputs, write_text
from .common import check_finite, main, output_file, output_folder, show_warnings, value_domains

MIN_PERIOD = 1e-6  # s: a plan's times are in ms to 6 decimals, so a shorter cycle put every row at time 0


def command_events(project, program, named: tuple[str, ...]) -> tuple[list[str], str]:
    """The input events that are commands, and how that was decided: named by --command, else those the
    project's mapping does not produce (as a twin takes them from its source), else all of them."""
    from ..robosim.pmodel_elements import Mapping

    events = [ev.name for ev in program.inputs]
    if named:
        unknown = [n for n in named if n not in events]
        if unknown:
            raise click.BadParameter(f"{', '.join(unknown)}: not an input event of module {program.module.name} "
                                     f"(events: {', '.join(events)})", param_hint="--command")
        return [e for e in events if e in named], "named by --command"
    mappings = [m for m in project.elements(Mapping)]
    if len(mappings) == 1:
        from ..twin.assembly.system import external_events

        return external_events(program, mappings[0]), f"those mapping {mappings[0].name} does not produce"
    return events, "all input events (no mapping given: name commands with --command to stub the platform's answers)"


@main.command()
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module (default: the only one)")
@click.option("--coverage", "criterion", type=click.Choice(["states", "transitions", "transition-pairs"]),
              default="transitions", show_default=True, help="what the suite covers")
@click.option("--domain", "domains", multiple=True, metavar="PORT=LOW..HIGH",
              help="values of an event's value port, e.g. MovementArgs_target_X=0..15 (repeatable)")
@click.option("--command", "commands", multiple=True, metavar="EVENT",
              help="an input event that is a command (repeatable; default: those the mapping among MODEL does "
                   "not produce, else every input event); the others are the platform's answers")
@click.option("--answers", type=click.Choice(["stub", "platform", "auto"]), default="stub", show_default=True,
              help="stub: each case carries the platform's answers; platform: each case leaves them to the platform; "
                   "auto (with --project): left to the platform where its simulated platform follows the case, "
                   "else stubbed")
@click.option("--project", type=click.Path(), help="a twin project (cotwin.toml) to try the cases on (--answers auto)")
@click.option("--split", type=click.Choice(["rest", "length"]), default="rest", show_default=True,
              help="rest: a case ends back at rest having covered something; length: only at --max-cycles")
@click.option("--max-cycles", default=30, show_default=True, type=click.IntRange(min=1, max=10 ** 6),
              help="cycles of one case (a case's first item may lie further)")
@click.option("--max-states", default=100_000, show_default=True, type=click.IntRange(min=1, max=10 ** 8),
              help="stop exploring after this many states (states and transitions: also once every transition "
                   "was taken)")
@click.option("--period", default=0.1, show_default=True, type=click.FloatRange(min=MIN_PERIOD, max=3600),
              help="seconds per d-model cycle in the plans")
@click.option("--settle", default=10.0, show_default=True, type=click.FloatRange(min=0, max=86_400),
              help="seconds a plan leaves the platform to answer (cases with --answers platform)")
@click.option("--drivers/--no-drivers", default=True, show_default=True,
              help="build each stub case as a test driver FMU (case_NN.fmu) reporting a verdict")
@click.option("--cc", default="cc", show_default=True, help="C compiler for the driver FMUs")
@click.option("-o", "--output", "out", callback=output_folder, required=True, help="the folder for the suite")
def testgen(model: tuple[str, ...], module_name: str | None, criterion: str, domains: tuple[str, ...],
            commands: tuple[str, ...], answers: str, project: str | None, split: str, max_cycles: int, max_states: int,
            period: float, settle: float, drivers: bool, cc: str, out: str) -> None:
    """Generate a test suite covering every reachable state, transition or pair of a d-model module."""
    from ..dmodel.program import build_program
    from ..dmodel.testgen import generate
    from ..dmodel.testgen_files import write_suite
    from ..dmodel.testgen_graph import explore
    from ..robosim.check import load_checked

    check_finite(period=period, settle=settle)  # nan passes click's range checks
    if (answers == "auto") != (project is not None):
        raise click.BadParameter("--answers auto tries the cases on a project's simulated platform: give both",
                                 param_hint="--answers" if project is None else "--project")
    models = load_checked(model)
    program = build_program(models, module_name)
    parsed = value_domains(program, domains)
    chosen, why = command_events(models, program, commands)
    system = None
    if answers == "auto":  # a project that cannot be loaded is refused before anything is written
        from ..twin.assembly.run import load

        system = load(project, reader="cotwin testgen")
    import os
    import tempfile

    from ..diagnostics import Interrupted
    from ..interrupts import signals_held
    from ..twin.assembly.build import folder_lock
    from .progress import ProgressReport

    earlier = os.path.isfile(os.path.join(out, "suite.json"))
    made = not os.path.lexists(out)  # a folder this testgen makes is removed again if it writes no suite there
    placed = False
    try:
        try:
            # one testgen (or run) in the folder at a time: two at once each said its suite was written, one was not
            with folder_lock(Path(out)):
                with ProgressReport("exploring the d-model's states", "states") as progress:
                    graph = explore(program, parsed, max_states=max_states,
                                    until_all_taken=criterion != "transition-pairs",
                                    progress=lambda done, found: progress(found, max_states, f"{done} expanded"))
                suite = generate(graph, criterion, max_cycles, chosen, "platform" if answers == "auto" else answers, split)
                # The suite is made in a folder of its own inside `out` and only then moved over the suite there, its
                # driver FMUs with it: a run that fails (a project the cases cannot run on, a C compiler that fails) or
                # is interrupted leaves the earlier suite (its driver FMUs too) as it was, never a suite without its
                # drivers or beside the earlier suite's.
                with tempfile.TemporaryDirectory(prefix=".cotwin-testgen-", dir=out) as stage:
                    write_suite(suite, stage, period, settle)
                    if answers == "auto":
                        try_on_platform(suite, system, stage, period, settle)
                    built = []
                    if drivers:
                        from ..dmodel.testgen_driver import build_driver
                        from ..dmodel.testgen_files import oracle

                        for case in suite.cases:
                            if case.answers == "stub":
                                built.append(build_driver(program, case.name, oracle(case)["cycles"],
                                                          Path(stage) / f"{case.name}.fmu", cc))
                    with signals_held():  # an interrupt meanwhile comes once the suite is in place, said below
                        write_suite(suite, out, period, settle, drivers=drivers, fmus=built)
                        placed = True
        finally:
            if made and not placed:
                _unmake(Path(out))
    except KeyboardInterrupt:
        raise Interrupted(f"{out}: interrupted after the suite was written (it is whole there)" if placed else
                          f"{out}: interrupted before the suite was written: none of it is there"
                          + ("; the earlier suite there is as it was" if earlier else "")) from None
    click.echo(format_suite(suite, period, why, out, drivers))
    if not suite.cases:
        click.echo("no case: nothing is reachable to cover", err=True)
        sys.exit(1)


def _unmake(folder: Path) -> None:
    """Remove the folder a testgen made and wrote no suite into (its lock the only file left); kept if anything else
    is there."""
    try:
        (folder / ".cotwin.lock").unlink(missing_ok=True)
        folder.rmdir()
    except OSError:
        pass


def try_on_platform(suite, system, out: str, period: float, settle: float) -> dict[str, str]:
    """--answers auto: every case (written with its answers left to the platform) run on the project's
    simulated platform; those it does not follow are rewritten with their answers stubbed. Returns
    {case: why it was stubbed}."""
    import tempfile

    from ..dmodel.testgen_files import read_suite, write_suite
    from ..twin.analysis.testing import run_suite

    with tempfile.TemporaryDirectory(prefix="cotwin-testgen-") as tmp:
        result = run_suite(system, read_suite(out), tmp)
    stubbed = {}
    for case, ran in zip(suite.cases, result.cases):
        if ran.passed:
            case.note = "left to the platform: the project's simulated platform follows it"
        else:
            case.answers = "stub"
            case.note = stubbed[case.name] = f"stubbed: on the project's simulated platform, {ran.divergence}"
    write_suite(suite, out, period, settle)
    return stubbed


def format_suite(suite, period: float, why: str, out: str, drivers: bool = False) -> str:
    from ..dmodel.verify import growth_hint

    graph = suite.graph
    reached, covered = len(suite.reached), len(suite.covered)
    lines = [f"module {suite.program.module.name}: {len(graph.snapshots)} states, {graph.edges} distinct cycles explored "
             f"in {graph.seconds:.2f} s" + ("" if graph.complete else " (INCOMPLETE: a counter grows without bound)"
                                            if graph.unbounded else
                                            f" (INCOMPLETE: the state limit was reached{growth_hint(suite.program, graph.snapshots)})")
             + (f" (stopped: {graph.stopped})" if graph.stopped else "")]
    lines += [f"  note: {n}" for n in graph.value_notes]
    lines.append(f"  commands: {', '.join(suite.commands) or 'none'} ({why}); platform answers: "
                 f"{', '.join(ev.name for ev in suite.program.inputs if ev.name not in suite.commands) or 'none'}")
    share = 100.0 * covered / reached if reached else 100.0
    lines.append(f"{suite.criterion}: {covered} of {reached} reachable covered ({share:.0f}%), {len(suite.total)} in the model")
    lines.append(f"  {len(suite.cases)} case(s), {suite.cycles} cycles, {suite.cycles * period:g} s of simulated time at "
                 f"{period:g} s per cycle; greedy minimisation kept {len(suite.cases)} of {suite.walks} walk(s)")
    for case in suite.cases:
        lines.append(f"  {case.name}: {case.cycles} cycles, answers {case.answers}, {len(case.covers)} item(s) first covered"
                     + (f"; {case.note}" if case.note else ""))
    label = "unreachable" if graph.complete else "not reached"
    for item, why_not in suite.unreachable:
        lines.append(f"  {label}: {item}: {why_not}")
    for item, why_not in suite.uncovered:
        lines.append(f"  uncovered: {item}: {why_not}")
    drivers = sum(1 for c in suite.cases if c.answers == "stub") if drivers else 0
    lines.append(f"written to {out}/ (suite.json, per case a plan .csv and an .oracle.json"
                 + (f", test driver FMUs of the {drivers} stub case(s), reporting `verdict`" if drivers else "") + ")")
    return "\n".join(lines)


__all__ = ["testgen"]


def pt_option(ctx, param, value: str | None) -> str | None:
    """--pt: the project's [pt] ("project"), or an OPC UA URL for it."""
    if value is None or value == "project":
        return value
    if not value.startswith("opc.tcp://"):
        raise click.BadParameter(f"{value!r}: give an OPC UA URL (opc.tcp://HOST:PORT), or --pt alone for the "
                                 "project's [pt]")
    return value


@main.command("test")
@click.argument("project", type=click.Path())
@click.argument("tests", type=click.Path())
@click.option("--pt", "pt", is_flag=False, flag_value="project", default=None, callback=pt_option, metavar="[URL]",
              help="run against the PT through the twin (hardware in the loop): the project's [pt], or the OPC UA "
                   "plant at URL")
@click.option("--junit", callback=output_file, help="write the results as JUnit XML")
@click.option("--algorithm", type=click.Choice(["jacobi", "gauss-seidel"]), help="(default: the project's)")
@click.option("--fmi", "version", type=click.Choice(["2", "3"]), default="2", show_default=True,
              help="the d-model FMU's FMI version (3: its cycle a clock)")
@click.option("--case", "cases", multiple=True, metavar="NAME", help="run only this case (repeatable)")
@click.option("-o", "--output", "out", callback=output_folder, default=None,
              help="folder for the built FMU (default: a temporary one)")
@click.option("--cc", default="cc", show_default=True, help="C compiler for the d-model FMU")
def test_command(project: str, tests: str, pt: str | None, junit: str | None, algorithm: str | None, version: str,
                 cases: tuple[str, ...], out: str | None, cc: str) -> None:
    """Run a generated suite on a twin project's co-simulation (or its PT) and judge each case by its oracle."""
    import tempfile

    from ..dmodel.testgen_files import read_suite
    from ..twin.assembly.run import load
    from ..twin.analysis.testing import format_result, junit_xml, run_suite

    reader = "cotwin test --pt project" if pt == "project" else "cotwin test"
    system = load(project, reader=reader)
    show_warnings(system.spec.ignored_sections(reader))
    suite = read_suite(tests)
    if junit:
        check_outputs([junit], [*system.spec.inputs, *suite_inputs(suite)], "--junit")
    endpoint, target = None, "the co-simulation (the project's simulated platform)"
    if pt is not None:
        endpoint, target = _pt_endpoint(system, pt)

    def progress(k, n, result):
        click.echo(f"  [{k}/{n}] {result.name}: {'pass' if result.passed else 'FAIL'}", err=True)

    with tempfile.TemporaryDirectory(prefix="cotwin-test-") as tmp:
        result = run_suite(system, suite, out or tmp, endpoint, target, algorithm, int(version), cc,
                           list(cases) or None, progress)
    if junit:
        write_text(junit, junit_xml(result))
    click.echo(format_result(result))
    if junit:
        click.echo(f"JUnit XML: {junit}")
    if not result.cases:
        click.echo("no case ran", err=True)
        sys.exit(1)
    sys.exit(0 if result.passed else 1)


def suite_inputs(suite) -> list[Path]:
    """The files of a suite that `cotwin test` and `cotwin mutants` read (an output must not replace them)."""
    return [suite.folder / "suite.json", *(p for c in suite.cases
                                           for p in (c.plan, suite.folder / f"{c.name}.oracle.json"))]


def _pt_endpoint(system, pt: str):
    """A function making the PT's endpoint for each case, and how to name it."""
    if pt == "project":
        from ..twin.live.runtime import pt_endpoint

        spec = system.spec.pt
        if spec is None:
            raise click.BadParameter(f"{system.spec.path} has no [pt] table: name the plant's URL (--pt opc.tcp://...)",
                                     param_hint="--pt")
        return (lambda: pt_endpoint(system)), f"the PT ({spec.endpoint}{' at ' + spec.url if spec.url else ''})"
    from ..mapping.opcua import OPCUAEndpoint

    return (lambda: OPCUAEndpoint(system.models.tree, pt)), f"the PT (OPC UA plant at {pt})"


@main.command()
@click.argument("tests", type=click.Path())
@click.argument("model", nargs=-1, required=True)
@click.option("--module", "module_name", help="the module (default: the only one)")
@click.option("--fmu", "through_fmu", is_flag=True, help="run each mutant's cases through its FMU (built with --cc)")
@click.option("--cc", default="cc", show_default=True, help="C compiler (with --fmu)")
@click.option("--min-kill", type=click.FloatRange(0, 100), metavar="PERCENT",
              help="exit 1 when fewer of the non-equivalent mutants are killed")
@click.option("-o", "--output", "out", callback=output_file, default=None, help="write the outcomes as JSON")
def mutants(tests: str, model: tuple[str, ...], module_name: str | None, through_fmu: bool, cc: str,
            min_kill: float | None, out: str | None) -> None:
    """Mutate a d-model automatically and run a generated suite on every mutant: the kill rate, and why each
    survivor survived (equivalent, or told apart by an input sequence the suite lacks)."""
    import json

    from ..dmodel.program import build_program
    from ..dmodel.testgen import model_digest
    from ..dmodel.testgen_files import read_suite
    from ..cosim.driver import FMUDriver
    from ..dmodel.testgen_mutants import analyse, format_report, make_mutants
    from ..robosim.check import load_checked

    check_finite(**{"min-kill": min_kill})  # nan passed click's range and made the gate never fail
    files = [Path(m) for m in model]
    folders = [f for f in files if f.is_dir()]
    if folders:
        raise click.BadParameter(f"{folders[0]}: name the model files (the .rst files are mutated)", param_hint="MODEL")
    program = build_program(load_checked(files), module_name)
    suite = read_suite(tests)
    if not suite.cases:  # every mutant would survive it: a kill rate of 0% and exit 0 said nothing was run
        raise click.BadParameter(f"{tests}/suite.json holds no case: nothing to run on the mutants", param_hint="TESTS")
    if out:
        check_outputs([out], [*files, *suite_inputs(suite)])
    if suite.data.get("model_digest") != model_digest(program):
        raise click.BadParameter(f"{tests}/suite.json was generated from another d-model (module "
                                 f"{suite.data.get('module')}): mutate the model the suite was made from",
                                 param_hint="MODEL")
    events = [ev.name for ev in program.inputs]
    made = [m for f in files if f.suffix == ".rst" for m in make_mutants(f, events)]
    builder = None
    if through_fmu:
        from ..dmodel.fmu import build_fmu

        builder = (lambda prog, path: build_fmu(prog, path, cc=cc))
    domains = suite.data.get("exploration", {}).get("domains") or {}
    report = analyse(program, suite, made, files, module_name, domains, builder, FMUDriver)
    click.echo(format_report(report, suite.criterion))
    if out:
        rows = [{"mutant": o.mutant.name, "operator": o.mutant.operator, "where": o.mutant.where,
                 "change": o.mutant.change, "status": o.status, "by": o.by, "equivalent": o.equivalent,
                 "explanation": o.explanation} for o in report.outcomes]
        write_text(out, json.dumps({"criterion": suite.criterion, "mutants": len(report.outcomes),
                                         "valid": report.valid, "killed": len(report.of("killed")),
                                         "equivalent": report.equivalent, "kill_rate": report.kill_rate,
                                         "kill_rate_non_equivalent": report.kill_rate_non_equivalent,
                                         "outcomes": rows}, indent=1) + "\n")
    if not made:
        click.echo("no mutant: the model has nothing the operators change", err=True)
        sys.exit(1)
    if min_kill is not None and 100 * report.kill_rate_non_equivalent < min_kill:
        sys.exit(1)
