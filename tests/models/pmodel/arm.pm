// Parts, part-level connections, indexed links, closed chains and surfaces (legacy joint library).
import physmod::joints::*
import physmod::sensors::*
import physmod::actuators::*

pmodel Finger {
	const LENGTH: real
	local link Knuckle {
		def { inertial information { mass 0.05 } cylinder(radius = 0.01, length = LENGTH) }
		jref Bend = Revolute {
			instantiation AXIS = (|1, 0, 0|)
			aref Servo = ServoMotor { instantiation Kp = 20 }
		}
	}
	local link Tip {
		def { inertial information { mass 0.02 } sphere(radius = 0.012) }
		pose { x = 0 y = 0 z = LENGTH roll = 0 pitch = 0 yaw = 0 }
	}
}

pmodel Hand {
	part Thumb = Finger {
		instantiation LENGTH = 4cm
		pose { x = 0.03 y = 0 z = 0.05 roll = 0 pitch = 0 yaw = 0 }
		link Knuckle fixed to Palm
		joint Bend flexibly connected to Tip in Thumb
	}
	local link Palm {
		def {
			inertial information { mass 0.4 inertia matrix { ixx = 1e-3 ixy = 0 ixz = 0 iyy = 1e-3 iyz = 0 izz = 1e-3 } }
			box(length = 0.08, width = 0.08, height = 0.02)
		}
		local body Pad {
			pose { x = 0 y = 0 z = 0.011 roll = 0 pitch = 0 yaw = 0 }
			def {
				box(length = 0.06, width = 0.06, height = 0.002)
				friction { translational { coefficient1 1.5 coefficient2 1.2 slip1 0 slip2 0 } torsional { coefficient 0.2 } }
				laser retro 0.5
			}
		}
	}
	local link Segment {
		index i : [1, 3]
		def { inertial information { mass 0.01 } box(length = 0.01, width = 0.01, height = 0.01) }
		pose { x = -0.05 y = 0 z = 0.02 * i roll = 0 pitch = 0 yaw = 0 }
	}
}

// a four-bar linkage: four revolute joints around a closed loop
pmodel FourBar {
	local link A {
		def { inertial information { mass 1 } box(length = 0.4, width = 0.02, height = 0.02) }
		jref AB = Revolute { flexibly connected to B instantiation AXIS = (|0, 0, 1|)
			pose { x = 0.2 y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 } }
	}
	local link B {
		def { inertial information { mass 1 } box(length = 0.02, width = 0.4, height = 0.02) }
		pose { x = 0.2 y = 0.2 z = 0 roll = 0 pitch = 0 yaw = 0 }
		jref BC = Revolute { flexibly connected to C instantiation AXIS = (|0, 0, 1|)
			pose { x = 0 y = 0.2 z = 0 roll = 0 pitch = 0 yaw = 0 } }
	}
	local link C {
		def { inertial information { mass 1 } box(length = 0.4, width = 0.02, height = 0.02) }
		pose { x = 0 y = 0.4 z = 0 roll = 0 pitch = 0 yaw = 0 }
		jref CD = Revolute { flexibly connected to D instantiation AXIS = (|0, 0, 1|)
			pose { x = -0.2 y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 } }
	}
	local link D {
		def { inertial information { mass 1 } box(length = 0.02, width = 0.4, height = 0.02) }
		pose { x = -0.2 y = 0.2 z = 0 roll = 0 pitch = 0 yaw = 0 }
		jref DA = Revolute { flexibly connected to A instantiation AXIS = (|0, 0, 1|)
			pose { x = 0 y = -0.2 z = 0 roll = 0 pitch = 0 yaw = 0 } }
	}
}

fragment Gripper {
	local link Jaw { def { box(length = 0.01, width = 0.01, height = 0.01) } }
	sref JawSensor = PositionSensor { 1 == 1 }
}
