"""What-ifs and sweeps from the state of a twin run with the FMI 3.0 d-model (`cotwin run --fmi 3`): the fork is
built as the DT ran, the FMI 3.0 d-model clocked with the saved period, its ticks in the saved phase."""

from __future__ import annotations

import csv
import subprocess
import sys

import pytest

from conftest import EXAMPLES
from cotwin.cosim.observers import Observer
from cotwin.diagnostics import CotwinError
from cotwin.cosim.state import StateError, pack, unpack
from cotwin.cosim.execution import saved_execution
from cotwin.twin.analysis.sweep import failures, grid, run_sweep, summary
from cotwin.twin.assembly.clocked import saved_clock
from cotwin.twin.assembly.run import load, run_twin
from cotwin.twin.assembly.scenario import Command
from cotwin.twin.assembly.system import DMODEL
from cotwin.twin.services.whatif import Forks, predict

JOINTS = [f"q{k}" for k in range(6)]
PERIOD = 0.3  # s: the clock ticks at 0, 0.3, ...: the fork at 5 s is between two ticks (5.1 is the next)


@pytest.fixture(scope="module")
def system():
    return load(EXAMPLES / "ur5e" / "cotwin.toml")


class Save(Observer):
    """Takes the run's state after `at` steps."""

    def __init__(self, at: int):
        self.at, self.state = at, None

    def step_complete(self, execution) -> None:
        if execution.steps == self.at:
            self.state = execution.get_state()


@pytest.fixture(scope="module")
def fmi3_run(system, tmp_path_factory):
    """The paper's plan run with the FMI 3.0 d-model ticking every 0.3 s: its folder, its state saved at 5 s and
    what became of its commands."""
    out = tmp_path_factory.mktemp("fmi3run")
    save = Save(at=50)
    ran = run_twin(system, out, plot=False, fmi=3, cycle_period=PERIOD, observers=[save])
    return out, save.state, ran.outcomes.outcomes  # the outcomes: what became of each command in the run


def test_a_whatif_from_an_fmi3_runs_state_goes_on_as_the_run_did(system, fmi3_run):
    """The commands after 5 s replayed on a fork of the FMI 3.0 run's state at 5 s: the same trajectory, bit for
    bit, and every command completes as the run's did (the d-model FMI 3.0's, ticking every 0.3 s from 0)."""
    out, state, outcomes = fmi3_run
    assert saved_clock(saved_execution(state)) == PERIOD
    remaining = [Command(c.time - 5.0, c.values, c.where) for c in system.commands if c.time > 5.0]
    prediction = predict(system, remaining, state, horizon=15.0, artefacts=out)
    live = {r["time"]: r for r in csv.DictReader(open(out / "outputs.csv"))}
    assert prediction.start == 5.0 and len(prediction.trajectory["time"]) > 100
    for k, t in enumerate(prediction.trajectory["time"]):
        row = live[repr(round(t, 12))]
        assert [float(row[f"{{mapping}}.mapping.{q}"]) for q in JOINTS] == [prediction.trajectory[q][k] for q in JOINTS]
    assert [c.verdict for c in prediction.commands] == ["completed"] * 3
    outcome = lambda c: (c.time, c.delivered, c.accepted, c.feasible, c.done, c.verdict)  # noqa: E731
    assert [outcome(c) for c in prediction.commands] == [outcome(c) for c in outcomes[1:]]


def test_a_sweep_from_an_fmi3_runs_state_answers_as_its_whatifs_do(system, fmi3_run):
    """A sweep's forks (Forks, restored plan after plan) and its pool of processes answer each plan as `predict`
    does from the FMI 3.0 run's state."""
    out, state, _ = fmi3_run
    plans = grid(system.models.program, "moveDiscreteCommand", {"target_X": [0, 3], "target_Y": [20], "target_Z": [1]})
    alone = [summary(predict(system, plan, state, horizon=3.0, artefacts=out, decimate=10**9)) for plan in plans]
    with Forks(system, state, artefacts=out) as forks:
        assert [summary(forks.predict(plan, horizon=3.0, decimate=10**9)) for plan in plans] == alone
    answers = run_sweep(system.spec.path, plans, state, horizon=3.0, workers=1, artefacts=out / "sweep")
    assert not failures(answers), answers
    assert [{k: v for k, v in row.items() if k in alone[0]} for row in answers] == alone
    assert all(row["feasible"] and row["time_to_done"] is not None for row in answers), answers


