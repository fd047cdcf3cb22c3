// cotwin's built-in physmod sensor library (the legacy `physmod::sensors`): ideal sensors of joint
// quantities, and the robot sensors of RoboTool's earlier examples.
package physmod::sensors

import physmod::math::*

sensor PositionSensor {
	input input_position: real
	output output_position: real
	equation input_position == output_position
}

sensor VelocitySensor {
	input input_vel: real
	output output_vel: real
	equation input_vel == output_vel
}

sensor TorqueSensor {
	input input_torque: real
	output output_torque: real
	equation input_torque == output_torque
}

sensor ForceSensor {
	input input_force: real
	output output_force: real
	equation input_force == output_force
}

// infrared proximity: the distance to the nearest surface along the sensor's x axis, within range
sensor IR {
	input distance: real
	output measurement: real
	const range_max: real
	equation measurement == min(distance, range_max)
}

sensor Camera {
	input scene: real
	output image: real
}

sensor Accelerometer {
	input acceleration: vector(real, 3)
	output measurement: vector(real, 3)
	equation measurement == acceleration
}

sensor Gyroscope {
	input angular_velocity: vector(real, 3)
	output measurement: vector(real, 3)
	equation measurement == angular_velocity
}
