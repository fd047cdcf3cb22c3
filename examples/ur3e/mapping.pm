// cotwin example: the paper's FlexCellArm d-model on the UR3e of the paper's published p-model
// (ur3e_gripper, read unchanged from ../shared/robosim/ur3e, or examples/ur3e/ur3e.pm where that is
// absent). The UR3e reaches about 0.5 m: its plate is a small one (8 x 8 holes at 40 mm) placed in
// front of the base, its grid written here as the Flex-cell scene reads it (HOLE_DIST, X_MAX, Y_MAX,
// Z_TABLE, XMAX, YMAX). The published UR3e carries no gripper: pick and place only record the
// request, and the gripper events follow at once.
import physmod::math::*

enumeration Feasibility {
	none
	feasible
	infeasible
}

enumeration Motion {
	idle
	moving
	completed
}

map UR3eMapping dmodel FlexCellArm to pmodel ur3e_gripper {
	// a plate of 8 x 8 holes at 40 mm: x from 0.14 to 0.42 m, y from -0.14 to 0.14 m in the base frame
	const HOLE_DIST: real = 0.04
	const X_MAX: real = 0.46
	const Y_MAX: real = 0.14
	const Z_TABLE: real = 0.040  // targets 40 mm above the plate: at 20 mm the wrist met the plate on the corner holes
	const XMAX: int = 7
	const YMAX: int = 7
	const ZMAX: int = 4
	const POSITION_TOLERANCE: real = 0.002
	const VELOCITY_TOLERANCE: real = 0.02
	const COLLISION_TORQUE: real = 60.0

	var target_q: vector(real, 6) = [| 0.0, 0.0, 0.0, 0.0, 0.0, 0.0 |]
	var feasibility: Feasibility = Feasibility::none
	var motion: Motion = Motion::idle
	var gripper_closing: boolean = false
	var gripper_opening: boolean = false
	var q0: real, q1: real, q2: real, q3: real, q4: real, q5: real
	var qd0: real, qd1: real, qd2: real, qd3: real, qd4: real, qd5: real

	operation movediscrete {
		var x: real = X_MAX - (target_Y + 1) * HOLE_DIST
		var y: real = Y_MAX - target_X * HOLE_DIST
		var z: real = Z_TABLE + target_Z * HOLE_DIST
		var in_grid: boolean = 0 <= target_X /\ target_X <= XMAX /\ 0 <= target_Y /\ target_Y <= YMAX
			/\ 0 <= target_Z /\ target_Z <= ZMAX
		var ok: boolean = in_grid /\ reachable(x, y, z)
		action target_q = if ok then inverse_kinematics(x, y, z) else target_q end
		action feasibility = if ok then Feasibility::feasible else Feasibility::infeasible end
		action motion = if ok then Motion::moving else motion end
		equation ur3e_gripper::base_link::shoulder_pan_joint::M1.dangle == target_q[0]
		equation ur3e_gripper::shoulder_link::shoulder_lift_joint::M2.dangle == target_q[1]
		equation ur3e_gripper::upper_arm_link::elbow_joint::M3.dangle == target_q[2]
		equation ur3e_gripper::forearm_link::wrist_1_joint::M4.dangle == target_q[3]
		equation ur3e_gripper::wrist_1_link::wrist_2_joint::M5.dangle == target_q[4]
		equation ur3e_gripper::wrist_2_link::wrist_3_joint::M6.dangle == target_q[5]
	}

	operation movejoint {
		action target_q = [| target_q0, target_q1, target_q2, target_q3, target_q4, target_q5 |]
		action motion = Motion::moving
		equation ur3e_gripper::base_link::shoulder_pan_joint::M1.dangle == target_q[0]
		equation ur3e_gripper::shoulder_link::shoulder_lift_joint::M2.dangle == target_q[1]
		equation ur3e_gripper::upper_arm_link::elbow_joint::M3.dangle == target_q[2]
		equation ur3e_gripper::forearm_link::wrist_1_joint::M4.dangle == target_q[3]
		equation ur3e_gripper::wrist_1_link::wrist_2_joint::M5.dangle == target_q[4]
		equation ur3e_gripper::wrist_2_link::wrist_3_joint::M6.dangle == target_q[5]
	}

	operation stop {
		action motion = Motion::idle
		equation ur3e_gripper::base_link::shoulder_pan_joint::M1.dangle == ur3e_gripper::base_link::APSJ1.output_angle
		equation ur3e_gripper::shoulder_link::shoulder_lift_joint::M2.dangle == ur3e_gripper::shoulder_link::APSJ2.output_angle
		equation ur3e_gripper::upper_arm_link::elbow_joint::M3.dangle == ur3e_gripper::upper_arm_link::APSJ3.output_angle
		equation ur3e_gripper::forearm_link::wrist_1_joint::M4.dangle == ur3e_gripper::forearm_link::APSJ4.output_angle
		equation ur3e_gripper::wrist_1_link::wrist_2_joint::M5.dangle == ur3e_gripper::wrist_1_link::APSJ5.output_angle
		equation ur3e_gripper::wrist_2_link::wrist_3_joint::M6.dangle == ur3e_gripper::wrist_2_link::APSJ6.output_angle
	}

	operation pick {
		action gripper_closing = true
		action gripper_opening = false
	}

	operation place {
		action gripper_opening = true
		action gripper_closing = false
	}

	input event feasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::feasible
	}

	input event nonfeasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::infeasible
	}

	input event moveCompleted {
		equation motion == Motion::moving
		equation abs(ur3e_gripper::base_link::APSJ1.output_angle - target_q[0]) < POSITION_TOLERANCE
		equation abs(ur3e_gripper::shoulder_link::APSJ2.output_angle - target_q[1]) < POSITION_TOLERANCE
		equation abs(ur3e_gripper::upper_arm_link::APSJ3.output_angle - target_q[2]) < POSITION_TOLERANCE
		equation abs(ur3e_gripper::forearm_link::APSJ4.output_angle - target_q[3]) < POSITION_TOLERANCE
		equation abs(ur3e_gripper::wrist_1_link::APSJ5.output_angle - target_q[4]) < POSITION_TOLERANCE
		equation abs(ur3e_gripper::wrist_2_link::APSJ6.output_angle - target_q[5]) < POSITION_TOLERANCE
	}

	input event robotStopped {
		equation abs(ur3e_gripper::base_link::VSJ1.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur3e_gripper::shoulder_link::VSJ2.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur3e_gripper::upper_arm_link::VSJ3.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur3e_gripper::forearm_link::VSJ4.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur3e_gripper::wrist_1_link::VSJ5.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur3e_gripper::wrist_2_link::VSJ6.output_vel) < VELOCITY_TOLERANCE
	}

	input event gripperClosed {
		equation gripper_closing
	}

	input event gripperOpened {
		equation gripper_opening
	}

	// Commands come from the scenario (controller or broker), not from sensors.
	input event moveDiscreteCommand {
		predicate false
	}
	input event openGripperCommand {
		predicate false
	}
	input event closeGripperCommand {
		predicate false
	}

	input event collision {
		equation abs(ur3e_gripper::base_link::TSJ1.output_torque) > COLLISION_TORQUE \/
			abs(ur3e_gripper::shoulder_link::TSJ2.output_torque) > COLLISION_TORQUE \/
			abs(ur3e_gripper::upper_arm_link::TSJ3.output_torque) > COLLISION_TORQUE
	}
}

// Provided by cotwin's function registry: inverse kinematics on the p-model's kinematic tree with
// the tool pointing down, and whether a point is reachable that way.
function inverse_kinematics(x: real, y: real, z: real): vector(real, 6) { }
function reachable(x: real, y: real, z: real): boolean { }
