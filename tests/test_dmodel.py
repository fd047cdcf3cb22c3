"""d-model execution: the interpreter and the compiled FMU follow the cycle semantics and agree."""

from __future__ import annotations

import subprocess
import sys
import zipfile

import pytest
from fmpy.validation import validate_fmu
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cotwin.diagnostics import CotwinError
from cotwin.dmodel.fmu import build_fmu, fmu_sources
from cotwin.dmodel.ports import PortLayout
from cotwin.dmodel.interpreter import ExecutionError, Interpreter
from cotwin.dmodel.program import build_program
from cotwin.cosim.driver import FMUDriver
from cotwin.dmodel.verify import verify
from cotwin.robosim.check import load_checked

ARGS = {"target_X": 0, "target_Y": 23, "target_Z": 1}
# docs/robosim-notation.md, section 6: inputs per cycle -> outputs
PAPER_TRACE = [
    ({}, []),
    ({"moveDiscreteCommand": ARGS}, ["movediscrete(0, 23, 1)"]),
    ({"feasibleMoveDiscreteCommand": None}, ["movediscrete(0, 23, 1)"]),
    ({}, []),
    ({"moveCompleted": None}, ["stop()"]),
    ({"robotStopped": None}, []),
]


@pytest.fixture(scope="module")
def paper_program():
    from conftest import SHARED

    if not (SHARED / "ur5e" / "ur5e_gripper.rst").is_file():
        pytest.skip(f"the paper's published models are not at {SHARED}")
    return build_program(load_checked([SHARED / "ur5e" / "ur5e_gripper.rst"]))


@pytest.fixture(scope="module")
def example_program():
    from conftest import EXAMPLES

    return build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]))


@pytest.fixture(scope="module")
def paper_fmu(paper_program, tmp_path_factory):
    return build_fmu(paper_program, tmp_path_factory.mktemp("fmu") / "ur5e.fmu")


@pytest.fixture(scope="module")
def example_fmu(example_program, tmp_path_factory):
    return build_fmu(example_program, tmp_path_factory.mktemp("fmu") / "arm.fmu")


def test_interpreter_reproduces_the_paper_trace(paper_program):
    interp = Interpreter(paper_program)
    for inputs, expected in PAPER_TRACE:
        assert [str(o) for o in interp.step(inputs)] == expected
    assert interp.active_leaf() == "Idle"
    assert interp.warnings == []


def test_fmu_reproduces_the_paper_trace_through_fmpy(paper_program, paper_fmu):
    driver = FMUDriver(paper_program, paper_fmu)
    try:
        states = []
        for inputs, expected in PAPER_TRACE:
            assert [str(o) for o in driver.step(inputs)] == expected
            states.append(paper_program.leaf_names(paper_program.machines[0])[driver.state()])
        assert states == ["Idle", "ArmMove", "ArmMoving", "ArmMoving", "ArmStopping", "Idle"]
    finally:
        driver.close()


def test_fmus_validate_without_problems(paper_fmu, example_fmu):
    assert validate_fmu(str(paper_fmu)) == []
    assert validate_fmu(str(example_fmu)) == []
    with zipfile.ZipFile(paper_fmu) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", "binaries/linux64/DiscreteGrippingArm.so", "sources/model.c",
            "sources/fmi2.c"} <= names


def test_ports_follow_the_interop_naming(paper_program):
    names = {v.name: v for v in PortLayout(paper_program).variables}
    assert names["moveDiscreteCommand"].causality == "input" and names["moveDiscreteCommand"].fmi_type == "Boolean"
    for field in ("target_X", "target_Y", "target_Z"):
        assert names[f"MovementArgs_{field}"].causality == "input"
        assert names[field].causality == "output" and names[field].fmi_type == "Integer"
    assert names["movediscrete"].causality == "output"
    assert names["state"].fmi_type == "Integer" and "0=Idle" in names["state"].description
    assert names["closing_diameter"].causality == "parameter"  # a const without a value
    assert names["cycle_period"].causality == "parameter"


def test_generated_sources_are_deterministic(paper_program):
    assert fmu_sources(paper_program) == fmu_sources(build_program(paper_program.project))


def test_fmu_runs_in_libcosimpy(example_program, example_fmu):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    ports = {v.name: v.vr for v in PortLayout(example_program).variables}
    ex = CosimExecution.from_step_size(step_size=int(1e9))
    idx = ex.add_local_slave(CosimLocalSlave(fmu_path=str(example_fmu), instance_name="arm"))
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    manipulator = CosimManipulator.create_override()
    ex.add_manipulator(manipulator)
    assert ex.step()
    manipulator.slave_boolean_values(idx, [ports["moveDiscreteCommand"]], [True])
    manipulator.slave_integer_values(idx, [ports["MovementArgs_target_Y"]], [17])
    assert ex.step()
    assert observer.last_boolean_values(idx, [ports["movediscrete"]]) == [True]
    assert observer.last_integer_values(idx, [ports["target_Y"]]) == [17]
    leaves = example_program.leaf_names(example_program.machines[0])
    assert leaves[observer.last_integer_values(idx, [ports["state"]])[0]] == "Requested"


