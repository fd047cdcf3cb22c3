// RoboSim p-model of the robot 'panda', imported by cotwin import-urdf from example-robot-data's panda.urdf (its
// collision meshes kept under meshes/collision; its visual meshes and their `annotation Visual` left out).
// Link poses are the URDF link frames at zero joint values, in the model frame; joint poses are the URDF joint
// origins, relative to the parent link. Each moving joint has a position servo and position, velocity, effort sensors.
import physmod::joints::*
import physmod::actuators::*
import physmod::sensors::*

pmodel panda {
	local link panda_link0 {
		def {
			inertial information {
				mass 0.629769 kg
				inertia matrix { ixx = 0.00315 ixy = 8.2904e-07 ixz = 0.00015 iyy = 0.00388 iyz = 8.2299e-06 izz = 0.004285 }
				pose { x = -0.041018 y = -0.00014 z = 0.049974 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link0_collision {
			def {
				mesh { shape "meshes/collision/link0.stl" scaling 1.0 }
			}
		}
		jref panda_joint1 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -2.8973 upper = 2.8973 velocity = 2.175 effort = 87.0 }
				}
			}
			aref panda_joint1_motor = ServoMotor { relation panda_joint1.tau == panda_joint1_motor.T }
			sref panda_joint1_position = PositionSensor
			sref panda_joint1_velocity = VelocitySensor
			sref panda_joint1_effort = TorqueSensor
			flexibly connected to panda_link1
			pose { x = 0.0 y = 0.0 z = 0.333 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
	}

	local link panda_link1 {
		def {
			inertial information {
				mass 4.970684 kg
				inertia matrix { ixx = 0.70337 ixy = -0.000139 ixz = 0.006772 iyy = 0.70661 iyz = 0.019169 izz = 0.009117 }
				pose { x = 0.003875 y = 0.002081 z = -0.04762 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link1_collision {
			def {
				mesh { shape "meshes/collision/link1.stl" scaling 1.0 }
			}
		}
		jref panda_joint2 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -1.7628 upper = 1.7628 velocity = 2.175 effort = 87.0 }
				}
			}
			aref panda_joint2_motor = ServoMotor { relation panda_joint2.tau == panda_joint2_motor.T }
			sref panda_joint2_position = PositionSensor
			sref panda_joint2_velocity = VelocitySensor
			sref panda_joint2_effort = TorqueSensor
			flexibly connected to panda_link2
			pose { x = 0.0 y = 0.0 z = 0.0 roll = -1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = 0.0 z = 0.333 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link2 {
		def {
			inertial information {
				mass 0.646926 kg
				inertia matrix { ixx = 0.007962 ixy = -0.003925 ixz = 0.010254 iyy = 0.02811 iyz = 0.000704 izz = 0.025995 }
				pose { x = -0.003141 y = -0.02872 z = 0.003495 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link2_collision {
			def {
				mesh { shape "meshes/collision/link2.stl" scaling 1.0 }
			}
		}
		jref panda_joint3 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -2.8973 upper = 2.8973 velocity = 2.175 effort = 87.0 }
				}
			}
			aref panda_joint3_motor = ServoMotor { relation panda_joint3.tau == panda_joint3_motor.T }
			sref panda_joint3_position = PositionSensor
			sref panda_joint3_velocity = VelocitySensor
			sref panda_joint3_effort = TorqueSensor
			flexibly connected to panda_link3
			pose { x = 0.0 y = -0.316 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = 0.0 z = 0.333 roll = -1.5707963267948966 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link3 {
		def {
			inertial information {
				mass 3.228604 kg
				inertia matrix { ixx = 0.037242 ixy = -0.004761 ixz = -0.011396 iyy = 0.036155 iyz = -0.012805 izz = 0.01083 }
				pose { x = 0.027518 y = 0.039252 z = -0.066502 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link3_collision {
			def {
				mesh { shape "meshes/collision/link3.stl" scaling 1.0 }
			}
		}
		jref panda_joint4 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -3.0718 upper = -0.0698 velocity = 2.175 effort = 87.0 }
				}
			}
			aref panda_joint4_motor = ServoMotor { relation panda_joint4.tau == panda_joint4_motor.T }
			sref panda_joint4_position = PositionSensor
			sref panda_joint4_velocity = VelocitySensor
			sref panda_joint4_effort = TorqueSensor
			flexibly connected to panda_link4
			pose { x = 0.0825 y = 0.0 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = -1.934941942652818e-17 z = 0.649 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link4 {
		def {
			inertial information {
				mass 3.587895 kg
				inertia matrix { ixx = 0.025853 ixy = 0.007796 ixz = -0.001332 iyy = 0.019552 iyz = 0.008641 izz = 0.028323 }
				pose { x = -0.05317 y = 0.104419 z = 0.027454 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link4_collision {
			def {
				mesh { shape "meshes/collision/link4.stl" scaling 1.0 }
			}
		}
		jref panda_joint5 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -2.8973 upper = 2.8973 velocity = 2.61 effort = 12.0 }
				}
			}
			aref panda_joint5_motor = ServoMotor { relation panda_joint5.tau == panda_joint5_motor.T }
			sref panda_joint5_position = PositionSensor
			sref panda_joint5_velocity = VelocitySensor
			sref panda_joint5_effort = TorqueSensor
			flexibly connected to panda_link5
			pose { x = -0.0825 y = 0.384 z = 0.0 roll = -1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0825 y = -1.934941942652818e-17 z = 0.649 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link5 {
		def {
			inertial information {
				mass 1.225946 kg
				inertia matrix { ixx = 0.035549 ixy = -0.002117 ixz = -0.004037 iyy = 0.029474 iyz = 0.000229 izz = 0.008627 }
				pose { x = -0.011953 y = 0.041065 z = -0.038437 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link5_collision {
			def {
				mesh { shape "meshes/collision/link5.stl" scaling 1.0 }
			}
		}
		jref panda_joint6 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -0.0175 upper = 3.7525 velocity = 2.61 effort = 12.0 }
				}
			}
			aref panda_joint6_motor = ServoMotor { relation panda_joint6.tau == panda_joint6_motor.T }
			sref panda_joint6_position = PositionSensor
			sref panda_joint6_velocity = VelocitySensor
			sref panda_joint6_effort = TorqueSensor
			flexibly connected to panda_link6
			pose { x = 0.0 y = 0.0 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = 4.163799117101001e-18 z = 1.033 roll = 0.0 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link6 {
		def {
			inertial information {
				mass 1.666555 kg
				inertia matrix { ixx = 0.001964 ixy = 0.000109 ixz = -0.001158 iyy = 0.004354 iyz = 0.000341 izz = 0.005433 }
				pose { x = 0.060149 y = -0.014117 z = -0.010517 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link6_collision {
			def {
				mesh { shape "meshes/collision/link6.stl" scaling 1.0 }
			}
		}
		jref panda_joint7 = Revolute {
			annotation Revolute {
				axis = Axis {
					xyz = (|0.0, 0.0, 1.0|)
					dynamics = Dynamics { damping = 0.003 _friction = 0.0 }
					limit = Limit { lower = -2.8973 upper = 2.8973 velocity = 2.61 effort = 12.0 }
				}
			}
			aref panda_joint7_motor = ServoMotor { relation panda_joint7.tau == panda_joint7_motor.T }
			sref panda_joint7_position = PositionSensor
			sref panda_joint7_velocity = VelocitySensor
			sref panda_joint7_effort = TorqueSensor
			flexibly connected to panda_link7
			pose { x = 0.088 y = 0.0 z = 0.0 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.0 y = 4.163799117101001e-18 z = 1.033 roll = 1.5707963267948966 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link7 {
		def {
			inertial information {
				mass 0.735522 kg
				inertia matrix { ixx = 0.012516 ixy = -0.000428 ixz = -0.001196 iyy = 0.010027 iyz = -0.000741 izz = 0.004815 }
				pose { x = 0.010517 y = -0.004252 z = 0.061597 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_link7_collision {
			def {
				mesh { shape "meshes/collision/link7.stl" scaling 1.0 }
			}
		}
		jref panda_joint8 = Fixed {
			flexibly connected to panda_link8
			pose { x = 0.0 y = 0.0 z = 0.107 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.088 y = 4.163799117101001e-18 z = 1.033 roll = 3.141592653589793 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_link8 {
		def {
			inertial information {
				mass 0.0 kg
				inertia matrix { ixx = 0.0 ixy = 0.0 ixz = 0.0 iyy = 0.0 iyz = 0.0 izz = 0.0 }
			}
		}
		jref panda_hand_joint = Fixed {
			flexibly connected to panda_hand
			pose { x = 0.0 y = 0.0 z = 0.0 roll = 0.0 pitch = 0.0 yaw = -0.7853981633974483 }
		}
		pose { x = 0.088 y = -8.939921633775679e-18 z = 0.9259999999999999 roll = 3.141592653589793 pitch = 0.0 yaw = 0.0 }
	}

	local link panda_hand {
		def {
			inertial information {
				mass 0.73 kg
				inertia matrix { ixx = 0.001 ixy = 0.0 ixz = 0.0 iyy = 0.0025 iyz = 0.0 izz = 0.0017 }
				pose { x = -0.01 y = 0.0 z = 0.03 roll = 0.0 pitch = 0.0 yaw = 0.0 }
			}
		}
		local body panda_hand_collision {
			def {
				mesh { shape "meshes/collision/hand.stl" scaling 1.0 }
			}
		}
		jref panda_hand_tcp_joint = Fixed {
			flexibly connected to panda_hand_tcp
			pose { x = 0.0 y = 0.0 z = 0.1034 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		jref panda_finger_joint1 = Prismatic {
			annotation Prismatic {
				axis = Axis {
					xyz = (|0.0, 1.0, 0.0|)
					dynamics = Dynamics { damping = 0.3 }
					limit = Limit { lower = 0.0 upper = 0.04 velocity = 0.2 effort = 100.0 }
				}
			}
			aref panda_finger_joint1_motor = ServoMotor { relation panda_finger_joint1.tau == panda_finger_joint1_motor.T }
			sref panda_finger_joint1_position = PositionSensor
			sref panda_finger_joint1_velocity = VelocitySensor
			sref panda_finger_joint1_effort = ForceSensor
			flexibly connected to panda_leftfinger
			pose { x = 0.0 y = 0.0 z = 0.0584 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		jref panda_finger_joint2 = Prismatic {
			annotation Prismatic {
				axis = Axis {
					xyz = (|0.0, -1.0, 0.0|)
					dynamics = Dynamics { damping = 0.3 }
					limit = Limit { lower = 0.0 upper = 0.04 velocity = 0.2 effort = 100.0 }
				}
			}
			annotation Mimic { leader = "panda_finger_joint1" multiplier = 1.0 offset = 0.0 }
			aref panda_finger_joint2_motor = ServoMotor { relation panda_finger_joint2.tau == panda_finger_joint2_motor.T }
			sref panda_finger_joint2_position = PositionSensor
			sref panda_finger_joint2_velocity = VelocitySensor
			sref panda_finger_joint2_effort = ForceSensor
			flexibly connected to panda_rightfinger
			pose { x = 0.0 y = 0.0 z = 0.0584 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.088 y = -8.939921633775679e-18 z = 0.9259999999999999 roll = 3.141592653589793 pitch = 8.659560562354932e-17 yaw = 0.7853981633974483 }
	}

	local link panda_hand_tcp {
		def {
			inertial information {
				mass 0.0 kg
				inertia matrix { ixx = 0.0 ixy = 0.0 ixz = 0.0 iyy = 0.0 iyz = 0.0 izz = 0.0 }
			}
		}
		pose { x = 0.088 y = -2.160276953695931e-17 z = 0.8225999999999999 roll = 3.141592653589793 pitch = 8.659560562354932e-17 yaw = 0.7853981633974483 }
	}

	local link panda_leftfinger {
		def {
			inertial information {
				mass 0.015 kg
				inertia matrix { ixx = 2.3749999999999997e-06 ixy = 0.0 ixz = 0.0 iyy = 2.3749999999999997e-06 iyz = 0.0 izz = 7.5e-07 }
			}
		}
		local body panda_leftfinger_collision_0 {
			def {
				box ( length = 0.022 , width = 0.015 , height = 0.02 )
			}
			pose { x = 0.0 y = 0.0185 z = 0.011 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_leftfinger_collision_1 {
			def {
				box ( length = 0.022 , width = 0.0088 , height = 0.0038 )
			}
			pose { x = 0.0 y = 0.0068 z = 0.0022 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_leftfinger_collision_2 {
			def {
				box ( length = 0.0175 , width = 0.007 , height = 0.0235 )
			}
			pose { x = 0.0 y = 0.0159 z = 0.02835 roll = 0.5235987755982988 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_leftfinger_collision_3 {
			def {
				box ( length = 0.0175 , width = 0.0152 , height = 0.0185 )
			}
			pose { x = 0.0 y = 0.00758 z = 0.04525 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.088 y = -1.609185894079622e-17 z = 0.8675999999999999 roll = 3.141592653589793 pitch = 8.659560562354932e-17 yaw = 0.7853981633974483 }
	}

	local link panda_rightfinger {
		def {
			inertial information {
				mass 0.015 kg
				inertia matrix { ixx = 2.3749999999999997e-06 ixy = 0.0 ixz = 0.0 iyy = 2.3749999999999997e-06 iyz = 0.0 izz = 7.5e-07 }
			}
		}
		local body panda_rightfinger_collision_0 {
			def {
				box ( length = 0.022 , width = 0.015 , height = 0.02 )
			}
			pose { x = 0.0 y = -0.0185 z = 0.011 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_rightfinger_collision_1 {
			def {
				box ( length = 0.022 , width = 0.0088 , height = 0.0038 )
			}
			pose { x = 0.0 y = -0.0068 z = 0.0022 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_rightfinger_collision_2 {
			def {
				box ( length = 0.0175 , width = 0.007 , height = 0.0235 )
			}
			pose { x = 0.0 y = -0.0159 z = 0.02835 roll = -0.5235987755982988 pitch = 0.0 yaw = 0.0 }
		}
		local body panda_rightfinger_collision_3 {
			def {
				box ( length = 0.0175 , width = 0.0152 , height = 0.0185 )
			}
			pose { x = 0.0 y = -0.00758 z = 0.04525 roll = 0.0 pitch = 0.0 yaw = 0.0 }
		}
		pose { x = 0.088 y = -1.609185894079622e-17 z = 0.8675999999999999 roll = 3.141592653589793 pitch = 8.659560562354932e-17 yaw = 0.7853981633974483 }
	}
}
