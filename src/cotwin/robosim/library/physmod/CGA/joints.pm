// Joints of RoboTool's conformal geometric algebra formulation, as cotwin reads them: a motor is 8
// coefficients [s, e12, e13, e23, e1i, e2i, e3i, e123i]; a joint's motor is its frame motor times
// the rotor (axis_rot, revolute) or translator (axis_lin, prismatic) of its coordinate q.
package physmod::CGA::joints

import physmod::math::*

function motorProduct(a: vector(real, 8), b: vector(real, 8)): vector(real, 8) { }
function rotor(axis: vector(real, 3), angle: real): vector(real, 8) { }
function translator(axis: vector(real, 3), distance: real): vector(real, 8) { }

joint FixedJoint_CGA {
	InOut motor_frame: vector(real, 8)
	InOut motor_joint: vector(real, 8)
	equation motor_joint == motor_frame
}

joint RevoluteJoint_CGA {
	InOut q: real
	InOut axis_rot: vector(real, 3) = (| 0, 1, 0 |)
	InOut motor_frame: vector(real, 8)
	InOut motor_joint: vector(real, 8)
	equation motor_joint == motorProduct(motor_frame, rotor(axis_rot, q))
}

joint PrismaticJoint_CGA {
	InOut q: real
	InOut axis_lin: vector(real, 3) = (| 0, 0, 1 |)
	InOut motor_frame: vector(real, 8)
	InOut motor_joint: vector(real, 8)
	equation motor_joint == motorProduct(motor_frame, translator(axis_lin, q))
}
