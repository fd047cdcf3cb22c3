"""Honest outcomes (issue 19 item 5) and one naming of command arguments (item 8): `cotwin run`, `twin`
and `whatif` end with what became of every command, warn when none completed, and `--strict` makes that
exit status 3; arguments are named by their port everywhere, the field name accepted where old files use it."""

from __future__ import annotations

import csv
import json

import pytest

from conftest import cotwin_in_process
from cotwin.diagnostics import CotwinError, Finding, Location, Severity
from cotwin.twin.assembly.run import load
from cotwin.twin.services.whatif import predict
from test_reliability import project  # noqa: F401 - a copy of the UR5e example in tmp_path/ur5e

HEADER = "timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z\n"


def cotwin(*args, cwd=None):
    """`cotwin ARGS` through its entry point in this process: these tests are about what a run says and its
    exit code, not about the process (a subprocess spent most of each test importing)."""
    return cotwin_in_process(*args, cwd=cwd)


def test_a_run_whose_commands_were_all_infeasible_says_so_and_strict_fails(project, tmp_path):
    """Issue 19 item 5: four infeasible commands printed '201 rows to t = 20 s' and exit 0. Run from another
    working directory, with a plan that is not the example's."""
    (project / "plan.csv").write_text(HEADER + "1000,true,15,23,3\n3000,true,15,23,4\n")
    out = tmp_path / "out"
    proc = cotwin("run", "ur5e/cotwin.toml", "-o", out, "--end", "6", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "commands: 2, 2 infeasible" in proc.stdout
    assert "applied at t = 1.1 s moveDiscreteCommand(MovementArgs_target_X=15, MovementArgs_target_Y=23, " \
           "MovementArgs_target_Z=3): infeasible (nonfeasibleMoveDiscreteCommand)" in proc.stdout
    assert "warning: no command completed (2 applied)" in proc.stderr
    strict = cotwin("run", "ur5e/cotwin.toml", "-o", out, "--end", "6", "--strict", cwd=tmp_path)
    assert strict.returncode == 3 and "--strict: 2 command(s) or wait(s) did not end well" in strict.stderr


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_run_lists_each_command_completed_infeasible_or_not_taken(project, tmp_path, algorithm):
    (project / "plan.csv").write_text(HEADER + "1000,true,0,23,1\n1300,true,3,20,2\n5000,true,15,23,3\n"
                                               "9000,true,8,10,0\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "14", "--algorithm", algorithm)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    head = next(k for k, line in enumerate(lines) if line.startswith("commands:"))
    assert lines[head] == "commands: 4, 2 completed, 1 infeasible, 1 not taken"
    verdicts = [line.split("): ", 1)[1] for line in lines[head + 1:head + 5]]
    assert verdicts[0].startswith("completed at t = ") and verdicts[3].startswith("completed at t = ")
    assert verdicts[1].startswith("not taken (the d-model was in state ")  # busy with the first move
    assert verdicts[2] == "infeasible (nonfeasibleMoveDiscreteCommand)"
    assert proc.stderr.strip().splitlines()[-1] == "0 error(s), 0 warning(s)" and "warning:" not in proc.stderr
    assert cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "14", "--algorithm", algorithm,
                  "--strict").returncode == 3


def test_a_live_twin_sums_up_each_side(tmp_path):
    from conftest import EXAMPLES

    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.twin.live.runtime import LiveTwin

    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    pt = SimulatedEndpoint(PlatformSimulator(system.models.tree, system.models.scene))
    result = LiveTwin(system, tmp_path, pt=pt, end=4.0).run()
    for side in ("pt", "dt"):
        summary = result.sides[side].summary()
        assert summary.lines()[0] == "commands: 1, 1 completed" and not summary.warnings()
        assert summary.outcomes[0].args == {"MovementArgs_target_X": 0, "MovementArgs_target_Y": 23,
                                            "MovementArgs_target_Z": 1}


def test_whatif_sums_up_and_strict_fails_on_an_infeasible_command(tmp_path):
    from conftest import EXAMPLES

    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps([{"time": 0.5, "event": "moveDiscreteCommand",
                                 "args": {"MovementArgs_target_X": 15, "MovementArgs_target_Y": 23,
                                          "MovementArgs_target_Z": 3}}]))
    proc = cotwin("whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan", plan, "--strict")
    assert proc.returncode == 3, proc.stderr
    assert "NOT feasible" in proc.stdout and "commands: 1, 1 infeasible" in proc.stdout
    assert "warning: no command completed (1 applied)" in proc.stderr


