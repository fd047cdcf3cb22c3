"""p-models in RoboTool's current notation: each construct family checked, and exported where it has
geometry (SDF, URDF and MJCF, the last loaded by MuJoCo). Models: tests/models/pmodel/."""

from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import Severity
from cotwin.pmodel.mjcf import to_mjcf
from cotwin.pmodel.sdf import to_sdf
from cotwin.pmodel.simulator import PlatformSimulator
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.urdf import to_urdf
from cotwin.robosim.check import check_paths, load_checked
from cotwin.robosim.parser import parse_text
from cotwin.robosim.project import library_packages

MODELS = Path(__file__).resolve().parent / "models" / "pmodel"


def _findings(result, severity):
    return [(f.location.line, f.message) for f in result.findings if f.severity is severity]


def _exports_load(tree):
    for text in (to_sdf(tree), to_sdf(tree, "robotool"), to_urdf(tree)):
        ET.fromstring(text)
    return mujoco.MjModel.from_xml_string(to_mjcf(tree))


@pytest.fixture(scope="module")
def rover():
    return load_checked([MODELS / "rover.pm"])


@pytest.fixture(scope="module")
def arm():
    return load_checked([MODELS / "arm.pm"])


def test_library_packages_under_robotool_and_cotwin_names():
    packages = {"::".join(k) for k in library_packages()}
    for name in ("physmod::sdf::annotations", "physmod::SKO::joints", "physmod::CGA::joints",
                 "physmod::Featherstone::joints", "physmod::trivial::actuators", "physmod::trivial::sensors",
                 "physmod::trivial::bodies", "physmod::trivial::links", "physmod::joints", "physmod::actuators",
                 "physmod::sensors", "physmod::math"):
        assert name in packages
    revolute_y = next(e for e in library_packages()[("physmod", "SKO", "joints")].source.elements
                      if getattr(e, "name", "") == "Revolute_y")
    assert revolute_y.port("H") is not None and revolute_y.port("theta").kind == "InOut"


def test_several_packages_in_one_file_import_each_other(rover):
    packages = {f.package.parts for f in rover.files if f.package is not None}
    assert {("rover_parts",), ("rover",)} <= packages
    assert rover.lookup("body", "rover_parts::WheelBody") is not None


def test_units_exponents_and_parameters_evaluate(rover):
    tree = build_tree(rover)
    assert tree.link("Base").pose[2, 3] == pytest.approx(0.05)  # 5cm
    left = tree.link("LeftWheel")
    assert left.pose[1, 3] == pytest.approx(0.08)  # (16)cm / 2
    assert left.mass == pytest.approx(0.028)  # 2.8e-2, from the body through bref
    tyre = left.geoms[0]
    assert (tyre.kind, tyre.size["radius"], tyre.size["length"]) == ("cylinder", pytest.approx(0.033), pytest.approx(0.018))
    assert tyre.surface["restitution"] == pytest.approx(0.1) and tyre.surface["threshold"] == pytest.approx(1e5)
    result = check_paths([MODELS / "rover.pm"])
    assert any("SPEED_LIMIT" in m and "no value" in m for _, m in _findings(result, Severity.WARNING))
    assert not _findings(result, Severity.ERROR)


def test_named_units_and_unit_declarations(tmp_path):
    (tmp_path / "units.pm").write_text(
        "package units\nprimitive unit metre\nprimitive unit second\n"
        "pmodel U {\n  local d : real\n  equation d == 1.0 metre + derivative(d)\n"
        "  local link L { def { inertial information { mass 2 kilogram } }\n"
        "    pose { x=0.5 metre y=(10)cm z=90 degree roll=0 pitch=0 yaw=0 }\n"
        "    local body B { def { box(length=0.1 metres, width=0.1, height=0.1) } } }\n}\n")
    result = check_paths([tmp_path])
    assert not _findings(result, Severity.ERROR)
    assert not any("derivative" in m for _, m in _findings(result, Severity.WARNING))
    link = build_tree(load_checked([tmp_path])).link("L")
    assert link.pose[0, 3] == pytest.approx(0.5) and link.pose[1, 3] == pytest.approx(0.1)
    assert link.pose[2, 3] == pytest.approx(math.pi / 2) and link.mass == pytest.approx(2.0)


