"""The native loop (cotwin.cosim.native): quiet stretches of steps made in C give the run the FMU path gives,
byte for byte in the CSV, with the same outcomes and state; observers hear of every step; the CSV rows'
text made in C (cotwin.cosim.rowtext: Grisu3, else Python's own function) is repr's; where the loop does not
apply, the run says why."""

from __future__ import annotations

import math
import random
import shutil
import struct

import numpy as np
import pytest

from cotwin.cosim.observers import Observer
from cotwin.twin.assembly.build import build
from cotwin.twin.assembly.run import load, run_twin


from test_fused import built  # noqa: F401 - the examples' twins and their build, a fixture


def artefacts(built_dir, out):
    """A run's folder holding the build's d-model FMU and build record (so that the run builds nothing)."""
    out.mkdir()
    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built_dir / name, out / name)
    return out


class Seen(Observer):
    """Every step's time, machine state and q0, as the observer is told of it."""

    def simulation_initialized(self, execution) -> None:
        self.steps = []
        self.read = execution.reader([("{dmodel}.dmodel", "state"), ("{mapping}.mapping", "q0")])

    def step_complete(self, execution) -> None:
        self.steps.append((execution.steps, execution.time, *self.read()))

    def repeated(self, execution, rows) -> None:
        for _ in rows.replay(execution):  # it reads only the values on the connections
            self.step_complete(execution)

    def whole_changes(self, execution) -> tuple:
        return ()  # every row is told to it: no change need end a stretch


class Saves(Observer):
    """Saves the execution's state after step `at` (it reads the units themselves: it needs the step live)."""

    def __init__(self, at: int):
        self.at, self.state = at, None

    def step_complete(self, execution) -> None:
        if execution.steps == self.at:
            self.state = execution.get_state()


def run(twin, built_dir, out, **options):
    artefacts(built_dir, out)
    seen = Seen()
    ran = run_twin(twin, out, plot=False, observers=[seen], **options)
    return ran, (out / "outputs.csv").read_bytes(), (out / "state").read_bytes(), seen.steps


@pytest.mark.parametrize("step", [0.1, 0.01, 0.001])
@pytest.mark.parametrize("case, algorithm", [("paper", "jacobi"), ("paper", "gauss-seidel"),
                                             ("pick-and-place", "gauss-seidel"), ("pick-and-place", "jacobi"),
                                             ("random", "jacobi"), ("random", "gauss-seidel")])
def test_the_native_loop_writes_the_csv_of_the_fmu_path_byte_for_byte(built, tmp_path, case, algorithm, step):
    from conftest import FUZZ_SEED
    from test_fused import random_plan

    twins, built_dir = built
    twin = {"paper": twins["cotwin.toml"], "pick-and-place": twins["pick_place_project.toml"],
            "random": twins["cotwin.toml"].with_plan(random_plan(FUZZ_SEED))}[case]
    end = 10.0 if case == "random" else None
    fmu = run(twin, built_dir, tmp_path / "fmu", step=step, end=end, fused=False, algorithm=algorithm)
    native = run(twin, built_dir, tmp_path / "native", step=step, end=end, algorithm=algorithm)
    result = native[0].result
    assert result.algorithm == algorithm
    assert fmu[0].result.stepping == "step by step" and result.stepping == "fused"
    assert result.native_steps > 0.6 * result.steps, result.describe_stepping()  # most steps are quiet
    assert native[1] == fmu[1]  # the CSV
    assert native[2] == fmu[2]  # the state left for a what-if
    assert native[3] == fmu[3]  # every step told to an observer, with its time and values
    assert [o.__dict__ for o in native[0].outcomes.outcomes] == [o.__dict__ for o in fmu[0].outcomes.outcomes]


def test_the_run_says_how_many_steps_the_native_loop_made_and_why_not(built, tmp_path):
    twins, built_dir = built
    ran = run(twins["cotwin.toml"], built_dir, tmp_path / "jacobi", step=0.01)[0].result
    assert "steps in the native loop" in ran.describe_stepping() and ran.native_why is None
    ran = run(twins["cotwin.toml"], built_dir, tmp_path / "fmu", step=0.01, fused=False)[0].result
    assert ran.native_steps == 0 and ran.describe_stepping() == "step by step"