def test_whatif_says_a_command_due_after_the_horizon_was_never_applied_not_ignored(tmp_path):
    """A what-if's commands due after its horizon were never offered to the d-model: `cotwin whatif` says so
    instead of "ignored by the d-model" (what it said of every command not taken)."""
    from conftest import EXAMPLES

    move = lambda t, x: {"time": t, "event": "moveDiscreteCommand",  # noqa: E731
                         "args": {"MovementArgs_target_X": x, "MovementArgs_target_Y": 20, "MovementArgs_target_Z": 0}}
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps([move(0.5, 3), move(9.0, 5)]))
    proc = cotwin("whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan", plan, "--horizon", "4")
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.startswith("t = ")]
    assert len(lines) == 2, proc.stdout
    assert ", accepted, done at t = " in lines[0]
    assert ", never applied (due after the prediction ended), not done within the horizon" in lines[1]
    assert "ignored" not in lines[1] and "commands: 2, 1 completed, 1 not applied" in proc.stdout


def test_a_command_read_while_an_earlier_one_moves_the_d_model_on_is_not_taken(tmp_path):
    """The d-model reads a gripper command in the cycle its move goes from Requested towards Moving: its state
    changes, but on no way that reads the gripper command, so the command was not taken (it was counted as
    taken, and the move's feasibility credited to it). Read in Idle (after an infeasible move), it is taken."""
    from conftest import EXAMPLES

    from cotwin.twin.assembly.scenario import read_plan

    system = load(EXAMPLES / "ur5e" / "cotwin.toml")
    head = "timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z,openGripperCommand\n"
    together = tmp_path / "together.csv"
    together.write_text(head + "500,true,3,20,2,true\n")
    move, gripper = predict(system, read_plan(together, system.models.program), horizon=6.0).commands
    assert (move.event, move.accepted, move.feasible, move.verdict) == ("moveDiscreteCommand", True, True, "completed")
    assert (gripper.event, gripper.accepted, gripper.verdict, gripper.busy) == \
        ("openGripperCommand", False, "not taken", "Requested")
    later = tmp_path / "later.csv"
    later.write_text(head + "500,true,15,23,3,false\n800,false,0,0,0,true\n")
    move, gripper = predict(system, read_plan(later, system.models.program), horizon=6.0).commands
    assert move.verdict == "infeasible" and gripper.accepted and gripper.verdict == "completed"


def test_whatif_whose_only_command_is_due_after_the_horizon_does_not_say_it_was_applied(tmp_path):
    """"commands: 1, 1 not applied" was followed by "warning: no command completed (1 applied)"."""
    from conftest import EXAMPLES

    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps([{"time": 9.0, "event": "moveDiscreteCommand", "args": {
        "MovementArgs_target_X": 5, "MovementArgs_target_Y": 20, "MovementArgs_target_Z": 0}}]))
    proc = cotwin("whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan", plan, "--horizon", "1")
    assert "commands: 1, 1 not applied" in proc.stdout
    assert "warning: no command completed (0 of 1 applied)" in proc.stderr, proc.stderr


def test_command_arguments_have_one_naming_and_old_files_keep_working(tmp_path):
    """The port name (MovementArgs_target_X: the RMQ FMU's wire, plan CSVs, the page) everywhere; TOML
    scenarios, what-if plans and the page also take the field name (target_X) older files use."""
    from conftest import EXAMPLES

    from cotwin.twin.assembly.scenario import read_toml
    from cotwin.twin.services.whatif import plan_from_json

    program = load(EXAMPLES / "ur5e" / "cotwin.toml").models.program
    canonical = {"MovementArgs_target_X": 3, "MovementArgs_target_Y": 20, "MovementArgs_target_Z": 2}
    old = {"target_X": 3, "target_Y": 20, "target_Z": 2}
    expected = (("moveDiscreteCommand", True), *canonical.items())
    scenario = tmp_path / "s.toml"
    for args in (canonical, old, {"target_X": 3, "MovementArgs_target_Y": 20, "target_Z": 2}):
        body = ", ".join(f"{k} = {v}" for k, v in args.items())
        scenario.write_text(f'[[command]]\ntime = 1.0\nevent = "moveDiscreteCommand"\nargs = {{ {body} }}\n')
        assert [c.values for c in read_toml(scenario, program)] == [expected]
        assert [c.values for c in plan_from_json([{"time": 1, "event": "moveDiscreteCommand", "args": args}],
                                                 program)] == [expected]
    scenario.write_text('[[command]]\ntime = 1.0\nevent = "moveDiscreteCommand"\n'
                        'args = { target_X = 3, MovementArgs_target_X = 4, target_Y = 1, target_Z = 0 }\n')
    with pytest.raises(CotwinError, match=r"s.toml:4:\d+: error: \[\[command\]\] 1: argument MovementArgs_target_X "
                                          r"of moveDiscreteCommand is given twice"):
        read_toml(scenario, program)
    # the page's panel: the same reader
    from cotwin.twin.services.dashboard.commands import PagePublisher
    from cotwin.twin.assembly.rabbitmq import port_scalars, port_types

    live = load(EXAMPLES / "ur5e" / "live.toml")
    [move] = [ev for ev in live.models.program.inputs if ev.name == "moveDiscreteCommand"]
    panel = PagePublisher(None, port_types(live.models.program, live.source_ports),
                          [{"name": move.name, "values": [{"port": p} for p, _ in move.value_ports]}],
                          scalars=port_scalars(live.models.program))
    for args in (canonical, old):
        message = panel.command("moveDiscreteCommand", args)
        assert {k: message[k] for k in canonical} == canonical and message["moveDiscreteCommand"] is True


