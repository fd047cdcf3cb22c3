"""FMI 3.0: the d-model's cycle as a clock, the master running FMI 3.0 units beside FMI 2.0 ones, and the
paper's command-to-servo delay under FMI 2.0 Jacobi, Gauss-Seidel and FMI 3.0 clocks, in one run."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from ctypes import c_double, c_int, c_uint

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from conftest import EXAMPLES
from cotwin.cosim.algorithm import algorithm
from cotwin.cosim.execution import Execution
from cotwin.diagnostics import CotwinError
from cotwin.dmodel.fmi3 import build_fmu3
from cotwin.dmodel.fmu import build_fmu
from cotwin.dmodel.interpreter import Interpreter
from cotwin.dmodel.program import build_program
from cotwin.cosim.driver import FMUDriver
from cotwin.robosim.check import load_checked
from cotwin.twin.assembly.clocked import servo_delays
from cotwin.twin.assembly.run import dt_endpoint, load, run_twin
from cotwin.twin.assembly.scenario import Command

MOVE = {"target_X": 3, "target_Y": 20, "target_Z": 2}
# a sequence that is not the example's: a move, its answers, a gripper command refused mid-move, then a close
SCRIPT = [{}, {"moveDiscreteCommand": MOVE}, {}, {"feasibleMoveDiscreteCommand": None, "closeGripperCommand": None},
          {}, {"moveCompleted": None}, {}, {"robotStopped": None}, {"closeGripperCommand": None}, {},
          {"gripperClosed": None}, {}]


@pytest.fixture(scope="module")
def program():
    return build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"]))


@pytest.fixture(scope="module")
def fmus(program, tmp_path_factory):
    out = tmp_path_factory.mktemp("fmi3")
    return build_fmu(program, out / "dmodel2.fmu"), build_fmu3(program, out / "dmodel3.fmu")


def _calls(outputs) -> list[str]:
    return sorted(str(o) for o in outputs)


class EventModeDriver:
    """FMPy's FMU3Slave driven in Event Mode as the standard asks: at each tick enter Event Mode, activate the
    clock, set the clocked inputs, update the discrete states, read the outputs, then step to the next tick."""

    def __init__(self, program, path, period=0.1, log=None):
        self.program = program
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="d")
        logger = None if log is None else (lambda env, status, category, message: log.append(message.decode()))
        self.fmu.instantiate(eventModeUsed=True, logMessage=logger)
        self.fmu.setFloat64([self.vr["cycle_period"]], [period])
        self.fmu.enterInitializationMode(startTime=0.0)
        interval, qualifier = (c_double * 1)(), (c_int * 1)()
        self.fmu.getIntervalDecimal((c_uint * 1)(self.vr["cycle"]), interval, qualifier)
        self.period = interval[0]
        self.fmu.exitInitializationMode()
        self.time = 0.0

    def tick(self, inputs: dict) -> tuple[list[str], int]:
        fmu, vr = self.fmu, self.vr
        fmu.setClock([vr["cycle"]], [True])
        for ev in self.program.inputs:
            fmu.setBoolean([vr[ev.name]], [ev.name in inputs])
            for port, sc in ev.value_ports if ev.name in inputs else ():
                fmu.setInt32([vr[port]], [inputs[ev.name][sc.path[-1]]])
        fmu.updateDiscreteStates()
        calls = []
        for op in self.program.operations:
            if fmu.getBoolean([vr[op.name]])[0]:
                args = []
                for group in op.arg_ports:
                    for port, sc in group:
                        get = fmu.getInt32 if sc.fmi_type == "Integer" else fmu.getFloat64
                        args.append(get([vr[port]])[0])
                calls.append(f"{op.name}({', '.join(repr(a) if isinstance(a, float) else str(a) for a in args)})")
        state = fmu.getInt32([vr["state"]])[0]
        fmu.enterStepMode()
        handling, *_ = fmu.doStep(self.time, self.period)
        assert handling, "the step ends on the next tick: the FMU asks for Event Mode there"
        self.time += self.period
        fmu.enterEventMode()
        return sorted(calls), state


def test_the_fmi3_fmu_validates_and_runs_in_fmpy_to_the_fmi2_fmus_calls(program, fmus):
    fmu2, fmu3 = fmus
    assert validate_fmu(str(fmu3)) == []
    md = read_model_description(str(fmu3))
    assert md.fmiVersion == "3.0" and md.coSimulation.hasEventMode
    clock = next(v for v in md.modelVariables if v.type == "Clock")
    assert (clock.name, clock.causality, clock.intervalVariability) == ("cycle", "input", "fixed")
    assert all(v.clocks for v in md.modelVariables if v.causality in ("input", "output") and v.type != "Clock")
    reference, two = Interpreter(program), FMUDriver(program, fmu2, step_size=0.1)
    three = EventModeDriver(program, fmu3)
    assert three.period == 0.1
    seen = []
    for inputs in SCRIPT:
        expected = reference.step(inputs)
        calls3, state3 = three.tick(inputs)
        calls2 = two.step(inputs)
        assert calls3 == _calls(calls2) == _calls(expected), inputs
        assert state3 == two.state() == reference.state_index()
        seen += calls3
    assert seen == ["movediscrete(3, 20, 2)", "stop()", "pick(0.035, 0.1, 40.0)"]  # the close mid-move is ignored
    two.close()


def test_fmpys_simulate_fmu_runs_the_fmi3_fmu_without_event_mode_as_the_fmi2_one(fmus):
    names = ["moveDiscreteCommand", "MovementArgs_target_X", "MovementArgs_target_Y", "MovementArgs_target_Z",
             "feasibleMoveDiscreteCommand", "moveCompleted", "robotStopped"]
    dtype = [("time", np.float64)] + [(n, np.int32 if n.startswith("Movement") else np.bool_) for n in names]

    def row(t, **values):
        return (t, *(values.get(n, 0) for n in names))

    signals = np.array([row(0.0), row(0.1, moveDiscreteCommand=True, MovementArgs_target_X=3, MovementArgs_target_Y=20,
                                       MovementArgs_target_Z=2),
                        row(0.2), row(0.3, feasibleMoveDiscreteCommand=True), row(0.4), row(0.5, moveCompleted=True),
                        row(0.6, robotStopped=True), row(0.7)], dtype=dtype)
    results = [simulate_fmu(str(f), stop_time=0.8, output_interval=0.1, input=signals,
                            output=["movediscrete", "stop", "state", "target_Y"]) for f in fmus]
    assert [tuple(r) for r in results[0]] == [tuple(r) for r in results[1]]
    assert [int(r["state"]) for r in results[1]] == [0, 0, 1, 2, 3, 3, 4, 0, 0]
    assert sum(bool(r["movediscrete"]) for r in results[1]) == 1 and max(r["target_Y"] for r in results[1]) == 20


def test_an_importer_that_skips_or_passes_a_tick_gets_an_error_naming_it(program, fmus):
    logged = []
    driver = EventModeDriver(program, fmus[1], log=logged)
    driver.tick({})  # the tick at 0; now at 0.1 in Event Mode
    driver.fmu.enterStepMode()  # without activating the clock at 0.1
    with pytest.raises(Exception):
        driver.fmu.doStep(0.1, 0.1)
    assert "tick at t = 0.1 s was not activated" in logged[-1]
    driver = EventModeDriver(program, fmus[1], log=logged)
    driver.fmu.setClock([driver.vr["cycle"]], [True])
    driver.fmu.updateDiscreteStates()
    driver.fmu.enterStepMode()
    with pytest.raises(Exception):
        driver.fmu.doStep(0.0, 0.25)
    assert "passes the clock's tick at 0.1 s" in logged[-1]


def _short_plan(system):
    return system.with_plan([Command(1.0, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 0),
                                           ("MovementArgs_target_Y", 23), ("MovementArgs_target_Z", 1)), "plan item 1")])


def test_the_command_to_servo_delay_under_jacobi_gauss_seidel_and_fmi3_clocks(tmp_path):
    """The paper's three steps under FMI 2.0 Jacobi, one under Gauss-Seidel, and one under FMI 3.0 clocks with
    Jacobi stepping: the clock, not the ordering of the steps, brings the command through in its own step."""
    system = _short_plan(load(EXAMPLES / "ur5e" / "cotwin.toml"))
    found = {}
    for name, alg, fmi in (("jacobi", "jacobi", 2), ("gauss-seidel", "gauss-seidel", 2), ("fmi3", "jacobi", 3)):
        ran = run_twin(system, tmp_path / name, end=1.6, algorithm=alg, plot=False, fmi=fmi)
        found[name] = servo_delays(system.commands, ran.mapping.executed, 0.1)
    assert found == {"jacobi": [(1.0, pytest.approx(1.2), 3)], "gauss-seidel": [(1.0, 1.0, 1)],
                     "fmi3": [(1.0, 1.0, 1)]}


def test_a_clock_slower_than_the_step_keeps_a_command_for_its_next_tick(tmp_path):
    """Robot steps of 0.05 s, d-model cycles of 0.2 s: a command at 1.05 s is delivered at the tick at 1.2 s,
    once; a clock that would tick between communication points is refused."""
    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    late = system.with_plan([Command(1.05, (("moveDiscreteCommand", True), ("MovementArgs_target_X", 0),
                                            ("MovementArgs_target_Y", 23), ("MovementArgs_target_Z", 1)), "p")])
    ran = run_twin(late, tmp_path / "slow", step=0.05, end=2.0, plot=False, fmi=3, cycle_period=0.2)
    moves = [t for t, op, _ in ran.mapping.executed if op == "movediscrete"]
    assert moves == [pytest.approx(1.2)]
    with pytest.raises(CotwinError, match="not a whole number of steps"):
        run_twin(late, tmp_path / "odd", step=0.03, end=2.0, plot=False, fmi=3, cycle_period=0.1)


@pytest.mark.parametrize("algorithm_name, period", [("jacobi", 0.1), ("gauss-seidel", 0.1), ("jacobi", 0.3)])
def test_an_fmi3_twins_commands_are_judged_at_the_dmodels_tick(tmp_path, algorithm_name, period):
    """The paper's plan with the d-model an FMI 3.0 FMU: a command crosses the d-model in the event phase of the
    tick that reads it (its own step, or a later one with a clock slower than the step), so the ledger judges it
    there: every move is taken and completes, as the run shows, under Jacobi as under Gauss-Seidel."""
    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    ran = run_twin(system, tmp_path / "run", plot=False, fmi=3, algorithm=algorithm_name, cycle_period=period)
    moves = [t for t, op, _ in ran.mapping.executed if op == "movediscrete"]
    assert len(moves) == 4  # the run did every move
    assert [o.verdict for o in ran.outcomes.outcomes] == ["completed"] * 4, ran.outcomes.lines()
    assert ran.blocked == []


def test_a_slow_clock_blocks_the_wait_it_misses_an_answer_in_not_the_one_it_reads_later(tmp_path):
    """d-model cycles of 0.5 s: an answer of the platform delivered between two ticks is read at the next one, so
    the wait for it is not blocked (the first move completes); a move's completion delivered in the tick that
    takes the d-model into Moving is lost (RoboSim: an event lasts one cycle), and that wait is blocked."""
    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    ran = run_twin(system, tmp_path / "run", plot=False, fmi=3, cycle_period=0.5)
    verdicts = [o.verdict for o in ran.outcomes.outcomes]
    assert verdicts == ["completed", "never completed", "not taken", "not taken"], ran.outcomes.lines()
    assert [(b.state, b.since) for b in ran.blocked] == [("Moving", pytest.approx(6.0))]


def test_an_fmi3_twin_forks_from_its_saved_state_bit_for_bit(tmp_path):
    system = _short_plan(load(EXAMPLES / "ur5e" / "cotwin.toml"))
    fmu = tmp_path / "dmodel3.fmu"
    build_fmu3(system.models.program, fmu)
    from cotwin.twin.assembly.clocked import clocked_system

    def execution():
        return Execution(clocked_system(system, fmu, dt_endpoint(system), 0.1), algorithm("jacobi"), 0.1)

    live = execution()
    live.initialize()
    for _ in range(11):
        live.step()
    state = live.get_state()
    fork = execution()
    fork.set_state(state)
    for _ in range(5):
        live.step()
        fork.step()
        assert dict(fork.values) == dict(live.values)
    assert live.values[("{dmodel}.dmodel", "state")] != 0  # the move is under way in both
    live.close()
    fork.close()


def test_simulate_runs_an_fmi3_dmodel_beside_fmi2_units(tmp_path):
    """`cotwin simulate` on the built multimodel with the d-model swapped for its FMI 3.0 FMU: the master loads
    each FMU by its version; the FMI 2.0 controller's command reaches the clocked d-model one step later (its
    output changes only at communication points), and the robot in the same step as the d-model's call."""
    from cotwin.twin.assembly.build import build

    out = tmp_path / "twin"
    build(load(EXAMPLES / "ur5e" / "cotwin.toml"), out)
    build_fmu3(build_program(load_checked([EXAMPLES / "ur5e" / "arm.rst"])), out / "dmodel3.fmu")
    data = json.loads((out / "multimodel.json").read_text())
    data["fmus"]["{dmodel}"] = "dmodel3.fmu"
    (out / "mm3.json").write_text(json.dumps(data))
    for name in ("multimodel", "mm3"):
        proc = subprocess.run([sys.executable, "-m", "cotwin", "simulate", str(out / f"{name}.json"), "--end", "2",
                               "-o", str(out / f"{name}.csv")], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
    rows = {name: list(csv.DictReader(open(out / f"{name}.csv"))) for name in ("multimodel", "mm3")}
    calls = {name: [r["time"] for r in rs if r["{dmodel}.dmodel.movediscrete"] == "true"] for name, rs in rows.items()}
    assert calls == {"multimodel": ["1.2"], "mm3": ["1.1"]}
    # the arm started a step earlier with the FMI 3.0 d-model
    assert abs(float(rows["mm3"][-1]["{mapping}.mapping.q0"])) > abs(float(rows["multimodel"][-1]["{mapping}.mapping.q0"]))
    shutil.rmtree(out, ignore_errors=True)


@pytest.mark.parametrize("algorithm_name", ["jacobi", "gauss-seidel"])
def test_a_command_at_the_runs_start_is_judged_under_fmi3(tmp_path, algorithm_name):
    """A command due at t = 0 crosses a clocked d-model in the run's first event phase, before any step: the robot
    moved and arrived, but the ledger, starting after that phase, took it for one applied before the run and said
    'commands: none applied'. It is judged by the d-model's first cycle (from its initial junction)."""
    system = load(EXAMPLES / "ur5e" / "cotwin.toml").with_plan([Command(0.0, (
        ("moveDiscreteCommand", True), ("MovementArgs_target_X", 0), ("MovementArgs_target_Y", 23),
        ("MovementArgs_target_Z", 1)), "plan item 1")])
    ran = run_twin(system, tmp_path / "run", end=2.0, plot=False, fmi=3, algorithm=algorithm_name)
    assert [t for t, op, _ in ran.mapping.executed if op == "movediscrete"] == [0.0]  # the move ran, from t = 0
    [outcome] = ran.outcomes.outcomes
    assert (outcome.delivered, outcome.accepted, outcome.verdict) == (0.0, True, "completed"), ran.outcomes.lines()
