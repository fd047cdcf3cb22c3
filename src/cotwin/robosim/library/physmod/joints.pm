// cotwin's built-in physmod joint library (the legacy `physmod::joints` of RoboTool's p-models).
// `tau` is the generalised effort (torque or force) applied by an actuator, `position`/`velocity`
// the joint coordinate and its rate; AXIS (a unit vector in the joint frame) may be instantiated,
// else an SDF-style `annotation Revolute { axis = Axis { xyz = (|x, y, z|) } }` gives it.
package physmod::joints

joint Revolute {
	const AXIS: vector(real, 3)
	input tau: real
	output position: real, velocity: real
}

joint Prismatic {
	const AXIS: vector(real, 3)
	input tau: real
	output position: real, velocity: real
}

joint Continuous {
	const AXIS: vector(real, 3)
	input tau: real
	output position: real, velocity: real
}

joint Fixed {
}
