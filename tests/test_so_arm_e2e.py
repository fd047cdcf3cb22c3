"""The SO-ARM100 (5 joints to its gripper link, a revolute jaw) as a new user brings it: imported from
example-robot-data's URDF, a small d-model of one's own (move the tool to a point, wait for the answer and
the move), a mapping from the paths `import-urdf` prints, the gripper link named as the tool, run through
the CLI: both moves complete, the gripper's tip at each point pointing down (the IK refused the arm, needing
6 joints)."""

from __future__ import annotations

import csv

import numpy as np

from conftest import cotwin_in_process
from test_ik_fewer_joints import SO_ARM
from test_urdf_import import robot_data

DMODEL = r"""// A small d-model of our own: on each goCommand, ask the arm to move its tool to a point (cm, robot frame),
// wait for the answer, then for the move to complete.

interface ReachOperations {
	moveto(cx: int, cy: int, cz: int)
}

interface Commands {
	event goCommand: Point
}

interface Feedback {
	event feasible
	event infeasible
	event moveCompleted
}

datatype Point {
	cx: int
	cy: int
	cz: int
}

stm Reach {
	cycleDef cycle == 1
	var p: Point
	input context {
		uses Commands
		uses Feedback
	}
	output context {
		requires ReachOperations
	}

	initial i0
	state Idle { }
	state Requested { entry $moveto(p.cx, p.cy, p.cz) }
	state Await { }
	junction JAnswer
	state Moving { }
	junction JMoving

	transition init { from i0 to Idle }
	transition idle { from Idle to Idle exec condition not $goCommand }
	transition go { from Idle to Requested condition $goCommand?p }
	transition requested { from Requested to JAnswer exec }
	transition await { from Await to JAnswer exec }
	transition yes { from JAnswer to Moving condition $feasible }
	transition no { from JAnswer to Idle condition $infeasible /\ not $feasible }
	transition undecided { from JAnswer to Await condition not ($feasible \/ $infeasible) }
	transition moving { from Moving to JMoving exec }
	transition arrived { from JMoving to Idle condition $moveCompleted }
	transition stillMoving { from JMoving to Moving condition not $moveCompleted }
}

controller ReachControl {
	cycleDef cycle == 1
	uses Commands
	uses Feedback
	requires ReachOperations
	sref stm_ref = Reach
	connection ReachControl on goCommand to stm_ref on goCommand (_async)
	connection ReachControl on feasible to stm_ref on feasible (_async)
	connection ReachControl on infeasible to stm_ref on infeasible (_async)
	connection ReachControl on moveCompleted to stm_ref on moveCompleted (_async)
}

module SoReach {
	cycleDef cycle == 1
	robotic platform SoArm {
		provides ReachOperations
		uses Commands
		uses Feedback
	}
	cref ctrl = ReachControl
	connection SoArm on goCommand to ctrl on goCommand (_async)
	connection SoArm on feasible to ctrl on feasible (_async)
	connection SoArm on infeasible to ctrl on infeasible (_async)
	connection SoArm on moveCompleted to ctrl on moveCompleted (_async)
}
"""

