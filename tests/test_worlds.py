"""What any mobile robot gets, on our own small models: ray sensors casting beams in a world, worlds read
strictly, a free base placed on the floor and its contacts with obstacles recorded, and the readings the
tree builder takes of defective p-models (a wheel turning off its centre, an impossible inertia, a mesh
nobody published)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cotwin.diagnostics import Severity
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import StandIn, build_tree, transform
from cotwin.pmodel.world import Obstacle, World, _corners, load_world, lowest_point
from cotwin.robosim.check import load_checked

MODELS = Path(__file__).parent / "models" / "pmodel"

CART = """
import physmod::SKO::joints::Revolute_y
import physmod::trivial::actuators::ControlledMotor

pmodel Cart {
	local link Base {
		def { }
		local body Frame {
			def {
				box(length = 0.2, width = 0.12, height = 0.05)
				inertial information { mass 1.0 inertia matrix { ixx MOMENT ixy 0 ixz 0 iyy MOMENT iyz 0 izz MOMENT } }
			}
			pose { x = 0 y = 0 z = 0.06 roll = 0 pitch = 0 yaw = 0 }
		}
		local body Skid {
			def {
				mesh { shape "meshes/skid.stl" scaling 1 }
				inertial information { mass 0.01 }
			}
			pose { x = -0.09 y = 0 z = 0.0 roll = 0 pitch = 0 yaw = 0 }
		}
		jref LeftJoint = Revolute_y {
			flexibly connected to LeftWheel
			pose { x = 0 y = 0.08 z = AXLE roll = 0 pitch = 0 yaw = 0 }
			aref LeftMotor = ControlledMotor { }
		}
		jref RightJoint = Revolute_y {
			flexibly connected to RightWheel
			pose { x = 0 y = -0.08 z = AXLE roll = 0 pitch = 0 yaw = 0 }
			aref RightMotor = ControlledMotor { }
		}
		pose { x = 0 y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 }
	}
	local link LeftWheel {
		def { }
		local body Tyre {
			def { cylinder(radius = 0.04, length = 0.02) inertial information { mass 0.05 } }
			pose { x = 0 y = 0 z = 0 roll = 1.5707963267948966 pitch = 0 yaw = 0 }
		}
		pose { x = 0 y = 0.08 z = 0.04 roll = 0 pitch = 0 yaw = 0 }
	}
	local link RightWheel {
		def { }
		local body Tyre {
			def { cylinder(radius = 0.04, length = 0.02) inertial information { mass 0.05 } }
			pose { x = 0 y = 0 z = 0 roll = 1.5707963267948966 pitch = 0 yaw = 0 }
		}
		pose { x = 0 y = -0.08 z = 0.04 roll = 0 pitch = 0 yaw = 0 }
	}
}
"""


def _cart(tmp_path: Path, axle: float = 0.04, moment: float = 0.004, stand_ins=None):
    (tmp_path / "cart.pm").write_text(CART.replace("AXLE", repr(axle)).replace("MOMENT", repr(moment)))
    return build_tree(load_checked([tmp_path / "cart.pm"]), stand_ins=stand_ins)


def _warnings(tree) -> list[str]:
    return [f"{f.location.line}: {f.message}" for f in tree.findings if f.severity is Severity.WARNING]


def test_a_wheel_turning_off_its_centre_is_moved_onto_it_with_a_located_warning(tmp_path):
    tree = _cart(tmp_path, axle=0.025)
    joints = {j.name: j for j in tree.joints}
    assert joints["LeftJoint"].pose[:3, 3] == pytest.approx([0, 0.08, 0.04])  # through the tyre's centre
    assert any(w.startswith("22: joint LeftJoint turns LeftWheel by speed (a wheel) about an axis 15 mm")
               for w in _warnings(tree)), _warnings(tree)
    centred = _cart(tmp_path, axle=0.04)
    assert not any("a wheel" in w for w in _warnings(centred))


def test_an_inertia_no_body_of_its_geometry_can_have_is_replaced(tmp_path):
    heavy = _cart(tmp_path, moment=0.5)  # 1 kg within 11.9 cm of its centre: at most 0.014 kg m^2
    assert any(w.startswith("11: inertia of body Frame is beyond what its geometry allows") for w in _warnings(heavy))
    base = heavy.link("Base")
    assert np.linalg.eigvalsh(base.inertia).max() < 0.02
    plausible = _cart(tmp_path, moment=0.004)
    assert not any("beyond" in w for w in _warnings(plausible))
    assert plausible.link("Base").inertia[2, 2] > 0.004  # the given one, moved to the link's centre of mass


def test_a_mesh_nobody_published_gets_the_projects_stand_ins(tmp_path):
    plain = _cart(tmp_path)
    skid = next(g for g in plain.link("Base").geoms if g.written == "meshes/skid.stl")
    assert skid.placeholder and not plain.stood_in
    ball = StandIn("sphere", {"radius": 0.01}, transform((0.0, 0.0, 0.01)), friction=0.0)
    stood = _cart(tmp_path, stand_ins={"meshes/skid.stl": [ball]})
    geoms = [g for g in stood.link("Base").geoms if g.written == "meshes/skid.stl"]
    assert stood.stood_in == {"meshes/skid.stl"} and [g.kind for g in geoms] == ["sphere"]
    assert geoms[0].pose[:3, 3] == pytest.approx([-0.09, 0, 0.01]) and not geoms[0].placeholder
    assert geoms[0].surface["friction"]["translational"]["coefficient1"] == 0.0
    assert lowest_point(stood) == pytest.approx(0.0)  # the wheels and the ball reach the same floor


def test_a_free_base_stands_on_the_floor_and_its_contacts_with_obstacles_are_recorded(tmp_path):
    ball = StandIn("sphere", {"radius": 0.01}, transform((0.0, 0.0, 0.01)), friction=0.0)
    tree = _cart(tmp_path, stand_ins={"meshes/skid.stl": [ball]})
    world = World("wall ahead", [Obstacle("box_1", "box", 0.6, 0.0, (0.1, 1.0, 0.3))], (0.0, 0.0, 0.0), (-2, 2, -2, 2))
    sim = PlatformSimulator(tree, world, base="free")
    sim.advance(0.5)
    x, y, z, yaw = sim.base_pose()
    assert abs(z) < 0.002 and abs(yaw) < 1e-3 and not sim.touches  # at rest on the floor, level
    sim.write_actuators({"LeftMotor": 10.0, "RightMotor": 10.0})  # 0.4 m/s straight into the box
    sim.advance(2.0)
    assert sim.touches and sim.touches[0][2] == "box_1" and 0.8 < sim.touches[0][0] < 2.0
    assert sim.base_pose()[0] == pytest.approx(0.55 - 0.1, abs=0.03)  # its front against the box's face
    sim.reset()
    assert not sim.touches and sim.base_pose()[0] == pytest.approx(0.0, abs=1e-9)


def test_sonars_cast_one_beam_each_the_way_they_face(tmp_path):
    rover = build_tree(load_checked([MODELS / "rover.pm"]))
    sonars = [s for s in rover.sensors if s.name.startswith("Sonar_")]
    assert {s.quantity for s in sonars} == {"range"}
    assert {(s.ray.samples, s.ray.range_max) for s in sonars} == {(1, 4.0)}
    world = World("", [Obstacle("box_1", "box", 1.1, 0.0, (0.2, 2.0, 0.3))], (0.0, 0.0, 0.0), (-5, 5, -5, 5))
    readings = PlatformSimulator(rover, world, base="free").read_sensors()
    assert readings["Rover::Base::Sonar_0.range"] == pytest.approx(1.0 - 0.1, abs=1e-6)  # x = 0.1 facing +x
    assert readings["Rover::Base::Sonar_2.range"] == math.inf  # facing -x: nothing within 4 m
    assert readings["Rover::Base::Sonar_1.range"] == math.inf  # facing +y: the box is ahead, not beside


def test_a_world_file_round_trip_geometry(tmp_path):
    path = tmp_path / "world.toml"
    path.write_text('name = "w"\n[arena]\nsize = [3.0, 2.0]\nwall_thickness = 0.1\n[start]\nx = -1.0\nyaw = 90\n'
                    '[[wall]]\nfrom = [0.0, -1.0]\nto = [0.0, 0.2]\n[[cylinder]]\nname = "post"\ncenter = [1.0, 0.5]\n'
                    'radius = 0.1\n[[box]]\ncenter = [1.0, -0.5]\nsize = [0.4, 0.2, 0.3]\nyaw = 90\n')
    world = load_world(path)
    names = [o.name for o in world.obstacles]
    assert names == ["arena_wall_1", "arena_wall_2", "arena_wall_3", "arena_wall_4", "wall_1", "box_1", "cylinder_post"]
    assert world.start == pytest.approx((-1.0, 0.0, math.pi / 2)) and world.extent() == (-1.5, 1.5, -1.0, 1.0)
    clearance = world.clearance(np.array([[0.5, -0.5], [1.0, 0.5], [-1.0, 0.0]]))
    assert clearance == pytest.approx([0.4, 0.0, 0.5])  # the box turned 90 deg; inside the post; the arena wall
    full = world.coverage(np.array([[-1.5, y] for y in np.linspace(-1, 1, 3)] + [[1.5, 1.0]]), 10.0)
    assert full == 1.0 and world.coverage(np.array([[-1.0, 0.0]]), 0.2) < 0.05


def test_a_robot_is_placed_by_the_posture_it_starts_in_not_by_its_zero_posture():
    """A joint whose limits exclude 0 starts at the limit nearest 0 (TJoint.start), but the world put the robot's
    lowest point on the floor as it is with every joint at 0: an arm started folded below its base (the shoulder
    at 3 rad) was placed as if upright, through the floor, and its footprint measured upright too."""
    tree = build_tree(load_checked([Path(__file__).parents[1] / "examples" / "ur5e" / "ur5e.pm"]))
    lift = next(j for j in tree.actuated if j.name == "shoulder_lift_joint")
    upright = lowest_point(tree)
    lift.lower, lift.upper = 3.0, 3.1
    assert lift.start == 3.0
    poses = tree.geom_poses({"shoulder_lift_joint": 3.0})
    folded = min(float(_corners(g, poses[g.name])[:, 2].min()) for l in tree.links for g in l.geoms if not g.placeholder)
    assert folded < upright - 0.5
    assert lowest_point(tree) == pytest.approx(folded)
