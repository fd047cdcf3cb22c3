// Joints of RoboTool's Featherstone formulation (spatial vectors, Featherstone's "Rigid Body Dynamics
// Algorithms"), as cotwin reads them: S is the motion subspace [angular; linear], X_T = XJ the joint
// transform, vJ = S qd the joint velocity and cJ its bias (zero for these one-degree joints).
package physmod::Featherstone::joints

import physmod::math::*

joint RevoluteJoint_X {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 1, 0, 0, 0, 0, 0 |)
	equation X_T == Xrot((| 1, 0, 0 |), q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint RevoluteJoint_Y {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 1, 0, 0, 0, 0 |)
	equation X_T == Xrot((| 0, 1, 0 |), q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint RevoluteJoint_Z {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 1, 0, 0, 0 |)
	equation X_T == Xrot((| 0, 0, 1 |), q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_X {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, 1, 0, 0 |)
	equation X_T == Xtrans((| q, 0, 0 |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_Y {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, 0, 1, 0 |)
	equation X_T == Xtrans((| 0, q, 0 |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_Z {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, 0, 0, 1 |)
	equation X_T == Xtrans((| 0, 0, q |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint RevoluteJoint_X_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| -1, 0, 0, 0, 0, 0 |)
	equation X_T == Xrot((| 1, 0, 0 |), -q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint RevoluteJoint_Y_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, -1, 0, 0, 0, 0 |)
	equation X_T == Xrot((| 0, 1, 0 |), -q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint RevoluteJoint_Z_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, -1, 0, 0, 0 |)
	equation X_T == Xrot((| 0, 0, 1 |), -q)
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_X_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, -1, 0, 0 |)
	equation X_T == Xtrans((| -q, 0, 0 |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_Y_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, 0, -1, 0 |)
	equation X_T == Xtrans((| 0, -q, 0 |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}

joint PrismaticJoint_Z_neg {
	InOut q: real
	InOut qd: real
	InOut qdd: real
	InOut tau: real
	InOut X_T: matrix(real, 6, 6)
	InOut XJ: matrix(real, 6, 6)
	InOut vJ: vector(real, 6)
	InOut cJ: vector(real, 6)
	const S: vector(real, 6) = (| 0, 0, 0, 0, 0, -1 |)
	equation X_T == Xtrans((| 0, 0, -q |))
	equation XJ == X_T
	equation vJ == S * qd
	equation cJ == (| 0, 0, 0, 0, 0, 0 |)
}
