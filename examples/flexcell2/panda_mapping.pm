// examples/flexcell2: the paper's FlexCellArm d-model on the Franka Panda imported from its URDF, sharing the
// UR5e's plate (the same grid constants: a hole is the same point of the plate for both arms; where the
// Panda stands on it is the project's [[robots]] base). Its collision: touching the other robot of the cell
// (cotwin's robot_contact()) or a torque beyond what a free move needs.
import physmod::math::*

enumeration Feasibility {
	none
	feasible
	infeasible
}

enumeration Motion {
	idle
	moving
}

map PandaMapping dmodel FlexCellArm to pmodel panda {
	const HOLE_DIST: real = 0.05
	const X_MAX: real = 1.128
	const Y_MAX: real = 0.711
	const Z_TABLE: real = 0.020
	const XMAX: int = 15
	const YMAX: int = 23
	const ZMAX: int = 4
	const POSITION_TOLERANCE: real = 0.002
	const VELOCITY_TOLERANCE: real = 0.02
	const COLLISION_TORQUE: real = 80.0
	const OPEN: real = 0.04

	var target_q: vector(real, 7) = [| 0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785 |]
	var feasibility: Feasibility = Feasibility::none
	var motion: Motion = Motion::idle
	var finger_target: real = 0.04
	var gripper_closing: boolean = false
	var gripper_opening: boolean = false
	var q0: real, q1: real, q2: real, q3: real, q4: real, q5: real, q6: real

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
		equation panda::panda_link0::panda_joint1::panda_joint1_motor.dangle == target_q[0]
		equation panda::panda_link1::panda_joint2::panda_joint2_motor.dangle == target_q[1]
		equation panda::panda_link2::panda_joint3::panda_joint3_motor.dangle == target_q[2]
		equation panda::panda_link3::panda_joint4::panda_joint4_motor.dangle == target_q[3]
		equation panda::panda_link4::panda_joint5::panda_joint5_motor.dangle == target_q[4]
		equation panda::panda_link5::panda_joint6::panda_joint6_motor.dangle == target_q[5]
		equation panda::panda_link6::panda_joint7::panda_joint7_motor.dangle == target_q[6]
	}

	operation movejoint {
		action target_q = [| target_q0, target_q1, target_q2, target_q3, target_q4, target_q5, target_q[6] |]
		action motion = Motion::moving
		equation panda::panda_link0::panda_joint1::panda_joint1_motor.dangle == target_q[0]
		equation panda::panda_link1::panda_joint2::panda_joint2_motor.dangle == target_q[1]
		equation panda::panda_link2::panda_joint3::panda_joint3_motor.dangle == target_q[2]
		equation panda::panda_link3::panda_joint4::panda_joint4_motor.dangle == target_q[3]
		equation panda::panda_link4::panda_joint5::panda_joint5_motor.dangle == target_q[4]
		equation panda::panda_link5::panda_joint6::panda_joint6_motor.dangle == target_q[5]
		equation panda::panda_link6::panda_joint7::panda_joint7_motor.dangle == target_q[6]
	}

	operation stop {
		action motion = Motion::idle
		equation panda::panda_link0::panda_joint1::panda_joint1_motor.dangle == panda::panda_link0::panda_joint1::panda_joint1_position.output_position
		equation panda::panda_link1::panda_joint2::panda_joint2_motor.dangle == panda::panda_link1::panda_joint2::panda_joint2_position.output_position
		equation panda::panda_link2::panda_joint3::panda_joint3_motor.dangle == panda::panda_link2::panda_joint3::panda_joint3_position.output_position
		equation panda::panda_link3::panda_joint4::panda_joint4_motor.dangle == panda::panda_link3::panda_joint4::panda_joint4_position.output_position
		equation panda::panda_link4::panda_joint5::panda_joint5_motor.dangle == panda::panda_link4::panda_joint5::panda_joint5_position.output_position
		equation panda::panda_link5::panda_joint6::panda_joint6_motor.dangle == panda::panda_link5::panda_joint6::panda_joint6_position.output_position
		equation panda::panda_link6::panda_joint7::panda_joint7_motor.dangle == panda::panda_link6::panda_joint7::panda_joint7_position.output_position
	}

	operation pick {
		action finger_target = max(0.0, diameter / 2)
		action gripper_closing = true
		action gripper_opening = false
		equation panda::panda_hand::panda_finger_joint1::panda_finger_joint1_motor.dangle == finger_target
		equation panda::panda_hand::panda_finger_joint2::panda_finger_joint2_motor.dangle == finger_target
	}

	operation place {
		action finger_target = OPEN
		action gripper_opening = true
		action gripper_closing = false
		equation panda::panda_hand::panda_finger_joint1::panda_finger_joint1_motor.dangle == finger_target
		equation panda::panda_hand::panda_finger_joint2::panda_finger_joint2_motor.dangle == finger_target
	}

	input event feasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::feasible
	}

	input event nonfeasibleMoveDiscreteCommand {
		equation feasibility == Feasibility::infeasible
	}

	input event moveCompleted {
		equation motion == Motion::moving
		equation abs(panda::panda_link0::panda_joint1::panda_joint1_position.output_position - target_q[0]) < POSITION_TOLERANCE
		equation abs(panda::panda_link1::panda_joint2::panda_joint2_position.output_position - target_q[1]) < POSITION_TOLERANCE
		equation abs(panda::panda_link2::panda_joint3::panda_joint3_position.output_position - target_q[2]) < POSITION_TOLERANCE
		equation abs(panda::panda_link3::panda_joint4::panda_joint4_position.output_position - target_q[3]) < POSITION_TOLERANCE
		equation abs(panda::panda_link4::panda_joint5::panda_joint5_position.output_position - target_q[4]) < POSITION_TOLERANCE
		equation abs(panda::panda_link5::panda_joint6::panda_joint6_position.output_position - target_q[5]) < POSITION_TOLERANCE
		equation abs(panda::panda_link6::panda_joint7::panda_joint7_position.output_position - target_q[6]) < POSITION_TOLERANCE
	}

	input event robotStopped {
		equation abs(panda::panda_link0::panda_joint1::panda_joint1_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link1::panda_joint2::panda_joint2_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link2::panda_joint3::panda_joint3_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link3::panda_joint4::panda_joint4_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link4::panda_joint5::panda_joint5_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link5::panda_joint6::panda_joint6_velocity.output_vel) < VELOCITY_TOLERANCE
		equation abs(panda::panda_link6::panda_joint7::panda_joint7_velocity.output_vel) < VELOCITY_TOLERANCE
	}

	input event gripperClosed {
		equation gripper_closing
		equation abs(panda::panda_hand::panda_finger_joint1::panda_finger_joint1_velocity.output_vel) < VELOCITY_TOLERANCE
	}

	input event gripperOpened {
		equation gripper_opening
		equation abs(panda::panda_hand::panda_finger_joint1::panda_finger_joint1_position.output_position - finger_target) < POSITION_TOLERANCE
	}

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
		equation robot_contact() \/
			abs(panda::panda_link1::panda_joint2::panda_joint2_effort.output_torque) > COLLISION_TORQUE
	}
}

function inverse_kinematics(x: real, y: real, z: real): vector(real, 7) { }
function reachable(x: real, y: real, z: real): boolean { }
function robot_contact(): boolean { }