def test_a_unit_without_a_native_step_keeps_the_run_in_the_fused_loop(tmp_path):
    from cotwin.cosim.algorithm import Jacobi
    from cotwin.cosim.execution import Execution
    from cotwin.cosim.system import System
    from test_fused import Counter

    unit = Counter().unit
    execution = Execution(System.of([unit], [], log={unit.name: ["n"]}), Jacobi(), 0.1, fused=True)
    result = execution.run(1.0)
    assert result.steps == 10 and unit.values["n"] == 10 and result.native_steps == 0
    assert "has no native step" in result.native_why and "{c}.c" in result.native_why


def test_the_native_source_is_deterministic(built, tmp_path):
    from cotwin.cosim.native import NativeLoop

    twins, built_dir = built
    sources = []
    for k in range(2):
        captured = []
        original = NativeLoop._source

        def spy(self):
            text = original(self)
            captured.append(text)
            return text

        NativeLoop._source = spy
        try:
            run(twins["cotwin.toml"], built_dir, tmp_path / f"run{k}", step=0.1)
        finally:
            NativeLoop._source = original
        sources.append(captured[0])
    assert sources[0] == sources[1] and "cotwin_segment" in sources[0]


def reference(times, values, kinds) -> str:
    """The rows as CSVWriter spells them from Python values (repr, true/false, round(t, 12))."""
    lines = []
    for t, row in zip(times, values):
        cells = [("true" if v else "false") if k == "b" else repr(int(v)) if k == "i" else repr(v) for v, k in zip(row, kinds)]
        lines.append(",".join([repr(round(t, 12)), *cells]) + "\n")
    return "".join(lines)


def test_the_rows_text_made_in_c_is_the_text_repr_makes():
    from cotwin.cosim.rowtext import rows_text

    rng = random.Random(7)

    def number() -> float:
        k = rng.random()
        if k < 0.3:
            return struct.unpack("d", struct.pack("Q", rng.getrandbits(64)))[0]  # any double, NaNs included
        if k < 0.45:
            return math.copysign(2.0 ** rng.randint(-1074, 1023), rng.choice([1, -1]))  # powers of two
        if k < 0.65:
            return round(rng.uniform(-1e3, 1e3), rng.randint(0, 17))
        if k < 0.75:
            return rng.choice([0.0, -0.0, math.inf, -math.inf, 1e16, 9.999999999999999e15, 1e-4, 9.9999e-5, 0.1])
        return rng.uniform(-10, 10)

    n = 20000
    kinds = "rribrr"
    values = []
    for _ in range(n):
        row = []
        for kind in kinds:
            row.append(number() if kind == "r" else float(rng.randint(-2 ** 40, 2 ** 40)) if kind == "i"
                       else float(rng.random() < 0.5))
        if rng.random() < 0.3 and values:
            row[0] = values[-1][0]  # a value held from the row before (the text is remembered per column)
        values.append(row)
    times = [rng.choice([k * rng.choice([0.001, 0.01, 0.1, 0.0005, 1 / 3]), rng.uniform(0, 5000), 1e-9 * k,
                         k * 0.001 + 20.0]) for k in range(n)]
    rows = np.array(values)
    text = rows_text(rows, list(range(len(kinds))), kinds, times)
    assert text is not None, "no C compiler here"
    assert text == reference(times, values, kinds)
    # every power of two, the extremes and the doubles next to them (the boundaries Grisu3 must weigh)
    edges = [math.copysign(2.0 ** k, sign) for k in range(-1074, 1024) for sign in (1, -1)]
    edges += [math.nextafter(x, 0.0) for x in edges] + [math.nextafter(x, math.copysign(math.inf, x)) for x in edges]
    edges += [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 9007199254740993.0, 1e22, 1e23, 0.3]
    column = np.array(edges).reshape(-1, 1)
    assert rows_text(column, [0], "r", [0.0] * len(edges)) == reference([0.0] * len(edges), column.tolist(), "r")
    # columns picked out of a wider row, in another order
    assert rows_text(rows, [3, 0], "br", times[:]) == reference(times, [[r[3], r[0]] for r in values], "br")