def test_caret_is_a_power_in_pmodels(tmp_path):
    (tmp_path / "power.pm").write_text(
        "pmodel P {\n  const K : real = 2^3 + -2^2\n"
        "  local link L { def { inertial information { mass K } }\n"
        "    pose { x=2^-1 y=0 z=0 roll=0 pitch=0 yaw=0 } } }\n")
    link = build_tree(load_checked([tmp_path])).link("L")
    assert link.pose[0, 3] == pytest.approx(0.5)
    assert link.mass == pytest.approx(12.0)  # 2^3 + (-2)^2: `^` sits at RoboChart's `cat` level, above unary minus


def test_let_and_the_bind_as_in_robochart_in_pmodel_constants(tmp_path):
    """A p-model's constants take RoboChart's levels too: `let a == 2 @ a + 0 == a` is `(let a == 2 @ a + 0) == a`,
    the second a the constant 10 (cotwin read 2 + 0 == 2, true), and `2 == the k: int | k in {2} @ k` is read
    (a syntax error before)."""
    (tmp_path / "levels.pm").write_text(
        "pmodel P {\n  const a : real = 10\n  const M : real = if let a == 2 @ a + 0 == a then 1 else 5 end\n"
        "  const X : real = if 2 == the k: int | k in {2, 3} /\\ k < 3 @ k then 0.25 else 0.5 end\n"
        "  local link L { def { inertial information { mass M } }\n"
        "    pose { x=X y=0 z=0 roll=0 pitch=0 yaw=0 } } }\n")
    link = build_tree(load_checked([tmp_path])).link("L")
    assert link.mass == pytest.approx(5.0) and link.pose[0, 3] == pytest.approx(0.25)


def test_dollar_names_a_constant_and_its_field_in_pmodels(tmp_path):
    """RoboSim's `$v` and `$p.f` (SimRefExp on a name with a value: the value, its field) in a p-model's constants
    and poses (cotwin refused `$p.f` and could not evaluate `$v` there)."""
    (tmp_path / "dollar.pm").write_text(
        "datatype Dim { w: real h: real }\npmodel P {\n  const D : Dim = Dim(|w = 0.5, h = 2.0|)\n"
        "  const K : real = $D.h * 3\n  local link L { def { inertial information { mass $K } }\n"
        "    pose { x=$D.w y=0 z=0 roll=0 pitch=0 yaw=0 } } }\n")
    link = build_tree(load_checked([tmp_path])).link("L")
    assert link.mass == pytest.approx(6.0) and link.pose[0, 3] == pytest.approx(0.5)


def test_declarations_directly_in_a_joints_block(tmp_path):
    """RoboTool's serializer writes `local number : real = 3` directly in a jref's block (its FourBarPlanarLinkage
    case study's eqnComp-gen output), outside `def`: read as the joint's own declarations, seen by its relations
    (a syntax error before)."""
    (tmp_path / "j.pm").write_text(
        "import physmod::joints::*\npmodel P {\n  local link A { def { inertial information { mass 1.0 } }\n"
        "    jref J = Revolute { flexibly connected to B\n      local number : real = 3\n      relation number == 3\n"
        "      pose { x=0 y=0 z=0.5 roll=0 pitch=0 yaw=0 } } }\n"
        "  local link B { def { inertial information { mass 1.0 } } } }\n")
    result = check_paths([tmp_path])
    assert not _findings(result, Severity.ERROR) and not _findings(result, Severity.WARNING)
    [joint] = build_tree(load_checked([tmp_path])).joints
    assert (joint.name, joint.kind) == ("J", "revolute")


def test_joints_from_the_sko_library_and_local_definitions(rover):
    tree = build_tree(rover)
    joints = {j.name: j for j in tree.joints}
    for name in ("Left", "Right"):
        assert joints[name].kind == "revolute"
        assert joints[name].axis == pytest.approx([0, 1, 0])  # from H = (|0,1,0,0,0,0|)
    assert (joints["Left"].servos[0].mode, joints["Left"].servos[0].port) == ("velocity", "ControlIn")
    assert (joints["Right"].servos[0].mode, joints["Right"].servos[0].port) == ("velocity", "speed")


