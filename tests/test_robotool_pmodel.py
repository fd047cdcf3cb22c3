"""RoboTool parity, p-models: each rule of docs/pmodel-notation.md that RoboTool's physmod tools define (its SDF
generator's test data, UoY-RoboStar/pmodel-examples, and its metamodel-coverage models), on small models of
our own: how a model is read, how its kinematic tree is built and named, and the SDF RoboTool would write."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from cotwin.diagnostics import CotwinError, Severity
from cotwin.pmodel.mjcf import load, to_mjcf
from cotwin.pmodel.sdf import to_sdf
from cotwin.pmodel.tree import build_tree
from cotwin.pmodel.urdf import to_urdf
from cotwin.robosim.check import check_paths, load_checked

BOX = "local body B { def { box(length = 0.1, width = 0.1, height = 0.1) } }"


def _project(tmp_path, text: str, name: str = "m.pm"):
    (tmp_path / name).write_text(text)
    result = check_paths([tmp_path])
    return result


def _tree(tmp_path, text: str, pmodel: str | None = None):
    _project(tmp_path, text).raise_if_errors()
    return build_tree(load_checked([tmp_path]), pmodel)


def _messages(findings, severity=Severity.WARNING):
    return [f.message for f in findings if f.severity is severity]


def _sdf(tree, style="cotwin"):
    return ET.fromstring(to_sdf(tree, style)).find("model")


INDEXED = f"""pmodel Rig {{
	part p = Pod {{
		index i : [1, 2]
		pose {{ x = (i - 1.5) * 0.2 y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 }}
		joint Slide flexibly connected to Hub
	}}
	local link Hub {{ def {{ }} {BOX} pose {{ x = 0 y = 0 z = 0.2 roll = 0 pitch = 0 yaw = 0 }} }}
	local link Tip {{
		def {{ }} {BOX}
		index k : [1, 4]
		pose {{ x = 0 y = 0 z = 0 roll = 0 pitch = 0 yaw = k }}
	}}
	local link Base {{
		def {{ }} {BOX}
		local joint Spoke {{
			def {{ annotation Revolute {{ axis = Axis {{ xyz = (|0, 0, 1|) }} }} }}
			index j : [0, 3)
			pose {{ x = 0.1 * j y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 }}
			flexibly connected to Wheel
		}}
	}}
	local link Wheel {{ def {{ }} {BOX} index w : [1, 2] }}
}}
pmodel Pod {{
	local link Foot {{
		def {{ }} {BOX}
		local joint Slide {{ def {{ annotation Prismatic {{ axis = Axis {{ xyz = (|0, 0, 1|) }} }} }} }}
	}}
}}
"""


def test_index_replicates_links_parts_and_joints_in_every_position(tmp_path):
    tree = _tree(tmp_path, INDEXED)
    names = [l.name for l in tree.links]
    # a replica of an indexed link is `1-Tip` ... (the range inclusive at both ends), no joint between them
    assert {"1-Tip", "2-Tip", "3-Tip", "4-Tip"} <= set(names)
    assert not any("Tip" in (j.parent + j.child) for j in (*tree.joints, *tree.loops))
    assert tree.link("3-Tip").pose[:3, :3] == pytest.approx(np.array([[np.cos(3), -np.sin(3), 0],
                                                                       [np.sin(3), np.cos(3), 0], [0, 0, 1]]))
    # an indexed part: one instance per value, its link names scoped only because they clash
    assert {"1-p/Foot", "2-p/Foot"} <= set(names)
    assert tree.link("1-p/Foot").pose[0, 3] == pytest.approx(-0.1) and tree.link("2-p/Foot").part == "2-p"
    # a part clause's joint from an indexed part: one per instance, each to Hub
    slides = [j for j in (*tree.joints, *tree.loops) if j.source == "Slide"]
    assert sorted((j.parent, j.child, j.kind) for j in slides) == [("1-p/Foot", "Hub", "prismatic"),
                                                                  ("2-p/Foot", "Hub", "prismatic")]
    # an indexed joint to an indexed link: one per index value and per target replica, the index in its pose
    spokes = [j for j in (*tree.joints, *tree.loops) if j.source == "Spoke"]
    assert len(spokes) == 6 and {j.child for j in spokes} == {"1-Wheel", "2-Wheel"}
    assert sorted({round(j.pose[0, 3], 6) for j in spokes}) == [0.0, 0.1, 0.2]
    names = [j.name for j in (*tree.joints, *tree.loops)]
    assert len(set(names)) == len(names)  # unique, qualified where they would clash
    load(to_mjcf(tree), tree)


def test_a_clash_between_two_instances_is_a_finding_at_the_element(tmp_path):
    tree = _tree(tmp_path, INDEXED)
    clashes = [f for f in tree.findings if "has the name of another link" in f.message]
    assert {f.location.line for f in clashes} == {INDEXED.splitlines().index("\tlocal link Foot {") + 1}
    assert any(f.message == "link Foot has the name of another link of the model: it is named 1-p/Foot in the exports"
               for f in clashes)


def test_robotool_sdf_of_indexed_elements(tmp_path):
    model = _sdf(_tree(tmp_path, INDEXED), "robotool")
    links = [l.get("name") for l in model.findall("link")]
    # RoboTool: one running number, parts' links first, indexed links last
    assert links[:2] == ["1-Foot", "2-Foot"] and [l.split("-", 1)[1] for l in links[-6:]] == ["Tip"] * 4 + ["Wheel"] * 2


ROOTS = f"""pmodel Bench {{
	local link Table {{ def {{ inertial information {{ mass 5 }} }} {BOX} }}
	local link Ball {{ def {{ }} local body S {{ def {{ sphere(radius = 0.02) }} }}
		pose {{ x = 0 y = 0 z = 0.5 roll = 0 pitch = 0 yaw = 0 }} }}
}}
"""


def test_several_root_links_are_free_bodies_and_a_link_without_inertial_gets_robotools_default(tmp_path):
    result = _project(tmp_path, ROOTS)
    assert result.ok  # a model, not an error
    tree = build_tree(load_checked([tmp_path]))
    assert [l.name for l in tree.roots] == ["Table", "Ball"] and tree.joints == []
    assert any("free bodies beside the base Table" in m for m in _messages(tree.findings))
    ball = tree.link("Ball")
    assert ball.mass == 1.0 and ball.inertia == pytest.approx(np.eye(3))  # RoboTool: 1 kg, ixx = iyy = izz = 1
    sdf = _sdf(tree)
    assert [float(sdf.findtext(f"link[@name='Ball']/inertial/inertia/{k}")) for k in ("ixx", "iyy", "izz")] == [1, 1, 1]
    assert sdf.find("joint") is None
    model = mujoco.MjModel.from_xml_string(to_mjcf(tree))
    assert model.njnt == 1 and model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE  # the ball falls, the table stays
    robot = ET.fromstring(to_urdf(tree))
    assert robot.find("joint[@name='Ball_free']").get("type") == "floating"  # URDF's one root


def test_robotool_refuses_what_cotwin_refuses(tmp_path):
    result = _project(tmp_path, "pmodel P { local link L { def { inertial information { mass -2 } "
                                "box(length = -1, width = 1, height = 1) } } }")
    assert _messages(result.findings, Severity.ERROR) == ["mass of link L must be positive, is -2",
                                                          "box length in link L must be positive, is -1"]


def test_a_number_that_is_not_finite_is_refused_where_it_is_written(tmp_path):
    """`mass 1e400` (infinity), a pose of 0.0/0.0, a joint limit of 1e400 and an axis of 1e400 checked 'ok' and
    reached the MJCF as mass="inf", range="-inf inf", axis="nan nan nan"."""
    text = ("pmodel P {\n local link L { def { inertial information { mass 1e400 } } pose { x = 0.0/0.0 } }\n"
            " local link M { def { } local joint J { def { annotation Revolute { axis = Axis { xyz = (|0, 0, 1e400|) }\n"
            " limit = Limit { lower = -1e400 upper = 1 velocity = 1 effort = 1 } } } flexibly connected to L } } }")
    result = _project(tmp_path, text)
    errors = [(f.location.line, f.message) for f in result.findings if f.severity is Severity.ERROR]
    assert errors == [(2, "mass of link L must be a finite number, is inf"),
                      (2, "pose x of link L must be a finite number, is nan"),
                      (3, "annotation Axis.xyz must be finite, is (|0, 0, inf|)"),
                      (4, "annotation Limit.lower must be finite, is -inf")], errors


ANNOTATED = f"""pmodel Drive {{
	part g = Gear
	local link Ref {{ def {{ }} {BOX} }}
	local link Arm {{
		def {{ }}
		local body Shell {{ def {{ box(length = 0.1, width = 0.1, height = 0.1) }} }}
		local joint Geared {{
			def {{ annotation Gearbox {{ gearbox_ratio = 0.5 gearbox_reference_body = Ref }} }}
			flexibly connected to Out in g
		}}
		local sensor Bumper {{
			def {{ annotation Contact {{ contact = ContactDetails {{ collision = Arm::Shell }} }} }}
		}}
		local actuator Lamp {{ def {{ annotation Light {{ }} }} }}
		local sensor Eye {{ def {{ annotation Logical_camera {{ update_rate = 2 }} }}
			pose {{ x = 0.1 y = 0 z = 0 roll = 0 pitch = 0 yaw = 0 }} }}
		local sensor Plain {{ def {{ output value: real }} }}
		local joint Spin {{ def {{ annotation Continuous {{ axis = Axis {{ xyz = (|0, 1, 0|) }} }} }}
			flexibly connected to Ref }}
	}}
}}
pmodel Gear {{ local link Out {{ def {{ }} {BOX} }} }}
"""


def test_annotation_values_name_bodies_links_and_parts(tmp_path):
    tree = _tree(tmp_path, ANNOTATED)
    model = _sdf(tree)
    geared = model.find("joint[@name='Geared']")
    assert geared.get("type") == "gearbox" and geared.findtext("gearbox_reference_body") == "Ref"
    assert geared.findtext("gearbox_ratio") == "0.5"
    assert model.find("joint[@name='Spin']").get("type") == "continuous"
    assert model.find("joint[@name='Spin']/axis/limit/lower") is None  # continuous: unlimited
    sensors = {s.get("name"): s for s in model.iter("sensor")}
    assert sensors["Bumper"].findtext("contact/collision") == "Shell"
    robotool = _sdf(tree, "robotool")
    collision = robotool.find("link[@name='3-Arm']/collision").get("name")
    assert {s.get("name"): s for s in robotool.iter("sensor")}["Bumper"].findtext("contact/collision") == collision
    assert robotool.find("joint[@name='4-Geared']").findtext("gearbox_reference_body") == "2-Ref"


def test_sensors_as_robotool_writes_them_and_none_it_would_not(tmp_path):
    tree = _tree(tmp_path, ANNOTATED)
    model = _sdf(tree)
    sensors = {s.get("name"): s.get("type") for s in model.iter("sensor")}
    # the type is the annotation's (Logical_camera: logical_camera, not camera); an unannotated sensor is no SDF sensor
    assert sensors == {"Bumper": "contact", "Eye": "logical_camera"}
    assert model.find("link[@name='Arm']/light").get("name") == "Lamp"  # an actuator annotated Light
    pose = [float(v) for v in model.find("link[@name='Arm']/sensor[@name='Eye']/pose").text.split()]
    assert pose == pytest.approx([0.1, 0, 0, 0, 0, 0])  # cotwin: the sensor's pose as the model gives it
    turned = [float(v) for v in _sdf(tree, "robotool").find(".//sensor[@name='Eye']/pose").text.split()]
    assert turned == pytest.approx([0.1, 0, 0, 0, np.pi / 2, 0])  # RoboTool turns every sensor by pi/2 in pitch


def test_indexed_sensors_are_named_as_robotool_names_them(tmp_path):
    text = f"""pmodel Ring {{ local link L {{ def {{ }} {BOX}
		local sensor Sonar {{ index i : [0, 3) def {{ annotation Sonar {{ sonar = SonarDetails {{ min = 0.1 max = 2 }} }} }}
			pose {{ x = 0 y = 0 z = 0 roll = 0 pitch = 0 yaw = i }} }} }} }}"""
    names = [s.get("name") for s in _sdf(_tree(tmp_path, text)).iter("sensor")]
    assert names == ["Sonar::0", "Sonar::1", "Sonar::2"]


JOINTS = f"""pmodel J {{
	local link A {{ def {{ }} {BOX}
		local joint Bare {{ def {{ }} flexibly connected to B }}
	}}
	local link B {{ def {{ }} {BOX} }}
}}
"""


def test_joint_kinds_come_from_the_definition_and_never_silently_fixed(tmp_path):
    tree = _tree(tmp_path, JOINTS)
    [bare] = tree.joints
    # nothing tells: RoboTool's SDF generator writes revolute (about SDF's default axis), and says so
    assert (bare.kind, list(bare.axis)) == ("revolute", [0, 0, 1])
    assert any("revolute about z, as RoboTool's SDF generator writes it" in m for m in _messages(tree.findings))
    (tmp_path / "m.pm").write_text(JOINTS.replace("local joint Bare { def { }", "local joint Bare { def { annotation Ball { } }"))
    with pytest.raises(CotwinError, match=r"m.pm:3:\d+: error: joint Bare \(Bare\): its annotation Ball names an SDF "
                                          r"ball joint, which cotwin cannot export"):
        build_tree(load_checked([tmp_path]))


PARAMETERS = """pmodel Params {
	const k: int
	const d: real
	part Q = Part { instantiation H = 0.05 pose { x = k y = 0 z = 0 roll = 0 pitch = 0 yaw = d } }
	local link Core { def { inertial information { mass d + k } } }
}
pmodel Part {
	const H: real
	const W: real
	local link Plate { def { } local body S { def { box(length = W, width = 1, height = H) } } }
}
"""


def test_parameters_take_robotools_values_in_the_order_it_meets_them(tmp_path):
    result = _project(tmp_path, PARAMETERS)
    assert result.ok
    assert any(m.startswith("constant 'k' of p-model Params has no value") for m in _messages(result.findings))
    tree = build_tree(load_checked([tmp_path]))
    # RoboTool's SDF generator: the part's pose first (k = 1, d = 2), then the part (W = 3), then Core
    plate = tree.link("Plate")
    assert plate.pose[0, 3] == pytest.approx(1.0) and np.arctan2(plate.pose[1, 0], plate.pose[0, 0]) == pytest.approx(2.0)
    assert [plate.geoms[0].size[k] for k in ("length", "height")] == pytest.approx([3.0, 0.05])  # H instantiated
    assert tree.link("Core").mass == pytest.approx(3.0)
    assert any(m.startswith("'W' has no value: it is 3") for m in _messages(tree.findings))


def test_names_of_a_part_resolve_in_their_scope(tmp_path):
    text = f"""pmodel Top {{
	part a = Piece
	part b = Piece
	local link Base {{ def {{ }} {BOX}
		local joint J {{ def {{ annotation Revolute {{ }} }} flexibly connected to Stud }}
	}}
}}
pmodel Piece {{ local link Stud {{ def {{ }} {BOX} }} }}
"""
    result = _project(tmp_path, text)
    [error] = _messages(result.findings, Severity.ERROR)
    assert error == "joint J: link 'Stud' is ambiguous: parts a, b all have one (name one: 'Stud in a')"
    result = _project(tmp_path, text.replace("\tpart b = Piece\n", ""))
    assert result.ok and any("RoboTool needs 'Stud in a'" in m for m in _messages(result.findings))
    tree = build_tree(load_checked([tmp_path]))
    assert [(j.parent, j.child) for j in tree.joints] == [("Base", "Stud")]  # bare: nothing else is called Stud


def test_a_joint_of_the_pmodel_itself_has_the_base_as_parent(tmp_path):
    text = f"""pmodel Pendulum {{
	local link Base {{ def {{ }} {BOX} }}
	local link Arm {{ def {{ }} {BOX} }}
	local joint theta {{ def {{ annotation Revolute {{ axis = Axis {{ xyz = (|0, 1, 0|) }} }} }} flexibly connected to Arm }}
}}
derived unit newton {{ base kilogram * metre / second^2 factor 1.0 }}
"""
    result = _project(tmp_path, text)
    assert result.ok and any("its parent is the base link" in m for m in _messages(result.findings))
    [joint] = build_tree(load_checked([tmp_path])).joints
    assert (joint.parent, joint.child, joint.kind) == ("Base", "Arm", "revolute")


def test_mujoco_refusal_names_the_pmodel_element(tmp_path):
    tree = _tree(tmp_path, ROOTS)
    tree.link("Ball").geoms[0].size["radius"] = -1.0  # what MuJoCo refuses, made after the checks
    with pytest.raises(CotwinError) as err:
        load(to_mjcf(tree), tree)
    [finding] = err.value.findings
    assert finding.location.path.endswith("m.pm") and finding.location.line == 3
    assert finding.message.startswith("MuJoCo rejected the model made of this element (S): ")
