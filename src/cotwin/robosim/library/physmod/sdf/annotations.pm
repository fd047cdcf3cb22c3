// Annotations that carry SDF data in RoboTool's p-models (`annotation Ray { ... }` on a sensor,
// `annotation Revolute { axis = Axis { ... } }` on a joint). cotwin's SDF writer turns an annotated
// sensor into an SDF <sensor> of the matching type and writes the entries as SDF elements (a leading
// `_`, used where the entry's name is a keyword, e.g. `_friction`, is dropped).
package physmod::sdf::annotations

// ---- joints
annotation template Dynamics {
	damping: real
	_friction: real
	spring_reference: real
	spring_stiffness: real
}
annotation template Limit {
	lower: real
	upper: real
	effort: real
	velocity: real
}
annotation template Axis {
	xyz: vector(real, 3)
	dynamics: template Dynamics
	limit: template Limit
}
annotation template Revolute {
	axis: template Axis
}
annotation template Prismatic {
	axis: template Axis
}
annotation template Gearbox {
	gearbox_ratio: real
	gearbox_reference_body: string
}

// ---- sensors
annotation template Noise {
	type: string
	mean: real
	stddev: real
}
annotation template Scan_horizontal {
	samples: nat
	resolution: real
	min_angle: real
	max_angle: real
}
annotation template Scan_vertical {
	samples: nat
	resolution: real
	min_angle: real
	max_angle: real
}
annotation template Scan {
	horizontal: template Scan_horizontal
	vertical: template Scan_vertical
}
annotation template Range {
	min: real
	max: real
	resolution: real
}
annotation template RayDetails {
	scan: template Scan
	range: template Range
	noise: template Noise
}
annotation template Ray {
	always_on: boolean
	update_rate: real
	visualize: boolean
	ray: template RayDetails
}
annotation template SonarDetails {
	min: real
	max: real
	_radius: real
}
annotation template Sonar {
	always_on: boolean
	update_rate: real
	visualize: boolean
	sonar: template SonarDetails
}
annotation template IMU {
	always_on: boolean
	update_rate: real
	visualize: boolean
}
annotation template Image {
	width: nat
	height: nat
	format: string
}
annotation template Clip {
	near: real
	far: real
}
annotation template CameraDetails {
	horizontal_fov: real
	image: template Image
	clip: template Clip
}
annotation template Camera {
	always_on: boolean
	update_rate: real
	visualize: boolean
	camera: template CameraDetails
}
annotation template ContactDetails {
	collision: string
	topic: string
}
annotation template Contact {
	always_on: boolean
	update_rate: real
	contact: template ContactDetails
}

// ---- actuators
annotation template Light {
	cast_shadows: boolean
	range: real
	direction: vector(real, 3)
}
