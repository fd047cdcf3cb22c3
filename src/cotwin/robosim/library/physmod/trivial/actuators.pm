// Actuators of RoboTool's trivial formulation, as cotwin reads them.
package physmod::trivial::actuators

import physmod::math::*

// an ideal torque source: the commanded torque is applied to the joint
actuator TrivialMotor {
	input TorqueIn: real
	output TorqueOut: real
	equation TorqueOut == TorqueIn
}

// a motor whose command u is scaled by the gain matrix B_ctrl (1x1 by default: the identity).
// In RoboTool's published mobile robot the mapping sends ControlIn wheel speeds (rad/s): cotwin's
// simulator drives joints with this actuator by a velocity servo (docs/pmodel-notation.md).
actuator ControlledMotor {
	const B_ctrl: matrix(real, 1, 1) = [| 1.0 |]
	input ControlIn: real
	output TorqueOut: real
	equation TorqueOut == B_ctrl * ControlIn
}
