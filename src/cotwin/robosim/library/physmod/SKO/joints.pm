// Joints of RoboTool's SKO (spatial operator) formulation, as cotwin reads them. H is the joint's
// motion subspace as [angular; linear] columns, XJ its spatial transform for the joint coordinates.
// cotwin takes the joint type and axis from H; the equations are for RoboTool's solver.
package physmod::SKO::joints

import physmod::math::*

joint Revolute_x {
	const H: vector(real, 6) = (| 1, 0, 0, 0, 0, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 1, 0, 0 |), theta)
}

joint Revolute_y {
	const H: vector(real, 6) = (| 0, 1, 0, 0, 0, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 0, 1, 0 |), theta)
}

joint Revolute_z {
	const H: vector(real, 6) = (| 0, 0, 1, 0, 0, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 0, 0, 1 |), theta)
}

joint Prismatic_x {
	const H: vector(real, 6) = (| 0, 0, 0, 1, 0, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| theta, 0, 0 |))
}

joint Prismatic_y {
	const H: vector(real, 6) = (| 0, 0, 0, 0, 1, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, theta, 0 |))
}

joint Prismatic_z {
	const H: vector(real, 6) = (| 0, 0, 0, 0, 0, 1 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, 0, theta |))
}

// a screw of pitch h (m/rad): cotwin exports it as a revolute joint (the pitch is not modelled)
joint Helical_x {
	const h: real
	const H: vector(real, 6) = (| 1, 0, 0, h, 0, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| h * theta, 0, 0 |)) * Xrot((| 1, 0, 0 |), theta)
}

// a screw of pitch h (m/rad): cotwin exports it as a revolute joint (the pitch is not modelled)
joint Helical_y {
	const h: real
	const H: vector(real, 6) = (| 0, 1, 0, 0, h, 0 |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, h * theta, 0 |)) * Xrot((| 0, 1, 0 |), theta)
}

// a screw of pitch h (m/rad): cotwin exports it as a revolute joint (the pitch is not modelled)
joint Helical_z {
	const h: real
	const H: vector(real, 6) = (| 0, 0, 1, 0, 0, h |)
	InOut theta: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, 0, h * theta |)) * Xrot((| 0, 0, 1 |), theta)
}

joint Cylindrical_x {
	const H: matrix(real, 6, 2) = (| 1, 0; 0, 0; 0, 0; 0, 1; 0, 0; 0, 0 |)
	InOut q1: real
	InOut q2: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| q2, 0, 0 |)) * Xrot((| 1, 0, 0 |), q1)
}

joint Cylindrical_y {
	const H: matrix(real, 6, 2) = (| 0, 0; 1, 0; 0, 0; 0, 0; 0, 1; 0, 0 |)
	InOut q1: real
	InOut q2: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, q2, 0 |)) * Xrot((| 0, 1, 0 |), q1)
}

joint Cylindrical_z {
	const H: matrix(real, 6, 2) = (| 0, 0; 0, 0; 1, 0; 0, 0; 0, 0; 0, 1 |)
	InOut q1: real
	InOut q2: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xtrans((| 0, 0, q2 |)) * Xrot((| 0, 0, 1 |), q1)
}

joint Spherical {
	const H: matrix(real, 6, 3) = (| 1, 0, 0; 0, 1, 0; 0, 0, 1; 0, 0, 0; 0, 0, 0; 0, 0, 0 |)
	InOut q1: real
	InOut q2: real
	InOut q3: real
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 0, 0, 1 |), q1) * Xrot((| 0, 1, 0 |), q2) * Xrot((| 1, 0, 0 |), q3)
}

// two rotations, about x then about the rotated y: H's second column turns with q1
joint Universal_xy {
	InOut q1: real
	InOut q2: real
	InOut H: matrix(real, 6, 2)
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 1, 0, 0 |), q1) * Xrot((| 0, 1, 0 |), q2)
}

// two rotations, about y then about the rotated z: H's second column turns with q1
joint Universal_yz {
	InOut q1: real
	InOut q2: real
	InOut H: matrix(real, 6, 2)
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 0, 1, 0 |), q1) * Xrot((| 0, 0, 1 |), q2)
}

// two rotations, about z then about the rotated x: H's second column turns with q1
joint Universal_zx {
	InOut q1: real
	InOut q2: real
	InOut H: matrix(real, 6, 2)
	InOut XJ: matrix(real, 6, 6)
	equation XJ == Xrot((| 0, 0, 1 |), q1) * Xrot((| 1, 0, 0 |), q2)
}
