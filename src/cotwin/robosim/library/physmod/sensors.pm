// cotwin's built-in physmod sensor library: ideal sensors of joint quantities.
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