def test_index_replicates_sensors_and_links(rover, arm):
    tree = build_tree(rover)
    sonars = [d for d in tree.devices if d.name.startswith("Sonar_")]
    assert [d.name for d in sonars] == ["Sonar_0", "Sonar_1", "Sonar_2", "Sonar_3"]  # [0, 4): 4 is excluded
    yaws = [np.arctan2(d.pose[1, 0], d.pose[0, 0]) for d in sonars]
    assert yaws == pytest.approx([0, np.pi / 2, np.pi, -np.pi / 2])
    hand = build_tree(arm, "Hand")
    segments = [l for l in hand.links if l.name.endswith("-Segment")]
    assert [l.name for l in segments] == ["1-Segment", "2-Segment", "3-Segment"]  # [1, 3]: 3 is included
    assert [l.pose[2, 3] for l in segments] == pytest.approx([0.02, 0.04, 0.06])


def test_sdf_sensors_and_surfaces(rover, arm):
    model = ET.fromstring(to_sdf(build_tree(rover))).find("model")
    sensors = {s.get("name"): s for s in model.iter("sensor")}
    # RoboTool's names: `Sonar::1` for a replica of an indexed sensor
    assert sensors["Sonar::1"].get("type") == "sonar" and sensors["Gyro"].get("type") == "imu"
    assert sensors["Sonar::1"].find("sonar/radius").text == "0.01"  # `_radius` written as <radius>
    assert sensors["Sonar::1"].find("update_rate").text == "10"
    bounce = model.find("link[@name='LeftWheel']/collision/surface/bounce")
    assert float(bounce.find("restitution_coefficient").text) == pytest.approx(0.1)
    hand = ET.fromstring(to_sdf(build_tree(arm, "Hand"))).find("model")
    pad = hand.find("link[@name='Palm']/collision[@name='Pad_collision']")
    assert float(pad.find("laser_retro").text) == 0.5
    assert float(pad.find("surface/friction/ode/mu").text) == 1.5
    assert float(pad.find("surface/friction/torsional/coefficient").text) == 0.2


def test_robotool_sdf_naming(arm):
    tree = build_tree(arm, "Hand")
    model = ET.fromstring(to_sdf(tree, "robotool")).find("model")
    links = [l.get("name") for l in model.findall("link")]
    # parts' links first, numbered, without their part's name; then the p-model's own links
    assert links == ["1-Knuckle", "2-Tip", "3-Palm", "4-Segment", "5-Segment", "6-Segment"]
    joints = [j.get("name") for j in model.findall("joint")]
    # joints after links, a part's first, fixed connections after joints
    assert joints[:2] == ["7-Bend", "8-fixedJoint"]
    assert model.find("self_collide").text == "true"
    collision = model.find("link[@name='3-Palm']/collision")
    assert collision.get("name").endswith("--Palm_shape0") or "--" in collision.get("name")
    assert collision.find("surface/bounce/threshold").text == "100000"  # RoboTool's default surface


def test_parts_with_part_level_connections(arm):
    tree = build_tree(arm, "Hand")
    joints = {j.name: j for j in tree.joints}
    # a part's links and joints keep their names where nothing else has them (RoboTool's)
    # `link Knuckle fixed to Palm` (RoboTool writes the part's link as the parent), followed from the base
    fixed = joints["Knuckle_to_Palm"]
    assert (fixed.kind, fixed.parent, fixed.flipped) == ("fixed", "Palm", True)
    sdf = ET.fromstring(to_sdf(tree)).find("model/joint[@name='Knuckle_to_Palm']")
    assert (sdf.findtext("parent"), sdf.findtext("child")) == ("Knuckle", "Palm")
    bend = joints["Bend"]  # `joint Bend flexibly connected to Tip in Thumb`, in the part
    assert (bend.kind, bend.child) == ("revolute", "Tip") and bend.axis == pytest.approx([1, 0, 0])
    assert bend.servos[0].kp == 20 and bend.servos[0].mode == "position"
    assert tree.link("Tip").pose[2, 3] == pytest.approx(0.05 + 0.04)  # LENGTH instantiated as 4cm
    assert tree.link("Tip").part == "Thumb"
    _exports_load(tree)