def test_only_events_whose_name_says_a_move_stopped_stop_a_command():
    """The words of an event's name decide: a collision, fault, emergency or protective stop does; a name that
    says the opposite, or only contains those letters, does not (a match anywhere in the name turned
    `collisionFree` or `setDefault` into 'stopped' and failed --strict)."""
    from cotwin.twin.assembly.outcomes import stopping

    for name in ("collision", "robotCollision", "collisionDetected", "protectiveStop", "emergencyStop", "fault",
                 "fault_detected", "EMERGENCY"):
        assert stopping(name), name
    for name in ("noCollision", "collisionFree", "faultCleared", "resetFault", "setDefault", "defaultPose",
                 "moveCompleted", "robotStopped", "nonfeasibleMoveDiscreteCommand"):
        assert not stopping(name), name


def test_a_command_taken_in_a_step_of_several_d_model_cycles_is_taken(tmp_path):
    """With [cosim] parameters cycle_period shorter than the step (here five cycles a step) the d-model goes
    from Idle past Requested's exec in the step that reads the move: the move was called 'not taken' (CycleReads
    followed one cycle), though the arm moved and came back."""
    from conftest import EXAMPLES

    from cotwin.twin.assembly.scenario import read_plan

    system = load(EXAMPLES / "ur5e" / "cotwin.toml").with_parameters(cycle_period=0.02)
    plan = tmp_path / "plan.csv"
    plan.write_text(HEADER + "500,true,0,23,1\n")
    (move,) = predict(system, read_plan(plan, system.models.program), horizon=6.0).commands
    assert (move.accepted, move.verdict) == (True, "completed"), move.describe()


GRIPPER = HEADER.rstrip("\n") + ",closeGripperCommand,openGripperCommand\n"


def _verdicts(proc) -> list[str]:
    """The outcome lines of a run's summary, after 'commands:'."""
    lines = proc.stdout.splitlines()
    head = next(k for k, line in enumerate(lines) if line.startswith("commands:"))
    return [line.strip() for line in lines[head + 1:] if line.startswith("  applied")]


