"""p-model: kinematic tree, SDF/URDF/MJCF export, the MuJoCo platform simulator and the Scene seam."""