class Told(Observer):
    """Counts the steps told whole (`step_complete`) and made at once (`repeated`); `whole`: what whole_changes
    says (None: the default, every discrete change a step told whole)."""

    def __init__(self, whole):
        self.whole, self.told, self.repeats = whole, 0, 0

    def step_complete(self, execution) -> None:
        self.told += 1

    def repeated(self, execution, rows) -> None:
        self.repeats += len(rows)

    def whole_changes(self, execution):
        return self.whole


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_changes_the_units_c_reads_need_not_end_a_stretch(built, tmp_path, algorithm):
    """A change a unit's C reads step by step (the mapping's answer, a command shown, both read by the d-model)
    need not end a stretch when no observer must see it whole: the stretch goes on to the d-model's reply (an
    operation called, which Python runs); the run is the same, byte for byte, as with an observer that must see
    every discrete change whole, with a stretch end fewer per command at least."""
    twins, built_dir = built
    runs = []
    for whole in (None, ()):
        told = Told(whole)
        out = artefacts(built_dir, tmp_path / str(whole))
        ran = run_twin(twins["cotwin.toml"], out, plot=False, observers=[told], step=0.1, algorithm=algorithm)
        runs.append((told, (out / "outputs.csv").read_bytes(), (out / "state").read_bytes(),
                     [o.__dict__ for o in ran.outcomes.outcomes]))
    (every, *every_run), (some, *some_run) = runs
    commands = len(runs[0][3])
    assert some_run == every_run
    assert every.told + every.repeats == some.told + some.repeats == 200  # every step told, once
    assert every.told - some.told >= commands >= 4  # a stretch end fewer per command at least


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_command_is_shown_and_taken_inside_a_stretch(built, tmp_path, algorithm):
    """The controller's step is C too (cotwin.twin.assembly.native_commands): a command due is shown in its step
    and the d-model takes it natively, so Python makes only the steps that run an operation (the move and the
    stop of each command), and the run is the FMU path's byte for byte (CSV, state, outcomes)."""
    twins, built_dir = built
    fmu = run(twins["cotwin.toml"], built_dir, tmp_path / "fmu", step=0.1, fused=False, algorithm=algorithm)
    native = run(twins["cotwin.toml"], built_dir, tmp_path / "native", step=0.1, algorithm=algorithm)
    result, commands = native[0].result, len(native[0].outcomes.outcomes)
    assert commands >= 4 and result.steps - result.native_steps <= 2 * commands, result.describe_stepping()
    assert native[1:] == fmu[1:]
    assert [o.__dict__ for o in native[0].outcomes.outcomes] == [o.__dict__ for o in fmu[0].outcomes.outcomes]


@pytest.mark.parametrize("goes_on", [True, False])
def test_an_operation_called_is_run_by_python_and_its_step_made_natively(built, tmp_path, monkeypatch, goes_on):
    """Jacobi: the mapping's operations called in a step are run by Python before the next stretch's first step
    (NativePart.prepare), which the C then makes, so no step of the paper's run is made in Python; where the C
    cannot go on after them (here: said so by QuietStep.acted), the step is made in Python, the operations not
    run twice. Either way the run is the FMU path's, byte for byte."""
    from cotwin.mapping.cstep import QuietStep
    from cotwin.twin.assembly.mapping_unit import MappingUnit

    if not goes_on:
        monkeypatch.setattr(QuietStep, "acted", lambda self: False)
    executed = []
    act = MappingUnit.act

    def counted(self, t):
        before = len(self.executed)
        act(self, t)
        executed.extend(self.executed[before:])
    monkeypatch.setattr(MappingUnit, "act", counted)
    twins, built_dir = built
    native = run(twins["cotwin.toml"], built_dir, tmp_path / "native", step=0.1)
    ran_native, executed[:] = list(executed), []
    fmu = run(twins["cotwin.toml"], built_dir, tmp_path / "fmu", step=0.1, fused=False)
    assert ran_native == executed and len(executed) == 8  # each operation once: 4 moves, 4 stops
    assert native[1:] == fmu[1:]
    python_steps = native[0].result.steps - native[0].result.native_steps
    assert python_steps == 0 if goes_on else python_steps == len(executed)