def test_a_command_done_in_the_cycle_that_takes_the_next_completed(project, tmp_path):
    """The gripper closed and the d-model went AwaitClosed -> Idle -> Requested in one cycle (0.4 s): the state
    port never showed Idle, and the close was called 'accepted, never completed'."""
    (project / "plan.csv").write_text(GRIPPER + "0,false,0,0,0,true,false\n200,true,7,7,0,false,false\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "3")
    assert proc.returncode == 0, proc.stderr
    verdicts = _verdicts(proc)
    assert verdicts[0] == "applied at t = 0.1 s closeGripperCommand(): completed at t = 0.4 s"
    assert verdicts[1].startswith("applied at t = 0.3 s moveDiscreteCommand(") and "completed at t = " in verdicts[1]


def test_a_command_applied_again_before_a_slow_clocks_tick_replaces_the_first(project, tmp_path):
    """A clock of 0.3 s, a step of 0.1 s: the tick at 0.6 s reads one moveDiscreteCommand, with the arguments of
    the last applied (0.5 s); both were called taken (the first 'completed', or 'accepted, never completed')."""
    (project / "plan.csv").write_text(GRIPPER + "400,true,4,16,0,false,false\n500,true,7,7,0,false,false\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "1", "--fmi", "3",
                  "--cycle-period", "0.3")
    assert proc.returncode == 0, proc.stderr
    verdicts = _verdicts(proc)
    assert verdicts[0].endswith("not taken (replaced by the one applied at t = 0.5 s before the d-model's cycle "
                                "read it)")
    assert "moveDiscreteCommand(MovementArgs_target_X=7" in verdicts[1] and "not taken" not in verdicts[1]


def test_a_command_a_slow_clocks_tick_read_with_one_of_higher_priority_is_not_taken(project, tmp_path):
    """The tick at 0.6 s reads a moveDiscreteCommand (0.4 s) and a closeGripperCommand (0.5 s): Idle leaves for
    the move (its guard `$closeGripperCommand /\\ not $moveDiscreteCommand`), yet the close was called taken, as
    Idle's exec guard, read in the cycle before, was counted among what the cycle Idle -> Requested read."""
    (project / "plan.csv").write_text(GRIPPER + "400,true,4,16,0,false,false\n500,false,0,0,0,true,false\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "1", "--fmi", "3",
                  "--cycle-period", "0.3")
    assert proc.returncode == 0, proc.stderr
    verdicts = _verdicts(proc)
    assert "not taken" not in verdicts[0]
    assert verdicts[1] == "applied at t = 0.5 s closeGripperCommand(): not taken (the d-model was in state Idle)"


def test_whatif_says_an_infeasible_command_is_never_done_not_that_the_horizon_was_short(tmp_path):
    """An infeasible move ended the prediction at about 1 s of a 30 s horizon, and `cotwin whatif` said 'not done
    within the horizon' and 'completion: not within the horizon', as if a longer horizon could do it."""
    from conftest import EXAMPLES

    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps([{"time": 0.5, "event": "moveDiscreteCommand", "args": {
        "MovementArgs_target_X": 15, "MovementArgs_target_Y": 23, "MovementArgs_target_Z": 3}}]))
    proc = cotwin("whatif", EXAMPLES / "ur5e" / "cotwin.toml", "--plan", plan, "--horizon", "30")
    assert proc.returncode == 0, proc.stderr
    line = next(line for line in proc.stdout.splitlines() if line.startswith("t = "))
    assert line.endswith("NOT feasible, accepted, never done"), line
    assert "completion: never (1 command(s) not taken, infeasible or stopped)" in proc.stdout


def test_a_plan_rows_cells_for_an_event_it_does_not_raise_leave_the_last_commands_arguments(project, tmp_path):
    """A clock of 0.3 s: the move applied at 0.4 s is read at the tick at 0.6 s; the open row at 0.5 s carried
    cells 5, 9, 2 for the move's arguments, which were set, so the d-model moved to (5, 9, 2) while the summary
    said the move to (3, 13, 2) completed."""
    (project / "plan.csv").write_text(GRIPPER + "400,true,3,13,2,false,false\n500,false,5,9,2,false,true\n")
    out = tmp_path / "out"
    proc = cotwin("run", project / "cotwin.toml", "-o", out, "--end", "1", "--fmi", "3", "--cycle-period", "0.3")
    assert proc.returncode == 0, proc.stderr
    with open(out / "outputs.csv") as f:
        calls = [(r["time"], *(r["{dmodel}.dmodel.target_" + a] for a in "XYZ")) for r in csv.DictReader(f)
                 if r["{dmodel}.dmodel.movediscrete"] == "true"]
    assert calls == [("0.6", "3", "13", "2")]


