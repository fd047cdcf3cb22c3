// cotwin example: the UR5e arm with an OnRobot 2FG7-like two-finger gripper (our own p-model).
// Dimensions are the UR5e's published kinematic parameters (d1, a2, a3, d4, d5, d6) and link masses.
// Zero configuration: arm pointing straight up, every link frame aligned with the model frame;
// link poses are in the model frame, joint poses relative to their parent link (notation, section 3).
// A sensor declared after a jref measures that joint.
import physmod::joints::*
import physmod::actuators::*
import physmod::sensors::*

pmodel ur5e {
	const PI: real = 3.14159265358979
	const D1: real = 0.1625
	const A2: real = 0.425
	const A3: real = 0.3922
	const D4: real = 0.1333
	const D5: real = 0.0997
	const D6: real = 0.0996
	const SHOULDER_OFFSET: real = 0.138
	const ELBOW_OFFSET: real = 0.131
	const MASS_BASE: real = 4.0
	const MASS_SHOULDER: real = 3.761
	const MASS_UPPER_ARM: real = 8.058
	const MASS_FOREARM: real = 2.846
	const MASS_WRIST_1: real = 1.37
	const MASS_WRIST_2: real = 1.3
	const MASS_WRIST_3: real = 0.365

	local link base_link {
		def {
			inertial information {
				mass MASS_BASE kg
			}
		}
		local body base_link_body {
			def {
				cylinder ( radius = 0.075 , length = 0.1 )
			}
			pose {
				x = 0
				y = 0
				z = 0.05
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		jref shoulder_pan_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,0,1|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 150 }
				}
			}
			aref M1 = ServoMotor {
				instantiation Kp = 3000.0
				instantiation Kd = 150.0
				relation shoulder_pan_joint.tau == M1.T
			}
			flexibly connected to shoulder_link
			pose {
				x = 0
				y = 0
				z = D1
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS1 = PositionSensor
		sref VS1 = VelocitySensor
		sref TS1 = TorqueSensor
		pose {
			x = 0
			y = 0
			z = 0
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link shoulder_link {
		def {
			inertial information {
				mass MASS_SHOULDER kg
			}
		}
		local body shoulder_link_body {
			def {
				cylinder ( radius = 0.06 , length = 0.15 )
			}
			pose {
				x = 0
				y = 0
				z = 0
				roll = PI/2
				pitch = 0
				yaw = 0
			}
		}
		jref shoulder_lift_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,1,0|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 150 }
				}
			}
			aref M2 = ServoMotor {
				instantiation Kp = 3000.0
				instantiation Kd = 150.0
				relation shoulder_lift_joint.tau == M2.T
			}
			flexibly connected to upper_arm_link
			pose {
				x = 0
				y = SHOULDER_OFFSET
				z = 0
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS2 = PositionSensor
		sref VS2 = VelocitySensor
		sref TS2 = TorqueSensor
		pose {
			x = 0
			y = 0
			z = D1
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link upper_arm_link {
		def {
			inertial information {
				mass MASS_UPPER_ARM kg
			}
		}
		local body upper_arm_link_body {
			def {
				cylinder ( radius = 0.054 , length = A2 )
			}
			pose {
				x = 0
				y = 0
				z = A2/2
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		jref elbow_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,1,0|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 150 }
				}
			}
			aref M3 = ServoMotor {
				instantiation Kp = 3000.0
				instantiation Kd = 150.0
				relation elbow_joint.tau == M3.T
			}
			flexibly connected to forearm_link
			pose {
				x = 0
				y = -ELBOW_OFFSET
				z = A2
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS3 = PositionSensor
		sref VS3 = VelocitySensor
		sref TS3 = TorqueSensor
		pose {
			x = 0
			y = SHOULDER_OFFSET
			z = D1
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link forearm_link {
		def {
			inertial information {
				mass MASS_FOREARM kg
			}
		}
		local body forearm_link_body {
			def {
				cylinder ( radius = 0.04 , length = A3 )
			}
			pose {
				x = 0
				y = 0
				z = A3/2
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		jref wrist_1_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,1,0|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 28 }
				}
			}
			aref M4 = ServoMotor {
				instantiation Kp = 1000.0
				instantiation Kd = 50.0
				relation wrist_1_joint.tau == M4.T
			}
			flexibly connected to wrist_1_link
			pose {
				x = 0
				y = 0
				z = A3
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS4 = PositionSensor
		sref VS4 = VelocitySensor
		sref TS4 = TorqueSensor
		pose {
			x = 0
			y = SHOULDER_OFFSET-ELBOW_OFFSET
			z = D1+A2
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link wrist_1_link {
		def {
			inertial information {
				mass MASS_WRIST_1 kg
			}
		}
		local body wrist_1_link_body {
			def {
				cylinder ( radius = 0.0375 , length = 0.12 )
			}
			pose {
				x = 0
				y = 0.06
				z = 0
				roll = PI/2
				pitch = 0
				yaw = 0
			}
		}
		jref wrist_2_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,0,1|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 28 }
				}
			}
			aref M5 = ServoMotor {
				instantiation Kp = 1000.0
				instantiation Kd = 50.0
				relation wrist_2_joint.tau == M5.T
			}
			flexibly connected to wrist_2_link
			pose {
				x = 0
				y = D4-SHOULDER_OFFSET+ELBOW_OFFSET
				z = 0
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS5 = PositionSensor
		sref VS5 = VelocitySensor
		sref TS5 = TorqueSensor
		pose {
			x = 0
			y = SHOULDER_OFFSET-ELBOW_OFFSET
			z = D1+A2+A3
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link wrist_2_link {
		def {
			inertial information {
				mass MASS_WRIST_2 kg
			}
		}
		local body wrist_2_link_body {
			def {
				cylinder ( radius = 0.0375 , length = D5 )
			}
			pose {
				x = 0
				y = 0
				z = D5/2
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		jref wrist_3_joint = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0,1,0|)
					dynamics = Dynamics { damping = 5.0 }
					limit = Limit { lower = -2*PI upper = 2*PI velocity = PI effort = 28 }
				}
			}
			aref M6 = ServoMotor {
				instantiation Kp = 1000.0
				instantiation Kd = 50.0
				relation wrist_3_joint.tau == M6.T
			}
			flexibly connected to wrist_3_link
			pose {
				x = 0
				y = 0
				z = D5
				roll = 0
				pitch = 0
				yaw = 0
			}
		}
		sref PS6 = PositionSensor
		sref VS6 = VelocitySensor
		sref TS6 = TorqueSensor
		pose {
			x = 0
			y = D4
			z = D1+A2+A3
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	local link wrist_3_link {
		fixed to gripper_body in Gripper
		def {
			inertial information {
				mass MASS_WRIST_3 kg
			}
		}
		local body wrist_3_link_body {
			def {
				cylinder ( radius = 0.0375 , length = D6 )
			}
			pose {
				x = 0
				y = D6/2
				z = 0
				roll = PI/2
				pitch = 0
				yaw = 0
			}
		}
		pose {
			x = 0
			y = D4
			z = D1+A2+A3+D5
			roll = 0
			pitch = 0
			yaw = 0
		}
	}

	part Gripper = Gripper2FG7 {
		pose {
			x = 0.0
			y = D4 + D6
			z = D1 + A2 + A3 + D5
			roll = -PI/2
			pitch = 0.0
			yaw = 0.0
		}
	}
}

// The gripper in its own frame: origin at the tool flange, +z out of the tool, fingers closing along x.
// A finger's joint coordinate is its travel from fully closed (grip width 35 mm) to open (73 mm).
pmodel Gripper2FG7 {
	const BODY_HEIGHT: real = 0.1445
	const FINGER_HEIGHT: real = 0.045
	const HALF_MIN_WIDTH: real = 0.035/2
	const FINGER_THICKNESS: real = 0.005
	const STROKE: real = (0.073 - 0.035)/2

	local link gripper_body {
		def {
			inertial information {
				mass 1.1 kg
			}
		}
		local body gripper_housing {
			def {
				box ( length = 0.09 , width = 0.071 , height = BODY_HEIGHT )
			}
			pose { x = 0.0 y = 0.0 z = BODY_HEIGHT/2 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		jref left_finger_joint = Prismatic {
			annotation Prismatic {
				axis = Axis {
					xyz = (|-1,0,0|)
					dynamics = Dynamics { damping = 20.0 }
					limit = Limit { lower = 0.0 upper = STROKE velocity = 0.1 effort = 140 }
				}
			}
			aref LFM = ServoMotor {
				instantiation Kp = 10000.0
				instantiation Kd = 200.0
				relation left_finger_joint.tau == LFM.T
			}
			flexibly connected to left_finger
			pose { x = -(HALF_MIN_WIDTH + FINGER_THICKNESS/2) y = 0.0 z = BODY_HEIGHT roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		sref PSLF = PositionSensor
		sref VSLF = VelocitySensor
		jref right_finger_joint = Prismatic {
			annotation Prismatic {
				axis = Axis {
					xyz = (|1,0,0|)
					dynamics = Dynamics { damping = 20.0 }
					limit = Limit { lower = 0.0 upper = STROKE velocity = 0.1 effort = 140 }
				}
			}
			aref RFM = ServoMotor {
				instantiation Kp = 10000.0
				instantiation Kd = 200.0
				relation right_finger_joint.tau == RFM.T
			}
			flexibly connected to right_finger
			pose { x = HALF_MIN_WIDTH + FINGER_THICKNESS/2 y = 0.0 z = BODY_HEIGHT roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		sref PSRF = PositionSensor
		sref VSRF = VelocitySensor
		pose { x = 0.0 y = 0.0 z = 0.0 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link left_finger {
		def {
			inertial information {
				mass 0.05 kg
			}
		}
		local body left_pad {
			def {
				box ( length = FINGER_THICKNESS , width = 0.032 , height = FINGER_HEIGHT )
			}
			pose { x = 0.0 y = 0.0 z = FINGER_HEIGHT/2 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = -(HALF_MIN_WIDTH + FINGER_THICKNESS/2) y = 0.0 z = BODY_HEIGHT roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link right_finger {
		def {
			inertial information {
				mass 0.05 kg
			}
		}
		local body right_pad {
			def {
				box ( length = FINGER_THICKNESS , width = 0.032 , height = FINGER_HEIGHT )
			}
			pose { x = 0.0 y = 0.0 z = FINGER_HEIGHT/2 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = HALF_MIN_WIDTH + FINGER_THICKNESS/2 y = 0.0 z = BODY_HEIGHT roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}
}
