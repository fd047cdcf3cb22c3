// cotwin's built-in physmod actuator library (the legacy `physmod::actuators`). Which input of an
// actuator commands its joint (angle, speed or effort) is read from the names of its ports.
package physmod::actuators

actuator ServoMotor {
	input dangle: real
	input angular_vel: real
	output T: real
	output theta: real, av: real, e: real
	const b: real, Ke: real, Kt: real
	const R: real, L: real
	const Kp: real, Ki: real, Kd: real
}

actuator DCMotor {
	input V: real
	output T: real, av: real
	const Kt: real, Ke: real, R: real, L: real, b: real
}

// a motor whose controller tracks a commanded angular speed (rad/s) with torque T
actuator SpeedControlMotor {
	input speed: real
	output T: real, av: real
	const Kp: real, Ki: real
	equation T == Kp * (speed - av)
}

// a linear drive tracking a commanded speed (m/s) with force F
actuator LinearSpeedControlMotor {
	input speed: real
	output F: real, lv: real
	const Kp: real
	equation F == Kp * (speed - lv)
}

// an ideal torque source
actuator TorqueControlMotor {
	input TorqueIn: real
	output TorqueOut: real
	equation TorqueOut == TorqueIn
}