def test_a_move_that_never_completes_says_which_joint_is_at_its_effort_limit(project, tmp_path):
    """Found on TIAGo (example-robot-data): its arm_3_joint, limited to 17.86 N m, could not hold a posture the IK
    gave, and the run said only 'accepted, never completed'. It now names the joints pushing at their effort
    limit at the end. Here the UR5e's shoulder lift is given 0.05 N m, too weak to swing the arm (its weight
    compensated) to its goal in time."""
    _weaken_shoulder_lift(project)
    (project / "plan.csv").write_text(HEADER + "1000,true,0,23,1\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "8")
    assert proc.returncode == 0, proc.stderr
    assert "accepted, never completed" in proc.stdout
    assert ("warning: 1 command(s) never completed, and at the end these joints pushed at their effort limit: "
            "shoulder_lift_joint (0.05)") in proc.stderr


def test_a_whatif_that_never_completes_says_which_joint_is_at_its_effort_limit(project, tmp_path):
    _weaken_shoulder_lift(project)
    (tmp_path / "plan.csv").write_text(HEADER + "1000,true,0,23,1\n")
    proc = cotwin("whatif", project / "cotwin.toml", "--plan", tmp_path / "plan.csv", "--horizon", "8")
    assert proc.returncode == 0, proc.stderr
    assert ("warning: 1 command(s) never completed, and at the end these joints pushed at their effort limit: "
            "shoulder_lift_joint (0.05)") in proc.stderr


def _weaken_shoulder_lift(project) -> None:
    """The UR5e example's shoulder lift given 0.05 N m instead of 150."""
    pm = project / "ur5e.pm"
    text = pm.read_text()
    at = text.index("effort = 150", text.index("jref shoulder_lift_joint"))
    pm.write_text(text[:at] + "effort = 0.05" + text[at + len("effort = 150"):])


def test_a_completed_run_says_nothing_of_effort_limits(project, tmp_path):
    (project / "plan.csv").write_text(HEADER + "1000,true,0,23,1\n")
    proc = cotwin("run", project / "cotwin.toml", "-o", tmp_path / "out", "--end", "8")
    assert proc.returncode == 0 and "completed at t = " in proc.stdout and "effort limit" not in proc.stderr


def test_showing_outcomes_counts_their_warnings_and_only_the_strict_check_exits(capsys):
    """common.outcomes printed the outcomes, closed the run's count and exited under --strict, in one; each command
    kept its own `warned += show_warnings(...)` tally. Showing outcomes counts their warnings in the command's Tally
    and never exits; the --strict check exits, and only with --strict."""
    from cotwin.cli.common import Tally, show_outcomes, strict_exit
    from cotwin.twin.assembly.outcomes import STRICT_EXIT, CommandOutcome, Summary

    refused = CommandOutcome(1.0, "moveDiscreteCommand", {"X": 15}, delivered=1.1, accepted=True, feasible=False)
    summaries = {"PT": Summary([refused]), "DT": Summary([refused], blocked=["a wait"])}
    said = Tally()
    said.warn([Finding(Location("p.toml", 1, 1), Severity.WARNING, "before"),
               Finding(Location("p.toml", 2, 1), Severity.ERROR, "not a warning")])
    show_outcomes(summaries, said)
    strict_exit(summaries, strict=False)
    assert (said.errors, said.warnings) == (0, 4)  # 'before', PT's none completed, DT's blocked wait and none completed
    shown = capsys.readouterr()
    assert shown.out.splitlines()[:2] == ["PT: commands: 1, 1 infeasible", "PT:   applied at t = 1.1 s "
                                          "moveDiscreteCommand(X=15): infeasible"]
    assert shown.err.splitlines() == ["p.toml:1:1: warning: before", "PT: warning: no command completed (1 applied)",
                                      "DT: warning: blocked: a wait", "DT: warning: no command completed (1 applied)"]
    said.close()
    said.close()
    assert capsys.readouterr().err == "0 error(s), 4 warning(s)\n"  # said once
    with pytest.raises(SystemExit) as stop:
        strict_exit(summaries, strict=True)
    assert stop.value.code == STRICT_EXIT
    assert capsys.readouterr().err == "--strict: 3 command(s) or wait(s) did not end well; exit status 3\n"


def test_a_failed_commands_count_takes_each_error_at_a_place_and_a_failure_told_in_lines_as_one(capsys):
    """The closing count of a command that ended in an error: a run that failed midway says its cause and where its
    rows are (two lines, one error); a project's problems are each an error at its place."""
    from cotwin.cli.common import close_failed, closing_tally
    from cotwin.cosim.execution import ended_early

    closing_tally().warn([Finding(Location("p.toml", 1, 1), Severity.WARNING, "said before")])
    close_failed(ended_early(CotwinError("unit X failed a step"), 3.0, "the 30 row(s) computed are in o.csv").findings)
    problems = [Finding(Location("p.toml", line, 1), Severity.ERROR, "bad") for line in (2, 3, 4)]
    closing_tally()
    close_failed([*problems, Finding(Location("p.toml", 5, 1), Severity.WARNING, "odd")])
    close_failed(problems)  # no command keeping a count is running any more: nothing said
    assert capsys.readouterr().err.splitlines() == ["p.toml:1:1: warning: said before", "1 error(s), 1 warning(s)",
                                                    "3 error(s), 1 warning(s)"]
