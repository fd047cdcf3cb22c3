"""A robot of two arms as a new user brings it: Baxter of example-robot-data (two 7-joint arms, each with a
gripper of two prismatic fingers) imported by `cotwin import-urdf`, a reaching d-model of one's own and a mapping
driving its right arm. The IK's default tool is one of the two grippers: a mapping driving the other arm used to
run with the IK's values for the wrong arm, every move 'completing' with the tool elsewhere."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import cotwin_in_process
from cotwin.diagnostics import CotwinError
from test_urdf_import import robot_data

DMODEL = """
interface Ops {
	reach(px: real, py: real, pz: real)
	halt()
}
interface Cmds {
	event goCommand: Point
}
interface Fb {
	event accepted
	event refused
	event arrived
	event settled
}
datatype Point {
	px: real
	py: real
	pz: real
}
stm Reacher {
	cycleDef cycle == 1
	var goal: Point
	input context {
		uses Cmds
		uses Fb
	}
	output context { requires Ops }
	initial i0
	state Idle { }
	state Asking { entry $reach(goal.px, goal.py, goal.pz) }
	state Going { }
	state Halting { entry $halt() }
	transition init { from i0 to Idle }
	transition idle { from Idle to Idle exec condition not $goCommand }
	transition go { from Idle to Asking condition $goCommand?goal }
	transition wait { from Asking to Asking exec condition not ($accepted \\/ $refused) }
	transition no { from Asking to Idle exec condition $refused }
	transition yes { from Asking to Going exec condition $accepted /\\ not $refused }
	transition going { from Going to Going exec condition not $arrived }
	transition there { from Going to Halting exec condition $arrived }
	transition halting { from Halting to Halting exec condition not $settled }
	transition halted { from Halting to Idle exec condition $settled }
}
controller Ctl {
	cycleDef cycle == 1
	uses Cmds
	uses Fb
	requires Ops
	sref s = Reacher
	connection Ctl on goCommand to s on goCommand (_async)
	connection Ctl on accepted to s on accepted (_async)
	connection Ctl on refused to s on refused (_async)
	connection Ctl on arrived to s on arrived (_async)
	connection Ctl on settled to s on settled (_async)
}
module ReachCell {
	cycleDef cycle == 1
	robotic platform Arm {
		provides Ops
		uses Cmds
		uses Fb
	}
	cref c = Ctl
	connection Arm on goCommand to c on goCommand (_async)
	connection Arm on accepted to c on accepted (_async)
	connection Arm on refused to c on refused (_async)
	connection Arm on arrived to c on arrived (_async)
	connection Arm on settled to c on settled (_async)
}
"""

RIGHT = [("right_arm_mount", "right_s0"), ("right_upper_shoulder", "right_s1"), ("right_lower_shoulder", "right_e0"),
         ("right_upper_elbow", "right_e1"), ("right_lower_elbow", "right_w0"), ("right_upper_forearm", "right_w1"),
         ("right_lower_forearm", "right_w2")]
READY = "0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0"


def mapping(reached: int = 7) -> str:
    """The reaching mapping on Baxter's right arm, from the paths `import-urdf` prints; `reached`: how many of the
    arm's joints `reach` commands (fewer: the new user's slip of a joint left out)."""
    def path(i: int, port: str) -> str:
        link, joint = RIGHT[i]
        return f"baxter::{link}::{joint}::{joint}_{port}"

    command = "\n".join(f"\t\tequation {path(i, 'motor.dangle')} == target_q[{i}]" for i in range(reached))
    hold = "\n".join(f"\t\tequation {path(i, 'motor.dangle')} == {path(i, 'position.output_position')}"
                     for i in range(7))
    there = "\n".join(f"\t\tequation abs({path(i, 'position.output_position')} - target_q[{i}]) < 0.003"
                      for i in range(7))
    still = "\n".join(f"\t\tequation abs({path(i, 'velocity.output_vel')}) < 0.02" for i in range(7))
    return f"""import physmod::math::*
