// cotwin's own platform mapping of the random walk (the paper's Fig. 17): `move(av, lv)` becomes the
// two wheel speeds of a differential drive, and the LiDAR's nearest return the two input events.
map WalkMapping dmodel RandomWalk::TurtleBotWalk to pmodel Turtlebot3_Burger {
	// wheel speed (rad/s) = (lv -/+ av * track / 2) / wheel radius, track 0.160 m, radius 0.033 m
	operation move {
		equation Turtlebot3_Burger::BaseLink::LeftWheelJoint::LeftMotor.ControlIn == (lv - av * 0.160 / 2) / 0.033
		equation Turtlebot3_Burger::BaseLink::RightWheelJoint::RightMotor.ControlIn == (lv + av * 0.160 / 2) / 0.033
	}

	input event closestDistance?closest_distance {
		equation closest_distance == Turtlebot3_Burger::BaseLink::TBLidar.closestDistance
	}

	input event closestAngle?closest_angle {
		equation closest_angle == Turtlebot3_Burger::BaseLink::TBLidar.closestAngle
	}
}