def test_an_fmi3_state_without_its_clock_is_refused_saying_what_to_do(system, fmi3_run):
    """A state of an FMI 3.0 d-model saved by an earlier cotwin (no clock period, no phase) cannot be forked as
    it ran: the what-if says so and what to do, never that it is "a state of a FMU3, not of a FMU"."""
    _, state, _ = fmi3_run
    saved = saved_execution(state)
    dmodel = unpack(saved["units"][DMODEL.name], "FMU3")
    old_dmodel = pack("FMU3", {k: v for k, v in dmodel.items() if k not in ("start", "intervals")})
    old = pack("Execution", {**saved, "units": {**saved["units"], DMODEL.name: old_dmodel}})
    with pytest.raises(StateError, match=r"earlier cotwin.*run the twin again \(cotwin run --fmi 3\)"):
        predict(system, [], old, horizon=1.0)
    with pytest.raises(CotwinError, match="cycle_period 0.3 s is not a whole number of steps of 0.2 s"):
        predict(system, [], state, horizon=1.0, step=0.2)  # the saved clock cannot tick on this fork's steps


def test_an_fmi3_state_restored_into_a_dmodel_clocked_otherwise_is_refused_naming_both(system, fmi3_run):
    from cotwin.cosim.algorithm import algorithm
    from cotwin.cosim.execution import Execution
    from cotwin.twin.assembly.clocked import clocked_system
    from cotwin.twin.assembly.run import simulated_endpoint
    from cotwin.twin.assembly.system import MAPPING

    out, state, _ = fmi3_run
    fork = Execution(clocked_system(system, out / "dmodel3.fmu", simulated_endpoint(system), 0.2), algorithm("jacobi"),
                     0.1, 5.0)
    with pytest.raises(StateError, match="ticks clock cycle every 0.3 s, this one every 0.2 s"):
        fork.set_state(state, units=[DMODEL.name, MAPPING.name])


def test_whatif_from_an_fmi3_run_on_the_command_line(tmp_path):
    """`cotwin run --fmi 3` then `cotwin whatif --from` its state: the move is predicted from the end of the run."""
    project = EXAMPLES / "ur5e" / "cotwin.toml"
    run = subprocess.run([sys.executable, "-m", "cotwin", "run", project, "--fmi", "3", "-o", tmp_path / "out",
                          "--end", "3"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    plan = tmp_path / "p.csv"
    plan.write_text("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z\n"
                    "1000,true,2,20,1\n")
    proc = subprocess.run([sys.executable, "-m", "cotwin", "whatif", project, "--from", tmp_path / "out" / "state",
                           "--plan", plan], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "t = 4 s moveDiscreteCommand(MovementArgs_target_X=2, MovementArgs_target_Y=20, MovementArgs_target_Z=1): " \
           "feasible, accepted, done at" in proc.stdout, proc.stdout
    assert "forked at t = 3 s" in proc.stdout and "not of a FMU" not in proc.stderr


def test_a_command_at_the_forks_own_time_is_applied_and_alike_on_reused_forks(system, fmi3_run):
    """A command due at the fork's time (0 s into the what-if): the saved run had its event phase at that instant
    already, so the command is shown at the next communication point, as one due there (not lost to the fresh
    d-model instance its saved state replaced); a sweep's fork built with that plan or with another answers
    alike, and as `predict`."""
    out, state, _ = fmi3_run
    move = lambda at, x: [Command(at, (("moveDiscreteCommand", True), ("MovementArgs_target_X", x),  # noqa: E731
                                       ("MovementArgs_target_Y", 20), ("MovementArgs_target_Z", 1)), "test")]
    outcome = lambda p: [(c.delivered, c.accepted, c.feasible, c.done, c.verdict) for c in p.commands]  # noqa: E731
    at_once, next_point = (predict(system, move(at, 3), state, horizon=3.0, artefacts=out) for at in (0.0, 0.1))
    assert outcome(at_once) == outcome(next_point) and at_once.commands[0].verdict == "completed"
    plans = [move(0.0, 3), move(0.5, 0), move(0.0, 3)]
    alone = [summary(predict(system, plan, state, horizon=3.0, artefacts=out, decimate=10**9)) for plan in plans]
    for order in (plans, plans[1:]):  # the fork built with the plan at the fork's time, or with another
        with Forks(system, state, artefacts=out) as forks:
            answers = [summary(forks.predict(plan, horizon=3.0, decimate=10**9)) for plan in order]
        assert answers == alone[len(plans) - len(order):]