def test_closed_chain_is_exported_with_its_loop(arm):
    tree = build_tree(arm, "FourBar")
    assert [j.name for j in tree.loops] == ["DA"]
    sdf = ET.fromstring(to_sdf(tree)).find("model")
    assert len(sdf.findall("joint")) == 4  # SDF states loops
    assert "closes a kinematic loop" in to_urdf(tree)
    model = _exports_load(tree)
    assert model.neq == 1 and model.eq_type[0] == mujoco.mjtEq.mjEQ_CONNECT
    sim = PlatformSimulator(tree)
    sim.advance(0.2)
    world = {n: sim.body_pose(n) for n in "AD"}
    anchor_a = world["A"] @ np.array([-0.2, 0, 0, 1.0])  # DA's anchor is A's far end
    anchor_d = world["D"] @ np.array([0, -0.2, 0, 1.0])
    assert np.linalg.norm(anchor_a - anchor_d) < 1e-3


def test_meshes_present_missing_and_unreadable(tmp_path):
    triangles = [((0, 0, 0), (10, 0, 0), (0, 20, 0)), ((0, 0, 0), (0, 20, 0), (0, 0, 30)),
                 ((0, 0, 0), (0, 0, 30), (10, 0, 0)), ((10, 0, 0), (0, 0, 30), (0, 20, 0))]
    data = b"cotwin test tetrahedron".ljust(80, b" ") + struct.pack("<I", len(triangles))
    for tri in triangles:
        data += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v) for v in tri) + b"\0\0"
    (tmp_path / "tet.stl").write_bytes(data)
    (tmp_path / "m.pm").write_text("""pmodel M {
	local link L {
		def { inertial information { mass 1 } }
		local body Tet { def { mesh { shape "tet.stl" scaling 0.01 } } }
		local body Lost { def { mesh { shape "nowhere/lost.stl" scaling 0.001 } } }
	}
}
""")
    result = check_paths([tmp_path])
    warnings = _findings(result, Severity.WARNING)
    assert any(line == 5 and "'nowhere/lost.stl'" in m and "not found" in m for line, m in warnings)
    assert not _findings(result, Severity.ERROR)
    tree = build_tree(load_checked([tmp_path]))
    tet, lost = tree.link("L").geoms
    assert tet.kind == "mesh" and (tet.size["length"], tet.size["width"], tet.size["height"]) == pytest.approx((0.1, 0.2, 0.3))
    assert lost.placeholder and lost.kind == "sphere"
    model = _exports_load(tree)
    assert model.nmesh == 1
    assert model.geom("Lost").contype == 0 and model.geom("Lost").conaffinity == 0  # shown, never collides
    sdf = ET.fromstring(to_sdf(tree)).find("model/link")
    assert sdf.find("collision[@name='Tet_collision']/geometry/mesh/scale").text == "0.01 0.01 0.01"
    assert sdf.find("collision[@name='Lost_collision']") is None and sdf.find("visual[@name='Lost_visual']") is not None


@pytest.mark.parametrize("text, line, message", [
    ("pmodel P { lref L = Nowhere { } }", 1, "unknown link definition 'Nowhere' for lref L"),
    ("pmodel P { local link L { def { } bref B = Nowhere { } } }", 1, "unknown body definition 'Nowhere' for bref B"),
    ("pmodel P { local link L {\n def { inertial information { mass 1 } }\n local body B { def { inertial information { mass 1 } } } } }",
     2, "link L has inertial information and so does its body B: give it once (RoboTool's rule L2)"),
    ("pmodel P { local link L { def { } local joint J { def { } flexibly connected to Q } } }", 1,
     "joint J: unknown child link 'Q'"),
    ("pmodel P { local link L { def { } fixed to L } }", 1, "link L is fixed to itself"),
    ("pmodel P { local link L { index i : [0, 1.5) def { } } }", 1, "index bounds of link L must be integers, is 1.5"),
    ("pmodel P { part Q = Nowhere { } }", 1, "unknown p-model 'Nowhere' for part Q"),
    ("pmodel P { local link L { def { } local sensor S { def { } instantiation K = 1 } } }", 1,
     "sensor S has no constant 'K' (sensor S)"),
])
def test_reference_errors_are_located(text, line, message, tmp_path):
    (tmp_path / "p.pm").write_text(text)
    errors = _findings(check_paths([tmp_path]), Severity.ERROR)
    assert (line, message) in errors