MAPPING = r"""// Reach on the SO-ARM100 imported from its URDF: moveto(cx, cy, cz) puts the gripper's tip at that point
// (cm, robot frame), the gripper's z pointing down (cell.toml), the 5 arm joints from inverse_kinematics;
// the jaw is held closed.
import physmod::math::*

enumeration Answer {
	none
	yes
	no
}

enumeration Motion {
	idle
	moving
}

map SoReachMapping dmodel SoReach to pmodel so_arm100 {
	const POSITION_TOLERANCE: real = 0.01
	var target_q: vector(real, 5) = [| 0.0, 1.57, -1.57, 0.0, 0.0 |]
	var answer: Answer = Answer::none
	var motion: Motion = Motion::idle
	var q0: real, q1: real, q2: real, q3: real, q4: real

	operation moveto {
		var x: real = cx * 0.01
		var y: real = cy * 0.01
		var z: real = cz * 0.01
		var ok: boolean = reachable(x, y, z)
		action target_q = if ok then inverse_kinematics(x, y, z) else target_q end
		action answer = if ok then Answer::yes else Answer::no end
		action motion = if ok then Motion::moving else motion end
		equation so_arm100::base::shoulder_pan::shoulder_pan_motor.dangle == target_q[0]
		equation so_arm100::shoulder::shoulder_lift::shoulder_lift_motor.dangle == target_q[1]
		equation so_arm100::upper_arm::elbow_flex::elbow_flex_motor.dangle == target_q[2]
		equation so_arm100::lower_arm::wrist_flex::wrist_flex_motor.dangle == target_q[3]
		equation so_arm100::wrist::wrist_roll::wrist_roll_motor.dangle == target_q[4]
		equation so_arm100::gripper::gripper::gripper_motor.dangle == 0.0
	}

	input event feasible {
		equation answer == Answer::yes
	}

	input event infeasible {
		equation answer == Answer::no
	}

	input event moveCompleted {
		equation motion == Motion::moving
		equation abs(so_arm100::base::shoulder_pan::shoulder_pan_position.output_position - target_q[0]) < POSITION_TOLERANCE
		equation abs(so_arm100::shoulder::shoulder_lift::shoulder_lift_position.output_position - target_q[1]) < POSITION_TOLERANCE
		equation abs(so_arm100::upper_arm::elbow_flex::elbow_flex_position.output_position - target_q[2]) < POSITION_TOLERANCE
		equation abs(so_arm100::lower_arm::wrist_flex::wrist_flex_position.output_position - target_q[3]) < POSITION_TOLERANCE
		equation abs(so_arm100::wrist::wrist_roll::wrist_roll_position.output_position - target_q[4]) < POSITION_TOLERANCE
	}

	input event goCommand {
		predicate false
	}
}

function inverse_kinematics(x: real, y: real, z: real): vector(real, 5) { }
function reachable(x: real, y: real, z: real): boolean { }
"""

CELL = r"""[tool]
link = "gripper"          # the link before the revolute jaw
point = [0.0, -0.1, 0.0]  # 10 cm out along its roll axis
"""

PLAN = r"""timestep,goCommand,Point_cx,Point_cy,Point_cz
1000,true,-10,-30,10
6000,true,10,-30,10
"""

PROJECT = r"""[models]
dmodel = "reach.rst"
pmodel = "so_arm100.pm"
mapping = "mapping.pm"

[scenario]
plan = "plan.csv"

[platform]
scene = "none"
calibration = "cell.toml"

[monitor]
joints = "arm"

[cosim]
step = 0.1
end = 11.0
"""



def test_a_new_user_moves_the_so_arm_to_two_points(tmp_path, caplog):
    from cotwin.pmodel import ik
    from cotwin.pmodel.tree import build_tree
    from cotwin.robosim.check import load_checked

    urdf = robot_data() / SO_ARM
    if not urdf.is_file():
        import pytest

        pytest.skip(f"example-robot-data has no SO-ARM100 at {urdf} (an older release)")
    cell = tmp_path / "socell"
    imported = cotwin_in_process("import-urdf", urdf, "-o", cell)
    assert imported.returncode == 0, imported.stderr
    for name, text in (("reach.rst", DMODEL), ("mapping.pm", MAPPING), ("cell.toml", CELL), ("plan.csv", PLAN),
                       ("cotwin.toml", PROJECT)):
        (cell / name).write_text(text)
    run = cotwin_in_process("run", cell / "cotwin.toml", "-o", cell / "out", cwd=tmp_path,
                            env={"COTWIN_CACHE": str(tmp_path / "cache")})
    assert run.returncode == 0, run.stdout + run.stderr
    assert "commands: 2, 2 completed" in run.stdout, run.stdout
    told = [r.getMessage() for r in caplog.records if r.name == "cotwin.ik"]  # a warning, once
    assert len(told) == 1 and "has 5 moving joints" in told[0] and "approach axis" in told[0], told
    # where the simulated arm stood after each move: the tip at the point, its z down
    tree = build_tree(load_checked([cell / "so_arm100.pm"]))
    chain = ik.Chain(tree, ik.find_tool(tree, (0.0, -0.1, 0.0), "gripper"))
    rows = list(csv.DictReader(open(cell / "out" / "outputs.csv")))
    joints = [f"{{mapping}}.mapping.q{k}" for k in range(5)]
    for t, point in ((5.0, (-0.1, -0.3, 0.1)), (11.0, (0.1, -0.3, 0.1))):
        row = min(rows, key=lambda r: abs(float(next(iter(r.values()))) - t))
        T = chain.pose(np.array([float(row[j]) for j in joints]))
        assert np.linalg.norm(T[:3, 3] - point) < 0.01 and T[2, 2] < -0.999, (t, T)
