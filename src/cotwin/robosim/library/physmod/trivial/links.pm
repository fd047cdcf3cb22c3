// Links of RoboTool's trivial formulation.
package physmod::trivial::links

link TrivialLink {
	const mass: real = 1.0
	const number: nat = 0
}
