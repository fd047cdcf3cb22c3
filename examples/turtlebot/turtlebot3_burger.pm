// cotwin's own p-model of the TurtleBot3 Burger, with the names of RoboTool's published one
// (../shared/robosim/mobile/Turtlebot3_Burger.pm), so that the same mapping and d-model drive either.
// Written from the robot's published dimensions: a 14 cm chassis on two wheels of 33 mm radius, 16 cm
// apart, a caster ball at the back, the LDS-01 LiDAR on top. Unlike the published model it has no mesh
// files (shapes only), its wheel joints turn about the wheels' centres and its inertias are those of
// its shapes. The chassis slides where it touches the floor (friction 0), as the robot's skid does.
import physmod::SKO::joints::Revolute_y
import physmod::trivial::actuators::ControlledMotor
import physmod::sdf::annotations::*

pmodel Turtlebot3_Burger {
	local link BaseLink {
		def { }
		local body Chassis {
			def {
				box(length = 0.14, width = 0.14, height = 0.174)
				inertial information {
					mass 0.82573504
					inertia matrix { ixx 0.00343 ixy 0 ixz 0 iyy 0.00343 iyz 0 izz 0.0027 }
				}
				friction { translational { coefficient1 0.0 coefficient2 0.0 } }
			}
			pose { x = -0.032 y = 0.0 z = 0.070 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		local body Caster {
			def {
				sphere(radius = 0.01)
				inertial information {
					mass 0.005
					inertia matrix { ixx 2e-7 ixy 0 ixz 0 iyy 2e-7 iyz 0 izz 2e-7 }
				}
				friction { translational { coefficient1 0.0 coefficient2 0.0 } }
			}
			pose { x = -0.081 y = 0.0 z = -0.010 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}

		jref LeftWheelJoint = Revolute_y {
			flexibly connected to LeftWheel
			pose { x = 0.0 y = 0.08 z = 0.013 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			aref LeftMotor = ControlledMotor {
				pose { x = 0.0 y = 0.0 z = 0.0 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}

		jref RightWheelJoint = Revolute_y {
			flexibly connected to RightWheel
			pose { x = 0.0 y = -0.08 z = 0.013 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			aref RightMotor = ControlledMotor {
				pose { x = 0.0 y = 0.0 z = 0.0 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}

		sref TBLidar = LDS01 {
			pose { x = -0.032 y = 0.0 z = 0.162 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}

		sref TBIMU = IMU {
			pose { x = 0.0 y = 0.0 z = 0.071 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}

		pose { x = 0.0 y = 0.0 z = 0.010 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link LeftWheel {
		def { }
		local body Wheel {
			def {
				cylinder(radius = 0.033, length = 0.018)
				inertial information {
					mass 0.02849894
					inertia matrix { ixx 0.0000085 ixy 0 ixz 0 iyy 0.0000085 iyz 0 izz 0.0000155 }
				}
			}
			pose { x = 0.0 y = 0.0 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = 0.08 z = 0.023 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link RightWheel {
		def { }
		local body Wheel {
			def {
				cylinder(radius = 0.033, length = 0.018)
				inertial information {
					mass 0.02849894
					inertia matrix { ixx 0.0000085 ixy 0 ixz 0 iyy 0.0000085 iyz 0 izz 0.0000155 }
				}
			}
			pose { x = 0.0 y = 0.0 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = -0.08 z = 0.023 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}
}

// The LDS-01 LiDAR: 360 beams a turn, one a degree, 0.12 to 3.5 m, 5 turns a second. Its ports give the
// nearest return of the last scan: its range (m) and bearing (degrees, 0 ahead, counter-clockwise).
sensor LDS01 {
	input ranges: Seq(real)
	output closestDistance: real
	output closestAngle: real
	annotation Ray {
		always_on = true
		update_rate = 5
		visualize = false
		ray = RayDetails {
			scan = Scan { horizontal = Scan_horizontal { samples = 360 resolution = 1 min_angle = 0.0 max_angle = 6.265732014659643 } }
			range = Range { min = 0.12 max = 3.5 resolution = 0.015 }
		}
	}
}

// Yaw rate and forward speed of the base.
sensor IMU {
	input angularRateAV: real
	input angularRateLV: real
	output currentLV: real
	output currentAV: real
}
