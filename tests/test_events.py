"""Events are events (docs/interop.md): every RoboSim event crossing an FMU boundary is true in exactly
the step in which it occurs and carries the values of that occurrence; a request's answer is never a
previous request's. Under Jacobi and Gauss-Seidel, in the twin and in the mapping unit alone."""

from __future__ import annotations

import csv

import pytest

from cotwin.twin.assembly.run import load, run_twin
from cotwin.twin.assembly.scenario import Command
from test_twin_e2e import built, twin  # noqa: F401 - the example twin and its built FMU, shared fixtures

ALGORITHMS = ["jacobi", "gauss-seidel"]
MAPPING = "{mapping}.mapping"
DMODEL = "{dmodel}.dmodel"


def move(time: float, x: int, y: int, z: int) -> Command:
    return Command(time, (("moveDiscreteCommand", True), ("MovementArgs_target_X", x), ("MovementArgs_target_Y", y),
                          ("MovementArgs_target_Z", z)), f"move at {time:g} s")


def run(twin, built, tmp_path, plan, algorithm, step=0.1, end=14.0):
    import shutil

    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built / name, tmp_path / name)
    ran = run_twin(twin.with_plan(plan), tmp_path, step=step, end=end, algorithm=algorithm, plot=False)
    with open(tmp_path / "outputs.csv", newline="") as f:
        return ran, list(csv.DictReader(f))


def true_at(rows, column) -> list[float]:
    return [round(float(r["time"]), 6) for r in rows if r[column] == "true"]


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_an_infeasible_move_after_a_feasible_one_is_answered_as_infeasible(twin, built, tmp_path, algorithm):
    """Issue 19 item 1: feasible (0, 23, 1), unreachable (15, 23, 3), feasible (8, 10, 0). Under Jacobi the
    d-model read the first move's answer, still held, as the second's: it waited in Moving forever."""
    ran, rows = run(twin, built, tmp_path, [move(1.0, 0, 23, 1), move(5.0, 15, 23, 3), move(9.0, 8, 10, 0)], algorithm)
    program = twin.models.program
    leaves = program.leaf_names(program.machines[0])
    # one answer per request, each true in exactly one step
    feasible = true_at(rows, f"{MAPPING}.feasibleMoveDiscreteCommand")
    infeasible = true_at(rows, f"{MAPPING}.nonfeasibleMoveDiscreteCommand")
    assert len(feasible) == 2 and len(infeasible) == 1
    assert feasible[0] < 5.0 < infeasible[0] < 9.0 < feasible[1]
    # the infeasible move sends the d-model back to Idle, and the third move is made and completed
    after = [r for r in rows if infeasible[0] < float(r["time"]) < 9.0]
    assert {leaves[int(r[f"{DMODEL}.state"])] for r in after[2:]} == {"Idle"}
    targets = [(a["target_X"], a["target_Y"], a["target_Z"]) for _, op, a in ran.mapping.executed if op == "movediscrete"]
    assert targets == [(0, 23, 1), (15, 23, 3), (8, 10, 0)]
    completed = true_at(rows, f"{MAPPING}.moveCompleted")
    assert len(completed) == 2 and completed[1] > 9.0
    assert leaves[int(rows[-1][f"{DMODEL}.state"])] == "Idle"


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_two_feasible_moves_in_a_row_get_one_answer_each_after_their_request(twin, built, tmp_path, algorithm):
    """The same answer twice: it occurs again because the second request asked anew, and never before the
    mapping executed that request (under Jacobi one step after the d-model called it)."""
    ran, rows = run(twin, built, tmp_path, [move(1.0, 0, 23, 1), move(4.0, 3, 20, 2)], algorithm, end=8.0)
    executed = [round(t, 6) for t, op, _ in ran.mapping.executed if op == "movediscrete"]
    feasible = true_at(rows, f"{MAPPING}.feasibleMoveDiscreteCommand")
    # the answer is the output of the step that executed the request (its row is that step's end)
    assert feasible == [round(t + 0.1, 6) for t in executed]
    calls = true_at(rows, f"{DMODEL}.movediscrete")
    assert len(calls) == 2 and all(call <= answer for call, answer in zip(calls, feasible))


TICKER = """
interface Ops {
	beat(n: int)
}

stm Ticker {
	var n: int = 0
	output context { requires Ops }
	initial i0
	state Run { }
	transition init { from i0 to Run }
	transition tick { from Run to Run exec action n = n + 1; $beat(n) }
}

controller TickC {
	requires Ops
	sref s = Ticker
}

module Tick {
	robotic platform P { provides Ops }
	cref c = TickC
}
"""