def test_cycle_period_runs_several_cycles_per_step(example_program, example_fmu):
    # h = 3 cycles: the command arrives in the first, the FMU then waits for feasibility
    driver = FMUDriver(example_program, example_fmu, parameters={"cycle_period": 0.1}, step_size=0.3)
    try:
        outputs = driver.step({"moveDiscreteCommand": ARGS})
        assert [str(o) for o in outputs] == ["movediscrete(0, 23, 1)"]
        assert example_program.leaf_names(example_program.machines[0])[driver.state()] == "AwaitFeasibility"
    finally:
        driver.close()


def _inputs(program):
    events = [ev.name for ev in program.inputs]
    args = st.fixed_dictionaries({k: st.integers(-5, 30) for k in ("target_X", "target_Y", "target_Z")})

    @st.composite
    def cycle(draw):
        chosen = draw(st.lists(st.sampled_from(events), max_size=3, unique=True))
        return {e: (draw(args) if e == "moveDiscreteCommand" else None) for e in chosen}

    return st.lists(cycle(), min_size=1, max_size=25)


def _differential(program, fmu, sequence):
    interp = Interpreter(program)
    driver = FMUDriver(program, fmu)
    try:
        for inputs in sequence:
            try:
                expected = interp.step(inputs)
            except ExecutionError:
                with pytest.raises(Exception):
                    driver.step(inputs)
                return
            assert driver.step(inputs) == expected, f"after {sequence}"
            assert driver.state() == interp.state_index()
    finally:
        driver.close()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_differential_example_model(example_program, example_fmu, data):
    _differential(example_program, example_fmu, data.draw(_inputs(example_program)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_differential_paper_model(paper_program, paper_fmu, data):
    _differential(paper_program, paper_fmu, data.draw(_inputs(paper_program)))


def test_verify_reports_the_paper_models_findings_with_traces(paper_program):
    report = verify(paper_program)
    assert report.complete and not report.ok
    by_kind = {}
    for v in report.violations:
        by_kind.setdefault(v.property, []).append(v)
    idle = [v for v in by_kind["determinism"] if "node Idle" in v.message]
    assert idle and len(idle[0].trace) == 1
    assert "moveDiscreteCommand" in idle[0].trace[0] and len(idle[0].trace[0]) == 2
    # replaying the counterexample shows the overlap
    interp = Interpreter(paper_program)
    interp.step(idle[0].trace[0])
    assert interp.warnings and interp.warnings[0].node == "Idle" and len(interp.warnings[0].enabled) == 2
    assert by_kind["repeated-output"][0].trace == [
        {"moveDiscreteCommand": {"target_X": 0, "target_Y": 0, "target_Z": 0}, "nonfeasibleMoveDiscreteCommand": None}]
    assert "timelock" not in by_kind and report.unreached_states == []


def test_verify_our_model_all_properties_hold(example_program):
    report = verify(example_program)
    assert report.ok, [v.format() for v in report.violations]
    assert report.states > 5


TIMELOCK = """interface I { event go event other }
stm M {
	input context { uses I }
	initial i
	state A { }
	state B { }
	junction J
	transition t0 { from i to A }
	transition t1 { from A to A exec condition not $go }
	transition t2 { from A to J condition $go }
	transition t3 { from J to B condition $other }
	transition t4 { from B to B exec }
}
controller C { uses I sref m = M
	connection C on go to m on go (_async) connection C on other to m on other (_async) }
module Mod { robotic platform P { uses I } cref c = C
	connection P on go to c on go (_async) connection P on other to c on other (_async) }
"""


def test_verify_finds_a_timelock_with_its_trace(tmp_path):
    (tmp_path / "t.rst").write_text(TIMELOCK)
    program = build_program(load_checked([tmp_path / "t.rst"]))
    report = verify(program)
    [violation] = [v for v in report.violations if v.property == "timelock"]
    assert violation.trace == [{"go": None}] and "junction J" in violation.message
    with pytest.raises(ExecutionError, match="timelock"):
        Interpreter(program).step({"go": None})
    proc = subprocess.run([sys.executable, "-m", "cotwin", "verify", str(tmp_path / "t.rst")],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "cycle 1: {go}" in proc.stdout and "Traceback" not in proc.stderr


def test_build_dmodel_cli(tmp_path):
    from conftest import EXAMPLES

    out = tmp_path / "arm.fmu"
    proc = subprocess.run([sys.executable, "-m", "cotwin", "build-dmodel", str(EXAMPLES / "ur5e" / "arm.rst"),
                           "-o", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert validate_fmu(str(out)) == []


def test_build_dmodel_without_module_is_a_clean_error(tmp_path):
    (tmp_path / "i.rst").write_text("interface I { event e }\n")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "build-dmodel", str(tmp_path / "i.rst"), "-o",
                           str(tmp_path / "x.fmu")], capture_output=True, text=True)
    assert proc.returncode == 1 and "no module" in proc.stderr and "Traceback" not in proc.stderr


def _module_in(package: str) -> str:
    return (f"package {package}\ninterface I {{ event e }}\n"
            "stm M { input context { uses I } initial i state A { } transition t0 { from i to A }\n"
            "\ttransition t1 { from A to A exec } }\n"
            "controller C { uses I sref m = M connection C on e to m on e }\n"
            "module Mod { robotic platform P { uses I } cref c = C connection P on e to c on e (_async) }\n")


def test_a_module_name_two_packages_declare_is_refused_naming_each_where_it_is(tmp_path):
    """--module Mod with Mod in packages A and B took A's silently (the first of that name), and --module Z::Mod did
    too (its last part matched); several modules were listed as 'Mod, Mod'. Each is now named as --module takes it,
    at its declaration; a name matches a module's qualified name or its end only."""
    for package in ("A", "B"):
        (tmp_path / f"{package.lower()}.rst").write_text(_module_in(package))
    files = load_checked([tmp_path / "a.rst", tmp_path / "b.rst"])
    for name in (None, "Mod"):
        with pytest.raises(CotwinError) as err:
            build_program(files, name)
        found = [(f.location.path, f.location.line, f.message) for f in err.value.findings]
        which = "modules named 'Mod'" if name else "modules"
        assert found == [(str(tmp_path / f"{p.lower()}.rst"), 6, f"2 {which}: this is {p}::Mod: choose one with "
                          f"--module {p}::Mod") for p in ("A", "B")], found
    with pytest.raises(CotwinError, match=r"no module 'Z::Mod' \(modules: A::Mod, B::Mod\)"):
        build_program(files, "Z::Mod")
    assert build_program(files, "B::Mod").module is files.lookup("module", "B::Mod")


def test_unsupported_variable_types_are_located(tmp_path):
    text = TIMELOCK.replace("input context { uses I }", "var v: string\n\tinput context { uses I }")
    (tmp_path / "v.rst").write_text(text)
    with pytest.raises(CotwinError) as err:
        build_program(load_checked([tmp_path / "v.rst"]))
    [finding] = err.value.findings
    assert (finding.location.line, finding.location.column) == (3, 6)
    assert "values of type string cannot be executed yet" in finding.message


COMPOSITE_TIMEOUT = """
interface Ops { go() }
interface Cmds { event start }
stm M {
	cycleDef cycle == 1
	clock T
	input context { uses Cmds }
	output context { requires Ops }
	initial i0
	state Idle { }
	state Work {
		initial w0
		state Go { entry #T; $go() }
		state Wait { }
		transition w { from w0 to Go }
		transition sent { from Go to Wait exec }
		transition waiting { from Wait to Wait exec }
	}
	state Late { }
	transition init { from i0 to Idle }
	transition idle { from Idle to Idle exec condition not $start }
	transition begin { from Idle to Work condition $start }
	transition late { from Work to Late exec condition since(T) > 3 }
	transition lateWait { from Late to Late exec }
}
controller C { cycleDef cycle == 1 uses Cmds requires Ops sref m = M
	connection C on start to m on start (_async) }
module Mod { cycleDef cycle == 1
	robotic platform P { provides Ops uses Cmds }
	cref c = C
	connection P on start to c on start (_async) }
"""


def test_a_composite_is_entered_before_its_own_transitions_are_chosen(tmp_path):
    """A composite state's timeout (since(T) > 3, T reset by its substate's entry) must not fire at its initial
    junction, before the substate is entered: a command after a long idle used to go straight to Late, go()
    never called (a user's sorter: every leg after a pause timed out at once). Interpreter and C alike."""
    (tmp_path / "c.rst").write_text(COMPOSITE_TIMEOUT)
    program = build_program(load_checked([tmp_path / "c.rst"]))
    sequence = [{}] * 6 + [{"start": None}] + [{}] * 6
    interp = Interpreter(program)
    calls = [[str(o) for o in interp.step(inputs)] for inputs in sequence]
    assert calls[6] == ["go()"] and calls[7:10] == [[], [], []]
    assert interp.active_leaf() == "Late"
    _differential(program, build_fmu(program, tmp_path / "c.fmu"), sequence)
