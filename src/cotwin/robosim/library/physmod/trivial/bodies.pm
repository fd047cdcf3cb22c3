// Bodies of RoboTool's trivial formulation: a 10 cm cube of 1 kg.
package physmod::trivial::bodies

body TrivialBody {
	inertial information {
		mass 1.0
		inertia matrix { ixx 0.1 ixy 0.0 ixz 0.0 iyy 0.1 iyz 0.0 izz 0.1 }
	}
	box(length = 0.1, width = 0.1, height = 0.1)
}