def test_an_observer_that_must_see_every_step_live_keeps_the_run_in_the_fused_loop(built, tmp_path):
    """An observer without `repeated` (here one saving the state mid-run) sees the units at its own step:
    the native loop steps aside, says so, and the state saved is the step-by-step loop's."""
    twins, built_dir = built
    states = []
    for fused in (False, True):
        out = artefacts(built_dir, tmp_path / str(fused))
        saves = Saves(at=50)
        ran = run_twin(twins["cotwin.toml"], out, plot=False, observers=[saves], fused=fused, step=0.01)
        states.append(saves.state)
    assert ran.result.native_steps == 0 and "observer Saves must see every step" in ran.result.native_why
    assert states[0] == states[1] is not None


def test_the_math_functions_in_c_give_what_cotwins_math_functions_give():
    """The mapping's events in C call cotwin's math functions as C (cotwin.mapping.cstep.C_FUNCTIONS): on
    special values (domain errors, overflow, infinities, NaN, signed zeros) and random ones, each gives
    what cotwin.robosim.operators.MATH gives (NaN where Python would raise)."""
    import ctypes

    from cotwin.cbuild import compile_library
    from cotwin.mapping.cstep import C_FUNCTIONS, C_MATH
    from cotwin.robosim.operators import MATH

    names = sorted(C_FUNCTIONS)
    cases = "\n".join(f"        case {k}: return {C_FUNCTIONS[n][0]}({'x' if C_FUNCTIONS[n][1] == 1 else 'x, y'});"
                      for k, n in enumerate(names))
    source = ("#include <math.h>\n" + C_MATH +
              f"double call(int k, double x, double y) {{\n    switch (k) {{\n{cases}\n    }}\n    return 0.0;\n}}\n")
    call = compile_library(source, "mathtest").call
    call.argtypes, call.restype = [ctypes.c_int, ctypes.c_double, ctypes.c_double], ctypes.c_double
    rng = random.Random(5)
    specials = [-2.0, -1.0, -0.5, -0.0, 0.0, 0.5, 1.0, 2.0, 709.0, 710.0, -745.0, 1e308, -1e308, 5e-324,
                math.inf, -math.inf, math.nan]
    values = specials + [rng.uniform(-10, 10) for _ in range(200)] + [rng.uniform(-1e3, 1e3) for _ in range(50)]
    for k, name in enumerate(names):
        pairs = [(x, 0.0) for x in values] if C_FUNCTIONS[name][1] == 1 else \
            [(x, y) for x in specials for y in specials] + [(rng.uniform(-5, 5), rng.uniform(-5, 5)) for _ in range(200)]
        for x, y in pairs:
            expected = MATH[name](x) if C_FUNCTIONS[name][1] == 1 else MATH[name](x, y)
            got = call(k, x, y)
            assert (math.isnan(got) and math.isnan(expected)) or got == expected and \
                math.copysign(1, got) == math.copysign(1, expected), (name, x, y, got, expected)


MAPPING_FORMS = {  # input events of the example's mapping respelt with other forms the C spelling covers
    "equation abs(ur5e::base_link::VS1.output_vel) < VELOCITY_TOLERANCE":
        "equation max(abs(ur5e::base_link::VS1.output_vel), -sqrt(abs(ur5e::base_link::VS1.output_vel))) "
        "< VELOCITY_TOLERANCE",
    "equation abs(ur5e::shoulder_link::VS2.output_vel) < VELOCITY_TOLERANCE":
        "equation not (min(ur5e::shoulder_link::VS2.output_vel, 1.0) * -1.0 >= VELOCITY_TOLERANCE \\/ "
        "ur5e::shoulder_link::VS2.output_vel >= VELOCITY_TOLERANCE)",
    "equation motion == Motion::moving":
        "equation motion == Motion::moving /\\ (feasibility == Feasibility::infeasible => false) /\\ "
        "exp(log(1.0 + abs(target_q[0]))) > 0.5 - atan2(0.0, 1.0) /\\ (if gripper_closing then true else 1 > 0 end)",
}


