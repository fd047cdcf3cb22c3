"""The kinematic tree of a p-model: the one intermediate form SDF, URDF, MJCF and the simulator share.

Its data and frames are cotwin.pmodel.kinematics; cotwin.pmodel.tree_build builds it from a checked
p-model (docs/pmodel-notation.md, sections 4 and 7). This module is their public face: neither of them
imports it.
"""

from __future__ import annotations

from .kinematics import (  # noqa: F401 (the tree's API)
    Geom, KinematicTree, PlacedDevice, Sensor, Servo, StandIn, TJoint, TLink, actuator_names, axis_angle,
    command_path, inverse, matrix_rpy, reading_path, rpy_matrix, servo_mode, servo_name, transform,
)
from .kinds import SENSOR_QUANTITIES, RaySpec, sensor_quantity  # noqa: F401
from .tree_build import build_tree  # noqa: F401