enumeration Answer {{
	none
	yes
	no
}}
map BaxterReach dmodel ReachCell to pmodel baxter {{
	var target_q: vector(real, 7) = [| {READY} |]
	var answer: Answer = Answer::none
	var q0: real, q1: real, q2: real, q3: real, q4: real, q5: real, q6: real
	operation reach {{
		var ok: boolean = reachable(px, py, pz)
		action target_q = if ok then inverse_kinematics(px, py, pz) else target_q end
		action answer = if ok then Answer::yes else Answer::no end
{command}
	}}
	operation halt {{
		action answer = Answer::none
{hold}
	}}
	input event accepted {{
		equation answer == Answer::yes
	}}
	input event refused {{
		equation answer == Answer::no
	}}
	input event arrived {{
		equation answer == Answer::yes
{there}
	}}
	input event settled {{
{still}
	}}
	input event goCommand {{
		predicate false
	}}
}}
function inverse_kinematics(x: real, y: real, z: real): vector(real, 7) {{ }}
function reachable(x: real, y: real, z: real): boolean {{ }}
"""


PLAN = "timestep,goCommand,Point_px,Point_py,Point_pz\n500,true,0.7,-0.4,0.1\n"


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> tuple[Path, str]:
    """Baxter imported once into a folder of its own, and what the import printed."""
    urdf = robot_data() / "robots/baxter_description/urdf/baxter.urdf"
    if not urdf.is_file():
        pytest.skip(f"example-robot-data has no {urdf}")
    folder = tmp_path_factory.mktemp("baxter")
    done = cotwin_in_process("import-urdf", urdf, "-o", folder)
    assert done.returncode == 0, done.stderr
    return folder, done.stdout


def baxter_project(imported: tuple[Path, str], folder: Path, tool_link: str | None = None, plan: str = PLAN,
                   end: float = 4.0) -> Path:
    """The reaching project on the imported Baxter in `folder`; `tool_link`: the cell geometry's [tool] link."""
    source, _ = imported
    for name in ("baxter.pm", "meshes"):
        (folder / name).symlink_to(source / name)
    (folder / "reach.rst").write_text(DMODEL)
    (folder / "mapping.pm").write_text(mapping())
    (folder / "plan.csv").write_text(plan)
    platform = ""
    if tool_link is not None:
        (folder / "cell.toml").write_text(f'[tool]\nlink = "{tool_link}"\n[ik]\nreference = [{READY}]\n')
        platform = '[platform]\ncalibration = "cell.toml"\n'
    project = folder / "cotwin.toml"
    project.write_text('[models]\ndmodel = "reach.rst"\npmodel = "baxter.pm"\nmapping = "mapping.pm"\n'
                       f'[scenario]\nplan = "plan.csv"\n{platform}[cosim]\nstep = 0.1\nend = {end}\n')
    return project


def first_command_line() -> int:
    return next(k for k, text in enumerate(mapping().splitlines(), 1) if "motor.dangle == target_q[0]" in text)


def test_the_import_says_the_ik_took_one_of_two_grippers_and_names_the_other(imported):
    # it used to name the left gripper as the tool with no word of the right one
    _, said = imported
    line = next(text for text in said.splitlines() if text.startswith("inverse_kinematics:"))
    assert "tool link left_gripper (the grasp frame the URDF declares on left_gripper_base_link" in line
    assert "one of 2 grippers (also right_gripper_base_link)" in line and "[tool] link" in line


def test_a_mapping_driving_the_arm_the_ik_does_not_solve_for_is_a_located_error(imported, tmp_path):
    # the mapping commands the right arm; the IK's default tool is the left gripper: `check` said ok and the run
    # moved the right arm to the left arm's solutions (a target right of the robot 'refused', others 'completed')
    project = baxter_project(imported, tmp_path)
    check = cotwin_in_process("check", project)
    said = check.stdout + check.stderr
    assert check.returncode != 0, said
    assert f"mapping.pm:{first_command_line()}:" in said and "error:" in said
    assert "right_s0" in said and "tool link left_gripper " in said and "left_s0" in said
    assert "[tool] link" in said and "e.g. right_gripper_base_link (the gripper right_w2 moves)" in said
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode != 0 and "completed" not in run.stdout
    assert f"mapping.pm:{first_command_line()}:" in run.stderr