def test_a_mapping_of_other_forms_runs_in_the_native_loop_with_the_same_bytes(built, tmp_path):
    """Input events spelt with min, max, sqrt, exp, log, atan2, not, =>, if-then-else, unary minus and
    enumerations run in the native loop and give the FMU path's CSV byte for byte."""
    from conftest import EXAMPLES

    folder = tmp_path / "model"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    text = (folder / "mapping.pm").read_text()
    for old, new in MAPPING_FORMS.items():
        assert old in text
        text = text.replace(old, new)
    (folder / "mapping.pm").write_text(text)
    twin = load(folder / "cotwin.toml")
    build(twin, tmp_path / "build")
    fmu = run(twin, tmp_path / "build", tmp_path / "fmu", step=0.01, fused=False)
    native = run(twin, tmp_path / "build", tmp_path / "native", step=0.01)
    assert native[0].result.native_steps > 0.6 * native[0].result.steps, native[0].result.describe_stepping()
    assert native[1] == fmu[1] and native[2] == fmu[2]
    assert [o.__dict__ for o in native[0].outcomes.outcomes] == [o.__dict__ for o in fmu[0].outcomes.outcomes]
    assert native[0].outcomes.counts()["completed"] == 4


def test_a_step_failing_inside_a_stretch_keeps_every_row_before_it(built, tmp_path, monkeypatch):
    """A unit failing at t = 5 s, in Python and in C alike: the native run raises the same error and keeps the
    same partial CSV as the step-by-step run (the stretch's steps before the failure are told to observers)."""
    from cotwin.diagnostics import CotwinError
    from cotwin.twin.assembly.scenario import ScenarioUnit

    due = 5.0 - 1e-9
    step, part = ScenarioUnit.step, ScenarioUnit.native_part

    def failing_step(self, t, h):
        if t >= due:
            raise CotwinError(f"the scenario fails at t = {t:g}")
        step(self, t, h)

    def failing_part(self, execution):
        native = part(self, execution)
        native.step = f"if (t >= {due!r}) FAIL(7);\n" + native.step  # before the step shows anything

        def failed(code, t):
            raise CotwinError(f"the scenario fails at t = {t:g}")
        native.failed = failed
        return native

    monkeypatch.setattr(ScenarioUnit, "step", failing_step)
    monkeypatch.setattr(ScenarioUnit, "native_part", failing_part)
    twins, built_dir = built
    kept = []
    for fused in (False, True):
        out = artefacts(built_dir, tmp_path / str(fused))
        with pytest.raises(CotwinError, match="the scenario fails at t = 5") as caught:
            run_twin(twins["cotwin.toml"], out, plot=False, fused=fused, step=0.01)
        kept.append(((out / "outputs.partial.csv").read_bytes(), str(caught.value).replace(str(out), "OUT")))
    assert kept[0] == kept[1]
    assert kept[1][0].count(b"\n") == 502  # the header and t = 0 .. 5 (the failing step starts at 5)


def test_a_real_port_holding_an_integer_keeps_its_spelling(built, tmp_path):
    """A scenario's Real ports start as the integer 0 (a Python unit's default) until a command sets them: the
    native rows spell them as the step-by-step rows do ("0", not "0.0"), and the state keeps them ints."""
    from conftest import EXAMPLES

    folder = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    arm = (folder / "arm.rst").read_text()
    for name in ("target_X", "target_Y", "target_Z"):
        arm = arm.replace(f"{name}: int", f"{name}: real")
    (folder / "arm.rst").write_text(arm)
    twin = load(folder / "cotwin.toml")
    build(twin, tmp_path / "build")
    fmu = run(twin, tmp_path / "build", tmp_path / "fmu", step=0.1, fused=False)
    native = run(twin, tmp_path / "build", tmp_path / "native", step=0.1)
    assert native[0].result.native_steps > 0.6 * native[0].result.steps
    assert b"0.1,false,0,0,0," in fmu[1]  # the integer zeros the rows must keep
    assert native[1] == fmu[1] and native[2] == fmu[2]