def test_solver_generated_forms_are_read():
    text = """package Gen
pmodel Gen {
	local link L1 {
		def {
			InOut geom_1 : Geom = Geom (| geomType = "box" , geomVal = [| 0.1 , 0.1 |] |)
			InOut M_1 : matrix ( real , 2 , 2 ) = [| 1 , 0 ; 0 , 1 |]
			local number : real = 1
			equation submatrix ( M_1 ) ( 0 , 0 , 1 , 1 ) == M_1 ^ 2
			Constraint ( M_1 ) [ t == 0 ] == (| 1, 0; 0, 1 |)
			inertial information { mass 1.0 inertia matrix { ixx 0.1 ixy 0 ixz 0 iyy 0.1 iyz 0 izz 0.1 } }
		}
		relation M_1 == L1 . M_1
	}
	InOut B_k : Seq( matrix ( real , 4 , 4 ) )
	equation B_k == < B_1 >
}
datatype Geom { geomType : string geomVal : vector ( real ) }
function submatrix ( m : matrix ( real , 2 , 2 ) ) : matrix ( real , 2 , 2 ) { }
endpackage
"""
    source, findings = parse_text(text, "gen.pm")
    assert source is not None and not [f for f in findings if f.severity is Severity.ERROR]


def test_featherstone_end_closed_joints_and_cga_axes():
    text = """import physmod::CGA::joints::*
import physmod::Featherstone::joints::*
pmodel P {
	local link A { def { inertial information { mass 1 } }
		jref J1 = RevoluteJoint_CGA { flexibly connected to B }
		jref J2 = PrismaticJoint_Y_neg { flexibly connected to C } }
	local link B { def { inertial information { mass 1 } } }
	local link C { def { inertial information { mass 1 } } }
}
joint Local {
	InOut q : real
end
"""
    source, findings = parse_text(text, "f.pm")
    assert source is not None and not findings
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="cotwin-"))
    (folder / "f.pm").write_text(text)
    tree = build_tree(load_checked([folder]))
    joints = {j.name: j for j in tree.joints}
    assert (joints["J1"].kind, list(joints["J1"].axis)) == ("revolute", [0, 1, 0])  # axis_rot's default
    assert (joints["J2"].kind, list(joints["J2"].axis)) == ("prismatic", [0, -1, 0])  # S = (|0,0,0,0,-1,0|)


def test_published_turtlebot_is_read_exported_and_driven(published):
    path = published / "mobile" / "Turtlebot3_Burger.pm"
    result = check_paths([path])
    assert not _findings(result, Severity.ERROR)
    assert any("burger_base.stl" in m for _, m in _findings(result, Severity.WARNING))  # not published
    tree = build_tree(load_checked([path]))
    _exports_load(tree)
    wheels = [j for j in tree.joints if j.kind == "revolute"]
    assert [list(j.axis) for j in wheels] == [[0, 1, 0], [0, 1, 0]]
    assert {j.servos[0].mode for j in wheels} == {"velocity"}

    from cotwin.pmodel.scenes import SceneBase

    class Floor(SceneBase):  # a scene of the test's own (the Scene protocol's defaults, a plane to drive on)
        def add_to(self, worldbody):
            ET.SubElement(worldbody, "geom", name="floor", type="plane", size="5 5 0.1", contype="1", conaffinity="3")

    sim = PlatformSimulator(tree, Floor(), base="free")
    start = sim.body_pose("BaseLink")[:3, 3].copy()
    command = "Turtlebot3_Burger::BaseLink::{0}WheelJoint::{0}Motor.ControlIn"  # the mapping's paths
    sim.write_actuators({command.format("Left"): 4.0, command.format("Right"): 4.0})
    sim.advance(1.0)
    speeds = sim.joint_velocities()
    assert speeds["LeftWheelJoint"] == pytest.approx(speeds["RightWheelJoint"], rel=0.05) and speeds["LeftWheelJoint"] > 3
    assert sim.body_pose("BaseLink")[0, 3] - start[0] > 0.05  # rolled forward along x
    lidar, base = "Turtlebot3_Burger::BaseLink::TBLidar", "Turtlebot3_Burger::BaseLink"
    assert set(sim.read_sensors()) == {"Turtlebot3_Burger::BaseLink::TBIMU.currentLV",
                                       "Turtlebot3_Burger::BaseLink::TBIMU.currentAV",
                                       f"{lidar}.closestDistance", f"{lidar}.closestAngle",
                                       *(f"{base}.{p}" for p in ("x", "y", "z", "yaw"))}
    assert sim.read_sensors()[f"{lidar}.closestDistance"] >= 0.12  # the LDS-01's shortest range (inf: nothing)