def test_an_output_raised_in_several_cycles_of_one_step_is_said_to_be_lost(tmp_path, caplog):
    """A Boolean port carries one occurrence per step: with cycle_period a third of the step, an operation
    called every cycle reaches the platform once per step, and the FMU says the others are lost (once)."""
    from cotwin.dmodel.fmu import build_fmu
    from cotwin.dmodel.program import build_program
    from cotwin.cosim.driver import FMUDriver
    from cotwin.robosim.check import load_checked

    (tmp_path / "tick.rst").write_text(TICKER)
    program = build_program(load_checked([tmp_path / "tick.rst"]))
    fmu = build_fmu(program, tmp_path / "tick.fmu")
    for period, warned in ((0.1, True), (0.3, False)):
        caplog.clear()
        driver = FMUDriver(program, fmu, parameters={"cycle_period": period}, step_size=0.3)
        try:
            driver.step({})
            second = driver.step({})
        finally:
            driver.close()
        assert [o.name for o in second] == ["beat"]
        lost = [r.getMessage() for r in caplog.records if "several of the 3 cycles" in r.getMessage()]
        assert len(lost) == (1 if warned else 0)
        if warned:
            assert "beat" in lost[0] and "unit dmodel" in lost[0]


@pytest.fixture
def mapping(twin):
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.mapping.runtime import Mapping
    from cotwin.pmodel.simulator import PlatformSimulator

    models = twin.models
    runtime = Mapping(models.project, SimulatedEndpoint(PlatformSimulator(models.tree, models.scene)))
    runtime.start_mapping()
    yield runtime
    runtime.stop_mapping()


def occurring(runtime) -> set[str]:
    runtime.step(0.1)
    return {name for name, (occurs, _) in runtime.report().items() if occurs}


def test_answers_are_events_read_from_what_operations_assign_and_observations_the_rest(mapping):
    assert mapping.answers == {"feasibleMoveDiscreteCommand", "nonfeasibleMoveDiscreteCommand", "moveCompleted",
                               "gripperClosed", "gripperOpened"}
    # an observation occurs in every step it holds (each step a new sample): the arm at rest
    assert all("robotStopped" in occurring(mapping) for _ in range(3))


def test_an_answer_occurs_once_per_request_and_never_for_the_next_one(mapping):
    mapping.execute_operation("movediscrete", {"target_X": 0, "target_Y": 23, "target_Z": 1})
    assert "feasibleMoveDiscreteCommand" in occurring(mapping)
    for _ in range(3):  # the definition still holds: no new occurrence
        assert not {"feasibleMoveDiscreteCommand", "nonfeasibleMoveDiscreteCommand"} & occurring(mapping)
    mapping.execute_operation("movediscrete", {"target_X": 3, "target_Y": 20, "target_Z": 2})
    assert "feasibleMoveDiscreteCommand" in occurring(mapping)  # asked anew: its own answer
    mapping.execute_operation("movediscrete", {"target_X": 15, "target_Y": 23, "target_Z": 3})
    got = occurring(mapping)
    assert "nonfeasibleMoveDiscreteCommand" in got and "feasibleMoveDiscreteCommand" not in got


