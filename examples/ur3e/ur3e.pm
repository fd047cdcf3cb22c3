// cotwin example: a UR3e of our own, for where the paper's published ur3e_gripper.pm (in
// ../shared/robosim/ur3e) is not at hand: the same model name, link, joint and sensor names (so
// examples/ur3e/mapping.pm reads either), its dimensions the UR3e's published kinematic parameters
// (d1, a2, a3, d4, d5, d6) and link masses, built as examples/ur5e/ur5e.pm is (zero configuration:
// the arm straight up). Like the published model it carries no gripper.
import physmod::joints::*
import physmod::actuators::*

sensor ForceSensor {
	input input_force: real
	output output_force: real
	equation input_force == output_force
}

sensor TorqueSensor {
	input input_torque: real
	output output_torque: real
	equation input_torque == output_torque
}

sensor VelocitySensor {
	input input_vel: real
	output output_vel: real
	equation input_vel == output_vel
}

sensor AngularPositionSensor {
	input input_angle: real
	output output_angle: real
	equation input_angle == output_angle
}

pmodel ur3e_gripper {
	const PI: real = 3.14159265358979
	const D1: real = 0.15185
	const A2: real = 0.24355
	const A3: real = 0.2132
	const D4: real = 0.13105
	const D5: real = 0.08535
	const D6: real = 0.0921
	const SHOULDER_OFFSET: real = 0.12
	const ELBOW_OFFSET: real = 0.093
	const MASS_BASE: real = 2.0
	const MASS_SHOULDER: real = 1.98
	const MASS_UPPER_ARM: real = 3.4445
	const MASS_FOREARM: real = 1.437
	const MASS_WRIST_1: real = 0.871
	const MASS_WRIST_2: real = 0.805
	const MASS_WRIST_3: real = 0.261

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
		sref APSJ1 = AngularPositionSensor
		sref VSJ1 = VelocitySensor
		sref TSJ1 = TorqueSensor
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
		sref APSJ2 = AngularPositionSensor
		sref VSJ2 = VelocitySensor
		sref TSJ2 = TorqueSensor
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
		sref APSJ3 = AngularPositionSensor
		sref VSJ3 = VelocitySensor
		sref TSJ3 = TorqueSensor
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
		sref APSJ4 = AngularPositionSensor
		sref VSJ4 = VelocitySensor
		sref TSJ4 = TorqueSensor
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
		sref APSJ5 = AngularPositionSensor
		sref VSJ5 = VelocitySensor
		sref TSJ5 = TorqueSensor
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
		sref APSJ6 = AngularPositionSensor
		sref VSJ6 = VelocitySensor
		sref TSJ6 = TorqueSensor
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
}