def test_the_runtime_refuses_the_other_arm_when_the_models_were_not_checked_as_a_twin(imported, tmp_path):
    # the last line of defence: a Mapping made from the models alone sets its kinematics up with the mapping
    from cotwin.mapping.endpoint import SimulatedEndpoint
    from cotwin.mapping.runtime import Mapping
    from cotwin.pmodel.simulator import PlatformSimulator
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    baxter_project(imported, tmp_path)
    project = load_checked([tmp_path / "reach.rst", tmp_path / "baxter.pm", tmp_path / "mapping.pm"])
    with pytest.raises(CotwinError) as err:
        Mapping(project, SimulatedEndpoint(PlatformSimulator(build_tree(project, "baxter"))))
    assert f"mapping.pm:{first_command_line()}:" in str(err.value) and "tool link left_gripper " in str(err.value)


def test_naming_the_right_gripper_as_the_tool_checks_and_the_right_arm_reaches(imported, tmp_path):
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link")
    check = cotwin_in_process("check", project)
    assert check.returncode == 0, check.stdout + check.stderr
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    assert "commands: 1, 1 completed" in run.stdout, run.stdout


def test_a_cell_of_robots_running_a_dmodel_of_ones_own_says_which_moves_completed(imported, tmp_path):
    # two Baxters in one cell, each reaching with its right arm: the cell's outcomes counted the paper's
    # `moveCompleted` events and its `collision`, so a d-model of other names had '0 move(s) completed' for moves
    # that completed; now each robot's commands are judged as a single robot's (taken, done, back at rest)
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link")
    project.write_text('[models]\ndmodel = "reach.rst"\n'
                       '[[robots]]\nname = "a"\npmodel = "baxter.pm"\nmapping = "mapping.pm"\n'
                       'calibration = "cell.toml"\n'
                       '[[robots]]\nname = "b"\npmodel = "baxter.pm"\nmapping = "mapping.pm"\n'
                       'calibration = "cell.toml"\n'
                       'xyz = [0.0, 3.0, 0.0]\n'
                       '[scenario]\nplan = "cell.csv"\n[cosim]\nstep = 0.1\nend = 4.0\n')
    (tmp_path / "cell.csv").write_text("timestep,a.goCommand,a.Point_px,a.Point_py,a.Point_pz,"
                                       "b.goCommand,b.Point_px,b.Point_py,b.Point_pz\n"
                                       "500,true,0.7,-0.4,0.1,true,0.7,2.6,0.1\n")
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    assert "a: 1 command(s) applied, 1 move(s) completed, no collision" in run.stdout, run.stdout
    assert "b: 1 command(s) applied, 1 move(s) completed, no collision" in run.stdout, run.stdout


def test_outcomes_names_a_dmodels_own_answers_so_a_refused_command_is_not_completed(imported, tmp_path):
    # the reaching d-model answers `refused` for a target out of reach: the outcomes knew only the paper's names
    # (nonfeasible*, infeasible*, unreachable*), so the refused command, back at rest, was 'completed'
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link",
                             plan="timestep,goCommand,Point_px,Point_py,Point_pz\n500,true,3.0,0.0,0.0\n", end=2.0)
    project.write_text(project.read_text() + '[outcomes]\ninfeasible = ["refused"]\nfeasible = ["accepted"]\n')
    run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert "commands: 1, 1 infeasible" in run.stdout, run.stdout + run.stderr
    assert "infeasible (refused)" in run.stdout and "completed at" not in run.stdout
    whatif = cotwin_in_process("whatif", project, "--plan", tmp_path / "plan.csv")
    assert "NOT feasible" in whatif.stdout and "1 infeasible" in whatif.stdout, whatif.stdout + whatif.stderr


def test_an_outcomes_name_that_is_no_event_of_the_dmodel_is_an_error_at_its_key(imported, tmp_path):
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link")
    text = project.read_text() + '[outcomes]\ninfeasible = ["refuse"]\n'
    project.write_text(text)
    check = cotwin_in_process("check", project)
    said = check.stdout + check.stderr
    assert check.returncode != 0
    line = text.splitlines().index('infeasible = ["refuse"]') + 1
    assert f"cotwin.toml:{line}:" in said and "did you mean 'refused'" in said, said