def test_answers_that_come_together_are_delivered_one_per_step_and_a_new_request_drops_the_old(mapping):
    mapping.execute_operation("movediscrete", {"target_X": 0, "target_Y": 23, "target_Z": 1})
    seen = [occurring(mapping) for _ in range(40)]
    done = next(k for k, s in enumerate(seen) if "moveCompleted" in s)
    mapping.execute_operation("stop", {})
    occurring(mapping)
    # a move to where the arm is: feasible and completed in the same step, delivered in that order
    mapping.execute_operation("movediscrete", {"target_X": 0, "target_Y": 23, "target_Z": 1})
    first, second, third = occurring(mapping), occurring(mapping), occurring(mapping)
    answers = mapping.answers
    assert first & answers == {"feasibleMoveDiscreteCommand"} and second & answers == {"moveCompleted"}
    assert not third & answers and done > 0
    # the same again, but a new request comes before the waiting completion is delivered: it was the
    # previous request's answer, so it is dropped
    mapping.execute_operation("stop", {})
    occurring(mapping)
    mapping.execute_operation("movediscrete", {"target_X": 0, "target_Y": 23, "target_Z": 1})
    assert occurring(mapping) & answers == {"feasibleMoveDiscreteCommand"}
    mapping.execute_operation("movediscrete", {"target_X": 8, "target_Y": 10, "target_Z": 0})
    assert occurring(mapping) & answers == {"feasibleMoveDiscreteCommand"}


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_a_wait_for_an_answer_that_cannot_come_is_said_naming_the_state_and_the_reason(tmp_path, algorithm, caplog):
    """A mapping that forgets to set `motion` when a move is feasible: the d-model waits in Moving for a
    moveCompleted whose condition no motion can make true. The run says so, once, where and why."""
    import shutil

    from conftest import EXAMPLES

    project = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", project)
    mapping = project / "mapping.pm"
    text = mapping.read_text()
    assert "\t\taction motion = if ok then Motion::moving else motion end\n" in text
    mapping.write_text(text.replace("\t\taction motion = if ok then Motion::moving else motion end\n", ""))
    (project / "plan.csv").write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,"
                                      "MovementArgs_target_Z\n1000,true,0,23,1\n")
    with caplog.at_level("WARNING", logger="cotwin.twin"):
        ran = run_twin(load(project / "cotwin.toml"), tmp_path / "out", end=5.0, algorithm=algorithm, plot=False)
    assert len(ran.blocked) == 1
    blocked = ran.blocked[0]
    assert (blocked.state, blocked.events, blocked.others) == ("Moving", ["collision", "moveCompleted"], ["collision"])
    assert "motion == Motion::moving" in blocked.reasons["moveCompleted"]
    assert "mapping.pm:107:12" in blocked.reasons["moveCompleted"] and "(movejoint, stop)" in blocked.reasons["moveCompleted"]
    said = [r.getMessage() for r in caplog.records if "waits in state Moving" in r.getMessage()]
    assert len(said) == 1 and f"since t = {blocked.since:g} s" in said[0]


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_a_blocked_wait_is_found_at_the_same_step_in_the_native_loop_as_step_by_step(tmp_path, algorithm):
    """The native loop lets a wait entered among a stretch's steps pass only where the judgement could not find it
    blocked (Observer.whole_values, checkpoints): a wait that is blocked is found at the step the step-by-step
    loop finds it, with the same reasons, and the run's outcomes and CSV are the same."""
    import shutil

    from conftest import EXAMPLES

    project = tmp_path / "ur5e"
    shutil.copytree(EXAMPLES / "ur5e", project)
    mapping = project / "mapping.pm"
    text = mapping.read_text()
    mapping.write_text(text.replace("\t\taction motion = if ok then Motion::moving else motion end\n", ""))
    (project / "plan.csv").write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,"
                                      "MovementArgs_target_Z\n1000,true,0,23,1\n3000,true,8,10,0\n")
    twin = load(project / "cotwin.toml")
    found = []
    for fused in (False, True):
        out = tmp_path / str(fused)
        ran = run_twin(twin, out, end=5.0, step=0.1, algorithm=algorithm, plot=False, fused=fused)
        found.append(([b.__dict__ for b in ran.blocked], [o.__dict__ for o in ran.outcomes.outcomes],
                      (out / "outputs.csv").read_bytes()))
    assert ran.result.native_steps > 0.6 * ran.result.steps
    assert len(found[1][0]) == 1 and found[1] == found[0]


@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("plan", [[(1.0, 0, 23, 1), (5.0, 15, 23, 3), (9.0, 8, 10, 0)], [(1.0, 0, 23, 1), (4.2, 3, 20, 2)]])
def test_no_wait_is_said_blocked_in_a_run_that_completes(twin, built, tmp_path, algorithm, plan):
    """The second plan's move completes three steps into Moving: the completion, just delivered, is not
    yet read by the d-model when the watch looks, which must not call it lost."""
    ran, rows = run(twin, built, tmp_path, [move(*m) for m in plan], algorithm, end=8.0 if len(plan) == 2 else 14.0)
    assert ran.blocked == []
    assert len(true_at(rows, f"{MAPPING}.moveCompleted")) == len(plan) - (len(plan) == 3)


def test_a_wait_whose_answer_may_still_come_does_not_end_a_native_stretch(twin, built, tmp_path):
    """The blocked-wait watch judges a wait `patience` steps after the d-model entered it, on a step seen whole.
    While the move is under way its answer may come, and stays so until it comes (which ends the stretch
    anyway): the judgement cannot find it blocked, so it must not end the native stretch there (issue 23: a
    stretch end per command for nothing). A wait that is blocked is still found (the tests above)."""
    from cotwin.cosim.observers import Observer

    class Whole(Observer):
        def __init__(self):
            self.steps: list[int] = []

        def step_complete(self, execution) -> None:
            self.steps.append(execution.steps)

        def repeated(self, execution, rows) -> None:
            return None

    import shutil

    for name in ("dmodel.fmu", "build.json"):
        shutil.copy(built / name, tmp_path / name)
    whole = Whole()
    ran = run_twin(twin.with_plan([move(1.0, 0, 23, 1)]), tmp_path, step=0.1, end=4.0, plot=False, observers=[whole])
    assert ran.result.native_steps > 0 and ran.blocked == []
    with open(tmp_path / "outputs.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    program = twin.models.program
    leaves = program.leaf_names(program.machines[0])
    step = {round(float(r["time"]) / 0.1): r for r in rows}
    entered = min(k for k, r in step.items() if leaves[int(r[f"{DMODEL}.state"])] == "Moving")
    came = min(k for k, r in step.items() if r[f"{MAPPING}.moveCompleted"] == "true")
    judged = entered + 3  # WaitWatch's patience
    assert judged < came - 1  # the move is still under way when the watch judges
    assert entered in whole.steps and came in whole.steps  # changes are seen whole
    assert judged not in whole.steps
