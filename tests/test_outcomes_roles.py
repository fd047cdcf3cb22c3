"""[outcomes]: which events say a command was infeasible, feasible or stopped. An event named in two roles is an error
at its key (it was judged infeasible in silence); one named for a role is no other role's by its name; an empty list
gives a role no event; an output event is refused saying what to do; a cell says a problem of it once."""
import shutil
from pathlib import Path

from click.testing import CliRunner

from cotwin.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ur5e"


def test_an_event_in_two_outcome_roles_is_an_error_at_the_later_key(tmp_path):
    project = _ur5e(tmp_path, '[outcomes]\ninfeasible = ["moveCompleted"]\nfeasible = ["moveCompleted"]\n')
    result, line = _check(project, 'feasible = ["moveCompleted"]')
    assert result.exit_code != 0, result.output
    assert f"cotwin.toml:{line}:" in result.output, result.output
    assert "moveCompleted is already named in [outcomes] infeasible" in result.output, result.output


EXAMPLES = EXAMPLE.parent
BAD_PLAN = ("timestep,moveDiscreteCommand,MovementArgs_target_X,MovementArgs_target_Y,MovementArgs_target_Z\n"
            "1000,true,0,23,1\n5500,true,99,99,9\n")  # the second out of the mapping's reach: nonfeasible...


def _check(project: Path, key: str):
    """`cotwin check` of the project, and the line of its file that reads `key` (where an error must be said)."""
    return CliRunner().invoke(main, ["check", str(project)]), project.read_text().splitlines().index(key) + 1


def _ur5e(tmp_path, outcomes: str) -> Path:
    """A copy of examples/ur5e whose project ends with `outcomes` (its [outcomes] table)."""
    shutil.copytree(EXAMPLE, tmp_path / "ur5e")
    project = tmp_path / "ur5e" / "cotwin.toml"
    project.write_text(project.read_text() + "\n" + outcomes)
    return project


def test_an_event_named_for_one_role_is_never_another_roles_by_its_name(tmp_path):
    # `feasible = ["nonfeasibleMoveDiscreteCommand"]` left the infeasible default on, which matched the name: the
    # command the project says was answered feasible was judged infeasible anyway
    from cotwin.twin.assembly.outcomes import EventRoles
    from cotwin.twin.project import load_project

    project = _ur5e(tmp_path, '[outcomes]\nfeasible = ["nonfeasibleMoveDiscreteCommand"]\n')
    roles = EventRoles.of(load_project(project))
    assert roles.feasible("nonfeasibleMoveDiscreteCommand") and not roles.infeasible("nonfeasibleMoveDiscreteCommand")
    assert roles.infeasible("unreachableTarget") and roles.stops("collision")  # names no list gives: by their names
    named = EventRoles(infeasible_events=frozenset({"collisionAhead"}))
    assert named.infeasible("collisionAhead") and not named.stops("collisionAhead")  # a stop by its name, but named
    (tmp_path / "ur5e" / "bad.csv").write_text(BAD_PLAN)
    project.write_text(project.read_text().replace("plan.csv", "bad.csv").replace("end = 20.0", "end = 8.0"))
    result = CliRunner().invoke(main, ["run", str(project), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "commands: 2, 2 completed" in result.output and "infeasible (" not in result.output, result.output


def test_an_empty_list_gives_a_role_no_event(tmp_path):
    # `stops = []`: no event stops a move, not even one named collision (the defaults are for a key left out);
    # docs/project.md says so, from the schema
    from cotwin.twin.assembly.outcomes import EventRoles
    from cotwin.twin.project import load_project

    roles = EventRoles.of(load_project(_ur5e(tmp_path, "[outcomes]\nstops = []\ninfeasible = []\n")))
    assert not roles.stops("collision") and not roles.infeasible("nonfeasibleMoveDiscreteCommand")
    assert roles.feasible("feasibleMoveDiscreteCommand")  # the key left out: by its name
    doc = (EXAMPLES.parent / "docs" / "project.md").read_text()
    assert "an empty list: no event has that role" in doc


def _with_output_event(arm: str) -> str:
    """examples/ur5e's d-model sending the platform an output event armIdle when back at rest from a move."""
    edits = [("interface Feedback {", "interface Status {\n\tevent armIdle\n}\n\ninterface Feedback {"),
             ("\toutput context {\n\t\trequires ArmOperations", "\toutput context {\n\t\tuses Status\n\t\trequires ArmOperations"),
             ("condition $robotStopped }", "condition $robotStopped action $armIdle }"),
             ("\tuses Feedback\n\trequires ArmOperations", "\tuses Feedback\n\tuses Status\n\trequires ArmOperations"),
             ("to stm_ref on collision (_async)\n}", "to stm_ref on collision (_async)\n"
                                                     "\tconnection stm_ref on armIdle to ArmControl on armIdle (_async)\n}"),
             ("\t\tuses Feedback\n\t}\n\tcref ctrl", "\t\tuses Feedback\n\t\tuses Status\n\t}\n\tcref ctrl"),
             ("to ctrl on collision (_async)\n}", "to ctrl on collision (_async)\n"
                                                 "\tconnection ctrl on armIdle to UR5eWithGripper on armIdle (_async)\n}")]
    for old, new in edits:
        assert arm.count(old) == 1, old
        arm = arm.replace(old, new)
    return arm


def test_an_output_event_in_outcomes_says_what_to_do_at_its_key(tmp_path):
    # it said only "armIdle is not an input event", as for a misspelt name
    project = _ur5e(tmp_path, '[outcomes]\nstops = ["armIdle"]\n')
    arm = tmp_path / "ur5e" / "arm.rst"
    arm.write_text(_with_output_event(arm.read_text()))
    result, line = _check(project, 'stops = ["armIdle"]')
    assert result.exit_code != 0, result.output
    said = [s for s in result.output.splitlines() if "armIdle" in s]
    assert len(said) == 1 and f"cotwin.toml:{line}:" in said[0], result.output
    assert "[outcomes] stops: armIdle is an output event of d-model module FlexCellArm" in said[0], said
    assert "remove it from [outcomes] stops or name an input event" in said[0], said
    assert "(its input events: moveDiscreteCommand, " in said[0] and "collision)" in said[0], said


def test_a_cells_outcomes_problem_is_said_once_at_its_key(tmp_path):
    # each robot's models are checked alone, against the shared d-model: the same [outcomes] error came once per
    # robot, each said of its robot ("robot panda (...): [outcomes] stops: ...")
    shutil.copytree(EXAMPLE, tmp_path / "ur5e")
    shutil.copytree(EXAMPLES / "flexcell2", tmp_path / "flexcell2")
    project = tmp_path / "flexcell2" / "cotwin.toml"
    project.write_text(project.read_text() + '\n[outcomes]\nstops = ["colision"]\n')
    result, line = _check(project, 'stops = ["colision"]')
    assert result.exit_code != 0, result.output
    said = [s for s in result.output.splitlines() if "colision" in s]
    assert len(said) == 1, result.output
    assert f"cotwin.toml:{line}:1: error: [outcomes] stops: colision is not an input event" in said[0], said
    assert "did you mean 'collision'" in said[0], said