def test_holding_a_joint_that_stands_at_its_limit_is_no_goal_beyond_it(imported, tmp_path, caplog):
    # the IK puts right_w2 at its lower limit for this target; `halt` commands every joint to its reading, which
    # the simulated joint at its limit exceeds by a hair: a warning said halt commanded it beyond its limits
    import csv
    import logging

    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link",
                             plan="timestep,goCommand,Point_px,Point_py,Point_pz\n0,true,0.8,-0.3,0.1\n", end=3.0)
    with caplog.at_level(logging.WARNING, logger="cotwin.twin"):
        run = cotwin_in_process("run", project, "-o", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    assert "commands: 1, 1 completed" in run.stdout, run.stdout
    rows = list(csv.DictReader((tmp_path / "out" / "outputs.csv").open()))
    assert abs(float(rows[-1]["{mapping}.mapping.q6"]) - -3.059) < 1e-3  # the premise: right_w2 at its limit
    said = [r.getMessage() for r in caplog.records] + [run.stderr]
    assert not [m for m in said if "beyond its limits" in m], said


def test_cotwin_test_counts_as_collisions_the_events_the_project_says_stop_a_move(imported, tmp_path):
    # a suite's platform report counted events with 'collision' in their names: a d-model of one's own whose stop
    # is named otherwise had 'collisions 0' whatever happened; [outcomes] stops names them (here, for the test's
    # sake, `settled`, which every case's halt brings)
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link")
    project.write_text(project.read_text() + '[outcomes]\nstops = ["settled"]\n')
    made = cotwin_in_process("testgen", tmp_path / "reach.rst", tmp_path / "baxter.pm", tmp_path / "mapping.pm",
                             "--project", project, "--answers", "auto", "-o", tmp_path / "suite")
    assert made.returncode == 0, made.stderr
    ran = cotwin_in_process("test", project, tmp_path / "suite")
    reports = [line for line in ran.stdout.splitlines() if "platform:" in line]
    assert reports and all("settled x" in line for line in reports), ran.stdout + ran.stderr
    assert all("collisions 0" not in line for line in reports), ran.stdout


def test_an_operation_solving_the_ik_but_leaving_an_arm_joint_uncommanded_is_warned_at_its_first_command(
        imported, tmp_path):
    # `reach` commands right_s0..right_w1 with the IK's values and leaves right_w2 where it is: check said ok
    project = baxter_project(imported, tmp_path, tool_link="right_gripper_base_link")
    (tmp_path / "mapping.pm").write_text(mapping(reached=6))
    check = cotwin_in_process("check", project)
    said = check.stdout + check.stderr
    assert check.returncode == 0, said
    assert f"mapping.pm:{first_command_line()}:" in said and "warning: operation reach" in said, said
    assert "does not command right_w2" in said
    (tmp_path / "mapping.pm").write_text(mapping())  # every joint commanded: nothing said
    again = cotwin_in_process("check", project)
    assert again.returncode == 0 and "does not command" not in again.stdout + again.stderr


def test_a_whatifs_contact_check_spares_the_fingers_of_the_projects_tool_not_the_default_ones(imported, tmp_path):
    """With [tool] link naming the right gripper, a what-if's contacts of the robot with the scene left out the
    fingers of the IK's default tool (the left gripper's) and counted the right gripper's touching what it grips."""
    from cotwin.twin.assembly.run import load
    from cotwin.twin.services.whatif import Forks

    twin = load(baxter_project(imported, tmp_path, tool_link="right_gripper_base_link"))
    assert twin.models.tool.link == "right_gripper_base_link"
    with Forks(twin, artefacts=tmp_path / "forks") as forks:
        forks.predict(twin.commands[:1], horizon=0.3)
        (contacts,) = forks._contacts.values()
        model = contacts.sim.model
        checked = {model.body(model.geom_bodyid[g]).name for g in contacts.robot}
    fingers = {j.child for j in twin.models.tree.joints if j.name in twin.models.tool.fingers}
    assert fingers and all(f.startswith("r_gripper") for f in fingers) and not fingers & checked
    left = {j.child for j in twin.models.tree.joints if j.kind == "prismatic" and j.child.startswith("l_gripper")}
    assert left and left <= checked  # the other gripper is robot like the rest
