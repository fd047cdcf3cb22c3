// examples/flexcell2: the UR5e's mapping of examples/ur5e, its collision also the contact with the cell's
// other robot (cotwin's robot_contact()). How the FlexCellArm d-model's operations and events are
// realised on the ur5e p-model. An operation's actions set mapping variables and its equations
// `actuator.port == e` command the servos (the endpoint moves there smoothly within the joints'
// velocity limits). The equations of an input event are a conjunction over variables and sensors.
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

map FlexCellMapping dmodel FlexCellArm to pmodel ur5e {
	// Flex-cell plate: 16 x 24 holes at 50 mm, in the robot base frame (as in the paper's mapping).
	const HOLE_DIST: real = 0.05
	const X_MAX: real = 1.128
	const Y_MAX: real = 0.711
	const Z_TABLE: real = 0.020
	const XMAX: int = 15
	const YMAX: int = 23
	const ZMAX: int = 4
	const POSITION_TOLERANCE: real = 0.002
	const VELOCITY_TOLERANCE: real = 0.02
	const COLLISION_TORQUE: real = 140.0
	const FINGER_TOLERANCE: real = 0.002
	const HALF_MIN_WIDTH: real = 0.0175

	var target_q: vector(real, 6) = [| 0.0, 0.0, 0.0, 0.0, 0.0, 0.0 |]
	var feasibility: Feasibility = Feasibility::none
	var motion: Motion = Motion::idle
	var finger_target: real = 0.0
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
		equation ur5e::base_link::shoulder_pan_joint::M1.dangle == target_q[0]
		equation ur5e::shoulder_link::shoulder_lift_joint::M2.dangle == target_q[1]
		equation ur5e::upper_arm_link::elbow_joint::M3.dangle == target_q[2]
		equation ur5e::forearm_link::wrist_1_joint::M4.dangle == target_q[3]
		equation ur5e::wrist_1_link::wrist_2_joint::M5.dangle == target_q[4]
		equation ur5e::wrist_2_link::wrist_3_joint::M6.dangle == target_q[5]
	}

	operation movejoint {
		action target_q = [| target_q0, target_q1, target_q2, target_q3, target_q4, target_q5 |]
		action motion = Motion::moving
		equation ur5e::base_link::shoulder_pan_joint::M1.dangle == target_q[0]
		equation ur5e::shoulder_link::shoulder_lift_joint::M2.dangle == target_q[1]
		equation ur5e::upper_arm_link::elbow_joint::M3.dangle == target_q[2]
		equation ur5e::forearm_link::wrist_1_joint::M4.dangle == target_q[3]
		equation ur5e::wrist_1_link::wrist_2_joint::M5.dangle == target_q[4]
		equation ur5e::wrist_2_link::wrist_3_joint::M6.dangle == target_q[5]
	}

	// stop: hold the arm where it is
	operation stop {
		action motion = Motion::idle
		equation ur5e::base_link::shoulder_pan_joint::M1.dangle == ur5e::base_link::PS1.output_position
		equation ur5e::shoulder_link::shoulder_lift_joint::M2.dangle == ur5e::shoulder_link::PS2.output_position
		equation ur5e::upper_arm_link::elbow_joint::M3.dangle == ur5e::upper_arm_link::PS3.output_position
		equation ur5e::forearm_link::wrist_1_joint::M4.dangle == ur5e::forearm_link::PS4.output_position
		equation ur5e::wrist_1_link::wrist_2_joint::M5.dangle == ur5e::wrist_1_link::PS5.output_position
		equation ur5e::wrist_2_link::wrist_3_joint::M6.dangle == ur5e::wrist_2_link::PS6.output_position
	}

	operation pick {
		action finger_target = max(0.0, diameter / 2 - HALF_MIN_WIDTH)
		action gripper_closing = true
		action gripper_opening = false
		equation ur5e::gripper_body::left_finger_joint::LFM.dangle == finger_target
		equation ur5e::gripper_body::right_finger_joint::RFM.dangle == finger_target
	}

	operation place {
		action finger_target = max(0.0, diameter / 2 - HALF_MIN_WIDTH)
		action gripper_opening = true
		action gripper_closing = false
		equation ur5e::gripper_body::left_finger_joint::LFM.dangle == finger_target
		equation ur5e::gripper_body::right_finger_joint::RFM.dangle == finger_target
	}

	input event feasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::feasible
	}

	input event nonfeasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::infeasible
	}

	input event moveCompleted {
		equation motion == Motion::moving
		equation abs(ur5e::base_link::PS1.output_position - target_q[0]) < POSITION_TOLERANCE
		equation abs(ur5e::shoulder_link::PS2.output_position - target_q[1]) < POSITION_TOLERANCE
		equation abs(ur5e::upper_arm_link::PS3.output_position - target_q[2]) < POSITION_TOLERANCE
		equation abs(ur5e::forearm_link::PS4.output_position - target_q[3]) < POSITION_TOLERANCE
		equation abs(ur5e::wrist_1_link::PS5.output_position - target_q[4]) < POSITION_TOLERANCE
		equation abs(ur5e::wrist_2_link::PS6.output_position - target_q[5]) < POSITION_TOLERANCE
	}

	input event robotStopped {
		equation abs(ur5e::base_link::VS1.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::shoulder_link::VS2.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::upper_arm_link::VS3.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::forearm_link::VS4.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::wrist_1_link::VS5.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::wrist_2_link::VS6.output_vel) < VELOCITY_TOLERANCE
	}

	input event gripperClosed {
		equation gripper_closing
		equation abs(ur5e::gripper_body::VSLF.output_vel) < VELOCITY_TOLERANCE
		equation abs(ur5e::gripper_body::VSRF.output_vel) < VELOCITY_TOLERANCE
		equation ur5e::gripper_body::PSLF.output_position < finger_target + 0.02
	}

	input event gripperOpened {
		equation gripper_opening
		equation abs(ur5e::gripper_body::PSLF.output_position - finger_target) < FINGER_TOLERANCE
		equation abs(ur5e::gripper_body::PSRF.output_position - finger_target) < FINGER_TOLERANCE
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

	// a collision: the arm touches the other robot of the cell, or a joint's torque says it hit something
	input event collision {
		equation robot_contact() \/ abs(ur5e::base_link::TS1.output_torque) > COLLISION_TORQUE \/
			abs(ur5e::shoulder_link::TS2.output_torque) > COLLISION_TORQUE \/
			abs(ur5e::upper_arm_link::TS3.output_torque) > COLLISION_TORQUE
	}
}

// Provided by cotwin's function registry: inverse kinematics on the p-model's kinematic tree with
// the tool pointing down, and whether a point is reachable that way.
function inverse_kinematics(x: real, y: real, z: real): vector(real, 6) { }
function reachable(x: real, y: real, z: real): boolean { }
// Provided by cotwin: did the robot touch another robot of its world in the step just made?
function robot_contact(): boolean { }
