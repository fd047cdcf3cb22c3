// cotwin's built-in physmod actuator library.
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