def test_integer_arithmetic_in_an_event_stays_in_python_and_says_why(built, tmp_path):
    """Integer arithmetic is exact in Python (and checked for overflow), not in doubles: an event reading
    `a * a + 1 - a * a == 1` with a = 2^27 + 1 holds in Python and not in doubles, so the native step does
    not spell it; the run says so, and its rows are the FMU path's."""
    from conftest import EXAMPLES

    folder = tmp_path / "model"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    text = (folder / "mapping.pm").read_text()
    text = text.replace("\tvar target_q:", "\tvar a: int = 134217729\n\tvar target_q:", 1)
    text = text.replace("\t\tequation gripper_opening\n", "\t\tequation a * a + 1 - a * a == 1\n", 1)
    (folder / "mapping.pm").write_text(text)
    twin = load(folder / "cotwin.toml")
    build(twin, tmp_path / "build")
    fmu = run(twin, tmp_path / "build", tmp_path / "fmu", step=0.1, fused=False)
    native = run(twin, tmp_path / "build", tmp_path / "native", step=0.1)
    result = native[0].result
    assert result.native_steps == 0 and "the operator * on an integer" in result.native_why
    assert "mapping.pm:" in result.native_why  # where
    assert native[1] == fmu[1] and native[2] == fmu[2]


def test_what_an_fmu_logs_inside_a_stretch_carries_the_time_of_its_step(tmp_path, caplog):
    """A warning the d-model logs from a step made in the native loop names that step's time, as from the
    step-by-step loop (the unit's own time is only brought up to date after a stretch). The d-model here
    calls stop every 301 cycles, twice within one step (cycle_period 5 ms at step 10 ms): the FMU warns."""
    import logging

    from conftest import EXAMPLES

    folder = tmp_path / "model"
    shutil.copytree(EXAMPLES / "ur5e", folder)
    arm = (folder / "arm.rst").read_text()
    arm = arm.replace("\tvar margs: MovementArgs\n", "\tvar margs: MovementArgs\n\tclock C\n", 1)
    arm = arm.replace("\tstate Idle { }\n", "\tstate Idle { }\n\tstate Tick { entry $stop() }\n\tstate Tock { entry $stop() }\n", 1)
    idle = "condition not ($moveDiscreteCommand \\/ $openGripperCommand \\/ $closeGripperCommand)\n\t}\n"
    assert idle in arm
    arm = arm.replace(idle, idle.replace(")\n", ") /\\ since(C) < 301\n") +
                      "\ttransition tick {\n\t\tfrom Idle to Tick\n\t\t" + idle.replace(")\n", ") /\\ since(C) >= 301\n\t\taction #C\n")
                      + "\ttransition tock { from Tick to Tock exec }\n\ttransition back { from Tock to Idle exec }\n", 1)
    (folder / "arm.rst").write_text(arm)
    project = (folder / "cotwin.toml").read_text().replace("[cosim]\n", "[cosim]\nparameters = { cycle_period = 0.005 }\n", 1)
    (folder / "cotwin.toml").write_text(project)
    twin = load(folder / "cotwin.toml")
    build(twin, tmp_path / "build")
    warned = []
    for fused in (False, True):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            ran = run(twin, tmp_path / "build", tmp_path / str(fused), step=0.01, fused=fused)[0]
        warned.append([r.getMessage() for r in caplog.records if "at t =" in r.getMessage() and "{dmodel}" in r.getMessage()])
    assert ran.result.native_steps > 0.6 * ran.result.steps
    assert warned[0] and warned[0] == warned[1]


def test_an_interrupt_during_a_stretch_is_handled_once_its_steps_are_told(built, tmp_path):
    """A SIGINT that comes while a stretch's steps are committed and told (here sent by an observer told of its
    repeats) is handled once they are: the stretch's last step reaches step_complete before the run stops."""
    import os
    import signal

    from cotwin.diagnostics import CotwinError

    class Interrupts(Observer):
        def __init__(self):
            self.sent, self.told = None, False

        def step_complete(self, execution) -> None:
            self.told = self.told or (self.sent is not None and execution.steps == self.sent)

        def repeated(self, execution, rows) -> None:
            if self.sent is None:
                self.sent = execution.steps  # the stretch's last step, told to step_complete next
                os.kill(os.getpid(), signal.SIGINT)

    twins, built_dir = built
    interrupts = Interrupts()
    with pytest.raises((CotwinError, KeyboardInterrupt), match="interrupted"):
        run_twin(twins["cotwin.toml"], artefacts(built_dir, tmp_path / "run"), step=0.01, plot=False,
                 observers=[interrupts])
    assert interrupts.sent is not None and interrupts.told
