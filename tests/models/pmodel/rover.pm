// A small wheeled rover in RoboTool's current notation: packages, SKO joints, a controlled motor,
// local sensors and actuators with definitions, index replication, units and exponent literals.
package rover_parts

import physmod::SKO::joints::*
import physmod::trivial::actuators::ControlledMotor
import physmod::sdf::annotations::*

const WHEEL_RADIUS: real = 3.3cm
const TRACK: real = (16)cm

body WheelBody {
	cylinder(radius = WHEEL_RADIUS, length = 18mm)
	inertial information {
		mass 2.8e-2
		inertia matrix { ixx 1.8e-5 ixy 0 ixz 0 iyy 1.8e-5 iyz 0 izz 3.0e-5 }
	}
	bounce { restitution coefficient 0.1 threshold 1e5 }
	friction { translational { coefficient1 0.9 coefficient2 0.9 } }
}

link Wheel {
	const number: nat = 1
}

endpackage

package rover

import rover_parts::*
import physmod::math::*
import physmod::SKO::joints::Revolute_y
import physmod::trivial::actuators::ControlledMotor

pmodel Rover {
	const HEIGHT: real = 0.1
	const SPEED_LIMIT: real
	InOut v: real
	equation v == derivative(v) * 0
	local link Base {
		def {
			inertial information {
				mass 1.2
				inertia matrix { ixx 0.004 ixy 0 ixz 0 iyy 0.006 iyz 0 izz 0.008 }
			}
			box(length = 0.2, width = 0.14, height = HEIGHT)
		}
		pose { x = 0 y = 0 z = 5cm roll = 0 pitch = 0 yaw = 0 }
		jref Left = Revolute_y {
			flexibly connected to LeftWheel
			pose { x = 0 y = TRACK / 2 z = -0.017 roll = 0 pitch = 0 yaw = 0 }
			aref LeftMotor = ControlledMotor { }
		}
		local joint Right {
			def {
				const H: vector(real, 6) = (| 0, 1, 0, 0, 0, 0 |)
				InOut theta: real
				equation theta == theta
			}
			flexibly connected to RightWheel
			pose { x = 0 y = -TRACK / 2 z = -0.017 roll = 0 pitch = 0 yaw = 0 }
			local actuator RightMotor {
				def {
					input speed: real
					output torque: real
					equation torque == 0.5 * speed
				}
			}
		}
		local sensor Sonar {
			index i : [0, 4)
			pose { x = 0.1 y = 0 z = 0 roll = 0 pitch = 0 yaw = i * 1.5707963267948966 }
			def {
				input distance: real
				output range: real
				equation range == distance
				annotation Sonar {
					always_on = true
					update_rate = 10
					sonar = SonarDetails { min = 0.02 max = 4 _radius = 0.01 }
				}
			}
		}
		local sensor Gyro {
			pose { x = 0 y = 0 z = 0.06 roll = 0 pitch = 0 yaw = 0 }
			def {
				input rate: real
				output yawAV: real
				equation yawAV == rate
				annotation IMU { update_rate = 100 }
			}
		}
	}
	lref LeftWheel = Wheel {
		pose { x = 0 y = TRACK / 2 z = 0.033 roll = 0 pitch = 0 yaw = 0 }
		bref Tyre = WheelBody { pose { x = 0 y = 0 z = 0 roll = 1.5707963267948966 pitch = 0 yaw = 0 } }
	}
	lref RightWheel = Wheel {
		pose { x = 0 y = -TRACK / 2 z = 0.033 roll = 0 pitch = 0 yaw = 0 }
		bref Tyre = WheelBody { pose { x = 0 y = 0 z = 0 roll = 1.5707963267948966 pitch = 0 yaw = 0 } }
	}
	solution {
		solutionExpr phi : real
		order 1
		method Eval
		Input v : real
		Constraint (v) [t == 0] == 0.0
	}
}

endpackage
