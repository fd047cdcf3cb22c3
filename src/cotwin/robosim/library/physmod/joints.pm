// cotwin's built-in physmod joint library. `tau` is the generalised effort (torque or force) applied
// by an actuator, `position`/`velocity` the joint coordinate and its rate.
joint Revolute {
	input tau: real
	output position: real, velocity: real
}

joint Prismatic {
	input tau: real
	output position: real, velocity: real
}

joint Continuous {
	input tau: real
	output position: real, velocity: real
}

joint Fixed {
}
